#!/usr/bin/env python3
"""Time of the gyro calibration on the Xsens MTi recording beside imu_tk's full run (issue 11).

Cases, wall time (median of --runs) and CPU time of whole processes:
  imu_tk     imu_tk's test program on xsens_acc.mat + xsens_gyro.mat (accelerometer and gyroscope,
             as it publishes them); built by scripts/build_imutk.sh, given with --imutk
  imucal     `imucal calibrate --data ACC --gyro-data GYRO --no-figures --quiet` (both sensors)
  imucal-acc the same without the gyroscope
and, in one process, the parts of imucal's gyro fit: first call (builds the NLP for this shape),
later calls (solver cached), without and with g-sensitivity, and the 1-D search for the nominal
scale that raw counts need (imu_tk is given its nominal scale, 1/6258, in its test program).
Then the check that the fast segment path (imucal/gyro/attitude.py) finds the optimum of the NLP
it replaced: imu_tk's RK4 steps chained in one CasADi graph, IPOPT with the exact Hessian, same
nominal scale, weights and data; and that the pruned scale search returns the grid's argmin.
Writes docs/benchmarks_gyro.md.

    sh scripts/build_imutk.sh IMU_TK_SOURCE /tmp/imutk && python scripts/bench_gyro.py --imutk /tmp/imutk/test_imu_calib
    python scripts/bench_gyro.py            # imucal only
"""
from __future__ import annotations

import argparse
import os
import platform
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import casadi as ca
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from imucal.config.run import load_config  # noqa: E402
from imucal.files.output import write_text_atomic  # noqa: E402
from imucal.gyro import GyroOptions, fit_gyro  # noqa: E402
from imucal.gyro import attitude  # noqa: E402
from imucal.gyro.fit import _grid_argmin, _search_scale, _segment_sigma, _steps  # noqa: E402
from imucal.gyro.gsens import fit_static  # noqa: E402
from imucal.gyro.result import arrays  # noqa: E402
from imucal.model.gyroscope import gyro_model, gyro_parameters, misalignment_entries  # noqa: E402
from imucal.gyro.segments import motion_segments  # noqa: E402
from imucal.gyro.run import gyro_data  # noqa: E402
from imucal.pipeline import calibrate_accelerometer  # noqa: E402

DATA = ROOT / "data" / "xsens-mti-imutk"
ACC, GYRO = DATA / "xsens_acc.mat", DATA / "xsens_gyro.mat"
OUT = ROOT / "docs" / "benchmarks_gyro.md"


def timed_process(cmd: list[str], runs: int, cwd: str, env: dict | None = None) -> dict:
    """Median and min wall time, mean user+system CPU of ``runs`` runs of ``cmd``."""
    wall, cpu = [], []
    for _ in range(runs):
        r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        p = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True)
        wall.append(time.perf_counter() - t0)
        r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        if p.returncode != 0:
            raise SystemExit(f"{cmd[0]} failed ({p.returncode}): {p.stderr.strip()[-400:]}")
        cpu.append(r1.ru_utime - r0.ru_utime + r1.ru_stime - r0.ru_stime)
    return {"median": statistics.median(wall), "min": min(wall), "cpu": statistics.mean(cpu), "runs": runs}


def imucal_cmd(out: str, gyro: bool) -> list[str]:
    cmd = [sys.executable, "-m", "imucal", "calibrate", "--data", str(ACC), "--gravity", "9.81744", "--out", out,
           "--no-figures", "--quiet"]
    return cmd + (["--gyro-data", str(GYRO)] if gyro else [])


def _timed_fit(data, options: GyroOptions) -> tuple[float, float]:
    c0, t0 = time.process_time(), time.perf_counter()
    fit_gyro(data, options)
    return time.perf_counter() - t0, time.process_time() - c0


def parts(runs: int) -> list[tuple[str, float, float]]:
    """In-process wall and CPU times [s] of the gyro fit's parts (median of ``runs``)."""
    run = calibrate_accelerometer(load_config(ROOT / "configs" / "xsens-mti-imutk.yaml"))
    data, _ = gyro_data(run, str(GYRO))
    out = []
    med = (lambda v: tuple(statistics.median(c) for c in zip(*v)))
    for gs in ("off", "auto"):
        attitude._generated.cache_clear()
        out.append((f"fit_gyro, g-sensitivity {gs}, first call (generates the numpy evaluators)",
                    *_timed_fit(data, GyroOptions(gsens=gs))))
        out.append((f"fit_gyro, g-sensitivity {gs}, later calls",
                    *med([_timed_fit(data, GyroOptions(gsens=gs)) for _ in range(runs)])))
    scale = arrays(fit_gyro(data, GyroOptions(gsens="auto"))).scale.mean()
    given = med([_timed_fit(data, GyroOptions(gsens="auto", nominal_scale=float(scale))) for _ in range(runs)])
    out.append(("fit_gyro, g-sensitivity auto, later calls, nominal scale given (no search, as imu_tk)", *given))
    return out


