"""The magnetometer's axes in the accelerometer's frame, found without a hint.

Chips are mounted with their axes permuted and flipped: the AK8963 in an MPU-9250 reads mx along the
accelerometer's y, my along x and mz along -z, a 180 deg rotation. At still poses the angle between the
field and gravity is constant, so the right frame makes asin(a . P h) constant (a, h unit vectors):

  search       each of the 24 proper signed permutations P (right-handed to right-handed); the one whose
               dip angle scatters least wins (``search_axes``);
  closed form  a_k^T M h_k = c for every pose is linear in (M, c): the smallest right singular vector of
               the rows [vec(a_k h_k^T), -1] gives M = alpha R, c = alpha sin(dip); R is the rotation nearest
               M / alpha (Wahba's problem, by the SVD), alpha's sign the one that makes det R = +1
               (``closed_form``). It refines the search (the fit starts from it) and checks it.

A left-handed magnetometer frame (one axis wired inverted) makes the same dip scatter as its mirror image
with the dip's sign reversed: the dip alone cannot tell the two apart (the hemisphere's sign can).
"""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

AXIS_NAMES = ("x", "y", "z")


def _proper_signed_permutations() -> tuple[tuple[int, ...], ...]:
    out = []
    for perm in itertools.permutations(range(3)):
        for signs in itertools.product((1, -1), repeat=3):
            P = np.zeros((3, 3), int)
            for i, (j, sg) in enumerate(zip(perm, signs)):
                P[i, j] = sg
            if round(np.linalg.det(P)) == 1:
                out.append(tuple(int(v) for v in P.ravel()))
    return tuple(out)


#: The 24 rotations that map axes to axes: h_acc = P h_mag.
SIGNED_PERMUTATIONS = _proper_signed_permutations()


def axes_words(axes: tuple[int, ...]) -> str:
    """The mounting in words: "mx = ay, my = ax, mz = -az" (each magnetometer axis is the accelerometer's)."""
    P = np.array(axes, int).reshape(3, 3)
    parts = []
    for i in range(3):  # h_mag = P^T h_acc: row i of P^T is column i of P
        j = int(np.argmax(np.abs(P[:, i])))
        parts.append(f"m{AXIS_NAMES[i]} = {'-' if P[j, i] < 0 else ''}a{AXIS_NAMES[j]}")
    return ", ".join(parts)


def _unit(x: np.ndarray) -> np.ndarray:
    return x / np.maximum(np.linalg.norm(x, axis=1, keepdims=True), 1e-300)


def dip_angles(a: np.ndarray, h: np.ndarray) -> np.ndarray:
    """asin(a . h / |a||h|) per row [rad]."""
    return np.arcsin(np.clip(np.sum(_unit(a) * _unit(h), axis=1), -1.0, 1.0))


@dataclass(frozen=True)
class AxesCandidate:
    axes: tuple[int, ...]
    dip_scatter: float  #: standard deviation of the dip angle over the poses [rad]
    dip: float  #: its mean [rad]

    @property
    def words(self) -> str:
        return axes_words(self.axes)


@dataclass(frozen=True)
class AxesSearch:
    """All 24 candidates, best first, and the closed form's verdict."""

    ranked: tuple[AxesCandidate, ...]
    closed_form: "ClosedForm"

    @property
    def best(self) -> AxesCandidate:
        return self.ranked[0]

    @property
    def agrees(self) -> bool:
        """The closed form's rotation is nearest to the searched permutation."""
        return nearest_permutation(self.closed_form.rotation) == self.best.axes

    @property
    def margin(self) -> float:
        """Runner-up's dip scatter over the best's (how clearly the search decided)."""
        return self.ranked[1].dip_scatter / max(self.ranked[0].dip_scatter, 1e-300)


def search_axes(a: np.ndarray, h: np.ndarray) -> AxesSearch:
    """Rank the 24 mountings by the dip scatter of the poses' accelerometer ``a`` and field ``h`` (N x 3)."""
    hu = _unit(np.asarray(h, float))
    cands = []
    for axes in SIGNED_PERMUTATIONS:
        d = dip_angles(a, hu @ np.array(axes, float).reshape(3, 3).T)
        cands.append(AxesCandidate(axes, float(np.std(d)), float(np.mean(d))))
    cands.sort(key=lambda c: c.dip_scatter)
    return AxesSearch(tuple(cands), closed_form(a, h))


@dataclass(frozen=True)
class ClosedForm:
    rotation: np.ndarray  #: R with a . R h = sin(dip) at every pose, as nearly as the poses allow
    dip: float  #: [rad]
    conditioning: float  #: second-smallest over smallest singular value (large: well determined)


def closed_form(a: np.ndarray, h: np.ndarray) -> ClosedForm:
    """The rotation that holds the dip constant, in closed form (module docstring)."""
    au, hu = _unit(np.asarray(a, float)), _unit(np.asarray(h, float))
    rows = np.column_stack([np.einsum("ki,kj->kij", au, hu).reshape(-1, 9), -np.ones(len(au))])
    _, sv, Vt = np.linalg.svd(rows, full_matrices=False)
    v = Vt[-1]
    M, c = v[:9].reshape(3, 3), v[9]
    sign = 1.0 if np.linalg.det(M) >= 0 else -1.0  # M = alpha R with det R = +1: alpha takes det M's sign
    U, S, Wt = np.linalg.svd(sign * M)
    R = U @ np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Wt))]) @ Wt  # nearest rotation (Wahba)
    alpha = sign * float(np.mean(S))
    dip = float(np.arcsin(np.clip(c / alpha, -1.0, 1.0))) if alpha != 0 else 0.0
    cond = float(sv[-2] / max(sv[-1], 1e-300)) if sv.size > 1 else math.inf
    return ClosedForm(R, dip, cond)


def nearest_permutation(R: np.ndarray) -> tuple[int, ...]:
    """The signed permutation closest to a rotation (largest trace of P^T R)."""
    return max(SIGNED_PERMUTATIONS, key=lambda p: float(np.trace(np.array(p, float).reshape(3, 3).T @ R)))


def euler_angles(R: np.ndarray) -> tuple[float, float, float]:
    """(rx, ry, rz) with R = Rz(rz) Ry(ry) Rx(rx) (imucal.mag.model.rotation)."""
    ry = -math.asin(max(-1.0, min(1.0, float(R[2, 0]))))
    return math.atan2(float(R[2, 1]), float(R[2, 2])), ry, math.atan2(float(R[1, 0]), float(R[0, 0]))


def rotation_angle(R: np.ndarray) -> float:
    """The angle of a rotation [rad]."""
    return math.acos(max(-1.0, min(1.0, (float(np.trace(R)) - 1.0) / 2.0)))
