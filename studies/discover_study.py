"""Detection study for `imucal discover` over the effect grammar: how often it names the hidden term, by size and noise.

Each case is a seeded simulated recording (imucal.analysis.simulate.draw_effect_case: random sensor in raw
counts or m/s^2, 18-26 poses of 3 s at 100 Hz with hand-held transitions and vibration, warm-up plus a
non-monotonic temperature swing) with one effect on a random axis subset, two effects, or none.
Discover runs without being told anything.

The effect size is the largest change of a reading at 1 g over the recording [mg]; the
signal-to-noise ratio (SNR) divides it by the noise of one interval mean. That is a physical size,
not what the data can see: the part of the effect the base model cannot absorb, in chi-square
units, is lambda (the chi-square the noise-free effect adds to the base fit of the same recording;
the non-centrality of every test of it). Each case reports lambda, and "oracle" is the power of the
best possible single test, one that knows the term, its axes and signs: P(chi2_1(lambda) > 10.83),
at the 1e-3 level discovery uses. No method can name a term more often than its oracle.

    python studies/discover_study.py                 # the full study over the grammar (15 terms)
    python studies/discover_study.py --quick         # a reduced run (2 cases per cell, SNR 10 and 40)
    python studies/discover_study.py --classic       # the five effects before the grammar (studies/results/discover_study.md)
    python studies/discover_study.py --new-terms     # issue 28's terms: asymmetric scale, bias step, hysteresis,
                                                     # angles in temperature, single and in pairs, and the
                                                     # cross-axis term on two axes nearly cancelling
                                                     # (studies/results/discover_new_terms_study.md)
    python studies/discover_study.py --new-terms --visible --coefficient
                                                     # the same, SNR = the weakest coefficient in standard errors
                                                     # (studies/results/discover_new_terms_coefficient_study.md)
    python studies/discover_study.py --visible       # SNR = sqrt(lambda) (studies/results/discover_visible_study.md)
    python studies/discover_study.py --visible --revisit --snr 10 20 --cases 16
                                                     # every pose held twice (studies/results/discover_revisit_visible_study.md)
    python studies/discover_study.py --revisit --snr 10 20 40
                                                     # the same plan, SNR as size (studies/results/discover_revisit_grammar_study.md)
    python studies/discover_study.py --visible --coefficient --snr 10 20 --cases 16
                                                     # SNR = the weakest coefficient in standard errors
                                                     # (studies/results/discover_coefficient_study.md; with --revisit:
                                                     # studies/results/discover_revisit_coefficient_study.md; with
                                                     # --tau-known, a warm-up's tau held at its truth)
For the cross-axis term only the sum of its coefficients over the axes reaches |a| (see
imucal.model.effects), so "correct" there means the term on one axis.
Writes studies/results/discover_grammar_study.md (studies/results/discover_study.md with --classic) and prints it.
"""
from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import math  # noqa: E402

import numpy as np  # noqa: E402

from imucal.constants import STANDARD_GRAVITY  # noqa: E402
from imucal.model.effects import CLASSIC, EFFECTS, make_effect  # noqa: E402
from imucal.report.progress import progress  # noqa: E402
from imucal.solve.stats import power_chi2_1  # noqa: E402

#: "reliably": the right effect and axes in at least this share of the cases.
RELIABLE = 0.9
#: chi-square(1) at p = 1e-3: the oracle's threshold.
ORACLE_CRIT = 10.828


def oracle_power(lam: float) -> float:
    """P(chi2_1(lam) > ORACLE_CRIT): the power of a single 1-dof test that knows the effect."""
    return power_chi2_1(lam, ORACLE_CRIT)


#: Noise draws of the selection oracle per case.
GENIE_DRAWS = 400


#: Penalties per parameter the selection oracle is also evaluated at (chi-square(1) at p = 0.16,
#: 0.05, 1e-2, 1e-3; discover's own, DiscoverSettings.penalty, is 1e-2).
GENIE_PENALTIES = (2.0, 3.84, 10.83)
#: Prices of a shape parameter (a warm-up's tau) the selection oracle is also evaluated at, the
#: coefficients at discover's own penalty: whether tau should cost less or more than a coefficient.
GENIE_TAU_PRICES = (0.0, 2.0, 3.84, 10.83)
#: The tau grid of the profiled selection oracle (fractions of the recording, over the fit's tau
#: range imucal.model.effects.WARMUP_TAU_FIT, 15 % apart): every warm-up candidate, the truth's
#: included, is profiled over it, so none is given the true tau.
PROFILE_TAU_GRID = tuple(np.geomspace(0.02, 1.0, 30))


def selection_oracle(signal: np.ndarray, base: np.ndarray, options: list, truth: tuple,
                     penalties: tuple[float, ...], seed: int, draws: int = GENIE_DRAWS,
                     shapes: tuple[int, ...] = (), tau_prices: tuple[float, ...] = ()
                     ) -> dict[float, float]:
    """Share of noise draws in which the penalised linear selection names exactly ``truth``, by penalty.

    The data are the whitened noise-free effect plus unit noise; every candidate (name, axes, k,
    column blocks, one per screened shape value) is scored by the chi-square its columns remove
    beyond the base model, profiled over the blocks, minus ``penalty`` * k, and the best score
    wins. A search that is exact (every candidate tried, linear, no local minima) with discovery's
    own ranking: what the selection rule can do with this much information. Misses of discover
    beyond it are the search's; misses inside it are the data's. With ``shapes`` (the shape
    parameters among each option's k) and ``tau_prices``, also keyed ``(penalty, price)``: the
    coefficients at the first penalty, each shape parameter at ``price``."""
    from imucal.analysis.min_p import column_basis

    rng = np.random.default_rng([seed, 7])
    Qb = column_basis(base)
    Y = signal[:, None] + rng.standard_normal((signal.size, draws))  # Q below is orthogonal to the base
    gains = np.zeros((len(options), draws))
    for i, (_, _, _, blocks) in enumerate(options):
        for C in blocks:
            Q = column_basis(C - Qb @ (Qb.T @ C))
            gains[i] = np.maximum(gains[i], np.sum((Q.T @ Y) ** 2, axis=0))
    k = np.array([o[2] for o in options], float)[:, None]
    hits = [i for i, (n, ax, _, _) in enumerate(options) if (n, ax) == truth]
    share = lambda price: float(np.mean(np.isin(np.argmax(gains - price, axis=0), hits)))  # noqa: E731
    out: dict = {p: share(p * k) for p in penalties}
    if tau_prices:
        m = np.array(shapes, float)[:, None]
        out.update({(penalties[0], t): share(penalties[0] * (k - m) + t * m) for t in tau_prices})
    return out


def coefficient_chi2(base: np.ndarray, parts: list[np.ndarray]) -> list[float]:
    """The chi-square of each part of a whitened signal (one coefficient's column times its value)
    beside the ``base`` columns and the other parts: that coefficient in standard errors, squared."""
    out = []
    for i, y in enumerate(parts):
        A = np.column_stack([base, *parts[:i], *parts[i + 1:]])
        x, *_ = np.linalg.lstsq(A, y, rcond=None)
        out.append(float(np.sum((y - A @ x) ** 2)))
    return out


