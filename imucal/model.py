"""The paper's sensor model, built once, symbolically, in CasADi.

Notation (shared/seed, Sections 2-3):
  raw_i = s_i + b_i * m_i            Eq. (theModel): shift s_i [raw], scale b_i [raw/(m/s^2)]
  m_i   = e_i . a                    Lemma 1: projection of the true acceleration on unit axis e_i
  G     = Gram matrix of the e_i     Eq. (eq:12): 1 on the diagonal, cos phi, cos psi, cos theta off it
  abar  = G^-1 m                     Lemma 2 / Remark 1 (Tbar = G^-1): affine coordinates
  |a|^2 = m . abar = m^T G^-1 m      Lemma 3 (a_nonorth) and Proposition 2
  E     = Tbar^orth (upper triangular, columns e_i in the frame f)    Proposition 3, Eq. (eq:125)
  a_orth = E abar = E^-T m           Theorem; E^-T is lower triangular, so the whole apply map is
                                     a lower-triangular matrix A = E^-T diag(1/b) and an offset -A s.
Exact trigonometry throughout: no small-angle approximation.

Effects (see imucal.effects) extend the shifts, the scales or the measured value with terms in
covariates such as temperature or time; the base model has none.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
from typing import Mapping, Sequence

import casadi as ca
import numpy as np

from .parameters import BASE_NAMES, Parameter, Parameters


class Effect:
    """A named physical effect: extra parameters and terms in the sensor model.

    Subclasses override ``shift_scale`` (to make s, b depend on covariates) and/or
    ``correct`` (to change the measured value m). ``key`` identifies the effect for caching.
    """

    name: str = "effect"
    covariates: tuple[str, ...] = ()

    def __init__(self, axes: Sequence[int] = (0, 1, 2)) -> None:
        self.axes = tuple(sorted(set(int(a) for a in axes)))

    @property
    def key(self) -> tuple:
        return (self.name, self.axes)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Effect) and self.key == other.key

    def __hash__(self) -> int:
        return hash(self.key)

    def __repr__(self) -> str:
        return f"{type(self).__name__}(axes={self.axes})"

    def parameters(self, base: Parameters) -> list[Parameter]:
        return []

    def shift_scale(self, s: list, b: list, cov: Mapping[str, ca.SX], p: Mapping[str, ca.SX]
                    ) -> tuple[list, list]:
        return s, b

    def correct(self, m: list, raw: ca.SX, cov: Mapping[str, ca.SX], p: Mapping[str, ca.SX]) -> list:
        return m


def gram(phi, psi, theta):
    """Gram matrix of the unit axes, Eq. (eq:12)."""
    cphi, cpsi, cth = ca.cos(phi), ca.cos(psi), ca.cos(theta)
    return ca.vertcat(ca.horzcat(1, cphi, cpsi), ca.horzcat(cphi, 1, cth), ca.horzcat(cpsi, cth, 1))


def gram_det(phi, psi, theta):
    """det G = 1 - cos^2 phi - cos^2 psi - cos^2 theta + 2 cos phi cos psi cos theta, Eq. (eq:12).

    The one place this determinant is written: Tbar, E, E^-T, the file checks and the
    generated C all take it from here.
    """
    cphi, cpsi, cth = ca.cos(phi), ca.cos(psi), ca.cos(theta)
    return 1 - cphi**2 - cpsi**2 - cth**2 + 2 * cphi * cpsi * cth


def tbar(phi, psi, theta):
    """Tbar = G^-1 in the paper's closed form (Remark 1): adj(G) / det G."""
    cphi, cpsi, cth = ca.cos(phi), ca.cos(psi), ca.cos(theta)
    den = -gram_det(phi, psi, theta)
    t12 = cphi - cth * cpsi
    t13 = cpsi - cphi * cth
    t23 = cth - cphi * cpsi
    return ca.vertcat(ca.horzcat(-ca.sin(theta) ** 2, t12, t13),
                      ca.horzcat(t12, -ca.sin(psi) ** 2, t23),
                      ca.horzcat(t13, t23, -ca.sin(phi) ** 2)) / den


