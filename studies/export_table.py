#!/usr/bin/env python3
"""What each export format holds, and the error it loses, measured on the Xsens recording.

Calibrates configs/xsens-mti-imutk.yaml (accelerometer and gyroscope), exports to every format,
reads each file back with imucal.export.peers (strict readers; imu_tk's gyro file too), and
measures against our calibration:
  - over all directions at |a| = g (20 000 random unit directions, the peer's output rotated onto
    ours by the least-squares rotation, since a mounting rotation is not calibration):
    max and RMS of |a_ours - a_peer| [m/s^2];
  - on the recording's still intervals (imucal.analysis.compare): RMS of |a| - g [m/s^2];
  - the gyroscope, in that same rotation (the board turns both sensors alike): max and RMS of
    |omega_peer - omega_ours| [deg/s] over 20 000 directions at |omega| = 1 rad/s with a = 0, and at
    rest over 20 000 directions of a at |a| = g; and the RMS over every sample of the Xsens log.
    ArduPilot and PX4 read rad/s from their driver: raw / k with the sensitivity k the export states.
The same calibration given effects (bias_temperature, scale_drift) checks that each says what it drops.
ArduPilot and PX4 hold m/s^2 and refuse a calibration of counts: their rows are the same sensor with its
readings converted as a driver does (driver_si), measured against that converted calibration.
Writes studies/results/export_formats.md (and prints it).

    python studies/export_table.py
"""
from __future__ import annotations

import dataclasses
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from imucal.analysis.compare import compare  # noqa: E402
from imucal.calibration.frozen import Calibration  # noqa: E402
from imucal.config.run import load_config  # noqa: E402
from imucal.data.load import load_recording  # noqa: E402
from imucal.data.static import detect_static  # noqa: E402
from imucal.export.autopilot import gyro_fit  # noqa: E402
from imucal.export.formats import ExportOptions  # noqa: E402
from imucal.export.peers import read_imutk_calib  # noqa: E402
from imucal.export.registry import FORMATS, export, read_peer  # noqa: E402
from imucal.gyro.run import gyro_on_accel_samples  # noqa: E402
from imucal.files.output import write_text_atomic  # noqa: E402
from imucal.model.effects import make_effect  # noqa: E402
from imucal.pipeline import calibrate_imu  # noqa: E402


def _rate_map(g) -> tuple:
    """(C, c, D) with omega = C raw + c - D a: the gyroscope's map through the one accessor (affine)."""
    a = g.affine()
    return a.A, a.c, -a.B

CONFIG = ROOT / "configs" / "xsens-mti-imutk.yaml"
NAMES = {"imutk": "x.calib", "madlab": "x.json", "matrix": "x.json", "kalibr": "imu.yaml",
         "ardupilot": "x.param", "px4": "x.params"}
#: What each format can hold, from its definition (imucal/export/*.py cites each peer's source).
HOLDS = {
    "imutk": ("full matrix (T K) + offset", "no", "second .calib: T K + offset; no G_s term", "no"),
    "madlab": ("full matrix (R_a^-1 K_a^-1) + offset", "no", "R_g^-1 K_g^-1, b_g, K_ga (= G_s), output deg/s", "no"),
    "matrix": ("full matrix + offset", "no", "matrix, offset, acc_matrix (= D)", "no"),
    "kalibr": ("lower-triangular M (= ours, exactly); bias only as imucal's extra key (Kalibr estimates it "
               "online)", "no", "M, C_gyro_i, A (= G_s), exactly; bias as imucal's extra key",
               "yes (`--data`: Allan deviation, both sensors)"),
    "ardupilot": ("offset + diagonal scale (no misalignment)", "INS_TCAL1_*: the bias terms (cubic in T) exactly over TMIN..TMAX; no scale term",
                  "INS_GYROFFS only (rad/s)", "no"),
    "px4": ("offset + diagonal scale (no misalignment)", "TC_A0_*: the bias terms (cubic in T) exactly over TMIN..TMAX; no scale term",
            "CAL_GYRO0_*OFF only (rad/s)", "no"),
}


def unit_vectors(n: int, seed: int) -> np.ndarray:
    u = np.random.default_rng(seed).normal(size=(n, 3))
    return u / np.linalg.norm(u, axis=1, keepdims=True)