def visible_chi2(case, path: str, rel: bool = True, genie: bool = False,
                 weakest: bool = False, tau_known: bool = False) -> tuple[float, float, dict]:
    """(lambda, lambda_rel, selection oracle) of the hidden effect, linearised at the base fit of the
    clean twin (same seed, same noise, no effect) written to ``path``. lambda: the chi-square the
    noise-free effect adds to the base fit; with ``weakest``, that of its weakest coefficient beside
    the base model and the term's other parameters (its coefficient in standard errors, squared): a
    warm-up's tau is fitted beside them as discover and calibrate fit it, linearised at the true term,
    unless ``tau_known`` holds it at its true value (no fit knows it: smaller errors, smaller cases).
    lambda_rel: what is left of it when its closest relative is fitted instead (any other candidate of discovery's first round that does not contain the truth,
    a warm-up at any screened tau): the evidence that tells the term and axes from the nearest wrong
    answer. Selection oracle (``genie``): ``selection_oracle`` over the same candidates, the truth's
    own tau added to its term's screened values; and under the key "profiled", the same with every
    warm-up candidate, the truth's included, profiled over ``PROFILE_TAU_GRID`` instead: the
    counterpart of discover's search, which fits tau for every warm-up it tries."""
    import dataclasses

    from imucal.analysis.discover import DiscoverSettings
    from imucal.analysis.discover.candidates import candidates as _candidates, extra as _extra, testable as _testable
    from imucal.analysis.discover.problem import Problem as _Problem, canonical as _canonical
    from imucal.analysis.discover.screening import own_screens as _own, screen as _screen
    from imucal.config.run import config_from_dict
    from imucal.model.effects import make_effect
    from imucal.pipeline import calibrate_accelerometer
    from imucal.solve.fit import jacobian_rows

    sensor = case.config.sensor
    clean = dataclasses.replace(case.config, sensor=dataclasses.replace(sensor, effects={}))
    with open(path, "w") as f:
        f.write(clean.run().to_csv_text())
    cfg = config_from_dict({"data": {"path": path, "unit": sensor.unit}, "fit": {"weights": "noise"}})
    base = calibrate_accelerometer(cfg)
    prob = _Problem(cfg, base)
    e = make_effect(case.effect, case.axes)
    truth = sensor.effects[case.effect]
    start = {**base.result.values(), **{n: v for n, v in truth.items() if n in (*e.shape_names, *e.given_names)}}
    every = (0, 1, 2) if EFFECTS[case.effect].axes_observable else case.axes  # the truth's term on any axes
    model, params = prob.parameters(_canonical({case.effect: every}), start, check=False)
    params = params.with_values({n: 0.0 for n in make_effect(case.effect, every).coefficient_names})
    J = jacobian_rows(prob.data(model), params, model, prob.gravity) / base.result.sigma[:, None]
    col = {n: i for i, n in enumerate(params.free_names)}
    signal = sum(J[:, col[n]] * truth[n] / params[n].scale for n in e.coefficient_names)

    def left(A: np.ndarray, y: np.ndarray = signal) -> float:
        x, *_ = np.linalg.lstsq(A, y, rcond=None)
        return float(np.sum((y - A @ x) ** 2))

    B = J[:, [col[n] for n in base.result.free_names]]
    lam = left(B)
    if weakest:
        shape = []  # a warm-up's tau, fitted beside its coefficients: its direction at the true term
        if e.shape_names and not tau_known:
            Jt = jacobian_rows(prob.data(model), params.with_values({n: truth[n] for n in e.coefficient_names}),
                               model, prob.gravity) / base.result.sigma[:, None]
            shape = [Jt[:, col[n]] for n in e.shape_names]
        lam = min(coefficient_chi2(np.column_stack([B, *shape]),
                                   [J[:, col[n]] * truth[n] / params[n].scale for n in e.coefficient_names]))
    if not rel:
        return lam, math.nan, {}
    names = _testable(list(EFFECTS), base.intervals, path, [])
    screens, _, col2, free = _screen(prob, base.result, {}, names)
    base_cols = [col2[n] for n in free]
    fine = _screen(prob, base.result, {}, names, tau_grid=PROFILE_TAU_GRID)[0] if genie else []
    rel, options, profiled = math.inf, [], []
    for n, ax, new in _candidates(names, {}, len(free), base.intervals.n, base.observability.n_distinct):
        eff = make_effect(n, new)
        coef = eff.coefficient_names
        cols, k = [col2[c] for c in coef], len(new) + _extra(n, {})
        blocks = lambda grid: [grid[i].J[:, cols] for i in _own(grid, n, new)]  # noqa: E731  (tau, a step's time)
        own_tau = [J[:, [col[c] for c in coef]]] if n == case.effect and all(c in col for c in coef) else []
        options.append((n, ax, k, blocks(screens) + own_tau))  # the truth's term also at its own tau
        profiled.append((n, ax, k, blocks(fine)))
        if n == case.effect and (set(case.axes) <= set(ax) or not EFFECTS[n].axes_observable):
            continue  # the truth itself, or a model containing it
        rel = min(rel, *(left(g.J[:, base_cols + cols]) for g in screens))
    if not genie:
        return lam, rel, {}
    truth = (case.effect, tuple(case.axes))
    if not EFFECTS[case.effect].axes_observable:
        options, profiled = ([(n, (ax if n != case.effect else truth[1]), k, b) for n, ax, k, b in o]
                             for o in (options, profiled))
    base_J = screens[0].J[:, base_cols]
    own = DiscoverSettings().penalty
    pens = (own, *sorted(set(GENIE_PENALTIES) - {own}))
    shapes = tuple(_extra(n, {}) for n, *_ in options)
    out = selection_oracle(signal, base_J, options, truth, pens, case.seed, shapes=shapes, tau_prices=GENIE_TAU_PRICES)
    out["profiled"] = selection_oracle(signal, base_J, profiled, truth, (own,), case.seed)[own]
    return lam, rel, out


def _design(opts: dict) -> dict:
    """The recording design of --hold / --rate (draw_effect_case's hold and rate; default 3 s at 100 Hz)."""
    return {k: opts[k] for k in ("hold", "rate") if k in opts}


