"""Gyroscope calibration: recovery of known truth, refusal of unobservable motions, one evaluation formula."""
from __future__ import annotations

import numpy as np
import pytest

from imucal.errors import ImucalError
from imucal.gyro import GyroOptions, fit_gyro
from conftest import gyro_rate, rk4_directions
from imucal.gyro.evaluate import direction_errors_deg
from imucal.gyro.fit import _steps
from imucal.gyro.result import arrays, motions
from imucal.model.gyroscope import gyro_model, gyro_parameters, misalignment_entries, misalignment_matrix
from imucal.solve.vectorize import apply_values
from imucal.gyro.segments import motion_segments
from imucal.gyro.simulate import GyroTruth, simulate

TURNS = [(0, 1.5), (1, 1.4), (2, 1.6), (0, -1.3), (1, -1.5), (2, -1.2), (0, 2.0), (1, 1.1), (2, 1.7),
         (0, -1.7), (1, -1.2), (2, -1.9)]
TRUTH = GyroTruth(bias=np.array([32768.0, 32450.0, 32510.0]), scale=np.array([4780.0, 4760.0, 4770.0]),
                  mis=np.array([0.01, -0.02, 0.015, 0.03, -0.025, 0.02]), gsens=np.zeros((3, 3)), noise=3.0)


def test_recovers_scale_and_misalignment_within_three_std() -> None:
    data = simulate(TRUTH, TURNS, seed=1)
    res = fit_gyro(data, GyroOptions(gsens="off"))
    r = arrays(res)
    assert np.all(np.abs(r.scale - TRUTH.scale) <= 3 * r.scale_std), (r.scale, r.scale_std)
    m = misalignment_entries(r.misalignment)
    ms = misalignment_entries(r.misalignment_std)
    assert np.all(np.abs(m - TRUTH.mis) <= 3 * ms), (m, ms)
    assert np.all(np.abs(r.bias - TRUTH.bias) <= 3 * r.bias_std + 1e-9)
    assert motions(res).rms_direction_error_deg["after"] < motions(res).rms_direction_error_deg["before"]


def test_gsensitivity_selected_and_recovered() -> None:
    G = np.array([[0.0, 2e-4, -1e-4], [3e-4, 0.0, 1e-4], [-2e-4, 1e-4, 0.0]])
    truth = GyroTruth(TRUTH.bias, TRUTH.scale, TRUTH.mis, G, noise=1.0)
    data = simulate(truth, TURNS, seed=2)
    res = fit_gyro(data, GyroOptions(gsens="auto"))
    r = arrays(res)
    assert motions(res).gsens_selected.all()
    assert np.all(np.abs(r.gsens - G) <= 3 * r.gsens_std + 1e-12), (r.gsens, r.gsens_std)
    off = fit_gyro(data, GyroOptions(gsens="off"))
    assert motions(res).rms_direction_error_deg["after"] < motions(off).rms_direction_error_deg["after"]


def test_no_gsensitivity_when_there_is_none() -> None:
    r = fit_gyro(simulate(TRUTH, TURNS, seed=3), GyroOptions(gsens="auto"))
    assert not motions(r).gsens_selected.any()


def test_refuses_when_an_axis_is_never_turned_about() -> None:
    turns = [(a, s) for a, s in TURNS if a != 2]
    data = simulate(TRUTH, turns, seed=4)
    with pytest.raises(ImucalError, match="the gyro z scale is not determined") as e:
        fit_gyro(data, GyroOptions(gsens="off"))
    assert "add rotations about the z axis" in str(e.value)


def test_generated_integration_equals_an_independent_numpy_rk4() -> None:
    """The fit's residuals (the description's apply, RK4 increments and products generated from CasADi) and
    the report's direction errors agree with imu_tk's RK4 written in plain numpy (conftest.rk4_directions)."""
    data = simulate(TRUTH, TURNS[:4], seed=5)
    seg = motion_segments(data)
    scale, mis = TRUTH.scale * (1 + np.r_[0.01, -0.02, 0.005]), np.r_[0.01, 0.0, -0.01, 0.02, 0.0, 0.01]
    params = gyro_parameters("raw", TRUTH.bias, scale, mis)
    free = params.free_names
    r = _steps(data, seg).residuals(gyro_model(), free, [params[n].value for n in free], params.values())
    ang = rk4_directions(data.t, gyro_rate(data.gyro, TRUTH.bias, scale, mis), seg)
    # |R^T u0 - u1| = 2 sin(angle / 2) for unit vectors
    np.testing.assert_allclose(np.linalg.norm(r, axis=1), 2 * np.sin(np.radians(ang) / 2), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(direction_errors_deg(data.t, gyro_rate(data.gyro, TRUTH.bias, scale, mis), seg), ang,
                               rtol=1e-9, atol=1e-12)


def test_apply_inverts_the_forward_model() -> None:
    """The description's map (numpy generated from CasADi) inverts raw = s_g + B_g (M_g omega + G_s a)."""
    rng = np.random.default_rng(0)
    omega, acc = rng.normal(size=(5, 3)), rng.normal(size=(5, 3))
    G = rng.normal(size=(3, 3)) * 1e-4
    M = misalignment_matrix(TRUTH.mis)
    raw = TRUTH.bias + (omega @ M.T + acc @ G.T) * TRUTH.scale
    p = gyro_parameters("raw", TRUTH.bias, TRUTH.scale, TRUTH.mis, (TRUTH.scale[:, None] * G).ravel())
    np.testing.assert_allclose(apply_values(gyro_model(), p.values(), raw, acc), omega, atol=1e-9)
    assert misalignment_entries(M).tolist() == TRUTH.mis.tolist()


def test_bad_gsens_option_is_refused() -> None:
    with pytest.raises(ImucalError, match="gsens 'maybe' is not one of auto, on, off"):
        GyroOptions(gsens="maybe")
