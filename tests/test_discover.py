"""`discover`: hidden effects are named (scored on seeded cases), clean data stay clean, the gap shrinks,
real data get no invented effect, confounded effects are reported as such, bad input is refused."""
from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

from imucal.config.run import config_from_dict
from imucal.analysis.discover import DiscoverSettings, Outcome, discover
from imucal.report.discover_text import discovery_json, discovery_report, verdict_text
from imucal.solve.stats import chi2_sf
from imucal.model.effects import CLASSIC
from imucal.errors import ImucalError
from imucal.analysis.simulate import (PosePlan, TemperatureProfile, cube_directions, draw_effect_case, mems_counts_sensor,
                             random_directions, simulate)

ROOT = Path(__file__).resolve().parents[1]

#: Scored cases: effect sizes drawn log-uniformly in this range of SNR (size / noise of one
#: interval mean). studies/results/discover_study.md measures where detection becomes reliable.
SNR_RANGE = (40.0, 120.0)
N_EFFECT_CASES = 32
N_CLEAN_CASES = 10
MIN_SCORE = 0.9


def _discover_sim(sim, unit, tmp_path, name, **settings):
    path = tmp_path / f"{name}.csv"
    path.write_text(sim.to_csv_text())
    return discover(config_from_dict({"data": {"path": str(path), "unit": unit}}), DiscoverSettings(**settings))


def _discover_cases(tmp, cases) -> list:
    return [(c, _discover_sim(c.config.run(), c.config.sensor.unit, tmp, f"case{k}")) for k, c in enumerate(cases)]


#: Product-sized: one case of each classic effect at an SNR where the study (docs/discover_study.md)
#: finds detection reliable, and two clean sensors. The scored sample below is the study's.
NAMED_SNR = 100.0


@pytest.fixture(scope="module")
def named(tmp_path_factory):
    """One case per classic effect and two clean ones: (case, discovery)."""
    cases = [draw_effect_case(7100 + k, effect=e, snr=NAMED_SNR) for k, e in enumerate(CLASSIC)]
    cases += [draw_effect_case(8000 + k, effect=None) for k in range(2)]
    return _discover_cases(tmp_path_factory.mktemp("named"), cases)


@pytest.fixture(scope="module")
def scored(tmp_path_factory):
    """Every scored case once: (case, discovery): the study's sample (42 discoveries)."""
    cases = [draw_effect_case(7000 + k, effect="random", snr=SNR_RANGE) for k in range(N_EFFECT_CASES)]
    cases += [draw_effect_case(8000 + k, effect=None) for k in range(N_CLEAN_CASES)]
    return _discover_cases(tmp_path_factory.mktemp("scored"), cases)


def _named(d) -> list[tuple[str, tuple[int, ...]]]:
    return [(e.name, tuple(e.axes)) for e in d.effects]


def test_each_classic_effect_is_named_with_its_axes(named):
    cases = [(c, d) for c, d in named if c.effect is not None]
    assert {c.effect for c, _ in cases} == set(CLASSIC)
    assert [(c.label, _named(d)) for c, d in cases] == [(c.label, [(c.effect, c.axes)]) for c, _ in cases]
    clean = [d for c, d in named if c.effect is None]
    assert clean and all(not d.effects and d.final is d.base for d in clean), [d.verdict for d in clean]


@pytest.mark.study
def test_names_the_hidden_effect_and_axes(scored):
    cases = [(c, d) for c, d in scored if c.effect is not None]
    assert len(cases) >= 30
    assert len({c.effect for c, _ in cases}) == 5  # every effect of the library is drawn
    right = [_named(d) == [(c.effect, c.axes)] for c, d in cases]
    wrong = [(c.label, round(c.snr), [e.label for e in d.effects]) for (c, d), ok in zip(cases, right) if not ok]
    assert np.mean(right) >= MIN_SCORE, wrong


