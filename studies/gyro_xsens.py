#!/usr/bin/env python3
"""Gyroscope calibration against imu_tk's published results (issue 11).

On the Xsens MTi recording (raw counts; the ROS recordings: studies/gyro_ros.py), on OUR static
intervals and motion segments, one evaluation formula (imucal.gyro.evaluate) scores every
calibration: the angle between the start gravity direction carried through the integrated rate
and the measured end direction. imu_tk's gyro is scored with imu_tk's own accelerometer
calibration (its own frame), ours with ours. Ours is cross-validated over held-out motion
segments (5 folds, segment k in fold k % 5). Writes studies/results/gyro_xsens.md and prints it.

    python studies/gyro_xsens.py
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from imucal.config.run import load_config  # noqa: E402
from imucal.gyro import GyroOptions, fit_gyro, gyro_data_from_run  # noqa: E402
from imucal.gyro.evaluate import direction_errors_deg, rms  # noqa: E402
from imucal.gyro.fit import cross_validate  # noqa: E402
from imucal.gyro.result import arrays, motions  # noqa: E402
from imucal.report.gyro import gyro_report  # noqa: E402
from imucal.gyro.gsens import fit_static  # noqa: E402
from imucal.gyro.lead_in import EDGE_RATIO, lead_in_for, edge_motion  # noqa: E402
from imucal.gyro.segments import GyroData, motion_segments  # noqa: E402
from imucal.files.output import write_text_atomic  # noqa: E402
from imucal.export.peers import read_imutk_calib  # noqa: E402
from imucal.pipeline import calibrate_accelerometer  # noqa: E402

REAL = ROOT.parent / "shared" / "data" / "real"  # ../shared beside the repository
XSENS = REAL / "xsens-mti-imutk"
ROS = REAL / "ros-imu-getovermassif"
OUT = ROOT / "studies" / "results" / "gyro_xsens.md"
#: the figure quoted by issue 11 for imu_tk on this recording
IMUTK_ISSUE_DEG = 0.518
#: where imu_tk is cross-validated like ours (studies/gyro_imutk_cv.py)
IMUTK_CV = ("imu_tk's figures here are its published calibration, fitted on every segment (in sample). imu_tk "
            "refitted by its own code on the same 5 folds and scored the same way (the no-g-sensitivity target like "
            "for like): [gyro_imutk_cv.md](gyro_imutk_cv.md), `python studies/gyro_imutk_cv.py --driver DRIVER`.")
#: [s] integration from inside the still poses (GyroOptions.lead_in_s) in the second table
LEAD_IN = 0.5


def _real() -> Path:
    if REAL.exists():
        return REAL
    raise SystemExit("real recordings not found (../shared/data/real)")


def load(config: str, gyro_file: Path, unit: str) -> tuple[object, GyroData, np.ndarray]:
    run = calibrate_accelerometer(load_config(ROOT / "configs" / config))
    g = np.loadtxt(gyro_file)
    return run, gyro_data_from_run(run, g[:, 0], g[:, 1:4], unit=unit), g


def imutk_errors(data: GyroData, acc_raw: np.ndarray, acc_calib: Path, gyro_calib: Path,
                 lead_in: float = 0.0) -> np.ndarray:
    """imu_tk's gyro (omega = T K (raw - b)) with imu_tk's accelerometer, on our segments."""
    acc = read_imutk_calib(acc_calib)
    gyr = read_imutk_calib(gyro_calib)
    d = GyroData(data.t, data.gyro, acc.apply(acc_raw), data.start, data.end, data.unit, data.source)
    return direction_errors_deg(d.t, gyr.apply(d.gyro), motion_segments(d, lead_in))


def frame_rotation(a_ours: np.ndarray, a_peer: np.ndarray) -> np.ndarray:
    """Rotation R with a_peer ~ R a_ours (Kabsch on the static means)."""
    U, _, Vt = np.linalg.svd(a_peer.T @ a_ours)
    D = np.diag([1, 1, np.sign(np.linalg.det(U @ Vt))])
    return U @ D @ Vt


def imutk_in_our_convention(data: GyroData, acc_raw_means: np.ndarray, acc_calib: Path, gyro_calib: Path):
    """imu_tk's gyro as (B_g, M_g) mapping OUR accelerometer frame: A = (R^T T K)^-1, B = diag(A), M = B^-1 A."""
    acc = read_imutk_calib(acc_calib)
    gyr = read_imutk_calib(gyro_calib)
    R = frame_rotation(data.static_means()[2], acc.apply(acc_raw_means))
    A = np.linalg.inv(R.T @ gyr.M)
    B = np.diag(A).copy()
    return gyr.o, B, A / B[:, None]


