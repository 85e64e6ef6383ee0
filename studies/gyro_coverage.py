#!/usr/bin/env python3
"""Monte-Carlo coverage of the gyro fit's standard errors (issue 11, "must show").

For each setting, simulate hand-held sessions of one sensor (imucal.gyro.simulate.hand_held:
turns of 60-180 deg about random axes with tremor and hand translation, random timing, known
bias, scale, misalignment, g-sensitivity and white noise), fit each exactly as `imucal
calibrate` does (imucal.gyro.fit_gyro, g-sensitivity selected by its test), and count how often
|estimate - truth| / reported std < 1.96. Honest standard errors give 95 %, within the two-sided
binomial band (level 0.05) of the number of estimates. Writes studies/results/gyro_coverage.md.

    python studies/gyro_coverage.py              # 50 seeds per setting, about 3 min on 2 cores
    python studies/gyro_coverage.py --seeds 10   # quick look (does not write the doc)
"""
from __future__ import annotations

import argparse
import multiprocessing as mp
import platform
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from imucal.files.output import write_text_atomic  # noqa: E402
from imucal.report.progress import progress  # noqa: E402
from imucal.gyro import GyroOptions  # noqa: E402
from imucal.gyro.coverage import Z95, Coverage, binomial_band, monte_carlo, names  # noqa: E402
from imucal.gyro.simulate import GyroTruth  # noqa: E402
from imucal.report.text import t_quantile_975  # noqa: E402

OUT = ROOT / "studies" / "results" / "gyro_coverage.md"
G_S = np.array([[0.0, 2e-4, -1e-4], [3e-4, 0.0, 1e-4], [-2e-4, 1e-4, 0.0]])  # (rad/s) per (m/s^2)
MIS = np.array([0.01, -0.02, 0.015, 0.03, -0.025, 0.02])
#: a factory-scaled MEMS gyro in rad/s; 2 mrad/s per 100 Hz sample = 0.011 deg/s/sqrt(Hz)
MEMS = GyroTruth(np.array([0.01, -0.02, 0.005]), np.array([1.01, 0.99, 1.005]), MIS, G_S, noise=2e-3)
#: the Xsens MTi of imu_tk's test data, in raw counts (nominal scale found by the fit's search)
COUNTS = GyroTruth(np.array([32768.0, 32450.0, 32510.0]), np.array([4780.0, 4760.0, 4770.0]), MIS, G_S, noise=3.0)

SETTINGS = [
    ("24 poses, rad/s, g-sensitivity present", MEMS, dict(unit="rad/s", n_poses=24)),
    ("12 poses (22 residual dof), rad/s, g-sensitivity present", MEMS, dict(unit="rad/s", n_poses=12)),
    ("24 poses, rad/s, no g-sensitivity (test should keep none)",
     GyroTruth(MEMS.bias, MEMS.scale, MIS, np.zeros((3, 3)), MEMS.noise), dict(unit="rad/s", n_poses=24)),
    ("24 poses, raw counts (Xsens-like, nominal scale searched)", COUNTS, dict(unit="raw", n_poses=24)),
]


def _run(args: tuple) -> Coverage:
    truth, seeds, session = args
    return monte_carlo(truth, seeds, GyroOptions(gsens="auto"), **session)


def study(truth: GyroTruth, session: dict, n: int, jobs: int) -> Coverage:
    chunks = [range(i, n, jobs) for i in range(jobs)]
    if jobs == 1:
        return _run((truth, chunks[0], session))
    with mp.get_context("spawn").Pool(jobs) as pool:
        return Coverage.merge(pool.map(_run, [(truth, c, session) for c in chunks]))


def pooled(cov: Coverage) -> tuple[float, float, int, float, float]:
    """Fractions inside 1.96 and inside Student-t over every estimate of a setting, their number, the binomial band."""
    ok = {g: np.isfinite(v) for g, v in cov.z.items()}
    z = np.abs(np.concatenate([cov.z[g][ok[g]] for g in ok]))
    q = np.concatenate([cov.t[g][ok[g]] for g in ok])
    lo, hi = binomial_band(z.size)
    return float(np.mean(z < Z95)), float(np.mean(z < q)), int(z.size), lo, hi


