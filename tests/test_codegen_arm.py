"""Generated C on a Cortex-M4F: compiled with arm-none-eabi-gcc, inspected, run under QEMU.

Needs Debian's gcc-arm-none-eabi (and libnewlib-arm-none-eabi, qemu-system-arm for the QEMU
test); each test skips with the reason when a tool is missing.

Measured with arm-none-eabi-gcc 12.2 -Os (float): imucal_apply 136 bytes (98 bytes of code and
a 36-byte literal pool of the 9 constants), imucal_apply_coeffs 98 bytes, imucal_prepare 388;
the Xsens gyroscope (g-sensitivity selected): imucal_apply_gyro 304 bytes (18 multiplies, 18
additions, the 21 constants in the pool), imucal_apply_imu 34 bytes (two calls).
"""
from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from imucal.calibration.frozen import Calibration

from imucal.calibration.frozen import load_calibration
from imucal.export.codegen import write_c

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "codegen"
XSENS = ROOT / "data" / "xsens-mti-imutk" / "xsens_acc.mat"  # shipped with the repository
XSENS_GYRO = XSENS.with_name("xsens_gyro.mat")
ARM_CC = shutil.which("arm-none-eabi-gcc")
QEMU = shutil.which("qemu-system-arm")
M4 = ["-mcpu=cortex-m4", "-mthumb", "-mfpu=fpv4-sp-d16", "-mfloat-abi=hard"]
FLAGS = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", *M4, "-Os"]
#: Upper bound asserted on the size of NAME_apply [bytes] (measured 136 with gcc 12.2).
APPLY_SIZE_BOUND = 160
#: Upper bound asserted on the size of NAME_apply_gyro with a g-sensitivity [bytes] (measured 304).
APPLY_GYRO_SIZE_BOUND = 340
N_QEMU = 100_000

pytestmark = pytest.mark.skipif(ARM_CC is None, reason="arm-none-eabi-gcc not found (Debian: apt-get "
                                "install gcc-arm-none-eabi libnewlib-arm-none-eabi)")


def _tool(name: str) -> str:
    return str(Path(ARM_CC).with_name(name))


@pytest.fixture(scope="module")
def calibration(tmp_path_factory) -> tuple[Calibration, Path]:
    d = tmp_path_factory.mktemp("arm")
    if XSENS.exists() and XSENS_GYRO.exists():  # both sensors; the gyro with a g-sensitivity
        from imucal.config.run import config_from_dict
        from imucal.pipeline import calibrate_imu

        run = calibrate_imu(config_from_dict({"data": {"path": str(XSENS)}, "gravity": {"value": 9.81744}}),
                            gyro_file=str(XSENS_GYRO))
        cal = run.calibration
    else:  # synthetic truth: same code shape
        from imucal.calibration.gyro import from_arrays
        from imucal.model.parameters import base_parameters

        z3, z33 = np.zeros(3), np.zeros((3, 3))
        gyro = from_arrays(unit="raw", bias=np.array([12.0, -30.0, 7.5]), scale=np.array([940.0, 930.0, 945.0]),
                               misalignment=np.array([[1, 0.01, -0.02], [0.015, 1, 0.005], [-0.01, 0.02, 1]]),
                               gsens=np.array([[1.0, 2, -3], [-2, 1.5, 4], [3, -1, 2.5]]) * 1e-4,
                               std={"bias": z3, "scale": z3, "misalignment": z33, "gsens": z33})
        cal = Calibration(params=base_parameters([30, -20, 10], [1670, 1680, 1660], [1.57, 1.56, 1.58]),
                          std={}, gravity=9.80665, attached=(gyro,))
    path = d / "calibration.yaml"
    cal.save(path)
    return load_calibration(path), d


@pytest.fixture(scope="module")
def m4_object(calibration) -> Path:
    cal, d = calibration
    gen = d / "gen_float"
    write_c(cal, gen, precision="float")
    obj = d / "imucal_m4.o"
    subprocess.run([ARM_CC, *FLAGS, "-ffunction-sections", f"-I{gen}", "-c", "-o", str(obj),
                    str(gen / "imucal.c")], check=True, capture_output=True, text=True)
    return obj


