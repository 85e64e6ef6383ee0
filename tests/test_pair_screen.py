"""The two-effect screen: its linearised chi-square of a pair equals the least-squares fit of the
base columns plus the pair's columns, for every pair, with profiled members taking the best screen."""
from __future__ import annotations

import itertools

import numpy as np

from imucal.analysis.pair_screen import pair_chi2


def _direct(J: np.ndarray, r: np.ndarray, cols: list[int]) -> float:
    x, *_ = np.linalg.lstsq(J[:, cols], -r, rcond=None)
    return float(np.sum((r + J[:, cols] @ x) ** 2))


def test_pair_chi2_is_the_least_squares_fit_of_base_plus_pair():
    rng = np.random.default_rng(3)
    n, nb = 30, 9
    base = list(range(nb))
    # members: 1-3 columns each; member 2 is profiled (its columns differ between the screens)
    members = [([9], False), ([10, 11], False), ([12, 13, 14], True), ([15], False), ([16, 17], True)]
    J0 = rng.standard_normal((n, 18))
    screens = [J0]
    for _ in range(3):  # other shape values: only the profiled members' columns change
        J = J0.copy()
        J[:, [12, 13, 14, 16, 17]] = rng.standard_normal((n, 5))
        screens.append(J)
    r = rng.standard_normal(n) + J0[:, 10] * 3.0 + screens[2][:, 13] * 2.0
    pairs = list(itertools.combinations(range(len(members)), 2))
    got = pair_chi2(screens, r, base, members, pairs)
    for q, (i, j) in enumerate(pairs):
        use = screens if members[i][1] or members[j][1] else screens[:1]
        want = min(_direct(J, r, base + members[i][0] + members[j][0]) for J in use)
        assert abs(got[q] - want) < 1e-8 * max(1.0, want), (i, j, got[q], want)


def test_dependent_columns_do_not_break_the_screen():
    """A member that repeats a base column (or the other member) removes nothing more: the
    pseudo-inverse drops the dependent direction instead of dividing by zero."""
    rng = np.random.default_rng(4)
    J = rng.standard_normal((20, 6))
    J[:, 4] = J[:, 1]  # member 0 repeats a base column
    J[:, 5] = 2.0 * J[:, 3]  # member 2 repeats member 1
    r = rng.standard_normal(20)
    base = [0, 1, 2]
    got = pair_chi2([J], r, base, [([4], False), ([3], False), ([5], False)], [(0, 1), (1, 2), (0, 2)])
    assert np.all(np.isfinite(got))
    only3 = _direct(J, r, base + [3])
    assert abs(got[0] - only3) < 1e-8 and abs(got[1] - only3) < 1e-8 and abs(got[2] - only3) < 1e-8
    assert abs(_direct(J, r, base) - pair_chi2([J], r, base, [([4], False), ([1], False)], [(0, 1)])[0]) < 1e-8
