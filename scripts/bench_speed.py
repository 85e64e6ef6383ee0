#!/usr/bin/env python
"""Speed and memory of imucal on this machine (issues 6 and 30); writes docs/benchmarks.md.

Cases, each in a fresh subprocess so that its peak resident memory (ru_maxrss) is its own:
  calibrate   end-to-end `imucal calibrate --no-figures` on the shipped Xsens recording
              (hyperfine when installed, else the median of repeated subprocess runs)
  paired      whole processes paired with imu_tk in one run (--imutk DIR: scripts/build_imutk.sh's
              folder), A B A B ..., the ratio pair by pair: the Xsens accelerometer (test_imu_acc),
              accelerometer + gyroscope (test_imu_calib), and the default `imucal calibrate` with its
              figures and report against test_imu_acc; with where the time of that run goes (imports
              by package, reading, detection, fit, files, each figure's drawing, layout and PNG)
  fit-means   fit time against the number of interval means (10 .. 1000); first call builds the
              IPOPT solver for that problem shape, later calls reuse it
  fit-samples samples-mode fit time against the number of samples (10^4 .. 10^6)
  apply       Calibration.apply on 10^7 samples against a plain numpy matrix product

    python scripts/bench_speed.py --imutk /tmp/imutk-build   # all cases, writes docs/benchmarks.md
    python scripts/bench_speed.py --quick    # smaller sizes, fewer repeats
"""
from __future__ import annotations

import argparse
import json
import math
import os
import platform
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
XSENS = ROOT / "data" / "xsens-mti-imutk" / "xsens_acc.mat"
G = 9.80665  # m/s^2, simulations (imucal.constants.STANDARD_GRAVITY)


# --- cases run inside a child process -----------------------------------------------------------
def _sim_means(n: int, seed: int = 0):
    from imucal.analysis.simulate import frame_matrix, mems_counts_sensor, random_directions

    rng = np.random.default_rng(seed)
    sensor = mems_counts_sensor(np.random.default_rng(7))
    u = random_directions(n, rng)
    clean = np.asarray(sensor.s) + np.asarray(sensor.b) * (G * u @ frame_matrix(np.asarray(sensor.angles)))
    return sensor, clean, rng


def _params(means: np.ndarray):
    from imucal.solve.initial import ellipsoid_guess
    from imucal.model.parameters import base_parameters

    g = ellipsoid_guess(means, G)
    return base_parameters(g.s, g.b, g.angles, raw_unit="raw", gravity=G)


def case_fit_means(n: int, repeats: int) -> dict:
    from imucal.solve.fit import FitData, fit
    from imucal.model.sensor import build_model

    from imucal.model.effects import make_effect

    sensor, clean, rng = _sim_means(n)
    sig = 0.2  # counts per mean (4 counts per sample, 400 samples)
    model = build_model()
    mapped_model = build_model([make_effect("bias_drift", (0, 1, 2))])

    def mapped_params(base):
        p = mapped_model.parameters(base)
        extra = [k for k in p.names if k not in base.names]
        return p.with_fixed(extra, values={k: 0.0 for k in extra})
    times, statuses, vec = [], [], []
    for k in range(repeats + 1):
        means = clean + rng.normal(0, sig, clean.shape)
        data = FitData(raw=means, cov=np.zeros((n, 0)), raw_var=np.full(means.shape, sig**2), group=np.arange(n),
                       mode="means")
        params = _params(means)
        t0 = time.perf_counter()
        res = fit(data, params, model, G)
        times.append(time.perf_counter() - t0)
        statuses.append(res.status)
        # the same rows through the CasADi map NLP that fits models with effects (an effect whose
        # coefficients are held at zero), for comparison
        t0 = time.perf_counter()
        res_v = fit(FitData(raw=means, cov=np.zeros((n, 1)), raw_var=data.raw_var, group=data.group,
                            mode="means"), mapped_params(params), mapped_model, G)
        vec.append(time.perf_counter() - t0)
        dmax = max(abs(res_v.params[p].value - res.params[p].value) / res.std[p] for p in res.free_names)
    return {"n": n, "first_s": times[0], "cached_median_s": statistics.median(times[1:]),
            "cached_min_s": min(times[1:]), "status": statuses, "vectorised_median_s": statistics.median(vec),
            "vectorised_max_diff_std": dmax}


