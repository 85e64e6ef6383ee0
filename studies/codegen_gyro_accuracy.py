#!/usr/bin/env python3
"""Measure the generated gyroscope C (NAME_apply_imu) against Python's Calibration.apply_imu.

    python studies/codegen_gyro_accuracy.py [--calibration CAL.yaml] [--out docs/codegen_gyro.md]

Without --calibration, the shipped Xsens recording (data/xsens-mti-imutk, accelerometer and
gyroscope) is calibrated first. The C is generated in float and double, compiled with gcc -O2
-std=c99, loaded with ctypes and run on the recording's raw samples and on 10^5 random 16-bit
vectors of both sensors. Reported: the operation count of NAME_apply_gyro, the max error of the
rate against Python's double apply [rad/s], the a priori bound (imucal.export.codegen.
affine_float_error_bound with the accelerometer's bound carried through D, plus the rounding of
Python's double reference) and the largest
error / bound over the samples, and the Cortex-M4F size of the functions when arm-none-eabi-gcc
is installed. The table replaces the block between the markers in --out. Not a test.
"""
from __future__ import annotations

import argparse
import ctypes
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from imucal.calibration.frozen import load_calibration  # noqa: E402
from imucal.calibration.frozen import Calibration  # noqa: E402
from imucal.export.codegen import float_error_bound, generate_c, affine_float_error_bound, write_c  # noqa: E402


def _rate_map(g) -> tuple:
    """(C, c, D) with omega = C raw + c - D a: the gyroscope's map through the one accessor (affine)."""
    a = g.affine()
    return a.A, a.c, -a.B

DATA = ROOT / "data" / "xsens-mti-imutk"
CFLAGS = ["-std=c99", "-O2", "-Wall", "-Wextra", "-Werror", "-pedantic", "-fPIC", "-shared"]
M4 = ["-std=c99", "-mcpu=cortex-m4", "-mthumb", "-mfpu=fpv4-sp-d16", "-mfloat-abi=hard", "-Os",
      "-ffunction-sections", "-c"]
U53 = 2.0**-53
BEGIN, END = "<!-- begin:gyro_accuracy -->", "<!-- end:gyro_accuracy -->"


def _calibration(path: str | None, work: Path) -> tuple[Calibration, str]:
    if path:
        return load_calibration(path), Path(path).name
    from imucal.config.run import config_from_dict
    from imucal.pipeline import calibrate_imu

    run = calibrate_imu(config_from_dict({"data": {"path": str(DATA / "xsens_acc.mat")},
                                          "gravity": {"value": 9.81744}}),
                        gyro_file=str(DATA / "xsens_gyro.mat"))
    p = work / "calibration.yaml"
    run.calibration.save(p)
    return load_calibration(p), "the Xsens MTi recording (imucal calibrate --gyro-data, g = 9.81744)"


def _apply_imu(lib: ctypes.CDLL, dtype, raw_a: np.ndarray, raw_g: np.ndarray) -> np.ndarray:
    ra, rg = (np.ascontiguousarray(x, dtype=dtype) for x in (raw_a, raw_g))
    acc, omega = np.zeros_like(ra), np.zeros_like(rg)
    fn = lib.imucal_apply_imu_batch
    fn.argtypes = [ctypes.c_void_p] * 4 + [ctypes.c_size_t]
    fn.restype = None
    fn(ra.ctypes.data, rg.ctypes.data, acc.ctypes.data, omega.ctypes.data, ra.shape[0])
    return omega.astype(float)


def _python_rounding_acc(cal: Calibration, raw: np.ndarray) -> np.ndarray:
    """Rounding of the reference's own double acc, raw @ A.T + c."""
    A, c = cal.linear_map()
    return 4 * U53 * (np.abs(raw) @ np.abs(A).T + np.abs(c))


