"""Effect discovery: find where the paper's model and the data disagree, name the effect, add it.

The workflow (``discover``), on interval means:

1. Fit the base model (the paper's nine parameters, plus any effects the config already lists).
   Each interval mean carries its own noise (``Intervals.mean_std``, from the interval's scatter),
   propagated to sigma_k of the residual |a_k| - g. If chi2 = sum (r_k / sigma_k)^2 is
   consistent with chi-square(dof) (upper-tail p >= ``alpha_noise``), stop: nothing to explain.
2. Show where they disagree: the residual against time, temperature, orientation and axis; and,
   for each candidate effect on each axis, how much of the chi-square its pattern would remove
   (the linearised score below).
3. Candidates: every effect of the library on every non-empty axis subset (x, y, z, xy, xz, yz,
   xyz), merged with effects already in the model. Each is screened by a Gauss-Newton step from
   the current fit (the score, or Lagrange-multiplier, approximation of its chi-square), and the
   most promising ones are fitted in full (one IPOPT NLP each, warm-started).
   A candidate c with k_c new coefficients is significant when its likelihood-ratio statistic
       LR_c = (chi2_current - chi2_c) / max(1, chi2_c / dof_c)
   has a family-wise p below ``alpha_effect``: P(min over the round's candidates of p_c' <= p_c),
   p_c = P(chi2(k_c) > LR_c), from the joint null of the screened statistics
   (``imucal.analysis.min_p``; Bonferroni p_c * M overstated the overlapping candidates'
   multiplicity). A round also runs when the omnibus test passes but one screened candidate
   stands out at the stricter family-wise level ``alpha_scan``, which it must then also pass. The division by the remaining misfit is the honest part: when the noise of the
   means is underestimated (real sensors, chi2/dof >> 1 for reasons no candidate explains) an
   effect must remove a share of the misfit, not merely a few "sigmas" of an optimistic sigma.
   Among significant candidates the one with the lowest chi2_c / scale + penalty * k_c wins
   (``penalty`` = chi-square(1) at p = 0.01 per coefficient, so an axis joins only when it earns
   its coefficient). A non-nested competitor (another effect, or disjoint axes) within
   ``ambiguity`` of the winner is reported as ambiguous: the data cannot tell them apart.
4. Add the winner, refit, and repeat while the residual still disagrees with the noise.
   If no candidate is significant and the residual still disagrees, the verdict says so:
   "disagreement not explained by any candidate". No effect is invented.

The result (``Discovery``) holds the base and final calibration runs, every candidate's score,
the effects found with coefficients, standard errors and units, and the gap before and after.
"""
from __future__ import annotations

import dataclasses
import itertools
import math
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from imucal.config.run import EffectSpec, RunConfig
from imucal.model.effects import (AXIS_NAMES, EFFECTS, MIN_DOF, MIN_TEMPERATURE_SPREAD, AxisEffect, Term, make_effect,
                                  fit_to_data, prepare_parameters, temperature_spread)
from imucal.solve.f_test import f_sf
from imucal.analysis import stochastic as stoch
from imucal.analysis.min_p import MinPNull, min_p_null
from imucal.analysis.pair_screen import pair_chi2
from imucal.solve.stats import between_excess, chi2_sf, power_chi2_1
from imucal.errors import ImucalError
from imucal.solve.fit import FitData, FitResult, fit, jacobian_rows

from imucal.model.parameters import BASE_NAMES
from imucal.model.sensor import build_model
from imucal.pipeline import CalibrationRun, calibrate, fit_data, make_parameters, observability

#: chi-square(1) upper quantiles at p = 1e-3 and 1e-2.
CHI2_1_P1E3 = 10.828
#: The price of one more coefficient when ranking candidates and pruning axes: an axis joins a
#: term (or stays in it) when it removes more than chi-square(1) at p = 0.01. Significance is the
#: family-wise test, not this; the price only chooses among significant models (a clean axis joins
#: a true term in ~1 % of cases, a true axis of a weak term is kept more often than at p = 1e-3).
CHI2_1_P1E2 = 6.635
#: Extra room [chi-square] when choosing which screened candidates to fit in full for the
#: ambiguity check (the Gauss-Newton screen matches full fits to ~0.1 on simulated data).
_SCREEN_SLACK = 5.0
#: An axis a found term lacks counts as ruled out when a coefficient there as large as the term's
#: largest would be kept (removes more than ``penalty``) at least this often (``_unresolved``).
RESOLVED_POWER = 0.9
#: Warm-up time constants screened, as fractions of the recording's last interval time: the
#: screen is linear in the amplitudes only, so tau is profiled on this grid and the full fit
#: starts from the best one.
TAU_GRID = (0.03, 0.06, 0.12, 0.25, 0.5)


@dataclass(frozen=True)
class DiscoverSettings:
    """Thresholds of the discovery workflow (all dimensionless)."""

    candidates: tuple[str, ...] = tuple(EFFECTS)  #: effect names to try
    alpha_noise: float = 1e-3  #: chi-square test: p below this means "residual disagrees with the noise"
    alpha_effect: float = 1e-3  #: family-wise level for adding an effect (min-p over a round's candidates)
    #: family-wise level when the omnibus chi-square test passes: a round then runs only when one
    #: candidate stands out at this stricter level (the two paths together keep clean data clean)
    alpha_scan: float = 1e-4
    penalty: float = CHI2_1_P1E2  #: chi-square per added coefficient when ranking candidates and pruning axes
    ambiguity: float = 10.0  #: competitors within this (scaled chi-square) are "cannot tell apart"
    max_effects: int = 3  #: effects added at most
    full_fits: int = 4  #: candidates fitted in full per round (best by the screening score)
    lookahead: int = 3  #: when no single candidate passes, pairs starting from this many are tried

    def __post_init__(self) -> None:
        unknown = [c for c in self.candidates if c not in EFFECTS]
        if unknown:
            raise ImucalError(f"unknown effect {unknown[0]!r}", field="candidates",
                              fix=f"choose from {', '.join(EFFECTS)}")
        if not self.candidates:
            raise ImucalError("no candidate effects", field="candidates", fix=f"choose from {', '.join(EFFECTS)}")
        for name in ("alpha_noise", "alpha_effect", "alpha_scan"):
            v = getattr(self, name)
            if not 0 < v < 1:
                raise ImucalError(f"{name} {v!r} must lie in (0, 1)", field=name)
        if self.max_effects < 1 or self.full_fits < 1:
            raise ImucalError("max_effects and full_fits must be >= 1", field="settings")


# --- statistics (no scipy) -------------------------------------------------------------------
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
    p_adjusted: float = math.nan  #: Bonferroni: p * candidates in the round
    score: float = math.nan  #: chi2 / scale + penalty * k, for ranking
    fitted: bool = False
    converged: bool = False
    significant: bool = False

    @property
    def label(self) -> str:
        return f"{self.name}[{''.join(AXIS_NAMES[a] for a in self.axes)}]"

    @property
    def k(self) -> int:
        """Free parameters the candidate adds: its new coefficients and shape parameters."""
        return len(self.new_axes) + self.extra


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
    p_value: float  #: Bonferroni-adjusted p when it was added
    ambiguous_with: tuple[str, ...] = ()
    #: axes the term lacks that these poses cannot rule out (``_unresolved``): it may be there too
    unresolved_axes: tuple[int, ...] = ()

    @property
    def label(self) -> str:
        return f"{self.name}[{''.join(AXIS_NAMES[a] for a in self.axes)}]"


