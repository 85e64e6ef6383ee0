"""Calibrating a fleet: every unit on a worker, each unit's files in DIR/<unit id>/.

A unit runs the same library path as `imucal calibrate` (imucal.report.run_files) and publishes
its files atomically (imucal.files.output). Its outcome, the SHA-256 of its inputs and the hash
of its settings go last into DIR/<unit id>/done.json: a rerun skips the units whose marker matches,
so a killed batch resumes where it stopped. A unit that fails is recorded with its one-line error
and does not stop the others.

Workers: processes on this machine by default (``_Processes``: a worker that dies takes only its
own unit, which is retried; no worker outlives the batch, even one killed by SIGKILL), or a
dask.distributed cluster (``scheduler``: its address). Both give the units' records as they finish.
"""
from __future__ import annotations

import collections
import concurrent.futures as cf
import contextlib
import hashlib
import json
import multiprocessing
import os
import signal
import threading
import time
from dataclasses import dataclass
from multiprocessing.connection import Connection, wait
from pathlib import Path
from typing import Any, Callable, Iterator

from imucal.errors import (EXIT_INTERRUPTED, INTERRUPTING, ImucalError, interrupt_on_signals, raise_if_signalled,
                           short, signal_name)
from imucal.files.inputs import max_data_bytes, open_regular, read_input_text, unreadable
from imucal.files.output import OutputSet, remove_stale_staging, write_json_atomic
from imucal.fleet.manifest import Manifest, Unit
from imucal.fleet.workers import worker_context
from imucal.report.progress import progress

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
        raise unreadable(path, "data", exc) from None
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


def calibrate_files(*args: Any, **kw: Any) -> Any:
    """imucal.report.run_files.calibrate_files, loaded when a unit runs: the batch's own process never
    calibrates (measured start-up), and its workers have it loaded before they start (imucal.fleet.warm)."""
    from imucal.report.run_files import calibrate_files as files

    return files(*args, **kw)


def stage_files(*args: Any, **kw: Any) -> None:
    """imucal.report.run_files.stage_files, loaded as ``calibrate_files``."""
    from imucal.report.run_files import stage_files as stage

    stage(*args, **kw)


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


def _unit_record(unit: Unit, out: str) -> dict:
    """``calibrate_unit``, with an error it lets out (its marker could not be written) as the unit's record."""
    try:
        return calibrate_unit(unit, out)
    except Exception as exc:  # noqa: BLE001 - a bug in one unit must not stop the fleet
        why = str(exc) if isinstance(exc, ImucalError) else f"{type(exc).__name__}: {short(str(exc), 200)}"
        return _lost(unit, why)


def _lost(unit: Unit, error: str) -> dict:
    """The record of a unit without a result (its worker died, or its marker could not be written):
    status INTERNAL, so the next run tries it again."""
    return {"unit": unit.id, "status": INTERNAL, "error": error, "inputs": unit.inputs, "input_sha256": {},
            "settings_hash": unit.settings_hash, "seconds": 0.0, "cpu_seconds": 0.0, "summary": None,
            "skipped": False}


def default_workers() -> int:
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


#: Workers a unit may take down (killed: out of memory, a crash in native code, kill -9) before it is
#: recorded as failed. The first loss is retried on a new worker, as it is often not the unit's doing
#: (a kill from outside, the OOM killer choosing the largest of several processes); a second is.
WORKER_LOSSES = 2
#: Seconds a worker told to stop (SIGTERM: its batch was interrupted or is gone) has to remove its
#: unit's staging and exit before it is killed. The cleanup takes milliseconds; only a worker stuck
#: that long in native code is killed (the next run into its folder removes the staging it left).
WORKER_STOP_SECONDS = 5.0


def _stop_with_batch(batch_alive: Connection) -> None:
    """Stop this worker when its batch is gone, even by SIGKILL: the batch holds the only write end of
    ``batch_alive`` and never writes, so reading gives EOF exactly when the batch has ended."""
    with contextlib.suppress(EOFError, OSError):
        batch_alive.recv_bytes()
    os.kill(os.getpid(), signal.SIGTERM)  # as the batch would stop it: the unit's staging is removed ...
    time.sleep(WORKER_STOP_SECONDS)
    os._exit(EXIT_INTERRUPTED)  # ... unless it is stuck in native code: then it ends all the same