def _python_rounding_gyro(cal: Calibration, raw_g: np.ndarray, acc: np.ndarray, acc_err: np.ndarray) -> np.ndarray:
    """Rounding of the reference's double rate, raw @ C.T + c - acc @ D.T, and of its acc through D."""
    C, _, D = _rate_map(cal.gyro)
    return (6 * U53 * (np.abs(raw_g) @ np.abs(C).T + np.abs(C) @ np.abs(cal.gyro.forward().s) + np.abs(acc) @ np.abs(D).T)
            + acc_err @ np.abs(D).T)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--calibration", help="calibration.yaml with a gyroscope part (default: calibrate the Xsens recording)")
    ap.add_argument("--out", default=str(ROOT / "studies" / "results" / "codegen_gyro_accuracy.md"), help="markdown result file (its block is inserted into docs/codegen_gyro.md)")
    args = ap.parse_args(argv)
    gcc = shutil.which("gcc")
    if gcc is None:
        print("gcc not found", file=sys.stderr)
        return 1
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        cal, what = _calibration(args.calibration, work)
        if cal.gyro is None:
            print("the calibration has no gyroscope part", file=sys.stderr)
            return 1
        rng = np.random.default_rng(3)
        sets = {"recording": (np.loadtxt(DATA / "xsens_acc.mat")[:, 1:], np.loadtxt(DATA / "xsens_gyro.mat")[:, 1:]),
                "10^5 random 16-bit vectors": (rng.integers(0, 65536, (100_000, 3)).astype(float),
                                               rng.integers(0, 65536, (100_000, 3)).astype(float))}
        if args.calibration:
            sets.pop("recording")
        ops = generate_c(cal).apply_gyro_ops
        rows = []
        for prec, dtype in (("float", np.float32), ("double", np.float64)):
            d = work / prec
            write_c(cal, d, precision=prec)
            so = d / "libimucal.so"
            subprocess.run([gcc, *CFLAGS, "-o", str(so), str(d / "imucal.c"), "-lm"], check=True)
            lib = ctypes.CDLL(str(so))
            for name, (ra, rg) in sets.items():
                acc_ref, omega_ref = cal.apply_imu(ra, rg)
                err = np.abs(_apply_imu(lib, dtype, ra, rg) - omega_ref)
                py_acc = _python_rounding_acc(cal, ra)
                bound = (affine_float_error_bound(cal.gyro, rg, acc_ref, prec,
                                                input_error=float_error_bound(cal, ra, prec) + py_acc)
                         + _python_rounding_gyro(cal, rg, acc_ref, py_acc))
                rows.append(f"| {prec} | {name} | {err.max():.2g} | {bound.max():.2g} | {(err / bound).max():.2f} |")
        sizes = ""
        arm = shutil.which("arm-none-eabi-gcc")
        if arm:
            d = work / "float"
            obj = work / "imucal_m4.o"
            subprocess.run([arm, *M4, f"-I{d}", "-o", str(obj), str(d / "imucal.c")], check=True)
            nm = subprocess.run([str(Path(arm).with_name("arm-none-eabi-nm")), "--print-size", "--radix=d", str(obj)],
                                check=True, capture_output=True, text=True).stdout
            size = {m.group(2): int(m.group(1)) for m in re.finditer(r"^\d+ (\d+) T (\w+)$", nm, re.M)}
            version = subprocess.run([arm, "--version"], capture_output=True, text=True).stdout.splitlines()[0]
            sizes = (f"\n\nCortex-M4F ({version}, {' '.join(M4[1:6])}, float): imucal_apply_gyro "
                     f"{size['imucal_apply_gyro']} bytes, imucal_apply_imu {size['imucal_apply_imu']} bytes "
                     f"(two calls), imucal_apply_gyro_i16 {size['imucal_apply_gyro_i16']} bytes.")
    uses = "with" if cal.gyro.reads_inputs() else "without"
    block = "\n".join([
        BEGIN,
        f"Written by `studies/codegen_gyro_accuracy.py` (rerun it to refresh). Calibration: {what}, {uses} "
        "g-sensitivity.",
        f"NAME_apply_gyro: {ops}.",
        "Error: max over the samples and axes of |omega from NAME_apply_imu - Calibration.apply_imu| [rad/s]; "
        "bound: the a priori bound of the C (affine_float_error_bound, the accelerometer's float_error_bound "
        "carried through D) plus the rounding of Python's own double apply (the same order as the C's in "
        "double); error / bound: the largest ratio over the samples and axes.",
        "",
        "| precision | inputs | max error [rad/s] | max bound [rad/s] | max error / bound |",
        "|---|---|---:|---:|---:|",
        *rows,
    ]) + sizes + "\n" + END
    out = Path(args.out)
    text = out.read_text() if out.exists() else f"{BEGIN}\n{END}\n"
    if BEGIN not in text or END not in text:
        print(f"{out}: no {BEGIN} ... {END} block", file=sys.stderr)
        return 1
    out.write_text(text[:text.index(BEGIN)] + block + text[text.index(END) + len(END):])
    print(block)
    return 0


if __name__ == "__main__":
    sys.exit(main())
