"""A sensor's evidence, as the one fit sees it (issue 26).

The fit (imucal.solve.fit), its covariance and its observability check know a sensor only through its
description (imucal.model.sensor.SensorModel), its Parameters and one Evidence: the residuals of its kind
of evidence as functions of the free parameters, their Jacobian, each residual's noise. Two kinds exist:

- rows (imucal.solve.least_squares.RowEvidence): one residual per interval mean or sample, |a| - g for
  the accelerometer, accumulated block by block so that 10^6 samples fit in bounded memory;
- motion segments (imucal.gyro.evidence.MotionEvidence): three residual components per motion between
  still poses, R_k^T u0 - u1 after integrating the gyroscope's calibrated rate.

Every evaluator takes the free parameters ``pfree`` (in the order of Parameters.free_names) and the
values of all parameters ``pfix`` (imucal.solve.least_squares.split_parameters). A small evidence (a
Jacobian of a few thousand rows) implements ``jacobian`` and inherits the rest from JacobianEvidence.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

import numpy as np

if TYPE_CHECKING:
    from imucal.solve.observability import Determination


class EvidenceSummary(Protocol):
    """What an evidence says about the fit beyond the parameters (FitResult.summary): a typed value, put into
    words only in imucal.report (the gyroscope's: imucal.gyro.result.MotionSummary)."""


class Evidence(Protocol):
    """What the one fit needs of a sensor's evidence."""

    n_free: int  #: free parameters the evaluators take

    def residuals(self, pfree: np.ndarray, pfix: np.ndarray) -> np.ndarray:
        """Every residual (m,) at these parameter values."""

    def normal_equations(self, pfree: np.ndarray, pfix: np.ndarray, w: np.ndarray, exact: bool = False
                         ) -> tuple[float, np.ndarray, np.ndarray]:
        """1/2 sum w r^2, its gradient J^T W r and the Gauss-Newton Hessian J^T W J (+ the curvature term
        when ``exact`` and the evidence has it)."""

    def r_factor(self, pfree: np.ndarray, pfix: np.ndarray, sigma: np.ndarray) -> np.ndarray:
        """R (n_free x n_free) with R^T R = J^T diag(1/sigma^2) J (the covariance's one routine reads it)."""


class FitEvidence(Evidence, Protocol):
    """An evidence that the one fit (imucal.solve.fit.fit_evidence) takes whole: its noise, degrees of
    freedom and what to say when it leaves a parameter undetermined."""

    sigma: np.ndarray  #: (m,) noise of each residual
    dof: int  #: degrees of freedom of its chi-square
    source: str | None  #: the recording, for messages

    def observability_rows(self, pfree: np.ndarray, pfix: np.ndarray) -> np.ndarray:
        """The rows (m', n_free) whose information the observability check reads (whitened as the evidence's
        own rule wants: the noise, or the geometry alone)."""

    def require_determined(self, det: Determination) -> None:
        """Raise the one-line ImucalError naming what to record when ``det`` leaves parameters undetermined."""


class JacobianEvidence:
    """Normal equations and R factor from one Jacobian per point (``jacobian``, cached): a small evidence."""

    n_free: int
    _key: bytes | None = None
    _rj: tuple[np.ndarray, np.ndarray] = (np.zeros(0), np.zeros((0, 0)))

    def jacobian(self, pfree: np.ndarray, pfix: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Residuals (m,) and their Jacobian (m, n_free) in the parameters' units."""
        raise NotImplementedError

    def _at(self, pfree, pfix) -> tuple[np.ndarray, np.ndarray]:
        key = np.asarray(pfree, float).tobytes() + np.asarray(pfix, float).tobytes()
        if self._key != key:
            self._rj = self.jacobian(np.asarray(pfree, float), np.asarray(pfix, float))
            self._key = key
        return self._rj

    def normal_equations(self, pfree, pfix, w: np.ndarray, exact: bool = False) -> tuple[float, np.ndarray, np.ndarray]:
        r, J = self._at(pfree, pfix)
        Jw = J * w[:, None]
        return 0.5 * float(r @ (w * r)), Jw.T @ r, Jw.T @ J

    def r_factor(self, pfree, pfix, sigma: np.ndarray) -> np.ndarray:
        return np.linalg.qr(self._at(pfree, pfix)[1] / sigma[:, None], mode="r")
