"""Issue 10: each piece of maths is written once, in CasADi; everything else is generated from it
or pinned to it here.

- The Gram determinant is written once in the package (a source scan).
- The closed forms kept for speed (design sensitivities, the samples-mode gradient) equal the
  Jacobian CasADi derives from the model's residual.
- The effect terms are checked against an independent forward model written in this test from
  the published formulas (not the fit's or the simulator's code), in both directions: the
  simulator produces it, and the fit's model inverts it.
"""
from __future__ import annotations

import math
import re
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from imucal.analysis.design import DesignSensor, sensitivity
from imucal.model.effects import REFERENCE_TEMPERATURE, make_effect
from imucal.model.sensor import build_model, frame_np, gram_det_np, gram_np
from imucal.analysis.simulate import SensorSpec

PKG = Path(__file__).resolve().parents[1] / "imucal"
ANGLES = np.array([1.53938, 1.60221, 1.58])
G0 = 9.80665


def test_the_gram_determinant_is_written_once():
    pat = re.compile(r"1\s*-\s*\w+\s*\*\*\s*2\s*-\s*\w+\s*\*\*\s*2\s*-\s*\w+\s*\*\*\s*2")
    hits = [(p.name, i + 1) for p in PKG.rglob("*.py") for i, line in enumerate(p.read_text().splitlines())
            if pat.search(line) and not line.lstrip().startswith(("#", '"', "det G ="))]
    assert [h[0] for h in hits] == ["geometry.py"], hits


def test_generated_geometry_is_the_papers():
    c = np.cos(ANGLES)
    G = np.array([[1, c[0], c[1]], [c[0], 1, c[2]], [c[1], c[2], 1]])
    np.testing.assert_allclose(gram_np(ANGLES), G, atol=1e-15)
    assert gram_det_np(ANGLES) == pytest.approx(np.linalg.det(G), rel=1e-12)
    E = frame_np(ANGLES)
    np.testing.assert_allclose(E.T @ E, G, atol=1e-14)  # the columns are the unit axes
    assert np.allclose(np.tril(E, -1), 0)


def _casadi_jacobian(raw: np.ndarray, p: np.ndarray, g: float) -> np.ndarray:
    model = build_model()
    rs, ps = ca.SX.sym("raw", 3), ca.SX.sym("p", 9)
    r = model.residual(rs, ca.SX(0, 1), ps, g)
    J = ca.Function("J", [rs, ps], [ca.jacobian(r, ps)])
    return np.vstack([np.asarray(J(x, p)).ravel() for x in raw])


