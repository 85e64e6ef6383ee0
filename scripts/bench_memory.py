#!/usr/bin/env python
"""Long recordings: time and peak memory of `imucal calibrate` on the Xsens log tiled 10, 100 and
1000 times (0.5 M, 5 M, 51 M samples), paired with imu_tk's accelerometer calibration on the same
files, the parse floor, and the CSV parsers compared (issues 13 and 30). Writes
docs/benchmarks_memory.md.

The tiled files are written to a temporary folder (--tmp, default imucal-tiles in the system temporary folder), never into
the repository: tile i is the recording shifted by i times its span (time stamps written with
5 decimals, the readings as in the file). Every measurement runs in a fresh process; its peak
resident set (ru_maxrss) is that process's own.

    python scripts/bench_memory.py                      # 10, 100, 1000 tiles
    python scripts/bench_memory.py --sizes 10,100       # skip the 3 GB file
    python scripts/bench_memory.py --whole 10,100       # also read whole (--stream never) at these
    python scripts/bench_memory.py --imutk /tmp/imutk/test_imu_acc     # imu_tk beside (scripts/build_imutk.sh)
    python scripts/bench_memory.py --resume ...         # after a stop: measure only what is missing
"""
from __future__ import annotations

import argparse
import json
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
XSENS = ROOT / "data" / "xsens-mti-imutk" / "xsens_acc.mat"
GRAVITY = "9.81744"  # the Xsens recording's g (imu_tk's test)


def tile(k: int, folder: Path, sep: str = " ", src: Path = XSENS) -> Path:
    """The Xsens log ``src`` tiled ``k`` times (written once, reused while its size matches); the
    shift is the accelerometer log's span, so the gyroscope log tiled alike keeps its time base."""
    lines = [ln for ln in src.read_text().splitlines() if ln.strip()]
    t = np.array([float(ln.split()[0]) for ln in lines])
    rest = [sep.join(ln.split()[1:]) if sep != " " else ln.lstrip().split(None, 1)[1] for ln in lines]
    t_acc = np.loadtxt(XSENS, usecols=0)
    span = t_acc[-1] - t_acc[0] + float(np.median(np.diff(t_acc)))
    name = "xsens" if src == XSENS else src.stem
    path = folder / f"{name}_x{k}{'.csv' if sep == ',' else '.txt'}"
    if path.exists():  # written whole under another name, then renamed
        return path
    folder.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".part")
    with open(tmp, "w") as f:
        for i in range(k):
            f.write("\n".join(f"{a:.5f}{sep}{r}" for a, r in zip((t + i * span).tolist(), rest)))
            f.write("\n")
    tmp.replace(path)
    return path


#: The child that runs one measured command: its wall time, CPU (user + system of the command and
#: its descendants), peak resident set of its largest process (ru_maxrss) and the peak of the sum over
#: the command's process tree (sampled every TREE_SAMPLE_S from /proc: a run that starts worker
#: processes holds their memory too).
TREE_SAMPLE_S = 0.1
_MEASURE = """
import json, os, resource, subprocess, sys, threading, time

def tree_bytes(root):
    kids = {}
    for d in os.listdir("/proc"):
        if d.isdigit():
            try:
                with open(f"/proc/{d}/stat") as f:
                    kids.setdefault(int(f.read().rsplit(")", 1)[1].split()[1]), []).append(int(d))
            except (OSError, IndexError, ValueError):
                pass
    total, todo = 0, [root]
    while todo:
        pid = todo.pop()
        todo += kids.get(pid, [])
        try:
            with open(f"/proc/{pid}/statm") as f:
                total += int(f.read().split()[1])
        except OSError:
            pass
    return total * os.sysconf("SC_PAGE_SIZE")

t0 = time.perf_counter()
p = subprocess.Popen(sys.argv[2:], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
peak = [0]
def watch():
    while p.poll() is None:
        if os.path.isdir("/proc"):
            peak[0] = max(peak[0], tree_bytes(p.pid))
        time.sleep(float(sys.argv[1]))
threading.Thread(target=watch, daemon=True).start()
out, err = p.communicate()
wall = time.perf_counter() - t0
u = resource.getrusage(resource.RUSAGE_CHILDREN)
print(json.dumps({"wall_s": wall, "code": p.returncode, "cpu_s": u.ru_utime + u.ru_stime,
                  "err": err.strip()[-300:], "maxrss_mb": u.ru_maxrss / 1024, "tree_mb": peak[0] / 2**20}))
"""