def _frame_terms(phi, psi, theta):
    """cos phi, cos psi, sin phi, cos xi, cos eta of Eq. (eq:125).

    cos(eta) uses the corrected line cos eta = sqrt(1 - cos^2 xi - cos^2 psi) (the source prints
    "+ cos^2 psi"), which equals sqrt(det G) / sin phi.
    """
    cphi, cpsi, cth = ca.cos(phi), ca.cos(psi), ca.cos(theta)
    sphi = ca.sin(phi)
    cxi = (cth - cphi * cpsi) / sphi
    ceta = ca.sqrt(gram_det(phi, psi, theta)) / sphi
    return cphi, cpsi, sphi, cxi, ceta


def frame(phi, psi, theta):
    """E = Tbar^orth, Eq. (eq:125): columns are e_1, e_2, e_3 in the orthonormal frame f
    (f_1 = e_1, f_2 in the e_1 e_2 plane)."""
    cphi, cpsi, sphi, cxi, ceta = _frame_terms(phi, psi, theta)
    return ca.vertcat(ca.horzcat(1, cphi, cpsi), ca.horzcat(0, sphi, cxi), ca.horzcat(0, 0, ceta))


def frame_inverse_transpose(phi, psi, theta):
    """L = E^-T, lower triangular with structural zeros above the diagonal (Theorem: T^orth Tbar)."""
    cphi, cpsi, sphi, cxi, ceta = _frame_terms(phi, psi, theta)
    L = ca.SX(3, 3) if isinstance(phi, ca.SX) else ca.MX(3, 3)  # structural zeros above the diagonal
    L[0, 0] = 1
    L[1, 0] = -cphi / sphi
    L[1, 1] = 1 / sphi
    L[2, 0] = (cphi * cxi - cpsi * sphi) / (sphi * ceta)
    L[2, 1] = -cxi / (sphi * ceta)
    L[2, 2] = 1 / ceta
    return L


# --- numerical evaluators, generated from the symbolic geometry above ---------------------------
@lru_cache(maxsize=1)
def geometry_function() -> ca.Function:
    """angles[3] -> (G, det G, E, E^-T): the paper's geometry as one CasADi Function."""
    a = ca.SX.sym("angles", 3)
    return ca.Function("geometry", [a], [gram(a[0], a[1], a[2]), gram_det(a[0], a[1], a[2]),
                                         frame(a[0], a[1], a[2]), ca.densify(frame_inverse_transpose(a[0], a[1], a[2]))],
                       ["angles"], ["G", "det", "E", "L"])


def _geometry(angles, out: int) -> np.ndarray:
    """Output ``out`` of geometry_function for angles (..., 3), stacked over the leading axes."""
    a = np.asarray(angles, float)
    flat = a.reshape(-1, 3)
    n = flat.shape[0]
    f = geometry_function()
    res = np.asarray((f.map(n) if n > 1 else f)(flat.T)[out])
    if out == 1:
        return res.reshape(a.shape[:-1])
    return res.reshape(3, n, 3).transpose(1, 0, 2).reshape(*a.shape[:-1], 3, 3)


def gram_np(angles) -> np.ndarray:
    """G (Eq. eq:12) for angles (..., 3) [rad], from the CasADi source."""
    return _geometry(angles, 0)


def gram_det_np(angles) -> np.ndarray:
    """det G for angles (..., 3) [rad], from the CasADi source."""
    return _geometry(angles, 1)


def frame_np(angles) -> np.ndarray:
    """E (Eq. eq:125) for angles (..., 3) [rad], from the CasADi source."""
    return _geometry(angles, 2)


