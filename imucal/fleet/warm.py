"""What a batch's worker processes need, loaded once in the forkserver they are forked from
(imucal.fleet.workers.WORKER_PRELOAD): the calibration path's modules, and the base model's generated
numpy code and IPOPT solver, built by one small fit. Each worker then starts warm instead of paying
for its own imports and first fit (most of a small batch's fixed cost).
"""
from __future__ import annotations

import numpy as np

import imucal.fleet.run  # noqa: F401 - the workers' own module (their loop, imucal.fleet.run._worker)
from imucal.constants import STANDARD_GRAVITY
from imucal.model.parameters import base_parameters
from imucal.model.sensor import build_model
from imucal.report.run_files import calibrate_files, stage_files  # noqa: F401 - loaded for the workers
from imucal.solve.fit import FitData, fit

#: Interval means of the warm-up fit: the 6 faces, 12 edges and 8 corners of a cube.
_CUBE = np.array([v for v in np.ndindex(3, 3, 3) if v != (1, 1, 1)], float) - 1.0


def warm_up() -> None:
    """One fit of the base model (the default weights) on exact cube poses: the row functions and
    the solver for 9 unknowns are generated and kept for every later fit in this process."""
    u = _CUBE / np.linalg.norm(_CUBE, axis=1, keepdims=True)
    raw = STANDARD_GRAVITY * u + np.random.default_rng(0).normal(0.0, 1e-3, u.shape)
    params = base_parameters([0.0] * 3, [1.0] * 3, [np.pi / 2] * 3, raw_unit="m/s^2", gravity=STANDARD_GRAVITY)
    data = FitData(raw=raw, cov=np.zeros((len(raw), 0)), raw_var=np.full(raw.shape, 1e-6), group=np.arange(len(raw)),
                   mode="means", t=np.arange(len(raw)) * 10.0)
    fit(data, params, build_model(), STANDARD_GRAVITY, weights="auto")


warm_up()
