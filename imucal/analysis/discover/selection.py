"""A round's selection: the best screened candidates fitted in full, tested (family-wise p), ranked, and
pairs of terms tried when two effects hide each other (the lookahead)."""
from __future__ import annotations

import dataclasses
import itertools
import math

import numpy as np

from imucal.analysis.discover.candidates import nested
from imucal.analysis.discover.problem import Effects, Problem, canonical, p_lr, p_noise
from imucal.analysis.discover.result import Candidate, Step
from imucal.analysis.discover.screening import Scan
from imucal.analysis.discover.settings import SCREEN_SLACK, DiscoverSettings
from imucal.analysis.pair_screen import pair_chi2
from imucal.errors import ImucalError
from imucal.model.effects import MIN_DOF, make_effect
from imucal.solve.fit import FitResult


def fit_candidate(prob: Problem, current: FitResult, effects: Effects, c: Candidate) -> tuple[FitResult | None, str]:
    """The full fit of candidate ``c`` from ``current``, or (None, why it is not counted): a fit the
    model refuses, or a warm-up whose tau ends on its bound (a step or a straight line, not this term)."""
    try:
        res = prob.fit(canonical({**effects, c.name: c.axes}), {**current.values(), **dict(c.start)})
    except ImucalError as exc:
        return None, f"{c.label}: {exc.message}"
    bound = [n for n in make_effect(c.name, c.axes).shape_names if n in res.at_bound]
    if bound:
        return None, f"{c.label}: {bound[0]} at its {res.at_bound[bound[0]]} bound, not counted"
    return res, ""


def _may_be_loose(c: Candidate) -> bool:
    """Whether the poses may leave a fitted candidate undetermined where its coefficients alone are not:
    a shape (a warm-up's tau), a given time (a step's), or a cross-axis term on more than one axis
    (told apart by its second-order terms only)."""
    e = make_effect(c.name, c.axes)
    return bool(e.shape_names or e.given_names or (not e.axes_observable and len(c.axes) > 1))


def _picked(scan: Scan, settings: DiscoverSettings) -> list[int]:
    """Which screened candidates to fit in full: the best few by the screening score, and every
    non-nested competitor close enough to the best to matter for the ambiguity check."""
    screened = scan.screened

    def pre(c: Candidate) -> float:
        return c.chi2_screen + settings.penalty * c.price

    order = sorted(range(len(screened)), key=lambda i: pre(screened[i]))
    top = screened[order[0]]
    pick = list(order[: settings.full_fits])
    pick += [i for i in order[settings.full_fits:]
             if pre(screened[i]) - pre(top) < settings.ambiguity + SCREEN_SLACK and not nested(screened[i], top)]
    return pick[: 2 * settings.full_fits]


def _fit_picked(prob: Problem, current: FitResult, effects: Effects, scan: Scan, settings: DiscoverSettings,
                notes: list[str], level: float) -> tuple[list[Candidate], dict[int, FitResult]]:
    """Full fits of the picked candidates, each tested by its scaled LR at the family-wise ``level``."""
    screened = list(scan.screened)
    fits: dict[int, FitResult] = {}
    for i in _picked(scan, settings):
        c = screened[i]
        res, why = fit_candidate(prob, current, effects, c)
        if res is None:
            notes.append(why)
            continue
        # Judged by the calibration's own observability check at the fitted values (noise only: the
        # misfit a candidate leaves is the LR test's to weigh, and scaling by it here refused a
        # correct warm-up whenever another term was still missing).
        loose = prob.undetermined(canonical({**effects, c.name: c.axes}), res) if _may_be_loose(c) else ()
        if loose:  # the final calibration would refuse it
            notes.append(f"{c.label}: the poses leave {', '.join(loose)} undetermined, not counted")
            continue
        fits[i] = res
        # LR scaled by the misfit the candidate leaves: an underestimated noise cannot pass for an effect.
        # A fit that stopped early has a chi2 above its optimum, so its LR errs on the small side.
        lr = max(0.0, (current.chi2 - res.chi2) / max(1.0, res.redchi))
        p = p_lr(lr, c.k, res, settings.alpha_noise)
        p_adj = scan.null.adjust(p)  # family-wise over every candidate of the round, screened or fitted
        screened[i] = dataclasses.replace(c, chi2=res.chi2, dof=res.dof, lr=lr, p_value=p,
                                          p_adjusted=p_adj, fitted=True, converged=res.success,
                                          significant=bool(np.isfinite(res.chi2)) and p_adj < level)
    return screened, fits


def round_(prob: Problem, current: FitResult, effects: Effects, scan: Scan, settings: DiscoverSettings, index: int,
           notes: list[str], level: float) -> tuple[Step, dict[int, FitResult]]:
    """Fit the best screened candidates, test them (family-wise p, min-p, below ``level``), pick the
    winner (if any)."""
    screened, fits = _fit_picked(prob, current, effects, scan, settings, notes, level)
    sig = [i for i in fits if screened[i].significant]
    # The misfit scale candidates are ranked on: the least misfit among the significant ones (or
    # among all fitted ones when none is significant, for the report).
    common = max(1.0, min((fits[i].redchi for i in (sig or fits)), default=1.0))
    for i in fits:
        screened[i] = dataclasses.replace(screened[i], score=screened[i].chi2 / common + settings.penalty * screened[i].price)
    if not sig:
        step = Step(index, current.chi2, current.dof, tuple(screened), None, scale=common, p_scan=scan.p)
        return lookahead(prob, current, effects, scan, step, fits, settings, notes, level)
    best = min(sig, key=lambda i: screened[i].score)
    chosen = screened[best]
    amb = tuple(screened[i] for i in sig if i != best and not nested(screened[i], chosen)
                and screened[i].label != chosen.label and screened[i].score - chosen.score < settings.ambiguity)
    step = Step(index, current.chi2, current.dof, tuple(screened), chosen, amb, common, p_scan=scan.p)
    # Two terms may still describe the data better than the best one (a drift and a temperature term
    # on one axis, which a warm-up on 18-26 poses mimics with as many parameters). When the single
    # leaves a residual that disagrees with the noise, a pair with a lower penalised score wins; when
    # it is at noise level, only by more than the ambiguity margin (with ~5000 pairs to choose from,
    # a smaller gain is what chance offers a true single).
    margin = settings.ambiguity if p_noise(fits[best]) >= settings.alpha_noise else 0.0
    paired, pfit = lookahead(prob, current, effects, scan, dataclasses.replace(step, chosen=None, ambiguous_with=()),
                             fits, settings, notes, level, beat=chosen.score - margin, scale=common, single=chosen)
    if paired.chosen is not None:
        return paired, pfit
    return step, {best: fits[best]}