def cv(data: GyroData, gsens: str, lead_in: float = 0.0) -> np.ndarray:
    return cross_validate(data, GyroOptions(gsens=gsens, lead_in_s=lead_in))


def param_table(res, tk) -> list[str]:
    b, B, M = tk
    ax = "xyz"
    L = ["| parameter | ours | std | imu_tk (our convention) | (imu_tk - ours) / std |", "|---|---|---|---|---|"]
    for j in range(3):
        L.append(f"| s_{ax[j]} [raw] | {arrays(res).bias[j]:.6g} | {arrays(res).bias_std[j]:.2g} | {b[j]:.6g} | {(b[j]-arrays(res).bias[j])/arrays(res).bias_std[j]:+.1f} |")
    for j in range(3):
        L.append(f"| b_{ax[j]} [raw per rad/s] | {arrays(res).scale[j]:.6g} | {arrays(res).scale_std[j]:.2g} | {B[j]:.6g} | {(B[j]-arrays(res).scale[j])/arrays(res).scale_std[j]:+.1f} |")
    for i in range(3):
        for j in range(3):
            if i != j:
                s = arrays(res).misalignment_std[i, j]
                L.append(f"| m_{ax[i]}{ax[j]} | {arrays(res).misalignment[i, j]:+.5f} | {s:.2g} | {M[i, j]:+.5f} | {(M[i, j]-arrays(res).misalignment[i, j])/s:+.1f} |")
    return L


def study(name: str, config: str, gyro_file: Path, unit: str, acc_calib: Path, gyro_calib: Path) -> dict:
    run, data, _ = load(config, gyro_file, unit)
    acc_raw = run.recording.raw
    tk = imutk_errors(data, acc_raw, acc_calib, gyro_calib)
    fits, cvs = {}, {}
    for gs in ("off", "auto"):
        t0 = time.perf_counter()
        fits[gs] = fit_gyro(data, GyroOptions(gsens=gs, lead_in_s=0.0))
        fits[gs] = (fits[gs], time.perf_counter() - t0)
        cvs[gs] = cv(data, gs)
    conv = imutk_in_our_convention(data, run.intervals.mean, acc_calib, gyro_calib)
    lead = {"tk": imutk_errors(data, acc_raw, acc_calib, gyro_calib, LEAD_IN)}
    for gs in ("off", "auto"):
        lead[gs] = fit_gyro(data, GyroOptions(gsens=gs, lead_in_s=LEAD_IN))
        lead[f"cv {gs}"] = cv(data, gs, LEAD_IN)
    gm, _, am, _ = data.static_means()
    rule = {"ratio": edge_motion(data, fit_static(gm, am, "auto")).ratio,
            **{gs: lead_in_for(data, gs, "auto") for gs in ("off", "auto")}}
    return {"name": name, "run": run, "data": data, "tk": tk, "fits": fits, "cv": cvs, "conv": conv, "lead": lead,
            "rule": rule}


