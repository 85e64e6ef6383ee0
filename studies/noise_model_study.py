#!/usr/bin/env python
"""Monte-Carlo: interval means weighted by their own scatter vs by a measured noise model (issue 14).

For each setting (hold length, noise kind) one long still log of the sensor is simulated and
characterised with `imucal noise --json` (the noise model, measured once per sensor as a user
would); then many multi-pose recordings are simulated and calibrated twice by the pipeline
(`imucal.api.calibrate`, weights "noise"): with each interval's scatter (the default) and with
``noise=`` that file. Reported: coverage of the 95 % intervals (Student-t, dof = n - 9) pooled
over the nine parameters and the worst parameter, the mean reduced chi-square, the RMS of
z = (estimate - truth) / reported std, and the RMS error relative to the scatter-weighted fit.

Noise kinds: white (0.01 m/s^2 per sample at 100 Hz) and AR(1) low-pass noise (coefficient 0.8,
as a sensor's digital low-pass filter makes it; the same per-sample std), where an interval's
scatter over sqrt(n) underestimates the noise of its mean and the batch-means factor is
estimated from few samples.

    python studies/noise_model_study.py --n 200 --jobs 2     # writes docs/noise_model.md
"""
from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import resource
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from imucal.analysis.simulate import PosePlan, cube_directions, si_sensor, simulate  # noqa: E402
from imucal.api import calibrate  # noqa: E402
from imucal.config.run import config_from_dict  # noqa: E402
from imucal.model.parameters import BASE_NAMES  # noqa: E402
from imucal.report.text import t_quantile_975  # noqa: E402

RATE = 100.0  # Hz
SIGMA = 0.01  # per-sample noise std [raw]
AR = 0.8  # AR(1) coefficient of the low-pass noise
STILL_S = 600.0  # the still log characterised by `imucal noise` [s]
SETTINGS = [(4.0, "white"), (1.0, "white"), (0.6, "white"), (4.0, "ar1"), (1.0, "ar1"), (0.6, "ar1")]


def noise(kind: str, n: int, rng: np.random.Generator) -> np.ndarray:
    """(n, 3) noise of per-sample std SIGMA: white, or AR(1) with coefficient AR."""
    e = rng.normal(0.0, SIGMA, (n, 3))
    if kind == "white":
        return e
    e *= np.sqrt(1 - AR**2)
    out = np.empty_like(e)
    out[0] = e[0] / np.sqrt(1 - AR**2)
    for k in range(1, n):
        out[k] = AR * out[k - 1] + e[k]
    return out


def sensor():
    return replace(si_sensor(np.random.default_rng(101)), noise=(0.0, 0.0, 0.0), unit="raw")


def noise_file(kind: str, folder: Path) -> Path:
    """`imucal noise --json` on a simulated still log of this noise (the sensor lying flat)."""
    rng = np.random.default_rng(7)
    sim = simulate(sensor(), PosePlan(directions=np.array([[0.0, 0.0, 1.0]]), hold=STILL_S, rate=RATE), seed=7)
    raw = sim.raw + noise(kind, sim.raw.shape[0], rng)
    csv, out = folder / f"still_{kind}.csv", folder / f"noise_{kind}.json"
    np.savetxt(csv, np.column_stack([sim.t, raw]), delimiter=",", header="t,ax,ay,az", comments="")
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    subprocess.run([sys.executable, "-m", "imucal", "noise", "--data", str(csv), "--json", str(out)],
                   check=True, env=env, stdout=subprocess.DEVNULL)
    return out


def one(args: tuple) -> dict:
    """Both fits of one simulated recording: z-scores, coverage flags, reduced chi-square."""
    hold, kind, seed, nfile = args
    s = sensor()
    plan = PosePlan(directions=cube_directions("faces+edges"), hold=hold, transition=1.5, rate=RATE)
    sim = simulate(s, plan, seed=seed)
    raw = sim.raw + noise(kind, sim.raw.shape[0], np.random.default_rng(seed + 10**6))
    truth = dict(zip(BASE_NAMES, [*s.s, *s.b, *s.angles]))
    base = config_from_dict({"data": {"path": "<sim>", "unit": "raw"},
                             "static": {"window": 0.2, "min_duration": 0.3, "trim": 0.05}})
    out = {}
    for how, nf in (("scatter", None), ("model", nfile)):
        run = calibrate(raw, t=sim.t, weights="noise", noise=nf, config=base)
        r = run.result
        q = t_quantile_975(r.dof)
        err = np.array([r.params[n].value - truth[n] for n in BASE_NAMES])
        sd = np.array([r.std[n] for n in BASE_NAMES])
        out[how] = {"err": err.tolist(), "z": (err / sd).tolist(), "cover": (np.abs(err) <= q * sd).tolist(),
                    "redchi": r.redchi, "n_samples": float(np.mean(run.intervals.n_samples))}
    return out