def _worker(conn: Connection, batch_alive: Connection) -> None:
    """A worker process: calibrate the units the batch sends on ``conn``, one at a time, and send each
    record back, until the batch sends None or closes its end."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the batch's to handle: it stops its workers
    interrupt_on_signals()  # SIGTERM and the others end the unit as they end `imucal calibrate`
    threading.Thread(target=_stop_with_batch, args=(batch_alive,), name="imucal-batch-watch", daemon=True).start()
    try:
        while (job := conn.recv()) is not None:
            rec = _unit_record(*job)
            raise_if_signalled()  # one that native code turned into the unit's error ends the worker all the same
            conn.send(rec)
    except (EOFError, OSError):  # the batch closed its end, or is gone
        pass
    except KeyboardInterrupt as exc:  # a signal: the unit's staging is removed; end as a caught signal does
        os._exit(128 + getattr(exc, "signum", signal.SIGINT))


def _death(exitcode: int | None) -> str:
    """How a worker process ended, in words: "killed by SIGKILL", "stopped by SIGTERM"."""
    if exitcode is not None and exitcode < 0:
        return f"killed by {signal_name(-exitcode)}"
    if exitcode is not None and exitcode - 128 in INTERRUPTING:  # caught, and ended as _worker ends
        return f"stopped by {signal_name(exitcode - 128)}"
    return f"ended with status {exitcode}"


def _deaths_text(unit: Unit, exitcodes: list[int | None]) -> str:
    """The one-line error of a unit that took WORKER_LOSSES workers down with it."""
    signalled = any(c is not None and (c < 0 or c - 128 in INTERRUPTING) for c in exitcodes)
    why = ": out of memory, a crash in native code or a kill from outside" if signalled else ""
    return (f"unit {unit.id}: its worker process died {len(exitcodes)} times "
            f"({', then '.join(map(_death, exitcodes))}){why}; the unit is tried again on the next run")


@dataclass
class _Worker:
    process: Any  #: a multiprocessing Process (forkserver or spawn)
    conn: Connection  #: the batch's end of the worker's pipe
    unit: Unit | None = None  #: the unit it is calibrating


class _Processes:
    """Worker processes on this machine, each calibrating one unit at a time (a context manager).

    A worker that dies (killed, out of memory) takes only its own unit with it: the unit is tried on
    a new worker, and after WORKER_LOSSES deaths recorded as failed, naming the signals; the other
    units go on. Leaving the block stops every worker (SIGTERM: its unit's staging is removed; SIGKILL
    after WORKER_STOP_SECONDS); a worker whose batch is gone, even by SIGKILL, stops itself
    (``_stop_with_batch``). No worker outlives its batch.
    """

    def __init__(self, workers: int) -> None:
        self.workers = workers
        self._ctx = worker_context()
        self._alive, self._alive_w = self._ctx.Pipe(duplex=False)  # the write end never leaves this process
        self._pool: list[_Worker] = []
        self._leaving: list[_Worker] = []  #: told to end (nothing left to give): joined by ``stop``

    def __enter__(self) -> "_Processes":
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _give(self, unit: Unit, out: str) -> None:
        """Send ``unit`` to an idle worker, or to a new one."""
        while True:
            w = next((w for w in self._pool if w.unit is None), None)
            if w is None:
                mine, theirs = self._ctx.Pipe()
                process = self._ctx.Process(target=_worker, args=(theirs, self._alive), name="imucal-batch-worker")
                try:
                    process.start()
                except OSError as exc:  # no memory or process slot left for another worker
                    raise ImucalError(f"cannot start a worker process: {exc.strerror or exc}", field="--workers",
                                      fix="give fewer --workers, or free memory; rerun the same command to resume") \
                        from None
                finally:
                    theirs.close()  # the worker's end lives in the worker only: its death closes it
                w = _Worker(process, mine)
                self._pool.append(w)
            try:
                w.conn.send((unit, out))
            except OSError:  # an idle worker that died (killed between two units): not the unit's doing
                self._drop(w)
                continue
            w.unit = unit
            return

    def _drop(self, w: _Worker) -> None:
        w.process.join()
        w.conn.close()
        self._pool.remove(w)

    def _collect(self, w: _Worker) -> dict | int | None:
        """The record ``w`` sent, or the exit status it died with without one (it is then dropped)."""
        try:
            if w.conn.poll():
                rec, w.unit = w.conn.recv(), None
                return rec
        except (EOFError, OSError):
            pass
        self._drop(w)
        return w.process.exitcode

    def results(self, units: list[Unit], out: str) -> Iterator[dict]:
        """Each unit's record, as the units finish."""
        queue, deaths = collections.deque(units), collections.defaultdict(list)
        while queue or any(w.unit is not None for w in self._pool):
            while queue and sum(w.unit is not None for w in self._pool) < self.workers:
                self._give(queue.popleft(), out)
            busy = [w for w in self._pool if w.unit is not None]
            ready = set(wait([w.conn for w in busy] + [w.process.sentinel for w in busy]))
            for w in busy:
                if w.conn in ready or w.process.sentinel in ready:
                    unit, got = w.unit, self._collect(w)
                    if isinstance(got, dict):
                        yield got
                        continue
                    deaths[unit.id].append(got)
                    remove_stale_staging(Path(out) / unit.id)  # what a killed worker had staged
                    if len(deaths[unit.id]) < WORKER_LOSSES:
                        queue.appendleft(unit)
                    else:
                        yield _lost(unit, _deaths_text(unit, deaths[unit.id]))
            if not queue:  # nothing left to give: idle workers may go
                for w in [w for w in self._pool if w.unit is None]:
                    with contextlib.suppress(OSError):
                        w.conn.send(None)
                    self._pool.remove(w)
                    self._leaving.append(w)

    def stop(self) -> None:
        """End every worker: an idle one is let go, a busy one told to stop (SIGTERM), then killed after
        WORKER_STOP_SECONDS (at once on a second Ctrl-C)."""
        every = self._pool + self._leaving
        try:
            for w in self._pool:
                if w.unit is None:
                    with contextlib.suppress(OSError):
                        w.conn.send(None)
                else:
                    w.process.terminate()
            deadline = time.monotonic() + WORKER_STOP_SECONDS
            for w in every:
                w.process.join(max(0.0, deadline - time.monotonic()))
        finally:
            for w in every:
                if w.process.is_alive():
                    w.process.kill()
                w.process.join()
                w.conn.close()
            self._pool.clear()
            self._leaving.clear()
            self._alive_w.close()  # after the workers: they would take its EOF for the batch's end
            self._alive.close()


