"""Stochastic biases of a calibration run, for discovery: the REML test and the Allan view.

``assess`` runs imucal.solve.stochastic's test (bias_instability, bias_random_walk, both or none) on
the interval means of a fitted run. ``allan_view`` puts the random walk found there beside the
overlapping Allan deviation (imucal.analysis.noise) of the recording's longest still interval,
when that interval is long enough: a random walk of density q has Allan variance q^2 tau / 3
(IEEE Std 952, Annex C), the +1/2 slope line sigma(tau) = q sqrt(tau / 3).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum

import numpy as np

from imucal.analysis.noise import allan_deviation, estimate
from imucal.model.effects import make_effect
from imucal.pipeline import CalibrationRun, fit_data
from imucal.model.sensor import build_model
from imucal.solve import least_squares as lsq
from imucal.solve import stochastic
from imucal.solve.stats import chi2_sf
from imucal.solve.stochastic import RANDOM_WALK, StochasticFit

#: The Allan view needs one still interval of at least this many samples: the overlapping curve then
#: spans 3 decades of tau (1 to ~1,300 sample periods; 13 s at 100 Hz), enough to see where a walk's
#: +1/2 line meets the white noise's -1/2 line when it does so inside the interval.
MIN_ALLAN_SAMPLES = 4_000


def assess(run: CalibrationRun, alpha: float = 1e-3) -> StochasticFit | None:
    """The REML test of the stochastic biases on ``run``'s interval means, at its fitted values;
    None above imucal.solve.stochastic.MAX_INTERVALS intervals."""
    if not stochastic.feasible(run.intervals.n):
        return None
    res, cal = run.result, run.calibration
    model = build_model(cal.effect_objects())
    data = fit_data(model, run.intervals, run.recording, "means", run.recording.source)
    free = res.free_names
    fns, rows = lsq.row_functions(model, free), lsq.Rows(data.raw, data.cov)
    pfix = np.array(res.params.values(), float)
    pfree = np.array([res.params[n].value for n in free])
    sigma0 = lsq.noise_sigma(fns, rows, data.raw_var, pfree, pfix, res.gravity)
    b = np.array([res.params[f"b{i}"].value for i in (1, 2, 3)])
    return stochastic.select(stochastic.components_at(fns, rows, pfree, pfix, res.gravity, sigma0, b, data.t),
                             alpha)


class Preferred(str, Enum):
    """Which explanation of one excess the data prefer."""

    TERM = "term"  #: the term adds significantly to the walk
    WALK = "random_walk"  #: it does not, and the terms leave an excess the walk is needed for anyway: dropped
    EITHER = "either"  #: it does not, but the terms leave no excess: the data cannot tell; the term is kept


@dataclass(frozen=True)
class Rival:
    """A deterministic term and a bias random walk that both explain one excess, and the test between them:
    the full-likelihood ratio of the walk with and without the term (per-visit offsets and the walk
    re-estimated by ML), LR ~ chi-square(k), Bonferroni over the terms weighed."""

    term: str  #: the effect's name
    axes: tuple[int, ...]
    lr: float  #: 2 (loglik with the term - loglik without it), both beside the walk
    k: int  #: the term's parameters (coefficients and a warm-up's tau)
    p_adjusted: float
    q: float  #: the walk's density under the null, no term [m/s^2/sqrt(s)]
    preferred: Preferred

    def to_json(self) -> dict:
        return {"term": self.term, "axes": list(self.axes), "lr": self.lr, "k": self.k, "p_adjusted": self.p_adjusted,
                "random_walk_q": self.q, "q_unit": "m/s^2/sqrt(s)", "preferred": self.preferred.value}


def walk_rivals(run: CalibrationRun, effects: dict[str, tuple[int, ...]], alpha: float = 1e-3,
                excess: bool = True) -> tuple[Rival, ...]:
    """Each term of ``effects`` weighed against a bias random walk that would explain the same excess.

    A random walk has trends of its own, so a drift, a step or a temperature polynomial found by the search
    (which weighs the means as independent) must beat the walk; a term of the specific force (a scale
    asymmetry) can meet a walk's trend by the order of the poses, and is weighed too. Under the null (those terms removed, linearised:
    r0 = r - J_term beta_term, exact for amplitudes) the REML test runs; if it names no random walk, no walk
    rivals them (empty). Otherwise each term is tested by the full-likelihood ratio of the nested models with
    and without it (``Rival``). One not significant at ``alpha`` loses to the walk when the terms leave an
    ``excess`` (the walk is needed anyway and the term adds nothing to it); without one, either explains the
    data (a drift and a walk are one trend in one recording) and the term, which corrects, is kept.
    """
    terms = sorted(effects)
    if not terms or not stochastic.feasible(run.intervals.n):
        return ()
    res = run.result
    model = build_model(run.calibration.effect_objects())
    data = fit_data(model, run.intervals, run.recording, "means", run.recording.source)
    free = list(res.free_names)
    fns, rows = lsq.row_functions(model, tuple(free)), lsq.Rows(data.raw, data.cov)
    pfix, pfree = np.array(res.params.values(), float), np.array([res.params[n].value for n in free])
    r, J, Jraw = lsq.jacobians(fns, rows, pfree, pfix, res.gravity)
    made = {n: make_effect(n, effects[n]) for n in terms}
    cols = {n: [free.index(c) for c in (*e.coefficient_names, *e.shape_names) if c in free] for n, e in made.items()}
    amp = sorted({free.index(c) for e in made.values() for c in e.coefficient_names if c in free})
    drop = {i for n in terms for i in cols[n]}
    r0 = r - J[:, amp] @ pfree[amp]
    keep = [i for i in range(len(free)) if i not in drop]
    sigma0 = lsq.noise_sigma(fns, rows, data.raw_var, pfree, pfix, res.gravity)
    b = np.array([res.params[f"b{i}"].value for i in (1, 2, 3)])
    c = stochastic.components(r0, sigma0, J[:, keep], Jraw * b, data.t)
    sto = stochastic.select(c, alpha)
    if RANDOM_WALK not in sto.named:
        return ()
    ll0 = stochastic.fit_model(c, "both", ml=True).loglik
    out = []
    for n in terms:
        c1 = stochastic.components(r0, sigma0, J[:, keep + cols[n]], Jraw * b, data.t)
        lr = max(0.0, 2.0 * (stochastic.fit_model(c1, "both", ml=True).loglik - ll0))
        p = min(1.0, chi2_sf(lr, len(cols[n])) * len(terms))
        out.append(Rival(n, tuple(effects[n]), lr, len(cols[n]), p, sto.q,
                         Preferred.TERM if p < alpha else Preferred.WALK if excess else Preferred.EITHER))
    return tuple(out)


@dataclass(frozen=True)
class AllanView:
    """The Allan deviation of the longest still interval, beside the random walk discovery found."""

    interval: int  #: index of the interval
    duration: float  #: [s]
    rate: float  #: [Hz]
    tau: np.ndarray  #: [s]
    adev: np.ndarray  #: (k, 3) [m/s^2]
    q: float  #: discovered density [m/s^2/sqrt(s)] (0: none named)
    q_std: float
    q_allan: tuple[float, float, float]  #: the curve's own +1/2-slope fit per axis [m/s^2/sqrt(s)] (nan: not seen)
    q_allan_rel_err: tuple[float, float, float]

    def line(self) -> np.ndarray:
        """sigma(tau) = q sqrt(tau / 3) of the discovered random walk [m/s^2]."""
        return self.q * np.sqrt(self.tau / 3.0)

    def to_json(self) -> dict:
        def num(x: float):
            return float(x) if math.isfinite(x) else None

        return {"interval": self.interval, "duration_s": self.duration, "rate_hz": self.rate,
                "tau_s": self.tau.tolist(), "adev": {a: self.adev[:, i].tolist() for i, a in enumerate("xyz")},
                "adev_unit": "m/s^2", "q_discovered": self.q, "q_discovered_std": num(self.q_std),
                "line_adev": self.line().tolist(), "q_allan": {a: num(v) for a, v in zip("xyz", self.q_allan)},
                "q_allan_rel_err": {a: num(v) for a, v in zip("xyz", self.q_allan_rel_err)},
                "q_unit": "m/s^2/sqrt(s)"}


def allan_view(run: CalibrationRun, found: StochasticFit | None,
               min_samples: int = MIN_ALLAN_SAMPLES) -> AllanView | None:
    """The Allan view of ``run``'s longest still interval, or None when it has < ``min_samples`` samples."""
    iv, rec = run.intervals, run.recording
    if iv.n == 0:
        return None
    k = int(np.argmax(iv.n_samples))
    if int(iv.n_samples[k]) < min_samples:
        return None
    t = rec.t[iv.start[k]:iv.end[k]]
    rate = (t.size - 1) / float(t[-1] - t[0])
    b = np.array([run.result.params[f"b{i}"].value for i in (1, 2, 3)])
    y = rec.raw[iv.start[k]:iv.end[k]] / b  # [m/s^2] per axis (scale only: the Allan curve ignores offsets)
    curve = allan_deviation(y, rate)
    est = [estimate(curve, a) for a in range(3)]
    named = found is not None and RANDOM_WALK in found.named
    return AllanView(interval=k, duration=float(t[-1] - t[0]), rate=float(rate), tau=curve.tau, adev=curve.adev,
                     q=found.q if named else 0.0, q_std=found.q_std if named else float("nan"),
                     q_allan=tuple(e.random_walk for e in est), q_allan_rel_err=tuple(e.random_walk_rel_err for e in est))
