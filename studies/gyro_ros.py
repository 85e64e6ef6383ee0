#!/usr/bin/env python3
"""Gyroscope calibration on the ROS recordings data2-4 against imu_tk's (issue 11, "must show").

One IMU, three recordings (GetOverMassif's imu_tk fork: acc_data.txt in m/s^2, gyro_data.txt in
rad/s, imu_tk's .calib files per recording). Every number comes from one evaluation formula,
imucal.gyro.evaluate: per motion segment, the angle between the start pose's gravity direction
carried through the integrated calibrated rate and the end pose's measured direction. Every
calibration is scored on the same static intervals (ours, per recording) with its own
accelerometer calibration (imu_tk's gyro with imu_tk's accelerometer, ours with ours).

1. Per recording: before, imu_tk's published, ours in sample and cross-validated over held-out
   motion segments (5 folds, segment k in fold k % 5), without and with g-sensitivity.
2. Out of sample across recordings: both sensors' calibration from recording i applied to the
   raw data of recording j, as calibrated and with the gyro bias re-estimated from j's static
   intervals (what a device does at start-up).
3. Parameter repeatability: the spread of each parameter over the three recordings against its
   reported standard errors (chi-square of the three values about their weighted mean, 2 dof).

Writes studies/results/gyro_ros.md and prints it.

    python studies/gyro_ros.py
"""
from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "studies"))

from gyro_xsens import imutk_in_our_convention  # noqa: E402
from imucal.config.run import load_config  # noqa: E402
from imucal.export.peers import AffineCalibration, read_imutk_calib  # noqa: E402
from imucal.files.output import write_text_atomic  # noqa: E402
from imucal.gyro import GyroOptions, fit_gyro  # noqa: E402
from imucal.gyro.result import arrays, motions  # noqa: E402
from imucal.solve.fit import FitResult  # noqa: E402
from imucal.gyro.evaluate import direction_errors_deg, rms  # noqa: E402
from imucal.gyro.fit import cross_validate  # noqa: E402
from imucal.gyro.gsens import fit_static  # noqa: E402
from imucal.gyro.lead_in import EDGE_RATIO, edge_motion, lead_in_for  # noqa: E402
from imucal.gyro.model import misalignment_entries  # noqa: E402
from imucal.gyro.run import gyro_data  # noqa: E402
from imucal.gyro.segments import GyroData, motion_segments  # noqa: E402
from imucal.solve.stats import chi2_sf  # noqa: E402
from imucal.pipeline import calibrate_accelerometer  # noqa: E402

OUT = ROOT / "studies" / "results" / "gyro_ros.md"
#: [s] integration from inside the still poses (GyroOptions.lead_in_s), table 1b
LEAD_IN = 0.5
RECORDINGS = (2, 3, 4)
FOLDS = 5
GSENS = {"off": "no g-sensitivity", "auto": "g-sensitivity by test"}

AccMap = Callable[[np.ndarray], np.ndarray]
GyroMap = Callable[[np.ndarray, np.ndarray], np.ndarray]


def _real() -> Path:
    real = ROOT.parent / "shared" / "data" / "real"  # ../shared beside the repository
    if real.exists():
        return real
    raise SystemExit("real recordings not found (../shared/data/real)")


@dataclass
class Rec:
    """One ROS recording: our accelerometer run, the gyro data, imu_tk's published calibrations."""

    name: str
    run: object  #: imucal.pipeline.CalibrationRun
    data: GyroData  #: ours (calibrated acceleration from our accelerometer fit)
    folder: Path
    tk_acc: AffineCalibration
    tk_gyro: AffineCalibration

    @property
    def acc_raw(self) -> np.ndarray:
        return self.run.recording.raw

    def static_samples(self) -> np.ndarray:
        return np.concatenate([np.arange(a, b) for a, b in zip(self.data.start, self.data.end)])


def load(k: int, real: Path) -> Rec:
    folder = real / "ros-imu-getovermassif" / f"data{k}"
    run = calibrate_accelerometer(load_config(ROOT / "configs" / f"ros-imu-data{k}.yaml"))
    data, _ = gyro_data(run, str(folder / "gyro_data.txt"), unit="rad/s")
    return Rec(f"data{k}", run, data, folder, read_imutk_calib(folder / "test_imu_acc.calib"),
               read_imutk_calib(folder / "test_imu_gyro.calib"))