class _DaskPool:
    """Units on a dask.distributed cluster (a context manager).

    The scheduler retries a unit whose worker died on another worker (its ``allowed-failures``, 3 by
    default) and then gives up on it (KilledWorker). It counts every unit that was on the dying worker,
    queued there or running beside the culprit, so: no more units are in flight than the cluster has
    threads (none waits queued on a worker), and a unit given up is submitted again, to be recorded as
    failed after WORKER_LOSSES. Interrupted or killed, the batch's client goes away and the scheduler
    forgets the units not started; units already running finish on the cluster and publish whole
    (their markers make the rerun skip them).
    """

    def __init__(self, address: str) -> None:
        try:
            from distributed import Client, KilledWorker
        except ImportError:
            raise ImucalError("dask.distributed is not installed", field="--scheduler",
                              fix="python -m pip install 'dask[distributed]' (the repository's '.[fleet]'), "
                                  "or drop --scheduler to use local processes") from None
        try:
            self.client = Client(address, timeout=SCHEDULER_TIMEOUT)
        except (OSError, TimeoutError, ValueError) as exc:
            raise ImucalError(f"cannot reach the scheduler {short(address)}: {short(str(exc), 120)}",
                              field="--scheduler", fix="give a running scheduler's address, e.g. tcp://host:8786") \
                from None
        self.executor = self.client.get_executor(pure=False)
        self._killed = KilledWorker

    def __enter__(self) -> "_DaskPool":
        return self

    def __exit__(self, *exc: object) -> None:
        self.executor.shutdown(wait=False)
        self.client.close()

    def results(self, units: list[Unit], out: str) -> Iterator[dict]:
        """Each unit's record, as the units finish."""
        queue, futures = collections.deque(units), {}
        losses: collections.Counter[str] = collections.Counter()
        try:
            while queue or futures:
                slots = max(1, sum(self.client.nthreads().values()))  # the cluster's threads now
                while queue and len(futures) < slots:
                    unit = queue.popleft()
                    futures[self.executor.submit(_unit_record, unit, out)] = unit
                done, _ = cf.wait(list(futures), return_when=cf.FIRST_COMPLETED)
                for fut in done:
                    unit = futures.pop(fut)
                    try:
                        yield fut.result()
                        continue
                    except Exception as exc:  # noqa: BLE001 - its workers died (KilledWorker), or the cluster failed
                        error = exc
                    remove_stale_staging(Path(out) / unit.id)  # what its killed workers had staged (if seen here)
                    losses[unit.id] += 1
                    if isinstance(error, self._killed) and losses[unit.id] < WORKER_LOSSES:
                        queue.appendleft(unit)
                    else:
                        yield _lost(unit, f"unit {unit.id}: worker lost ({losses[unit.id]} times): "
                                          f"{type(error).__name__}: {short(str(error), 120)}")
        finally:  # interrupted: the units not started are cancelled
            for f in futures:
                f.cancel()


def executor(workers: int | None = None, scheduler: str | None = None) -> _Processes | _DaskPool:
    """Where a batch runs its units: worker processes here, or a dask.distributed cluster."""
    if scheduler is not None:
        return _DaskPool(scheduler)
    return _Processes(workers or default_workers())


def run_units(manifest: Manifest, out: str | Path, pool: _Processes | _DaskPool,
              progress: Callable[[dict], None] | None = None) -> list[dict]:
    """Calibrate every unit of ``manifest`` on ``pool`` (``executor``'s); records in manifest order.

    On KeyboardInterrupt (Ctrl-C, SIGTERM, SIGHUP, ...) the units not started are cancelled and the
    interrupt is raised again; leaving the pool's block stops the running ones (their staging removed).
    """
    out = str(Path(out).resolve())
    records: dict[str, dict] = {}
    for rec in pool.results(list(manifest.units), out):
        records[rec["unit"]] = rec
        if progress is not None:
            progress(rec)
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