def summarise(rows: list[dict], how: str) -> dict:
    z = np.array([r[how]["z"] for r in rows])
    cov = np.array([r[how]["cover"] for r in rows], float)
    err = np.array([r[how]["err"] for r in rows])
    err0 = np.array([r["scatter"]["err"] for r in rows])
    return {"coverage": 100 * cov.mean(), "worst": 100 * cov.mean(axis=0).min(),
            "redchi": float(np.mean([r[how]["redchi"] for r in rows])), "rms_z": float(np.sqrt(np.mean(z**2))),
            "rms_err_ratio": float(np.mean(np.sqrt(np.mean(err**2, axis=0)) / np.sqrt(np.mean(err0**2, axis=0)))),
            "n_samples": float(np.mean([r[how]["n_samples"] for r in rows]))}


def page(results: list[tuple], cmd: str, wall: float, cpu: float, noise_json: dict) -> str:
    L = ["# Noise model: interval means weighted by a measured noise density", "",
         f"Generated by `{cmd}` ({wall:.0f} s wall, {cpu:.0f} s CPU of this process and its workers, load "
         f"average {os.getloadavg()[0]:.1f} at the end). Do not edit by hand.", "",
         "`imucal calibrate --noise FILE` (or `fit.noise: FILE`) takes the JSON `imucal noise --json` writes (or a "
         "Kalibr imu.yaml) and sets each interval mean's noise to N sqrt(fs / n) per axis (N the white-noise "
         "density, n the interval's samples), plus the bias-instability floor when the Allan curve shows one "
         "(`imucal/analysis/noise_model.py`), instead of the interval's own scatter over sqrt(n) times the "
         "pooled batch-means factor (`imucal/data/static.py`).", "",
         f"Simulated: 18 poses (cube faces and edges), {RATE:g} Hz, per-sample noise std {SIGMA:g} raw, white or "
         f"AR(1) low-pass (coefficient {AR:g}); static detection with window 0.2 s, min_duration 0.3 s, trim 0.05 s; "
         "weights \"noise\" for both fits. The noise file comes from `imucal noise` on a simulated "
         f"{STILL_S:g} s still log of the same noise:", ""]
    for kind, d in noise_json.items():
        dens = ", ".join(f"{d['axes'][a]['white_density']:.4g}" for a in "xyz")
        true = SIGMA / np.sqrt(RATE) * (1.0 if kind == "white" else np.sqrt((1 + AR) / (1 - AR)))
        L.append(f"* {kind}: white density x, y, z = {dens} raw/sqrt(Hz) (true {true:.4g})")
    L += ["", "| hold [s] | noise | samples per interval | weights from | 95 % coverage, pooled [%] "
          "| worst parameter [%] | mean reduced chi-square | RMS z | RMS error / scatter's |",
          "|---|---|---|---|---|---|---|---|---|"]
    for hold, kind, n, summ in results:
        for how in ("scatter", "model"):
            s = summ[how]
            src = "own scatter" if how == "scatter" else "noise file"
            L.append(f"| {hold:g} | {kind} | {s['n_samples']:.0f} | {src} "
                     f"| {s['coverage']:.1f} | {s['worst']:.1f} | {s['redchi']:.3f} | {s['rms_z']:.3f} | "
                     f"{s['rms_err_ratio']:.3f} |")
    n = results[0][2]
    L += ["", f"{n} recordings per row; a pooled coverage is known to about "
          f"+-{100 * 1.96 * np.sqrt(0.05 * 0.95 / (9 * n)):.1f} points (95 %, if the nine were independent), "
          f"one parameter's to +-{100 * 1.96 * np.sqrt(0.05 * 0.95 / n):.1f}."]
    return "\n".join(L) + "\n"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=200, help="recordings per setting")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out", default=str(ROOT / "studies" / "results" / "noise_model_study.md"))
    a = ap.parse_args()
    t0 = time.perf_counter()
    results, njson = [], {}
    with tempfile.TemporaryDirectory() as tmp, mp.Pool(a.jobs) as pool:
        files = {k: noise_file(k, Path(tmp)) for k in ("white", "ar1")}
        njson = {k: json.loads(f.read_text()) for k, f in files.items()}
        for hold, kind in SETTINGS:
            rows = pool.map(one, [(hold, kind, 1000 + i, str(files[kind])) for i in range(a.n)])
            summ = {h: summarise(rows, h) for h in ("scatter", "model")}
            results.append((hold, kind, a.n, summ))
            print(hold, kind, summ, flush=True)
    wall = time.perf_counter() - t0
    ru = [resource.getrusage(w) for w in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN)]
    cpu = sum(r.ru_utime + r.ru_stime for r in ru)
    cmd = f"python studies/noise_model_study.py --n {a.n} --jobs {a.jobs}"
    Path(a.out).write_text(page(results, cmd, wall, cpu, njson))
    print(f"wrote {a.out} ({wall:.0f} s wall, {cpu:.0f} s CPU)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