def score(target: Rec, acc_map: AccMap, gyro_map: GyroMap, refresh_bias: bool = False,
          lead_in: float = 0.0) -> np.ndarray:
    """Per-segment direction errors [deg] of a calibration (acc_map, gyro_map) on ``target``'s raw data.

    ``refresh_bias``: subtract the calibrated rate's mean over the target's static samples (a
    start-up bias update), whatever the calibration's own bias.
    """
    d = target.data
    acc = acc_map(target.acc_raw)
    rate = gyro_map(d.gyro, acc)
    if refresh_bias:
        rate = rate - rate[target.static_samples()].mean(0)
    g = GyroData(d.t, d.gyro, acc, d.start, d.end, d.unit, d.source)
    return direction_errors_deg(d.t, rate, motion_segments(g, lead_in))


def ours(rec: Rec, res: FitResult) -> tuple[AccMap, GyroMap]:
    return rec.run.calibration.apply, res.apply


def imutk(rec: Rec) -> tuple[AccMap, GyroMap]:
    return rec.tk_acc.apply, lambda g, a: rec.tk_gyro.apply(g)


def nominal(rec: Rec, res: FitResult) -> tuple[AccMap, GyroMap]:
    """Before calibration: the fit's static bias, unit scale, no misalignment or g-sensitivity."""
    return rec.run.calibration.apply, lambda g, a: g - arrays(res).bias


def per_recording(recs: list[Rec], fits: dict, cvs: dict, pooled: dict[str, float]) -> list[str]:
    L = ["## 1. Each recording: imu_tk's published calibration against ours", "",
         "rms direction error [deg] over the recording's motion segments (ratio to imu_tk in brackets).",
         "imu_tk's published calibration was fitted on the whole recording: its numbers are in sample.", "",
         "| calibration | " + " | ".join(f"{r.name} ({len(motions(fits[r.name]['off']).segments)} motions)" for r in recs)
         + " | all three (pooled) |", "|---|" + "---|" * (len(recs) + 1)]
    rows: dict[str, list[np.ndarray]] = {}
    for r in recs:
        f = fits[r.name]
        rows.setdefault("before (static bias, unit scale, no misalignment)", []).append(score(r, *nominal(r, f["off"])))
        rows.setdefault("imu_tk published", []).append(score(r, *imutk(r)))
        for gs, label in GSENS.items():
            rows.setdefault(f"ours, {label}, in sample", []).append(score(r, *ours(r, f[gs])))
            rows.setdefault(f"ours, {label}, cross-validated", []).append(cvs[r.name][gs])
    tk = rows["imu_tk published"]
    for label, errs in rows.items():
        cells = [f"{rms(e):.3f} ({rms(e) / rms(t):.2f})" for e, t in zip(errs, tk)]
        pooled[label] = rms(np.concatenate(errs))
        pooled["motions"] = [e.size for e in errs]
        cells.append(f"{pooled[label]:.3f} ({pooled[label] / rms(np.concatenate(tk)):.2f})")
        L.append(f"| {label} | " + " | ".join(cells) + " |")
    L += ["", "g-sensitivity test (likelihood ratio on the static means, kept per axis when p < 0.01):", ""]
    for r in recs:
        f = fits[r.name]["auto"]
        kept = ", ".join("xyz"[i] for i in range(3) if motions(f).gsens_selected[i]) or "none"
        L.append(f"- {r.name}: p = {', '.join(f'{v:.2g}' for v in motions(f).gsens_p_value)} (x, y, z); kept: {kept}; "
                 f"IPOPT {f.status}, {f.iterations} iterations, reduced chi-square {f.redchi:.3g}.")
    return L + [""]


