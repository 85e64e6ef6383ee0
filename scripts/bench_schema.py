#!/usr/bin/env python3
"""What the one schema mechanism (imucal/files/schema.py) costs: start-up and time to read each file.

Writes the block ``schema-bench`` of docs/schema.md. Each import is timed in a fresh interpreter
(best of --repeat); file reads are timed in-process (median of --reads calls). CPU time is given next
to wall time, with the load average, since the machine may be shared.

    python scripts/bench_schema.py [--repeat 7] [--reads 200]
"""
from __future__ import annotations

import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from imucal.analysis.plan_file import read_plan  # noqa: E402
from imucal.analysis.simulate import load_simulation_config  # noqa: E402
from imucal.calibration.frozen import load_calibration  # noqa: E402
from imucal.calibration.gyro import from_arrays  # noqa: E402
from imucal.calibration.section import to_section  # noqa: E402
from imucal.config.run import load_config  # noqa: E402
from imucal.export.kalibr import read_kalibr_yaml  # noqa: E402
from imucal.files.output import write_text_atomic  # noqa: E402
from imucal.fleet.manifest import load_manifest  # noqa: E402

DOC = ROOT / "docs" / "schema.md"
IMPORTS = {
    "imucal.files.yamlio (PyYAML and the safe loader, which every YAML reader needs)": "import imucal.files.yamlio",
    "imucal.files.schema (standard library and imucal.errors only)": "import imucal.files.schema",
    "pydantic 2, one strict model with extra='forbid'": (
        "import pydantic\nclass A(pydantic.BaseModel):\n    model_config = pydantic.ConfigDict(extra='forbid', "
        "strict=True)\n    x: int = 0\nA(x=1)"),
}


def fresh(code: str, repeat: int) -> tuple[float, float] | None:
    """Best (wall, CPU) seconds of ``code`` in a fresh interpreter; None when it cannot run."""
    best = None
    for _ in range(repeat):
        r = subprocess.run([sys.executable, "-c", code_block(code)], capture_output=True, text=True,
                           env={**os.environ, "PYTHONPATH": str(ROOT)}, cwd=ROOT)
        if r.returncode != 0:
            return None
        w, c = json.loads(r.stdout.strip().splitlines()[-1])
        best = (w, c) if best is None or w < best[0] else best
    return best


def code_block(code: str) -> str:
    """A multi-line body timed as one block."""
    body = "\n".join("    " + ln for ln in code.splitlines())
    return ("import time, json\nw, c = time.perf_counter(), time.process_time()\nif True:\n" + body
            + "\nprint(json.dumps([time.perf_counter() - w, time.process_time() - c]))\n")


def version_time(repeat: int) -> tuple[float, float]:
    """Whole-process wall time of `imucal --version` (best of ``repeat``) and the children's CPU time."""
    best = (float("inf"), 0.0)
    for _ in range(repeat):
        c0 = os.times()
        w = time.perf_counter()
        subprocess.run([sys.executable, "-c", "from imucal.cli.main import main; main(['--version'])"],
                       capture_output=True, env={**os.environ, "PYTHONPATH": str(ROOT)}, cwd=ROOT)
        w = time.perf_counter() - w
        c1 = os.times()
        cpu = (c1.children_user - c0.children_user) + (c1.children_system - c0.children_system)
        best = min(best, (w, cpu))
    return best


def sample_files(tmp: Path) -> dict[str, tuple[Path, object]]:
    """One good file per reader, and the function that reads it."""
    cal = yaml.safe_load((ROOT / "tests" / "data" / "calibration_v1_before_rename.yaml").read_text())
    z = np.zeros(3)
    g = from_arrays(unit="rad/s", bias=z, scale=np.ones(3), misalignment=np.eye(3), gsens=np.zeros((3, 3)),
                        std={"bias": z, "scale": z, "misalignment": np.zeros((3, 3)), "gsens": np.zeros((3, 3))})
    cal = {**cal, "format_version": 3, "sensors": ["accelerometer", "gyroscope"], "gyroscope": to_section(g)}
    files = {
        "run config (configs/xsens-mti-imutk.yaml)": (ROOT / "configs" / "xsens-mti-imutk.yaml", load_config),
        "simulation (configs/simulate_example.yaml)": (ROOT / "configs" / "simulate_example.yaml",
                                                       load_simulation_config),
        "pose plan, 24 poses (JSON)": ("plan.json", json.dumps({"poses": np.eye(3).tolist() * 8}), read_plan),
        "calibration, version 2 with a gyroscope": ("cal.yaml", yaml.safe_dump(cal), load_calibration),
        "fleet manifest, 100 units": ("fleet.yaml", yaml.safe_dump(
            {"units": [{"id": f"U{i:03d}", "data": f"U{i:03d}.csv"} for i in range(100)]}), load_manifest),
        "Kalibr imu.yaml": ("imu.yaml", yaml.safe_dump(
            {"model": "scale-misalignment", "accelerometers": {"M": (np.eye(3) * 400).tolist()},
             "accelerometer_noise_density": 0.002, "update_rate": 200.0}), read_kalibr_yaml),
    }
    out = {}
    for label, spec in files.items():
        if len(spec) == 3:
            name, text, read = spec
            path = tmp / name
            path.write_text(text)
        else:
            path, read = spec
        out[label] = (path, read)
    return out


def read_times(files: dict, reads: int) -> dict[str, tuple[float, float]]:
    """Median wall and CPU seconds of one read of each file (YAML parsing included)."""
    res = {}
    for label, (path, read) in files.items():
        read(str(path))  # warm: first-call imports and caches
        walls, cpus = [], []
        for _ in range(reads):
            w, c = time.perf_counter(), time.process_time()
            read(str(path))
            walls.append(time.perf_counter() - w)
            cpus.append(time.process_time() - c)
        res[label] = (statistics.median(walls), statistics.median(cpus))
    return res


def table(repeat: int, reads: int) -> str:
    load = os.getloadavg()
    lines = [f"Measured by `python scripts/bench_schema.py --repeat {repeat} --reads {reads}` "
             f"(load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}).", "",
             "| start-up (fresh interpreter, best of runs) | wall [ms] | CPU [ms] |", "|---|---:|---:|"]
    for label, code in IMPORTS.items():
        t = fresh(code, repeat)
        lines.append(f"| import {label} | " + ("not installed | - |" if t is None
                                                 else f"{t[0] * 1e3:.1f} | {t[1] * 1e3:.1f} |"))
    w, c = version_time(repeat)
    lines.append(f"| `imucal --version` (whole process) | {w * 1e3:.1f} | {c * 1e3:.1f} |")
    lines += ["", "| reading one file (median, parsing included) | wall [ms] | CPU [ms] |", "|---|---:|---:|"]
    with tempfile.TemporaryDirectory() as tmp:
        for label, (w, c) in read_times(sample_files(Path(tmp)), reads).items():
            lines.append(f"| {label} | {w * 1e3:.2f} | {c * 1e3:.2f} |")
    return "\n".join(lines) + "\n"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--reads", type=int, default=200)
    a = ap.parse_args()
    block = table(a.repeat, a.reads)
    print(block)
    text = DOC.read_text(encoding="utf-8")
    new = re.sub(r"(<!-- begin:schema-bench -->\n).*?(<!-- end:schema-bench -->)",
                 lambda m: m.group(1) + block + m.group(2), text, flags=re.S)
    write_text_atomic(DOC, new)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