def run_case(args: tuple) -> dict:
    """Simulate one case, run discover, classify the outcome."""
    seed, effect, snr, noise_mg, pool, visible, revisit, *more = args
    opts = more[0] if more else {}  # step_anywhere, scan_holds (--step-anywhere, --no-hold-scan)
    from imucal.config.run import config_from_dict
    from imucal.analysis.discover import DiscoverSettings, discover
    from imucal.analysis.simulate import draw_effect_case

    if effect == "pair":
        return run_pair(seed, snr, noise_mg, pool, visible)
    with tempfile.TemporaryDirectory() as d:  # (the cancelling cross-axis cells keep their size SNR)
        phys = (visible_snr(seed, effect, snr, noise_mg, os.path.join(d, "ref.csv"), revisit,
                            weakest=str(visible).startswith("coefficient"), tau_known=visible == "coefficient-tau-known")
            if visible and effect and effect != CROSS_TWO else snr)
    if not math.isfinite(phys):  # the base model absorbs this draw entirely: no size makes it visible
        return {"seed": seed, "effect": effect, "snr": snr, "noise_mg": noise_mg, "outcome": "invisible",
                "found": [], "truth": effect, "ambiguous": False, "size_mg": math.nan, "sigma_mean_mg": math.nan,
                "redchi_after": math.nan, "gap_after": math.nan, "gap_before": math.nan, "counts": False,
                "seconds": 0.0, "lam": 0.0, "lam_rel": 0.0, "oracle": 0.0, "genie": 0.0, "genie_by_penalty": {},
                "snr_size": math.nan}
    case = (cancelling_cross_case(seed, phys, noise_mg) if effect == CROSS_TWO
            else draw_effect_case(seed, effect=effect, snr=phys, noise_mg=noise_mg, revisit=revisit,
                                  step_anywhere=opts.get("step_anywhere", False), **_design(opts)))
    sim = case.config.run()
    with tempfile.TemporaryDirectory() as d:
        path = os.path.join(d, "case.csv")
        with open(path, "w") as f:
            f.write(sim.to_csv_text())
        t0 = time.perf_counter()
        res = discover(config_from_dict({"data": {"path": path, "unit": case.config.sensor.unit}}),
                       DiscoverSettings(scan_holds=opts.get("scan_holds", True)))
        dt = time.perf_counter() - t0
        lam, rel, genie = (visible_chi2(case, os.path.join(d, "clean.csv"), genie=True) if case.effect is not None
                           else (0.0, 0.0, {}))
    got = [(e.name, tuple(e.axes)) for e in res.effects]
    # a subset of the true axes named, every missing one reported as not ruled out (FoundEffect.unresolved_axes)
    subset = (len(res.effects) == 1 and res.effects[0].name == case.effect and EFFECTS[case.effect].axes_observable
              and set(res.effects[0].axes) < set(case.axes)
              and set(case.axes) - set(res.effects[0].axes) <= set(res.effects[0].unresolved_axes))
    on_time = step_on_time(case, res)
    if case.effect is None:
        outcome = "clean-ok" if not got else "false-positive"
    elif (got == [(case.effect, case.axes)] and on_time) or (
            effect != CROSS_TWO and not EFFECTS[case.effect].axes_observable and [n for n, _ in got] == [case.effect]):
        outcome = "correct"
    elif not got:
        outcome = "missed"
    elif (case.effect, case.axes) in got:
        outcome = "correct+extra"
    elif any(n == case.effect for n, _ in got):
        outcome = "wrong-axes"
    else:
        outcome = "wrong-effect"
    return {"seed": seed, "effect": effect, "snr": snr, "noise_mg": noise_mg, "outcome": outcome,
            "found": [e.label for e in res.effects], "truth": case.label, "step_on_time": on_time,
            "stochastic_called": stochastic_called(res), "verdict": res.verdict.outcome.value,
            "ambiguous": any(e.ambiguous_with for e in res.effects), "size_mg": case.size / STANDARD_GRAVITY * 1e3,
            "sigma_mean_mg": case.sigma_mean / STANDARD_GRAVITY * 1e3, "redchi_after": res.final.result.redchi,
            "gap_after": res.rms_after / res.rms_noise, "gap_before": res.rms_before / res.rms_noise,
            "counts": case.config.sensor.unit == "raw", "seconds": dt, "lam": lam, "lam_rel": rel, "oracle": oracle_power(lam),
            "genie": genie.get(DiscoverSettings().penalty, math.nan), "snr_size": phys, "subset_flagged": subset,
            "genie_by_penalty": {p: v for p, v in genie.items() if not isinstance(p, (tuple, str))},
            "genie_profiled": genie.get("profiled", math.nan),
            "genie_by_tau": {p[1]: v for p, v in genie.items() if isinstance(p, tuple)}}


#: The physical SNR at which --visible cases are first drawn (lambda is then scaled to the target).
_REFERENCE_SNR = 10.0


def visible_snr(seed: int, effect: str, snr: float, noise_mg: float, path: str, revisit: bool = False,
                weakest: bool = False, tau_known: bool = False, axes: tuple[int, ...] | None = None) -> float:
    """The physical SNR (size / sigma_mean) at which this seed's effect has sqrt(lambda) = ``snr``
    (with ``weakest``: its weakest coefficient is ``snr`` standard errors; ``tau_known``: see visible_chi2).

    The case is drawn at a reference size; every random draw (sensor, plan, axes, signs, warm-up tau,
    noise) is independent of the size and the effect is linear in its coefficients, so lambda grows
    with the square of the size: one reference lambda fixes the size. Infinite when lambda is 0."""
    from imucal.analysis.simulate import draw_effect_case

    lam0 = visible_chi2(draw_effect_case(seed, effect=effect, axes=axes, snr=_REFERENCE_SNR, noise_mg=noise_mg,
                                         revisit=revisit), path, rel=False, weakest=weakest, tau_known=tau_known)[0]
    return _REFERENCE_SNR * snr / math.sqrt(lam0) if lam0 > 1e-9 else math.inf


#: Issue 28's terms (docs/discover.md): what real MEMS do beyond the grammar before it.
NEW_TERMS = ("scale_asymmetry", "bias_step", "bias_hysteresis", "angle_temperature")
#: The cross-axis term on two axes whose coefficients nearly cancel (q_j = -1.1 q_i): |a| sees their small sum
#: to first order and each one's square to second order, so the SNR of these cells is far larger.
CROSS_TWO = "cross_axis_nonlinearity:2"
CROSS_TWO_SNR = (250.0, 500.0, 1000.0)
#: The default recording design: each pose held DEFAULT_HOLD s, sampled at DEFAULT_RATE Hz (draw_effect_case).
DEFAULT_HOLD, DEFAULT_RATE = 3.0, 100.0


def cancelling_cross_case(seed: int, snr: float, noise_mg: float):
    """A cross-axis term on two random axes, the second coefficient -1.1 times the first (the issue's case:
    q_y = +0.0047, q_z = -0.0052 leaves a first-order sum a tenth of either)."""
    import dataclasses

    from imucal.analysis.simulate import draw_effect_case

    rng = np.random.default_rng([seed, 28])
    axes = tuple(sorted(int(a) for a in rng.choice(3, 2, replace=False)))
    case = draw_effect_case(seed, effect="cross_axis_nonlinearity", axes=axes, snr=snr, noise_mg=noise_mg)
    q = case.config.sensor.effects["cross_axis_nonlinearity"]
    names = sorted(q)
    q = {names[0]: q[names[0]], names[1]: -1.1 * q[names[0]]}
    sensor = dataclasses.replace(case.config.sensor, effects={"cross_axis_nonlinearity": q})
    return dataclasses.replace(case, config=dataclasses.replace(case.config, sensor=sensor))


def step_on_time(case, res) -> bool:
    """A hidden bias step found inside its reported confidence set of change points (True for other terms)."""
    if case.effect != "bias_step":
        return True
    t = case.config.sensor.effects["bias_step"]["bias_step_t"]
    return any(e.change_point is not None and e.change_point.lower <= t <= e.change_point.upper
               for e in res.effects if e.name == "bias_step")


def stochastic_called(res) -> bool:
    """The verdict names a stochastic bias (alone or beside terms)."""
    from imucal.analysis.discover import Outcome

    return res.verdict.outcome in (Outcome.STOCHASTIC, Outcome.TERMS_AND_STOCHASTIC)