@dataclass(frozen=True)
class Discovery:
    """What ``discover`` found: the base and final runs, the rounds, the effects, the verdict."""

    base: CalibrationRun
    final: CalibrationRun
    steps: tuple[Step, ...]
    effects: tuple[FoundEffect, ...]
    verdict: str  #: one sentence
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
    #: "auto" and the residual exceeds the noise (the excess then in its weights and standard errors)
    kept: CalibrationRun | None = None
    #: a temperature sweep's calibration (imucal.thermal.run.ThermalCalibration), when the recording is one
    thermal: object | None = None

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

    def to_json(self) -> dict:
        """The machine-readable summary (``imucal discover --json``)."""
        b, f = self.base.result, self.final.result

        def num(x: float):
            return float(x) if math.isfinite(x) else None

        return {
            "format": "imucal-discover", "format_version": 1,
            "data": dict(self.final.calibration.data),
            "verdict": self.verdict,
            "effects": [{"name": e.name, "axes": [AXIS_NAMES[a] for a in e.axes],
                         "coefficients": e.coefficients, "std": {k: num(v) for k, v in e.std.items()},
                         "units": e.units, "reference": e.reference, "lr": num(e.lr),
                         "p_value": num(e.p_value), "ambiguous_with": list(e.ambiguous_with),
                         "unresolved_axes": [AXIS_NAMES[a] for a in e.unresolved_axes]}
                        for e in self.effects],
            "rms_before": self.rms_before, "rms_after": self.rms_after, "rms_noise": self.rms_noise,
            "rms_unit": "m/s^2",
            "chi2_before": self.chi2_before, "chi2_after": self.chi2_after,
            "dof": int(f.dof), "dof_before": int(b.dof), "dof_after": int(f.dof),
            "redchi_before": num(b.redchi), "redchi_after": num(f.redchi),
            "p_before": self.p_before, "p_after": self.p_after,
            "consistent_before": self.consistent_before, "consistent_after": self.consistent_after,
            "n_intervals": int(self.base.intervals.n),
            "model_before": b.model_name, "model_after": f.model_name,
            "calibration_weights": self.calibration_run.calibration.fit.get("weights"),  # of the one --out writes
            "disagreement": [{"pattern": p, "chi2_removed": num(v)} for p, v in self.disagreement],
            "steps": [{"round": s.index, "chi2_before": s.chi2_before, "dof_before": s.dof_before,
                       "scale": s.scale, "p_scan": num(s.p_scan), "chosen": s.chosen.label if s.chosen else None,
                       "jointly_with": s.jointly_with,
                       "ambiguous_with": [c.label for c in s.ambiguous_with],
                       "candidates": [{"effect": c.label, "new_axes": [AXIS_NAMES[a] for a in c.new_axes],
                                       "chi2_screen": num(c.chi2_screen), "chi2": num(c.chi2),
                                       "dof": c.dof, "lr": num(c.lr), "p_adjusted": num(c.p_adjusted),
                                       "fitted": c.fitted, "significant": c.significant}
                                      for c in s.candidates]}
                      for s in self.steps],
            "notes": list(self.notes),
            "settings": dataclasses.asdict(self.settings),
            "stochastic": self.stochastic.to_json() if self.stochastic is not None else None,
            "allan": self.allan.to_json() if self.allan is not None else None,
            "thermal": _thermal_json(self.thermal),
        }

    def report(self) -> str:
        """A text report: verdict, gap before/after, effects with coefficients, the rounds."""
        b, f = self.base.result, self.final.result
        L = ["[[Discovery]]",
             f"    data      = {self.base.recording.source} ({self.base.intervals.n} static intervals)",
             f"    verdict   = {self.verdict}",
             "[[Gap]]            before          after           (interval means)",
             f"    RMS |a|-g  = {self.rms_before:<15.6g} {self.rms_after:<15.6g} m/s^2 "
             f"(noise alone: {self.rms_noise:.3g})",
             f"    chi2 / dof = {b.chi2:.4g} / {b.dof:<6d}  {f.chi2:.4g} / {f.dof}",
             f"    chi2/dof   = {b.redchi:<15.4g} {f.redchi:<15.4g} (1 = residual at noise level)",
             f"    p (chi2)   = {self.p_before:<15.3g} {self.p_after:<15.3g} "
             f"(below {self.settings.alpha_noise:g}: disagrees with the noise)",
             f"    model      = {b.model_name}  ->  {f.model_name}"]
        if self.thermal is not None:  # a sweep's gap is its poses' constancy (imucal.report.thermal)
            from imucal.report.thermal import gap_lines

            L[3:] = gap_lines(self.thermal, self.settings.alpha_noise) + [f"    model      = {f.model_name}"]
        L.append("[[Effects found]]" + ("" if self.effects else "  none"))
        for e in self.effects:
            amb = f"  (ambiguous with {', '.join(e.ambiguous_with)})" if e.ambiguous_with else ""
            L.append(f"    {e.label}: LR = {e.lr:.4g}, p (adjusted) = {e.p_value:.3g}{amb}")
            if e.unresolved_axes:
                L.append(f"        not ruled out on {', '.join(AXIS_NAMES[a] for a in e.unresolved_axes)}: "
                         "these poses barely see the term there (see the notes)")
            for n, v in e.coefficients.items():
                L.append(f"        {n} = {v:.6g} +/- {e.std[n]:.3g} {e.units[n]}")
            for n, v in e.reference.items():
                L.append(f"        {n} = {v:.6g} {e.units.get(n, '')} (fixed reference)")
        L.append("[[Where the base model disagrees]]  chi-square a single-axis effect would remove "
                 "(linearised)")
        for p, v in self.disagreement[:8]:
            L.append(f"    {p:<28s} {v:10.4g}")
        for s in self.steps:
            L.append(f"[[Round {s.index}]]  chi2 = {s.chi2_before:.6g} on {s.dof_before} dof, "
                     f"{len(s.candidates)} candidates, misfit scale {s.scale:.3g}, family-wise p of the best "
                     f"screened {s.p_scan:.3g}")
            shown = sorted(s.candidates, key=lambda c: (not c.fitted, c.score if c.fitted else c.chi2_screen))
            for c in shown[:10]:
                if c.fitted:
                    flag = "significant" if c.significant else "not significant"
                    L.append(f"    {c.label:<28s} chi2 {c.chi2:10.5g}  LR {c.lr:9.4g}  p_adj {c.p_adjusted:9.3g}  "
                             f"score {c.score:9.5g}  {flag}")
                else:
                    L.append(f"    {c.label:<28s} chi2 ~ {c.chi2_screen:8.5g} (screened out)")
            if s.chosen is not None:
                L.append(f"    -> added {s.chosen.label}"
                         + (f" (significant given {s.jointly_with}: the pair explains the data better than any "
                            "single term, and each is significant given the other)" if s.jointly_with else "")
                         + (f"; cannot be told apart from {', '.join(c.label for c in s.ambiguous_with)}"
                            if s.ambiguous_with else ""))
            else:
                L.append("    -> no candidate is significant")
        if self.thermal is not None:
            from imucal.report.thermal import thermal_lines

            L.extend(thermal_lines(self.thermal))
        L.extend(_stochastic_lines(self))
        if self.notes:
            L.append("[[Notes]]")
            L.extend(f"    - {n}" for n in self.notes)
        return "\n".join(L) + "\n"


def _thermal_json(tc: object | None) -> dict | None:
    if tc is None:
        return None
    from imucal.report.thermal import thermal_json

    return thermal_json(tc)


# --- the workflow ----------------------------------------------------------------------------
_EFFECT_ORDER = {n: i for i, n in enumerate(EFFECTS)}


def _canonical(effects: dict[str, tuple[int, ...]]) -> list[AxisEffect]:
    return [make_effect(n, ax) for n, ax in sorted(effects.items(), key=lambda kv: _EFFECT_ORDER[kv[0]])]


def _as_dict(effects: Sequence) -> dict[str, tuple[int, ...]]:
    out: dict[str, tuple[int, ...]] = {}
    for e in effects:
        out[e.name] = tuple(sorted(set(out.get(e.name, ())) | set(e.axes)))
    return out


def _subsets() -> list[tuple[int, ...]]:
    return [c for r in (1, 2, 3) for c in itertools.combinations(range(3), r)]


def _p_lr(lr: float, k: int, res: FitResult, alpha_noise: float) -> float:
    """p of a likelihood-ratio statistic scaled by max(1, chi2/dof): chi-square(k) while the fit's
    residual is consistent with the noise (the noise is known), F(k, dof) when it is not (the
    misfit scale is then estimated from the fit, and chi-square would overstate the evidence)."""
    if res.dof > 0 and res.redchi > 1.0 and _p_noise(res) < alpha_noise:
        return f_sf(lr / k, k, res.dof)
    return chi2_sf(lr, k)


