"""The fit: known truth -> simulate -> fit -> recover (CasADi sysid style), for raw counts and SI.

Also: rescaling the raw unit gives the same physical answer; fixing subsets; samples mode vs
means mode; at-bound flags; observability refusals that name the undetermined parameters; the
initial guess (linear ellipsoid fit); local gravity from WGS84.
"""
from __future__ import annotations

import re
import math

import numpy as np
import pytest

from conftest import calibrate_file, real_file, write_simulation
from imucal.constants import STANDARD_GRAVITY
from imucal.errors import ImucalError
from imucal.model.gravity import normal_gravity
from imucal.solve.initial import ellipsoid_guess
from imucal.model.parameters import ANGLE_NAMES, BASE_NAMES
from imucal.report.text import fit_report
from imucal.analysis.simulate import SensorSpec, cube_directions, mems_counts_sensor, random_directions, si_sensor

HALF_PI = math.pi / 2


def zscores(run, truth: dict[str, float]) -> dict[str, float]:
    res = run.result
    return {n: (res.params[n].value - truth[n]) / res.std[n] for n in truth}


# --- known truth ------------------------------------------------------------------------------
@pytest.mark.parametrize("which", ["counts", "si"])
def test_recovers_truth_within_3_std(request, which):
    rec = request.getfixturevalue(f"{which}_recording")
    run = request.getfixturevalue(f"{which}_run")
    res = run.result
    assert res.free_names == BASE_NAMES
    for n in BASE_NAMES:
        assert math.isfinite(res.std[n]) and res.std[n] > 0, n
    z = zscores(run, rec.truth)
    assert max(abs(v) for v in z.values()) < 3, z
    # the standard errors are small: the parameters are really determined
    assert res.std["b1"] / res.params["b1"].value < 1e-4
    assert max(res.std[a] for a in ANGLE_NAMES) < 2e-4  # rad
    assert res.params["b1"].unit == ("raw/(m/s^2)")


def test_standard_errors_are_honest(sim_csv):
    """Across seeds, (estimate - truth) / std scatters like a unit normal (not 3x too small)."""
    z = []
    for seed in range(6):
        rec = sim_csv(f"honest{seed}", si_sensor(np.random.default_rng(100 + seed)), cube_directions(),
                      seed=200 + seed)
        z.extend(zscores(calibrate_file(rec.path), rec.truth).values())
    z = np.array(z)
    assert 0.6 < np.sqrt(np.mean(z**2)) < 1.6
    assert np.abs(z).max() < 4.5


@pytest.mark.parametrize("which", ["counts", "si"])
def test_result_carries_uncertainty_and_goodness_of_fit(request, which):
    run = request.getfixturevalue(f"{which}_run")
    res, cal = run.result, run.calibration
    C = res.correlation
    assert C.shape == (9, 9)
    np.testing.assert_allclose(np.diag(C), 1.0, atol=1e-12)
    np.testing.assert_allclose(C, C.T, atol=1e-6)
    assert np.all(np.abs(C) <= 1 + 1e-12)
    np.testing.assert_allclose(np.sqrt(np.diag(res.covariance)), [res.std[n] for n in res.free_names])
    # chi-square against the noise estimate from the within-interval scatter
    assert res.dof == run.intervals.n - 9
    assert 0.2 < res.redchi < 3.0
    assert res.chi2 == pytest.approx(np.sum((res.residuals / res.sigma) ** 2))
    # RMS of |a| - g on interval means and on samples [m/s^2]
    noise_si = np.array(request.getfixturevalue(f"{which}_recording").sensor.noise) / \
        np.array(request.getfixturevalue(f"{which}_recording").sensor.b)
    assert cal.fit["rms_residual"] == pytest.approx(res.rms_residual)
    assert cal.fit["rms_residual"] < 0.2 * noise_si.max()  # means average the noise away
    assert cal.fit["rms_residual_samples"] == pytest.approx(run.rms_residual_samples)
    assert 0.5 * noise_si.min() < run.rms_residual_samples < 2 * noise_si.max()
    assert res.iterations > 0 and res.status and res.status_words
    assert res.at_bound == {}
    assert res.mode == "means"