def run_pair(seed: int, snr: float, noise_mg: float, pool: tuple[str, ...], visible: bool | str = False) -> dict:
    """Two different effects, one axis each, same SNR: are both named, and nothing else? With ``visible``,
    each effect is scaled to that SNR on its own, as ``visible_snr`` scales a single one (the draws of a
    case do not depend on its size, so the pair is the same pair at another size)."""
    from imucal.config.run import config_from_dict
    from imucal.analysis.discover import discover
    from imucal.analysis.simulate import draw_effect_case, draw_pair_case, pair_config

    c1, c2 = draw_pair_case(seed, snr=_REFERENCE_SNR if visible else snr, noise_mg=noise_mg, candidates=pool)
    if visible:
        with tempfile.TemporaryDirectory() as d:
            c1, c2 = (draw_effect_case(seed, effect=c.effect, axes=c.axes, noise_mg=noise_mg,
                                       snr=visible_snr(seed, c.effect, snr, noise_mg, os.path.join(d, "ref.csv"),
                                                       weakest=str(visible).startswith("coefficient"),
                                                       tau_known=visible == "coefficient-tau-known", axes=c.axes))
                      for c in (c1, c2))
    with tempfile.TemporaryDirectory() as d:
        path = os.path.join(d, "case.csv")
        with open(path, "w") as f:
            f.write(pair_config(c1, c2).run().to_csv_text())
        t0 = time.perf_counter()
        res = discover(config_from_dict({"data": {"path": path, "unit": c1.config.sensor.unit}}))
        dt = time.perf_counter() - t0
    def label(name: str, axes) -> str:  # the cross-axis term's axis is a convention
        return name if not EFFECTS[name].axes_observable else f"{name}[{EFFECTS[name].axis_label(axes)}]"

    found = sorted(label(e.name, e.axes) for e in res.effects)
    truth = sorted([label(c1.effect, c1.axes), label(c2.effect, c2.axes)])
    outcome = "pair-correct" if found == truth else ("pair-one" if set(found) & set(truth) else "pair-none")
    return {"seed": seed, "effect": "pair", "snr": snr, "noise_mg": noise_mg, "outcome": outcome,
            "found": found, "truth": " + ".join(truth), "ambiguous": any(e.ambiguous_with for e in res.effects),
            "size_mg": c1.size / STANDARD_GRAVITY * 1e3, "sigma_mean_mg": c1.sigma_mean / STANDARD_GRAVITY * 1e3,
            "redchi_after": res.final.result.redchi, "seconds": dt, "counts": c1.config.sensor.unit == "raw",
            "gap_after": res.rms_after / res.rms_noise, "gap_before": res.rms_before / res.rms_noise,
            "lookahead": any(s.jointly_with for s in res.steps), "stochastic_called": stochastic_called(res),
            "verdict": res.verdict.outcome.value}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--noise", type=float, nargs="+", help="noise per sample [mg] (default 0.3)")
    ap.add_argument("--snr", type=float, nargs="+", help="effect sizes / sigma_mean (default 5 10 20 40)")
    ap.add_argument("--cases", type=int, help="cases per (effect, noise, snr) cell (default 8)")
    ap.add_argument("--clean", type=int, help="clean cases per noise level (default 200)")
    ap.add_argument("--pairs", type=int, help="two-effect cases per pair SNR and noise level (default 10)")
    ap.add_argument("--pair-snr", type=float, nargs="+", help="SNR of each effect of a pair (default 10 20 40)")
    ap.add_argument("--jobs", type=int, default=max(1, (os.cpu_count() or 1)), help="worker processes")
    ap.add_argument("--seed", type=int, default=50000, help="first seed")
    ap.add_argument("--quick", action="store_true", help="a reduced run: 2 cases per cell, SNR 10 and 40, 1 noise")
    ap.add_argument("--classic", action="store_true", help="only the five effects before the grammar, with the "
                    "classic study's sizes (noise 0.1 0.3 1, SNR 10-60, 20 cases, 40 clean, pairs at SNR 20 and 40)")
    ap.add_argument("--new-terms", action="store_true", help="issue 28's terms (NEW_TERMS) at SNR 5-40, 16 cases a cell, "
                    "their pairs with the classic five at SNR 10, 20 and 40, the cancelling two-axis cross-axis term "
                    "(CROSS_TWO_SNR) and 200 clean cases; writes studies/results/discover_new_terms_study.md; with --visible "
                    "--coefficient: each term and each member of a pair scaled to its weakest coefficient's SNR 10, 20 "
                    "and 40, writes studies/results/discover_new_terms_coefficient_study.md")
    ap.add_argument("--effects", nargs="+", choices=list(EFFECTS), help="terms to hide (default: the grammar)")
    ap.add_argument("--visible", action="store_true", help="SNR = sqrt(lambda), what the data can see of the "
                    "effect (its coefficient in standard errors beside the base model), instead of size / sigma_mean; "
                    "SNR 5 10 20, no pairs; writes studies/results/discover_visible_study.md")
    ap.add_argument("--coefficient", action="store_true", help="with --visible: SNR = the term's weakest "
                    "coefficient in standard errors (beside the base model and its other coefficients), so every "
                    "true axis is SNR-visible (a warm-up's tau fitted beside them); writes "
                    "docs/discover_[revisit_]coefficient_study.md")
    ap.add_argument("--tau-known", action="store_true", help="with --coefficient: a warm-up's standard errors with "
                    "its tau held at the true value, which no fit knows (smaller errors, so smaller warm-ups)")
    ap.add_argument("--revisit", action="store_true", help="every pose held twice, the second pass in reverse order "
                    "(36-52 holds; imucal.analysis.simulate.draw_effect_case); no pairs")
    ap.add_argument("--step-anywhere", action="store_true", help="a bias step's time drawn over the holds and the "
                    "moves alike (by default it falls in a move); size SNR; writes "
                    "studies/results/discover_step_anywhere_study.md")
    ap.add_argument("--no-hold-scan", action="store_true", help="discover without its scan of the still intervals for "
                    "a step inside them (DiscoverSettings.scan_holds: the code before it), for comparison")
    ap.add_argument("--hold", type=float, default=DEFAULT_HOLD, help="each pose held this long [s] (default 3): "
                    "another recording design, written to studies/results/discover_design_HOLDs_RATEhz_study.md")
    ap.add_argument("--rate", type=float, default=DEFAULT_RATE, help="sample rate [Hz] (default 100); with --hold")
    ap.add_argument("--rows", help="re-render the page from a run's rows (OUT.rows.json) instead of running the cases")
    ap.add_argument("--out", help="markdown file to write (default studies/results/discover_grammar_study.md)")
    a = ap.parse_args(argv)
    given = list(sys.argv[1:] if argv is None else argv)  # the command as run, less what does not change results
    for opt in ("--out", "--jobs", "--rows"):
        while opt in given:
            i = given.index(opt)
            del given[i:i + 2]
    a.command = "".join(f" {x}" for x in given)
    size = (dict(noise=[0.1, 0.3, 1.0], snr=[10, 15, 20, 30, 40, 60], cases=20, clean=40, pairs=30, pair_snr=[20, 40])
            if a.classic else dict(noise=[0.3], snr=[5, 10, 20, 40], cases=8, clean=200, pairs=10, pair_snr=[10, 20, 40]))
    if a.visible:
        size.update(snr=[5, 10, 20], pairs=0, pair_snr=[])
    if a.revisit:
        size.update(pairs=0, pair_snr=[])
    if a.new_terms:
        size.update(noise=[0.3], snr=[10, 20, 40] if a.visible else [5, 10, 20, 40], cases=16, clean=200, pairs=20,
                    pair_snr=[10, 20, 40])
    if a.step_anywhere:
        if a.visible:
            ap.error("--step-anywhere measures by the size SNR: leave out --visible")
        size.update(noise=[0.3], snr=[10, 20, 40], cases=16, clean=50)
    design = (a.hold, a.rate) != (DEFAULT_HOLD, DEFAULT_RATE)
    if not (0.5 <= a.hold <= 600 and 10 <= a.rate <= 2000):
        ap.error("--hold must be 0.5 to 600 s and --rate 10 to 2000 Hz")
    if design and (a.visible or a.revisit or a.new_terms or a.classic):
        ap.error("--hold / --rate is a study of its own (size SNR, every term, no pairs): leave out the other modes")
    if design:  # size SNR, no pairs: how far the default design's results carry
        size.update(noise=[0.3], snr=[10, 20], cases=4, clean=60, pairs=0, pair_snr=[])
    if a.quick:
        size.update(noise=[0.3], snr=[10, 40], cases=2, clean=4, pairs=2, pair_snr=[40])
    if a.step_anywhere:  # one term: no pairs
        size.update(pairs=0, pair_snr=[])
    for k, v in size.items():
        if getattr(a, k) is None:
            setattr(a, k, v)
    if a.out is None:
        a.out = str(ROOT / "studies" / "results" / (
            f"discover_design_{a.hold:g}s_{a.rate:g}hz_study.md" if design else
            f"discover_step_anywhere{'_no_scan' if a.no_hold_scan else ''}_study.md" if a.step_anywhere else
            "discover_study.md" if a.classic else
                                     "discover_new_terms_coefficient_study.md" if a.new_terms and a.coefficient else
                                     "discover_new_terms_study.md" if a.new_terms else
                                     ("discover_revisit_" if a.revisit else "discover_") +
                                     ("coefficient_tau_known_study.md" if a.visible and a.tau_known else
                                      "coefficient_study.md" if a.visible and a.coefficient else
                                      "visible_study.md" if a.visible else "grammar_study.md")))
    a.terms = tuple(a.effects or (CLASSIC if a.classic else NEW_TERMS if a.new_terms else
                                  ("bias_step",) if a.step_anywhere else EFFECTS))
    a.pool = (*NEW_TERMS, *CLASSIC) if a.new_terms else a.terms  # the pairs' terms
    if a.coefficient and not a.visible:
        ap.error("--coefficient is a definition of the visible SNR: use it with --visible")
    if a.tau_known and not a.coefficient:
        ap.error("--tau-known is a variant of --coefficient: use it with --visible --coefficient")
    mode = ("coefficient-tau-known" if a.tau_known else "coefficient") if a.coefficient else a.visible
    opts = {"step_anywhere": a.step_anywhere, "scan_holds": not a.no_hold_scan, "hold": a.hold, "rate": a.rate}
    jobs = []
    seed = a.seed
    for noise in a.noise:
        for _ in range(a.clean):
            jobs.append((seed, None, 0.0, noise, a.terms, mode, a.revisit, opts))
            seed += 1
        for eff in a.terms:
            for snr in a.snr:
                for _ in range(a.cases):
                    jobs.append((seed, eff, snr, noise, a.pool, mode, a.revisit, opts))
                    seed += 1
        for snr in (CROSS_TWO_SNR if a.new_terms else ()):
            for _ in range(a.cases):
                jobs.append((seed, CROSS_TWO, snr, noise, a.pool, mode, a.revisit, opts))
                seed += 1
        for snr in a.pair_snr:
            for _ in range(a.pairs):
                jobs.append((seed, "pair", snr, noise, a.pool, mode, a.revisit, opts))
                seed += 1
    from imucal.files.output import write_text_atomic

    rows_path = Path(a.out).with_suffix(".rows.json")  # every case's row: the page re-rendered without a rerun
    if a.rows:
        saved = json.loads(Path(a.rows).read_text())
        rows, wall, a.jobs = saved["rows"], saved["wall"], saved.get("jobs", a.jobs)
        for r in rows:  # (JSON wrote the penalties and prices keying these as strings)
            for k in ("genie_by_penalty", "genie_by_tau"):
                r[k] = {float(x): v for x, v in r.get(k, {}).items()}
    else:
        t0 = time.perf_counter()
        rows = []
        with mp.get_context("fork").Pool(a.jobs) as pool, progress("cases", total=len(jobs), unit="case") as step:
            for row in pool.imap_unordered(run_case, jobs, chunksize=2):
                rows.append(row)
                step()
        rows.sort(key=lambda r: r["seed"])
        wall = time.perf_counter() - t0
        write_text_atomic(rows_path, json.dumps({"command": a.command, "wall": wall, "jobs": a.jobs, "rows": rows},
                                                  default=_plain))
    text = report(rows, a, wall)
    write_text_atomic(a.out, text)
    print(text)
    return 0


