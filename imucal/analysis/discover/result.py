"""What a discovery found, as typed values: candidates, rounds, effects and the Discovery itself
(its words and JSON: imucal.report.discover_text)."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from imucal.analysis import stochastic as stoch
from imucal.analysis.discover.changepoint import ChangePoint
from imucal.analysis.discover.problem import label
from imucal.analysis.discover.settings import DiscoverSettings
from imucal.analysis.discover.verdict import Verdict
from imucal.model.effects import EFFECTS
from imucal.pipeline import CalibrationRun


@dataclass(frozen=True)
class Candidate:
    """One candidate of one round: an effect on an axis subset, merged into the current model."""

    name: str
    axes: tuple[int, ...]  #: the candidate's axes (merged with the same effect already in the model)
    new_axes: tuple[int, ...]  #: the coefficients it adds
    chi2_screen: float  #: linearised (Gauss-Newton) chi-square with the candidate
    extra: int = 0  #: shared free parameters it adds besides the coefficients (a new warm-up's tau)
    start: tuple[tuple[str, float], ...] = ()  #: starting values of those (the screen's best tau)
    chi2: float = math.nan  #: chi-square of the full fit (nan when only screened)
    dof: int = 0
    lr: float = math.nan  #: likelihood-ratio statistic, scaled by max(1, chi2/dof)
    p_value: float = math.nan
    p_adjusted: float = math.nan  #: family-wise p (min-p over the round's candidates)
    score: float = math.nan  #: chi2 / scale + penalty * k, for ranking
    fitted: bool = False
    converged: bool = False
    significant: bool = False

    @property
    def label(self) -> str:
        return label(self.name, self.axes)

    #: the parameters it is priced at when ranked (None: ``k``): a step's time searched over ~20 gaps gains
    #: 2-3.4 chi-square on pure noise where a warm-up's tau gains 0.6-1 (imucal.analysis.min_p.search_gain)
    priced: float | None = None

    @property
    def k(self) -> int:
        """Free parameters the candidate adds: its new coefficients and shape parameters."""
        return len(self.new_axes) + self.extra

    @property
    def price(self) -> float:
        """The parameters it is ranked at: ``k``, or more for a search that gains more on noise."""
        return float(self.k) if self.priced is None else self.priced


@dataclass(frozen=True)
class Step:
    """One round: the candidates tried, the one added (if any) and its competitors."""

    index: int
    chi2_before: float
    dof_before: int
    candidates: tuple[Candidate, ...]
    chosen: Candidate | None
    ambiguous_with: tuple[Candidate, ...] = ()
    scale: float = 1.0  #: the misfit scale used to compare candidates
    jointly_with: str | None = None  #: the other member when the chosen one came with a pair (lookahead)
    p_scan: float = math.nan  #: family-wise p of the best screened candidate (min-p over the round)


@dataclass(frozen=True)
class FoundEffect:
    """An effect the data asked for, with its fitted coefficients."""

    name: str
    axes: tuple[int, ...]
    coefficients: dict[str, float]  #: parameter name -> value
    std: dict[str, float]  #: parameter name -> standard error
    units: dict[str, str]
    reference: dict[str, float]  #: fixed references ({name}_tref [degC], {name}_t0 [s], basis constants)
    lr: float  #: the likelihood-ratio statistic when it was added
    p_value: float  #: family-wise p when it was added
    ambiguous_with: tuple[str, ...] = ()
    #: axes the term lacks that these poses cannot rule out (``axes.unresolved``): it may be there too
    unresolved_axes: tuple[int, ...] = ()
    #: a bias step's time and its uncertainty (``changepoint``)
    change_point: ChangePoint | None = None
    #: what static poses see of a cross-axis term to first order: the sum of its coefficients and its
    #: standard error (``axes.observable_sum``)
    observable_sum: tuple[float, float] | None = None

    @property
    def label(self) -> str:
        return label(self.name, self.axes)

    @property
    def axis_names(self) -> tuple[str, ...]:
        """Its axes by name (x, y, z; an angle term's phi, psi, theta)."""
        return tuple(EFFECTS[self.name].axis_names[a] for a in self.axes)


@dataclass(frozen=True)
class Discovery:
    """What ``discover`` found: the base and final runs, the rounds, the effects, the verdict."""

    base: CalibrationRun
    final: CalibrationRun
    steps: tuple[Step, ...]
    effects: tuple[FoundEffect, ...]
    verdict: Verdict
    consistent_before: bool
    consistent_after: bool
    p_before: float  #: chi-square test p of the base fit
    p_after: float
    disagreement: tuple[tuple[str, float], ...]  #: (pattern, chi-square it would remove), base fit
    notes: tuple[str, ...] = ()
    settings: DiscoverSettings = field(default_factory=DiscoverSettings)
    stochastic: "stoch.StochasticFit | None" = None  #: the REML test of the stochastic biases (final fit)
    allan: "stoch.AllanView | None" = None  #: Allan view of the longest still interval, when long enough
    #: the calibration to keep (``--out``): ``final`` refitted with the weights asked for when they are
    #: "auto" and the residual exceeds the noise (the excess then in its standard errors)
    kept: CalibrationRun | None = None
    #: a temperature sweep's calibration (imucal.thermal.run.ThermalCalibration), when the recording is one
    thermal: object | None = None
    #: each term in time or temperature weighed against a bias random walk explaining the same excess, and
    #: which the data prefer (empty when no walk rivals them)
    rivals: tuple["stoch.Rival", ...] = ()
    #: still intervals cut where their mean moved within them (imucal.analysis.hold_steps.Cut)
    holds_cut: tuple = ()

    @property
    def calibration_run(self) -> CalibrationRun:
        return self.kept if self.kept is not None else self.final

    # the gap, on interval means
    @property
    def rms_before(self) -> float:
        return float(np.sqrt(np.mean(self.base.result.residuals ** 2)))

    @property
    def rms_after(self) -> float:
        return float(np.sqrt(np.mean(self.final.result.residuals ** 2)))

    @property
    def rms_noise(self) -> float:
        """RMS the residuals would have from the noise of the means alone [m/s^2]."""
        return float(np.sqrt(np.mean(self.final.result.sigma ** 2)))

    @property
    def chi2_before(self) -> float:
        return float(self.base.result.chi2)

    @property
    def chi2_after(self) -> float:
        return float(self.final.result.chi2)