def _p_noise(res: FitResult) -> float:
    return chi2_sf(res.chi2, res.dof) if res.dof > 0 else 1.0


class _Problem:
    """The fixed parts of one discovery: data, template config, and the fits it makes."""

    def __init__(self, config: RunConfig, base: CalibrationRun, step: Callable[[], None] | None = None) -> None:
        self.step = step or (lambda: None)  #: called after every fit (a progress bar, imucal.report.progress)
        self.config = config
        self.run = base
        self.iv = base.intervals
        self.rec = base.recording
        self.gravity = base.calibration.gravity
        self.cov = {"temp": self.iv.temp, "time": self.iv.t_mid}
        g = base.guess  # the interval directions of imucal.pipeline.initial_guess
        d = (self.iv.mean - g.s) / g.b
        self.directions = d / np.linalg.norm(d, axis=1, keepdims=True)

    def parameters(self, effects: list[AxisEffect], start: dict[str, float], check: bool = True):
        model = build_model(effects)
        params = make_parameters(self.run.guess, self.config, self.gravity, model, self.rec.unit)
        if check:
            params = prepare_parameters(model.effects, params, self.cov, self.iv.n, self.rec.source)
        else:  # the screening model holds every candidate at once: only its Jacobian is used
            params = fit_to_data(model.effects, params, self.cov)
        keep = {n: v for n, v in start.items() if n in params.names and not params[n].fixed}
        return model, params.with_values(keep)

    def data(self, model) -> FitData:
        return fit_data(model, self.iv, self.rec, "means", self.rec.source)

    def undetermined(self, effects: list[AxisEffect], res: FitResult) -> tuple[str, ...]:
        """What the calibration's observability check (imucal.pipeline.observability) would call
        undetermined in the model ``effects`` at the values of ``res``."""
        model = build_model(effects)
        return observability(model, res.params, self.data(model), self.directions, self.gravity,
                              self.config.fit.angle_tolerance).undetermined

    def fit(self, effects: list[AxisEffect], start: dict[str, float]) -> FitResult:
        model, params = self.parameters(effects, start)
        res = fit(self.data(model), params, model, self.gravity, source=self.rec.source)
        self.step()
        return res


def _screen(prob: _Problem, current: FitResult, cur_effects: dict[str, tuple[int, ...]],
            names: Sequence[str], tau_grid: Sequence[float] = TAU_GRID
            ) -> tuple[list[tuple[np.ndarray, dict[str, float]]], np.ndarray, dict[str, int], list[str]]:
    """Column-scaled Jacobians of the residuals w.r.t. base + every candidate coefficient, at the fit.

    Candidates not in the model enter with coefficient 0 (the current fit). A new warm-up's tau
    does not enter at amplitude 0, so the Jacobian is taken once per tau of ``tau_grid`` (fractions
    of the last interval's time).
    Returns ([(J / sigma, shape values)], r / sigma, column index by parameter name, current free names).
    """
    every = {n: (0, 1, 2) for n in names}
    for n, ax in cur_effects.items():
        every[n] = (0, 1, 2)
    model, params = prob.parameters(_canonical(every), current.values(), check=False)
    have = set(current.params.names)
    params = params.with_values({n: 0.0 for e in model.effects for n in e.coefficient_names if n not in have})
    shapes = [n for e in model.effects for n in e.shape_names if n not in have]
    t_end = float(np.max(prob.iv.t_mid)) if prob.iv.n else 1.0
    grid = [{n: f * t_end for n in shapes} for f in tau_grid] if shapes else [{}]
    w = 1.0 / current.sigma
    data = prob.data(model)
    screens = [(jacobian_rows(data, params.with_values(g), model, prob.gravity) * w[:, None], g) for g in grid]
    cols = {n: i for i, n in enumerate(params.free_names)}
    return screens, current.residuals * w, cols, list(current.free_names)


def _screen_candidate(screens: list, rw: np.ndarray, base_cols: list[int], col: dict[str, int], name: str,
                      new: tuple[int, ...]) -> tuple[float, tuple[tuple[str, float], ...]]:
    """Gauss-Newton chi-square of one candidate, profiled over the screened shape values."""
    eff = make_effect(name, new)
    cols = base_cols + [col[c] for c in eff.coefficient_names]
    best = None
    for Jw, g in screens:
        start = tuple((n, g[n]) for n in eff.shape_names if n in g)
        if best is not None and not start:
            break  # no shape parameter to profile: every screen gives the same columns
        chi2 = _linear_chi2(Jw, rw, cols)
        if best is None or chi2 < best[0]:
            best = (chi2, start)
    return best


def _linear_chi2(Jw: np.ndarray, rw: np.ndarray, cols: list[int]) -> float:
    """min_x |rw + Jw[:, cols] x|^2: the Gauss-Newton chi-square (exact for a linear model)."""
    A = Jw[:, cols]
    x, *_ = np.linalg.lstsq(A, -rw, rcond=None)
    return float(np.sum((rw + A @ x) ** 2))


def _nested(a: Candidate, b: Candidate) -> bool:
    return a.name == b.name and (set(a.axes) <= set(b.axes) or set(b.axes) <= set(a.axes))


def _found(name: str, axes: tuple[int, ...], res: FitResult, lr: float, p: float,
           ambiguous: tuple[str, ...], unresolved: tuple[int, ...] = ()) -> FoundEffect:
    e = make_effect(name, axes)
    coef = {n: float(res.params[n].value) for n in (*e.coefficient_names, *e.shape_names)}
    ref = {n: float(res.params[n].value) for n in e.reference_names}
    return FoundEffect(name=name, axes=tuple(axes), coefficients=coef,
                       std={n: float(res.std.get(n, math.nan)) for n in coef},
                       units={n: res.params[n].unit for n in (*coef, *ref)}, reference=ref, lr=lr, p_value=p,
                       ambiguous_with=ambiguous, unresolved_axes=unresolved)


def _extra(name: str, cur_effects: dict[str, tuple[int, ...]]) -> int:
    """Shape parameters (tau) an effect adds when it enters the model."""
    return 0 if name in cur_effects else len(make_effect(name, (0,)).shape_names)


def _candidates(names: Sequence[str], cur_effects: dict[str, tuple[int, ...]], n_free: int, n_rows: int,
                n_distinct: int) -> list[tuple[str, tuple[int, ...], tuple[int, ...]]]:
    """(name, merged axes, new axes) of every candidate: each effect on each axis subset, merged
    with the same effect already in the model, that the intervals can still carry."""
    out, seen = [], set()
    for n in names:
        have = set(cur_effects.get(n, ()))
        if not EFFECTS[n].axes_observable and have:
            continue  # only the sum over axes is determined: one axis carries it
        for sub in _subsets() if EFFECTS[n].axes_observable else [(0,), (1,), (2,)]:
            new = tuple(sorted(set(sub) - have))
            merged = tuple(sorted(set(sub) | have))
            nf = n_free + len(new) + _extra(n, cur_effects)
            if not new or (n, merged) in seen or n_rows - nf < MIN_DOF or nf > n_distinct:
                continue
            seen.add((n, merged))
            out.append((n, merged, new))
    return out


@dataclass(frozen=True)
class _Scan:
    """A round's screen: every candidate's linearised chi-square, and the min-p null over them."""

    screened: list[Candidate]
    null: MinPNull
    p: float  #: family-wise p of the best screened candidate (linearised, unscaled)
    screens: list[np.ndarray]  #: whitened Jacobians, one per screened shape value (``_screen``)
    rw: np.ndarray  #: whitened residual of the current fit
    col: dict[str, int]  #: column of each parameter in ``screens``
    base_cols: list[int]  #: columns of the current model's free parameters