def _plain(x):
    """JSON for the rows' numpy scalars and tuples."""
    return x.item() if hasattr(x, "item") else list(x)


#: lambda bins of the pooled table [chi-square].
LAMBDA_BINS = (0, 10, 20, 30, 40, 60, 100, math.inf)


def visibility(rows: list[dict], cells: dict, a: argparse.Namespace) -> list[str]:
    """What the data can see at each SNR (median lambda and lambda_rel, mean oracle power), and the
    share named correctly pooled over the terms by lambda and by lambda_rel."""
    L = ["## What the data can see: lambda, lambda_rel and the oracle", "",
         "lambda = chi-square the noise-free effect adds to the base fit; lambda_rel = what is left of it when "
         "its closest relative (another candidate of the round, not containing the truth) is fitted instead: "
         "the evidence that separates the right name from the nearest wrong one. Medians over the cell; "
         "oracle = mean power of a single test at 1e-3 that knows term, axes and signs, "
         "P(chi2_1(lambda) > 10.83). No method detects a term more often than its oracle, nor tells it from "
         "a relative when lambda_rel is a few units. *selection* = mean share of noise draws in which discovery's "
         "own ranking (chi-square removed minus the penalty per parameter), applied to every candidate of the "
         f"first round by an exact linear search, names exactly the truth ({GENIE_DRAWS} draws per case, "
         "`selection_oracle`): the same information without the search's losses. Where correct is near "
         "selection, the misses are the data's, not the search's.", "",
         "| effect | " + " | ".join(f"SNR {s:g}: lambda / lambda_rel / oracle / selection"
                                    f"{' / size SNR' if a.visible else ''}" for s in a.snr) + " |",
         "|---|" + "---|" * len(a.snr)]
    for eff in a.terms:
        vals = []
        for s in a.snr:
            cs = [r for n in a.noise for r in cells[(eff, n, s)]]
            vals.append(f"{np.median([r['lam'] for r in cs]):.3g} / {np.median([r['lam_rel'] for r in cs]):.3g} / "
                        f"{np.mean([r['oracle'] for r in cs]):.0%} / {np.mean([r['genie'] for r in cs]):.0%}"
                        + (f" / {np.median([r['snr_size'] for r in cs]):.3g}" if a.visible else "") if cs else "-")
        L.append(f"| {eff} | " + " | ".join(vals) + " |")
    single = [r for r in rows if r["effect"] not in (None, "pair")]
    for key, what in (("lam", "lambda"), ("lam_rel", "lambda_rel")):
        L += ["", f"Pooled over all terms and SNRs, by {what}:", "",
              f"| {what} | cases | correct | oracle | missed | wrong term | wrong axes |", "|---|---|---|---|---|---|---|"]
        for lo, hi in zip(LAMBDA_BINS[:-1], LAMBDA_BINS[1:]):
            cs = [r for r in single if lo <= r[key] < hi]
            if cs:
                n = len(cs)
                count = lambda *o: sum(r["outcome"] in o for r in cs)  # noqa: E731
                L.append(f"| {lo:g}-{hi:g} | {n} | {count('correct') / n:.0%} | "
                         f"{np.mean([r['oracle'] for r in cs]):.0%} | {count('missed') / n:.0%} | "
                         f"{count('wrong-effect') / n:.0%} | {count('wrong-axes', 'correct+extra') / n:.0%} |")
    pens = sorted({p for r in single for p in r.get("genie_by_penalty", {})})
    if pens:
        L += ["", "The selection oracle by the penalty per parameter (mean share named exactly; in brackets the "
              "terms at >= 90 %): whether another penalty would let the same ranking name more.", "",
              "| SNR | " + " | ".join(f"penalty {p:g}" for p in pens) + " |", "|---|" + "---|" * len(pens)]
        for s in a.snr:
            cs = [r for r in single if r["snr"] == s and r.get("genie_by_penalty")]
            vals = []
            for p in pens:
                by = defaultdict(list)
                for r in cs:
                    by[r["effect"]].append(r["genie_by_penalty"][p])
                vals.append(f"{np.mean([r['genie_by_penalty'][p] for r in cs]):.0%} "
                            f"({sum(np.mean(v) >= RELIABLE for v in by.values())} of {len(by)})")
            L.append(f"| {s:g} | " + " | ".join(vals) + " |")
    taus = sorted({t for r in single for t in r.get("genie_by_tau", {})})
    timed = sorted({r["effect"] for r in single if r.get("genie_by_tau")}
                   & {n for n in EFFECTS if "time" in EFFECTS[n].covariates or "temp" in EFFECTS[n].covariates},
                   key=list(EFFECTS).index)
    if taus and timed:
        from imucal.analysis.discover import DiscoverSettings

        own = DiscoverSettings().penalty
        L += ["", f"The selection oracle by the price of a warm-up's tau (coefficients at {own:.4g}; mean share "
              "named exactly per term in time or temperature, and over all terms): whether tau should cost "
              "less or more than a coefficient.", "",
              "| SNR | term | " + " | ".join(f"tau {t:g}" for t in taus) + f" | tau {own:.4g} (as now) |",
              "|---|---|" + "---|" * (len(taus) + 1)]
        for s in a.snr:
            cs = [r for r in single if r["snr"] == s and r.get("genie_by_tau")]
            for eff in [*timed, None]:
                es = [r for r in cs if eff is None or r["effect"] == eff]
                if es:
                    L.append(f"| {s:g} | {eff or 'all terms'} | "
                             + " | ".join(f"{np.mean([r['genie_by_tau'][t] for r in es]):.0%}" for t in taus)
                             + f" | {np.mean([r['genie'] for r in es]):.0%} |")
    shaped = [n for n in dict.fromkeys(r["effect"] for r in single) if n in EFFECTS and make_effect(n, (0,)).shape_names]
    if shaped and any(math.isfinite(r.get("genie_profiled", math.nan)) for r in single):
        L += ["", "The selection oracle gives the truth's term its exact tau and every other warm-up candidate only "
              "discover's screening grid. *Profiled*: every warm-up candidate, the truth's included, profiled over "
              f"{len(PROFILE_TAU_GRID)} values of tau 15 % apart (PROFILE_TAU_GRID), as discover fits tau for every "
              "warm-up it tries: an exact search with no candidate told the true tau.", "",
              "| SNR | term | discover | selection oracle | profiled |", "|---|---|---|---|---|"]
        for s in a.snr:
            cs = [r for r in single if r["snr"] == s and math.isfinite(r.get("genie_profiled", math.nan))]
            for eff in [*shaped, None]:
                es = [r for r in cs if eff is None or r["effect"] == eff]
                if es:
                    L.append(f"| {s:g} | {eff or 'all terms'} | {np.mean([r['outcome'] == 'correct' for r in es]):.0%} | "
                             f"{np.mean([r['genie'] for r in es]):.0%} | {np.mean([r['genie_profiled'] for r in es]):.0%} |")
    return L + [""]