def test_converges_on_good_data(counts_run, si_run):
    assert counts_run.result.success, counts_run.result.status
    assert si_run.result.success, si_run.result.status


def test_converges_on_every_seed(sim_csv):
    sensor = mems_counts_sensor(np.random.default_rng(2024))
    statuses = []
    for seed in range(1, 7):
        rec = sim_csv(f"conv{seed}", sensor, cube_directions(), seed=seed)
        statuses.append(calibrate_file(rec.path).result.status)
    assert all(s in ("Solve_Succeeded", "Solved_To_Acceptable_Level") for s in statuses), statuses


# --- units and rescaling -----------------------------------------------------------------------
@pytest.mark.parametrize("which, factor", [("si", 1000.0), ("si", 1 / 3.7), ("counts", STANDARD_GRAVITY / 16384)])
def test_rescaling_raw_units_gives_the_same_physical_answer(request, tmp_path, which, factor):
    """s and b scale with the raw unit, angles and std/value do not; no hand-made guess needed."""
    rec = request.getfixturevalue(f"{which}_recording")
    base = request.getfixturevalue(f"{which}_run").result
    scaled = write_simulation(tmp_path / "scaled.csv", rec.sensor, cube_directions(), seed=4 if which == "counts" else 5,
                              raw_factor=factor)
    np.testing.assert_allclose(scaled.sim.raw, rec.sim.raw * factor)
    res = calibrate_file(scaled.path).result
    for n in BASE_NAMES:
        k = factor if n[0] in "sb" else 1.0
        assert res.params[n].value / k == pytest.approx(base.params[n].value, abs=1e-3 * base.std[n]), n
        assert res.std[n] / k == pytest.approx(base.std[n], rel=1e-3), n


# --- fixing subsets ----------------------------------------------------------------------------
@pytest.fixture(scope="module")
def orthogonal_recording(sim_csv):
    """A counts sensor whose axes are exactly orthogonal: the 6-parameter model is exact."""
    rng = np.random.default_rng(77)
    s = mems_counts_sensor(rng)
    sensor = SensorSpec(s=s.s, b=s.b, angles=(HALF_PI,) * 3, noise=s.noise, quantum=1.0, unit="raw")
    return sim_csv("orthogonal", sensor, cube_directions("faces+edges"), seed=3)


def test_fixed_angles_six_parameter_model(orthogonal_recording):
    rec = orthogonal_recording
    run = calibrate_file(rec.path, fit={"fix": ["phi", "psi", "theta"]})
    res = run.result
    assert res.free_names == ("s1", "s2", "s3", "b1", "b2", "b3")
    for a in ANGLE_NAMES:
        assert res.params[a].value == HALF_PI and res.params[a].fixed
        assert math.isnan(res.std[a])
    assert res.correlation.shape == (6, 6)
    z = zscores(run, {n: v for n, v in rec.truth.items() if n not in ANGLE_NAMES})
    assert max(abs(v) for v in z.values()) < 3, z
    assert res.dof == run.intervals.n - 6


def test_fixed_angles_on_a_skewed_sensor_misfit(counts_recording, counts_run):
    """Holding the angles at 90 deg when they are not: chi-square says the model is wrong, so
    absurdly (reduced chi-square > 1e4) that the calibration is refused, naming the fix."""
    with pytest.raises(ImucalError, match=r"reduced chi-square 1\.\d+e\+05 .*refused.*free the held "
                                          r"parameters \(phi, psi, theta\)"):
        calibrate_file(counts_recording.path, fit={"fix": ["phi", "psi", "theta"]})
    assert counts_run.result.redchi < 2


def test_fix_one_parameter_at_a_given_value(counts_recording):
    truth = counts_recording.truth
    run = calibrate_file(counts_recording.path, fit={"fix": ["s2"], "initial": {"s2": truth["s2"]}})
    res = run.result
    assert res.params["s2"].value == truth["s2"] and res.params["s2"].fixed
    assert "s2" not in res.free_names and len(res.free_names) == 8
    z = zscores(run, {n: v for n, v in truth.items() if n != "s2"})
    assert max(abs(v) for v in z.values()) < 3, z


