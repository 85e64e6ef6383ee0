#!/usr/bin/env python
"""Fleet throughput on this machine (issues 13 and 30): `imucal batch` on simulated units: units per
second and efficiency on 1, 2 and all cores, and the fixed cost of a batch.

200 units from configs/simulate_fleet.yaml (3 defective, 2 corrupt files) are calibrated with
`imucal batch` (a subprocess each, wall time from start to the report) on local processes with
1 and 2 workers and on a dask.distributed LocalCluster of 2 single-threaded worker processes,
without per-unit figures, and once with them. Checks, on every run: every good unit calibrated,
the corrupt ones refused, the defective ones failed and flagged, the same table on every
executor; every good unit's parameters equal a single-unit run of the library path that
`imucal calibrate` takes; a batch killed (SIGKILL) half way resumes and fits only the rest.
Rewrites the block between <!-- begin:bench --> and <!-- end:bench --> in docs/fleet.md.

    python scripts/bench_fleet.py            # 200 units
    python scripts/bench_fleet.py --units 40 # quicker, for a try (docs/fleet.md not written)
"""
from __future__ import annotations

import argparse
import contextlib
import csv
import os
import platform
import re
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from imucal.analysis.simulate import load_simulation_config  # noqa: E402
from imucal.files.output import write_text_atomic  # noqa: E402
from imucal.fleet.manifest import load_manifest  # noqa: E402
from imucal.fleet.population import draw_fleet, write_fleet  # noqa: E402
from imucal.model.parameters import BASE_NAMES  # noqa: E402
from imucal.pipeline import calibrate_accelerometer  # noqa: E402

VOLATILE = ("seconds", "cpu_seconds", "skipped")


def batch(manifest: Path, out: Path, *extra: str) -> tuple[float, str, float]:
    """(wall time [s], stdout, CPUs busy on the whole machine meanwhile)."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    busy0 = busy_seconds()
    t0 = time.perf_counter()
    r = subprocess.run([sys.executable, "-m", "imucal", "batch", str(manifest), "--out", str(out), "--no-figures",
                        *extra], env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    busy = (busy_seconds() - busy0) / wall
    if r.returncode != 0:
        raise SystemExit(f"batch failed ({r.returncode}): {r.stderr}")
    return wall, r.stdout, busy


def table(out: Path) -> dict[str, dict]:
    with open(out / "fleet.csv", newline="") as f:
        return {r["unit"]: r for r in csv.DictReader(f)}


def check(t: dict[str, dict], truth: dict[str, dict]) -> int:
    """Asserts the verdicts; returns the good units flagged as outliers (false alarms)."""
    alarms = 0
    for uid, tr in truth.items():
        r = t[uid]
        if tr["corrupt"]:
            assert r["status"] == "error" and r["error"], (uid, r)
        elif tr["defect"]:
            assert r["status"] == "ok" and r["verdict"] == "fail" and r["outlier"], (uid, r)
        else:
            assert r["status"] == "ok" and r["verdict"] == "pass", (uid, r)
            alarms += bool(r["outlier"])
    return alarms


def stable(t: dict[str, dict]) -> dict:
    return {u: {k: v for k, v in r.items() if k not in VOLATILE} for u, r in t.items()}


def killed_and_resumed(manifest: Path, out: Path, n: int) -> tuple[int, int]:
    """SIGKILL a 2-worker batch (and its workers) after about half the units; rerun. (done, skipped)."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    p = subprocess.Popen([sys.executable, "-m", "imucal", "batch", str(manifest), "--out", str(out), "--no-figures",
                          "--workers", "2"], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                         start_new_session=True)
    while len(list(out.glob("*/done.json"))) < n // 2:
        time.sleep(0.05)
    os.killpg(p.pid, signal.SIGKILL)  # the batch and its worker processes: a crash, no cleanup
    p.wait()
    time.sleep(0.5)
    done = len(list(out.glob("*/done.json")))
    _, stdout, _ = batch(manifest, out, "--workers", "2")
    skipped = int(re.search(r"\((\d+) skipped", stdout).group(1))
    return done, skipped