def _scan(prob: _Problem, current: FitResult, cur_effects: dict[str, tuple[int, ...]], names: Sequence[str],
          cands: list) -> _Scan:
    """Gauss-Newton chi-square of each candidate from the current fit, and the joint null of
    their statistics (``imucal.analysis.min_p``): the round's multiple-testing correction."""
    screens, rw, col, cur_free = _screen(prob, current, cur_effects, names)
    base_cols = [col[n] for n in cur_free]
    screened, family = [], []
    for n, merged, new in cands:
        chi2, start = _screen_candidate(screens, rw, base_cols, col, n, new)
        c = Candidate(n, merged, new, chi2_screen=chi2, extra=_extra(n, cur_effects), start=start)
        screened.append(c)
        family.append(([col[x] for x in make_effect(n, new).coefficient_names], c.k, c.extra > 0))
    null = min_p_null([Jw for Jw, _ in screens], base_cols, family)
    p_best = min((chi2_sf(max(0.0, current.chi2 - c.chi2_screen), c.k) for c in screened), default=1.0)
    return _Scan(screened, null, null.adjust(p_best), [Jw for Jw, _ in screens], rw, col, base_cols)


def _round(prob: _Problem, current: FitResult, cur_effects: dict[str, tuple[int, ...]], names: Sequence[str],
           scan: _Scan, settings: DiscoverSettings, index: int, notes: list[str], level: float
           ) -> tuple[Step, dict[int, FitResult]]:
    """Fit the best screened candidates, test them (family-wise p, min-p, below ``level``), pick the
    winner (if any)."""
    screened = list(scan.screened)
    # Full fits: the best few by the screening score, and every non-nested competitor close
    # enough to the best to matter for the ambiguity check.
    def pre(c: Candidate) -> float:
        return c.chi2_screen + settings.penalty * c.k

    order = sorted(range(len(screened)), key=lambda i: pre(screened[i]))
    top = screened[order[0]]
    pick = list(order[: settings.full_fits])
    pick += [i for i in order[settings.full_fits:]
             if pre(screened[i]) - pre(top) < settings.ambiguity + _SCREEN_SLACK and not _nested(screened[i], top)]
    pick = pick[: 2 * settings.full_fits]
    fits: dict[int, FitResult] = {}
    for i in pick:
        c = screened[i]
        res, why = _fit_candidate(prob, current, cur_effects, c)
        if res is None:
            notes.append(why)
            continue
        shapes = make_effect(c.name, c.axes).shape_names
        # Judged by the calibration's own observability check at the fitted values (noise only: the
        # misfit a candidate leaves is the LR test's to weigh, and scaling by it here refused a
        # correct warm-up whenever another term was still missing).
        loose = prob.undetermined(_canonical({**cur_effects, c.name: c.axes}), res) if shapes else ()
        if loose:  # the final calibration would refuse it
            notes.append(f"{c.label}: the poses leave {', '.join(loose)} undetermined, not counted")
            continue
        fits[i] = res
        # LR scaled by the misfit the candidate leaves: an underestimated noise cannot pass for an effect.
        # A fit that stopped early has a chi2 above its optimum, so its LR errs on the small side.
        lr = max(0.0, (current.chi2 - res.chi2) / max(1.0, res.redchi))
        p = _p_lr(lr, c.k, res, settings.alpha_noise)
        p_adj = scan.null.adjust(p)  # family-wise over every candidate of the round, screened or fitted
        screened[i] = dataclasses.replace(c, chi2=res.chi2, dof=res.dof, lr=lr, p_value=p,
                                          p_adjusted=p_adj, fitted=True, converged=res.success,
                                          significant=bool(np.isfinite(res.chi2)) and p_adj < level)
    sig = [i for i in fits if screened[i].significant]
    # The misfit scale candidates are ranked on: the least misfit among the significant ones (or
    # among all fitted ones when none is significant, for the report).
    common = max(1.0, min((fits[i].redchi for i in (sig or fits)), default=1.0))
    for i in fits:
        screened[i] = dataclasses.replace(screened[i], score=screened[i].chi2 / common + settings.penalty * screened[i].k)
    if not sig:
        step = Step(index, current.chi2, current.dof, tuple(screened), None, scale=common, p_scan=scan.p)
        return _lookahead(prob, current, cur_effects, scan, step, fits, settings, notes, level)
    best = min(sig, key=lambda i: screened[i].score)
    chosen = screened[best]
    amb = tuple(screened[i] for i in sig if i != best and not _nested(screened[i], chosen)
                and screened[i].score - chosen.score < settings.ambiguity)
    step = Step(index, current.chi2, current.dof, tuple(screened), chosen, amb, common, p_scan=scan.p)
    # Two terms may still describe the data better than the best one (a drift and a temperature term
    # on one axis, which a warm-up on 18-26 poses mimics with as many parameters). When the single
    # leaves a residual that disagrees with the noise, a pair with a lower penalised score wins; when
    # it is at noise level, only by more than the ambiguity margin (with ~5000 pairs to choose from,
    # a smaller gain is what chance offers a true single).
    margin = settings.ambiguity if _p_noise(fits[best]) >= settings.alpha_noise else 0.0
    paired, pfit = _lookahead(prob, current, cur_effects, scan, dataclasses.replace(step, chosen=None, ambiguous_with=()),
                              fits, settings, notes, level, beat=chosen.score - margin, scale=common, single=chosen)
    if paired.chosen is not None:
        return paired, pfit
    return step, {best: fits[best]}


def _lookahead(prob: _Problem, current: FitResult, cur_effects: dict[str, tuple[int, ...]], scan: _Scan,
               step: Step, fits: dict[int, FitResult], settings: DiscoverSettings, notes: list[str], level: float,
               beat: float = math.inf, scale: float = 1.0, single: Candidate | None = None
               ) -> tuple[Step, dict[int, FitResult]]:
    """Two terms at once. Two comparable effects: neither alone leaves a residual at noise level, so
    each one's LR, scaled by the misfit it leaves, is small; or a relative on more axes, or a term
    with a shape, describes part of both better than either. Every pair of the round's candidates
    (two different terms) is screened by its linearised chi-square (``imucal.analysis.pair_screen``);
    the best ``settings.lookahead`` whose screened score could beat ``beat`` (the chosen single's
    score, when one is significant) are fitted in full. A pair passes when its misfit scale makes
    *both* members significant, each tested given the other, Bonferroni over all pairs screened, and
    its score chi2 / max(scale, chi2/dof) + penalty * k is below ``beat``. The member more significant
    given the other is added now; the next round tests the other one alone. ``single`` (the term the
    pair must beat) is reported as ambiguous with the pair when within the ambiguity margin."""
    fits = dict(fits)
    cands = step.candidates
    n_free, n_distinct = len(current.free_names), prob.run.observability.n_distinct
    pairs = [(i, j) for i, j in itertools.combinations(range(len(cands)), 2)
             if cands[i].name != cands[j].name and n_free + cands[i].k + cands[j].k <= min(
                 n_distinct, prob.iv.n - MIN_DOF)]
    if not pairs:
        return step, {}
    members = [([scan.col[x] for x in make_effect(c.name, c.new_axes).coefficient_names], c.extra > 0) for c in cands]
    chi2 = pair_chi2(scan.screens, scan.rw, scan.base_cols, members, pairs)
    score = chi2 / scale + settings.penalty * np.array([cands[i].k + cands[j].k for i, j in pairs])
    M2 = len(pairs)
    passing: list[tuple[float, int, float, float, str]] = []
    order = [q for q in np.argsort(score, kind="stable") if score[q] < beat + _SCREEN_SLACK]
    for q in order[: settings.lookahead]:
        i, j = pairs[q]
        alone = []
        for m in (i, j):
            if m not in fits:
                res, why = _fit_candidate(prob, current, cur_effects, cands[m])
                if res is None:
                    notes.append(f"lookahead: {why}")
                    break
                fits[m] = res
            alone.append(fits[m])
        else:
            c, d = cands[i], cands[j]
            try:
                res_cd = prob.fit(_canonical({**cur_effects, c.name: c.axes, d.name: d.axes}),
                                  {**current.values(), **dict(c.start), **dict(d.start)})
            except ImucalError as exc:
                notes.append(f"lookahead {c.label} + {d.label}: {exc.message}")
                continue
            bound = [n for e in (c, d) for n in make_effect(e.name, e.axes).shape_names if n in res_cd.at_bound]
            if bound:
                notes.append(f"lookahead {c.label} + {d.label}: {bound[0]} at its {res_cd.at_bound[bound[0]]} bound")
                continue
            s2 = max(1.0, res_cd.redchi)
            lr = [max(0.0, (alone[1 - m].chi2 - res_cd.chi2) / s2) for m in (0, 1)]  # each given the other
            p = [min(1.0, _p_lr(lr[m], e.k, res_cd, settings.alpha_noise) * M2) for m, e in enumerate((c, d))]
            total = res_cd.chi2 / max(scale, s2) + settings.penalty * (c.k + d.k)
            if max(p) < level and total < beat:
                first = int(p[1] < p[0])
                passing.append((total, (i, j)[first], lr[first], p[first], (d, c)[first].label))
    if not passing:
        return step, {}
    total, i, lr_c, p_c, second = min(passing)
    # Another pair (not the same two terms) within the ambiguity margin: the data cannot tell them apart.
    rivals = tuple(cands[j] for t, j, _, _, d in passing if t - total < settings.ambiguity
                   and {cands[j].label, d} != {cands[i].label, second})
    if single is not None and single.score - total < settings.ambiguity and single.label not in (cands[i].label, second):
        rivals += (single,)
    out = list(cands)
    out[i] = dataclasses.replace(out[i], lr=lr_c, p_adjusted=p_c, significant=True)
    return (dataclasses.replace(step, candidates=tuple(out), chosen=out[i], jointly_with=second,
                                ambiguous_with=rivals), {i: fits[i]})