def default_rule(x: dict) -> list[str]:
    """The targets with the default segments (GyroOptions(lead_in_s="auto"): imucal.gyro.lead_in)."""
    tk0 = rms(x["tk"])
    rule = x["rule"]
    L = []
    for gs, label, target in (("off", "no g-sensitivity", 1.0), ("auto", "with g-sensitivity", 0.4)):
        lead = rule[gs]
        if lead not in (0.0, LEAD_IN):
            raise SystemExit(f"the rule picked a lead-in of {lead} s, not tabulated here")
        err = rms(x["cv"][gs]) if lead == 0 else rms(x["lead"][f"cv {gs}"])
        tk = tk0 if lead == 0 else rms(x["lead"]["tk"])
        L.append(f"{label}: lead-in {lead:g} s, cross-validated {err:.3f} deg = {err / tk:.2f} x imu_tk on the same "
                 f"segments ({tk:.3f}; target <= {target:g} x: {'met' if err <= target * tk else 'MISSED'})"
                 + ("" if lead == 0 else f", {err / tk0:.2f} x imu_tk on the detected intervals' segments"))
    return [f"Default segments (`lead_in_s: auto`, imucal/gyro/lead_in.py; edge ratio {rule['ratio']:.1f}, the poses' "
            f"edges turn at >= {EDGE_RATIO:g}): " + "; ".join(L) + "."]


def section(s: dict) -> list[str]:
    f_off, t_off = s["fits"]["off"]
    f_on, t_on = s["fits"]["auto"]
    tk = rms(s["tk"])
    ld = s["lead"]
    ltk = rms(ld["tk"])
    L = [f"## {s['name']}", "",
         f"{s['data'].n_intervals} static intervals, {len(s['tk'])} motion segments, "
         f"{s['data'].t.size} samples.", "",
         "| calibration | rms direction error [deg] | ratio to imu_tk |", "|---|---|---|",
         f"| before (static bias, nominal scale, no misalignment) | {rms(motions(f_off).error_before_deg):.3f} | {rms(motions(f_off).error_before_deg)/tk:.2f} |",
         f"| imu_tk published | {tk:.3f} | 1.00 |",
         f"| ours, no g-sensitivity, in sample | {rms(motions(f_off).error_deg):.3f} | {rms(motions(f_off).error_deg)/tk:.2f} |",
         f"| ours, no g-sensitivity, cross-validated | {rms(s['cv']['off']):.3f} | {rms(s['cv']['off'])/tk:.2f} |",
         f"| ours, g-sensitivity by test, in sample | {rms(motions(f_on).error_deg):.3f} | {rms(motions(f_on).error_deg)/tk:.2f} |",
         f"| ours, g-sensitivity by test, cross-validated | {rms(s['cv']['auto']):.3f} | {rms(s['cv']['auto'])/tk:.2f} |",
         "", f"The same, every segment integrated from {LEAD_IN} s before the end of its start pose to {LEAD_IN} s after the "
         "start of its end pose (`GyroOptions(lead_in_s=0.5)`; at most a quarter of a pose): the accelerometer's static "
         "detector (0.5 s window) can count a motion's first and last moments as still, which the default segments "
         "then miss. Directions stay the whole poses' means.", "",
         "| calibration | rms direction error [deg] | ratio to imu_tk |", "|---|---|---|",
         f"| imu_tk published | {ltk:.3f} | 1.00 |",
         f"| ours, no g-sensitivity, in sample | {rms(motions(ld['off']).error_deg):.3f} | {rms(motions(ld['off']).error_deg)/ltk:.2f} |",
         f"| ours, no g-sensitivity, cross-validated | {rms(ld['cv off']):.3f} | {rms(ld['cv off'])/ltk:.2f} |",
         f"| ours, g-sensitivity by test, in sample | {rms(motions(ld['auto']).error_deg):.3f} | {rms(motions(ld['auto']).error_deg)/ltk:.2f} |",
         f"| ours, g-sensitivity by test, cross-validated | {rms(ld['cv auto']):.3f} | {rms(ld['cv auto'])/ltk:.2f} |",
         "", f"g-sensitivity test p-values per gyro axis: {', '.join(f'{v:.2g}' for v in motions(f_on).gsens_p_value)} "
         f"(kept: {', '.join('xyz'[i] for i in range(3) if motions(f_on).gsens_selected[i]) or 'none'}).",
         f"Fit time (whole recording, incl. static fit, scale search, NLP build and solve): "
         f"{t_off:.2f} s without, {t_on:.2f} s with g-sensitivity; IPOPT {f_on.status}, {f_on.iterations} iterations.",
         "", "Parameters without g-sensitivity against imu_tk's (converted: A = (R^T T K)^-1 with R the rotation "
         "from our accelerometer frame to imu_tk's, B_g = diag(A), M_g = B_g^-1 A):", ""]
    L += param_table(f_off, s["conv"])
    L += ["", "With g-sensitivity:", "", "```", gyro_report(f_on), "```", ""]
    return L


