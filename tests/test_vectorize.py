"""The numpy evaluators generated from CasADi (imucal.solve.vectorize): rows in cache-sized blocks
and parameters broadcast against rows give the numbers of one evaluation over every row."""
from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from imucal.solve import vectorize
from imucal.solve.vectorize import Vectorized


@pytest.fixture(scope="module")
def fn() -> Vectorized:
    """A rotation of the row x by angle p[0] about z, scaled by p[1]: parameters and rows mixed."""
    p, x = ca.SX.sym("p", 2), ca.SX.sym("x", 3)
    c, s = ca.cos(p[0]), ca.sin(p[0])
    y = ca.vertcat(c * x[0] - s * x[1], s * x[0] + c * x[1], x[2]) / p[1] + ca.sqrt(ca.sumsqr(x))
    return Vectorized(ca.Function("f", [p, x], [y, p[1] * p[0]]))


def test_rows_in_blocks_are_the_rows_at_once(fn, monkeypatch):
    x = np.random.default_rng(1).normal(size=(3, 3 * vectorize.ROW_BLOCK + 17))
    p = np.array([0.3, 2.0])
    blocked = fn(p, x)
    monkeypatch.setattr(vectorize, "ROW_BLOCK", 10**9)
    whole = fn(p, x)
    assert blocked[0].shape == (3, x.shape[1]) and blocked[1].shape == (1, x.shape[1])
    assert all(np.array_equal(a, b) for a, b in zip(blocked, whole))
    direct = np.array(fn.function.map(x.shape[1])(p, x)[0])
    np.testing.assert_allclose(blocked[0], direct, rtol=1e-15, atol=0)


def test_parameters_broadcast_against_rows(fn):
    rng = np.random.default_rng(2)
    k, n = 5, vectorize.ROW_BLOCK + 3
    p = np.vstack([rng.uniform(0, 1, k), rng.uniform(1, 2, k)])  # (2, k): one column per candidate
    x = rng.normal(size=(3, n))
    got = fn(p[:, :, None], x[:, None, :])
    assert got[0].shape == (3, k, n) and got[1].shape == (1, k, n)
    tiled = fn(np.repeat(p, n, axis=1), np.tile(x, (1, k)))[0]  # what a caller did before: k n columns
    assert np.array_equal(got[0].reshape(3, -1), tiled)


def test_one_evaluation_without_rows(fn):
    out = fn([0.0, 1.0], [1.0, 2.0, 2.0])
    assert out[0].shape == (3,) and np.array_equal(out[0], [4.0, 5.0, 5.0]) and out[1].shape == (1,)