def _sizes(obj: Path) -> dict[str, int]:
    out = subprocess.run([_tool("arm-none-eabi-nm"), "--print-size", "--radix=d", str(obj)],
                         check=True, capture_output=True, text=True).stdout
    return {m.group(2): int(m.group(1)) for m in re.finditer(r"^\d+ (\d+) T (\w+)$", out, re.M)}


def _instructions(obj: Path, fn: str) -> list[str]:
    out = subprocess.run([_tool("arm-none-eabi-objdump"), "-d", "--no-show-raw-insn", str(obj)],
                         check=True, capture_output=True, text=True).stdout
    body = re.search(rf"<{fn}>:\n(.*?)(?:\n\n|\Z)", out, re.S).group(1)
    return [m.group(1) for m in re.finditer(r"^\s+[0-9a-f]+:\s+([a-z][\w.]*)", body, re.M)
            if m.group(1) not in (".word", ".short", "nop")]  # literal pool and its padding


def test_apply_on_cortex_m4_is_small_branch_free_single_precision(m4_object, record_property):
    sizes = _sizes(m4_object)
    record_property("imucal_apply_bytes", sizes["imucal_apply"])
    record_property("imucal_apply_coeffs_bytes", sizes["imucal_apply_coeffs"])
    assert sizes["imucal_apply"] <= APPLY_SIZE_BOUND
    assert sizes["imucal_apply_coeffs"] <= APPLY_SIZE_BOUND
    for fn in ("imucal_apply", "imucal_apply_coeffs"):
        ins = _instructions(m4_object, fn)
        assert ins[-1] == "bx" and ins.count("bx") == 1  # the return is the only branch
        branches = [i for i in ins if re.fullmatch(r"(b|bl|blx|cbn?z|it\w*|b\w\w)(\.\w)?", i)]
        assert branches == [], (fn, branches)  # no call (libm, __aeabi_*), no conditional code
        assert not [i for i in ins if i.endswith(".f64") or i.startswith("vdiv")], (fn, ins)
        mul = sum(i in ("vmul.f32", "vmla.f32", "vmls.f32", "vfma.f32", "vnmul.f32") for i in ins)
        add = sum(i in ("vadd.f32", "vsub.f32", "vmla.f32", "vmls.f32", "vfma.f32") for i in ins)
        assert (mul, add) == (6, 6), (fn, ins)


def test_gyro_apply_on_cortex_m4_is_branch_free_single_precision(m4_object, record_property):
    sizes = _sizes(m4_object)
    record_property("imucal_apply_gyro_bytes", sizes["imucal_apply_gyro"])
    record_property("imucal_apply_imu_bytes", sizes["imucal_apply_imu"])
    assert sizes["imucal_apply_gyro"] <= APPLY_GYRO_SIZE_BOUND
    ins = _instructions(m4_object, "imucal_apply_gyro")
    assert ins[-1] == "bx" and ins.count("bx") == 1
    assert [i for i in ins if re.fullmatch(r"(b|bl|blx|cbn?z|it\w*|b\w\w)(\.\w)?", i)] == [], ins
    assert not [i for i in ins if i.endswith(".f64") or i.startswith("vdiv")], ins
    mul = sum(i in ("vmul.f32", "vmla.f32", "vmls.f32", "vfma.f32", "vnmul.f32") for i in ins)
    add = sum(i in ("vadd.f32", "vsub.f32", "vmla.f32", "vmls.f32", "vfma.f32") for i in ins)
    assert (mul, add) == (18, 18), ins  # C (raw_g - s_g): 9 + 9; D acc: 9 + 6, and 3 subtractions
    # NAME_apply_imu calls the two kernels and nothing else (no libm, no __aeabi_* helper)
    out = subprocess.run([_tool("arm-none-eabi-objdump"), "-dr", "--no-show-raw-insn", str(m4_object)],
                         check=True, capture_output=True, text=True).stdout
    body = re.search(r"<imucal_apply_imu>:\n(.*?)(?:\n\n|\Z)", out, re.S).group(1)
    assert re.findall(r"R_ARM_THM_(?:CALL|JUMP24)\s+(\w+)", body) == ["imucal_apply", "imucal_apply_gyro"]
    assert "vdiv" not in body and ".f64" not in body