def measured(cmd: list[str], cwd: str | Path = ROOT) -> dict:
    """Wall time, CPU, peak RSS (the largest process's, and the process tree's sampled sum) and exit
    status of one run of ``cmd`` in a child process."""
    p = subprocess.run([sys.executable, "-c", _MEASURE, str(TREE_SAMPLE_S), *cmd], capture_output=True, text=True,
                       cwd=cwd, env={**os.environ, "PYTHONPATH": str(ROOT)})
    return json.loads(p.stdout)


def imutk(exe: str, k: int, folder: Path) -> dict:
    """imu_tk's accelerometer calibration (test_imu_acc, scripts/build_imutk.sh: its test program
    without the gyroscope) on the ``k``-tile log. It reads the file whole."""
    work = tempfile.mkdtemp(prefix="imucal-imutk-")  # it writes test_imu_acc.calib into its working folder
    r = measured([str(Path(exe).resolve()), str(tile(k, folder))], cwd=work)
    cal = Path(work) / "test_imu_acc.calib"
    r["acc_calib"] = cal.read_text() if cal.exists() else None
    return r


def imutk_full(exe: str, k: int, folder: Path) -> dict:
    """imu_tk's test_imu_calib (accelerometer and gyroscope) on the ``k``-tile logs of both sensors."""
    work = tempfile.mkdtemp(prefix="imucal-imutk-")
    return measured([str(Path(exe).resolve()), str(tile(k, folder)),
                     str(tile(k, folder, src=XSENS.with_name("xsens_gyro.mat")))], cwd=work)


def calibrate(data: Path, stream: str, mode: str = "means") -> dict:
    out = tempfile.mkdtemp(prefix="imucal-bench-")
    r = measured([sys.executable, "-m", "imucal", "calibrate", "--data", str(data), "--gravity", GRAVITY,
                  "--out", out, "--no-figures", "--quiet", "--stream", stream, "--mode", mode])
    cal = Path(out) / "calibration.yaml"
    r["calibration"] = cal.read_text() if cal.exists() else None
    return r