def _fit_candidate(prob: _Problem, current: FitResult, cur_effects: dict[str, tuple[int, ...]], c: Candidate
                   ) -> tuple[FitResult | None, str]:
    """The full fit of candidate ``c`` from ``current``, or (None, why it is not counted): a fit the
    model refuses, or a warm-up whose tau ends on its bound (a step or a straight line, not this term)."""
    try:
        res = prob.fit(_canonical({**cur_effects, c.name: c.axes}), {**current.values(), **dict(c.start)})
    except ImucalError as exc:
        return None, f"{c.label}: {exc.message}"
    bound = [n for n in make_effect(c.name, c.axes).shape_names if n in res.at_bound]
    if bound:
        return None, f"{c.label}: {bound[0]} at its {res.at_bound[bound[0]]} bound, not counted"
    return res, ""


def _prune(prob: _Problem, current: FitResult, cur_effects: dict[str, tuple[int, ...]], found_names: set[str],
           settings: DiscoverSettings, notes: list[str]) -> tuple[FitResult, dict[str, tuple[int, ...]]]:
    """Backward step: drop a coefficient (effect, axis) added earlier that the final model no
    longer needs, i.e. whose removal costs less than ``penalty`` in scaled chi-square. A greedy
    forward search can pick an extra axis early that a later effect explains better."""
    while True:
        scale = max(1.0, current.redchi)
        trials = []
        for n in sorted(found_names & set(cur_effects), key=_EFFECT_ORDER.get):
            for a in cur_effects[n]:
                reduced = dict(cur_effects)
                rest = tuple(x for x in cur_effects[n] if x != a)
                if rest:
                    reduced[n] = rest
                else:
                    del reduced[n]
                try:
                    res = prob.fit(_canonical(reduced), current.values())
                except ImucalError:
                    continue
                k = 1 + (0 if rest else len(make_effect(n, (0,)).shape_names))
                trials.append(((res.chi2 - current.chi2) / scale / k, n, a, res, reduced))
        if not trials:
            return current, cur_effects
        cost, n, a, res, reduced = min(trials, key=lambda t: t[0])
        if cost >= settings.penalty:
            return current, cur_effects
        notes.append(f"dropped {n} on axis {AXIS_NAMES[a]} after the later effects: it removed only "
                     f"{max(cost, 0.0):.3g} of scaled chi-square (< {settings.penalty:.3g} per coefficient)")
        current, cur_effects = res, reduced


#: Bins of the piecewise-constant alternative in the shape check (quantiles of the covariate).
SHAPE_BINS = 6
#: What the verdict says when the shape check drops a term.
SHAPE_FAILED = "a piecewise-constant shape fits significantly better"
#: The time covariate's name (imucal.model.effects), as the verdict names it.
TIME = "time"
#: The note of a stochastic bias withheld because the residual follows temperature.
_IN_TEMPERATURE = "a stochastic bias is not named: the shape check found structure in temperature"


def _shape_check(prob: _Problem, current: FitResult, cur_effects: dict[str, tuple[int, ...]],
                 found_names: set[str], settings: DiscoverSettings) -> dict[str, str]:
    """Is each term found in time or temperature the right *shape*? Its alternative is a
    piecewise-constant bias or scale in the same covariate on the same axes (``SHAPE_BINS``
    quantile bins), added to the final model in a Gauss-Newton step. When that removes
    significantly more (scaled LR, Bonferroni over the checks), the data follow the covariate in
    a way no term of the grammar describes (a step, say): the term is dropped and the verdict says
    so. Returns {effect name: note} of the terms that fail."""
    terms = [n for n in sorted(found_names & set(cur_effects), key=_EFFECT_ORDER.get)
             if isinstance(make_effect(n, (0,)), Term)]
    if not terms:
        return {}
    model, params = prob.parameters(_canonical(cur_effects), current.values(), check=False)
    J = jacobian_rows(prob.data(model), params, model, prob.gravity) * (1.0 / current.sigma)[:, None]
    rw = current.residuals / current.sigma
    col = {n: i for i, n in enumerate(params.free_names)}
    base_cols = [col[n] for n in current.free_names]
    out: dict[str, str] = {}
    for n in terms:
        e = make_effect(n, cur_effects[n])
        x = np.asarray(prob.cov[e.basis.covariate], float)
        edges = np.quantile(x, np.linspace(0, 1, SHAPE_BINS + 1)[1:-1])
        ind = np.eye(SHAPE_BINS)[np.searchsorted(edges, x, side="right")]  # one-hot bin of each row
        extra = np.hstack([J[:, [col[f"{'s' if e.target == 'bias' else 'b'}{a + 1}"]]] * ind for a in e.axes])
        A = np.hstack([J[:, base_cols], extra])
        sol, *_ = np.linalg.lstsq(A, -rw, rcond=None)
        chi2_bins = float(np.sum((rw + A @ sol) ** 2))
        k = (SHAPE_BINS - 1) * len(e.axes)  # one bin per axis is the shift or scale itself
        dof = current.dof - k
        if dof < MIN_DOF:
            continue
        scale = chi2_bins / dof
        lr = max(0.0, (current.chi2 - chi2_bins) / max(1.0, scale))
        p = (f_sf(lr / k, k, dof) if scale > 1 and chi2_sf(chi2_bins, dof) < settings.alpha_noise else chi2_sf(lr, k))
        if p * len(terms) < settings.alpha_effect:
            out[n] = (f"{_label(n, cur_effects[n])} dropped: a piecewise-constant {e.target} in "
                      f"{e.basis.covariate} ({SHAPE_BINS} bins) removes {current.chi2 - chi2_bins:.4g} more chi-square "
                      f"(LR {lr:.3g} on {k} parameters, p adjusted {min(1.0, p * len(terms)):.2g}): not its shape")
    return out


def _simplify(prob: _Problem, current: FitResult, cur_effects: dict[str, tuple[int, ...]], found_names: set[str],
              settings: DiscoverSettings, notes: list[str]) -> tuple[FitResult, dict[str, tuple[int, ...]], set[str]]:
    """Replace a term by its nested simpler relative (a warm-up by the drift it tends to) when the
    simpler one explains the data within ``penalty`` per parameter saved."""
    for n in sorted(found_names & set(cur_effects), key=_EFFECT_ORDER.get):
        simple = EFFECTS[n].simpler
        if simple is None or simple not in settings.candidates:
            continue
        reduced = {k: v for k, v in cur_effects.items() if k != n}
        reduced[simple] = tuple(sorted(set(reduced.get(simple, ())) | set(cur_effects[n])))
        try:
            res = prob.fit(_canonical(reduced), current.values())
        except ImucalError:
            continue
        saved = len(current.free_names) - len(res.free_names)
        cost = (res.chi2 - current.chi2) / max(1.0, current.redchi)
        if saved > 0 and cost < settings.penalty * saved:
            notes.append(f"{_label(n, cur_effects[n])} replaced by the simpler {_label(simple, reduced[simple])}: "
                         f"it explains the data within {max(cost, 0.0):.3g} of scaled chi-square")
            current, cur_effects = res, reduced
            found_names = (found_names - {n}) | {simple}
    return current, cur_effects, found_names