def direction_error(cal, peer, n: int = 20000) -> tuple[float, float, np.ndarray]:
    """max, RMS of |a_ours - a_peer R| at |a| = g, and R (rows: a_peer @ R ~ a_ours)."""
    u = unit_vectors(n, 0)
    A, c = cal.linear_map()
    raw = np.linalg.solve(A, (cal.gravity * u - c).T).T
    ours, theirs = cal.apply(raw), peer.apply(raw)
    U, _, Vt = np.linalg.svd(theirs.T @ ours)
    R = U @ Vt
    e = np.linalg.norm(theirs @ R - ours, axis=1)
    return float(e.max()), float(np.sqrt(np.mean(e**2))), R


def gyro_errors(cal, peer, R: np.ndarray, k: float, raw_a: np.ndarray, raw_g: np.ndarray, n: int = 20000
                ) -> tuple[float, float, float, float, float]:
    """[deg/s]: max, RMS at |omega| = 1 rad/s (a = 0); max, RMS at rest (|a| = g); RMS on the log."""
    C, c, D = _rate_map(cal.gyro)
    A, ca = cal.linear_map()

    def err(omega: np.ndarray, a: np.ndarray) -> np.ndarray:
        rg = np.linalg.solve(C, (omega - c + a @ D.T).T).T  # raw gyro imucal calibrates to omega
        ra = np.linalg.solve(A, (a - ca).T).T
        return np.degrees(np.linalg.norm(peer.gyro.apply(rg / k, peer.apply(ra)) @ R - omega, axis=1))

    zero = np.zeros((n, 3))
    e1, e2 = err(unit_vectors(n, 1), zero), err(zero, cal.gravity * unit_vectors(n, 2))
    acc, omega = cal.apply_imu(raw_a, raw_g)
    e3 = np.degrees(np.linalg.norm(peer.gyro.apply(raw_g / k, peer.apply(raw_a)) @ R - omega, axis=1))
    rms = lambda e: float(np.sqrt(np.mean(e**2)))  # noqa: E731
    return float(e1.max()), rms(e1), float(e2.max()), rms(e2), rms(e3)


def with_effects(cal: Calibration) -> Calibration:
    """The Xsens calibration with bias_temperature (x, y, z) and scale_drift (z) of non-zero size."""
    effects = (("bias_temperature", (0, 1, 2)), ("scale_drift", (2,)))
    params = cal.params
    for name, axes in effects:
        params = params.extended(make_effect(name, axes).parameters(params))
    params = params.with_values({"bias_temperature_x": 0.4, "scale_drift_z": 1e-6})
    return dataclasses.replace(cal, params=params, std={n: 0.0 for n in params.names}, effects=effects)


#: the formats whose parameters apply to a driver's readings in m/s^2 (imucal.export.autopilot)
AUTOPILOTS = ("ardupilot", "px4")


def driver_si(cal: Calibration, rec):
    """The same sensor with its readings in m/s^2 as a driver converts them, (raw - z) / k (z: the shifts'
    mean, the ADC's zero; k: the mean sensitivity [raw per m/s^2]): the calibration of those readings
    (the calibrated acceleration unchanged) and the recording so converted. As tests/test_export_peers.py."""
    from imucal.model.parameters import Parameters

    z, k = float(np.mean(cal.values[0:3])), float(np.mean(cal.values[3:6]))
    shift = {"s1": z, "s2": z, "s3": z}
    params = Parameters(dataclasses.replace(
        p, value=(p.value - shift.get(n, 0.0)) / k, lower=(p.lower - shift.get(n, 0.0)) / k,
        upper=(p.upper - shift.get(n, 0.0)) / k, scale=p.scale / k, unit="m/s^2" if n in shift else "1")
        if n in ("s1", "s2", "s3", "b1", "b2", "b3") else p for n, p in cal.params.items())
    return (dataclasses.replace(cal, params=params, raw_unit="m/s^2"),
            dataclasses.replace(rec, raw=(rec.raw - z) / k, unit="m/s^2"), z, k)


