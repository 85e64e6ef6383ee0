"""Structure against noise: the terms that a bias random walk explains as well are dropped, and the
stochastic biases of the final fit are tested (imucal.analysis.stochastic)."""
from __future__ import annotations

from imucal.analysis import stochastic as stoch
from imucal.analysis.discover.problem import Effects, p_noise
from imucal.analysis.discover.settings import DiscoverSettings
from imucal.pipeline import CalibrationRun


def beaten(final: CalibrationRun, found: list, effects: Effects, settings: DiscoverSettings,
           notes: list[str]) -> tuple[set[str], Effects]:
    """The terms in time that a bias random walk explains as well (imucal.analysis.stochastic.beaten_terms),
    with their notes added, and the effects without them."""
    if not found or p_noise(final.result) >= settings.alpha_noise:  # no excess left: nothing to beat
        return set(), effects
    out = stoch.beaten_terms(final, {f[0] for f in found}, settings.alpha_effect)
    notes.extend(out.values())
    return set(out), {n: ax for n, ax in effects.items() if n not in out}


def assess(final: CalibrationRun, settings: DiscoverSettings) -> "stoch.StochasticFit | None":
    """The REML test of the stochastic biases when the final fit still exceeds the noise."""
    return stoch.assess(final, settings.alpha_noise) if p_noise(final.result) < settings.alpha_noise else None