def lead_in(recs: list[Rec]) -> list[str]:
    """Table 1b: every segment integrated from LEAD_IN s inside its poses, imu_tk on the same segments."""
    L = [f"### 1b. Segments integrated from {LEAD_IN} s inside the still poses", "",
         f"As in the Xsens study (studies/results/gyro_xsens.md): each segment starts {LEAD_IN} s before the end of its start pose "
         "and ends as far into its end pose (`GyroOptions(lead_in_s=...)`), for every row.", "",
         "| calibration | " + " | ".join(r.name for r in recs) + " | all three (pooled) |", "|---|" + "---|" * (len(recs) + 1)]
    rows: dict[str, list[np.ndarray]] = {"imu_tk published": [score(r, *imutk(r), lead_in=LEAD_IN) for r in recs]}
    for gs, label in GSENS.items():
        opt = GyroOptions(gsens=gs, lead_in_s=LEAD_IN)
        rows[f"ours, {label}, in sample"] = [score(r, *ours(r, fit_gyro(r.data, opt)), lead_in=LEAD_IN) for r in recs]
        rows[f"ours, {label}, cross-validated"] = [cross_validate(r.data, opt, FOLDS) for r in recs]
    tk = rows["imu_tk published"]
    for label, errs in rows.items():
        cells = [f"{rms(e):.3f} ({rms(e) / rms(t):.2f})" for e, t in zip(errs, tk)]
        cells.append(f"{rms(np.concatenate(errs)):.3f} ({rms(np.concatenate(errs)) / rms(np.concatenate(tk)):.2f})")
        L.append(f"| {label} | " + " | ".join(cells) + " |")
    return L + [""]


def across(recs: list[Rec], fits: dict, pooled: dict[str, float]) -> list[str]:
    L = ["## 2. Out of sample across recordings", "",
         "Both sensors' calibration from recording i (accelerometer and gyroscope; imu_tk's published files, ours",
         "fitted on i) applied to the raw data of recording j; rms direction error [deg] over j's motions.",
         "\"bias refreshed\": the calibrated rate's mean over j's static samples subtracted (a start-up bias",
         "update, as a device would do), which removes the turn-on bias change between recordings.", "",
         "| calibrated on -> evaluated on | imu_tk | ours, no g-sens. | ours, g-sens. by test "
         "| imu_tk, bias refreshed | ours, no g-sens., bias refreshed | ours, g-sens., bias refreshed |",
         "|---|---|---|---|---|---|---|"]
    cols: list[list[np.ndarray]] = [[] for _ in range(6)]
    for a in recs:
        for b in recs:
            if a is b:
                continue
            maps = [(a.tk_acc.apply, lambda g, x, a=a: a.tk_gyro.apply(g)),
                    (a.run.calibration.apply, fits[a.name]["off"].apply),
                    (a.run.calibration.apply, fits[a.name]["auto"].apply)]
            errs = [score(b, *m) for m in maps] + [score(b, *m, refresh_bias=True) for m in maps]
            for c, e in zip(cols, errs):
                c.append(e)
            L.append(f"| {a.name} -> {b.name} | " + " | ".join(f"{rms(e):.3f}" for e in errs) + " |")
    for key, c in zip(("imu_tk", "off", "auto", "imu_tk refreshed", "off refreshed", "auto refreshed"), cols):
        pooled[f"across {key}"] = rms(np.concatenate(c))
    L.append("| all six (pooled) | " + " | ".join(f"**{rms(np.concatenate(c)):.3f}**" for c in cols) + " |")
    return L + [""]


def _params(res: FitResult) -> dict[str, tuple[float, float]]:
    """Named parameter values and standard errors of a fit (bias, scale, misalignment, G_s rows kept)."""
    out = {}
    for j, a in enumerate("xyz"):
        out[f"s_{a} [mrad/s]"] = (1e3 * arrays(res).bias[j], 1e3 * arrays(res).bias_std[j])
    for j, a in enumerate("xyz"):
        out[f"b_{a} - 1 [1e-3]"] = (1e3 * (arrays(res).scale[j] - 1), 1e3 * arrays(res).scale_std[j])
    m, ms = misalignment_entries(arrays(res).misalignment), misalignment_entries(arrays(res).misalignment_std)
    for name, v, s in zip(("m_xy", "m_xz", "m_yx", "m_yz", "m_zx", "m_zy"), m, ms):
        out[f"{name} [1e-3]"] = (1e3 * v, 1e3 * s)
    for i, a in enumerate("xyz"):
        if motions(res).gsens_selected[i]:
            for j, c in enumerate("xyz"):
                out[f"G_{a}{c} [1e-6 (rad/s)/(m/s^2)]"] = (1e6 * arrays(res).gsens[i, j], 1e6 * arrays(res).gsens_std[i, j])
    return out