def discover(config: RunConfig, settings: DiscoverSettings = DiscoverSettings(),
             progress: Callable[[], None] | None = None) -> Discovery:
    """Fit the base model, test its residual against the noise, add effects while they are needed.

    ``progress`` is called after every candidate fit (imucal.report.progress)."""
    notes: list[str] = []
    asked = config
    if config.fit.weights == "auto":  # discovery tests the residual against the noise alone
        config = dataclasses.replace(config, fit=dataclasses.replace(config.fit, weights="noise"))
    if config.fit.mode != "means":
        notes.append("discovery works on interval means; fit.mode: samples was ignored")
        config = dataclasses.replace(config, fit=dataclasses.replace(config.fit, mode="means"))
    from imucal.thermal.run import sweep_of  # a temperature sweep: its own evidence (imucal.thermal)
    from imucal.thermal.select import TEMPERATURE_TERMS

    try:
        sweep = sweep_of(config) if set(TEMPERATURE_TERMS) & set(settings.candidates) else None
        if sweep is not None and sweep.rows is not None:  # still poses held over a temperature change
            return _sweep_discovery(asked, sweep, settings, progress)
        base = calibrate(config, sweep.recording if sweep is not None else None)
    except ImucalError as exc:
        if exc.field != "intervals":
            raise
        raise ImucalError(f"discover fits interval means: {exc.message}", file=exc.file, field=exc.field,
                          fix="record more static orientations (e.g. 18 to 30 holds of 3 s)") from None
    prob = _Problem(config, base, progress)
    iv, src = base.intervals, base.recording.source
    names = _testable(list(settings.candidates), iv, src, notes)
    n_free0 = len(base.result.free_names)
    if iv.n - (n_free0 + 1) < MIN_DOF:
        raise ImucalError(f"{iv.n} static intervals are too few to test effects: the base model has {n_free0} free "
                          f"parameters, one effect coefficient more needs at least {n_free0 + 1 + MIN_DOF} intervals",
                          file=src, field="intervals", fix="record more static orientations (e.g. 18 to 30 holds of 3 s)")

    p_before = _p_noise(base.result)
    st = _backward(prob, base, _search(prob, base, names, settings, notes, p_before), settings, notes)
    current, cur_effects, found, verdict = st.current, st.cur_effects, st.found, st.verdict
    try:
        final = _final_run(config, base, found, cur_effects, current, notes)
    except ImucalError as exc:  # the calibration refuses the model found (e.g. a parameter undetermined)
        notes.append(f"the calibration with {_added(found, cur_effects)} was refused: {exc.message}")
        final, found, cur_effects = base, [], {}
        verdict = (f"disagreement not explained by any candidate: chi2/dof = {base.result.redchi:.3g} "
                   f"(p = {p_before:.3g}); the model found cannot be calibrated from these poses")
    final, found, cur_effects, verdict = _beaten(config, base, final, found, cur_effects, current, verdict,
                                                 settings, notes)
    if found and verdict.startswith("explained"):  # name the effects as kept after the backward step
        verdict = (f"explained: after adding {_added(found, cur_effects)} chi2/dof = {final.result.redchi:.3g} "
                   f"(p = {_p_noise(final.result):.3g}), at noise level")
    elif found and verdict.startswith("partly"):
        verdict = f"partly explained by {_added(found, cur_effects)}; the remaining " + verdict.split("; the remaining ", 1)[1]
    _axis_notes(cur_effects, found, final, notes)
    last = {n: (lr, p, amb) for n, lr, p, amb in found}
    unresolved = {n: _unresolved(prob, final.result, cur_effects, n, settings.penalty, notes) for n in last}
    effects = tuple(_found(n, ax, final.result, *last[n], tuple(unresolved[n])) for n, ax in
                    sorted(cur_effects.items(), key=lambda kv: _EFFECT_ORDER[kv[0]]) if n in last)
    p_after = _p_noise(final.result)
    sto = stoch.assess(final, settings.alpha_noise) if p_after < settings.alpha_noise else None
    # A term in time that the shape check dropped leaves structure in time: a random walk has such
    # structure, and a step (which it does not explain) is tested by stochastic.select itself. Structure
    # in temperature no stochastic bias of time explains.
    if sto is not None and sto.named and SHAPE_FAILED in verdict and f"follows {TIME} but" not in verdict:
        sto = dataclasses.replace(sto, named=(), withheld=sto.named, chosen=sto.fits["none"], ambiguous=False,
                                  notes=sto.notes + (_IN_TEMPERATURE,))
    verdict = _stochastic_verdict(verdict, sto)
    kept = None
    if asked.fit.weights == "auto" and p_after < settings.alpha_noise:  # the excess into the weights kept
        try:
            auto = dataclasses.replace(config, fit=dataclasses.replace(config.fit, weights="auto"))
            kept = calibrate(_final_config(auto, cur_effects, current) if found else auto)
        except ImucalError as exc:
            notes.append(f"the calibration with weights auto was refused ({exc.message}); the one kept has "
                         "weights noise")
    return Discovery(base=base, final=final, steps=tuple(st.steps), effects=effects, verdict=verdict, kept=kept,
                     consistent_before=p_before >= settings.alpha_noise,
                     consistent_after=p_after >= settings.alpha_noise, p_before=p_before, p_after=p_after,
                     disagreement=tuple(st.disagreement), notes=tuple(notes) + (sto.notes if sto else ()),
                     settings=settings, stochastic=sto, allan=stoch.allan_view(final, sto))


def _sweep_discovery(config: RunConfig, sweep, settings: DiscoverSettings,
                     progress: Callable[[], None] | None) -> Discovery:
    """A temperature sweep's Discovery: its thermal calibration (imucal.thermal.run), the order selection's
    rounds as rounds, the terms as effects, the tests against the noise those of the rows about their poses."""
    from imucal.report.thermal import verdict
    from imucal.thermal.run import first_added, thermal_calibration

    tc = thermal_calibration(dataclasses.replace(sweep, config=config), progress, settings.alpha_effect)
    fit, added, steps = tc.selection.fit, first_added(tc), []
    for r in tc.selection.rounds:
        cands = tuple(Candidate(t.name, (t.axis,), (t.axis,), t.chi2_screen, chi2=t.chi2, dof=t.dof, lr=t.lr,
                                p_value=t.p_adjusted, p_adjusted=t.p_adjusted, score=t.chi2, fitted=t.dof > 0,
                                converged=t.dof > 0, significant=t.significant) for t in r.trials if t.determined)
        chosen = next((c for c in cands if r.chosen is not None and c.label == r.chosen.label), None)
        steps.append(Step(r.index, r.chi2_before, r.dof_before, cands, chosen,
                          p_scan=min((c.p_adjusted for c in cands if c.fitted), default=math.nan)))
    effects = tuple(_found(n, ax, dataclasses.replace(tc.final.result, params=fit.params, std=fit.std), *added[n], ())
                    for n, ax in sorted(tc.effects.items(), key=lambda kv: _EFFECT_ORDER[kv[0]]))
    notes = ["temperature sweep: the terms were chosen on the pose constancy of the still poses' temperature rows "
             "(imucal.thermal; see [[Temperature]]); the calibration kept is |a| - g on the still intervals with "
             "the terms held"]
    if tc.base is None:
        notes.append(f"the base model without temperature terms was refused ({tc.base_refusal}): the base run "
                     "shown is the final one")
    a = settings.alpha_noise
    return Discovery(base=tc.base or tc.final, final=tc.final, steps=tuple(steps), effects=effects, verdict=verdict(tc),
                     consistent_before=tc.p_noise(False) >= a, consistent_after=tc.p_noise(True) >= a,
                     p_before=tc.p_noise(False), p_after=tc.p_noise(True), disagreement=(), notes=tuple(notes),
                     settings=settings, thermal=tc)