def test_samples_mode_agrees_with_means_mode(si_recording, si_run):
    run = calibrate_file(si_recording.path, fit={"mode": "samples"})
    res, ref = run.result, si_run.result
    assert res.mode == "samples"
    assert res.residuals.size == run.intervals.n_samples.sum()
    for n in BASE_NAMES:
        assert abs(res.params[n].value - ref.params[n].value) < ref.std[n], n
        assert res.std[n] == pytest.approx(ref.std[n], rel=0.5), n
    # the residual on interval means is reported in samples mode too
    assert run.calibration.fit["rms_residual"] == pytest.approx(si_run.calibration.fit["rms_residual"], rel=0.2)
    z = zscores(run, si_recording.truth)
    assert max(abs(v) for v in z.values()) < 3, z


# --- bounds ------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def skewed_recording(sim_csv):
    """phi is 3 % above 90 deg: outside the default box pi/2 (1 +- 0.02)."""
    sensor = SensorSpec(s=(0.1, -0.05, 0.02), b=(1.01, 0.99, 1.0), angles=(HALF_PI * 1.03, HALF_PI, HALF_PI * 0.995),
                        noise=(0.01,) * 3, unit="m/s^2")
    return sim_csv("skewed", sensor, cube_directions(), seed=9)


def test_truth_outside_the_angle_box_is_flagged(skewed_recording):
    run = calibrate_file(skewed_recording.path)
    res = run.result
    assert res.at_bound == {"phi": "upper"}
    assert res.params["phi"].value == pytest.approx(HALF_PI * 1.02, rel=1e-6)
    assert "(at upper bound)" in fit_report(run)
    assert res.redchi_noise > 10  # and the misfit shows against the noise


def test_wider_angle_tolerance_recovers_it(skewed_recording):
    run = calibrate_file(skewed_recording.path, fit={"angle_tolerance": 0.05})
    assert run.result.at_bound == {}
    z = zscores(run, skewed_recording.truth)
    assert max(abs(v) for v in z.values()) < 3, z


# --- observability -----------------------------------------------------------------------------
@pytest.fixture(scope="module")
def six_pose_recording(sim_csv):
    return sim_csv("six", mems_counts_sensor(np.random.default_rng(6)), cube_directions("faces"), seed=6)


def test_six_poses_refuse_the_nine_parameter_fit(six_pose_recording):
    with pytest.raises(ImucalError) as ei:
        calibrate_file(six_pose_recording.path)
    msg = str(ei.value)
    assert "\n" not in msg and msg.startswith(str(six_pose_recording.path))
    assert "only 6 distinct orientations for 9 free parameters" in msg
    assert "phi, psi, theta undetermined" in msg
    assert "b1" not in msg and "s1" not in msg  # the scales and shifts are determined
    assert "--fix-angles" in msg and "fit.fix: [phi, psi, theta]" in msg
    assert "more orientations" in msg


def test_ferraris_six_pose_session_gets_the_refusal():
    p = real_file("imucal-ferraris", "annotated_session.csv")
    with pytest.raises(ImucalError) as ei:
        calibrate_file(p, data={"sample_rate": 204.8})
    msg = str(ei.value)
    assert "only 6 distinct orientations" in msg
    assert all(a in msg for a in ANGLE_NAMES)
    assert "--fix-angles" in msg


def test_ferraris_fixed_angles_in_samples_mode():
    p = real_file("imucal-ferraris", "annotated_session.csv")
    run = calibrate_file(p, data={"sample_rate": 204.8}, gravity={"value": 9.81},
                         fit={"fix": list(ANGLE_NAMES), "mode": "samples"})
    res = run.result
    assert res.success
    # mad-lab-fau's published K_a diagonal [counts per m/s^2] and offsets (example_cal.json);
    # their model also rotates the axes, so agreement is to ~0.1 % and a few counts.
    K = [208.54567263762615, 208.0011341167055, 214.78455364603022]
    b = [-6.018868019671572, -48.287874016760156, -28.96636637224333]
    for i in range(3):
        assert res.params[f"b{i+1}"].value == pytest.approx(K[i], rel=2e-3)
        assert res.params[f"s{i+1}"].value == pytest.approx(b[i], abs=2.0)