def test_double_precision_also_builds_for_cortex_m4(calibration):
    cal, d = calibration
    gen = d / "gen_double"
    write_c(cal, gen, precision="double")
    subprocess.run([ARM_CC, *FLAGS, f"-I{gen}", "-c", "-o", str(d / "imucal_m4_double.o"),
                    str(gen / "imucal.c")], check=True, capture_output=True, text=True)


def _rdimon() -> bool:
    out = subprocess.run([ARM_CC, *M4, "-print-file-name=rdimon.specs"], capture_output=True, text=True)
    return ARM_CC is not None and Path(out.stdout.strip()).is_file()


@pytest.mark.skipif(QEMU is None, reason="qemu-system-arm not found (Debian: apt-get install qemu-system-arm)")
def test_example_runs_on_qemu_mps2_an386_and_matches_python(calibration, tmp_path):
    if not _rdimon():
        pytest.skip("newlib's rdimon.specs not found (Debian: apt-get install libnewlib-arm-none-eabi)")
    cal, d = calibration
    gen = d / "gen_float"
    if not (gen / "imucal.c").exists():
        write_c(cal, gen, precision="float")
    elf = tmp_path / "imucal_example_m4.elf"
    subprocess.run([ARM_CC, *FLAGS, "--specs=rdimon.specs", "-T", str(EXAMPLE / "cortex-m4" / "mps2_an386.ld"),
                    f"-I{gen}", "-o", str(elf), str(EXAMPLE / "cortex-m4" / "startup.c"),
                    str(EXAMPLE / "example.c"), str(gen / "imucal.c"), "-lm"],
                   check=True, capture_output=True, text=True)
    rng = np.random.default_rng(5)
    zero = 32768 if cal.values[0:3].mean() > 16384 else 0  # offset-binary or signed 16-bit counts
    raw = rng.integers(zero - 32768, zero + 32768, (N_QEMU, 3))
    text = "x,y,z\n" + "\n".join(f"{x},{y},{z}" for x, y, z in raw) + "\n"
    qemu = [QEMU, "-M", "mps2-an386", "-cpu", "cortex-m4", "-semihosting", "-nographic", "-monitor",
            "none", "-serial", "none", "-kernel", str(elf)]
    res = subprocess.run(qemu, input=text, capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    lines = res.stdout.splitlines()
    assert lines[0] == "ax,ay,az" and len(lines) == N_QEMU + 1
    gcc = shutil.which("gcc")
    if gcc:  # the same bits as the host build of the same files (VMLA rounds like mul + add)
        host = tmp_path / "imucal_example"
        subprocess.run([gcc, "-std=c99", "-O2", f"-I{gen}", "-o", str(host), str(EXAMPLE / "example.c"),
                        str(gen / "imucal.c"), "-lm"], check=True, capture_output=True, text=True)
        assert subprocess.run([str(host)], input=text, capture_output=True, text=True,
                              timeout=60).stdout == res.stdout
    acc = np.loadtxt(lines[1:], delimiter=",")
    ref = cal.apply(raw.astype(float))
    mag = np.maximum(np.linalg.norm(ref, axis=1), cal.gravity)
    ulp = np.abs(acc - ref).max(axis=1) / 2.0 ** (np.floor(np.log2(mag)) - 23)
    assert ulp.max() <= 4.0  # the host bound (tests/test_codegen.py FLOAT_ULP_BOUND)
    # run-time parameters (imucal_prepare with newlib's sinf/cosf/sqrtf on the target)
    args = " ".join(repr(float(v)) for v in cal.values[:9])
    res = subprocess.run([*qemu, "-append", args], input="\n".join(text.splitlines()[:2001]) + "\n",
                         capture_output=True, text=True, timeout=60)
    assert res.returncode == 0, res.stderr
    acc = np.loadtxt(res.stdout.splitlines()[1:], delimiter=",")
    p32 = cal.values[:9].astype(np.float32).astype(float)
    ref = Calibration(params=cal.params.with_values(dict(zip(cal.params.names, p32))), std={},
                      gravity=cal.gravity).apply(raw[:2000].astype(float))
    mag = np.maximum(np.linalg.norm(ref, axis=1), cal.gravity)
    assert (np.abs(acc - ref).max(axis=1) / 2.0 ** (np.floor(np.log2(mag)) - 23)).max() <= 4.0


@pytest.mark.skipif(QEMU is None, reason="qemu-system-arm not found (Debian: apt-get install qemu-system-arm)")
def test_example_with_gyro_on_qemu_matches_host_and_python(calibration, tmp_path):
    """The example's gyro path on the target: imucal_apply then imucal_apply_gyro, as imucal_apply_imu."""
    from imucal.export.codegen import float_error_bound, affine_float_error_bound

    if not _rdimon():
        pytest.skip("newlib's rdimon.specs not found (Debian: apt-get install libnewlib-arm-none-eabi)")
    cal, d = calibration
    gen = d / "gen_float"
    if not (gen / "imucal.c").exists():
        write_c(cal, gen, precision="float")
    elf = tmp_path / "imucal_example_m4.elf"
    subprocess.run([ARM_CC, *FLAGS, "--specs=rdimon.specs", "-T", str(EXAMPLE / "cortex-m4" / "mps2_an386.ld"),
                    f"-I{gen}", "-o", str(elf), str(EXAMPLE / "cortex-m4" / "startup.c"),
                    str(EXAMPLE / "example.c"), str(gen / "imucal.c"), "-lm"],
                   check=True, capture_output=True, text=True)
    if XSENS.exists() and XSENS_GYRO.exists():  # the recording itself (rest and turns), every 3rd sample
        raw_a = np.loadtxt(XSENS)[::3, 1:]
        raw_g = np.loadtxt(XSENS_GYRO)[::3, 1:]
    else:
        rng = np.random.default_rng(6)
        raw_a, raw_g = (rng.integers(-32768, 32768, (20_000, 3)).astype(float) for _ in range(2))
    text = "ax,ay,az,gx,gy,gz\n" + "\n".join(",".join(f"{v:.0f}" for v in r) for r in np.hstack([raw_a, raw_g])) + "\n"
    qemu = [QEMU, "-M", "mps2-an386", "-cpu", "cortex-m4", "-semihosting", "-nographic", "-monitor",
            "none", "-serial", "none", "-kernel", str(elf)]
    res = subprocess.run(qemu, input=text, capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    lines = res.stdout.splitlines()
    assert lines[0] == "ax,ay,az,gx,gy,gz" and len(lines) == raw_a.shape[0] + 1
    gcc = shutil.which("gcc")
    if gcc:  # the same bits as the host build
        host = tmp_path / "imucal_example"
        subprocess.run([gcc, "-std=c99", "-O2", f"-I{gen}", "-o", str(host), str(EXAMPLE / "example.c"),
                        str(gen / "imucal.c"), "-lm"], check=True, capture_output=True, text=True)
        assert subprocess.run([str(host)], input=text, capture_output=True, text=True,
                              timeout=60).stdout == res.stdout
    out = np.loadtxt(lines[1:], delimiter=",")
    acc_ref, omega_ref = cal.apply_imu(raw_a, raw_g)
    # the a priori bounds, with room for Python's own double rounding (1e-12 of the sums)
    acc_err = float_error_bound(cal, raw_a) + 1e-12 * (1 + np.abs(acc_ref))
    assert np.all(np.abs(out[:, :3] - acc_ref) <= acc_err)
    bound = affine_float_error_bound(cal.gyro, raw_g, acc_ref, "float", input_error=acc_err) + 1e-12
    assert np.all(np.abs(out[:, 3:] - omega_ref) <= bound)