@dataclass
class _State:
    """Where the forward search stands: the current fit, its effects, and what was found."""

    current: FitResult
    cur_effects: dict
    steps: list = field(default_factory=list)
    found: list = field(default_factory=list)  #: (name, lr, p, ambiguous labels)
    disagreement: list = field(default_factory=list)
    verdict: str = ""


def _search(prob: "_Problem", base: CalibrationRun, names: list[str], settings: DiscoverSettings,
            notes: list[str], p_before: float) -> _State:
    """Forward rounds: a round runs while the residual disagrees with the noise or a candidate
    stands out; each adds the most significant candidate (family-wise min-p level)."""
    iv = base.intervals
    current = base.result
    cur_effects = _as_dict(base.calibration.effect_objects())
    consistent = p_before >= settings.alpha_noise
    steps: list[Step] = []
    found: list[tuple[str, float, float, tuple[str, ...]]] = []  # name, lr, p, ambiguous
    disagreement: list[tuple[str, float]] = []
    verdict = (f"consistent with noise: chi2/dof = {current.redchi:.3g} (p = {p_before:.3g}); "
               "the base model explains the data")
    while True:  # a round runs while the residual disagrees with the noise or a candidate stands out
        if len(steps) >= settings.max_effects:
            if not consistent:
                verdict = f"stopped after {settings.max_effects} effects; the residual still disagrees with the noise"
            break
        cands = _candidates(names, cur_effects, len(current.free_names), iv.n, base.observability.n_distinct)
        if not cands:
            if not consistent:
                notes.append(f"no candidate fits: {iv.n} intervals ({base.observability.n_distinct} distinct "
                             f"orientations) leave too few degrees of freedom for {len(current.free_names)} + 1 "
                             "free parameters")
                verdict = "disagreement, but too few intervals to test more effects"
            break
        scan = _scan(prob, current, cur_effects, names, cands)
        if consistent and scan.p >= settings.alpha_scan:
            break  # the omnibus test passes and no single candidate stands out from the noise
        level = settings.alpha_effect if not consistent else settings.alpha_scan
        step, fits = _round(prob, current, cur_effects, names, scan, settings, len(steps) + 1, notes, level)
        if step.index == 1:  # where the base model disagrees: single-axis patterns, linearised
            disagreement = sorted(((c.label, current.chi2 - c.chi2_screen) for c in step.candidates
                                   if len(c.axes) == 1 and c.axes == c.new_axes), key=lambda t: -t[1])
        if step.chosen is None and consistent:
            break  # the candidate that stood out in the screen is not significant when fitted
        steps.append(step)
        if step.chosen is None:
            tau = math.sqrt(between_excess(current.residuals, current.sigma, current.dof))
            verdict = (f"disagreement not explained by any candidate: chi2/dof = {current.redchi:.3g} "
                       f"(p = {_p_noise(current):.3g}) and no candidate effect is significant; the scatter "
                       f"between intervals fits a random bias per visit of a pose (bias_instability, "
                       f"{tau:.3g} m/s^2 rms), which the default fit (weights: auto) includes in its weights "
                       "and standard errors")
            if found:
                verdict = f"partly explained by {_added(found, cur_effects)}; the remaining {verdict}"
            break
        c = step.chosen
        found.append((c.name, c.lr, c.p_adjusted, tuple(a.label for a in step.ambiguous_with)))
        cur_effects = {**cur_effects, c.name: c.axes}
        (current,) = fits.values()
        consistent = _p_noise(current) >= settings.alpha_noise
        if consistent:
            verdict = (f"explained: after adding {_added(found, cur_effects)} "
                       f"chi2/dof = {current.redchi:.3g} (p = {_p_noise(current):.3g}), at noise level")
    return _State(current, cur_effects, steps, found, disagreement, verdict)


def _backward(prob: "_Problem", base: CalibrationRun, st: _State, settings: DiscoverSettings,
              notes: list[str]) -> _State:
    """Simplify, prune and shape-check what the forward rounds found."""
    current, cur_effects, found, verdict = st.current, st.cur_effects, st.found, st.verdict
    if found:
        current, cur_effects, kept = _simplify(prob, current, cur_effects, {f[0] for f in found}, settings, notes)
        found = [f if f[0] in kept else (EFFECTS[f[0]].simpler, *f[1:]) for f in found]
        current, cur_effects = _prune(prob, current, cur_effects, {f[0] for f in found}, settings, notes)
        found = [f for f in found if f[0] in cur_effects]
        wrong = _shape_check(prob, current, cur_effects, {f[0] for f in found}, settings)
        if wrong:
            notes.extend(wrong.values())
            cur_effects = {n: ax for n, ax in cur_effects.items() if n not in wrong}
            found = [f for f in found if f[0] not in wrong]
            current = prob.fit(_canonical(cur_effects), current.values()) if found else base.result
            verdict = (f"disagreement not explained by any candidate: chi2/dof = {current.redchi:.3g} "
                       f"(p = {_p_noise(current):.3g}); the residual follows "
                       f"{', '.join(sorted({EFFECTS[n].covariates[0] for n in wrong}))} but not as any term of "
                       f"the grammar ({SHAPE_FAILED})")
            if found:
                verdict = f"partly explained by {_added(found, cur_effects)}; the remaining {verdict}"
    return dataclasses.replace(st, current=current, cur_effects=cur_effects, found=found, verdict=verdict)


def _axis_notes(cur_effects: dict, found: list, final: CalibrationRun, notes: list[str]) -> None:
    """Effects whose axis static poses cannot tell (the sum of their coefficients is determined)."""
    for n, ax in cur_effects.items():
        if n in {f[0] for f in found} and not EFFECTS[n].axes_observable:
            e = make_effect(n, ax)
            v = sum(final.result.params[c].value for c in e.coefficient_names)
            notes.append(f"{n}: static poses determine only the sum of its coefficients over the axes "
                         f"({v:.4g} {final.result.params[e.coefficient_names[0]].unit}; |a|^2 changes by 2 (q_x + q_y "
                         f"+ q_z) m_x m_y m_z), not which axis carries it: axis {_label(n, ax)[-2]} is a convention")


def _unresolved(prob: _Problem, res: FitResult, cur_effects: dict[str, tuple[int, ...]], name: str,
                penalty: float, notes: list[str]) -> dict[int, float]:
    """Axes a found term lacks that these poses cannot rule out: {axis: lambda}.

    lambda = the (misfit-scaled) chi-square a coefficient on that axis as large as the term's largest
    found one would add, linearised at the final fit (the other missing axes left out): its squared
    size over its standard error. The backward step keeps such a coefficient only when it removes
    more than ``penalty``, i.e. with probability P(chi2_1(lambda) > penalty); below
    ``RESOLVED_POWER`` the absence of the axis is not a finding. (A warm-up shows only in the
    first intervals, so their orientations decide which of its axes the data can see.)"""
    have = cur_effects[name]
    if not EFFECTS[name].axes_observable or len(have) == 3:
        return {}
    missing = {a: make_effect(name, (a,)).coefficient_names[0] for a in range(3) if a not in have}
    model, params = prob.parameters(_canonical({**cur_effects, name: (0, 1, 2)}), res.values(), check=False)
    params = params.with_values({c: 0.0 for c in missing.values()})
    J = jacobian_rows(prob.data(model), params, model, prob.gravity) / res.sigma[:, None]
    col = {n: i for i, n in enumerate(params.free_names)}
    base = [col[n] for n in res.free_names]
    found = make_effect(name, have).coefficient_names
    ref = max(found, key=lambda c: abs(res.params[c].value))
    out: dict[int, float] = {}
    for a, c in missing.items():
        A = J[:, base + [col[c]]]
        var = float(np.linalg.pinv(A.T @ A)[-1, -1]) * max(1.0, res.redchi)  # scaled units
        lam = (res.params[ref].value / params[c].scale) ** 2 / var if var > 0 else 0.0
        power = power_chi2_1(lam, penalty)
        if power < RESOLVED_POWER:
            out[a] = lam
            notes.append(f"{_label(name, have)}: axis {AXIS_NAMES[a]} not ruled out: a coefficient there as large as "
                         f"{ref} ({abs(res.params[ref].value):.3g} {res.params[ref].unit}) would add only {lam:.3g} "
                         f"chi-square and be kept in {power:.0%} of such recordings; these poses barely see "
                         f"{name} on {AXIS_NAMES[a]}: to test it, {_where_to_look(name, a, res)}")
    return out