def same_optimum(data) -> list[str]:
    """Our fit against the chained-graph NLP with IPOPT's exact Hessian (markdown lines)."""
    res = fit_gyro(data, GyroOptions(gsens="auto"))
    gm, _, am, _ = data.static_means()
    st = fit_static(gm, am, "auto")
    seg = motion_segments(data)
    steps = _steps(data, seg)
    model = gyro_model()
    start = gyro_parameters(data.unit, st.bias, np.ones(3), gsens=st.H)
    free = start.free_names  # scale_x..z, then the six entries of M_g
    scale0 = np.full(3, _search_scale(steps, start))
    coarse = 10.0 ** np.arange(-2, 6.01, 0.1)
    xs, rv = attitude.chained_graph(data.t, seg, data.gyro, data.acc, model, free, np.array(start.values()))
    cost = ca.Function("cost", [xs], [ca.sumsqr(rv)])  # every scale at the grid's k, M_g = I
    grid_cost = [float(cost(np.r_[np.full(3, k), np.zeros(6)])) for k in coarse]
    params = gyro_parameters(data.unit, st.bias, scale0, gsens=st.H)
    xs, rv = attitude.chained_graph(data.t, seg, data.gyro, data.acc, model, free, np.array(params.values()))
    w = np.repeat(1.0 / _segment_sigma(data, seg, scale0), 3)
    d = np.array([params[n].scale for n in free])
    p0 = np.array([params[n].value for n in free])
    x = ca.MX.sym("x", len(free))
    solver = ca.nlpsol("chained", "ipopt", {"x": x, "f": 0.5 * ca.sumsqr(ca.substitute(rv, xs, p0 + d * x) * ca.DM(w))},
                       {"ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes", "ipopt.tol": 1e-12})
    ref = p0 + d * np.asarray(solver(x0=np.zeros(len(free)))["x"]).ravel()
    ours = np.r_[arrays(res).scale, misalignment_entries(arrays(res).misalignment)]
    sd = np.r_[arrays(res).scale_std, misalignment_entries(arrays(res).misalignment_std)]
    names = ["scale_x", "scale_y", "scale_z", "m_xy", "m_xz", "m_yx", "m_yz", "m_zx", "m_zy"]
    L = ["## Same optimum as the exact-Hessian NLP it replaced", "",
         "Xsens recording, g-sensitivity auto: our fit (products of RK4 increments, Gauss-Newton Hessian) and "
         "imu_tk's normalised RK4 steps chained in one CasADi graph solved by IPOPT with its exact Hessian "
         f"(tol 1e-12, status {solver.stats()['return_status']}), same nominal scale {scale0[0]:.6g}, weights and data.", "",
         "| parameter | ours | chained graph, exact Hessian | relative difference | difference / standard error |",
         "|---|---|---|---|---|"]
    for n, a, b, s in zip(names, ours, ref, sd):
        L.append(f"| {n} | {a:.10g} | {b:.10g} | {abs(a - b) / max(abs(b), 1e-300):.1e} | {abs(a - b) / s:.1e} |")
    pruned = _grid_argmin(steps, start, coarse)
    L += ["", f"Coarse scale grid (81 points, 10^-2 to 10^6): pruned search {pruned:.6g}, argmin of the chained "
          f"graph's cost at every point {coarse[int(np.argmin(grid_cost))]:.6g}."]
    return L


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--imutk", help="imu_tk's test_imu_calib built by scripts/build_imutk.sh")
    ap.add_argument("--runs", type=int, default=10)
    a = ap.parse_args()
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    load = os.getloadavg()[0]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        if a.imutk:
            rows.append(("imu_tk test_imu_calib (accelerometer + gyroscope, C++/Ceres)",
                         timed_process([str(Path(a.imutk).resolve()), str(ACC), str(GYRO)], a.runs, tmp)))
        rows.append(("`imucal calibrate --gyro-data` (accelerometer + gyroscope)",
                     timed_process(imucal_cmd(str(Path(tmp) / "o1"), True), a.runs, tmp, env)))
        rows.append(("`imucal calibrate` (accelerometer only)",
                     timed_process(imucal_cmd(str(Path(tmp) / "o2"), False), a.runs, tmp, env)))
        rows.append(("floor: `python -c 'import numpy, casadi'`",
                     timed_process([sys.executable, "-c", "import numpy, casadi"], a.runs, tmp, env)))
    inproc = parts(a.runs)
    import casadi

    L = ["# Gyroscope calibration: time on the Xsens MTi recording", "",
         f"Generated by `python scripts/bench_gyro.py{' --imutk ...' if a.imutk else ''}` on {platform.processor() or platform.machine()}, "
         f"{os.cpu_count()} cores, Python {platform.python_version()}, casadi {casadi.__version__}, numpy {np.__version__}; "
         f"load average {load:.2f} at the start (a shared machine: wall times carry other jobs' noise). Do not edit by hand.",
         "", "Recording: 51,175 samples at 100 Hz, 38 static intervals, 37 motion segments (our detection).", "",
         "## Whole processes", "", "<!-- begin:summary -->",
         "| what | runs | median wall [s] | min wall [s] | CPU (user + system) [s] |", "|---|---|---|---|---|"]
    for name, r in rows:
        L.append(f"| {name} | {r['runs']} | {r['median']:.3f} | {r['min']:.3f} | {r['cpu']:.3f} |")
    if not a.imutk:
        L += ["", "imu_tk not timed: give its test program with --imutk (scripts/build_imutk.sh builds it)."]
    L += ["<!-- end:summary -->"]
    L += ["", "## Parts of imucal's gyro fit (one process, medians)", "", "| what | wall [s] | CPU [s] |",
          "|---|---|---|"]
    L += [f"| {name} | {t:.3f} | {c:.3f} |" for name, t, c in inproc]
    acc_run = calibrate_accelerometer(load_config(ROOT / "configs" / "xsens-mti-imutk.yaml"))
    L += [""] + same_optimum(gyro_data(acc_run, str(GYRO))[0])
    text = "\n".join(L)
    write_text_atomic(OUT, text + "\n")
    print(text)


if __name__ == "__main__":
    main()
