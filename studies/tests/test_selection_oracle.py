"""The selection oracle of studies/discover_study.py (issue 12): the reference that tells the
search's misses from the data's. Checked against least squares draw by draw."""
from __future__ import annotations

import importlib.util

import numpy as np

from studies.tests.helpers import study as study_program

_spec = importlib.util.spec_from_file_location(
    "discover_study", study_program("discover_study"))
study = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(study)


def _brute(signal, base, options, truth, penalty, seed, draws):
    """The same selection with one least-squares fit per candidate, block and draw."""
    rng = np.random.default_rng([seed, 7])
    Y = signal[:, None] + rng.standard_normal((signal.size, draws))
    hits = 0
    for d in range(draws):
        y = Y[:, d]
        rss0 = np.sum((y - base @ np.linalg.lstsq(base, y, rcond=None)[0]) ** 2)
        scores = []
        for _, _, k, blocks in options:
            gain = 0.0
            for C in blocks:
                A = np.hstack([base, C])
                gain = max(gain, rss0 - np.sum((y - A @ np.linalg.lstsq(A, y, rcond=None)[0]) ** 2))
            scores.append(gain - penalty * k)
        n, ax, _, _ = options[int(np.argmax(scores))]
        hits += (n, ax) == truth
    return hits / draws


def _problem(rng, strength):
    n = 60
    base = rng.standard_normal((n, 4))
    cols = rng.standard_normal((n, 5))
    shape = [cols[:, [3]], cols[:, [3]] + 0.6 * cols[:, [4]]]  # a term with a shape: one block per value
    options = [("a", (0,), 1, [cols[:, [0]]]), ("a", (0, 1), 2, [cols[:, [0, 1]]]),
               ("b", (0,), 1, [cols[:, [0]] + 0.5 * cols[:, [2]]]), ("w", (0,), 2, shape)]
    signal = strength * (cols[:, 0] + 0.3 * cols[:, 1]) / np.sqrt(n)
    return signal, base, options


def test_the_selection_oracle_is_least_squares_selection_draw_by_draw():
    rng = np.random.default_rng(3)
    for strength in (3.0, 6.0):
        signal, base, options = _problem(rng, strength)
        got = study.selection_oracle(signal, base, options, ("a", (0, 1)), (0.0, 2.0, 6.63), seed=11, draws=300)
        for p, share in got.items():
            assert share == _brute(signal, base, options, ("a", (0, 1)), p, 11, 300)
        assert got[0.0] > got[6.63]  # the second column is weak: a price per parameter drops it more often


def test_a_strong_term_without_close_relatives_is_always_selected():
    rng = np.random.default_rng(4)
    signal, base, options = _problem(rng, 60.0)
    assert study.selection_oracle(signal, base, options, ("a", (0, 1)), (2.0, 6.63), seed=1, draws=200) == {
        2.0: 1.0, 6.63: 1.0}


def test_each_coefficients_chi2_is_its_value_over_its_standard_error_squared():
    """--coefficient scales a case so the weakest coefficient is SNR standard errors: z_a^2 = c_a^2 / cov_aa."""
    rng = np.random.default_rng(5)
    base, cols = rng.standard_normal((50, 4)), rng.standard_normal((50, 3))
    cols[:, 1] += 0.9 * cols[:, 0]  # two correlated coefficients: each sees less than the sum
    c = np.array([0.8, -0.5, 0.3])
    A = np.hstack([base, cols])
    cov = np.linalg.inv(A.T @ A)[4:, 4:]
    got = study.coefficient_chi2(base, [cols[:, i] * c[i] for i in range(3)])
    np.testing.assert_allclose(got, c ** 2 / np.diag(cov), rtol=1e-9)
    total = cols @ c - base @ np.linalg.lstsq(base, cols @ c, rcond=None)[0]
    assert max(got) < np.sum(total ** 2)  # the term's lambda is more than any one coefficient's part


def test_a_separate_price_for_tau_prices_only_the_shape_parameters():
    """(penalty, price): coefficients at the penalty, each shape parameter at the price; at price ==
    penalty it is the uniform selection, at 0 the least-squares selection with tau free of charge."""
    rng = np.random.default_rng(6)
    signal, base, options = _problem(rng, 5.0)
    shapes = (0, 0, 0, 1)  # "w" has a shape parameter among its k = 2
    truth = ("w", (0,))
    signal = signal + 5.0 * (options[3][3][1][:, 0] - options[3][3][1][:, 0].mean()) / np.sqrt(60)
    got = study.selection_oracle(signal, base, options, truth, (6.63,), seed=2, draws=300, shapes=shapes,
                                 tau_prices=(0.0, 6.63))
    assert got[(6.63, 6.63)] == got[6.63]
    free = [(n, ax, k - s, b) for (n, ax, k, b), s in zip(options, shapes)]
    assert got[(6.63, 0.0)] == _brute(signal, base, free, truth, 6.63, 2, 300)
    assert got[(6.63, 0.0)] >= got[6.63]  # a cheaper tau can only help the term that has one


def test_a_warm_ups_coefficient_is_counted_in_standard_errors_with_its_tau_fitted(tmp_path):
    """--coefficient: a warm-up's tau is fitted beside its coefficients (as discover fits it), so its
    coefficients see less than with tau known; a term without a shape is unchanged; lambda stays
    quadratic in the size, so one reference case fixes the size."""
    from imucal.analysis.simulate import draw_effect_case

    path = str(tmp_path / "clean.csv")

    def lam(effect, seed, snr, known):
        case = draw_effect_case(seed, effect=effect, snr=snr, noise_mg=0.3)
        return study.visible_chi2(case, path, rel=False, weakest=True, tau_known=known)[0]

    fitted, known = lam("bias_warmup", 60001, 10.0, False), lam("bias_warmup", 60001, 10.0, True)
    assert fitted < 0.9 * known
    np.testing.assert_allclose(lam("bias_warmup", 60001, 20.0, False), 4 * fitted, rtol=1e-3)
    assert lam("bias_drift", 60001, 10.0, False) == lam("bias_drift", 60001, 10.0, True)