def test_ferraris_fixed_angles_cli(run_cli, tmp_path):
    """The remedy the refusal offers must work as offered: --fix-angles, nothing else."""
    p = real_file("imucal-ferraris", "annotated_session.csv")
    r = run_cli(["calibrate", "--data", p, "--sample-rate", "204.8", "--fix-angles",
                 "--out", tmp_path / "out", "--no-figures", "--quiet"])
    assert r.code == 0, r.err
    assert (tmp_path / "out" / "calibration.yaml").exists()


@pytest.mark.parametrize("kind, n", [("five", 5), ("eight", 8)])
def test_too_few_orientations(sim_csv, kind, n):
    dirs = cube_directions("faces")[:5] if kind == "five" else cube_directions("corners")
    rec = sim_csv(f"few{n}", si_sensor(np.random.default_rng(n)), dirs, seed=n)
    with pytest.raises(ImucalError, match=f"only {n} distinct orientations for 9 free parameters") as ei:
        calibrate_file(rec.path)
    assert "undetermined" in str(ei.value) and "more orientations" in str(ei.value)


def test_degenerate_orientations_in_one_plane(sim_csv):
    """12 poses, all with gravity in the x-y plane: the z axis is not determined."""
    ang = np.linspace(0, 2 * np.pi, 13)[:-1]
    dirs = np.column_stack([np.cos(ang), np.sin(ang), np.zeros_like(ang)])
    rec = sim_csv("plane", mems_counts_sensor(np.random.default_rng(3)), dirs, seed=1)
    with pytest.raises(ImucalError, match="undetermined") as ei:
        calibrate_file(rec.path)
    msg = str(ei.value)
    named = [n for n in BASE_NAMES if n in msg.split("undetermined")[0]]
    assert named and set(named) <= {"s3", "b3", "psi", "theta"}, msg
    assert "add orientations" in msg


def test_corners_only_refuse_the_fixed_angle_model(sim_csv):
    rec = sim_csv("corners", mems_counts_sensor(np.random.default_rng(3)), cube_directions("corners"), seed=1)
    with pytest.raises(ImucalError, match="undetermined") as ei:
        calibrate_file(rec.path, fit={"fix": list(ANGLE_NAMES)})
    # Every corner has |m_i| = g/sqrt(3): with the angles fixed only a combination of the scales
    # is determined (the sensor's true non-orthogonality adds a little information, so which
    # scales are named depends on the sensor); the message names scales, and nothing else.
    msg = str(ei.value)
    named = [n for n in BASE_NAMES if re.search(rf"\b{n}\b", msg.split("undetermined")[0])]
    assert len(named) >= 2 and set(named) <= {"b1", "b2", "b3"}, msg


# --- initial guess -----------------------------------------------------------------------------
@pytest.mark.parametrize("which", ["counts", "si"])
def test_ellipsoid_guess_is_close(request, which):
    rec = request.getfixturevalue(f"{which}_recording")
    run = request.getfixturevalue(f"{which}_run")
    guess = ellipsoid_guess(run.intervals.mean, STANDARD_GRAVITY)
    assert guess.method == "ellipsoid-9"
    t = rec.truth
    b = np.array([t["b1"], t["b2"], t["b3"]])
    np.testing.assert_allclose(guess.b, b, rtol=2e-3)
    np.testing.assert_allclose(guess.s, [t["s1"], t["s2"], t["s3"]], atol=2e-3 * b.max() * STANDARD_GRAVITY)
    np.testing.assert_allclose(guess.angles, [t[a] for a in ANGLE_NAMES], atol=2e-3)
    assert run.guess.method == "ellipsoid-9"


def test_ellipsoid_guess_six_and_refusals():
    b = np.array([1000.0, 1100.0, 900.0])
    s = np.array([10.0, -20.0, 30.0])
    faces = cube_directions("faces")
    g6 = ellipsoid_guess(s + b * faces * 9.8, 9.8)
    assert g6.method == "ellipsoid-6"
    np.testing.assert_allclose(g6.s, s, atol=1e-6)
    np.testing.assert_allclose(g6.b, b, rtol=1e-9)
    np.testing.assert_array_equal(g6.angles, [HALF_PI] * 3)
    with pytest.raises(ImucalError, match="only 5 static intervals; at least 6 orientations") as ei:
        ellipsoid_guess(s + b * faces[:5] * 9.8, 9.8, source="r.csv")
    assert str(ei.value).startswith("r.csv: intervals:")
    ring = np.column_stack([np.cos(np.arange(12)), np.sin(np.arange(12)), np.zeros(12)])
    with pytest.raises(ImucalError, match="do not span an ellipsoid"):
        ellipsoid_guess(s + b * ring * 9.8, 9.8)


