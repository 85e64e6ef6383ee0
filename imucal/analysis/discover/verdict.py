"""Discovery's verdict as a typed value: what explains the residual, and why the rest is not a term.

Decided once, at the end, from what the workflow found (``decide``); rendered to words only in
imucal.report.discover_text. Nothing downstream parses it: code reads its fields.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum

from imucal.solve.stochastic import StochasticFit


class Outcome(str, Enum):
    """What explains the interval means' residual."""

    CONSISTENT = "consistent"  #: the base model: the residual is at the noise level
    EXPLAINED = "explained"  #: the terms found bring the residual to the noise level
    STOCHASTIC = "stochastic"  #: no term helps; a stochastic bias explains the scatter
    TERMS_AND_STOCHASTIC = "terms_and_stochastic"  #: terms, and a stochastic bias for the rest
    PARTLY_EXPLAINED = "partly_explained"  #: terms found; the rest unexplained
    UNEXPLAINED = "unexplained"  #: neither a term nor a stochastic bias explains it


class Shortfall(str, Enum):
    """Why the residual left over is not (or not further) explained by a term of the grammar."""

    NO_CANDIDATE = "no_candidate"  #: no candidate effect is significant
    SHAPE = "shape"  #: it follows a covariate, but as no term of the grammar (the shape check)
    RANDOM_WALK = "random_walk"  #: the terms in time or temperature do not beat a bias random walk
    REFUSED = "refused"  #: the calibration refuses the model found (a parameter the poses leave undetermined)
    TOO_FEW_INTERVALS = "too_few_intervals"  #: no degrees of freedom left for another effect
    MAX_EFFECTS = "max_effects"  #: the search stopped at DiscoverSettings.max_effects


class Withheld(str, Enum):
    """Why a stochastic bias that fits the scatter is not claimed."""

    STEP = "step"  #: one step of the bias fits better (imucal.solve.stochastic.step_test)
    TEMPERATURE = "temperature"  #: the shape check found structure in temperature
    JUMP = "jump"  #: one jump between intervals is larger than a Gaussian stochastic bias allows


@dataclass(frozen=True)
class StochasticPart:
    """The stochastic biases of the verdict: named, or fitting but withheld (and why)."""

    named: tuple[str, ...]  #: bias_instability, bias_random_walk
    values: dict[str, tuple[float, float, str]]  #: {name: (value, std, unit)} of the named (or withheld) ones
    ambiguous: bool = False  #: the data cannot tell bias_instability from bias_random_walk
    withheld: Withheld | None = None
    step_at: float = math.nan  #: the time of the step that fits better [s] (``Withheld.STEP``)


@dataclass(frozen=True)
class SweepVerdict:
    """A temperature sweep's verdict (imucal.analysis.discover.sweep): its rows about their poses."""

    poses: int
    temperature_range: tuple[float, float]  #: [degC]
    rms_before: float  #: [m/s^2] RMS of the rows about their poses without temperature terms
    rms_after: float  #: with the terms found


@dataclass(frozen=True)
class Verdict:
    """Discovery's conclusion (rendered by imucal.report.discover_text.verdict_text)."""

    outcome: Outcome
    redchi: float  #: chi-square per dof of the final (noise-weighted) fit
    p: float  #: its chi-square test's p
    terms: tuple[str, ...] = ()  #: the effects kept, as labels (name[axes])
    shortfall: Shortfall | None = None  #: why the rest is not a term (outcomes other than CONSISTENT, EXPLAINED)
    shape_covariates: tuple[str, ...] = ()  #: the covariates the residual follows (``Shortfall.SHAPE``)
    max_effects: int = 0  #: the search's limit (``Shortfall.MAX_EFFECTS``)
    #: between-interval excess [m/s^2 rms] of a random bias per visit (Paule-Mandel) when no REML test ran
    excess_rms: float = math.nan
    stochastic: StochasticPart | None = None
    weights: str = "auto"  #: fit.weights of the calibration kept (auto: the excess in its standard errors)
    sweep: SweepVerdict | None = None  #: a temperature sweep's (redchi and p then those of its rows)

    @property
    def explained(self) -> bool:
        """The residual is at the noise level, or a stochastic bias accounts for the rest."""
        return self.outcome in (Outcome.CONSISTENT, Outcome.EXPLAINED, Outcome.STOCHASTIC,
                                Outcome.TERMS_AND_STOCHASTIC)

    def to_json(self) -> dict:
        def num(x: float):
            return float(x) if math.isfinite(x) else None

        s = self.stochastic
        return {"outcome": self.outcome.value, "terms": list(self.terms), "redchi": num(self.redchi),
                "p": num(self.p), "shortfall": self.shortfall.value if self.shortfall else None,
                "shape_covariates": list(self.shape_covariates), "excess_rms": num(self.excess_rms),
                "weights": self.weights,
                "stochastic": None if s is None else {
                    "named": list(s.named), "ambiguous": s.ambiguous,
                    "withheld": s.withheld.value if s.withheld else None, "step_at_s": num(s.step_at),
                    "values": {n: {"value": v, "std": num(sd), "unit": u} for n, (v, sd, u) in s.values.items()}}}


def stochastic_part(sto: StochasticFit | None, in_temperature: bool) -> StochasticPart | None:
    """The verdict's view of the REML test: what it names, or what fits but is withheld and why
    (``in_temperature``: withheld because the shape check found structure in temperature, which no
    stochastic bias of time explains)."""
    if sto is None or not (sto.named or sto.withheld):
        return None
    if sto.named:
        return StochasticPart(sto.named, sto.values(), ambiguous=sto.ambiguous)
    why = (Withheld.STEP if math.isfinite(sto.step_at) else Withheld.TEMPERATURE if in_temperature
           else Withheld.JUMP)
    return StochasticPart((), sto.values(sto.withheld), withheld=why, step_at=sto.step_at)


def decide(consistent_before: bool, consistent_after: bool, terms: tuple[str, ...], shortfall: Shortfall | None,
           redchi: float, p: float, **fields) -> Verdict:
    """The verdict from the workflow's findings; ``fields`` fill the rest of ``Verdict``."""
    sto: StochasticPart | None = fields.get("stochastic")
    if not terms and consistent_before:
        return Verdict(Outcome.CONSISTENT, redchi, p, **fields)
    if terms and consistent_after:
        return Verdict(Outcome.EXPLAINED, redchi, p, terms, **fields)
    named = sto is not None and bool(sto.named)
    if named:
        outcome = Outcome.TERMS_AND_STOCHASTIC if terms else Outcome.STOCHASTIC
    else:
        outcome = Outcome.PARTLY_EXPLAINED if terms else Outcome.UNEXPLAINED
    return Verdict(outcome, redchi, p, terms, shortfall or Shortfall.NO_CANDIDATE, **fields)
