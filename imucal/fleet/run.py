"""Calibrating a fleet: every unit on a worker, each unit's files in DIR/<unit id>/.

A unit runs the same library path as `imucal calibrate` (imucal.report.run_files) and publishes
its files atomically (imucal.files.output). Its outcome, the SHA-256 of its inputs and the hash
of its settings go last into DIR/<unit id>/done.json: a rerun skips the units whose marker matches,
so a killed batch resumes where it stopped. A unit that fails is recorded with its one-line error
and does not stop the others.

Workers: Python's concurrent.futures (processes) by default, or a dask.distributed cluster
(``scheduler``: its address), through the same Executor interface.
"""
from __future__ import annotations

import concurrent.futures as cf
import contextlib
import hashlib
import json
import multiprocessing
import os
import signal
import time
from pathlib import Path
from typing import Any, Callable, Iterator

from imucal.errors import ImucalError, short
from imucal.files.inputs import max_data_bytes, open_regular, read_input_text
from imucal.files.output import OutputSet, write_json_atomic
from imucal.fleet.manifest import Manifest, Unit
from imucal.report.progress import progress
from imucal.report.run_files import calibrate_files, stage_files

DONE_FILE, SUMMARY_FILE = "done.json", "summary.json"
MARKER_FORMAT, MARKER_VERSION = "imucal-fleet-unit", 1
#: Unit statuses: converged, solver did not converge (files written), refused with a one-line
#: error (deterministic: kept as done), internal error (not kept: retried on the next run).
OK, NOT_CONVERGED, ERROR, INTERNAL = "ok", "not converged", "error", "internal error"
_CHUNK = 1 << 20
#: How long to try to reach a dask scheduler before giving up.
SCHEDULER_TIMEOUT = "10s"


def file_sha256(path: str) -> str:
    """SHA-256 of an input file, read through imucal.files.inputs in chunks."""
    fd, _ = open_regular(path, field="data", max_bytes=max_data_bytes())
    h = hashlib.sha256()
    try:
        with os.fdopen(fd, "rb") as f:
            for block in iter(lambda: f.read(_CHUNK), b""):
                h.update(block)
    except OSError as exc:
        raise ImucalError(f"cannot read: {exc.strerror or exc}", file=path, field="data") from None
    return h.hexdigest()


def read_marker(folder: Path) -> dict | None:
    """The unit's done marker, or None when absent or unreadable (the unit is then run again)."""
    p = folder / DONE_FILE
    if not p.is_file():
        return None
    try:
        d = json.loads(read_input_text(p, field="marker"))
    except (ImucalError, ValueError):
        return None
    if not isinstance(d, dict) or d.get("format") != MARKER_FORMAT or d.get("format_version") != MARKER_VERSION:
        return None
    return d


def calibrate_unit(unit: Unit, out: str) -> dict:
    """Calibrate one unit into ``out``/<unit id> (or skip it when its marker matches); its record."""
    t0, c0 = time.perf_counter(), time.process_time()
    folder = Path(out) / unit.id
    record: dict[str, Any] = {"format": MARKER_FORMAT, "format_version": MARKER_VERSION, "unit": unit.id,
                              "status": INTERNAL, "error": "", "inputs": unit.inputs, "input_sha256": {},
                              "settings_hash": unit.settings_hash, "seconds": 0.0, "cpu_seconds": 0.0,
                              "summary": None}
    try:
        record["input_sha256"] = {role: file_sha256(p) for role, p in unit.inputs.items()}
        prev = read_marker(folder)
        if (prev is not None and prev.get("input_sha256") == record["input_sha256"]
                and prev.get("settings_hash") == unit.settings_hash and prev.get("status") != INTERNAL):
            return {**prev, "skipped": True}
        if prev is not None:  # outdated: no marker stands beside files being replaced
            (folder / DONE_FILE).unlink(missing_ok=True)
        files = calibrate_files(unit.config, unit.config.data.gyro_path)
        if files.summary["data"].get("sha256") != record["input_sha256"]["data"]:  # the loader's own hash
            raise ImucalError("the file changed while the unit was calibrated", file=unit.config.data.path,
                              field="data", fix="run the batch again when the recording is complete")
        with OutputSet(unit.inputs.values()) as o:
            stage_files(o, folder, files, unit.config.output.figures, folder / SUMMARY_FILE)
        record.update(status=OK if files.success else NOT_CONVERGED, summary=files.summary)
    except ImucalError as exc:
        record.update(status=ERROR, error=str(exc))
    except MemoryError:
        record.update(error="out of memory")
    except Exception as exc:  # noqa: BLE001 - a bug in one unit must not stop the fleet
        record.update(error=f"{type(exc).__name__}: {short(str(exc), 200)}")
    record["seconds"] = round(time.perf_counter() - t0, 4)  # wall time on the worker
    record["cpu_seconds"] = round(time.process_time() - c0, 4)  # its CPU time (this process, all threads)
    if record["status"] != INTERNAL and record["input_sha256"]:
        write_json_atomic(folder / DONE_FILE, record)  # last: the unit is done
    return {**record, "skipped": False}