@dataclass(frozen=True)
class SensorModel:
    """The symbolic model with a fixed set of effects; CasADi functions are built once.

    Functions (all per sample; ``cov`` holds the covariates named in ``covariates``):
      measured(raw[3], cov[k], p[np]) -> m[3]          Eq. (theModel) plus effects
      accel(raw, cov, p)              -> a_orth[3]     Theorem
      norm(raw, cov, p)               -> |a|           Proposition 2 (m^T G^-1 m)
      residual(raw, cov, p, g)        -> |a| - g       the calibration condition g = a_nonorth
      linear_map(p)                   -> A[3x3], c[3]  a_orth = A raw + c (base model only)
    """

    effects: tuple[Effect, ...]
    names: tuple[str, ...]
    covariates: tuple[str, ...]
    functions: Mapping[str, ca.Function] = field(compare=False, repr=False)

    @property
    def name(self) -> str:
        if not self.effects:
            return "nakov-ivanov-9"
        return "nakov-ivanov-9+" + "+".join(f"{e.name}[{''.join('xyz'[a] for a in e.axes)}]"
                                            for e in self.effects)

    @property
    def is_affine(self) -> bool:
        return not self.effects

    def parameters(self, base: Parameters) -> Parameters:
        """Base parameters extended by each effect's parameters."""
        extra: list[Parameter] = []
        for e in self.effects:
            extra.extend(e.parameters(base))
        return base.extended(extra)

    def __getattr__(self, name: str) -> ca.Function:
        fns = object.__getattribute__(self, "functions")
        if name in fns:
            return fns[name]
        raise AttributeError(name)


def _build(effects: tuple[Effect, ...], names: tuple[str, ...]) -> dict:
    covs = tuple(sorted({c for e in effects for c in e.covariates}))
    raw = ca.SX.sym("raw", 3)
    cov = ca.SX.sym("cov", len(covs))
    p = ca.SX.sym("p", len(names))
    g = ca.SX.sym("g")
    pd = {n: p[i] for i, n in enumerate(names)}
    cd = {c: cov[i] for i, c in enumerate(covs)}
    s = [pd["s1"], pd["s2"], pd["s3"]]
    b = [pd["b1"], pd["b2"], pd["b3"]]
    for e in effects:
        s, b = e.shift_scale(s, b, cd, pd)
    m = [(raw[i] - s[i]) / b[i] for i in range(3)]  # Eq. (theModel)
    for e in effects:
        m = e.correct(m, raw, cd, pd)
    m = ca.vertcat(*m)
    phi, psi, theta = pd["phi"], pd["psi"], pd["theta"]
    abar = ca.mtimes(tbar(phi, psi, theta), m)  # Lemma 2
    norm = ca.sqrt(ca.dot(m, abar))  # Proposition 2: |a|^2 = m^T G^-1 m
    L = frame_inverse_transpose(phi, psi, theta)
    a_orth = ca.mtimes(L, m)  # Theorem
    fns = {
        "covariates": covs,
        "measured": ca.Function("measured", [raw, cov, p], [m], ["raw", "cov", "p"], ["m"]),
        "accel": ca.Function("accel", [raw, cov, p], [a_orth], ["raw", "cov", "p"], ["a"]),
        "norm": ca.Function("norm", [raw, cov, p], [norm], ["raw", "cov", "p"], ["norm"]),
        "residual": ca.Function("residual", [raw, cov, p, g], [norm - g],
                                ["raw", "cov", "p", "g"], ["r"]),
    }
    if not effects:
        A = ca.SX(3, 3)  # structural zeros stay zeros
        for i in range(3):
            for j in range(i + 1):
                A[i, j] = L[i, j] / b[j]  # A = E^-T diag(1/b): lower triangular
        c = -ca.mtimes(A, ca.vertcat(*s))
        fns["linear_map"] = ca.Function("linear_map", [p], [A, c], ["p"], ["A", "c"])
    return fns


@lru_cache(maxsize=64)
def _cached(effects_key: tuple, effects: tuple[Effect, ...]) -> SensorModel:
    from .parameters import base_parameters

    names = BASE_NAMES + tuple(p.name for e in effects
                               for p in e.parameters(base_parameters([0, 0, 0], [1, 1, 1])))
    fns = _build(effects, names)
    return SensorModel(effects, names, fns.pop("covariates"), fns)


def build_model(effects: Sequence[Effect] = ()) -> SensorModel:
    """The sensor model with the given effects; symbolic functions are built once per effect set."""
    effects = tuple(effects)
    return _cached(tuple(e.key for e in effects), effects)
