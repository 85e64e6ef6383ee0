"""The min-p family-wise correction of a discovery round (imucal.analysis.min_p) and the array chi-square tail."""
from __future__ import annotations

import numpy as np
import pytest

from imucal.analysis.min_p import min_p_null
from imucal.solve.stats import chi2_sf, chi2_sf_array


@pytest.mark.parametrize("k", [1, 2, 3, 4, 5])
def test_chi2_sf_array_matches_the_scalar_tail(k):
    x = np.array([0.0, 1e-3, 0.5, 1.0, 3.0, 10.83, 19.5, 40.0, 300.0])
    want = np.array([chi2_sf(v, k) for v in x])
    assert np.allclose(chi2_sf_array(x, k), want, rtol=1e-12, atol=1e-300)


def _design(n: int = 30, m: int = 12, seed: int = 1) -> tuple[np.ndarray, list[int], list[int]]:
    """Whitened Jacobian: 3 base columns and m orthogonal candidate columns (orthogonal to the base)."""
    Q, _ = np.linalg.qr(np.random.default_rng(seed).normal(size=(n, 3 + m)))
    return Q, [0, 1, 2], list(range(3, 3 + m))


def test_independent_candidates_give_the_sidak_correction():
    """m orthogonal 1-dof candidates: P(min p <= p) = 1 - (1 - p)^m (the exact family-wise p)."""
    J, base, cands = _design()
    null = min_p_null([J], base, [([c], 1, False) for c in cands], draws=40000)
    for p in (1e-3, 1e-2, 5e-2):
        want = 1 - (1 - p) ** len(cands)
        assert null.adjust(p) == pytest.approx(want, rel=4 / np.sqrt(40000 * want))


def test_overlapping_candidates_cost_less_than_bonferroni():
    """A column, the same column twice, and it nested in pairs: one test, not many."""
    J, base, cands = _design(m=2)
    a, b = cands
    family = [([a], 1, False), ([a], 1, False), ([a, b], 2, False), ([b], 1, False)]
    null = min_p_null([J], base, family, draws=40000)
    p = 1e-3
    assert null.adjust(p) < 0.8 * p * len(family)  # Bonferroni says 4e-3; the overlap makes it ~2.8e-3
    assert null.adjust(p) > p  # but more than one test


def test_columns_in_the_base_model_carry_no_evidence():
    """A candidate column inside the current model's span removes nothing: the null ignores it."""
    J, base, cands = _design(m=1)
    inside = J[:, :3] @ np.array([1.0, -2.0, 0.5])
    J2 = np.column_stack([J, inside])
    null = min_p_null([J2], base, [([cands[0]], 1, False), ([J2.shape[1] - 1], 1, False)], draws=20000)
    assert null.adjust(1e-2) == pytest.approx(1e-2, rel=0.25)


def test_the_null_is_reproducible():
    J, base, cands = _design()
    fam = [([c], 1, False) for c in cands]
    assert np.array_equal(min_p_null([J], base, fam).min_p, min_p_null([J], base, fam).min_p)
