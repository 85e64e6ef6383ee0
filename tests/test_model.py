"""The paper's identities (shared/seed, Sections 2-3), checked on the symbolic model.

Lemma 2 / Remark 1: abar = Tbar m with Tbar = G^-1.  Proposition 2: |a|^2 = numerator/denominator
= m^T G^-1 m.  Proposition 3: E^T E = G, E upper triangular, cos(eta) from the corrected line.
Theorem: a_orth = T^orth Tbar T raw - T^orth Tbar s = E^-T diag(1/b)(raw - s), lower triangular
with structural zeros.
"""
from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from imucal.model.sensor import build_model, frame, frame_inverse_transpose, gram, tbar
from imucal.model.parameters import BASE_NAMES
from imucal.analysis.simulate import frame_matrix

RNG = np.random.default_rng(7)
HALF_PI = math.pi / 2

#: Angle triples near 90 deg (the sensor's range) and further off (the identities are exact).
ANGLES = [(HALF_PI, HALF_PI, HALF_PI), (1.58, 1.56, 1.575), (1.3, 1.7, 1.45), (1.9, 1.2, 1.6),
          tuple(HALF_PI * (1 + 0.02 * RNG.uniform(-1, 1, 3)))]


def num(f) -> np.ndarray:
    if isinstance(f, ca.MX):  # frame_inverse_transpose builds MX for numeric arguments
        f = ca.evalf(f)
    return np.asarray(ca.DM(f), float)


def paper_tbar(phi, psi, theta) -> np.ndarray:
    """Remark 1 typed in from the paper, with numpy, independently of imucal.model.sensor."""
    cf, cp, ct = np.cos([phi, psi, theta])
    den = -1 + cf**2 + cp**2 + ct**2 - 2 * cf * cp * ct
    return np.array([[-np.sin(theta) ** 2, cf - ct * cp, cp - cf * ct],
                     [cf - ct * cp, -np.sin(psi) ** 2, ct - cf * cp],
                     [cp - cf * ct, ct - cf * cp, -np.sin(phi) ** 2]]) / den


def paper_norm_squared(m, phi, psi, theta) -> float:
    """Proposition 2's numerator / denominator, typed in from the paper."""
    ax, ay, az = m
    cf, cp, ct = np.cos([phi, psi, theta])
    numerator = (2 * (-1 + np.cos(2 * theta)) * ax**2 + 2 * (-1 + np.cos(2 * psi)) * ay**2
                 + 2 * (-1 + np.cos(2 * phi)) * az**2 + 8 * (cf - cp * ct) * ax * ay
                 + 8 * (ct - cf * cp) * ay * az + 8 * (cp - cf * ct) * ax * az)
    denominator = 2 + 2 * np.cos(2 * phi) + 2 * np.cos(2 * psi) + 2 * np.cos(2 * theta) - 8 * cf * cp * ct
    return numerator / denominator


def pvec(s=(0.0, 0.0, 0.0), b=(1.0, 1.0, 1.0), angles=(HALF_PI,) * 3) -> np.ndarray:
    return np.array([*s, *b, *angles], float)


@pytest.mark.parametrize("angles", ANGLES)
def test_gram_matrix_is_eq12(angles):
    G = num(gram(*angles))
    cf, cp, ct = np.cos(angles)
    np.testing.assert_allclose(G, [[1, cf, cp], [cf, 1, ct], [cp, ct, 1]], rtol=0, atol=1e-15)


