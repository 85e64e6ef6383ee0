"""Issue 25, processes and signals.

Every signal that would end a run (SIGHUP, SIGQUIT, SIGUSR1, ...) ends it as SIGINT and SIGTERM do:
staged outputs removed, the old set put back when it lands while a set is placed, one line naming
the signal, exit status 130; an ignored one stays ignored. A batch's workers die with it, even when
it is killed with SIGKILL, and leave no half-written unit; a killed worker costs only its own unit,
which is retried once; `imucal batch` run again finishes the rest.

Units are made to kill or hang their worker by a test-only sitecustomize (HOOK) that the worker
processes import at start-up: the product has no test hook.
"""
from __future__ import annotations

import csv
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import psutil
import pytest

from conftest import write_simulation
from imucal.analysis.simulate import load_simulation_config, si_sensor, cube_directions
from imucal.errors import EXIT_INTERRUPTED, INTERRUPTING, signal_name
from imucal.fleet.population import draw_fleet, write_fleet
from imucal.fleet.run import DONE_FILE

ROOT = Path(__file__).resolve().parents[1]
N_UNITS = 8
#: A deadline for a process to end, not a measured time: a run takes seconds; this only stops a hang.
DEADLINE = 120

#: Imported by every Python process started with the test's environment (batch, forkserver, workers,
#: dask workers): units named in KILL_ALWAYS / KILL_ONCE kill their worker with SIGKILL once their files
#: are staged (always / on the first try); units in HANG wait there until the worker is stopped.
HOOK = '''
import os
if os.environ.get("IMUCAL_TEST_HOOK"):
    import signal, time
    from pathlib import Path
    import imucal.fleet.run as _run

    _marks, _real = Path(os.environ["IMUCAL_TEST_HOOK"]), _run.stage_files

    def _ids(name):
        return [u for u in os.environ.get(name, "").split(",") if u]

    def stage_files(o, folder, *args, **kw):
        _real(o, folder, *args, **kw)
        unit = Path(folder).name
        first = not (_marks / ("killed-" + unit)).exists()
        if unit in _ids("KILL_ALWAYS") or (unit in _ids("KILL_ONCE") and first):
            (_marks / ("killed-" + unit)).touch()
            os.kill(os.getpid(), signal.SIGKILL)
        if unit in _ids("HANG"):
            (_marks / ("hanging-" + unit)).touch()
            time.sleep(3600)

    _run.stage_files = stage_files
'''

#: Runs `imucal ARGS` as the program, with SIGNAL sent to itself at WHEN: "staging" (as its first staging
#: folder is made) or "publishing" (once the first new file of the set is in place); "ignored" starts it
#: with the signal ignored, as nohup does with SIGHUP.
DRIVER = '''
import os, signal, sys, tempfile
import imucal.files.output as output
from imucal.cli.main import main

sig, when, mode = int(sys.argv[1]), sys.argv[2], sys.argv[3]
signal.signal(sig, signal.SIG_IGN if mode == "ignored" else signal.SIG_DFL)  # whatever the test runner had
if when == "staging":
    real_mkdtemp = tempfile.mkdtemp
    def mkdtemp(*a, **k):
        d = real_mkdtemp(*a, **k)
        os.kill(os.getpid(), sig)
        return d
    output.tempfile.mkdtemp = mkdtemp
else:
    real_replace, moved = os.replace, []
    def replace(a, b):
        real_replace(a, b)
        moved.append(b)
        if len(moved) == 2:  # the old calibration.yaml to its backup, then the new one in place
            os.kill(os.getpid(), sig)
    output.os.replace = replace
sys.argv = ["imucal", *sys.argv[4:]]
raise SystemExit(main())
'''


def _env(tmp_path: Path, **hooks: str) -> dict[str, str]:
    """The environment of a subprocess: this checkout, one BLAS thread, and the HOOK with ``hooks``."""
    hook_dir, marks = tmp_path / "hook", tmp_path / "marks"
    hook_dir.mkdir(exist_ok=True)
    marks.mkdir(exist_ok=True)
    (hook_dir / "sitecustomize.py").write_text(HOOK)
    env = {k: v for k, v in os.environ.items() if k not in ("KILL_ALWAYS", "KILL_ONCE", "HANG")}
    return {**env, "PYTHONPATH": f"{hook_dir}{os.pathsep}{ROOT}", "OPENBLAS_NUM_THREADS": "1",
            "IMUCAL_TEST_HOOK": str(marks), **hooks}


