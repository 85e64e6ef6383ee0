"""A sensor is data (issue 26): every sensor is a SensorModel, and what is generated from its CasADi map
(the numpy evaluator, the affine map for people) equals CasADi's own evaluation of it."""
from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from imucal.model.channels import ACCELERATION, ANGULAR_RATE, TEMPERATURE, TIME
from imucal.model.effects import make_effect
from imucal.model.gyroscope import GSENS_NAMES, gyro_model, gyro_parameters
from imucal.model.parameters import base_parameters
from imucal.model.sensor import ACCELEROMETER, GYROSCOPE, SensorModel, build_model
from imucal.solve.vectorize import apply_values

RNG = np.random.default_rng(26)


def _accelerometer(effects=()) -> tuple[SensorModel, np.ndarray]:
    model = build_model([make_effect(n, a) for n, a in effects])
    params = model.parameters(base_parameters([300.0, -200.0, 150.0], [410.0, 415.0, 405.0], [1.56, 1.575, 1.58]))
    p = np.array(params.values())
    p[9:] = RNG.normal(size=p.size - 9) * 1e-3  # small effect coefficients
    return model, p


def _gyroscope() -> tuple[SensorModel, np.ndarray]:
    params = gyro_parameters("raw", [32768.0, 32450.0, 32510.0], [4780.0, 4760.0, 4770.0],
                             RNG.normal(size=6) * 0.02, RNG.normal(size=9) * 0.5)
    return gyro_model(), np.array(params.values())


CASES = {"accelerometer": lambda: _accelerometer(), "gyroscope": _gyroscope,
         "accelerometer+temperature": lambda: _accelerometer([("bias_temperature", (0, 1, 2))]),
         "accelerometer+nonlinear": lambda: _accelerometer([("scale_nonlinearity", (0, 2))])}


@pytest.mark.parametrize("case", list(CASES))
def test_generated_apply_equals_casadis_own(case: str) -> None:
    model, p = CASES[case]()
    n, k = 50, len(model.inputs)
    raw = (p[0:3] if model.kind == GYROSCOPE else np.array([300.0, -200.0, 150.0])) + RNG.normal(size=(n, 3)) * 900
    inputs = RNG.normal(size=(n, k)) * 5
    want = np.asarray(model.apply.map(n)(raw.T, inputs.T, p)).T
    np.testing.assert_allclose(apply_values(model, p, raw, inputs), want, rtol=1e-13, atol=1e-13 * np.abs(want).max())


@pytest.mark.parametrize("case", list(CASES))
def test_affine_map_is_the_apply_where_it_is_affine(case: str) -> None:
    """``affine`` is derived from apply by CasADi (its Jacobians and its value at zero): A raw + c + B inputs
    equals apply wherever apply is affine in raw and inputs; a nonlinear effect has none."""
    model, p = CASES[case]()
    if case.endswith("nonlinear"):
        assert model.affine is None and not model.is_affine
        return
    A, c, B = (np.asarray(v) for v in model.affine(p))
    raw, inputs = RNG.normal(size=(20, 3)) * 500, RNG.normal(size=(20, len(model.inputs)))
    got = raw @ A.T + c.ravel() + inputs @ B.T
    np.testing.assert_allclose(got, apply_values(model, p, raw, inputs), rtol=1e-10, atol=1e-12)


def test_the_accelerometers_affine_map_is_its_lower_triangular_linear_map() -> None:
    model, p = _accelerometer()
    A, c, B = model.affine(p)
    A0, c0 = model.linear_map(p)
    np.testing.assert_allclose(np.asarray(A), np.asarray(A0), rtol=1e-15)
    np.testing.assert_allclose(np.asarray(c), np.asarray(c0), rtol=1e-12)
    assert B.shape == (3, 0)
    assert [A.sparsity().has_nz(i, j) for i in range(3) for j in range(i + 1, 3)] == [False] * 3  # structural zeros


def test_the_gyroscopes_g_sensitivity_is_its_only_input() -> None:
    """omega = C (raw - s_g) - C H a: with H = 0 the map does not depend on its inputs (the C drops them)."""
    model, p = _gyroscope()
    p[[model.names.index(n) for n in GSENS_NAMES]] = 0.0
    _, _, B = model.affine(p)
    assert not np.any(np.asarray(B))
    raw, a = ca.SX.sym("raw", 3), ca.SX.sym("a", 3)
    assert not ca.depends_on(model.apply(raw, a, ca.DM(p)), a)


def test_descriptions_say_what_they_read_and_write() -> None:
    acc, gyro = build_model([make_effect("bias_temperature", (0,))]), gyro_model()
    assert (acc.kind, acc.channel, acc.inputs, acc.output.unit) == (ACCELEROMETER, ACCELERATION, ("temp",), "m/s^2")
    assert acc.reads == (ACCELERATION, TEMPERATURE)
    assert (gyro.kind, gyro.channel, gyro.inputs, gyro.output.columns, gyro.output.unit) == (
        GYROSCOPE, ANGULAR_RATE, ("ax", "ay", "az"), ("gx", "gy", "gz"), "rad/s")
    assert gyro.reads == (ANGULAR_RATE, ACCELERATION, TIME)
    assert len(set(gyro.names)) == len(gyro.names) == 21


def test_an_evidence_may_read_other_inputs_than_the_map() -> None:
    """The magnetometer's rows read their kind and the calibrated acceleration, its map nothing: the
    description's ``evidence_inputs`` sizes the rows' covariates (least_squares.row_functions)."""
    from imucal.model.channels import ACCELERATION as MAG  # any channel: the test's sensor is made up
    from imucal.solve.least_squares import Rows, residuals, row_functions

    raw, inp, p = ca.SX.sym("raw", 3), ca.SX.sym("inputs", 0), ca.SX.sym("p", 2)
    cov, g = ca.SX.sym("cov", 2), ca.SX.sym("g")
    y = p[0] * (raw - p[1])
    fns = {"apply": ca.Function("apply", [raw, inp, p], [y]),
           "residual": ca.Function("residual", [raw, cov, p, g], [ca.norm_2(y) - g + cov[0] * cov[1]])}
    model = SensorModel(effects=(), names=("k", "o"), inputs=(), functions=fns, kind="made-up", label="made-up",
                        channel=MAG, output=MAG, evidence_inputs=("kind", "ax"))
    assert model.covariates == () and model.evidence_covariates == ("kind", "ax")
    rows = Rows(np.array([[3.0, 4.0, 1.0], [0.0, 0.0, 2.0]]), np.array([[1.0, 0.5], [0.0, 7.0]]))
    r = residuals(row_functions(model, ("k",)), rows, [2.0], [2.0, 1.0], 1.0)
    np.testing.assert_allclose(r, [2 * np.sqrt(4 + 9) - 1 + 0.5 * 1.0, 2 * np.sqrt(3) - 1 + 7.0 * 0.0])