def fixed_cost(tmp: Path, cfg, runs: int) -> dict:
    """A batch's fixed cost: the wall time of a one-unit batch on one worker less the unit's own time
    on its worker (hash, fit, files): the command's start, the manifest, the worker's start and the
    fleet report. ``runs`` batches, each into a new folder."""
    manifest = write_fleet(draw_fleet(cfg, 1, 0, 0), tmp / "one", [], settings={"output": {"figures": False}})
    got, walls, busy = [], [], []
    for i in range(runs + 1):
        out = tmp / f"fixed{i}"
        wall, _, b = batch(manifest, out, "--workers", "1")
        unit = next(iter(table(out).values()))
        if i:  # the first warms the file cache
            got.append(wall - float(unit["seconds"]))
            walls.append(wall)
            busy.append(b)
    return {"median": statistics.median(got), "min": min(got), "max": max(got), "wall": statistics.median(walls),
            "runs": runs, "busy": statistics.median(busy)}


def fixed_lines(fixed: dict, one: tuple) -> list[str]:
    label, wall, _, _, _, _, workers, unit_seconds = one
    return [f"Fixed cost of a batch (target under 0.5 s): a one-unit batch on one worker takes "
            f"{fixed['wall']:.2f} s, {fixed['median']:.2f} s of it (median of {fixed['runs']}; "
            f"{fixed['min']:.2f} to {fixed['max']:.2f}) outside the unit's own work, the whole machine's CPUs busy "
            f"{fixed['busy']:.2f} of {os.cpu_count()} meanwhile (median; the batch's own included); "
            f"in the {label} run below, "
            f"{wall - unit_seconds:.1f} s of its {wall:.1f} s were outside the units' work (each unit's wall time on "
            "its worker, summed). The batch's own process never loads the calibration path; its workers are "
            "forked from a forkserver that has loaded it and fitted once (imucal.fleet.warm), started before the "
            "batch loads its own modules; the report's writers (pyarrow, matplotlib) load in a thread while the "
            "units run.",
            ""]


def busy_seconds() -> float:
    """CPU seconds the whole machine has spent busy since boot (/proc/stat), or NaN."""
    try:
        f = [int(x) for x in Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:]]
    except (OSError, ValueError):
        return float("nan")
    idle = f[3] + (f[4] if len(f) > 4 else 0)
    return (sum(f[:8]) - idle) / os.sysconf("SC_CLK_TCK")


