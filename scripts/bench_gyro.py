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

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from imucal.config.run import load_config  # noqa: E402
from imucal.files.output import write_text_atomic  # noqa: E402
from imucal.gyro import GyroOptions, fit_gyro  # noqa: E402
from imucal.gyro.fit import _problem  # noqa: E402
from imucal.gyro.run import gyro_data  # noqa: E402
from imucal.pipeline import calibrate  # noqa: E402

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


def parts(runs: int) -> list[tuple[str, float]]:
    """In-process times [s] of the gyro fit's parts (median of ``runs``)."""
    run = calibrate(load_config(ROOT / "configs" / "xsens-mti-imutk.yaml"))
    data, _ = gyro_data(run, str(GYRO))
    out = []
    for gs in ("off", "auto"):
        _problem.cache_clear()
        t0 = time.perf_counter()
        fit_gyro(data, GyroOptions(gsens=gs))
        out.append((f"fit_gyro, g-sensitivity {gs}, first call (builds the NLP)", time.perf_counter() - t0))
        warm = [fit_gyro(data, GyroOptions(gsens=gs)).seconds for _ in range(runs)]
        out.append((f"fit_gyro, g-sensitivity {gs}, solver cached", statistics.median(warm)))
    scale = fit_gyro(data, GyroOptions(gsens="auto")).scale.mean()
    given = [fit_gyro(data, GyroOptions(gsens="auto", nominal_scale=float(scale))).seconds for _ in range(runs)]
    out.append(("fit_gyro, g-sensitivity auto, solver cached, nominal scale given (no search, as imu_tk)",
                statistics.median(given)))
    return out


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
    L += ["", "## Parts of imucal's gyro fit (one process, median wall time)", "", "| what | [s] |", "|---|---|"]
    L += [f"| {name} | {t:.3f} |" for name, t in inproc]
    text = "\n".join(L)
    write_text_atomic(OUT, text + "\n")
    print(text)


if __name__ == "__main__":
    main()
