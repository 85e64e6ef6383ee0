"""Structure against noise: the terms in time or temperature are weighed against a bias random walk (those
it explains as well are dropped), and the stochastic biases of the final fit are tested
(imucal.analysis.stochastic)."""
from __future__ import annotations

from imucal.analysis import stochastic as stoch
from imucal.analysis.discover.problem import Effects, p_noise
from imucal.analysis.discover.settings import DiscoverSettings
from imucal.pipeline import CalibrationRun


def rivals(final: CalibrationRun, found: list, effects: Effects, settings: DiscoverSettings
           ) -> tuple[tuple["stoch.Rival", ...], Effects]:
    """The terms found weighed against a bias random walk
    (imucal.analysis.stochastic.walk_rivals), and the effects without those the walk explains as well."""
    if not found:  # (weighed even when the terms leave no excess, for the report: a walk may explain them as well)
        return (), effects
    names = {f[0] for f in found}
    out = stoch.walk_rivals(final, {n: ax for n, ax in effects.items() if n in names}, settings.alpha_effect,
                            excess=p_noise(final.result) < settings.alpha_noise)
    lost = {r.term for r in out if r.preferred is stoch.Preferred.WALK}
    return out, {n: ax for n, ax in effects.items() if n not in lost}


def assess(final: CalibrationRun, settings: DiscoverSettings) -> "stoch.StochasticFit | None":
    """The REML test of the stochastic biases when the final fit still exceeds the noise."""
    return stoch.assess(final, settings.alpha_noise) if p_noise(final.result) < settings.alpha_noise else None