def test_design_sensitivities_equal_the_models_jacobian():
    rng = np.random.default_rng(1)
    u = rng.normal(size=(12, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    sensor = DesignSensor(s=(0.3, -0.1, 0.2), b=(1.02, 0.98, 1.01), angles=tuple(ANGLES))
    raw = np.asarray(sensor.s) + np.asarray(sensor.b) * (G0 * u @ frame_np(ANGLES))  # at the truth
    p = np.array([*sensor.s, *sensor.b, *ANGLES])
    np.testing.assert_allclose(sensitivity(u, sensor, G0), _casadi_jacobian(raw, p, G0), rtol=1e-9, atol=1e-12)


def test_generated_numpy_rows_equal_casadis_map_and_jacobian():
    """The one solver path evaluates rows with numpy code generated from the CasADi residual:
    it must equal CasADi's own evaluation (map) of the same function, value and derivatives,
    for the base model and with effects."""
    import casadi as ca

    from imucal.model.effects import make_effect
    from imucal.model.sensor import build_model
    from imucal.solve import least_squares as lsq

    rng = np.random.default_rng(2)
    for effects in [(), (make_effect("bias_temperature"), make_effect("scale_nonlinearity", (0, 2)),
                         make_effect("scale_drift", (1,)))]:
        model = build_model(effects)
        k, npar = len(model.covariates), len(model.names)
        raw = rng.normal(size=(3000, 3)) * 5 + 1.0
        cov = rng.normal(size=(3000, k))
        p = np.r_[0.3, -0.1, 0.2, 1.02, 0.98, 1.01, ANGLES, rng.normal(size=npar - 9) * 1e-3]
        free = tuple(model.names[i] for i in range(npar) if i != 4)  # one held
        fns = lsq.row_functions(model, free)
        pfree = np.array([p[model.names.index(n)] for n in free])
        r, J, Jraw = lsq.jacobians(fns, lsq.Rows(raw, cov), pfree, p, G0)
        rs, cs, ps, gs = ca.SX.sym("r", 3), ca.SX.sym("c", k), ca.SX.sym("p", npar), ca.SX.sym("g")
        res = model.residual(rs, cs, ps, gs)
        f = ca.Function("f", [rs, cs, ps, gs], [res, ca.jacobian(res, ps), ca.jacobian(res, rs)]).map(3000)
        r0, J0, Jr0 = (np.asarray(v) for v in f(raw.T, cov.T, p, G0))
        idx = [model.names.index(n) for n in free]
        np.testing.assert_allclose(r, r0.ravel(), rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(J, J0.reshape(3000, npar)[:, idx], rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(Jraw, Jr0.reshape(3000, 3), rtol=1e-10, atol=1e-12)


def test_base_model_jacobian_equals_the_models_jacobian():
    from imucal.model.sensor import build_model
    from imucal.model.parameters import BASE_NAMES
    from imucal.solve import least_squares as lsq

    rng = np.random.default_rng(2)
    raw = rng.normal(size=(20, 3)) * 5 + 1.0
    p = np.array([0.3, -0.1, 0.2, 1.02, 0.98, 1.01, *ANGLES])
    fns = lsq.row_functions(build_model(), BASE_NAMES)
    _, J, _ = lsq.jacobians(fns, lsq.Rows(raw, np.zeros((20, 0))), p, p, G0)
    np.testing.assert_allclose(J, _casadi_jacobian(raw, p, G0), rtol=1e-9, atol=1e-12)


# --- effects against an independent forward model (the formulas of imucal/model/effects.py's table) ---------
def true_force(m: np.ndarray, angles=ANGLES) -> np.ndarray:
    """The specific force a whose projections on the axes at ``angles`` are m (m = E^T a, Lemma 1)."""
    return np.linalg.solve(frame_np(np.asarray(angles)).T, m.T).T


def forward(name: str, s, b, m, t, T, k):
    """raw = s + b m with each effect's published term; written here, not imported."""
    dT = T - REFERENCE_TEMPERATURE
    return {
        "bias_temperature": s + k * dT[:, None] + b * m,
        "scale_temperature": s + b * (1 + k * dT[:, None]) * m,
        "bias_drift": s + k * t[:, None] + b * m,
        "scale_drift": s + b * (1 + k * t[:, None]) * m,
        "scale_nonlinearity": s + b * (m + k * m**2),
    }[name]


COEFF = {"bias_temperature": [0.02, -0.01, 0.015], "scale_temperature": [2e-4, -1e-4, 3e-4],
         "bias_drift": [1e-3, -2e-3, 5e-4], "scale_drift": [1e-5, -2e-5, 3e-5],
         "scale_nonlinearity": [2e-3, -1e-3, 1.5e-3]}


@pytest.mark.parametrize("name", sorted(COEFF))
def test_effects_match_an_independent_forward_model(name):
    rng = np.random.default_rng(3)
    n = 50
    s, b = np.array([0.3, -0.1, 0.2]), np.array([1.02, 0.98, 1.01])
    m = rng.normal(size=(n, 3)) * 6
    t = np.linspace(0, 300, n)
    T = np.linspace(15, 40, n)
    k = np.array(COEFF[name])
    want = forward(name, s, b, m, t, T, k)
    coeffs = {f"{name}_{a}": float(v) for a, v in zip("xyz", k)}
    sensor = SensorSpec(s=tuple(s), b=tuple(b), angles=tuple(ANGLES), effects={name: coeffs})
    np.testing.assert_allclose(sensor.forward(true_force(m), t, T), want, rtol=1e-12, atol=1e-12)  # the simulator
    model = build_model([make_effect(name, (0, 1, 2))])
    values = {**sensor.values(), f"{name}_tref": REFERENCE_TEMPERATURE}
    p = np.array([values[nm] for nm in model.names])
    cov = {"temp": T, "time": t}
    C = np.vstack([cov[c] for c in model.covariates]) if model.covariates else np.zeros((0, n))
    got = np.asarray(model.measured.map(n)(want.T, C, p)).T  # the fit's model inverts it
    np.testing.assert_allclose(got, m, rtol=1e-10, atol=1e-10)
    assert not math.isclose(float(np.abs(want - (s + b * m)).max()), 0.0)  # the effect is really there


# --- the grammar's new terms against forward models written here ---------------------------------
#: Reference constants (fixed parameters of the file) chosen away from the defaults, so a wrong
#: recurrence or a swapped constant shows.
REFS = {"tref": 27.5, "t0": 120.0, "a2": 29.0, "b2": 40.0, "a3": 26.0, "b3": 35.0}
TAU = 45.0


def grammar_basis(basis: str, t: np.ndarray, T: np.ndarray) -> np.ndarray:
    """The published bases: monic orthogonal polynomials in the recurrence form, and the warm-up."""
    a1T, a1t, a2, b2, a3, b3 = (REFS[k] for k in ("tref", "t0", "a2", "b2", "a3", "b3"))
    return {
        "temperature2": (T - a2) * (T - a1T) - b2,
        "temperature3": (T - a3) * ((T - a2) * (T - a1T) - b2) - b3 * (T - a1T),
        "drift2": (t - a2) * (t - a1t) - b2,
        "warmup": 1 - np.exp(-t / TAU),
    }[basis]


def grammar_forward(name: str, s, b, m, t, T, k):
    """raw for one new term (coefficients k per axis); the nonlinear ones on the true m."""
    if name == "scale_nonlinearity3":
        return s + b * (m + k * m**3)
    if name == "cross_axis_nonlinearity":
        mjmk = np.column_stack([m[:, 1] * m[:, 2], m[:, 0] * m[:, 2], m[:, 0] * m[:, 1]])
        return s + b * (m + k * mjmk)
    target, basis = name.split("_", 1)
    f = grammar_basis(basis, t, T)[:, None]
    return s + k * f + b * m if target == "bias" else s + b * (1 + k * f) * m


GRAMMAR_COEFF = {
    "bias_temperature2": [2e-3, -1e-3, 1.5e-3], "scale_temperature2": [2e-5, -1e-5, 3e-5],
    "bias_temperature3": [1e-4, -2e-4, 5e-5], "scale_temperature3": [1e-6, -2e-6, 3e-6],
    "bias_drift2": [1e-5, -2e-5, 5e-6], "scale_drift2": [1e-7, -2e-7, 3e-7],
    "bias_warmup": [0.05, -0.03, 0.02], "scale_warmup": [2e-3, -1e-3, 3e-3],
    "scale_nonlinearity3": [2e-4, -1.5e-4, 1e-4], "cross_axis_nonlinearity": [1.5e-3, -1e-3, 2e-3],
}


@pytest.mark.parametrize("name", sorted(GRAMMAR_COEFF))
def test_grammar_terms_match_an_independent_forward_model(name):
    rng = np.random.default_rng(4)
    n = 60
    s, b = np.array([0.3, -0.1, 0.2]), np.array([1.02, 0.98, 1.01])
    m = rng.normal(size=(n, 3)) * 8
    m *= np.minimum(1.0, 2.5 * G0 / np.linalg.norm(m, axis=1))[:, None]  # |m| up to 2.5 g
    t = np.linspace(0, 300, n)
    T = 25 + 12 * np.sin(t / 40)  # not monotonic in time
    k = np.array(GRAMMAR_COEFF[name])
    want = grammar_forward(name, s, b, m, t, T, k)
    eff = make_effect(name, (0, 1, 2))
    coeffs = {f"{name}_{a}": float(v) for a, v in zip("xyz", k)}
    refs = {n_: REFS[n_.rsplit("_", 1)[1]] for n_ in eff.reference_names}
    if eff.shape_names:
        refs[f"{name}_tau"] = TAU
    sensor = SensorSpec(s=tuple(s), b=tuple(b), angles=tuple(ANGLES), effects={name: {**coeffs, **refs}})
    np.testing.assert_allclose(sensor.forward(true_force(m), t, T), want, rtol=1e-12, atol=1e-12)  # the simulator
    model = build_model([eff])
    values = {**sensor.values(), **refs}
    p = np.array([values[nm] for nm in model.names])
    cov = {"temp": T, "time": t}
    C = np.vstack([cov[c] for c in model.covariates]) if model.covariates else np.zeros((0, n))
    got = np.asarray(model.measured.map(n)(want.T, C, p)).T  # the fit's model inverts it
    np.testing.assert_allclose(got, m, rtol=1e-11, atol=1e-11)
    assert float(np.abs(want - (s + b * m)).max()) > 1e-3  # the effect is really there


@pytest.mark.parametrize("name,q", [("scale_nonlinearity3", 3e-4), ("scale_nonlinearity3", -3e-4),
                                    ("cross_axis_nonlinearity", 6e-3), ("cross_axis_nonlinearity", -6e-3),
                                    ("scale_asymmetry", 0.05), ("scale_asymmetry", -0.05)])
def test_iterative_inverses_converge_at_the_coefficient_bounds(name, q):
    """Newton (cubic), fixed-point (cross-axis) and exact (asymmetry) inverses reach rounding at |m| = 2.5 g and
    the bounds."""
    eff = make_effect(name, (0, 1, 2))
    assert make_effect(name, (0,)).parameters(base_parameters_for_test())[0].upper == pytest.approx(abs(q))
    rng = np.random.default_rng(5)
    m = rng.normal(size=(200, 3))
    m *= (2.5 * G0 / np.linalg.norm(m, axis=1))[:, None]
    p = {f"{name}_{a}": q for a in "xyz"}
    u = np.column_stack(eff.distort([m[:, i] for i in range(3)], p))
    back = np.column_stack(eff.correct([u[:, i] for i in range(3)], None, {}, p))
    np.testing.assert_allclose(back, m, rtol=0, atol=1e-12 * 2.5 * G0)


def base_parameters_for_test():
    from imucal.model.parameters import base_parameters

    return base_parameters([0, 0, 0], [1, 1, 1])


def test_grammar_pair_composes_in_the_models_order():
    """Two specific-force terms: the sensor applies them in the grammar's order, the model undoes
    them in reverse (the pair's forward model written here as the composition)."""
    rng = np.random.default_rng(6)
    m = rng.normal(size=(40, 3)) * 7
    q2, qc = np.array([2e-3, -1e-3, 1e-3]), np.array([1e-3, 1e-3, -1.5e-3])
    u = m + q2 * m**2
    u = u + qc * np.column_stack([u[:, 1] * u[:, 2], u[:, 0] * u[:, 2], u[:, 0] * u[:, 1]])
    spec = {"scale_nonlinearity": {f"scale_nonlinearity_{a}": v for a, v in zip("xyz", q2)},
            "cross_axis_nonlinearity": {f"cross_axis_nonlinearity_{a}": v for a, v in zip("xyz", qc)}}
    sensor = SensorSpec(effects=spec)
    raw = sensor.forward(m, np.zeros(40), None)
    np.testing.assert_allclose(raw, u, rtol=1e-13, atol=1e-13)
    model = build_model([make_effect("scale_nonlinearity"), make_effect("cross_axis_nonlinearity")])
    p = np.array([sensor.values()[nm] for nm in model.names])
    got = np.asarray(model.measured.map(40)(raw.T, np.zeros((0, 40)), p)).T
    np.testing.assert_allclose(got, m, rtol=1e-11, atol=1e-11)


# --- issue 28's terms: what real MEMS do, against forward models written here ----------------------------------
def frame_by_cholesky(angles: np.ndarray) -> np.ndarray:
    """E with G = E^T E, upper triangular with a positive diagonal: the Gram matrix (Eq. eq:12) factored
    here by numpy, not by the model's frame (each row of ``angles`` one sample)."""
    c = np.cos(np.atleast_2d(angles))
    G = np.stack([np.stack([np.ones(len(c)), c[:, 0], c[:, 1]], -1), np.stack([c[:, 0], np.ones(len(c)), c[:, 2]], -1),
                  np.stack([c[:, 1], c[:, 2], np.ones(len(c))], -1)], 1)
    return np.transpose(np.linalg.cholesky(G), (0, 2, 1))


def local_slope(t: np.ndarray, T: np.ndarray, half: float = 10.0) -> np.ndarray:
    """dT/dt as the published definition says: the least-squares slope over +-half seconds of each row
    (at least the three nearest rows), by np.polyfit row by row."""
    out = []
    for k in range(len(t)):
        idx = np.flatnonzero(np.abs(t - t[k]) <= half)
        if idx.size < 3:
            idx = np.argsort(np.abs(t - t[k]), kind="stable")[:3]
        out.append(np.polyfit(t[idx], T[idx], 1)[0])
    return np.array(out)


ISSUE28 = {"scale_asymmetry": [0.02, -0.01, 0.015], "bias_step": [0.05, -0.03, 0.02],
           "bias_hysteresis": [0.04, -0.02, 0.03], "angle_temperature": [3e-4, -2e-4, 1e-4]}
STEP_T, R0 = 137.0, 0.01


def issue28_forward(name: str, s, b, a, t, T, k):
    """raw for one of the new terms from the true specific force a (frame f)."""
    E = frame_by_cholesky(ANGLES)[0]
    m = a @ E  # m_i = e_i . a, Lemma 1
    if name == "scale_asymmetry":
        return s + b * (m + k * np.abs(m))
    if name == "bias_step":
        return s + k * (t >= STEP_T)[:, None] + b * m
    if name == "bias_hysteresis":
        return s + k * np.clip(local_slope(t, T) / R0, -1, 1)[:, None] + b * m
    angles = ANGLES + np.outer(T - REFS["tref"], k)  # phi(T) = phi + c (T - T_ref), psi and theta alike
    return s + b * np.einsum("nj,nji->ni", a, frame_by_cholesky(angles))


@pytest.mark.parametrize("name", sorted(ISSUE28))
def test_issue28_terms_match_an_independent_forward_model(name):
    """Simulated by SensorSpec.forward and inverted by the model: the calibrated acceleration (Theorem,
    at each sample's angles) is the true one."""
    rng = np.random.default_rng(7)
    n = 60
    s, b = np.array([0.3, -0.1, 0.2]), np.array([1.02, 0.98, 1.01])
    a = rng.normal(size=(n, 3)) * 8
    a *= np.minimum(1.0, 2.5 * G0 / np.linalg.norm(a, axis=1))[:, None]
    t = np.linspace(0, 300, n)
    T = 25 + 12 * np.sin(t / 40)  # warms and cools
    k = np.array(ISSUE28[name])
    want = issue28_forward(name, s, b, a, t, T, k)
    eff = make_effect(name, (0, 1, 2))
    coeffs = {eff.coefficient(i): float(v) for i, v in enumerate(k)}
    fixed = {f"{name}_tref": REFS["tref"], f"{name}_t": STEP_T, f"{name}_r0": R0}
    refs = {n_: fixed[n_] for n_ in (*eff.reference_names, *eff.given_names)}
    sensor = SensorSpec(s=tuple(s), b=tuple(b), angles=tuple(ANGLES), effects={name: {**coeffs, **refs}})
    np.testing.assert_allclose(sensor.forward(a, t, T), want, rtol=1e-12, atol=1e-12)  # the simulator
    model = build_model([eff])
    p = np.array([{**sensor.values(), **refs}[nm] for nm in model.names])
    cov = {"temp": T, "time": t, "temp_rate": local_slope(t, T)}
    C = np.vstack([cov[c] for c in model.covariates]) if model.covariates else np.zeros((0, n))
    got = np.asarray(model.accel.map(n)(want.T, C, p)).T  # the fit's model inverts it
    np.testing.assert_allclose(got, a, rtol=1e-10, atol=1e-10)
    assert float(np.abs(want - (s + b * (a @ frame_by_cholesky(ANGLES)[0]))).max()) > 1e-3  # the effect is there


def test_the_temperature_rate_is_the_published_slope():
    """imucal.model.channels.temperature_rate (prefix sums) equals the slope written here, on uneven rows."""
    from imucal.model.channels import temperature_rate

    rng = np.random.default_rng(8)
    t = np.sort(rng.uniform(0, 200, 80))
    T = 25 + 8 * np.sin(t / 30) + rng.normal(0, 0.05, t.size)
    np.testing.assert_allclose(temperature_rate(t, T), local_slope(t, T), rtol=1e-9, atol=1e-12)
