"""The magnetometer study (issue 26): the real CK-Explorer log and simulated logs; writes studies/results/magnetometer_study.md.

    python studies/mag_study.py [--seeds 100]      (needs scipy, for the independent check)

1. The accelerometer of the log, calibrated by imucal (acc_log.csv), and whether it fits acc_mag_log.csv.
2. The magnetometer on the whole log: values, mounting, lag, the soft-iron test, figures before and after.
3. Cross-validated: fit on alternate blocks of the log, judged on the others, beside an independent check
   written here with numpy/scipy (an algebraic ellipsoid fit, its symmetric matrix square root, and a
   rotation that holds the dip constant found by scipy.optimize.least_squares).
4. The lag: the dip scatter with the magnetometer shifted by whole samples.
5. Monte-Carlo: simulated logs with known hard/soft iron, an AK8963 mounting and a misalignment; the spread
   of (value - truth) / standard error over seeds.
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from imucal.config.run import config_from_dict  # noqa: E402
from imucal.data.load import DataSpec, load_recording  # noqa: E402
from imucal.files.output import write_text_atomic  # noqa: E402
from imucal.mag import evidence as ev  # noqa: E402
from imucal.mag.calibrate import MagSettings, calibrate_mag  # noqa: E402
from imucal.mag.frame import dip_angles  # noqa: E402
from imucal.mag.model import vectorized  # noqa: E402
from imucal.mag.simulate import simulate_mag, truth_from_soft_iron  # noqa: E402
from imucal.pipeline import calibrate_accelerometer  # noqa: E402

LOGS = ROOT.parent / "shared" / "data" / "real" / "magnetometer-ckexplorer"
#: The rate is not stated. acc_log.csv's holds last about 76 samples: at an assumed 25 Hz (3 s) the
#: still-interval detector's 1.5 s minimum keeps them; at 100 Hz it finds none. Only the accelerometer's
#: still intervals depend on it; the magnetometer works in samples.
ASSUMED_RATE = 25.0
#: Samples per window of the moving log (the dip's poses): 1 s at the assumed rate.
WINDOW = 25
#: Block lengths of the cross-validation: the halves are alternate blocks.
BLOCKS = (250, 500, 1000, 2000)
AK8963 = (0, 1, 0, 1, 0, 0, 0, 0, -1)
SOFT = np.array([[1.05, 0.03, -0.02], [0.03, 0.97, 0.01], [-0.02, 0.01, 1.01]])
MISALIGNMENT_DEG = (1.0, -0.5, 1.5)


def _rms(x) -> float:
    return float(np.sqrt(np.mean(np.asarray(x, float) ** 2)))


# --- the independent check: plain numpy / scipy -------------------------------------------------------
def algebraic_ellipsoid(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centre s and symmetric A with |A (x - s)| = 1: the general quadric by linear least squares."""
    X, Y, Z = x.T
    M = np.column_stack([X * X, Y * Y, Z * Z, 2 * X * Y, 2 * X * Z, 2 * Y * Z, 2 * X, 2 * Y, 2 * Z])
    c = np.linalg.lstsq(M, np.ones(len(x)), rcond=None)[0]
    Q = np.array([[c[0], c[3], c[4]], [c[3], c[1], c[5]], [c[4], c[5], c[2]]])
    s = -np.linalg.solve(Q, c[6:])
    w, V = np.linalg.eigh(Q / (1 + s @ Q @ s))
    return s, V @ np.diag(np.sqrt(w)) @ V.T