def _imutk_params(rec: Rec) -> dict[str, float]:
    b, B, M = imutk_in_our_convention(rec.data, rec.run.intervals.mean, rec.folder / "test_imu_acc.calib",
                                      rec.folder / "test_imu_gyro.calib")
    out = {f"s_{a} [mrad/s]": 1e3 * b[j] for j, a in enumerate("xyz")}
    out.update({f"b_{a} - 1 [1e-3]": 1e3 * (B[j] - 1) for j, a in enumerate("xyz")})
    for name, v in zip(("m_xy", "m_xz", "m_yx", "m_yz", "m_zx", "m_zy"), misalignment_entries(M)):
        out[f"{name} [1e-3]"] = 1e3 * v
    return out


def repeatability(recs: list[Rec], fits: dict, gs: str, pooled: dict[str, float]) -> list[str]:
    ps = [_params(fits[r.name][gs]) for r in recs]
    tks = [_imutk_params(r) for r in recs]
    names = [n for n in ps[0] if all(n in p for p in ps)]
    L = [f"### {GSENS[gs]}", "",
         "| parameter | " + " | ".join(r.name for r in recs) + " | spread (sd of 3) | median std | "
         "chi2 (2 dof) | p | imu_tk's spread |", "|---|" + "---|" * (len(recs) + 5)]
    n_bad = 0
    scales = []
    for n in names:
        v = np.array([p[n][0] for p in ps])
        s = np.array([p[n][1] for p in ps])
        w = 1 / s**2
        mean = np.sum(w * v) / np.sum(w)
        chi2 = float(np.sum((v - mean) ** 2 * w))
        p = chi2_sf(chi2, len(v) - 1)
        n_bad += p < 0.01
        tk = f"{np.std([t[n] for t in tks], ddof=1):.3g}" if n in tks[0] else ""
        if n.startswith("b_"):
            scales.append((np.std(v, ddof=1), np.median(s), np.std([t[n] for t in tks], ddof=1)))
        L.append(f"| {n} | " + " | ".join(f"{a:+.3f} ± {b:.2g}" for a, b in zip(v, s))
                 + f" | {np.std(v, ddof=1):.3g} | {np.median(s):.2g} | {chi2:.3g} | {p:.2g} | {tk} |")
    pooled[f"repeat {gs}"] = (n_bad, len(names))
    pooled[f"scales {gs}"] = np.array(scales)  # [1e-3]: spread, median std, imu_tk's spread per axis
    L += ["", f"{n_bad} of {len(names)} parameters vary more across recordings than their standard errors allow "
          "(p < 0.01)."]
    return L + [""]


def summary(p: dict) -> list[str]:
    """The findings in numbers (pooled rms over the three recordings' motions)."""
    tk = p["imu_tk published"]
    ins, cvo = p["ours, no g-sensitivity, in sample"], p["ours, no g-sensitivity, cross-validated"]
    ins_g, cvg = p["ours, g-sensitivity by test, in sample"], p["ours, g-sensitivity by test, cross-validated"]
    a_tk, a_off, a_on = p["across imu_tk"], p["across off"], p["across auto"]
    (b0, n0), (b1, n1) = p["repeat off"], p["repeat auto"]
    sc = p["scales off"]
    overfit = (f"With {min(p['motions'])} to {max(p['motions'])} motions per recording the nine rotation parameters overfit: held-out errors are "
               f"{cvo / ins:.2f} x the in-sample ones." if cvo > 1.1 * ins else "")
    helps = "helps" if a_on < 0.95 * a_off else "does not help"
    return ["## Summary", "", "<!-- begin:summary -->",
            f"- In sample (each calibration scored on the recording it was fitted on), pooled over {sum(p['motions'])} "
            f"motions: imu_tk "
            f"{tk:.3f} deg, ours {ins:.3f} deg without and {ins_g:.3f} deg with g-sensitivity "
            f"({ins / tk:.2f} and {ins_g / tk:.2f} x imu_tk).",
            f"- Cross-validated over held-out motions, ours: {cvo:.3f} deg without and {cvg:.3f} deg with "
            f"g-sensitivity ({cvo / tk:.2f} and {cvg / tk:.2f} x imu_tk's in-sample figure; imu_tk cannot be "
            f"cross-validated from its published files). {overfit}",
            f"- Out of sample across recordings (calibrate on one, evaluate on another; the test a user's device "
            f"sees), pooled over the six pairs: imu_tk {a_tk:.3f} deg, ours {a_off:.3f} deg without and {a_on:.3f} "
            f"deg with g-sensitivity ({a_off / a_tk:.2f} and {a_on / a_tk:.2f} x imu_tk). g-sensitivity {helps} "
            f"across recordings of this IMU.",
            f"- Repeatability: {b0} of {n0} parameters (no g-sensitivity) and {b1} of {n1} (with) vary across the "
            f"recordings more than their standard errors allow (p < 0.01). Scales (no g-sensitivity): spread "
            f"{sc[:, 0].min():.1f}-{sc[:, 0].max():.1f}e-3 against standard errors of {sc[:, 1].min():.1f}-"
            f"{sc[:, 1].max():.1f}e-3; imu_tk's published scales spread {sc[:, 2].min():.1f}-{sc[:, 2].max():.1f}e-3. "
            f"The standard errors describe the noise within one recording, not what changes between recordings.",
            "<!-- end:summary -->", ""]


