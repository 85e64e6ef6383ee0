"""When a fit's residuals exceed its noise: one rule for every sensor's fit (issue 25).

A typed value, decided here; its words are written in imucal.report.misfit. The accelerometer
tests its chi-square against the noise of the interval means (imucal.pipeline.fit_warnings), the
gyroscope its chi-square against the static directions' noise and the angle random walk
(imucal.gyro.result.excess); the HTML verdict applies the same rule.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from imucal.solve.stats import chi2_sf

#: A fit whose chi-square p-value is below POOR_FIT_P and reduced chi-square above POOR_FIT_REDCHI
#: is flagged: the residuals exceed the noise (an effect the model misses, or excess noise).
POOR_FIT_P, POOR_FIT_REDCHI = 1.0e-3, 2.0


@dataclass(frozen=True)
class ExcessResiduals:
    """A fit's residuals exceed its noise: reduced chi-square above POOR_FIT_REDCHI, p below POOR_FIT_P."""

    chi2: float  #: chi-square against the noise
    dof: int
    p_value: float  #: P(chi-square(dof) > chi2)

    @property
    def redchi(self) -> float:
        return self.chi2 / self.dof


def excess_residuals(chi2: float, dof: int) -> ExcessResiduals | None:
    """The excess, or None when chi-square on ``dof`` is consistent with the noise (or cannot be tested)."""
    if dof <= 0 or not math.isfinite(chi2):
        return None
    p = chi2_sf(chi2, dof)
    return ExcessResiduals(float(chi2), int(dof), p) if chi2 / dof > POOR_FIT_REDCHI and p < POOR_FIT_P else None