def _leftovers(root: Path) -> list[Path]:
    """Staging folders, backups of a set being placed and temporary files under ``root``."""
    return [p for p in root.rglob("*") if p.name.startswith((".imucal-", ".previous-")) or p.name.endswith(".tmp")]


def _one_line(err: str, *parts: str) -> None:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("imucal: "), err
    for p in parts:
        assert p in lines[0], (p, err)


# --- every terminating signal is an interruption --------------------------------------------------

def test_the_signals_that_end_a_run():
    for name in ("SIGHUP", "SIGINT", "SIGQUIT", "SIGUSR1", "SIGUSR2", "SIGALRM", "SIGTERM", "SIGXCPU", "SIGPWR"):
        assert getattr(signal, name) in INTERRUPTING, name
    for name in ("SIGKILL", "SIGSTOP", "SIGSEGV", "SIGCHLD", "SIGWINCH", "SIGCONT", "SIGTSTP"):
        assert getattr(signal, name) not in INTERRUPTING, name
    assert signal_name(signal.SIGRTMIN + 2) == "SIGRTMIN+2" and signal_name(signal.SIGHUP) == "SIGHUP"


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> Path:
    import numpy as np

    path = tmp_path_factory.mktemp("rec") / "rec.csv"
    write_simulation(path, si_sensor(np.random.default_rng(25)), cube_directions(), seed=25)
    return path


def _driven(tmp_path: Path, recording: Path, sig: int, when: str, mode: str = "caught") -> subprocess.CompletedProcess:
    (tmp_path / "driver.py").write_text(DRIVER)
    return subprocess.run([sys.executable, str(tmp_path / "driver.py"), str(int(sig)), when, mode, "calibrate",
                           "--data", str(recording), "--out", "out", "--no-figures", "--quiet"],
                          cwd=tmp_path, env={**os.environ, "PYTHONPATH": str(ROOT), "OPENBLAS_NUM_THREADS": "1"},
                          capture_output=True, text=True, timeout=DEADLINE)


@pytest.mark.parametrize("name", ["SIGHUP", "SIGQUIT", "SIGUSR1", "SIGUSR2", "SIGALRM", "SIGXCPU", "SIGTERM",
                                  "SIGRTMIN"])
def test_any_terminating_signal_removes_the_staged_outputs(tmp_path, recording, name):
    sig = getattr(signal, name)
    r = _driven(tmp_path, recording, sig, "staging")
    assert r.returncode == EXIT_INTERRUPTED, r.stderr
    _one_line(r.stderr, f"imucal: terminated by {signal_name(sig)}; nothing was written")
    assert not (tmp_path / "out").exists() and not _leftovers(tmp_path)


@pytest.mark.parametrize("name", ["SIGHUP", "SIGUSR1"])
def test_any_terminating_signal_while_a_set_is_placed_puts_the_old_set_back(tmp_path, recording, name):
    out = tmp_path / "out"
    out.mkdir()
    old = {f: f"old {f}" for f in ("calibration.yaml", "report.txt", "report.html")}
    for f, text in old.items():
        (out / f).write_text(text)
    r = _driven(tmp_path, recording, getattr(signal, name), "publishing")
    assert r.returncode == EXIT_INTERRUPTED, r.stderr
    _one_line(r.stderr, f"terminated by {name}; nothing was written")
    assert {p.name: p.read_text() for p in out.iterdir()} == old
    assert not _leftovers(tmp_path)


def test_an_ignored_signal_stays_ignored(tmp_path, recording):
    """`nohup imucal ...`: SIGHUP is ignored from the start; the run completes and publishes."""
    out = tmp_path / "out"
    out.mkdir()
    (out / "calibration.yaml").write_text("old")
    r = _driven(tmp_path, recording, signal.SIGHUP, "publishing", "ignored")
    assert r.returncode == 0, r.stderr
    assert (out / "calibration.yaml").read_text().startswith("format: imucal-calibration")
    assert not _leftovers(tmp_path)


# --- batches: workers die with their batch; a killed worker costs only its unit --------------------

