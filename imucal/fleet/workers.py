"""Where a batch's worker processes come from: a forkserver that has loaded the calibration path
(imucal.fleet.warm) once, from which each worker is forked warm. This module imports nothing of
imucal's, so `imucal batch` can start the forkserver first thing, before its own imports: the
server's start (Python, numpy, CasADi, one fit: about 0.3 s) then overlaps everything the batch's
process does before its first unit (docs/fleet.md, "Fixed cost")."""
from __future__ import annotations

import multiprocessing
import multiprocessing.context

#: Modules the forkserver loads before it forks any worker: the calibration path and its generated
#: code (imucal.fleet.warm), loaded once per batch instead of once per worker.
WORKER_PRELOAD = ["imucal.fleet.warm"]


def worker_context() -> multiprocessing.context.BaseContext:
    """forkserver (workers start clean: no threads or signal handlers of the batch copied, and warm:
    forked from a server that has loaded WORKER_PRELOAD), else spawn."""
    if "forkserver" not in multiprocessing.get_all_start_methods():
        return multiprocessing.get_context("spawn")
    ctx = multiprocessing.get_context("forkserver")
    ctx.set_forkserver_preload(WORKER_PRELOAD)
    return ctx


def start_workers_early() -> None:
    """Start the forkserver now (it loads WORKER_PRELOAD while the batch does everything else); the
    workers are forked from it later. Nothing to do without forkserver."""
    if "forkserver" in multiprocessing.get_all_start_methods():
        from multiprocessing import forkserver

        worker_context()
        forkserver.ensure_running()