def dip_alignment(a: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Rotation vector and dip minimising the dip's scatter (scipy least squares from the identity)."""
    def res(x):
        return dip_angles(a, h @ Rotation.from_rotvec(x[:3]).as_matrix().T) - x[3]
    return least_squares(res, [0.0, 0.0, 0.0, float(np.mean(dip_angles(a, h)))]).x


# --- the log -------------------------------------------------------------------------------------------
def load_log():
    rec = load_recording(DataSpec(path=str(LOGS / "acc_mag_log.csv"), sample_rate=ASSUMED_RATE, unit="g"))
    return rec.mag, rec.raw


def accelerometer_section(acc: np.ndarray, mag_cal) -> tuple[list[str], np.ndarray]:
    """imucal's calibration of acc_log.csv, applied to acc_mag_log.csv's accelerometer, against the
    readings as logged: |a| of the windows, and the magnetometer's dip scatter with each."""
    cfg = config_from_dict({"data": {"path": str(LOGS / "acc_log.csv"), "sample_rate": ASSUMED_RATE, "unit": "g"}},
                           None)
    run = calibrate_accelerometer(cfg)
    fit = run.result
    applied = run.calibration.apply(acc) / 9.80665  # in g again
    w = ev.windows(len(acc), WINDOW)
    dev = {k: _rms(np.linalg.norm(w.means(v), axis=1) - 1.0) for k, v in (("logged", acc), ("applied", applied))}
    dips = {}
    for k, v in (("logged", acc), ("applied", applied)):
        dips[k] = calibrate_mag(mag_cal, v, settings=MagSettings(window=WINDOW), raw_unit="gauss").report.dip_deg
    s = [fit.params[f"s{i}"].value for i in (1, 2, 3)]
    L = ["## 1. The accelerometer", "",
         f"imucal calibrates `acc_log.csv` (16,000 rows in g, {ASSUMED_RATE:g} Hz assumed: its holds last about "
         f"76 samples, which the still-interval detector keeps at this rate and misses at 100 Hz): "
         f"{fit.dof + len(fit.free_names)} intervals, reduced chi-square {fit.redchi:.3g} with the per-visit "
         f"excess, shifts {s[0]:+.4f}, {s[1]:+.4f}, {s[2]:+.4f} g. "
         "`acc_mag_log.csv`'s own still parts (19 short intervals) leave s1, s2, b1, b2 and phi undetermined: "
         "imucal refuses them.", "",
         "Applied to `acc_mag_log.csv`'s accelerometer, that calibration makes things worse, not better:", "",
         "| accelerometer of acc_mag_log.csv | RMS of mean(a) over 25-sample windows minus 1 g | "
         "dip scatter after alignment [deg] |", "|---|---|---|",
         f"| as logged | {100 * dev['logged']:.2f} % | {dips['logged'].after:.3f} |",
         f"| imucal's calibration of acc_log.csv applied | {100 * dev['applied']:.2f} % | {dips['applied'].after:.3f} |",
         "",
         "The log's README says the magnetometer demo was recorded \"with a calibrated accelerometer\": its "
         "readings already carry a correction (an ellipsoid fit to its windows finds offsets near 0.002 g, where "
         f"acc_log.csv's are {min(abs(v) for v in s):.3f} to {max(abs(v) for v in s):.3f} g), and applying "
         "acc_log.csv's calibration corrects twice. The rest of this study uses the accelerometer as logged.", ""]
    return L, acc


def whole_log(mag: np.ndarray, acc: np.ndarray) -> tuple[list[str], object]:
    t0 = time.perf_counter()
    cal = calibrate_mag(mag, acc, settings=MagSettings(window=WINDOW), raw_unit="gauss", source="acc_mag_log.csv")
    dt = time.perf_counter() - t0
    r, rep = cal.report, cal.report
    rows = [f"| {n} | {cal.params[n].value:.6g} | {cal.fit.std[n]:.2g} | {cal.params[n].unit} |"
            for n in cal.fit.free_names]
    deg = {n: math.degrees(cal.params[n].value) for n in ("rx", "ry", "rz", "dip")}
    L = ["## 2. The magnetometer on the whole log", "",
         f"`calibrate_mag` ({dt:.1f} s): 12,000 NORM rows (every sample), {cal.poses.n} DIP rows (the "
         f"{WINDOW}-sample windows in which the field turns less than {ev.MAX_TURN_DEG:g} deg and |a| stays within "
         "5 % of the median), F fitted with the scales' geometric mean held at 1 gauss per gauss.", "",
         f"- mounting: **{cal.axes.best.words}** (dip scatter {math.degrees(cal.axes.best.dip_scatter):.2f} deg; "
         f"the runner-up's {cal.axes.margin:.1f} times larger; the closed form agrees: {cal.axes.agrees})",
         f"- lag: {'%.2f samples' % cal.lag.samples if cal.lag.estimated else 'not estimated'} (turn-speed "
         f"correlation {cal.lag.correlation:.2f}, below {ev.MIN_LAG_CORRELATION}: the two sensors' motion "
         "does not show one; section 4)",
         f"- soft iron: **{'full 3x3' if cal.full_soft_iron else 'symmetric'}** (F = {cal.soft_iron.f:.1f} "
         f"on 3 and {cal.poses.n - 4} dof, p = {cal.soft_iron.p:.2g}): the magnetometer is turned "
         f"**{math.degrees(cal.misalignment):.2f} deg** from the accelerometer beyond the symmetric soft iron",
         f"- field F = {cal.params['F'].value:.5f} +/- {cal.fit.std['F']:.1g} gauss (on the held size), dip "
         f"{deg['dip']:.2f} deg (the field points {'up' if deg['dip'] > 0 else 'down'} from the horizontal "
         "plane: south of the magnetic equator)",
         f"- noise of each kind's rows over what the readings' scatter predicts: NORM {cal.fit.factors[0]:.2f}, "
         f"DIP {cal.fit.factors[1]:.2f} (variance components; the standard errors include them)",
         f"- field steps between windows: CUSUM p = {cal.steps.p:.2g}, "
         f"{'a step after window %d' % cal.steps.step_after if cal.steps.step_after is not None else 'no step above 0.5 %'}"
         f", {len(cal.steps.outliers)} windows off the rest", "",
         "| figure | before | after | noise floor |", "|---|---|---|---|",
         f"| field-norm residual, RMS over samples [% of F] | {rep.norm_pct.before:.2f} | {rep.norm_pct.after:.3f} | "
         f"{rep.norm_pct.floor:.3f} |",
         f"| dip scatter over the windows [deg]: as read / symmetric soft iron / aligned | {r.dip_deg.before:.2f} | "
         f"{r.dip_deg.unaligned:.3f} / {r.dip_deg.after:.3f} | {r.dip_deg.floor:.3f} |", "",
         "| parameter | value | std | unit |", "|---|---|---|---|", *rows, ""]
    return L, cal


def _held_out_windows(mag, acc, s0, use):
    w = ev.quiet_windows(ev.shift(mag, 0.0) - s0, WINDOW)
    w = w.subset(w.inside(~use))
    an = np.linalg.norm(w.means(acc), axis=1)
    return w.subset(np.abs(an / np.median(an) - 1) <= 0.05)


def cross_validation(mag: np.ndarray, acc: np.ndarray, s_full: np.ndarray) -> list[str]:
    """Fit on alternate blocks, judge on the others; imucal beside the independent check."""
    L = ["## 3. Cross-validated", "",
         "The log is cut into blocks of B samples; one half is the even blocks, the other the odd ones. Each "
         "method fits one half and is judged on the other, both ways. Field-norm residual: RMS of |h| - F over "
         "the held-out samples in % of F (each method's own F). Dip scatter: the standard deviation of the dip "
         f"over the held-out {WINDOW}-sample windows in which the field turns less than {ev.MAX_TURN_DEG:g} deg "
         "(one selection for both methods), before and after each method's alignment. The independent check: "
         "a linear ellipsoid fit (numpy), its symmetric square root as the soft iron, and the rotation that "
         "holds the dip constant by scipy's least squares from the identity.", "",
         "| B | half | imucal norm [%] | independent norm [%] | imucal dip symmetric / aligned [deg] | "
         "independent dip before / aligned [deg] | alignment imucal / independent [deg] |",
         "|---|---|---|---|---|---|---|"]
    agg: dict[str, list[float]] = {k: [] for k in ("in", "ii", "ds", "da", "jb", "ja")}
    pairs = []
    for B in BLOCKS:
        pair = []
        for half in (0, 1):
            use = (np.arange(len(mag)) // B) % 2 == half
            cal = calibrate_mag(mag, acc, settings=MagSettings(window=WINDOW), raw_unit="gauss", use=use)
            pair.append(cal)
            F = cal.params["F"].value
            h = cal.apply(mag)
            n_imu = 100 * _rms((np.linalg.norm(h[~use], axis=1) - F) / F)
            sym_p = np.array(cal.symmetric.params.values(), float)
            h_sym = np.asarray(vectorized(cal.symmetric.model, "field")(mag.T, sym_p)[0]).T
            w = _held_out_windows(mag, acc, s_full, use)
            a_w = w.means(acc)
            d_sym = np.degrees(np.std(dip_angles(a_w, w.means(h_sym))))
            d_al = np.degrees(np.std(dip_angles(a_w, w.means(h))))
            s, A = algebraic_ellipsoid(mag[use])
            hi = (mag - s) @ A.T
            n_ind = 100 * _rms(np.linalg.norm(hi[~use], axis=1) - 1.0)
            wt = ev.quiet_windows(mag - s_full, WINDOW)
            wt = wt.subset(wt.inside(use))
            x = dip_alignment(wt.means(acc), wt.means(hi))
            Rm = Rotation.from_rotvec(x[:3]).as_matrix()
            j_b = np.degrees(np.std(dip_angles(a_w, w.means(hi))))
            j_a = np.degrees(np.std(dip_angles(a_w, w.means(hi) @ Rm.T)))
            L.append(f"| {B} | {'even' if half == 0 else 'odd'} | {n_imu:.3f} | {n_ind:.3f} | {d_sym:.3f} / {d_al:.3f} "
                     f"| {j_b:.3f} / {j_a:.3f} | {math.degrees(cal.misalignment):.2f} / "
                     f"{math.degrees(np.linalg.norm(x[:3])):.2f} |")
            for k, v in zip(agg, (n_imu, n_ind, d_sym, d_al, j_b, j_a)):
                agg[k].append(v)
        pairs.append((B, pair))
    m = {k: float(np.mean(v)) for k, v in agg.items()}
    L += [f"| mean | | **{m['in']:.3f}** | {m['ii']:.3f} | {m['ds']:.3f} / **{m['da']:.3f}** | {m['jb']:.3f} / "
          f"{m['ja']:.3f} | |", "",
          f"Range over the {2 * len(BLOCKS)} splits: imucal's field-norm residual {min(agg['in']):.3f} to "
          f"{max(agg['in']):.3f} % (the independent fit {min(agg['ii']):.3f} to {max(agg['ii']):.3f} %), imucal's "
          f"aligned dip scatter {min(agg['da']):.3f} to {max(agg['da']):.3f} deg (the independent "
          f"{min(agg['ja']):.3f} to {max(agg['ja']):.3f} deg). The issue's reference: 1.33-1.46 % and "
          "0.94-0.99 deg after a 1.1 deg alignment.", "",
          "<!-- begin:headline -->",
          f"Fit on half of the log and judged on the other ({2 * len(BLOCKS)} splits): field-norm residual "
          f"{m['in']:.2f} % of the field (an independent ellipsoid fit on the same splits: {m['ii']:.2f} %), dip "
          f"scatter {m['da']:.2f} deg after alignment ({m['ds']:.2f} deg with the symmetric soft iron alone; the "
          f"independent fit: {m['ja']:.2f} deg).",
          "<!-- end:headline -->", "", *half_consistency(pairs)]
    return L


def half_consistency(pairs) -> list[str]:
    """The two halves' values against their standard errors: z = (even - odd) / sqrt(std_e^2 + std_o^2)."""
    names = pairs[0][1][0].fit.free_names
    L = ["Do the standard errors hold on real data? The two halves are independent fits of one sensor, so "
         "z = (even - odd) / sqrt(std_even^2 + std_odd^2) should scatter like a standard normal:", "",
         "| B | " + " | ".join(names) + " |", "|---|" + "---|" * len(names)]
    allz = []
    for B, (e, o) in pairs:
        z = [(e.params[n].value - o.params[n].value) / math.hypot(e.fit.std[n], o.fit.std[n]) for n in names]
        allz += z
        L.append(f"| {B} | " + " | ".join(f"{v:+.1f}" for v in z) + " |")
    L += ["", f"RMS of z over all: {_rms(allz):.2f}. The standard errors include the batch-means inflation of "
          "residuals that move together in time (imucal.mag.fit.batch_inflation: on this log the field-norm "
          "residual's autocorrelation is 0.49 at 25 samples and vanishes by 500).", ""]
    return L


def lag_section(mag: np.ndarray, acc: np.ndarray, cal) -> list[str]:
    p = np.array(cal.params.values(), float)
    L = ["## 4. The lag", "",
         "The whole-log calibration applied to the magnetometer shifted by k samples (k > 0: the magnetometer "
         "taken k samples later, as if it lagged), the dip scatter over the same windows:", "",
         "| k | " + " | ".join(str(k) for k in range(-3, 4)) + " |", "|---|" + "---|" * 7]
    w = cal.poses
    vals = []
    for k in range(-3, 4):
        h = np.asarray(vectorized(cal.fit.model, "field")(ev.shift(mag, float(k)).T, p)[0]).T
        vals.append(np.degrees(np.std(dip_angles(w.means(acc), w.means(h)))))
    L += ["| dip scatter [deg] | " + " | ".join(f"{v:.3f}" for v in vals) + " |", "",
          f"The least scatter is at k = {int(np.argmin(vals)) - 3}: the magnetometer does not lag the accelerometer "
          "by a whole sample on this log (tests/test_mag_calibrate.py shows a 4-sample lag found and taken out on a "
          "simulated one).", ""]
    return L


def monte_carlo(seeds: int) -> list[str]:
    truth = truth_from_soft_iron(SOFT, axes=AK8963, misalignment=np.radians(MISALIGNMENT_DEG))
    v = truth.values()
    Z, found = [], 0
    for seed in range(seeds):
        sim = simulate_mag(truth, n_poses=20, hold=60, transition=30, seed=1000 + seed)
        cal = calibrate_mag(sim.mag, sim.acc, still=sim.holds, settings=MagSettings(field=truth.field))
        found += cal.axes.best.axes == AK8963
        Z.append([(cal.params[n].value - v[n]) / cal.fit.std[n] for n in cal.fit.free_names])
    Z = np.array(Z)
    names = cal.fit.free_names
    L = ["## 5. Monte-Carlo", "",
         f"{seeds} simulated logs (`imucal.mag.simulate`): 20 random still poses of 60 samples, 30-sample turns, "
         "white noise 0.002 on a field of 0.5 (0.4 %) and 0.02 g on the accelerometer; a symmetric soft iron of a "
         f"few per cent, hard iron (0.2, -0.1, 0.05), the AK8963 mounting (mx = ay, my = ax, mz = -az) and a "
         f"further rotation of {MISALIGNMENT_DEG} deg; F given. The mounting was found in {found} of {seeds}. "
         "z = (value - truth) / reported standard error:", "",
         "| parameter | " + " | ".join(names) + " |", "|---|" + "---|" * len(names),
         "| std of z | " + " | ".join(f"{x:.2f}" for x in Z.std(axis=0)) + " |",
         "| mean of z | " + " | ".join(f"{x:+.2f}" for x in Z.mean(axis=0)) + " |", "",
         f"Pooled mean of z^2: {np.mean(Z**2):.3f} (1 when the standard errors are those of the estimates; the "
         "DIP rows' variance component is estimated from about 20 poses, so z follows Student's t and its "
         "variance is a little above 1). tests/test_mag_calibrate.py repeats this with 12 seeds.", ""]
    return L


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=100)
    args = ap.parse_args()
    t0 = time.perf_counter()
    mag, acc = load_log()
    acc_lines, acc = accelerometer_section(acc, mag)
    whole, cal = whole_log(mag, acc)
    s_full = np.array([cal.params[f"s{i}"].value for i in (1, 2, 3)])
    text = ["# The magnetometer study", "",
            f"Generated by `python studies/mag_study.py --seeds {args.seeds}` ({{T}} s on this machine). The model "
            "and its choices: docs/magnetometer.md.", "",
            "The data: `../shared/data/real/magnetometer-ckexplorer` (CK-Explorer, Apache-2.0): `acc_mag_log.csv`, "
            "12,000 rows of ax, ay, az [g] and mx, my, mz [gauss], the board turned by hand through many "
            "orientations and never still for long; no time column and no stated rate.", "",
            *acc_lines, *whole, *cross_validation(mag, acc, s_full), *lag_section(mag, acc, cal),
            *monte_carlo(args.seeds)]
    out = "\n".join(text).replace("{T}", f"{time.perf_counter() - t0:.0f}")
    write_text_atomic(ROOT / "studies" / "results" / "magnetometer_study.md", out)
    print(out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