@pytest.mark.parametrize("angles", ANGLES)
def test_lemma2_affine_projections_solve_eq12(angles):
    """Lemma 2: abar = Tbar m equals the solution of G abar = m (Eq. eq:12)."""
    G = num(gram(*angles))
    T = num(tbar(*angles))
    np.testing.assert_allclose(T, paper_tbar(*angles), rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(T @ G, np.eye(3), atol=1e-12)
    for m in RNG.normal(0, 9.8, (5, 3)):
        np.testing.assert_allclose(T @ m, np.linalg.solve(G, m), rtol=1e-11, atol=1e-11)


@pytest.mark.parametrize("angles", ANGLES)
def test_proposition2_numerator_over_denominator_is_mT_Ginv_m(angles):
    model = build_model()
    G = num(gram(*angles))
    for m in RNG.normal(0, 9.8, (5, 3)):
        direct = m @ np.linalg.solve(G, m)
        assert paper_norm_squared(m, *angles) == pytest.approx(direct, rel=1e-11)
        # the model's norm: s = 0, b = 1 makes raw = m
        assert float(model.norm(m, [], pvec(angles=angles))) == pytest.approx(math.sqrt(direct), rel=1e-12)


def test_lemma3_norm_from_affine_coordinates():
    """Lemma 3: |a|^2 = abar^T G abar with abar = G^-1 m (so = m^T G^-1 m)."""
    angles = ANGLES[2]
    G = num(gram(*angles))
    m = np.array([3.0, -7.0, 5.5])
    abar = np.linalg.solve(G, m)
    cf, cp, ct = np.cos(angles)
    a2 = (abar @ abar + 2 * abar[0] * abar[1] * cf + 2 * abar[0] * abar[2] * cp
          + 2 * abar[1] * abar[2] * ct)
    assert a2 == pytest.approx(m @ abar, rel=1e-12)


@pytest.mark.parametrize("angles", ANGLES)
def test_proposition3_frame(angles):
    """E (Eq. eq:125): upper triangular, unit columns, E^T E = G, columns make the given angles."""
    E = num(frame(*angles))
    G = num(gram(*angles))
    assert np.all(np.tril(E, -1) == 0.0)
    np.testing.assert_allclose(E.T @ E, G, atol=1e-13)
    np.testing.assert_allclose(np.linalg.norm(E, axis=0), 1.0, atol=1e-14)
    phi, psi, theta = angles
    e1, e2, e3 = E.T
    assert math.acos(e1 @ e2) == pytest.approx(phi, abs=1e-12)
    assert math.acos(e1 @ e3) == pytest.approx(psi, abs=1e-12)
    assert math.acos(e2 @ e3) == pytest.approx(theta, abs=1e-12)
    assert E[2, 2] > 0  # eta small: cos(eta) > 0, a right-handed frame
    # The simulator's numeric E is the same matrix.
    np.testing.assert_allclose(frame_matrix(np.array(angles)), E, atol=1e-15)


@pytest.mark.parametrize("angles", ANGLES[1:])
def test_corrected_cos_eta_line(angles):
    """cos^2 eta + cos^2 xi + cos^2 psi = 1, so cos eta = sqrt(1 - cos^2 xi - cos^2 psi).

    The paper prints "+ cos^2 psi"; that line is wrong whenever psi != 90 deg, while its final
    closed form (Eq. eq:125) is right. The model must follow the corrected line.
    """
    phi, psi, theta = angles
    E = num(frame(*angles))
    cxi, ceta = E[1, 2], E[2, 2]
    assert ceta == pytest.approx(math.sqrt(1 - cxi**2 - math.cos(psi) ** 2), rel=1e-13)
    cf, cp, ct = math.cos(phi), math.cos(psi), math.cos(theta)
    closed = math.sqrt(1 - cf**2 - cp**2 - ct**2 + 2 * cf * cp * ct) / math.sin(phi)
    assert ceta == pytest.approx(closed, rel=1e-13)
    misprint = math.sqrt(1 - cxi**2 + cp**2)
    assert abs(ceta - misprint) > 1e-6


@pytest.mark.parametrize("angles", ANGLES)
def test_frame_inverse_transpose(angles):
    """L = E^-T = T^orth Tbar (Theorem): lower triangular, and equal to E G^-1."""
    E = num(frame(*angles))
    L = num(frame_inverse_transpose(*angles))
    np.testing.assert_allclose(L, np.linalg.inv(E).T, atol=1e-12)
    np.testing.assert_allclose(E @ num(tbar(*angles)), L, atol=1e-12)
    assert np.all(np.triu(L, 1) == 0.0)


def test_theorem_map_has_structural_zeros():
    """The apply map's upper triangle is structurally zero (CasADi sparsity), not just small."""
    model = build_model()
    sp = model.linear_map.sparsity_out(0)
    assert sp.size() == (3, 3)
    nz = set(zip(sp.row(), sp.get_col()))
    assert nz == {(i, j) for i in range(3) for j in range(i + 1)}
    sym = ca.SX.sym("a", 3)
    Ls = frame_inverse_transpose(sym[0], sym[1], sym[2])
    assert set(zip(Ls.sparsity().row(), Ls.sparsity().get_col())) == nz
    A, _ = model.linear_map(pvec(s=(1, 2, 3), b=(2, 3, 4), angles=ANGLES[3]))
    assert np.asarray(ca.DM(A).full())[0, 1] == 0.0


@pytest.mark.parametrize("angles", ANGLES)
def test_theorem_apply_map(angles):
    """A raw + c = T^orth Tbar T raw - T^orth Tbar s, and it equals the model's accel()."""
    model = build_model()
    s = RNG.normal(0, 300, 3)
    b = RNG.uniform(1000, 2000, 3)
    p = pvec(s, b, angles)
    A, c = (num(x) for x in model.linear_map(p))
    c = c.ravel()
    E, Tb = num(frame(*angles)), num(tbar(*angles))
    T = np.diag(1 / b)
    svec = s / b  # the paper's s is s_i / b_i
    for raw in RNG.normal(0, 20000, (4, 3)):
        paper = E @ Tb @ T @ raw - E @ Tb @ svec
        np.testing.assert_allclose(A @ raw + c, paper, rtol=1e-10, atol=1e-9)
        np.testing.assert_allclose(num(model.accel(raw, [], p)).ravel(), paper, rtol=1e-10, atol=1e-9)
        # |a_orth| = sqrt(m^T G^-1 m): the Theorem's vector has Proposition 2's length
        m = (raw - s) / b
        assert np.linalg.norm(paper) == pytest.approx(math.sqrt(m @ Tb @ m), rel=1e-11)
        assert float(model.norm(raw, [], p)) == pytest.approx(np.linalg.norm(paper), rel=1e-11)


def test_model_parameter_names():
    model = build_model()
    assert model.names == BASE_NAMES
    assert model.name == "nakov-ivanov-9"
    assert model.is_affine
    assert build_model() is model  # built once


def _rotation(q: np.ndarray) -> np.ndarray:
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


finite = dict(allow_nan=False, allow_infinity=False)


@settings(max_examples=150, deadline=None)
@given(q=st.lists(st.floats(-1, 1, **finite), min_size=4, max_size=4).filter(
           lambda v: np.linalg.norm(v) > 0.1),
       a=st.lists(st.floats(-20, 20, **finite), min_size=3, max_size=3).filter(
           lambda v: np.linalg.norm(v) > 0.5),
       dang=st.lists(st.floats(-0.03, 0.03, **finite), min_size=3, max_size=3),
       s=st.lists(st.floats(-500, 500, **finite), min_size=3, max_size=3),
       b=st.lists(st.floats(0.5, 3000, **finite), min_size=3, max_size=3))
def test_norm_residual_is_rotation_invariant(q, a, dang, s, b):
    """raw made from R a (any rotation R) gives |a| - g independent of R, and equal to |a| - g."""
    model = build_model()
    angles = HALF_PI * (1 + np.array(dang))
    p = pvec(s, b, angles)
    E = frame_matrix(angles)
    a = np.array(a)
    g = float(np.linalg.norm(a))
    res = []
    for R in (np.eye(3), _rotation(np.array(q))):
        m = E.T @ (R @ a)  # Lemma 1
        raw = np.array(s) + np.array(b) * m  # Eq. (theModel)
        res.append(float(model.residual(raw, [], p, g)))
        # and the Theorem's vector is R a itself
        np.testing.assert_allclose(num(model.accel(raw, [], p)).ravel(), R @ a, atol=1e-8 * (1 + g))
    assert abs(res[0]) < 1e-9 * (1 + g)
    assert res[1] == pytest.approx(res[0], abs=1e-9 * (1 + g))
