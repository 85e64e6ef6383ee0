"""Linearised chi-square of every pair of candidates: the two-effect screen of a discovery round.

Two comparable effects often hide each other: each alone removes little, or less than a relative
on more axes that absorbs part of both, while together they explain the data (scale_drift[x] +
bias_drift[y]: 811 -> 537 and 524 alone, 14 together). A greedy search that starts from the best
single candidates never meets the pair. In the Gauss-Newton picture of the round's screen the
pair's chi-square is exact for a linear model and needs no fit: with B an orthonormal basis of the
current model's whitened Jacobian columns, r_p = (I - B B^T) r and C_p = (I - B B^T) C the whitened
residual and candidate columns the current model leaves, a set S of columns removes
b_S^T G_S^+ b_S, with G = C_p^T C_p and b = C_p^T r_p. One Gram matrix over every candidate column
serves all pairs; each pair costs a k x k eigendecomposition (k <= 6), batched by size.
"""
from __future__ import annotations

from collections import defaultdict
from typing import Sequence

import numpy as np

from imucal.analysis.min_p import column_basis, screen_ids

#: Eigenvalues of G_S below this share of the largest squared column norm before projection are
#: directions the current model (or the other member) already spans: the pseudo-inverse drops them.
_RCOND = 1e-12


def pair_chi2(screens: Sequence[np.ndarray], rw: np.ndarray, base_cols: Sequence[int],
              members: Sequence[tuple[Sequence[int], bool | Sequence[int]]],
              pairs: Sequence[tuple[int, int]]) -> np.ndarray:
    """Linearised chi-square after adding each pair of ``members`` to the current model.

    ``screens``: whitened Jacobians at the current fit (one per screened shape value; the base
    columns are the same in each); ``rw``: whitened residual; ``members``: (columns a candidate
    adds, the screens it is profiled over: True for all, False for the first, or their indices);
    ``pairs``: indices into ``members``. A pair takes the best of its members' screens, as a single
    candidate does.
    """
    out = np.full(len(pairs), np.inf)
    if not len(pairs):
        return out
    B = column_basis(screens[0][:, list(base_cols)])
    rp = rw - B @ (B.T @ rw)
    r2 = float(rp @ rp)
    cols = sorted({c for m, _ in members for c in m})
    pos = {c: i for i, c in enumerate(cols)}
    own = np.zeros((len(members), len(screens)), bool)  # the screens of each member
    for k, (_, p) in enumerate(members):
        own[k, screen_ids(p, len(screens))] = True
    ends = np.asarray(pairs, int).reshape(-1, 2)
    uses = own[ends[:, 0]] | own[ends[:, 1]]  # a pair takes its members' screens
    # Pairs grouped by how many columns they add (a batch of k x k problems each), once for all screens.
    grouped: dict[int, tuple[list[int], list[list[int]]]] = defaultdict(lambda: ([], []))
    for q, (i, j) in enumerate(pairs):
        S = [pos[c] for c in (*members[i][0], *members[j][0])]
        grouped[len(S)][0].append(q)
        grouped[len(S)][1].append(S)
    groups = [(np.array(qs), np.array(S)) for qs, S in grouped.values()]
    for s, Jw in enumerate(screens):
        if not uses[:, s].any():
            continue  # the screens differ only in profiled members' columns
        C = Jw[:, cols]
        Cp = C - B @ (B.T @ C)
        G, b = Cp.T @ Cp, Cp.T @ rp
        size = np.sum(C * C, axis=0)  # a column the base model absorbs has |C_p|^2 << |C|^2
        for qs, S in groups:
            qs, S = qs[uses[qs, s]], S[uses[qs, s]]
            if not qs.size:
                continue
            w, V = np.linalg.eigh(G[S[:, :, None], S[:, None, :]])
            keep = w > _RCOND * size[S].max(axis=1, keepdims=True)
            c = np.einsum("nij,ni->nj", V, b[S])  # b_S in the eigenbasis of G_S
            red = np.sum(np.where(keep, c * c / np.where(keep, w, 1.0), 0.0), axis=1)
            out[qs] = np.minimum(out[qs], r2 - red)
    return out