# --- gravity -----------------------------------------------------------------------------------
def test_wgs84_normal_gravity_reference_values():
    # NIMA TR8350.2, Table 3.4: normal gravity at the equator and at the poles
    assert normal_gravity(0.0) == pytest.approx(9.7803253359, abs=1e-10)
    assert normal_gravity(90.0) == pytest.approx(9.8321849378, abs=1e-9)
    assert normal_gravity(-90.0) == normal_gravity(90.0)
    assert normal_gravity(-33.3) == normal_gravity(33.3)
    # free-air gradient ~ -0.3086 mGal/m
    assert (normal_gravity(45.0, 100.0) - normal_gravity(45.0)) / 100.0 == pytest.approx(-3.086e-6, rel=3e-3)
    lat = np.linspace(0, 90, 19)
    assert np.all(np.diff([normal_gravity(x) for x in lat]) > 0)


@pytest.mark.parametrize("lat, h, field", [(90.5, 0.0, "gravity.latitude"), (float("nan"), 0.0, "gravity.latitude"),
                                           (10.0, 2e5, "gravity.height"), (10.0, float("inf"), "gravity.height")])
def test_normal_gravity_refuses_implausible_input(lat, h, field):
    with pytest.raises(ImucalError) as ei:
        normal_gravity(lat, h)
    assert ei.value.field == field


def test_fit_with_gravity_from_latitude(sim_csv):
    g = normal_gravity(60.0, 500.0)
    rec = sim_csv("lat60", si_sensor(np.random.default_rng(60)), cube_directions(), seed=60, gravity=g)
    run = calibrate_file(rec.path, gravity={"latitude": 60.0, "height": 500.0})
    assert run.calibration.gravity == g
    assert "latitude 60.0" in run.gravity_source
    z = zscores(run, rec.truth)
    assert max(abs(v) for v in z.values()) < 3, z
    # The wrong gravity (standard) biases the scales by g_std / g_local
    wrong = calibrate_file(rec.path)
    assert wrong.result.params["b1"].value / run.result.params["b1"].value == pytest.approx(g / STANDARD_GRAVITY,
                                                                                           rel=1e-4)


def test_random_directions_recover_truth(sim_csv):
    rng = np.random.default_rng(31)
    rec = sim_csv("random", mems_counts_sensor(rng), random_directions(20, rng), seed=31)
    z = zscores(calibrate_file(rec.path), rec.truth)
    assert max(abs(v) for v in z.values()) < 3, z


def test_noise_std_is_what_the_weights_alone_predict_whatever_the_misfit(tmp_path):
    """An unmodelled warm-up leaves chi2/dof >> 1: ``std`` grows with it (lmfit's scale_covar),
    ``noise_std`` stays what the observability check predicts from the noise of each row."""
    from imucal.analysis.simulate import draw_effect_case
    from imucal.config.run import config_from_dict
    from imucal.pipeline import calibrate_accelerometer

    case = draw_effect_case(60081, effect="scale_warmup", snr=216.4, noise_mg=0.3)
    path = tmp_path / "warm.csv"
    path.write_text(case.config.run().to_csv_text())
    run = calibrate_accelerometer(config_from_dict({"data": {"path": str(path), "unit": case.config.sensor.unit},
                                      "fit": {"weights": "noise"}}))
    res = run.result
    assert res.redchi > 20
    for n in res.free_names:
        predicted = run.observability.predicted_z[n] * res.params[n].scale
        assert res.noise_std[n] == pytest.approx(predicted, rel=1e-3)
        assert res.std[n] == pytest.approx(predicted * math.sqrt(res.redchi), rel=1e-3)
