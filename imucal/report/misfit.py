"""Words for a fit whose residuals exceed its noise (imucal.solve.misfit), for every sensor."""
from __future__ import annotations

from imucal.solve.misfit import POOR_FIT_P, ExcessResiduals


def excess_words(e: ExcessResiduals) -> str:
    """The sentence every sensor's warning starts with."""
    return (f"reduced chi-square {e.redchi:.3g} against the noise ({e.dof} dof, p < {POOR_FIT_P:g}): the residuals "
            "exceed the noise, so the model misses an effect or the noise is underestimated")
