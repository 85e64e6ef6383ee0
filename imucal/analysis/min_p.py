"""Family-wise p-values of one discovery round: the single-step min-p method over the candidates.

A round tries ~100 candidates (each term on each axis subset). Bonferroni (p * M) treats them as
unrelated, but they are strongly related: bias_temperature[x] is nested in bias_temperature[xy],
temperature and warm-up follow each other, ... so p * M overstates the multiplicity and costs
power near the threshold. The joint null distribution of the candidates' statistics is known in
the Gauss-Newton picture the screen already uses: at the current fit the whitened residual is
r = P e, with e ~ N(0, I) and P the projector off the current model's Jacobian columns, and a
candidate c removes d_c = |Q_c^T r|^2 of chi-square (Q_c an orthonormal basis of P J_c; for a
warm-up, the largest over the screened tau values). Its per-candidate p is
p_c = P(chi2(k_c) > d_c). The family-wise p of an observed p is P(min_c p_c <= p) under that
null (Westfall & Young 1993, single-step min-p), estimated from seeded draws of e; it controls
the chance of adding *any* effect to a model that needs none at ``alpha``, like Bonferroni, but
without paying for the candidates' overlap.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from imucal.solve.stats import chi2_sf_array

#: Draws of the null distribution: the family-wise p has a resolution of 1 / DRAWS and a relative
#: Monte-Carlo error of about 1 / sqrt(DRAWS * p) (10 % at p = 1e-3, 32 % at p = 1e-4).
DRAWS = 100000
#: Fixed seed: a discovery is reproducible to the bit.
SEED = 20240612
#: Draws per block of the null (memory: columns x _CHUNK doubles).
_CHUNK = 10000
#: Singular values below this (relative to the largest) are dependent columns.
_RANK_TOL = 1e-9


@dataclass(frozen=True)
class MinPNull:
    """The sorted null draws of min_c p_c for one round."""

    min_p: np.ndarray

    def adjust(self, p: float) -> float:
        """Family-wise p of a candidate p-value: P(min_c p_c <= p), (1 + hits) / (1 + draws)."""
        hits = int(np.searchsorted(self.min_p, p, side="right"))
        return (1 + hits) / (1 + self.min_p.size)


def column_basis(A: np.ndarray, scale: float | None = None) -> np.ndarray:
    """Orthonormal basis of the column space of A (SVD; directions with a singular value below
    _RANK_TOL x ``scale``, default the largest one, are dependent and dropped)."""
    if A.shape[1] == 0:
        return A
    U, s, _ = np.linalg.svd(A, full_matrices=False)
    ref = scale if scale is not None else (s[0] if s.size else 0.0)
    return U[:, s > _RANK_TOL * max(ref, 1e-300)]


def screen_ids(profiled: bool | Sequence[int], n: int) -> list[int]:
    """The screens a candidate is profiled over: all ``n`` (True), the first (False), or those listed."""
    if isinstance(profiled, bool):
        return list(range(n)) if profiled else [0]
    return list(profiled)


def min_p_null(screens: Sequence[np.ndarray], base_cols: Sequence[int],
               candidates: Sequence[tuple[Sequence[int], int, bool | Sequence[int]]], draws: int = DRAWS,
               seed: int = SEED) -> MinPNull:
    """Null distribution of min_c p_c over a round's candidates.

    ``screens``: whitened Jacobians (rows / sigma, one per screened shape value; the base columns
    are the same in each); ``candidates``: (columns it adds, k for its p, the screens it is profiled
    over: True for all, False for the first, or their indices) each, as the round scores them.
    """
    J0 = screens[0]
    B = column_basis(J0[:, list(base_cols)])
    blocks, ks = [], []
    for cols, k, profiled in candidates:
        for Jw in (screens[i] for i in screen_ids(profiled, len(screens))):
            A = Jw[:, list(cols)]
            Q = column_basis(A - B @ (B.T @ A), scale=float(np.linalg.norm(A)))  # what the base model leaves
            if Q.shape[1]:
                blocks.append(Q)
                ks.append(k)
    if not blocks:
        return MinPNull(np.ones(draws))
    Q = np.hstack(blocks)  # Q_c is orthogonal to the base: Q_c^T P e = Q_c^T e
    starts = np.cumsum([0] + [b.shape[1] for b in blocks[:-1]])
    ks_arr = np.array(ks)
    rng = np.random.default_rng(seed)
    out = []
    for m in np.diff(np.r_[0:draws:_CHUNK, draws]):
        d = np.add.reduceat((Q.T @ rng.standard_normal((Q.shape[0], m))) ** 2, starts, axis=0)
        # p_c falls with d_c at fixed k: only the largest d per k matters in each draw
        out.append(np.min([chi2_sf_array(d[ks_arr == k].max(axis=0), int(k)) for k in np.unique(ks_arr)], axis=0))
    return MinPNull(np.sort(np.concatenate(out)))


#: Draws of the null when only a mean is estimated (``search_gain``): its relative error ~1 % at 2,000.
GAIN_DRAWS = 2000


def search_gain(screens: Sequence[np.ndarray], base_cols: Sequence[int],
                candidates: Sequence[tuple[Sequence[int], bool | Sequence[int]]], draws: int = GAIN_DRAWS,
                seed: int = SEED) -> np.ndarray:
    """What a candidate profiled over its screens removes from pure noise, on average: E[max over its
    screens of |Q_c,s^T e|^2] under the null of ``min_p_null`` (Ye 1998's generalised degrees of freedom
    of a search). A candidate with one screen gains its column count; a shape searched over a grid gains
    more, and a ranking that prices it so does not favour the term with the wider search."""
    J0 = screens[0]
    B = column_basis(J0[:, list(base_cols)])
    E = np.random.default_rng(seed).standard_normal((J0.shape[0], draws))
    E -= B @ (B.T @ E)
    out = np.zeros(len(candidates))
    for k, (cols, profiled) in enumerate(candidates):
        best = np.zeros(draws)
        for i in screen_ids(profiled, len(screens)):
            A = screens[i][:, list(cols)]
            Q = column_basis(A - B @ (B.T @ A), scale=float(np.linalg.norm(A)))
            best = np.maximum(best, np.sum((Q.T @ E) ** 2, axis=0))
        out[k] = float(np.mean(best))
    return out