def _where_to_look(name: str, axis: int, res: FitResult) -> str:
    """Which holds show a term on an axis: that axis along gravity (a bias or scale change on axis i
    moves |a| by m_i times it, m_i^2 for a scale), where the term's basis changes most."""
    e = make_effect(name, (axis,))
    hold = f"hold the {AXIS_NAMES[axis]} axis up and down"
    if not isinstance(e, Term):  # a term in the specific force: any time
        return hold
    if e.basis.covariate == "temp":
        return hold + " at the coldest and the warmest times"
    if e.shape_names:  # a warm-up
        return hold + f" within the first {2 * res.params[e.shape_names[0]].value:.3g} s (twice the fitted tau)"
    return hold + " at the start and at the end of the recording"


def _beaten(config: RunConfig, base: CalibrationRun, final: CalibrationRun, found: list, cur_effects: dict,
            current: FitResult, verdict: str, settings: DiscoverSettings, notes: list[str]):
    """Drop the terms in time that a bias random walk explains as well (imucal.analysis.stochastic)."""
    if not found or _p_noise(final.result) >= settings.alpha_noise:  # no excess left: nothing to beat
        return final, found, cur_effects, verdict
    beaten = stoch.beaten_terms(final, {f[0] for f in found}, settings.alpha_effect)
    if not beaten:
        return final, found, cur_effects, verdict
    notes.extend(beaten.values())
    found = [f for f in found if f[0] not in beaten]
    cur_effects = {n: ax for n, ax in cur_effects.items() if n not in beaten}
    final = _final_run(config, base, found, cur_effects, current, notes)
    verdict = (f"disagreement not explained by any candidate: chi2/dof = {final.result.redchi:.3g} "
               f"(p = {_p_noise(final.result):.3g}); no deterministic term beats a bias random walk")
    if found:
        verdict = f"partly explained by {_added(found, cur_effects)}; the remaining {verdict}"
    return final, found, cur_effects, verdict


def _stochastic_verdict(verdict: str, sto: "stoch.StochasticFit | None") -> str:
    """The verdict with the stochastic biases the REML test named (the per-visit sentence replaced)."""
    if sto is None:
        return verdict
    verdict = verdict.split("; the scatter between intervals fits", 1)[0]
    if not sto.named:
        if not sto.withheld:
            return verdict
        vals = ", ".join(f"{n} {v:.3g} +/- {s:.2g} {u}" for n, (v, s, u) in sto.values(sto.withheld).items())
        why = (f"a single step of the bias at t = {sto.step_at:.4g} s fits better (a step is no term of the grammar)"
               if math.isfinite(sto.step_at) else "the residual follows temperature" if _IN_TEMPERATURE in sto.notes
               else "one jump between intervals is larger than a Gaussian stochastic bias allows")
        return (f"{verdict}; a stochastic bias fits the scatter too ({vals}) but is not claimed: {why}; the default "
                "fit (weights: auto) still counts the excess in its weights and standard errors")
    vals = ", ".join(f"{n} {v:.3g} +/- {s:.2g} {u}" for n, (v, s, u) in sto.values().items())
    amb = (" (the data cannot tell bias_instability from bias_random_walk)" if sto.ambiguous else "")
    fit = "which the default fit (weights: auto) includes in its weights and standard errors"
    head, unexplained, rest = verdict.partition("disagreement not explained by any candidate: ")
    if unexplained and not head:  # no deterministic term helps; a stochastic one of the grammar does
        return f"explained by a stochastic bias: {vals}{amb}, {fit}; no deterministic term helps ({rest})"
    if unexplained:  # "partly explained by X; the remaining ..."
        terms = head.removeprefix("partly explained by ").split("; the remaining", 1)[0]
        return f"explained by {terms} plus a stochastic bias: {vals}{amb}, {fit} (without it: {rest})"
    return f"{verdict}; the scatter between intervals is a stochastic bias: {vals}{amb}, {fit}"


def _stochastic_lines(d: Discovery) -> list[str]:
    """The report's stochastic section: the REML estimates and tests, and the Allan view."""
    s = d.stochastic
    if s is None:
        return []
    L = ["[[Stochastic biases]]  REML on interval means, LR tests at level "
         f"{s.alpha:g} (boundary-corrected, Bonferroni over the two)"]
    for n, (v, sd, u) in s.values().items():
        L.append(f"    {n} = {v:.4g} +/- {sd:.2g} {u}")
    L.append(f"    named: {', '.join(s.named) or 'none'}" + ("  (ambiguous)" if s.ambiguous else ""))
    for n in s.p:
        L.append(f"    {n:<18s} p given the other {s.p[n]:9.3g}   p alone {s.p_alone[n]:9.3g}")
    if d.allan is not None:
        a = d.allan
        L.append(f"    Allan view: interval {a.interval} ({a.duration:.4g} s still); the curve's own +1/2 slope: "
                 + ", ".join(f"{x} {v:.3g}" for x, v in zip("xyz", a.q_allan)) + " m/s^2/sqrt(s)")
    return L


def _testable(names: list[str], iv, source: str, notes: list[str]) -> list[str]:
    """Drop the temperature effects when the data cannot carry them (and say why)."""
    temp_names = [n for n in names if "temp" in EFFECTS[n].covariates]
    reason = None
    if temp_names and iv.temp is None:
        reason = "the data have no temp column"
    elif temp_names and temperature_spread(iv.temp) < MIN_TEMPERATURE_SPREAD:
        reason = (f"the temperature is constant (interval means span {temperature_spread(iv.temp):.3g} degC "
                  f"< {MIN_TEMPERATURE_SPREAD} degC)")
    if reason is None:
        return names
    if len(temp_names) == len(names):
        raise ImucalError(f"{', '.join(temp_names)} cannot be tested: {reason}", file=source, field="candidates",
                          fix="record with a changing temperature column, or test other effects")
    notes.append(f"temperature effects not tested: {reason}")
    return [n for n in names if n not in temp_names]


def _final_run(config: RunConfig, base: CalibrationRun, found: list, cur_effects: dict[str, tuple[int, ...]],
               current: FitResult, notes: list[str]) -> CalibrationRun:
    """The whole pipeline once more with the effects found: the calibration file to keep."""
    if not found:
        return base
    final = calibrate(_final_config(config, cur_effects, current))
    if final.result.chi2 > current.chi2 * (1 + 1e-6) + 1e-9:
        notes.append(f"the final calibration's chi2 {final.result.chi2:.6g} is above the discovery fit's "
                     f"{current.chi2:.6g} (a different local optimum)")
    return final


def _final_config(config: RunConfig, cur_effects: dict[str, tuple[int, ...]], current: FitResult) -> RunConfig:
    """``config`` with the effects found, every free parameter starting where discovery left it (so the
    calibration's observability check judges the model at the values discovery judged it,
    imucal.pipeline.observability)."""
    specs = tuple(EffectSpec(n, tuple(AXIS_NAMES[a] for a in ax)) for n, ax in
                  sorted(cur_effects.items(), key=lambda kv: _EFFECT_ORDER[kv[0]]))
    names = {n for e in _canonical(cur_effects) for n in (*e.coefficient_names, *e.shape_names)}
    start = {n: min(max(p.value, p.lower), p.upper)  # (IPOPT may end a hair outside a bound)
             for n in current.free_names if n not in config.fit.initial and (n in BASE_NAMES or n in names)
             for p in [current.params[n]]}
    return dataclasses.replace(config, fit=dataclasses.replace(config.fit, effects=specs,
                                                               initial={**config.fit.initial, **start}))


def _label(name: str, axes: tuple[int, ...]) -> str:
    return f"{name}[{''.join(AXIS_NAMES[a] for a in axes)}]"


def _added(found: list, effects: dict[str, tuple[int, ...]]) -> str:
    return ", ".join(_label(n, effects[n]) for n in dict.fromkeys(f[0] for f in found))