@pytest.mark.study
def test_no_false_positive_on_clean_data(scored):
    clean = [d for c, d in scored if c.effect is None]
    assert len(clean) >= 8
    assert all(not d.effects for d in clean), [verdict_text(d.verdict) for d in clean if d.effects]
    assert all(d.final is d.base for d in clean)


def test_the_gap_shrinks_to_noise_level(named):
    for c, d in named:
        if c.effect is None or _named(d) != [(c.effect, c.axes)]:
            continue
        assert not d.consistent_before and d.chi2_before > 3 * d.base.result.dof
        # back at noise level: chi-square per dof passes the test, RMS near the noise of the means
        assert d.consistent_after, (c.label, d.final.result.redchi)
        assert d.final.result.redchi < 2.5
        assert d.rms_after < 1.6 * d.rms_noise, (c.label, d.rms_after, d.rms_noise)
        assert d.rms_after < d.rms_before
        # the coefficients come with standard errors and units, and the truth is inside 5 sigma
        truth = c.config.sensor.effects[c.effect]
        (e,) = d.effects
        for n, v in e.coefficients.items():
            assert math.isfinite(e.std[n]) and e.units[n]
            assert abs(v - truth[n]) < 5 * e.std[n] + 0.05 * abs(truth[n]), (n, v, truth[n], e.std[n])


def test_json_summary_has_the_documented_fields(named, tmp_path):
    c, d = next((c, d) for c, d in named if c.effect is not None and d.effects)
    js = json.loads(json.dumps(discovery_json(d)))
    for key in ("effects", "rms_before", "rms_after", "chi2_before", "chi2_after", "dof"):
        assert key in js
    e = js["effects"][0]
    assert set(e) >= {"name", "axes", "coefficients", "std"}
    assert all(a in ("x", "y", "z") for a in e["axes"])
    assert set(e["coefficients"]) == set(e["std"])
    assert js["rms_after"] < js["rms_before"]
    clean = next(d for c, d in named if c.effect is None)
    assert discovery_json(clean)["effects"] == []


def test_report_names_verdict_and_gap(named):
    c, d = next((c, d) for c, d in named if c.effect is not None and d.effects)
    text = discovery_report(d)
    assert "verdict" in text and "RMS |a|-g" in text and "chi2/dof" in text
    assert d.effects[0].label in text and "[[Round 1]]" in text


# --- honesty: unexplained misfit, confounded covariates ---------------------------------------------
def _per_pose_offsets(sim, scale, seed):
    """Random offsets per hold: a misfit none of the library's effects describes."""
    rng = np.random.default_rng(seed)
    raw = sim.raw.copy()
    for a, b in sim.hold_bounds:
        raw[a:b] += rng.normal(0, scale, 3)
    return dataclasses.replace(sim, raw=raw)


def test_per_pose_offsets_are_named_a_stochastic_bias_not_a_term(tmp_path):
    """A random offset per pose is bias_instability: no deterministic term is invented for it."""
    rng = np.random.default_rng(40)
    sensor = mems_counts_sensor(rng, noise_counts=4.0)
    dirs = np.vstack([cube_directions("faces+edges"), random_directions(6, rng)])
    sim = simulate(sensor, PosePlan(dirs, hold=3.0, transition=2.0), seed=40,
                   temperature=TemperatureProfile(period=100.0, swing=3.0))
    sim = _per_pose_offsets(sim, scale=2.0, seed=41)  # ~8 x the noise of a mean, random per pose
    d = _discover_sim(sim, "raw", tmp_path, "offsets")
    assert not d.consistent_before
    assert d.effects == ()
    assert d.verdict.outcome is Outcome.STOCHASTIC and d.verdict.stochastic.named == ("bias_instability",), d.verdict
    assert verdict_text(d.verdict).startswith("explained by a stochastic bias: bias_instability")
    assert "no deterministic term helps" in verdict_text(d.verdict)
    # ... and the calibration it keeps (--out) is the default fit the verdict names, the excess in its
    # weights and standard errors, not the noise-weighted fit the tests ran on
    kept, tested = d.calibration_run.calibration.fit, d.final.calibration.fit
    assert (kept["weights"], tested["weights"]) == ("auto", "noise")
    assert kept["bias_instability"] > 0 == tested["bias_instability"]
    assert d.calibration_run.result.std["s1"] > 2 * d.final.result.noise_std["s1"]
    assert discovery_json(d)["calibration_weights"] == "auto"