@pytest.fixture(scope="module")
def fleet(tmp_path_factory) -> Path:
    """N_UNITS simulated units (no figures: fast): the manifest's path."""
    d = tmp_path_factory.mktemp("fleet")
    cfg = load_simulation_config(str(ROOT / "configs" / "simulate_fleet.yaml"))
    return write_fleet(draw_fleet(cfg, N_UNITS), d / "sim", [], settings={"output": {"figures": False}})


def _ids(manifest: Path) -> list[str]:
    import yaml

    return [u["id"] for u in yaml.safe_load(manifest.read_text())["units"]]


def _default_signals() -> None:
    """In the child before exec: the dispositions of a fresh shell's command, whatever the test runner's
    (`nohup pytest` ignores SIGHUP; a job started with & ignores SIGINT)."""
    for s in INTERRUPTING:
        signal.signal(s, signal.SIG_DFL)


def _batch(manifest: Path, out: Path, env: dict[str, str]) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "imucal", "batch", str(manifest), "--out", str(out),
                             "--workers", "2", "--no-figures"], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, preexec_fn=_default_signals)


def _table(out: Path) -> dict[str, dict]:
    with open(out / "fleet.csv", newline="") as f:
        return {r["unit"]: r for r in csv.DictReader(f)}


def test_how_a_worker_died_is_said_in_words():
    from imucal.fleet.manifest import Unit
    from imucal.fleet.run import _death, _deaths_text

    assert [_death(c) for c in (-9, 128 + 15, 1)] == ["killed by SIGKILL", "stopped by SIGTERM", "ended with status 1"]
    unit = Unit("u7", None, "")
    assert _deaths_text(unit, [-9, 143]) == ("unit u7: its worker process died 2 times (killed by SIGKILL, then stopped "
                                             "by SIGTERM): out of memory, a crash in native code or a kill from outside; "
                                             "the unit is tried again on the next run")
    assert "out of memory" not in _deaths_text(unit, [1, 1])  # a worker that could not start: no signal to blame


def _units_consistent(out: Path, ids: list[str]) -> set[str]:
    """Every unit folder holds a whole set of files or none (its marker last); the units done."""
    sets = {u: {p.name for p in (out / u).iterdir()} if (out / u).is_dir() else set() for u in ids}
    done = {u for u, names in sets.items() if DONE_FILE in names}
    assert done, sets
    whole = sets[next(iter(done))]
    for u, names in sets.items():
        assert names in (set(), whole, whole - {DONE_FILE}), (u, names, whole)
    return done


def _resume(manifest: Path, out: Path, done: set[str]) -> None:
    r = subprocess.run([sys.executable, "-m", "imucal", "batch", str(manifest), "--out", str(out), "--workers", "2",
                        "--no-figures"], env={**os.environ, "PYTHONPATH": str(ROOT)}, capture_output=True, text=True,
                       timeout=DEADLINE)
    assert r.returncode == 0, r.stderr
    assert f"({len(done)} skipped: already done)" in r.stdout, r.stdout
    assert all(row["status"] == "ok" for row in _table(out).values())


def test_a_killed_worker_costs_only_its_unit(fleet, tmp_path):
    """One unit's worker is killed once (retried on a new worker: ok), another's every time (failed
    after two, naming the unit and the signal, and tried again by the next run); the rest finish."""
    ids = _ids(fleet)
    once, always = ids[1], ids[4]
    out = tmp_path / "res"
    p = _batch(fleet, out, _env(tmp_path, KILL_ONCE=once, KILL_ALWAYS=always))
    stdout, stderr = p.communicate(timeout=DEADLINE)
    assert p.returncode == 0, stderr
    table = _table(out)
    assert {u: r["status"] for u, r in table.items()} == {u: "internal error" if u == always else "ok" for u in ids}
    error = table[always]["error"]
    assert f"unit {always}: its worker process died 2 times (killed by SIGKILL, then killed by SIGKILL)" in error
    assert "\n" not in error and f"{always}: fail: unit {always}" in stdout
    assert (tmp_path / "marks" / f"killed-{once}").exists()  # it was killed, then retried
    assert not _leftovers(out)  # the killed workers' staging is removed
    assert not (out / always).exists() or not any((out / always).iterdir())
    _resume(fleet, out, _units_consistent(out, ids))