def _ignore_sigint() -> None:
    """Worker processes leave Ctrl-C to the batch, which lets running units finish."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def default_workers() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


class _DaskPool:
    """A dask.distributed Client as a concurrent.futures Executor (context manager)."""

    def __init__(self, address: str) -> None:
        try:
            from distributed import Client
        except ImportError:
            raise ImucalError("dask.distributed is not installed", field="--scheduler",
                              fix="pip install 'imucal-nlp[fleet]', or drop --scheduler to use local processes") from None
        try:
            self.client = Client(address, timeout=SCHEDULER_TIMEOUT)
        except (OSError, TimeoutError, ValueError) as exc:
            raise ImucalError(f"cannot reach the scheduler {short(address)}: {short(str(exc), 120)}",
                              field="--scheduler", fix="give a running scheduler's address, e.g. tcp://host:8786") \
                from None
        self.executor = self.client.get_executor(pure=False)

    def __enter__(self) -> cf.Executor:
        return self.executor

    def __exit__(self, *exc: object) -> None:
        self.executor.shutdown(wait=False)
        self.client.close()


def executor(workers: int | None = None, scheduler: str | None = None):
    """The Executor a batch runs on: processes, or a dask.distributed cluster."""
    if scheduler is not None:
        return _DaskPool(scheduler)
    # forkserver: workers start clean (no threads or signal handlers of the parent copied)
    ctx = multiprocessing.get_context("forkserver" if "forkserver" in multiprocessing.get_all_start_methods()
                                      else "spawn")
    return cf.ProcessPoolExecutor(max_workers=workers or default_workers(), mp_context=ctx,
                                  initializer=_ignore_sigint)


def _lost(unit: Unit, exc: BaseException) -> dict:
    """The record of a unit whose worker died (killed, out of memory): retried on the next run."""
    return {"unit": unit.id, "status": INTERNAL, "error": f"worker lost: {type(exc).__name__}: {short(str(exc), 120)}",
            "inputs": unit.inputs, "input_sha256": {}, "settings_hash": unit.settings_hash, "seconds": 0.0,
            "cpu_seconds": 0.0, "summary": None, "skipped": False}


def run_units(manifest: Manifest, out: str | Path, pool: cf.Executor,
              progress: Callable[[dict], None] | None = None) -> list[dict]:
    """Calibrate every unit of ``manifest`` on ``pool``; records in manifest order.

    On KeyboardInterrupt (Ctrl-C, SIGTERM) the units not started are cancelled, running ones
    finish and keep their files, and the interrupt is raised again.
    """
    out = str(Path(out).resolve())
    futures = {pool.submit(calibrate_unit, u, out): u for u in manifest.units}
    records: dict[str, dict] = {}
    try:
        for fut in cf.as_completed(futures):
            unit = futures[fut]
            try:
                rec = fut.result()
            except Exception as exc:  # noqa: BLE001 - a worker process died
                rec = _lost(unit, exc)
            records[unit.id] = rec
            if progress is not None:
                progress(rec)
    except KeyboardInterrupt:
        for f in futures:
            f.cancel()
        raise
    return [records[u.id] for u in manifest.units]


@contextlib.contextmanager
def progress_bar(total: int, enabled: bool | None = None) -> Iterator[Callable[[dict], None]]:
    """A progress callback: the terminal-only bar (imucal.report.progress) counting units and failures."""
    failed = 0
    with progress("units", total=total, unit="unit", enabled=enabled, delay=0, leave=True) as step:
        def on_unit(rec: dict) -> None:
            nonlocal failed
            failed += rec["status"] != OK
            step(1, note=f"{failed} not ok")

        yield on_unit