def new_terms_block(rows: list[dict], a: argparse.Namespace) -> list[str]:
    """Issue 28's targets: each new term named exactly at SNR >= 10, the cancelling cross-axis pair, a
    deterministic truth called stochastic, clean cases named nothing."""
    det = [r for r in rows if r["effect"] is not None and r["outcome"] != "invisible" and r["snr"] >= 10]
    called = [r for r in det if r.get("stochastic_called")]
    pairs = [r for r in rows if r["effect"] == "pair" and r["snr"] >= 10]
    L = ["<!-- begin:new_terms -->", f"Named right (exact term and axes, nothing else) per term and SNR; *in pairs*: of "
         f"the two-term cases at SNR >= 10 that hide the term (beside another new term or a classic one), the share "
         f"naming it on exactly its axes. Target: >= {RELIABLE:.0%} at SNR >= 10, single and in pairs.", "",
         "| term | " + " | ".join(f"SNR {s:g}" for s in a.snr) + " | single at SNR >= 10 | in pairs at SNR >= 10 | "
         "target |", "|---|" + "---|" * (len(a.snr) + 3)]
    for t in a.terms:
        cs = {s: [r for r in rows if r["effect"] == t and r["snr"] == s] for s in a.snr}
        ok = [r["outcome"] == "correct" for s in a.snr if s >= 10 for r in cs[s]]
        mine = [(r, next(x for x in r["truth"].split(" + ") if x.startswith(t + "["))) for r in pairs
                if any(x.startswith(t + "[") for x in r["truth"].split(" + "))]
        in_pairs = [lab in r["found"] for r, lab in mine]
        met = bool(ok) and np.mean(ok) >= RELIABLE and (not in_pairs or np.mean(in_pairs) >= RELIABLE)
        L.append(f"| {t} | " + " | ".join(f"{sum(r['outcome'] == 'correct' for r in cs[s])}/{len(cs[s])}" for s in a.snr)
                 + f" | {np.mean(ok):.1%} | " + (f"{sum(in_pairs)}/{len(in_pairs)}" if in_pairs else "-")
                 + f" | {'met' if met else 'NOT met'} |")
    cross = [r for r in rows if r["effect"] == CROSS_TWO]
    L += ["", "The cross-axis term on two axes, q_j = -1.1 q_i (SNR of each coefficient's size; "
          "named right = the term on exactly its two axes):", "",
          "| SNR | q_i [1/(m/s^2)] (median) | named right | the term on other axes | nothing |", "|---|---|---|---|---|"]
    for s in sorted({r["snr"] for r in cross}):
        cs = [r for r in cross if r["snr"] == s]
        L.append(f"| {s:g} | {np.median([r['size_mg'] for r in cs]) * 1e-3 * STANDARD_GRAVITY / (STANDARD_GRAVITY**2 / 2):.2g} "
                 f"| {sum(r['outcome'] == 'correct' for r in cs)}/{len(cs)} | "
                 f"{sum(r['outcome'] in ('wrong-axes', 'correct+extra') for r in cs)} | {sum(r['outcome'] == 'missed' for r in cs)} |")
    clean = [r for r in rows if r["effect"] is None]
    L += ["", f"A deterministic truth (a single term at SNR >= 10, a pair, or the cancelling cross-axis pair) called "
          f"\"stochastic\" (the verdict names a stochastic bias): {len(called)} of {len(det)} "
          f"(target: at most 1 of 50, i.e. {len(det) / 50:.3g} here: {'met' if len(called) <= len(det) / 50 else 'NOT met'}).",
          f"Clean recordings that named an effect: {sum(r['outcome'] == 'false-positive' for r in clean)} of {len(clean)}; "
          f"that named a stochastic bias: {sum(bool(r.get('stochastic_called')) for r in clean)}.",
          "<!-- end:new_terms -->", ""]
    if called:
        L += ["| seed | truth | SNR | found | verdict |", "|---|---|---|---|---|"]
        L += [f"| {r['seed']} | {r['truth']} | {r['snr']:g} | {', '.join(r['found'])} | {r.get('verdict')} |" for r in called]
        L.append("")
    return L