def default_rule(recs: list[Rec]) -> list[str]:
    """Which lead-in the default rule (GyroOptions(lead_in_s="auto"), imucal.gyro.lead_in) picks per recording."""
    out = []
    for r in recs:
        gm, _, am, _ = r.data.static_means()
        e = edge_motion(r.data, fit_static(gm, am, "auto"))
        picks = ", ".join(f"{GSENS[gs]} {lead_in_for(r.data, gs, 'auto'):g} s" for gs in GSENS)
        out.append(f"{r.name}: edge ratio {e.ratio:.2f} ({picks})")
    return ["Default segments (`lead_in_s: auto`, imucal/gyro/lead_in.py): the poses' edges turn when their integrated "
            f"rate's mean square is at least {EDGE_RATIO:g} x that of windows inside the poses. "
            + "; ".join(out) + ". Tables 1, 2 and 3 use no lead-in; table 1b the 0.5 s one.", ""]


def main() -> None:
    real = _real()
    recs = [load(k, real) for k in RECORDINGS]
    fits = {r.name: {gs: fit_gyro(r.data, GyroOptions(gsens=gs, lead_in_s=0.0)) for gs in GSENS} for r in recs}
    cvs = {r.name: {gs: cross_validate(r.data, GyroOptions(gsens=gs, lead_in_s=0.0), FOLDS) for gs in GSENS}
           for r in recs}
    L = ["# Gyroscope calibration on the ROS recordings data2-4 (one IMU, three recordings)", "",
         "Generated by `python studies/gyro_ros.py`; do not edit by hand. Data: GetOverMassif's imu_tk fork",
         "(../shared/data/real/ros-imu-getovermassif: acc in m/s^2, gyro in rad/s, 100 Hz, imu_tk's published",
         ".calib files per recording). Metric (imucal.gyro.evaluate, the same formula for every row): per motion",
         "segment between two still poses, the angle [deg] between the start pose's gravity direction carried",
         "through the integrated calibrated rate (imu_tk's quaternion RK4 step) and the end pose's measured",
         "direction; rms over segments. Every calibration is scored on the same static intervals (ours) with its",
         "own accelerometer calibration. Cross-validated: 5 folds, segment k in fold k % 5; the held-out",
         "segments' motions are not in the rotation fit (the static intervals still give bias and g-sensitivity).",
         ""]
    pooled: dict = {}
    body = per_recording(recs, fits, cvs, pooled) + lead_in(recs) + across(recs, fits, pooled)
    body += ["## 3. Parameter repeatability (one IMU, three recordings)", "",
             "Each parameter's value ± standard error on each recording; the chi-square of the three about their",
             "inverse-variance weighted mean (2 dof) tests whether the spread is within the standard errors.",
             "Misalignment in our convention (M_g maps the accelerometer's orthonormal frame to the gyro's axes);",
             "imu_tk's spread: its published parameters converted to our convention (bias as published).", ""]
    for gs in GSENS:
        body += repeatability(recs, fits, gs, pooled)
    L += summary(pooled) + default_rule(recs) + body
    text = "\n".join(L)
    write_text_atomic(OUT, text + "\n")
    print(text)


if __name__ == "__main__":
    main()