# --- parse floors, run in a child: `bench_memory.py --child CASE FILE` ------------------------
def child(case: str, path: str) -> None:
    import csv
    import io

    if case.startswith("pandas"):
        import pandas as pd  # imported before the clock starts
    elif case.startswith("pyarrow"):
        import pyarrow as pa
        import pyarrow.csv as pc
    from imucal.data.blocks import CHUNK_BYTES

    t0 = time.perf_counter()
    n = 0
    if case in ("pandas", "pandas-csv"):
        with open(path, "rb") as f:  # blocks of whole lines, as imucal.data.blocks reads them
            carry = b""
            while True:
                data = f.read(CHUNK_BYTES)
                buf = carry + data
                cut = buf.rfind(b"\n") + 1 if data else len(buf)
                if cut:
                    a = pd.read_csv(io.BytesIO(buf[:cut]), sep="," if case == "pandas-csv" else r"\s+", header=None,
                                    dtype=np.float64, comment="#", quoting=csv.QUOTE_NONE).to_numpy()
                    n += a.shape[0]
                carry = buf[cut:]
                if not data:
                    break
    elif case in ("pyarrow-csv", "pyarrow-ws"):
        reader = pc.open_csv(path, read_options=pc.ReadOptions(autogenerate_column_names=True),
                             parse_options=pc.ParseOptions(delimiter="," if case == "pyarrow-csv" else " "),
                             convert_options=pc.ConvertOptions(column_types={f"f{i}": pa.float64() for i in range(4)}))
        for batch in reader:
            a = np.column_stack([c.to_numpy() for c in batch.columns])
            n += a.shape[0]
    elif case == "loadtxt":
        n = np.loadtxt(path).shape[0]
    elif case == "numpy-pass":  # one numpy pass over the samples in memory: the floor below parsing
        a = np.random.default_rng(0).normal(size=(int(path), 4))
        t0 = time.perf_counter()
        a.sum(axis=0)
        n = a.shape[0]
    print(json.dumps({"rows": n, "s": time.perf_counter() - t0,
                      "maxrss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))


def parse_floor(case: str, arg: str) -> dict:
    p = subprocess.run([sys.executable, __file__, "--child", case, arg], capture_output=True, text=True,
                       cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)})
    if p.returncode != 0:
        return {"error": (p.stderr.strip().splitlines() or [f"exit {p.returncode}"])[-1][:160]}
    return json.loads(p.stdout)


def shipped(runs: int) -> dict:
    ts, rss = [], []
    for _ in range(runs):
        r = calibrate(XSENS, "auto")
        ts.append(r["wall_s"])
        rss.append(r["maxrss_mb"])
    return {"median_s": statistics.median(ts), "min_s": min(ts), "runs": runs, "maxrss_mb": max(rss)}


# --- report -----------------------------------------------------------------------------------
def markdown(r: dict, cmdline: str) -> str:
    try:
        cpu = next(ln.split(":", 1)[1].strip() for ln in Path("/proc/cpuinfo").read_text().splitlines()
                   if ln.startswith("model name"))
    except (OSError, StopIteration):
        cpu = platform.machine()
    import pandas

    L = ["# Long recordings: time and memory", "",
         f"Generated by `{cmdline}` on {cpu}, {os.cpu_count()} cores, Python {platform.python_version()}, "
         f"numpy {np.__version__}, pandas {pandas.__version__}. Each run is a fresh process; memory is its peak "
         "resident set (ru_maxrss; the largest process's when it starts workers) and, in the column \"all "
         "processes\", the peak of the resident sets summed over the run's process tree (sampled every "
         f"{TREE_SAMPLE_S:g} s: the worker processes a long log is judged on count too). Do not edit by hand.", "",
         f"Load average when the runs started: {r['load'][0]:.1f} and when they ended: {r['load_end'][0]:.1f} "
         f"(1 min, {os.cpu_count()} cores). This machine is shared: with a load above the core count every wall "
         "time below is stretched by the other jobs, so read them as upper bounds; CPU (user + system time of "
         "the process) is the steadier figure.", "",
         "The Xsens MTi recording (51,175 samples, 100 Hz, 38 poses) tiled k times, time stamps continued; "
         "`imucal calibrate --data FILE --gravity 9.81744 --no-figures --quiet`. Read whole (`--stream never`, "
         "the loader of issue 6) and in chunks (`--stream always`; `auto` chooses it above 64 MB); with "
         "`--mode samples` the fit takes every static sample (kept in memory) instead of the interval means. "
         "In chunks the text is parsed once and its numbers spilled to an unnamed temporary file that the later "
         "passes read (imucal.data.stream; docs/streaming.md).", "",
         "<!-- begin:summary -->",
         "| tiles | samples | file [MB] | read | wall [s] | CPU [s] | peak RSS [MB] | all processes [MB] | "
         "bytes/sample | intervals | result |",
         "|---|---|---|---|---|---|---|---|---|---|---|"]
    for row in sorted(r["calibrate"], key=lambda row: (row["k"], row["how"] != "whole", row["how"])):
        res = "exit 0" if row["code"] == 0 else f"exit {row['code']}: {row['err'].splitlines()[-1][:80] if row['err'] else ''}"
        if row.get("same_as_whole") is not None:
            res += {"identical": "; calibration file identical to reading whole",
                    "rounding": "; calibration file as reading whole, numbers equal to 1e-12 relative "
                                "(sums over the file's blocks round in another order)"}.get(
                row["same_as_whole"], "; DIFFERS from whole")
        L.append(f"| {row['k']} | {row['samples']:,} | {row['mb']:.0f} | {row['how']} | {row['wall_s']:.1f} | "
                 f"{row['cpu_s']:.1f} | "
                 f"{row['maxrss_mb']:.0f} | {_mb(row.get('tree_mb'))} | {row['maxrss_mb'] * 2**20 / row['samples']:.0f} | "
                 f"{row.get('intervals', '')} | {res} |")
    L += flatness(r)
    if r.get("imutk"):
        L += side_by_side(r)
    s = r.get("shipped")
    if s:
        L += ["", f"Shipped recording (`data/xsens-mti-imutk/xsens_acc.mat`, 3.3 MB, read whole): median "
                  f"{s['median_s']:.3f} s over {s['runs']} runs (min {s['min_s']:.3f} s), peak {s['maxrss_mb']:.0f} MB. "
                  "pandas is imported only when a file is read in chunks."]
    L += ["<!-- end:summary -->"]
    pf = r.get("parse")
    if pf:
        L += ["", "## Parse floor and the parsers compared", "",
              f"The {r['parse_k']}-tile file ({r['parse_rows']:,} rows), all four columns to float64, nothing else; "
              "pandas in 16 MB blocks of whole lines as `imucal.data.blocks` reads. pyarrow's reader takes one "
              "single-character delimiter, so it cannot read whitespace-aligned logs like imu_tk's (leading and "
              "repeated spaces); it is timed on the same numbers written with commas.", "",
              "| parser | input | time [s] | rows/s | peak RSS [MB] |", "|---|---|---|---|---|"]
        for name, inp, x in pf:
            if "error" in x:
                L.append(f"| {name} | {inp} | {x['error']} | | |")
            else:
                L.append(f"| {name} | {inp} | {x['s']:.2f} | {x['rows'] / x['s']:.3g} | {x['maxrss_mb']:.0f} |")
    return "\n".join(L) + "\n"


def _mb(x: float | None) -> str:
    return "" if x is None else f"{x:.0f}"


def flatness(r: dict) -> list[str]:
    """Issue 30's targets for the file read in chunks: the largest file's time and peak memory, and
    the memory added per added sample between the two largest files (flat: O(intervals) plus a fixed
    buffer)."""
    rows = sorted((row for row in r["calibrate"] if row["how"] == "chunks" and row["code"] == 0), key=lambda x: x["k"])
    if len(rows) < 2:
        return []
    a, b = rows[-2], rows[-1]
    per = (b["maxrss_mb"] - a["maxrss_mb"]) * 2**20 / (b["samples"] - a["samples"])
    return ["", f"Read in chunks, {b['samples']:,} samples: {b['wall_s']:.1f} s wall, {b['cpu_s']:.1f} s CPU, peak "
                f"{b['maxrss_mb']:.0f} MB, {_mb(b.get('tree_mb'))} MB over all its processes (targets: 40 s, 400 MB). From {a['samples']:,} to {b['samples']:,} samples "
                f"the peak moved by {b['maxrss_mb'] - a['maxrss_mb']:+.0f} MB: {per:+.2f} bytes per added sample "
                "(the intervals' numbers; the rows and the moving variance are spilled, not kept)."]


def side_by_side(r: dict) -> list[str]:
    """imucal (read in chunks) beside imu_tk on the same tiled logs."""
    ours = {row["k"]: row for row in r["calibrate"] if row["how"] == "chunks"}
    L = ["", "Beside imu_tk (C++/Ceres) on the same logs: its test program `test_imu_calib` with the gyroscope file "
         "and calls removed (`test_imu_acc`, built by `scripts/build_imutk.sh`, given with `--imutk`): it reads the "
         "log whole and calibrates the accelerometer, re-fitting it for 9 static-detection thresholds. CPU is "
         "user + system time." + (" imu_tk's runs are kept from an earlier run of this script (`--resume "
                                 "--keep-imutk`: it takes minutes at 1000 tiles); imucal's are this run's."
                                 if r.get("imutk_kept") else ""), ""]
    full = r.get("imutk_full")
    if full:
        L += [f"The full `test_imu_calib` (`--imutk-full`) on the accelerometer and gyroscope logs tiled alike, "
              f"{full['k']} tiles: {full['wall_s']:.1f} s, {full['cpu_s']:.1f} s CPU, peak {full['maxrss_mb']:.0f} MB "
              f"(exit {full['code']}): its gyroscope part needs far more memory than its accelerometer part, so it "
              "is not run on the larger logs.", ""]
    L += ["| tiles | samples | imucal wall [s] | imucal CPU [s] | imucal peak RSS [MB] | imu_tk wall [s] | "
          "imu_tk CPU [s] | imu_tk peak RSS [MB] | imu_tk result |", "|---|---|---|---|---|---|---|---|---|"]
    for k, it in sorted(r["imutk"].items()):
        o = ours.get(k, {})
        res = "exit 0" if it["code"] == 0 else f"exit {it['code']}: {(it['err'].splitlines() or [''])[-1][:60]}"
        if it["code"] == 0 and not it.get("acc_calib"):
            res += ", no calibration written"
        L.append(f"| {k} | {51175 * k:,} | {o.get('wall_s', float('nan')):.1f} | {o.get('cpu_s', float('nan')):.1f} | "
                 f"{o.get('maxrss_mb', float('nan')):.0f} | {it['wall_s']:.1f} | {it['cpu_s']:.1f} | "
                 f"{it['maxrss_mb']:.0f} | {res} |")
    return L


def save_raw(r: dict, folder: Path) -> None:
    """The measurements so far, as JSON beside the tiled files (a run that is stopped keeps them)."""
    (folder / "bench_memory_raw.json").write_text(json.dumps(r, default=str, indent=1))


def compare_files(whole: str, chunks: str) -> str:
    """'identical' (every line but the creation time), 'rounding' (same keys and text, every
    number equal to 1e-12 relative) or 'differs'."""
    import yaml

    a, b = yaml.safe_load(whole), yaml.safe_load(chunks)
    a.pop("created", None)
    b.pop("created", None)
    if a == b:
        return "identical"

    def close(x, y) -> bool:
        if isinstance(x, dict) and isinstance(y, dict):
            return x.keys() == y.keys() and all(close(x[k], y[k]) for k in x)
        if isinstance(x, list) and isinstance(y, list):
            return len(x) == len(y) and all(close(u, v) for u, v in zip(x, y))
        if isinstance(x, float) and isinstance(y, float):  # equal infinities and NaNs count as equal
            return x == y or (x != x and y != y) or abs(x - y) <= 1e-12 * max(abs(x), abs(y))
        return x == y
    return "rounding" if close(a, b) else "differs"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", default="10,100,1000", help="tile counts, read in chunks")
    ap.add_argument("--whole", default="10,100", help="tile counts also read whole (--stream never)")
    ap.add_argument("--tmp", default=str(Path(tempfile.gettempdir()) / "imucal-tiles"), help="folder for the tiled files")
    ap.add_argument("--parse-k", type=int, default=100, help="tile count of the parse-floor file")
    ap.add_argument("--shipped-runs", type=int, default=7)
    ap.add_argument("--resume", action="store_true", help="keep the measurements a stopped run saved in --tmp")
    ap.add_argument("--keep-imutk", action="store_true", help="with --resume: keep only imu_tk's saved runs, "
                                                               "measure imucal afresh (the table says so)")
    ap.add_argument("--samples-mode", default="200", help="tile counts also calibrated in samples mode (chunks)")
    ap.add_argument("--imutk", help="imu_tk's test_imu_acc (scripts/build_imutk.sh), run beside on the tiled logs")
    ap.add_argument("--imutk-sizes", default="10,100,1000", help="tile counts imu_tk is run on")
    ap.add_argument("--imutk-full", help="imu_tk's test_imu_calib (accelerometer + gyroscope), run once at the "
                                         "smallest of --imutk-sizes")
    ap.add_argument("--out", default=str(ROOT / "docs" / "benchmarks_memory.md"))
    ap.add_argument("--child", nargs=2, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        child(*args.child)
        return 0
    folder = Path(args.tmp)
    raw = folder / "bench_memory_raw.json"
    r: dict = {"load": os.getloadavg(), "calibrate": []}
    if args.resume and raw.exists():  # the measurements a stopped run saved, not repeated
        r = json.loads(raw.read_text())
        r["imutk"] = {int(k): v for k, v in r.get("imutk", {}).items()}
        if args.keep_imutk:  # imucal measured afresh, imu_tk's runs (minutes) kept from the saved run
            r = {"load": os.getloadavg(), "calibrate": [], "imutk": r["imutk"], "imutk_kept": True,
                 **({"imutk_full": r["imutk_full"]} if "imutk_full" in r else {})}
    done = {(row["k"], row["how"]) for row in r["calibrate"]}
    sizes = [int(x) for x in args.sizes.split(",") if x]
    whole = {int(x) for x in args.whole.split(",") if x}
    for k in sorted(set(sizes) | whole):
        path = tile(k, folder)
        samples = 51175 * k
        results = {}
        for how in (["never"] if k in whole else []) + (["always"] if k in sizes else []):
            if (k, "whole" if how == "never" else "chunks") in done:
                continue
            print(f"calibrate x{k} {how} ...", file=sys.stderr)
            x = calibrate(path, how)
            results[how] = x
            row = {"k": k, "samples": samples, "mb": path.stat().st_size / 2**20,
                   "how": "whole" if how == "never" else "chunks", **{f: x.get(f) for f in ("wall_s", "cpu_s", "code", "err", "maxrss_mb", "tree_mb")}}
            if x["calibration"]:
                row["intervals"] = next((ln.split(":")[1].strip() for ln in x["calibration"].splitlines()
                                         if ln.strip().startswith("n_intervals:")), "")
            r["calibrate"].append(row)
            save_raw(r, folder)
        if "never" in results and "always" in results and results["never"]["calibration"]:
            r["calibrate"][-1]["same_as_whole"] = compare_files(results["never"]["calibration"],
                                                                results["always"]["calibration"])
    for k in (int(x) for x in args.samples_mode.split(",") if x):  # samples mode: every static sample kept
        if (k, "chunks, samples mode") in done:
            continue
        print(f"calibrate x{k} always, samples mode ...", file=sys.stderr)
        path = tile(k, folder)
        x = calibrate(path, "always", mode="samples")
        row = {"k": k, "samples": 51175 * k, "mb": path.stat().st_size / 2**20, "how": "chunks, samples mode",
               **{f: x.get(f) for f in ("wall_s", "cpu_s", "code", "err", "maxrss_mb", "tree_mb")}}
        if x["calibration"]:
            row["intervals"] = next((ln.split(":")[1].strip() for ln in x["calibration"].splitlines()
                                     if ln.strip().startswith("n_intervals:")), "")
        r["calibrate"].append(row)
        save_raw(r, folder)
    if args.imutk:  # last: at 1000 tiles it runs for minutes
        r["imutk"] = r.get("imutk") or {}
        for k in (int(x) for x in args.imutk_sizes.split(",") if x):
            if k in r["imutk"]:
                continue
            print(f"imu_tk x{k} ...", file=sys.stderr)
            r["imutk"][k] = imutk(args.imutk, k, folder)
            save_raw(r, folder)
        if args.imutk_full and "imutk_full" not in r:
            k = min(int(x) for x in args.imutk_sizes.split(",") if x)
            print(f"imu_tk test_imu_calib x{k} ...", file=sys.stderr)
            r["imutk_full"] = {"k": k, **imutk_full(args.imutk_full, k, folder)}
            save_raw(r, folder)
    print("shipped ...", file=sys.stderr)
    r["shipped"] = shipped(args.shipped_runs)
    print("parse floor ...", file=sys.stderr)
    txt, csvp = tile(args.parse_k, folder), tile(args.parse_k, folder, sep=",")
    r["parse_k"], r["parse_rows"] = args.parse_k, 51175 * args.parse_k
    r["parse"] = [("pandas C engine (`sep=r\"\\s+\"`)", "whitespace text", parse_floor("pandas", str(txt))),
                  ("pandas C engine (`sep=\",\"`)", "CSV", parse_floor("pandas-csv", str(csvp))),
                  ("pyarrow `open_csv` (streaming, threads)", "CSV", parse_floor("pyarrow-csv", str(csvp))),
                  ("pyarrow `open_csv` (`delimiter=\" \"`)", "whitespace text", parse_floor("pyarrow-ws", str(txt))),
                  ("numpy.loadtxt (whole file)", "whitespace text", parse_floor("loadtxt", str(txt))),
                  ("one numpy pass over the samples in memory", "float64 array",
                   parse_floor("numpy-pass", str(r["parse_rows"])))]
    r["load_end"] = os.getloadavg()
    text = markdown(r, "python scripts/bench_memory.py" + (" " + " ".join(argv) if argv else
                                                         (" " + " ".join(sys.argv[1:]) if sys.argv[1:] else "")))
    from imucal.files.output import write_text_atomic

    write_text_atomic(args.out, text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