def summary_block(rows: list[dict], a: argparse.Namespace) -> list[str]:
    """The pooled results (the README's block): correct share and oracle by SNR, pairs, clean cases."""
    single = [r for r in rows if r["effect"] not in (None, "pair") and r["outcome"] != "invisible"]
    clean = [r for r in rows if r["effect"] is None]
    L = ["<!-- begin:summary -->",
         f"Clean recordings: {sum(r['outcome'] == 'false-positive' for r in clean)} of {len(clean)} named an effect.",
         "", "| SNR | single terms: correct (exact term and axes) | oracle (mean) | selection oracle (mean) | "
         "terms at >= 90 % | terms whose selection oracle is >= 90 % | pairs: both named |",
         "|---|---|---|---|---|---|---|"]
    for snr in sorted(set(a.snr) | set(a.pair_snr)):
        cs = [r for r in single if r["snr"] == snr]
        ps = [r for r in rows if r["effect"] == "pair" and r["snr"] == snr]
        good = [t for t in a.terms if (ts := [r for r in cs if r["effect"] == t])
                and np.mean([r["outcome"] == "correct" for r in ts]) >= RELIABLE]
        able = [t for t in a.terms if (ts := [r for r in cs if r["effect"] == t]) and np.mean([r["genie"] for r in ts]) >= RELIABLE]
        ok = sum(r["outcome"] == "correct" for r in cs)
        L.append(f"| {snr:g} | " + (f"{ok}/{len(cs)} ({ok / len(cs):.0%}) | {np.mean([r['oracle'] for r in cs]):.0%} | "
                                    f"{np.mean([r['genie'] for r in cs]):.0%} | {len(good)} of {len(a.terms)} | "
                                    f"{len(able)} of {len(a.terms)} |" if cs else "- | - | - | - | - |")
                 + (f" {sum(r['outcome'] == 'pair-correct' for r in ps)}/{len(ps)} |" if ps else " - |"))
    wrong = [r for r in single if r["outcome"] == "wrong-effect"]
    axes = [r for r in single if r["outcome"] == "wrong-axes"]
    L += ["", f"A wrong term was named in {len(wrong)} of {len(single)} single-term cases; the report flagged the "
          f"ambiguity in {sum(r['ambiguous'] for r in wrong)} of them. The right term on the wrong axes: "
          f"{len(axes)} cases; in {sum(r.get('subset_flagged', False) for r in axes)} of them a subset of the true "
          "axes, with every missing axis reported as not ruled out."]
    if getattr(a, "step_anywhere", False):
        hid = [r for r in single if r["snr"] >= 10]
        L += ["", f"A step called stochastic (the verdict names a stochastic bias) at SNR >= 10: "
              f"{sum(r['stochastic_called'] for r in hid)} of {len(hid)} (issue 28's target: at most 1 in 50)."]
    if (getattr(a, "hold", DEFAULT_HOLD), getattr(a, "rate", DEFAULT_RATE)) != (DEFAULT_HOLD, DEFAULT_RATE):
        hid = [r for r in single if r["snr"] >= 10]
        alone = [r for r in hid if r["stochastic_called"] and not r["found"]]
        L += ["", f"A hidden term called stochastic (the verdict names a stochastic bias) at SNR >= 10: "
              f"{sum(r['stochastic_called'] for r in hid)} of {len(hid)}; with no term named beside it: {len(alone)} "
              f"({', '.join(sorted(r['truth'] for r in alone)) or 'none'})."]
    L += ["<!-- end:summary -->", ""]
    return L