@dataclasses.dataclass(frozen=True)
class _Pair:
    """A pair that passed: its penalised score, the member added now, its LR and p, the other's label."""

    total: float
    member: int
    lr: float
    p: float
    second: str


def _screened_pairs(prob: Problem, current: FitResult, scan: Scan, cands: tuple[Candidate, ...],
                    settings: DiscoverSettings, beat: float, scale: float) -> tuple[list[tuple[int, int]], int]:
    """The pairs worth a full fit (best linearised scores that could beat ``beat``), and how many were screened."""
    n_free, n_distinct = len(current.free_names), prob.run.observability.n_distinct
    pairs = [(i, j) for i, j in itertools.combinations(range(len(cands)), 2)
             if cands[i].name != cands[j].name and n_free + cands[i].k + cands[j].k <= min(
                 n_distinct, prob.iv.n - MIN_DOF)]
    if not pairs:
        return [], 0
    members = [([scan.col[x] for x in make_effect(c.name, c.new_axes).coefficient_names], ids)
               for c, ids in zip(cands, scan.ids)]
    chi2 = pair_chi2(scan.screens, scan.rw, scan.base_cols, members, pairs)
    score = chi2 / scale + settings.penalty * np.array([cands[i].price + cands[j].price for i, j in pairs])
    order = [q for q in np.argsort(score, kind="stable") if score[q] < beat + SCREEN_SLACK]
    return [pairs[q] for q in order[: settings.lookahead]], len(pairs)


def _fit_pair(prob: Problem, current: FitResult, effects: Effects, cands: tuple[Candidate, ...], pair: tuple[int, int],
              fits: dict[int, FitResult], settings: DiscoverSettings, notes: list[str], level: float, beat: float,
              scale: float, m2: int) -> _Pair | None:
    """Both members fitted alone and together; the pair passes when each is significant given the other
    (Bonferroni over the ``m2`` pairs screened) and its score beats ``beat``."""
    alone = []
    for m in pair:
        if m not in fits:
            res, why = fit_candidate(prob, current, effects, cands[m])
            if res is None:
                notes.append(f"lookahead: {why}")
                return None
            fits[m] = res
        alone.append(fits[m])
    c, d = cands[pair[0]], cands[pair[1]]
    try:
        res_cd = prob.fit(canonical({**effects, c.name: c.axes, d.name: d.axes}),
                          {**current.values(), **dict(c.start), **dict(d.start)})
    except ImucalError as exc:
        notes.append(f"lookahead {c.label} + {d.label}: {exc.message}")
        return None
    bound = [n for e in (c, d) for n in make_effect(e.name, e.axes).shape_names if n in res_cd.at_bound]
    if bound:
        notes.append(f"lookahead {c.label} + {d.label}: {bound[0]} at its {res_cd.at_bound[bound[0]]} bound")
        return None
    s2 = max(1.0, res_cd.redchi)
    lr = [max(0.0, (alone[1 - m].chi2 - res_cd.chi2) / s2) for m in (0, 1)]  # each given the other
    p = [min(1.0, p_lr(lr[m], e.k, res_cd, settings.alpha_noise) * m2) for m, e in enumerate((c, d))]
    total = res_cd.chi2 / max(scale, s2) + settings.penalty * (c.price + d.price)
    if max(p) >= level or total >= beat:
        return None
    first = int(p[1] < p[0])
    return _Pair(total, pair[first], lr[first], p[first], (d, c)[first].label)


def lookahead(prob: Problem, current: FitResult, effects: Effects, scan: Scan, step: Step,
              fits: dict[int, FitResult], settings: DiscoverSettings, notes: list[str], level: float,
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
    tried, m2 = _screened_pairs(prob, current, scan, cands, settings, beat, scale)
    passing = [p for p in (_fit_pair(prob, current, effects, cands, pair, fits, settings, notes, level, beat, scale, m2)
                           for pair in tried) if p is not None]
    if not passing:
        return step, {}
    win = min(passing, key=lambda p: (p.total, p.member))
    i = win.member
    # Another pair (not the same two terms) within the ambiguity margin: the data cannot tell them apart.
    rivals = tuple(cands[p.member] for p in passing if p.total - win.total < settings.ambiguity
                   and {cands[p.member].label, p.second} != {cands[i].label, win.second}
                   and cands[p.member].label not in (cands[i].label, win.second))
    if single is not None and single.score - win.total < settings.ambiguity and single.label not in (cands[i].label, win.second):
        rivals += (single,)
    out = list(cands)
    out[i] = dataclasses.replace(out[i], lr=win.lr, p_adjusted=win.p, significant=True)
    return (dataclasses.replace(step, candidates=tuple(out), chosen=out[i], jointly_with=win.second,
                                ambiguous_with=rivals), {i: fits[i]})