def cpu_name() -> str:
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    return platform.processor() or "unknown CPU"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--units", type=int, default=200)
    ap.add_argument("--fixed-runs", type=int, default=5, help="one-unit batches timed for the fixed cost")
    args = ap.parse_args()
    n, n_def, n_bad = args.units, 3, 2
    from distributed import LocalCluster

    with tempfile.TemporaryDirectory() as tmpd:
        tmp = Path(tmpd)
        cfg = load_simulation_config(str(ROOT / "configs" / "simulate_fleet.yaml"))
        units = draw_fleet(cfg, n, n_def, n_bad)
        manifest = write_fleet(units, tmp / "sim", [], settings={"output": {"figures": False}})
        m = yaml.safe_load(manifest.read_text())  # the same recordings, with the unit figures
        m["settings"] = {}
        m["units"] = [{**u, "data": str(tmp / "sim" / u["data"])} for u in m["units"]]
        manifest_fig = tmp / "manifest_figures.yaml"
        manifest_fig.write_text(yaml.safe_dump(m))
        with open(tmp / "sim" / "truth.csv", newline="") as f:
            truth = {r["unit"]: r for r in csv.DictReader(f)}
        samples = sum(1 for _ in open(tmp / "sim" / "recordings" / f"{units[0].id}.csv")) - 1
        rows, tables = [], {}
        cores = os.cpu_count() or 1
        runs = [("processes, 1 worker", ("--workers", "1"), manifest),
                (f"processes, 2 workers{' (all cores)' if cores == 2 else ''}", ("--workers", "2"), manifest)]
        if cores > 2:
            runs.append((f"processes, {cores} workers (all cores)", ("--workers", str(cores)), manifest))
        runs += [("LocalCluster, 2 workers", None, manifest),
                 ("processes, 2 workers, with unit figures", ("--workers", "2"), manifest_fig)]
        for label, extra, man in runs:
            out = tmp / f"out{len(rows)}"
            if extra is None:
                t0 = time.perf_counter()
                with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                                  silence_logs=50) as cluster:
                    up = time.perf_counter() - t0
                    wall, _, busy = batch(man, out, "--scheduler", cluster.scheduler_address)
                label += f" (cluster start {up:.1f} s, not counted)"
            else:
                wall, _, busy = batch(man, out, *extra)
            t = table(out)
            alarms = check(t, truth)
            if man == manifest:
                tables[label] = stable(t)
            ok = [r for r in t.values() if r["status"] == "ok"]
            per_unit = statistics.median(float(r["seconds"]) for r in ok)
            cpu = statistics.median(float(r["cpu_seconds"]) for r in ok)
            units_cpu = sum(float(r["cpu_seconds"]) for r in t.values()) / wall  # the units' own, in CPUs
            workers = int(extra[1]) if extra is not None else 2
            unit_seconds = sum(float(r["seconds"]) for r in t.values())
            rows.append((label, wall, per_unit, cpu, units_cpu, busy, workers, unit_seconds))
            print(f"{label}: {wall:.1f} s, {per_unit * 1e3:.0f} ms per unit, {cpu * 1e3:.0f} ms CPU, "
                  f"units {units_cpu:.2f} CPUs, machine busy {busy:.2f} CPUs", flush=True)
        first = next(iter(tables.values()))
        assert all(tb == first for tb in tables.values()), "the executors gave different tables"
        # every good unit equals a single-unit run of the library path `imucal calibrate` takes
        m = load_manifest(manifest)
        t = table(tmp / "out0")
        t0 = time.perf_counter()
        good = [u for u in m.units if not truth[u.id]["corrupt"]]
        for u in good:
            v = calibrate_accelerometer(u.config).result.params.value_dict()
            assert [v[k] for k in BASE_NAMES] == [float(t[u.id][k]) for k in BASE_NAMES], u.id
        single = (time.perf_counter() - t0) / len(good)
        done, skipped = killed_and_resumed(manifest, tmp / "killed", n)
        fixed = fixed_cost(tmp, cfg, args.fixed_runs)
        n_out = sum(bool(r["outlier"]) for r in t.values())
    print(f"{len(good)} good units identical to single runs; killed at {done} done, resumed skipping {skipped}")
    one = rows[0]
    lines = fixed_lines(fixed, one)
    lines += [f"{n} simulated units ({samples} samples each: 18 poses, 3 s holds at 100 Hz; {n_def} defective, "
             f"{n_bad} with corrupt files) on {os.cpu_count()} CPUs ({cpu_name()}), Python "
             f"{platform.python_version()}; `python scripts/bench_fleet.py`. Wall time from the command's start "
             "to the written report; per unit: the median wall and CPU time a worker spends on one unit (hash, fit, "
             "files); units per CPU-hour: 3600 s over that CPU time, what one free core sustains; CPUs used: the units' CPU time over the wall time, and the whole machine's busy time over the "
             "wall time (/proc/stat): other jobs share this machine, and where the machine is busy on all its CPUs "
             "the wall times stretch while the CPU times stay.",
             "",
             "| executor | wall time [s] | units per second | efficiency | per unit, wall [ms] | per unit, CPU [ms] "
             "| units per CPU-hour | CPUs used by the units | CPUs busy, whole machine |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for label, wall, per_unit, cpu, units_cpu, busy, workers, _ in rows:
        # units/s over the workers x one worker's units/s (like for like: the runs without unit figures)
        eff = "" if "figures" in label else f"{(n / wall) / (workers * n / one[1]):.2f}"
        lines.append(f"| {label} | {wall:.1f} | {n / wall:.2f} | {eff} | {per_unit * 1e3:.0f} | {cpu * 1e3:.0f} "
                     f"| {3600 / cpu:,.0f} | {units_cpu:.2f} | {busy:.2f} |")
    lines += ["", "Efficiency: units per second over (workers x units per second of one worker); below 1 where the "
                  "workers share cores with each other or with other jobs (CPUs busy, whole machine)."]
    lines += ["",
              f"Every run: the {n - n_bad} readable units calibrated, the {n_bad} corrupt ones refused with their "
              f"one-line error, the {n_def} defective ones failed and flagged as outliers ({alarms} good unit(s) flagged "
              f"too, of {len(good) - n_def}); the three runs without "
              f"figures gave the same table; each of the {len(good)} good units' parameters equal, bit for bit, a "
              f"single run of the library path of `imucal calibrate` ({single * 1e3:.0f} ms per unit in one "
              f"process). A batch killed with SIGKILL after {done} units resumed and skipped those {skipped}."]
    block = "\n".join(lines) + "\n"
    print(block)
    if n == 200:
        doc = ROOT / "docs" / "fleet.md"
        text = doc.read_text(encoding="utf-8")
        new = re.sub(r"(<!-- begin:bench -->\n).*?(<!-- end:bench -->)", lambda mm: mm.group(1) + block + mm.group(2),
                     text, flags=re.S)
        write_text_atomic(doc, new)
        print(f"wrote {doc}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