def test_real_xsens_recording_gets_no_invented_effect():
    """imu_tk's Xsens log: chi2/dof ~ 8 with the base model, for reasons no candidate explains."""
    cfg_path = ROOT / "configs" / "xsens-mti-imutk.yaml"
    if not cfg_path.exists():
        pytest.skip("xsens config not present")
    from imucal.config.run import load_config

    d = discover(load_config(cfg_path))
    assert d.base.result.redchi > 3
    assert d.effects == ()
    assert d.verdict.outcome is Outcome.STOCHASTIC, d.verdict  # named and quantified
    assert d.stochastic is not None and d.stochastic.named and d.allan is not None
    assert any("no temp column" in n for n in d.notes)


@dataclasses.dataclass(frozen=True)
class _Ramp:
    """Temperature rising linearly with time [degC], with a little sensor noise."""

    start: float
    rate: float  #: degC/s

    def sample(self, t, rng):
        return self.start + self.rate * t + rng.normal(0, 0.02, t.size)


def test_monotonic_temperature_confounds_temperature_and_time(tmp_path):
    """Temperature rising linearly with time: a bias in temperature looks like a bias drift.

    discover must add one of the two and say that the other explains the data as well.
    """
    rng = np.random.default_rng(50)
    sensor = dataclasses.replace(mems_counts_sensor(rng, noise_counts=2.0),
                                 effects={"bias_temperature": {"bias_temperature_y": 3.0}})
    dirs = np.vstack([cube_directions("faces+edges"), random_directions(6, rng)])
    temp = _Ramp(start=20.0, rate=0.12)  # degC/s: temperature a straight line in time
    sim = simulate(sensor, PosePlan(dirs[rng.permutation(len(dirs))], hold=3.0, transition=2.0), seed=50,
                   temperature=temp)
    d = _discover_sim(sim, "raw", tmp_path, "confounded")
    assert len(d.effects) == 1
    (e,) = d.effects
    assert e.axes == (1,) and e.name in ("bias_temperature", "bias_drift")
    other = "bias_drift[y]" if e.name == "bias_temperature" else "bias_temperature[y]"
    assert other in e.ambiguous_with
    assert "cannot be told apart" in discovery_report(d)


def test_non_monotonic_temperature_tells_temperature_from_time(tmp_path):
    rng = np.random.default_rng(51)
    sensor = dataclasses.replace(mems_counts_sensor(rng, noise_counts=2.0),
                                 effects={"bias_temperature": {"bias_temperature_y": 3.0}})
    dirs = np.vstack([cube_directions("faces+edges"), random_directions(6, rng)])
    temp = TemperatureProfile(start=20.0, plateau=34.0, tau=40.0, swing=4.0, period=80.0)
    sim = simulate(sensor, PosePlan(dirs[rng.permutation(len(dirs))], hold=3.0, transition=2.0), seed=51,
                   temperature=temp)
    d = _discover_sim(sim, "raw", tmp_path, "separable")
    assert [(e.name, e.axes, e.ambiguous_with) for e in d.effects] == [("bias_temperature", (1,), ())]


# --- bad input -----------------------------------------------------------------------------------
def test_too_few_intervals_is_refused_with_a_message(tmp_path):
    rng = np.random.default_rng(60)
    sim = simulate(mems_counts_sensor(rng), PosePlan(cube_directions("faces+corners")[:11], hold=3.0),
                   seed=60, temperature=TemperatureProfile())
    with pytest.raises(ImucalError) as exc:
        _discover_sim(sim, "raw", tmp_path, "few")
    msg = str(exc.value)
    assert "11 static intervals are too few to test effects" in msg and "at least 13" in msg
    assert "few.csv" in msg and "fix:" in msg and "\n" not in msg