def case_fit_samples(n: int, repeats: int) -> dict:
    from imucal.solve.fit import FitData, fit
    from imucal.model.sensor import build_model

    n_poses = 50
    sensor, clean, rng = _sim_means(n_poses)
    k = np.repeat(np.arange(n_poses), -(-n // n_poses))[:n]
    noise = 4.0  # counts per sample
    model = build_model()
    times, statuses, iters = [], [], []
    for _ in range(repeats):
        raw = clean[k] + rng.normal(0, noise, (n, 3))
        data = FitData(raw=raw, cov=np.zeros((n, 0)), raw_var=np.full((n, 3), noise**2), group=k, mode="samples")
        params = _params(np.array([raw[k == j].mean(axis=0) for j in range(n_poses)]))
        t0 = time.perf_counter()
        res = fit(data, params, model, G)
        times.append(time.perf_counter() - t0)
        statuses.append(res.status)
        iters.append(res.iterations)
    return {"n": n, "median_s": statistics.median(times), "min_s": min(times), "status": statuses,
            "iterations": iters}


def case_apply(n: int, repeats: int) -> dict:
    import tracemalloc

    from imucal.calibration.frozen import Calibration
    from imucal.model.parameters import base_parameters

    sensor, clean, rng = _sim_means(30)
    params = base_parameters(sensor.s, sensor.b, sensor.angles, raw_unit="raw", gravity=G)
    cal = Calibration(params=params, std={}, gravity=G)
    raw = rng.normal(0, 1000, (n, 3))
    A, c = cal.linear_map()
    out = {"n": n}
    def transposed() -> np.ndarray:  # gemm with a 3 x N operand, offset added in place
        out = (A @ raw.T).T
        out += c
        return out

    for name, fn in (("imucal", lambda: cal.apply(raw)), ("numpy", lambda: raw @ A.T + c),
                     ("numpy_t", transposed)):
        fn()  # warm
        ts = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            fn()
            ts.append(time.perf_counter() - t0)
        tracemalloc.start()
        fn()
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        out[name] = {"median_s": statistics.median(ts), "samples_per_s": n / statistics.median(ts),
                     "tracemalloc_peak_mb": peak / 2**20}
    out["max_abs_diff"] = float(np.max(np.abs(cal.apply(raw) - (raw @ A.T + c))))
    return out


def child(case: str, n: int, repeats: int) -> None:
    t0 = time.perf_counter()
    if case == "parts":
        print(json.dumps(case_parts()))
        return
    out = {"fit-means": case_fit_means, "fit-samples": case_fit_samples, "apply": case_apply}[case](n, repeats)
    out["wall_s"] = time.perf_counter() - t0
    u = resource.getrusage(resource.RUSAGE_SELF)
    out["maxrss_mb"], out["cpu_s"] = u.ru_maxrss / 1024, u.ru_utime + u.ru_stime
    print(json.dumps(out))


def run_child(case: str, n: int, repeats: int, env: dict | None = None) -> dict:
    p = subprocess.run([sys.executable, __file__, "--child", case, "--size", str(n), "--repeats", str(repeats)],
                       capture_output=True, text=True, cwd=ROOT, env={**os.environ, **(env or {})})
    if p.returncode != 0:
        return {"n": n, "error": p.stderr.strip().splitlines()[-1] if p.stderr.strip() else f"exit {p.returncode}"}
    return json.loads(p.stdout.strip().splitlines()[-1])


# --- end-to-end calibrate ----------------------------------------------------------------------
def calibrate_cmd(out: str) -> list[str]:
    """The repository's `imucal calibrate` (run with PYTHONPATH=ROOT: this checkout's code, whatever is installed)."""
    return [sys.executable, "-m", "imucal", "calibrate", "--data", str(XSENS), "--gravity", "9.81744", "--out", out,
            "--no-figures", "--quiet"]


ENV = {**os.environ, "PYTHONPATH": str(ROOT)}
#: What the `imucal` command sets before numpy loads (imucal.cli.main), unless the user set it.
ONE_BLAS_THREAD = {"OPENBLAS_NUM_THREADS": os.environ.get("OPENBLAS_NUM_THREADS", "1"),
                   "MKL_NUM_THREADS": os.environ.get("MKL_NUM_THREADS", "1")}


def timed_runs(cmd: list[str], runs: int, warmup: int = 2, cwd: str | None = None) -> tuple[list[float], list[float]]:
    """Wall and CPU (user + system) time [s] of ``runs`` runs of ``cmd``, after ``warmup`` untimed ones."""
    walls, cpus = [], []
    for i in range(runs + warmup):
        r0, t0 = resource.getrusage(resource.RUSAGE_CHILDREN), time.perf_counter()
        subprocess.run(cmd, capture_output=True, check=True, env=ENV, cwd=cwd)
        t1, r1 = time.perf_counter(), resource.getrusage(resource.RUSAGE_CHILDREN)
        if i >= warmup:
            walls.append(t1 - t0)
            cpus.append(r1.ru_utime - r0.ru_utime + r1.ru_stime - r0.ru_stime)
    return walls, cpus


def bench_imutk(exe: str, runs: int) -> dict:
    """imu_tk's test_imu_calib (scripts/build_imutk.sh) on the shipped accelerometer and gyroscope files."""
    tmp = tempfile.mkdtemp(prefix="imucal-imutk-")  # it writes its .calib files into its working folder
    walls, cpus = timed_runs([str(Path(exe).resolve()), str(XSENS), str(XSENS.with_name("xsens_gyro.mat"))], runs,
                             warmup=1, cwd=tmp)
    shutil.rmtree(tmp, ignore_errors=True)
    return {"median_s": statistics.median(walls), "min_s": min(walls), "cpu_median_s": statistics.median(cpus),
            "runs": runs}


def bench_calibrate(runs: int) -> dict:
    # Byte-compiled modules, as `pip install` leaves them: where PYTHONDONTWRITEBYTECODE is set (this
    # machine), an editable install would otherwise recompile every module at every run.
    subprocess.run([sys.executable, "-m", "compileall", "-q", str(ROOT / "imucal")], capture_output=True, check=True)
    tmp = tempfile.mkdtemp(prefix="imucal-bench-")
    cmd = calibrate_cmd(tmp)
    shown = ["imucal", *cmd[cmd.index("calibrate"):]]
    res: dict = {"command": " ".join(shown).replace(str(ROOT) + "/", "").replace(tmp, "OUT")}
    hf = shutil.which("hyperfine")
    if hf:
        jpath = Path(tmp) / "hf.json"
        subprocess.run([hf, "--warmup", "2", "--runs", str(runs), "--export-json", str(jpath), "-N",
                        " ".join(cmd)], capture_output=True, text=True, check=True, env=ENV)
        r = json.loads(jpath.read_text())["results"][0]
        res.update(tool="hyperfine", median_s=r["median"], mean_s=r["mean"], stddev_s=r["stddev"],
                   min_s=r["min"], runs=len(r["times"]), user_s=r["user"], system_s=r["system"],
                   cpu_median_s=r["user"] + r["system"])
    else:
        walls, cpus = timed_runs(cmd, runs)
        res.update(tool="subprocess loop", median_s=statistics.median(walls), min_s=min(walls), runs=len(walls),
                   cpu_median_s=statistics.median(cpus), cpu_min_s=min(cpus))
    # peak memory of one run
    p = subprocess.run([sys.executable, "-c",
                        "import resource, subprocess, sys; subprocess.run(sys.argv[1:], capture_output=True); "
                        "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)", *cmd],
                       capture_output=True, text=True, env=ENV)
    res["maxrss_mb"] = int(p.stdout.strip()) / 1024
    # interpreter + import floor
    walls, cpus = timed_runs([sys.executable, "-c", "import numpy, casadi"], 7, warmup=1)
    res["floor_numpy_casadi_s"], res["floor_cpu_s"] = statistics.median(walls), statistics.median(cpus)
    res["import_top"] = import_profile(cmd)
    shutil.rmtree(tmp, ignore_errors=True)
    return res


def import_profile(cmd: list[str], top: int = 8) -> list[tuple[str, float]]:
    """Largest cumulative import times (python -X importtime) of one calibrate run [s]."""
    args = cmd[3:]  # after `python -m imucal`
    p = subprocess.run([sys.executable, "-X", "importtime", "-m", "imucal", *args], capture_output=True, text=True,
                       env=ENV)
    rows = []
    for line in p.stderr.splitlines():
        if not line.startswith("import time:") or "cumulative" in line:
            continue
        parts = line.split("|")
        name = parts[2].rstrip()
        if len(name) - len(name.lstrip()) == 1:  # one space: imported at top level
            rows.append((name.strip(), int(parts[1]) / 1e6))
    rows.sort(key=lambda t: -t[1])
    return rows[:top]


# --- whole processes paired with imu_tk (issue 30) --------------------------------------------------
GYRO = XSENS.with_name("xsens_gyro.mat")
#: Each pair: (name, imucal's arguments after `imucal calibrate` (OUT replaced), imu_tk's program and files, target)
PAIRS = [
    ("Xsens accelerometer", ["--data", str(XSENS), "--gravity", "9.81744", "--out", "OUT", "--no-figures", "--quiet"],
     ("test_imu_acc", [XSENS]), 0.75),
    ("Xsens accelerometer + gyroscope", ["--data", str(XSENS), "--gyro-data", str(GYRO), "--gravity", "9.81744",
                                         "--out", "OUT", "--no-figures", "--quiet"],
     ("test_imu_calib", [XSENS, GYRO]), 0.8),
    ("Xsens default `calibrate` (figures and report on) against imu_tk's accelerometer",
     ["--data", str(XSENS), "--gravity", "9.81744", "--out", "OUT"], ("test_imu_acc", [XSENS]), 2.0),
]
#: Runs one command and prints its wall time, CPU time (user + system) and peak resident set as JSON:
#: the numbers are the command's own, not this runner's.
RUNNER = ("import json, resource, subprocess, sys, time; t0 = time.perf_counter(); "
          "p = subprocess.run(sys.argv[1:], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL); "
          "w = time.perf_counter() - t0; u = resource.getrusage(resource.RUSAGE_CHILDREN); "
          "print(json.dumps({'wall': w, 'cpu': u.ru_utime + u.ru_stime, 'rss': u.ru_maxrss / 1024, 'code': p.returncode}))")


def one_run(cmd: list[str], cwd: str) -> dict:
    p = subprocess.run([sys.executable, "-c", RUNNER, *cmd], capture_output=True, text=True, env=ENV, cwd=cwd)
    return json.loads(p.stdout)


def paired(a: list[str], b: list[str], runs: int) -> dict:
    """A and B in turn (one warm-up each, then A B A B ...): each one's median wall, CPU and peak
    memory, and the median of the ratios A/B pair by pair (robust to the machine's drift)."""
    tmp = tempfile.mkdtemp(prefix="imucal-pair-")  # imu_tk writes its .calib files into its working folder
    out = []
    for i in range(runs + 1):
        shutil.rmtree(Path(tmp) / "out", ignore_errors=True)
        ra = one_run([x if x != "OUT" else str(Path(tmp) / "out") for x in a], tmp)
        rb = one_run(b, tmp)
        if i:
            out.append((ra, rb))
    shutil.rmtree(tmp, ignore_errors=True)

    def med(k: str, j: int) -> float:
        return statistics.median(r[j][k] for r in out)

    return {"runs": runs, "codes": sorted({r[j]["code"] for r in out for j in (0, 1)}),
            **{f"{w}_{k}": med(k, j) for j, w in ((0, "a"), (1, "b")) for k in ("wall", "cpu", "rss")},
            "ratio_wall": statistics.median(r[0]["wall"] / r[1]["wall"] for r in out),
            "ratio_wall_range": (min(r[0]["wall"] / r[1]["wall"] for r in out),
                                 max(r[0]["wall"] / r[1]["wall"] for r in out)),
            "ratio_cpu": statistics.median(r[0]["cpu"] / r[1]["cpu"] for r in out)}


def bench_paired(imutk: str, runs: int) -> list[dict]:
    subprocess.run([sys.executable, "-m", "compileall", "-q", str(ROOT / "imucal")], capture_output=True, check=True)
    rows = []
    for name, args, (prog, files), target in PAIRS:
        print(f"paired: {name} ...", file=sys.stderr)
        a = [sys.executable, "-m", "imucal", "calibrate", *args]
        b = [str(Path(imutk) / prog), *map(str, files)]
        shown = " ".join(["imucal calibrate", *args]).replace(str(ROOT) + "/", "")
        rows.append({"name": name, "imucal": shown, "imutk": " ".join([prog, *(Path(f).name for f in files)]),
                     "target": target, **paired(a, b, runs)})
    floor = paired([sys.executable, "-c", "import numpy, casadi"], [sys.executable, "-c", "pass"], runs)
    rows.append({"name": "floor: `python -c 'import numpy, casadi'` against `python -c pass`", "floor": True, **floor})
    return rows


# --- where the time of one default run goes (a child process) ---------------------------------------
class _ImportClock:
    """CPU time (this thread) each module's own import takes, its submodules' not counted."""

    def __init__(self) -> None:
        import importlib.abc

        self.self_time: dict[str, float] = {}
        stack: list[float] = []
        clock = self

        class Loader(importlib.abc.Loader):
            def __init__(self, inner):
                self.inner = inner

            def __getattr__(self, a):
                return getattr(self.inner, a)

            def create_module(self, spec):
                return self.inner.create_module(spec)

            def exec_module(self, module):
                t0 = time.thread_time()
                stack.append(0.0)
                try:
                    self.inner.exec_module(module)
                finally:
                    el, inner = time.thread_time() - t0, stack.pop()
                    clock.self_time[module.__name__] = el - inner
                    if stack:
                        stack[-1] += el

        class Finder(importlib.abc.MetaPathFinder):
            def find_spec(self, name, path, target=None):
                for f in sys.meta_path:
                    if f is self or not hasattr(f, "find_spec"):
                        continue
                    spec = f.find_spec(name, path, target)
                    if spec is not None:
                        if spec.loader is not None and hasattr(spec.loader, "exec_module"):
                            spec.loader = Loader(spec.loader)
                        return spec
                return None

        sys.meta_path.insert(0, Finder())

    def by_package(self) -> dict[str, float]:
        out: dict[str, float] = {}
        for name, t in self.self_time.items():
            top = name.split(".")[0]
            out[top] = out.get(top, 0.0) + t
        return out


def case_parts() -> dict:
    """The default `imucal calibrate` on the Xsens recording, step by step in one process: CPU time
    [s] of each step (imports counted apart, by package; matplotlib's with the figures)."""
    clock = _ImportClock()
    T = time.process_time
    parts: dict[str, float] = {}
    t0 = T()
    from imucal.config.run import config_from_dict
    from imucal.data.load import load_recording
    from imucal.files.output import OutputSet
    from imucal.pipeline import calibrate_accelerometer, read_intervals
    from imucal.report.run_files import RunFiles, stage_files
    from imucal.report.text import fit_report, summary as run_summary
    parts["imports of the calibration path"] = T() - t0
    imports_before = dict(clock.by_package())
    cfg = config_from_dict({"data": {"path": str(XSENS)}, "gravity": {"value": 9.81744}})
    t = T()
    rec = load_recording(cfg.data)
    parts["read (whole file)"] = T() - t
    t = T()
    read_intervals(cfg, rec)
    parts["static intervals"] = T() - t
    t = T()
    run = calibrate_accelerometer(cfg, rec)
    parts["calibrate (intervals again, guess, fit, covariance)"] = T() - t - parts["static intervals"]
    t = T()
    files = RunFiles(run=run, text=fit_report(run), summary=run_summary(run))
    parts["report text and summary"] = T() - t
    t = T()
    import matplotlib.backends.backend_agg  # noqa: F401 - what imucal.report.canvas draws with
    import matplotlib.figure  # noqa: F401
    parts["import matplotlib (figures)"] = T() - t
    from matplotlib.figure import Figure
    spent = {"layout": 0.0, "png": 0.0}

    def timed(name, fn):
        def wrapper(*a, **k):
            t1 = T()
            try:
                return fn(*a, **k)
            finally:
                spent[name] += T() - t1
        return wrapper

    Figure.tight_layout, Figure.savefig = timed("layout", Figure.tight_layout), timed("png", Figure.savefig)
    from imucal.report.figures import FIGURES
    from imucal.report.html import render_png
    for name, fn in FIGURES.items():
        before = dict(spent)
        t = T()
        render_png(fn, run)
        total = T() - t
        lay, png = spent["layout"] - before["layout"], spent["png"] - before["png"]
        parts[f"figure {name}: plot calls"] = total - lay - png
        if lay:  # (imucal.report.canvas places the axes by fixed margins: no layout pass)
            parts[f"figure {name}: tight_layout"] = lay
        parts[f"figure {name}: savefig (draw and PNG)"] = png
    t = T()
    out = tempfile.mkdtemp(prefix="imucal-parts-")
    with OutputSet([str(XSENS)]) as o:
        stage_files(o, Path(out) / "o", files, False)
    shutil.rmtree(out, ignore_errors=True)
    parts["files (YAML, text, HTML), without figures"] = T() - t
    return {"parts": parts, "imports": imports_before, "total_cpu": T() - t0}


# --- report ------------------------------------------------------------------------------------
def summary(r: dict) -> list[str]:
    """The headline numbers, between markers that scripts/update_readme.py splices into the README."""
    L = ["<!-- begin:summary -->"]
    L += paired_table(r.get("paired") or [])
    L += ["| what | measured |", "|---|---|"]
    c = r.get("calibrate")
    if c:
        # (imu_tk beside it only in the paired table above, like for like: not its two-sensor run here)
        L.append(f"| end-to-end `imucal calibrate --no-figures` (accelerometer only), Xsens (51,175 samples, "
                 f"38 intervals) | {c['median_s']:.3f} s median, {c['cpu_median_s']:.3f} s CPU ({c['tool']}, "
                 f"{c['runs']} runs), peak {c['maxrss_mb']:.0f} MB; floor `import numpy, casadi` "
                 f"{c['floor_numpy_casadi_s']:.3f} s |")
    for x in r.get("fit-means") or []:
        if "error" not in x and x["n"] in (10, 1000):
            L.append(f"| fit of {x['n']:,} interval means | {x['cached_median_s']:.3f} s (first call "
                     f"{x['first_s']:.3f} s) |")
    for x in r.get("fit-samples") or []:
        if "error" not in x:
            L.append(f"| samples mode, {x['n']:,} samples | {x['median_s']:.2f} s, peak {x['maxrss_mb']:.0f} MB |")
    ap = r.get("apply")
    if ap and "error" not in ap:
        L.append(f"| apply, {ap['n']:,} samples | `Calibration.apply` {ap['imucal']['samples_per_s']:.3g} "
                 f"samples/s; plain `raw @ A.T + c` {ap['numpy']['samples_per_s']:.3g} samples/s |")
    L.append("<!-- end:summary -->")
    return L


def paired_table(rows: list[dict]) -> list[str]:
    """Whole processes paired with imu_tk: medians, and the ratio pair by pair against the target."""
    if not rows:
        return []
    L = ["Whole processes, imucal and imu_tk in turn in one run (A B A B ...), "
         f"{rows[0]['runs']} pairs after a warm-up; the ratio is imucal's wall time over imu_tk's, pair by pair "
         "(median, and its range).", "", "<!-- begin:paired -->",
         "| what | imucal wall [s] / CPU [s] / peak [MB] | imu_tk wall [s] / CPU [s] / peak [MB] | ratio (range) "
         "| target |", "|---|---|---|---|---|"]
    for x in rows:
        met = "" if x.get("floor") else (" met" if x["ratio_wall"] <= x["target"] else " **not met**")
        lo, hi = x["ratio_wall_range"]
        target = "" if x.get("floor") else f"<= {x['target']:g}{met}"
        what = x["name"] if x.get("floor") else f"{x['name']}: `{x['imucal']}` against `{x['imutk']}`"
        L.append(f"| {what} | {x['a_wall']:.3f} / {x['a_cpu']:.3f} / {x['a_rss']:.0f} | {x['b_wall']:.3f} / "
                 f"{x['b_cpu']:.3f} / {x['b_rss']:.0f} | {x['ratio_wall']:.2f} ({lo:.2f}-{hi:.2f}) | {target} |")
    return L + ["<!-- end:paired -->", ""]


def parts_table(p: dict) -> list[str]:
    """Where the default run's CPU time goes (one process, step by step)."""
    if not p or "error" in p:
        return [f"(parts: {p.get('error', 'not measured')})", ""] if p else []
    L = ["## Where the default run's time goes", "",
         "The default `imucal calibrate --data xsens_acc.mat --gravity 9.81744` (figures and report on), step by step "
         "in one process (`bench_speed.py --child parts`, one BLAS thread as the command runs), CPU time; numpy "
         "is loaded before (in the floor `import numpy, casadi`) and the interpreter's own start (with this "
         "machine's site hooks) is the floor `python -c pass` above.", "",
         "| step | CPU [s] |", "|---|---|"]
    L += [f"| {k} | {v:.3f} |" for k, v in p["parts"].items()]
    L += ["", "Imports of the calibration path by package (each module's own CPU time, summed):", "",
          "| package | CPU [s] |", "|---|---|"]
    top = sorted(p["imports"].items(), key=lambda kv: -kv[1])
    L += [f"| {k} | {v:.3f} |" for k, v in top[:8]]
    rest = sum(v for _, v in top[8:])
    return L + [f"| {len(top) - 8} others | {rest:.3f} |", ""]


def markdown(r: dict, args) -> str:
    cpu = platform.processor() or platform.machine()
    try:
        model = next(ln.split(":", 1)[1].strip() for ln in Path("/proc/cpuinfo").read_text().splitlines()
                     if ln.startswith("model name"))
    except (OSError, StopIteration):
        model = cpu
    L = ["# Benchmarks", "",
         f"Generated by `python scripts/bench_speed.py{' --quick' if args.quick else ''}"
         f"{' --imutk IMUTK' if args.imutk else ''}"
         f"{f' --samples-max {args.samples_max}' if args.samples_max != 10_000_000 else ''}` on {model}, "
         f"{os.cpu_count()} cores, Python {platform.python_version()}, casadi "
         f"{__import__('casadi').__version__}, numpy {np.__version__}. Every case runs in a fresh process; "
         "memory is that process's peak resident set (ru_maxrss). Do not edit by hand.", "",
         f"Load average when the run started: {r.get('load', (math.nan,) * 3)[0]:.2f} and when it ended: "
         f"{r.get('load_end', (math.nan,) * 3)[0]:.2f} (1 min) on {os.cpu_count()} "
         "cores: this machine is shared, so wall times carry the noise of other jobs; CPU time (user + system) "
         "is the steadier figure.", ""]
    L += summary(r) + [""]
    L += parts_table(r.get("parts") or {})
    c = r.get("calibrate")
    if c:
        L += ["## End-to-end calibrate (Xsens MTi, 51,175 samples, 38 intervals)", "",
              f"    {c['command']}", "",
              "With the package byte-compiled first, as `pip install` leaves it (this machine sets "
              "PYTHONDONTWRITEBYTECODE, under which an editable install recompiles every module at every run).", "",
              "| tool | runs | median [s] | min [s] | CPU (user + system), median [s] | peak RSS [MB] | "
              "floor: `python -c 'import numpy, casadi'`, wall / CPU [s] |",
              "|---|---|---|---|---|---|---|",
              f"| {c['tool']} | {c['runs']} | {c['median_s']:.3f} | {c['min_s']:.3f} | {c['cpu_median_s']:.3f} | "
              f"{c['maxrss_mb']:.0f} | {c['floor_numpy_casadi_s']:.3f} / {c.get('floor_cpu_s', math.nan):.3f} |", ""]
        it = r.get("imutk")
        L += ([f"imu_tk's test_imu_calib (C++/Ceres, built by scripts/build_imutk.sh, given with --imutk) on the "
               "same file and the gyroscope file beside it (it calibrates both, and re-fits the accelerometer "
               f"for 9 thresholds): {it['median_s']:.3f} s median (min {it['min_s']:.3f} s), "
               f"{it['cpu_median_s']:.3f} s CPU, {it['runs']} runs.", ""] if it else
              ["imu_tk not timed here: give its test program with --imutk (scripts/build_imutk.sh builds it).", ""])
        L += ["Start-up: the modules a run without a gyroscope, figures or chunked reading does not use are not "
              "imported (matplotlib, pandas, numpy.ma, the gyroscope fit and calibration section, the noise-model "
              "reader, discovery, the other commands' modules, traceback; asserted by tests/test_startup.py). The "
              "fits start IPOPT's barrier near zero (2-5 iterations a solve) and the REML test takes "
              "average-information steps (imucal.solve.ipopt, imucal.solve.stochastic). The command runs BLAS on one thread unless "
              "OPENBLAS_NUM_THREADS (or MKL_NUM_THREADS) is set: its matrices have a few columns, and OpenBLAS's "
              "thread pool alone costs some 30 ms of wall time per start on this machine (the floor above is "
              "measured with the pool, as `python -c` starts).", "",
              "Largest top-level imports in one run (`python -X importtime`, cumulative):", "",
              "| module | s |", "|---|---|"] + [f"| {m} | {t:.3f} |" for m, t in c["import_top"]] + [""]
    fm = r.get("fit-means")
    if fm:
        L += ["## Fit time against the number of interval means", "",
              "Random directions, raw-count sensor (16384 LSB/g), 0.2 counts noise per mean. Every model is "
              "fitted by the one least-squares path (`imucal/solve/least_squares.py`: the row residual generated "
              "from the CasADi model as numpy code, normal equations accumulated in blocks, Gauss-Newton Hessian, "
              "IPOPT built once per number of unknowns). The second time column fits the same rows with a model "
              "that carries an effect (bias drift, coefficients held at zero). `first` includes "
              "generating the row functions for that model; later fits reuse them.", "",
              "| intervals | first [s] | median [s] | same rows, model with an effect held at zero, median [s] | "
              "peak RSS [MB] | IPOPT status |",
              "|---|---|---|---|---|---|"]
        for x in fm:
            if "error" in x:
                L.append(f"| {x['n']} | error: {x['error']} | | | |")
                continue
            st = {s: x["status"][1:].count(s) for s in set(x["status"][1:])}
            L.append(f"| {x['n']} | {x['first_s']:.3f} | {x['cached_median_s']:.3f} | {x['vectorised_median_s']:.3f} | "
                     f"{x['maxrss_mb']:.0f} | "
                     + ", ".join(f"{k} x{v}" for k, v in sorted(st.items())) + " |")
        L += ["", "The two models agree to "
              f"{max(x.get('vectorised_max_diff_std', math.nan) for x in fm if 'error' not in x):.1g} standard errors "
              "(also asserted by tests/test_fit_paths.py).", ""]
    fs = r.get("fit-samples")
    if fs:
        L += ["## Samples mode: fit time against the number of samples", "",
              "50 poses, 4 counts white noise per sample; `imucal.solve.fit.fit` with `mode=\"samples\"` (the same "
              "least-squares path, blocks of 8192 rows, Gauss-Newton Hessian). Time of the fit call only (data in memory).",
              "Peak RSS and CPU are the whole child process's: it also holds the simulated samples (raw "
              "readings, their variances and pose index: 56 bytes a sample) and draws them for every repeat.",
              "", "| samples | median [s] | min [s] | IPOPT iterations | process CPU [s] | peak RSS [MB] |",
              "|---|---|---|---|---|---|"]
        for x in fs:
            if "error" in x:
                L.append(f"| {x['n']:,} | error: {x['error']} | | | | |")
                continue
            L.append(f"| {x['n']:,} | {x['median_s']:.3f} | {x['min_s']:.3f} | {x['iterations']} | "
                     f"{x.get('cpu_s', math.nan):.1f} | {x['maxrss_mb']:.0f} |")
        L.append("")
    ap, ap1 = r.get("apply"), r.get("apply_1thread")
    if ap and "error" not in ap:
        names = {"imucal": "`Calibration.apply(raw)`", "numpy": "`raw @ A.T + c` (plain numpy)",
                 "numpy_t": "`out = (A @ raw.T).T; out += c` (the affine map as one product: Calibration.apply evaluates the numpy generated from the model's CasADi apply, in blocks, which holds any effect)"}
        L += ["## Apply throughput", "",
              f"{ap['n']:,} samples (N x 3 float64 in memory), median of repeats; numpy's BLAS with its default "
              "threads, and with `OPENBLAS_NUM_THREADS=1`. On a shared 2-core machine a multithreaded BLAS call "
              "competes with other jobs, which is what the spread between the two columns shows.", "",
              "| implementation | median [s], default threads | samples/s | median [s], 1 BLAS thread | samples/s | "
              "tracemalloc peak [MB] |", "|---|---|---|---|---|---|"]
        for k, label in names.items():
            a, b = ap[k], (ap1 or {}).get(k, {})
            L.append(f"| {label} | {a['median_s']:.3f} | {a['samples_per_s']:.3g} | {b.get('median_s', math.nan):.3f} | "
                     f"{b.get('samples_per_s', math.nan):.3g} | {a['tracemalloc_peak_mb']:.0f} |")
        L += ["", f"Largest difference between `Calibration.apply` and numpy: {ap['max_abs_diff']:.2g} m/s^2. "
              f"Process peak RSS {ap['maxrss_mb']:.0f} MB (input {ap['n']:,} x 3 doubles = "
              f"{ap['n'] * 24 / 2**20:.0f} MB, output the same).", ""]
    return "\n".join(L)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--only", default="paired,parts,calibrate,fit-means,fit-samples,apply")
    ap.add_argument("--imutk", help="scripts/build_imutk.sh's folder (test_imu_acc, test_imu_calib), or its "
                                    "test_imu_calib: paired with imucal")
    ap.add_argument("--pairs", type=int, default=11, help="A B pairs per paired case (after one warm-up)")
    ap.add_argument("--samples-max", type=int, default=10_000_000, help="largest samples-mode fit (full run)")
    ap.add_argument("--out", default=str(ROOT / "docs" / "benchmarks.md"))
    ap.add_argument("--child", help=argparse.SUPPRESS)
    ap.add_argument("--size", type=int, help=argparse.SUPPRESS)
    ap.add_argument("--repeats", type=int, default=3, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        child(args.child, args.size, args.repeats)
        return 0
    only = set(args.only.split(","))
    r: dict = {"load": os.getloadavg()}
    imutk_dir = None if not args.imutk else (args.imutk if os.path.isdir(args.imutk) else str(Path(args.imutk).parent))
    if "paired" in only and imutk_dir:
        r["paired"] = bench_paired(imutk_dir, 3 if args.quick else args.pairs)
    if "parts" in only:
        print("parts ...", file=sys.stderr)
        p = subprocess.run([sys.executable, __file__, "--child", "parts", "--size", "0"], capture_output=True,
                           text=True, cwd=ROOT, env={**ENV, **ONE_BLAS_THREAD})  # as the imucal command runs
        r["parts"] = json.loads(p.stdout.strip().splitlines()[-1]) if p.returncode == 0 else {"error": p.stderr[-300:]}
    if "calibrate" in only:
        print("calibrate ...", file=sys.stderr)
        r["calibrate"] = bench_calibrate(5 if args.quick else 20)
        if imutk_dir:
            r["imutk"] = bench_imutk(str(Path(imutk_dir) / "test_imu_calib"), 3 if args.quick else 10)
    if "fit-means" in only:
        sizes = (10, 100) if args.quick else (10, 30, 100, 300, 1000)
        r["fit-means"] = []
        for n in sizes:
            print(f"fit-means {n} ...", file=sys.stderr)
            r["fit-means"].append(run_child("fit-means", n, 3 if args.quick else 10))
    if "fit-samples" in only:
        sizes = (10_000, 100_000) if args.quick else tuple(
            n for n in (10_000, 100_000, 1_000_000, 10_000_000) if n <= args.samples_max)
        r["fit-samples"] = []
        for n in sizes:
            print(f"fit-samples {n} ...", file=sys.stderr)
            r["fit-samples"].append(run_child("fit-samples", n, 2 if args.quick or n >= 10_000_000 else 3))
    if "apply" in only:
        print("apply ...", file=sys.stderr)
        n_apply = 10**6 if args.quick else 10**7
        r["apply"] = run_child("apply", n_apply, 3 if args.quick else 7)
        r["apply_1thread"] = run_child("apply", n_apply, 3 if args.quick else 7, {"OPENBLAS_NUM_THREADS": "1"})
    r["load_end"] = os.getloadavg()
    text = markdown(r, args)
    from imucal.files.output import write_text_atomic

    write_text_atomic(args.out, text + "\n")
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