@pytest.mark.parametrize("name", ["SIGKILL", "SIGTERM", "SIGINT", "SIGHUP"])
def test_workers_die_with_their_batch(fleet, tmp_path, name):
    """The batch is stopped while two units sit staged in its two workers and the rest wait: no process
    of it outlives it (nor holds its stdout), the two leave nothing, the finished stay; a rerun finishes."""
    ids = _ids(fleet)
    hang = ids[2:4]
    out = tmp_path / "res"
    p = _batch(fleet, out, _env(tmp_path, HANG=",".join(hang)))
    deadline = time.monotonic() + DEADLINE
    while not all((tmp_path / "marks" / f"hanging-{u}").exists() for u in hang):
        assert p.poll() is None and time.monotonic() < deadline, p.communicate()
        time.sleep(0.05)
    family = psutil.Process(p.pid).children(recursive=True)
    assert len([c for c in family if c.is_running()]) >= 2  # two workers at least (and a forkserver)
    p.send_signal(getattr(signal, name))
    stdout, stderr = p.communicate(timeout=DEADLINE)  # returns once nobody holds its stdout
    _, alive = psutil.wait_procs(family, timeout=DEADLINE)
    assert not alive, [(c.pid, c.cmdline()) for c in alive]
    if name == "SIGKILL":
        assert p.returncode == -signal.SIGKILL
    else:
        assert p.returncode == EXIT_INTERRUPTED, stderr
        what = "interrupted" if name == "SIGINT" else f"terminated by {name}"
        _one_line(stderr, f"imucal: {what}; batch stopped: finished units are kept in {out}; rerun the same command "
                          "to resume")
    assert not _leftovers(out)
    done = _units_consistent(out, ids)
    assert not done & set(hang) and not any((out / u).is_dir() and any((out / u).iterdir()) for u in hang)
    _resume(fleet, out, done)


def test_dask_a_killed_worker_costs_only_its_unit(fleet, tmp_path, monkeypatch, run_cli):
    """On a dask cluster the scheduler retries a unit whose worker died elsewhere and then gives up
    (KilledWorker) on it, and on any unit that shared a dying worker with it: those are submitted again
    and finish; the unit that kills its workers is recorded, named, after two such losses."""
    import distributed  # the test extra (imucal-nlp[fleet] for users)
    import dask

    ids = _ids(fleet)
    always = ids[3]
    for k, v in _env(tmp_path, KILL_ALWAYS=always).items():
        monkeypatch.setenv(k, v)  # the cluster's worker processes start with the hook
    out = tmp_path / "dask"
    with dask.config.set({"distributed.scheduler.allowed-failures": 1}), \
            distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                                     silence_logs=50) as cluster:
        r = run_cli(["batch", fleet, "--out", out, "--scheduler", cluster.scheduler_address, "--no-figures"])
    assert r.code == 0, r.err
    table = _table(out)
    expected = {u: "internal error" if u == always else "ok" for u in ids}
    assert {u: row["status"] for u, row in table.items()} == expected, \
        {u: row["error"] for u, row in table.items() if row["error"]}
    assert f"unit {always}: worker lost (2 times): KilledWorker" in table[always]["error"]
    for k in ("IMUCAL_TEST_HOOK", "KILL_ALWAYS"):
        monkeypatch.delenv(k)
    r = run_cli(["batch", fleet, "--out", out, "--workers", "2", "--no-figures"])  # the rerun finishes it
    assert r.code == 0 and f"({len(ids) - 1} skipped: already done)" in r.out, r.err
    assert all(row["status"] == "ok" for row in _table(out).values())
    assert not _leftovers(out)  # what the killed cluster workers had staged: removed by the rerun at the latest


def test_a_worker_that_cannot_start_is_one_line(fleet, tmp_path, run_cli, unchanged, monkeypatch):
    import errno
    import multiprocessing.process

    def no_slot(self):
        raise OSError(errno.EAGAIN, "Resource temporarily unavailable")

    monkeypatch.setattr(multiprocessing.process.BaseProcess, "start", no_slot)
    with unchanged(tmp_path):
        r = run_cli(["batch", fleet, "--out", tmp_path / "res", "--workers", "2", "--no-figures"])
    assert r.code == 2 and r.out == ""
    _one_line(r.err, "imucal: error: --workers: cannot start a worker process: Resource temporarily unavailable "
                     "(fix: give fewer --workers, or free memory; rerun the same command to resume)")
