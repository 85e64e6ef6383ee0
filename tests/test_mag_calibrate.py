"""Magnetometer calibration on simulated 9-axis logs with known truth (issue 26)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from imucal.errors import ImucalError
from imucal.mag.calibrate import MagSettings, calibrate_mag
from imucal.mag.frame import axes_words, closed_form, nearest_permutation, search_axes
from imucal.mag.model import ROTATION_NAMES
from imucal.mag.simulate import MagTruth, _random_rotations, simulate_mag, truth_from_soft_iron

AK8963 = (0, 1, 0, 1, 0, 0, 0, 0, -1)
#: a symmetric soft iron of a few per cent, as on a small board
SOFT = np.array([[1.05, 0.03, -0.02], [0.03, 0.97, 0.01], [-0.02, 0.01, 1.01]])


def _truth(axes=AK8963, misalignment_deg=(1.0, -0.5, 1.5), **kw) -> MagTruth:
    return truth_from_soft_iron(SOFT, axes=axes, misalignment=np.radians(misalignment_deg), **kw)


def _z(cal, truth: MagTruth) -> np.ndarray:
    v = truth.values()
    return np.array([(cal.params[n].value - v[n]) / cal.fit.std[n] for n in cal.fit.free_names])


def test_monte_carlo_spread_matches_the_standard_errors():
    """Over seeds, (value - truth) / std has unit variance for every parameter (pooled): the standard
    errors are those of the estimates (a fuller check with more seeds: studies/mag_study.py)."""
    truth = _truth()
    z = []
    for seed in range(12):
        sim = simulate_mag(truth, n_poses=20, hold=60, transition=30, seed=seed)
        z.append(_z(calibrate_mag(sim.mag, sim.acc, still=sim.holds, settings=MagSettings(field=truth.field)), truth))
    z = np.array(z)
    assert z.shape[1] == 13  # 9 ellipsoid, 3 rotation, dip (F given)
    assert 0.6 < np.mean(z**2) < 1.8
    assert np.all(np.abs(z.mean(axis=0)) < 4.0 / math.sqrt(len(z)) + 0.5)


def test_ak8963_mounting_found_without_a_hint():
    truth = _truth()
    sim = simulate_mag(truth, n_poses=24, seed=3)
    cal = calibrate_mag(sim.mag, sim.acc, still=sim.holds, settings=MagSettings(field=truth.field))
    assert cal.axes.best.axes == AK8963 and cal.axes.best.words == "mx = ay, my = ax, mz = -az"
    assert cal.axes.agrees and cal.axes.margin > 5
    assert np.all(np.abs(_z(cal, truth)) < 4.5)
    assert math.degrees(cal.misalignment) == pytest.approx(math.degrees(np.linalg.norm(np.radians([1, -0.5, 1.5]))),
                                                           abs=0.3)


def test_closed_form_finds_any_rotation():
    rng = np.random.default_rng(7)
    sim = simulate_mag(MagTruth(rotation=(0.5, -0.3, 0.8), noise=1e-4, acc_noise=1e-3), n_poses=30, seed=4)
    a, h = sim.holds.means(sim.acc), sim.holds.means(sim.mag) - np.array(sim.truth.s)
    cf = closed_form(a, h)
    R = np.asarray(__import__("imucal.mag.model", fromlist=["rotation"]).rotation(0.5, -0.3, 0.8))
    assert np.max(np.abs(cf.rotation - R)) < 2e-3 and cf.dip == pytest.approx(sim.truth.dip, abs=2e-3)
    assert search_axes(a, h).best.axes == nearest_permutation(R)
    assert rng is not None


def test_axes_words():
    assert axes_words((1, 0, 0, 0, 1, 0, 0, 0, 1)) == "mx = ax, my = ay, mz = az"
    assert axes_words((0, -1, 0, 1, 0, 0, 0, 0, 1)) == "mx = ay, my = -ax, mz = az"


def test_lag_estimated_and_taken_out():
    """A magnetometer 4 samples late on a log that never stops: the lag is found by cross-correlation and
    shifted out; left in, the dip scatters more."""
    truth = _truth(lag=4.0, acc_noise=0.005)
    sim = simulate_mag(truth, n_poses=40, hold=0, transition=60, seed=5)
    cal = calibrate_mag(sim.mag, sim.acc, settings=MagSettings(field=truth.field, window=12))
    assert cal.lag.estimated and cal.lag.samples == pytest.approx(4.0, abs=0.5)
    kept = calibrate_mag(sim.mag, sim.acc, settings=MagSettings(field=truth.field, window=12, lag=0.0))
    assert cal.report.dip_deg.after < 0.7 * kept.report.dip_deg.after
    assert np.all(np.abs(_z(cal, truth)) < 5)


def test_soft_iron_form_chosen_by_the_F_test():
    sym_truth = _truth(misalignment_deg=(0.0, 0.0, 0.0))
    sim = simulate_mag(sym_truth, n_poses=24, seed=6)
    cal = calibrate_mag(sim.mag, sim.acc, still=sim.holds, settings=MagSettings(field=sym_truth.field))
    assert not cal.soft_iron.full and cal.fit is cal.symmetric and cal.misalignment < math.radians(0.05)
    tilted = _truth(misalignment_deg=(0.0, 2.0, 0.0))
    sim = simulate_mag(tilted, n_poses=24, seed=6)
    cal = calibrate_mag(sim.mag, sim.acc, still=sim.holds, settings=MagSettings(field=tilted.field))
    assert cal.soft_iron.full and cal.soft_iron.p < 1e-6
    assert cal.report.dip_deg.after < 0.5 * cal.report.dip_deg.unaligned
    forced = calibrate_mag(sim.mag, sim.acc, still=sim.holds, settings=MagSettings(field=tilted.field,
                                                                                   soft_iron="symmetric"))
    assert forced.fit is forced.symmetric


def test_field_in_another_unit_and_fitted():
    truth = _truth(axes=(1, 0, 0, 0, 1, 0, 0, 0, 1))
    sim = simulate_mag(truth, n_poses=20, seed=8)
    given = calibrate_mag(sim.mag, sim.acc, still=sim.holds, raw_unit="gauss",
                          settings=MagSettings(field=50.0, field_unit="uT"))
    assert given.field_unit == "gauss" and given.params["F"].value == pytest.approx(0.5) and given.params["F"].fixed
    assert given.params["b1"].value == pytest.approx(truth.b[0], abs=5 * given.fit.std["b1"])
    fitted = calibrate_mag(sim.mag, sim.acc, still=sim.holds, raw_unit="gauss", settings=MagSettings(size=1.0))
    b = np.array([fitted.params[f"b{i}"].value for i in (1, 2, 3)])
    assert np.prod(b) ** (1 / 3) == pytest.approx(1.0, abs=1e-5)
    gm = float(np.prod(truth.b)) ** (1 / 3)  # F in units of the held size
    assert fitted.params["F"].value == pytest.approx(truth.field * gm, abs=5 * fitted.fit.std["F"])


def test_without_an_accelerometer_the_ellipsoid_alone():
    truth = _truth(axes=(1, 0, 0, 0, 1, 0, 0, 0, 1))
    sim = simulate_mag(truth, n_poses=20, seed=9)
    cal = calibrate_mag(sim.mag, settings=MagSettings(field=truth.field))
    assert cal.report.dip_deg is None and cal.axes is None
    assert set(cal.fit.free_names) == {"s1", "s2", "s3", "b1", "b2", "b3", "phi", "psi", "theta"}
    assert cal.report.norm_pct.after == pytest.approx(cal.report.norm_pct.floor, rel=0.1)
    assert all(cal.params[n].fixed for n in ROTATION_NAMES)


def _flat_turns(n: int, seed: int) -> np.ndarray:
    """Orientations turned about the vertical only (the sensor flat on a table)."""
    yaw = np.random.default_rng(seed).uniform(0, 2 * math.pi, n)
    c, s = np.cos(yaw), np.sin(yaw)
    return np.stack([np.stack([c, -s, 0 * c], -1), np.stack([s, c, 0 * c], -1),
                     np.stack([0 * c, 0 * c, 1 + 0 * c], -1)], 1)


def test_too_few_directions_refused_naming_what_to_record():
    """Turned flat on a table the field never leaves one cone: refused, naming the axes to point along it."""
    truth = _truth(axes=(1, 0, 0, 0, 1, 0, 0, 0, 1))
    sim = simulate_mag(truth, n_poses=20, seed=10, orientations=_flat_turns(20, 10))
    with pytest.raises(ImucalError) as e:
        calibrate_mag(sim.mag, sim.acc, settings=MagSettings(field=truth.field), source="flat.csv")
    assert str(e.value) == ("flat.csv: mx, my, mz: the field's directions leave the hard and soft iron undetermined "
                            "(fix: turn the sensor so that the field also lies along -z, +z of its axes)")


def test_a_cap_of_directions_refused_by_the_observability_check():
    """The field within 60 deg of -z: an ellipsoid is fitted, but s3 and b3 stay undetermined."""
    truth = _truth(axes=(1, 0, 0, 0, 1, 0, 0, 0, 1))
    C = _random_rotations(np.random.default_rng(1), 4000)
    h_body = np.einsum("kji,j->ki", C, [math.cos(truth.dip), 0.0, math.sin(truth.dip)])
    C = C[h_body[:, 2] < -math.cos(math.radians(60))][:25]
    sim = simulate_mag(truth, n_poses=25, seed=10, orientations=C)
    with pytest.raises(ImucalError) as e:
        calibrate_mag(sim.mag, sim.acc, settings=MagSettings(field=truth.field), source="cap.csv")
    msg = str(e.value)
    assert msg.startswith("cap.csv: mx, my, mz: the field's directions (") and "leave s3, b3 undetermined" in msg
    assert "turn the sensor so that the field also lies along" in msg and "+z" in msg


def test_a_field_that_steps_between_poses_is_named():
    truth = _truth()
    sim = simulate_mag(truth, n_poses=24, seed=11, disturbed={k: 1.04 for k in range(14, 24)})
    cal = calibrate_mag(sim.mag, sim.acc, still=sim.holds, settings=MagSettings(field=truth.field))
    st = cal.steps
    assert st.disturbed and st.step_after == 13 and st.step == pytest.approx(0.04, abs=0.01)
    assert [p.pose for p in st.after] == list(range(14, 24)) and st.after[0].start == sim.holds.start[14]
    one = simulate_mag(truth, n_poses=24, seed=11, disturbed={7: 1.06})
    cal = calibrate_mag(one.mag, one.acc, still=one.holds, settings=MagSettings(field=truth.field))
    assert [p.pose for p in cal.steps.outliers] == [7] and cal.steps.step_after is None
    assert [p.pose for p in cal.excluded] == [7]  # left out of the fit: the others fit their field again
    assert max(abs(p.norm_after_pct) for k, p in enumerate(cal.report.poses) if k != 7) < 0.2
    clean = simulate_mag(truth, n_poses=24, seed=11)
    assert not calibrate_mag(clean.mag, clean.acc, still=clean.holds,
                             settings=MagSettings(field=truth.field)).steps.disturbed


def test_mismatched_sensors_refused():
    sim = simulate_mag(_truth(), n_poses=10, seed=12)
    with pytest.raises(ImucalError) as e:
        calibrate_mag(sim.mag, sim.acc[:-5], source="log.csv")
    assert str(e.value) == ("log.csv: ax, ay, az: accelerometer (1445 rows) and magnetometer (1450 rows) differ "
                            "(fix: give both sensors on one time base)")


def test_the_dip_poses_are_the_still_intervals_and_the_quiet_windows_between_them():
    """dip_poses: windows overlapping a still interval are left out, the rest join in time order, flagged."""
    from imucal.mag.calibrate import dip_poses
    from imucal.mag.evidence import Poses

    quiet = Poses(np.arange(0, 1000, 25), np.arange(25, 1025, 25), "windows of 25 samples")
    still = Poses(np.arange(10, 1000, 160), np.arange(40, 1030, 160), "still intervals")  # 7 intervals
    poses, is_still = dip_poses(quiet, still)
    assert np.all(np.diff(poses.start) > 0) and is_still.sum() == still.n
    assert np.array_equal(poses.start[is_still], still.start) and np.array_equal(poses.end[is_still], still.end)
    w = poses.subset(~is_still)
    assert not np.any((w.start[:, None] < still.end) & (w.end[:, None] > still.start))
    assert w.n == quiet.n - 2 * still.n and "between them" in poses.source  # each interval meets two windows
    few = still.subset(np.arange(still.n) < 5)  # fewer than MIN_STILL_POSES: the windows alone, as before
    poses, is_still = dip_poses(quiet, few)
    assert poses is quiet and not is_still.any()


def test_a_log_with_few_still_holds_and_slow_turns_takes_its_dip_from_both():
    """Eight short holds and slow turns between them: the windows between join the dip rows, the report and the
    field's step test still go by the holds, and the alignment is recovered."""
    truth = _truth()
    sim = simulate_mag(truth, n_poses=8, hold=60, transition=400, seed=5)
    cal = calibrate_mag(sim.mag, sim.acc, still=sim.holds, settings=MagSettings(field=truth.field))
    assert cal.poses.n > 2 * sim.holds.n and "between them" in cal.poses.source
    assert len(cal.report.poses) == sim.holds.n
    assert np.all(np.abs(_z(cal, truth)) < 4.5)