def test_temperature_candidates_without_temp_column(tmp_path):
    rng = np.random.default_rng(61)
    sim = simulate(mems_counts_sensor(rng), PosePlan(cube_directions("faces+edges"), hold=3.0), seed=61)
    with pytest.raises(ImucalError, match="bias_temperature cannot be tested: the data have no temp column"):
        _discover_sim(sim, "raw", tmp_path, "notemp", candidates=("bias_temperature",))


def test_constant_temperature_skips_temperature_effects(tmp_path):
    rng = np.random.default_rng(62)
    sensor = dataclasses.replace(mems_counts_sensor(rng, noise_counts=2.0),
                                 effects={"bias_drift": {"bias_drift_x": 0.3}})
    flat = TemperatureProfile(start=28.0, plateau=28.0, swing=0.0, noise=0.01)
    dirs = np.vstack([cube_directions("faces+edges"), random_directions(4, rng)])
    sim = simulate(sensor, PosePlan(dirs, hold=3.0), seed=62, temperature=flat)
    with pytest.raises(ImucalError, match="temperature is constant"):
        _discover_sim(sim, "raw", tmp_path, "flat1", candidates=("bias_temperature", "scale_temperature"))
    d = _discover_sim(sim, "raw", tmp_path, "flat2")
    assert any("temperature effects not tested: the temperature is constant" in n for n in d.notes)
    assert [e.label for e in d.effects] == ["bias_drift[x]"]


def test_settings_are_checked():
    with pytest.raises(ImucalError, match="unknown effect 'wobble'"):
        DiscoverSettings(candidates=("wobble",))
    with pytest.raises(ImucalError, match="alpha_noise 2 must lie in"):
        DiscoverSettings(alpha_noise=2)


# --- statistics --------------------------------------------------------------------------------
@pytest.mark.parametrize("k", [1, 2, 3, 4, 7, 15, 40])
def test_chi2_sf_matches_scipy(k):
    from scipy import stats
    for x in (0.0, 0.1, 1.0, k, 3.0 * k + 5, 200.0):
        assert chi2_sf(x, k) == pytest.approx(stats.chi2.sf(x, k), rel=1e-9, abs=1e-300)


def test_chi2_sf_known_values():
    assert chi2_sf(3.841458820694124, 1) == pytest.approx(0.05, rel=1e-9)
    assert chi2_sf(10.827566170662733, 1) == pytest.approx(1e-3, rel=1e-9)
    assert chi2_sf(0.0, 5) == 1.0 and chi2_sf(math.inf, 3) == 0.0


# --- two effects: rounds, lookahead, backward step ----------------------------------------------
def test_two_comparable_effects_are_both_named(tmp_path):
    """Neither effect alone brings the residual to the noise, so neither passes alone; the pair
    does (lookahead)."""
    from imucal.analysis.simulate import draw_pair_case, pair_config

    c1, c2 = draw_pair_case(30)
    d = _discover_sim(pair_config(c1, c2).run(), c1.config.sensor.unit, tmp_path, "pair")
    assert sorted(e.label for e in d.effects) == sorted([c1.label, c2.label])
    assert any(s.jointly_with for s in d.steps)
    assert d.consistent_after and d.final.result.redchi < 2.5
    assert "given" in discovery_report(d)


def test_a_pair_hidden_behind_a_relative_is_found_by_the_pair_screen(tmp_path):
    """scale_drift[x] + bias_drift[y]: alone each removes about a third of the chi-square, less than
    a relative on two axes (scale_nonlinearity[xy]) or a warm-up on three, so no search that starts
    from the best single candidates meets the pair; together they bring 811 to 14. The screen of
    every pair finds it and both are named."""
    from imucal.analysis.simulate import draw_pair_case, pair_config

    c1, c2 = draw_pair_case(51381, snr=40.0, noise_mg=0.3)
    assert {c1.label, c2.label} == {"scale_drift[x]", "bias_drift[y]"}
    d = _discover_sim(pair_config(c1, c2).run(), c1.config.sensor.unit, tmp_path, "hidden-pair")
    assert sorted(e.label for e in d.effects) == ["bias_drift[y]", "scale_drift[x]"]
    first = d.steps[0]  # no single candidate was significant: the pair made the first one so
    assert {first.chosen.label, first.jointly_with} == {"scale_drift[x]", "bias_drift[y]"}
    assert d.consistent_after