def main() -> int:
    cfg = load_config(CONFIG)
    gyro_file = str(cfg.base_dir / cfg.data.gyro_path)
    counts_cal = calibrate_imu(cfg, gyro_file=gyro_file).calibration
    counts_rec = load_recording(cfg.data, cfg.base_dir)
    raw_g = gyro_on_accel_samples(counts_rec, gyro_file)
    iv = detect_static(counts_rec.t, counts_rec.raw, cfg.static, counts_rec.temp, source=counts_rec.source)
    si_cal, si_rec, zero, k_si = driver_si(counts_cal, counts_rec)
    fit = gyro_fit(si_cal)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for fmt in FORMATS:
            name = NAMES[fmt]
            cal, rec = (si_cal, si_rec) if fmt in AUTOPILOTS else (counts_cal, counts_rec)
            out = export(cal, fmt, ExportOptions(filename=name))
            path = Path(tmp) / name
            path.write_text(out.text)
            if out.gyro_text is not None:
                (Path(tmp) / "gyro.calib").write_text(out.gyro_text)
                peer = read_imutk_calib(path, Path(tmp) / "gyro.calib")
            else:
                peer = read_peer(path, fmt)
            mx, rms, R = direction_error(cal, peer)
            k = fit.sensitivity if fmt in AUTOPILOTS else 1.0
            g = gyro_errors(cal, peer, R, k, rec.raw, raw_g)
            cmp = compare(cal, peer, rec, iv, cal.gravity, ("ours", fmt))
            dropped = [n for n in export(with_effects(cal), fmt, ExportOptions(filename=name)).notes
                       if n.startswith("effects")]
            rows.append((fmt, *HOLDS[fmt], mx, rms, float(cmp.rms[1]), float(cmp.rms[0]), g, bool(dropped)))
    lines = ["# Export formats: what each holds, and what it loses for the Xsens MTi", "",
             "Produced by `python studies/export_table.py`: the Xsens recording (`configs/xsens-mti-imutk.yaml`, "
             "accelerometer and gyroscope) calibrated, exported to each format, read back with imucal's strict "
             f"reader, and applied to raw readings. g = {counts_cal.gravity} m/s^2; {iv.n} still intervals.", "",
             "<!-- begin:table -->",
             "| format | map it holds | temperature terms | gyroscope | noise (Kalibr fields) | "
             "lost over all directions: max / RMS [m/s^2] | still intervals: RMS of abs(a) - g [m/s^2] (ours "
             f"{rows[0][8]:.5f}) |",
             "|---|---|---|---|---|---|---|"]
    for fmt, holds, temp, gyro, noise, mx, rms, crms, _, _, _ in rows:
        lines.append(f"| `{fmt}` | {holds} | {temp} | {gyro} | {noise} | {mx:.2g} / {rms:.2g} | {crms:.5f} |")
    lines += ["", "The gyroscope, in the accelerometer's best-aligned frame [deg/s]:", "",
              "| format | lost at abs(omega) = 1 rad/s, all directions: max / RMS | lost at rest, abs(a) = g, all "
              f"directions: max / RMS | on the Xsens log ({counts_rec.n} samples): RMS |",
              "|---|---|---|---|"]
    for r in rows:
        g = r[9]
        lines.append(f"| `{r[0]}` | {g[0]:.2g} / {g[1]:.2g} | {g[2]:.2g} / {g[3]:.2g} | {g[4]:.2g} |")
    lines += ["", "Every format drops effects (drift, nonlinearity; temperature except the bias terms ArduPilot's "
              "INS_TCAL1_* and PX4's TC_A0_* hold, `tests/test_export_tempcal.py`): the file holds the map at the "
              "effects' reference point and `imucal export` prints what was dropped (checked with the Xsens "
              f"calibration given bias_temperature and scale_drift terms: {sum(r[-1] for r in rows)} of {len(rows)} "
              "formats say so). `imucal codegen` keeps every effect.",
              "ArduPilot and PX4 apply their parameters to the driver's readings in m/s^2, and `imucal export` refuses "
              "a calibration of counts such as the Xsens one (it converts g and mg): their rows are the same sensor "
              f"with its readings converted as a driver does, (raw - {zero:.6g}) / {k_si:.6g} (the ADC's zero and the "
              "mean sensitivity), calibrated by the same map. Their gyro offsets are in rad/s for a driver "
              f"sensitivity k = {fit.sensitivity:.6g} counts per rad/s (the single value that best fits this "
              "calibration; the export states it).",
              "The Xsens gyroscope's g-sensitivity (G_s, all three rows selected) is "
              f"{np.abs(counts_cal.gyro.gsens).max():.2g} (rad/s)/(m/s^2) at most: imu_tk, which has no such term, loses it at rest; madlab (K_ga), Kalibr (A) "
              "and the matrix file (acc_matrix) hold it.",
              "Kalibr's row uses imucal's offset keys; Kalibr itself estimates the biases online.",
              "<!-- end:table -->", ""]
    text = "\n".join(lines)
    write_text_atomic(ROOT / "studies" / "results" / "export_formats.md", text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
