"""`discover` over the effect grammar: each term the grammar added to the classic five, hidden in a hand-built
recording, is named (term and axes), clean data stay clean (issue 28's terms: test_discover_real_mems.py)."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from imucal.analysis.discover import DiscoverSettings, Outcome, discover
from imucal.report.discover_text import discovery_report
from imucal.solve.f_test import f_sf
from imucal.analysis.simulate import draw_effect_case
from imucal.config.run import config_from_dict
from imucal.model.effects import CLASSIC, EFFECTS, make_effect, recurrence

#: The terms the grammar added to the classic five (issue 28's, what real MEMS do, are tested apart).
ISSUE28 = ("scale_asymmetry", "bias_step", "bias_hysteresis", "angle_temperature")
NEW_TERMS = [n for n in EFFECTS if n not in CLASSIC and n not in ISSUE28]
#: (axes, seed) of each hand-built case: one or two axes, SNR 60 (docs/discover.md measures the rest).
AXES = {"bias_temperature2": (0,), "scale_temperature2": (1, 2), "bias_temperature3": (2,),
        "scale_temperature3": (0,), "bias_drift2": (1,), "scale_drift2": (0, 2), "bias_warmup": (0, 1),
        "scale_warmup": (2,), "scale_nonlinearity3": (0, 1), "cross_axis_nonlinearity": (2,)}


def _discover(case, tmp_path, name, sim=None):
    path = tmp_path / f"{name}.csv"
    path.write_text((sim or case.config.run()).to_csv_text())
    return discover(config_from_dict({"data": {"path": str(path), "unit": case.config.sensor.unit}}),
                    DiscoverSettings())


def test_every_new_term_has_a_hand_built_case():
    assert sorted(AXES) == sorted(NEW_TERMS) and len(NEW_TERMS) == 10


@pytest.mark.parametrize("name", NEW_TERMS)
def test_each_new_term_is_named_with_its_axes(name, tmp_path):
    seed = 9200 if name == "cross_axis_nonlinearity" else 9100 + NEW_TERMS.index(name)  # 9200: a plan with corners
    case = draw_effect_case(seed, effect=name, axes=AXES[name], snr=60.0)
    d = _discover(case, tmp_path, name)
    assert d.consistent_after and d.rms_after < d.rms_before
    if not EFFECTS[name].axes_observable:  # the axis is a convention: test_cross_axis_term_is_named_...
        assert [(e.name, len(e.axes)) for e in d.effects] == [(name, 1)], d.verdict
        return
    assert [(e.name, e.axes) for e in d.effects] == [(name, AXES[name])], d.verdict
    (e,) = d.effects
    truth = case.config.sensor.effects[name]
    eff = make_effect(name, AXES[name])
    for n in eff.coefficient_names:  # the coefficients, with standard errors and units
        assert e.units[n] and np.isfinite(e.std[n]) and e.std[n] > 0
        assert abs(e.coefficients[n] - truth[n]) < 5 * e.std[n] + 0.05 * abs(truth[n]), (n, e.coefficients[n], truth[n])
    for n in eff.shape_names:  # the warm-up's tau, fitted and reported with its error
        assert n in e.coefficients and e.units[n] == "s" and np.isfinite(e.std[n])
        assert abs(e.coefficients[n] - truth[n]) < 5 * e.std[n] + 0.1 * truth[n], (n, e.coefficients[n], truth[n])
    for n in eff.reference_names:  # references recorded in the result and the calibration file
        assert n in e.reference and d.final.calibration.params[n].fixed
    if "temperature" in name and name.endswith(("2", "3")):
        assert f"{name}_tref" in discovery_report(d) and "fixed reference" in discovery_report(d)


def test_a_step_in_the_bias_is_named_with_its_time(tmp_path):
    """A bias that jumps halfway through the recording (before issue 28 no term of the grammar had that
    shape, and the verdict was "not explained"): a bias step, its time inside the gap it happened in."""
    for seed in (1, 3):
        case = draw_effect_case(seed, effect=None)
        sim = case.config.run()
        raw = sim.raw.copy()
        t_step = sim.t[-1] / 2
        raw[sim.t >= t_step, 1] += 40 * case.sigma_mean * float(np.mean(case.config.sensor.b))
        d = _discover(case, tmp_path, f"step{seed}", dataclasses.replace(sim, raw=raw))
        assert not d.consistent_before and d.verdict.outcome is Outcome.EXPLAINED, d.verdict
        (e,) = d.effects
        assert e.label == "bias_step[y]" and e.change_point.gap[0] <= t_step <= e.change_point.gap[1]


def test_no_false_positive_on_clean_recordings(tmp_path):
    for seed in range(9300, 9306):
        case = draw_effect_case(seed, effect=None)
        d = _discover(case, tmp_path, f"clean{seed}")
        assert d.effects == (), d.verdict


def test_cross_axis_term_is_named_by_its_observable_sum(tmp_path):
    """Only q_x + q_y + q_z reaches |a|: discovery puts it on one axis and says so."""
    case = draw_effect_case(9200, effect="cross_axis_nonlinearity", axes=(2,), snr=60.0)
    d = _discover(case, tmp_path, "cross")
    (e,) = d.effects
    assert e.name == "cross_axis_nonlinearity" and len(e.axes) == 1
    (q,) = e.coefficients.values()
    truth = case.config.sensor.effects["cross_axis_nonlinearity"]["cross_axis_nonlinearity_z"]
    assert abs(q - truth) < 5 * next(iter(e.std.values())) + 0.05 * abs(truth)
    assert any("only the sum of its coefficients" in n and "is a convention" in n for n in d.notes)


def test_orthogonal_bases_do_not_confound_orders():
    """The recurrence's constants make p1, p2, p3 orthogonal over the interval covariate values."""
    rng = np.random.default_rng(2)
    x = 20 + 15 * rng.random(25)
    e = make_effect("bias_temperature3", (0,))
    refs = e.data_values({"temp": x})
    p = [np.ones_like(x)] + [make_effect(n, (0,)).basis.value(x, {k.replace("bias_temperature3", n): v
                                                                   for k, v in refs.items()}, n)
                             for n in ("bias_temperature", "bias_temperature2", "bias_temperature3")]
    G = np.array([[a @ b for b in p] for a in p])
    corr = G / np.sqrt(np.outer(np.diag(G), np.diag(G)))
    assert np.abs(corr - np.eye(4)).max() < 1e-4  # T_ref rounded to 1e-3 degC as before the grammar
    a, b = recurrence(x, 2)
    assert a[0] == pytest.approx(np.mean(x)) and b[0] > 0


@pytest.mark.parametrize("x,d1,d2,want", [(20.0, 1, 28, 1.1721896654349718e-04), (3.0, 2, 10, 0.09536743164062497),
                                          (100.0, 3, 15, 3.844273525081982e-10)])
def test_f_sf_known_values(x, d1, d2, want):
    """Upper tail of F (values from scipy.stats.f.sf)."""
    assert f_sf(x, d1, d2) == pytest.approx(want, rel=1e-9)
    from scipy import stats
    assert f_sf(x, d1, d2) == pytest.approx(stats.f.sf(x, d1, d2), rel=1e-9)