def section(title: str, cov: Coverage, n: int, seconds: float) -> list[str]:
    L = [f"## {title}", "",
         f"{n} sessions, {cov.converged} converged; median reduced chi-square {np.median(cov.redchi):.3f}; "
         f"G_s rows kept by the test (x, y, z): {', '.join(str(int(v)) for v in cov.gsens_rows_selected)} of {n}; "
         f"{seconds:.0f} s.", "",
         "| parameters | estimates | inside ±1.96 std | inside ±t(dof) std | binomial band (95 %) | sd of error/std "
         "| verdict (Student-t) |", "|---|---|---|---|---|---|---|"]
    for g in names():
        frac, k = cov.fraction(g)
        if k == 0:
            L.append(f"| {g} | 0 | | | | | not estimated |")
            continue
        ft, _ = cov.fraction(g, student=True)
        lo, hi = binomial_band(k)
        z = cov.z[g][np.isfinite(cov.z[g])]
        L.append(f"| {g} | {k} | {frac:.3f} | {ft:.3f} | {lo:.3f} - {hi:.3f} | {np.std(z):.2f} | "
                 f"{'ok' if lo <= ft <= hi else 'OUTSIDE'} |")
    frac, ft, k, lo, hi = pooled(cov)
    allz = np.concatenate([v[np.isfinite(v)] for v in cov.z.values()])
    L.append(f"| **all** | {k} | **{frac:.3f}** | **{ft:.3f}** | {lo:.3f} - {hi:.3f} | {np.std(allz):.2f} | "
             f"{'ok' if lo <= ft <= hi else 'OUTSIDE'} |")
    per = []
    for g, ns in names().items():
        for j, name in enumerate(ns):
            col = cov.z[g][:, j] if cov.z[g].size else np.array([])
            col = col[np.isfinite(col)]
            if col.size:
                per.append(f"{name} {np.mean(np.abs(col) < Z95):.2f}")
    L += ["", "Per parameter (fraction inside): " + ", ".join(per) + ".", ""]
    return L


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=50, help="sessions per setting (default 50)")
    ap.add_argument("--jobs", type=int, default=min(2, mp.cpu_count()), help="processes (default 2)")
    a = ap.parse_args()
    L = ["# Gyro fit: Monte-Carlo coverage of the reported standard errors", "",
         f"Generated by `python studies/gyro_coverage.py` ({a.seeds} seeds per setting; Python "
         f"{platform.python_version()}); do not edit by hand.", "",
         "Each session: a random start attitude, then turns of 60-180 deg about random axes over 1-2 s (rate",
         "profile 1 - cos, plus a tremor of three 0.5-3 Hz sinusoids of 0.15 rad/s about random axes and a hand",
         "translation of about 1 m/s^2), still poses of 1.5-3 s; accelerometer white noise 0.02 m/s^2 per sample,",
         "100 Hz. Truth: bias, scale 0.5-1 % off, misalignment 1-3 %, G_s up to 3e-4 (rad/s)/(m/s^2), white",
         "gyro noise (2 mrad/s per sample in rad/s; 3 counts in raw counts). The fit is `imucal calibrate`'s:",
         "bias and G_s from the static means (G_s kept per axis by the likelihood-ratio test), scale and",
         "misalignment from the rotation NLP, standard errors scaled by the reduced chi-square.",
         "Since the standard errors are estimated from the residual scatter, the exact 95 % bound is Student-t's",
         "with the fit's dof (static intervals - 4 for bias with a G_s row, - 1 for bias alone; the rotation fit's",
         f"dof for scale and misalignment), not 1.96 (20 dof: {t_quantile_975(20):.3f}).",
         "Estimates pooled over sessions and parameters of a group are correlated within a session, so the",
         "binomial band is a guide, not an exact test. A G_s row counts only in the sessions that kept it.", ""]
    body, summ = [], ["<!-- begin:summary -->",
                      "| setting | sessions | estimates | inside ±1.96 std | inside ±t(dof) std | binomial band (95 %) "
                      "| median reduced chi-square |", "|---|---|---|---|---|---|---|"]
    with progress("settings", total=len(SETTINGS), unit="setting", delay=0) as step:
        for title, truth, session in SETTINGS:
            t0 = time.perf_counter()
            cov = study(truth, session, a.seeds, a.jobs)
            step()
            body += section(title, cov, a.seeds, time.perf_counter() - t0)
            frac, ft, k, lo, hi = pooled(cov)
            summ.append(f"| {title} | {a.seeds} | {k} | {frac:.3f} | {ft:.3f} | {lo:.3f} - {hi:.3f} "
                        f"| {np.median(cov.redchi):.2f} |")
            print(summ[-1], flush=True)
    L += ["## Summary", ""] + summ + ["<!-- end:summary -->", ""] + body
    if a.seeds >= 40:
        write_text_atomic(OUT, "\n".join(L) + "\n")
    print("\n".join(L))


if __name__ == "__main__":
    main()
