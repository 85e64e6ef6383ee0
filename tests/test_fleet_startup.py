"""A batch's fixed cost (issue 30): its own process never loads the calibration path, and its workers
are forked warm from a forkserver that has loaded it and fitted once (imucal.fleet.warm). The time
itself is measured by scripts/bench_fleet.py, never here."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

from imucal.analysis.simulate import load_simulation_config
from imucal.fleet.population import draw_fleet, write_fleet
from imucal.fleet.workers import WORKER_PRELOAD, worker_context

ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(ROOT), "OPENBLAS_NUM_THREADS": "1"}


def _run(code: str, cwd: Path) -> list:
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=cwd, env=ENV, timeout=300)
    assert p.returncode == 0, p.stderr
    return json.loads(p.stdout.strip().splitlines()[-1])


def _batch(tmp_path: Path, units: int, before: str, result: str) -> list:
    """Runs `imucal batch` on ``units`` simulated units in a fresh interpreter after the lines ``before``;
    returns [its exit code, the value of the expression ``result``]."""
    cfg = load_simulation_config(str(ROOT / "configs" / "simulate_fleet.yaml"))
    manifest = write_fleet(draw_fleet(cfg, units, 0, 0), tmp_path / "sim", [], settings={"output": {"figures": False}})
    code = ("import json, sys\n" + before + "from imucal.cli.main import main\n"
            f"rc = main(['batch', {str(manifest)!r}, '--out', {str(tmp_path / 'out')!r}, '--no-figures', "
            f"'--workers', '1'])\nprint(json.dumps([rc, {result}]))")
    return _run(code, tmp_path)


def test_the_batch_process_never_loads_the_calibration_path(tmp_path):
    """The batch reads the manifest, hands out units and writes the report: no CasADi, no pipeline, and
    no pandas (fleet.parquet is built without it: imucal.fleet.parquet)."""
    rc, mods = _batch(tmp_path, 2, "", "sorted(sys.modules)")
    assert rc == 0 and (tmp_path / "out" / "fleet.csv").exists()
    assert {"casadi", "imucal.pipeline", "imucal.report.run_files", "imucal.solve.fit", "pandas"}.isdisjoint(mods)
    assert (tmp_path / "out" / "fleet.parquet").exists() or "pyarrow" not in mods


def test_workers_are_forked_warm(tmp_path):
    """The forkserver loads imucal.fleet.warm before it forks a worker; loaded, that module leaves the
    base model's generated code and IPOPT solver built, so a unit's fit builds nothing more."""
    ctx = worker_context()
    if ctx.get_start_method() == "forkserver":
        assert WORKER_PRELOAD == ["imucal.fleet.warm"]
    cfg = load_simulation_config(str(ROOT / "configs" / "simulate_fleet.yaml"))
    manifest = write_fleet(draw_fleet(cfg, 1, 0, 0), tmp_path / "sim", [], settings={"output": {"figures": False}})
    code = ("import json\nimport imucal.fleet.warm\nfrom imucal.solve import least_squares as lsq\n"
            "from imucal.fleet.manifest import load_manifest\nfrom imucal.pipeline import calibrate_accelerometer\n"
            "before = (lsq.row_functions.cache_info().misses, lsq._solver.cache_info().misses)\n"
            f"run = calibrate_accelerometer(load_manifest({str(manifest)!r}).units[0].config)\n"
            "after = (lsq.row_functions.cache_info().misses, lsq._solver.cache_info().misses)\n"
            "print(json.dumps([before, after, run.result.success]))")
    before, after, ok = _run(code, tmp_path)
    assert ok and min(before) >= 1 and after == before


def test_the_workers_server_starts_before_the_batch_loads_numpy(tmp_path):
    """The forkserver (Python, numpy, CasADi and one fit: about 0.3 s) starts before the batch's own
    imports, so the two overlap on a machine with a free core (the fixed cost, docs/fleet.md)."""
    rc, seen = _batch(tmp_path, 1, "import imucal.fleet.workers as w\nseen = []\nstart = w.start_workers_early\n"
                      "w.start_workers_early = lambda: (seen.append(sorted({'numpy', 'yaml'} & set(sys.modules))), "
                      "start())\n", "seen")
    assert rc == 0 and seen == [[]]