def report(rows: list[dict], a: argparse.Namespace, wall: float) -> str:
    L = ["# Discover: detection rate, smallest detectable effect, false positives", "",
         f"Measured by `python studies/discover_study.py{a.command}` ({len(rows)} seeded cases, {wall / 60:.1f} min "
         f"wall time on {a.jobs} process{'es' if a.jobs != 1 else ''}, first seed {a.seed}; terms: {', '.join(a.terms)}; noise "
         f"{', '.join(f'{n:g}' for n in a.noise)} mg; SNR {', '.join(f'{s:g}' for s in a.snr)}; {a.cases} cases per cell, "
         f"{a.clean} clean cases and {a.pairs} pairs per SNR {', '.join(f'{s:g}' for s in a.pair_snr)} per noise level). "
         "Each case: a random sensor (raw counts with "
         "quantisation, or factory-scaled m/s^2), "
         + (f"18-26 poses of {a.hold:g} s at {a.rate:g} Hz, each held twice (the second pass in reverse order: "
            "36-52 holds), " if a.revisit else f"18-26 poses of {a.hold:g} s at {a.rate:g} Hz, ") + "warm-up plus non-monotonic "
         "temperature swing, one effect on a random axis subset with a random sign, or none. "
         "Discover is told nothing.", "",
         "*Size* = largest change of a reading at 1 g over the recording [mg]. *sigma_mean* = noise of one "
         "interval mean = noise per sample / sqrt(samples per interval) [mg]. "
         + ("*SNR* = the term's weakest coefficient in standard errors when the term is fitted beside the base "
            "model: sqrt of the chi-square that coefficient's part of the effect adds with the base model and the "
            "term's other coefficients fitted (for a term on one axis, sqrt(lambda)), so every true axis is at "
            "least SNR standard errors visible. "
            + ("A warm-up's tau is held at its true value, which no fit knows. " if a.tau_known else
               "A warm-up's tau is fitted beside its coefficients, as discover and calibrate fit it (linearised at "
               "the true term). ")
            + "Each case's size is scaled to give it "
            if a.visible and a.coefficient else
            "*SNR* = sqrt(lambda), lambda as below: the effect's coefficient in standard errors when it is fitted "
            "beside the base model (the deflection of detection theory). Each case's size is scaled to give it "
            if a.visible else "")
         + ("(the random draws do not depend on the size); *size SNR* = size / sigma_mean, the physical "
            "definition of studies/results/discover_grammar_study.md, is reported beside it. "
            if a.visible else "*SNR* = size / sigma_mean. ")
         + ("In a pair each term is scaled on its own, as a single one (beside the base model, not beside the "
            "other term); the cancelling cross-axis cells keep their size SNR. " if a.visible and a.new_terms else "")
         + "*Correct* = exactly the hidden effect on exactly its axes, nothing else. *lambda* = the chi-square the "
         "noise-free effect adds to the base fit (what the data can see of it), *oracle* = P(chi2_1(lambda) > 10.83).",
         ""]
    L += summary_block(rows, a)
    L += new_terms_block(rows, a) if a.new_terms else []
    clean = [r for r in rows if r["effect"] is None]
    L += ["## False positives on clean data", "", "| noise per sample [mg] | clean cases | effects named |",
          "|---|---|---|"]
    for noise in a.noise:
        cs = [r for r in clean if r["noise_mg"] == noise]
        fp = sum(r["outcome"] == "false-positive" for r in cs)
        L.append(f"| {noise:g} | {len(cs)} | {fp} |")
    L.append("")
    L += ["## Correct effect and axes, by SNR", "",
          "| effect | noise [mg] | " + " | ".join(f"SNR {s:g}" for s in a.snr) + " |",
          "|---|---|" + "---|" * len(a.snr)]
    cells: dict = defaultdict(list)
    for r in rows:
        if r["effect"] not in (None, "pair") and r["outcome"] != "invisible":  # (listed under All outcomes)
            cells[(r["effect"], r["noise_mg"], r["snr"])].append(r)
    for eff in a.terms:
        for noise in a.noise:
            vals = []
            for s in a.snr:
                cs = cells[(eff, noise, s)]
                vals.append(f"{sum(r['outcome'] == 'correct' for r in cs)}/{len(cs)}")
            L.append(f"| {eff} | {noise:g} | " + " | ".join(vals) + " |")
    L.append("")
    L += visibility(rows, cells, a)
    L += [f"## Smallest reliably found effect ({RELIABLE:.0%} correct at this SNR and at every larger one tried)",
          "", "| effect | noise per sample [mg] | sigma_mean [mg] | smallest SNR | smallest size [mg] |",
          "|---|---|---|---|---|"]
    for eff in a.terms:
        for noise in a.noise:
            ok = [s for s in a.snr if cells[(eff, noise, s)]
                  and np.mean([r["outcome"] == "correct" for r in cells[(eff, noise, s)]]) >= RELIABLE]
            smallest = next((s for s in a.snr if all(t in ok for t in a.snr if t >= s)), None)
            sig = np.nanmean([r["sigma_mean_mg"] for r in rows if r["noise_mg"] == noise])
            if smallest is None:
                L.append(f"| {eff} | {noise:g} | {sig:.3g} | > {max(a.snr):g} | - |")
            else:  # with --visible the size of a given SNR differs from case to case: the cell's median
                size = (np.median([r["size_mg"] for r in cells[(eff, noise, smallest)]]) if a.visible
                        else smallest * sig)
                L.append(f"| {eff} | {noise:g} | {sig:.3g} | {smallest:g} | {size:.3g} |")
    L.append("")
    pairs = [r for r in rows if r["effect"] == "pair"]
    if pairs:
        L += ["## Two effects at once", "",
              "Two different effects, each on one random axis, both of the given SNR, in one recording. "
              "*Both* = exactly the two, nothing else; *lookahead* = a round in which no single effect was "
              "significant on its own and the pair test added one.", "",
              "| SNR of each | noise [mg] | cases | both named | one of them | none | lookahead used |",
              "|---|---|---|---|---|---|---|"]
        for snr in a.pair_snr:
            for noise in a.noise:
                cs = [r for r in pairs if r["snr"] == snr and r["noise_mg"] == noise]
                if cs:
                    L.append(f"| {snr:g} | {noise:g} | {len(cs)} | {sum(r['outcome'] == 'pair-correct' for r in cs)} | "
                             f"{sum(r['outcome'] == 'pair-one' for r in cs)} | "
                             f"{sum(r['outcome'] == 'pair-none' for r in cs)} | {sum(r['lookahead'] for r in cs)} |")
        L.append("")
    L += ["## By sensor kind and the gap closed", "",
          "Correct share per sensor kind (raw counts with quantisation / factory-scaled m/s^2), single terms at "
          "SNR >= 10; *gap* = RMS of |a| - g on interval means over the RMS the noise alone gives (median), "
          "before and after discovery, over the correctly named cases.", "",
          "| sensor | cases | correct | gap before | gap after |", "|---|---|---|---|---|"]
    single = [r for r in rows if r["effect"] not in (None, "pair") and r["snr"] >= 10]
    for kind, flag in (("counts", True), ("SI (m/s^2)", False)):
        cs = [r for r in single if r["counts"] == flag]
        ok = [r for r in cs if r["outcome"] == "correct"]
        if cs:
            L.append(f"| {kind} | {len(cs)} | {len(ok)} ({len(ok) / len(cs):.0%}) | "
                     f"{np.median([r['gap_before'] for r in ok]) if ok else float('nan'):.3g} | "
                     f"{np.median([r['gap_after'] for r in ok]) if ok else float('nan'):.3g} |")
    L.append("")
    outcomes = defaultdict(int)
    for r in rows:
        outcomes[r["outcome"]] += 1
    L += ["## All outcomes", "", "| outcome | cases |", "|---|---|"]
    L += [f"| {k} | {v} |" for k, v in sorted(outcomes.items())]
    amb = sum(r["ambiguous"] for r in rows)
    L += ["", f"{amb} cases reported an ambiguity (a competitor within the ambiguity margin).", ""]
    we = [r for r in rows if r["outcome"] == "wrong-effect"]
    if we:
        L += [f"Wrong effect named in {len(we)} of {sum(r['effect'] not in (None, 'pair') for r in rows)} "
              f"single-effect cases, at SNR <= {max(r['snr'] for r in we):g}; the ambiguity was flagged in "
              f"{sum(r['ambiguous'] for r in we)} of them.", ""]
    wrong = [r for r in rows if r["outcome"] not in ("correct", "clean-ok", "missed", "pair-correct")]
    if wrong:
        L += ["## Misidentified cases", "", "*Missing axes flagged*: a subset of the true axes was named and the report "
              "says every missing axis is not ruled out.", "",
              "*Selection* = the selection oracle of the case (above).", "",
              "| seed | truth | SNR | noise [mg] | found | ambiguity flagged | missing axes flagged | lambda_rel | "
              "selection |", "|---|---|---|---|---|---|---|---|---|"]
        for r in wrong:
            g, lr = r.get("genie", math.nan), r.get("lam_rel", math.nan)  # (pairs have neither)
            L.append(f"| {r['seed']} | {r['truth']} | {r['snr']:g} | {r['noise_mg']:g} | {', '.join(r['found'])} | "
                     f"{'yes' if r['ambiguous'] else 'no'} | {'yes' if r.get('subset_flagged') else '-'} | "
                     f"{'-' if not math.isfinite(lr) else f'{lr:.3g}'} | {'-' if not math.isfinite(g) else f'{g:.0%}'} |")
        L.append("")
    secs = [r["seconds"] for r in rows]
    L += [f"Discover took {np.median(secs):.2f} s per case (median), {np.max(secs):.1f} s at most.", ""]
    return "\n".join(L)


if __name__ == "__main__":
    raise SystemExit(main())
