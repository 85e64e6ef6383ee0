"""The still runs of a long log judged on worker processes (imucal.data.stream).

Judging a run (imucal.data.static.still_segment) is some hundred small numpy calls, most of its time
spent holding the GIL: threads share one core, processes use one each. The runs go to the workers in
batches of about BATCH_ROWS rows, a few batches in flight; their results come back in the order of
the runs, the same numbers as in one process (each run judged alone, by the same code).

Workers are started only for the command line (``allow_workers``: its main module is safe to import
in a fresh interpreter, a caller's script may not be) and for a log of many runs (a worker's start,
a fresh interpreter importing numpy, costs about 0.2 s of CPU); otherwise the runs are judged in the
calling process.
"""
from __future__ import annotations

import collections
import os
import signal
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from typing import TypeVar

from imucal.errors import ImucalError

#: Worker processes at most (fewer with fewer cores) ...
RUN_WORKERS = 2
#: ... used from this many runs on (about 1.3 M samples of the Xsens log: a second of judging).
POOL_RUNS = 1000
#: Rows of runs sent to a worker at a time (a batch's samples: about 2 MB of readings and times) ...
BATCH_ROWS = 1 << 16
#: ... and the batches sent ahead of the one being collected, per worker (memory: their samples).
BATCHES_IN_FLIGHT = 3
#: Seconds between a worker's checks that the process that started it is alive (killed, even by
#: SIGKILL, its workers end within this).
PARENT_CHECK_S = 0.5

T = TypeVar("T")
R = TypeVar("R")

_allowed = [False]


def allow_workers(on: bool = True) -> None:
    """Let long logs be judged on worker processes (the command line's ``main`` calls this)."""
    _allowed[0] = on


def run_workers(n_runs: int) -> int:
    """Worker processes for ``n_runs`` runs: none unless allowed, for few runs, on one core, or inside
    a daemonic process (which may not start any)."""
    if not _allowed[0] or n_runs < POOL_RUNS:
        return 0
    import multiprocessing

    if multiprocessing.current_process().daemon:
        return 0
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    return min(RUN_WORKERS, cores) if cores > 1 else 0


def batches(items: Iterable[T], rows: Callable[[T], int]) -> Iterator[list[T]]:
    """Consecutive items grouped into lists of about BATCH_ROWS rows (``rows``: an item's)."""
    batch: list[T] = []
    held = 0
    for item in items:
        batch.append(item)
        held += rows(item)
        if held >= BATCH_ROWS:
            yield batch
            batch, held = [], 0
    if batch:
        yield batch


def _watch_parent(parent: int) -> None:
    while os.getppid() == parent:
        time.sleep(PARENT_CHECK_S)
    os._exit(1)  # the process that started this worker is gone: nobody wants its results


def _start_worker(parent: int) -> None:
    """A worker leaves Ctrl-C to the process that started it (which stops the pool) and ends when
    that process is gone, whatever ended it."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    threading.Thread(target=_watch_parent, args=(parent,), name="imucal-parent-watch", daemon=True).start()


def ordered_map(fn: Callable[[T], R], items: Iterable[T], workers: int) -> Iterator[tuple[T, R]]:
    """(item, fn(item)) for every item, in order: on ``workers`` processes (``fn`` and the items
    picklable; at most BATCHES_IN_FLIGHT x workers items held), or here with none. An error in
    ``fn`` is raised here and nothing after it is started; a worker that dies is one line."""
    if workers == 0:
        for item in items:
            yield item, fn(item)
        return
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor
    from concurrent.futures.process import BrokenProcessPool

    pending: collections.deque = collections.deque()
    ctx = multiprocessing.get_context("spawn")  # clean workers: no thread or handler of the caller copied
    try:
        with ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_start_worker,
                                 initargs=(os.getpid(),)) as pool:
            try:
                for item in items:
                    pending.append((item, pool.submit(fn, item)))
                    while len(pending) > BATCHES_IN_FLIGHT * workers:
                        item0, fut = pending.popleft()
                        yield item0, fut.result()
                while pending:
                    item0, fut = pending.popleft()
                    yield item0, fut.result()
            finally:
                for _, fut in pending:  # an error or an interruption: nothing more is started
                    fut.cancel()
    except BrokenProcessPool:
        raise ImucalError("a worker process judging the still intervals ended unexpectedly (killed, or out of "
                          "memory)", field="data.stream",
                          fix="run again; give --stream never to read the file whole in one process") from None