def test_an_axis_the_poses_barely_see_is_reported_not_ruled_out(tmp_path):
    """scale_drift[y]: a drift of the x scale as large as the y one would add about 4 chi-square on
    these poses (few of them along x when the drift is large), so its absence is no finding and the
    report says so; z is seen (about 25) and is ruled out. The linearised lambda agrees with the
    standard error of a full fit with the axis added."""
    from imucal.analysis.discover.problem import Problem, canonical

    case = draw_effect_case(301, effect="scale_drift", axes=(1,), snr=20.0, noise_mg=0.3)
    d = _discover_sim(case.config.run(), case.config.sensor.unit, tmp_path, "blind")
    (e,) = d.effects
    assert e.label == "scale_drift[y]" and e.unresolved_axes == (0,)
    (note,) = [n for n in d.notes if "not ruled out" in n]
    assert note.startswith("scale_drift[y]: axis x not ruled out")
    assert note.endswith("to test it, hold the x axis up and down at the start and at the end of the recording")
    lam = float(note.split("would add only ")[1].split()[0])
    assert discovery_json(d)["effects"][0]["unresolved_axes"] == ["x"] and "not ruled out on x" in discovery_report(d)
    cfg = config_from_dict({"data": {"path": str(tmp_path / "blind.csv"), "unit": case.config.sensor.unit},
                            "fit": {"weights": "noise"}})
    prob = Problem(cfg, d.base)
    for axes, name in (((0, 1), "scale_drift_x"), ((1, 2), "scale_drift_z")):
        r = prob.fit(canonical({"scale_drift": axes}), d.final.result.values())
        direct = (e.coefficients["scale_drift_y"] / r.std[name]) ** 2
        if name.endswith("x"):
            assert abs(direct - lam) < 0.25 * lam, (direct, lam)
        else:  # z: seen well, ruled out
            assert direct > 20


def test_the_backward_step_drops_an_axis_the_data_do_not_need(tmp_path):
    """An effect fitted on an axis that carries nothing (as a greedy forward search can pick up) is
    dropped by the backward step, with its note; the true axis stays."""
    from imucal.analysis.discover.backward import prune
    from imucal.analysis.discover.problem import Problem, canonical
    from imucal.pipeline import calibrate_accelerometer

    case = draw_effect_case(31, effect="scale_nonlinearity", axes=(0,), snr=60.0)
    path = tmp_path / "c.csv"
    path.write_text(case.config.run().to_csv_text())
    cfg = config_from_dict({"data": {"path": str(path), "unit": case.config.sensor.unit}})
    base = calibrate_accelerometer(cfg)
    prob = Problem(cfg, base)
    wide = {"scale_nonlinearity": (0, 1)}
    current = prob.fit(canonical(wide), base.result.values())
    notes: list[str] = []
    _, kept = prune(prob, current, wide, {"scale_nonlinearity"}, DiscoverSettings(), notes)
    assert kept == {"scale_nonlinearity": (0,)}
    assert len(notes) == 1 and notes[0].startswith("dropped scale_nonlinearity on axis y"), notes


@pytest.mark.study
def test_two_effect_cases_score(tmp_path):
    from imucal.analysis.simulate import draw_pair_case, pair_config

    right = []
    for seed in range(300, 310):
        c1, c2 = draw_pair_case(seed)
        d = _discover_sim(pair_config(c1, c2).run(), c1.config.sensor.unit, tmp_path, f"p{seed}")
        right.append(sorted(e.label for e in d.effects) == sorted([c1.label, c2.label]))
    assert sum(right) >= 8, right