def main() -> None:
    real = _real()
    xs = real / "xsens-mti-imutk"
    ref = xs / "reference_imutk_output"
    studies = [study("Xsens MTi (imu_tk test data, raw counts)", "xsens-mti-imutk.yaml", xs / "xsens_gyro.mat",
                     "raw", ref / "test_imu_acc.calib", ref / "test_imu_gyro.calib")]
    x = studies[0]
    tk = rms(x["tk"])
    lx = x["lead"]
    ltk = rms(lx["tk"])
    L = ["# Gyroscope calibration against imu_tk", "",
         "Generated by `python studies/gyro_xsens.py`. Metric: per motion segment, the angle [deg] between the",
         "gravity direction of the start pose carried through the integrated calibrated rate (imu_tk's RK4",
         "quaternion step on the time stamps) and the measured direction of the end pose; rms over segments.",
         "Same static intervals and segments for every row; imu_tk's gyro uses imu_tk's accelerometer.",
         "Cross-validated: 5 folds, each fold's segments held out of the fit and evaluated.", "",
         "<!-- begin:targets -->", *default_rule(x),
         f"Fixed segments. Issue 11 targets on the Xsens recording (imu_tk measured here: {tk:.3f} deg; the issue quotes "
         f"{IMUTK_ISSUE_DEG}): no g-sensitivity <= {tk:.3f} deg (cross-validated: "
         f"{rms(x['cv']['off']):.3f}, {'met' if rms(x['cv']['off']) <= tk else 'MISSED'}); with g-sensitivity "
         f"<= {0.4 * tk:.3f} deg (cross-validated: {rms(x['cv']['auto']):.3f}, "
         f"{'met' if rms(x['cv']['auto']) <= 0.4 * tk else 'MISSED'}).",
         f"With the segments integrated from {LEAD_IN} s inside the poses (second table; imu_tk on the same "
         f"segments: {ltk:.3f} deg): no g-sensitivity {rms(lx['cv off']):.3f} "
         f"({'met' if rms(lx['cv off']) <= ltk else 'MISSED'}), with g-sensitivity {rms(lx['cv auto']):.3f} = "
         f"{rms(lx['cv auto']) / ltk:.2f} x imu_tk ({'met' if rms(lx['cv auto']) <= 0.4 * ltk else 'MISSED'}); "
         f"against imu_tk on the default segments: {rms(lx['cv auto']) / tk:.2f} x.", "<!-- end:targets -->", "",
         IMUTK_CV, ""]
    for s in studies:
        L += section(s)
    L += ["The ROS recordings data2-4 (one IMU, three recordings, with repeatability across them): "
          "[gyro_ros.md](gyro_ros.md), `python studies/gyro_ros.py`.", ""]
    text = "\n".join(L)
    write_text_atomic(OUT, text + "\n")
    print(text)


if __name__ == "__main__":
    main()
