"""The paper's sensor geometry, written once, symbolically, in CasADi (Sections 2-3).

  G     = Gram matrix of the unit axes e_i       Eq. (eq:12)
  Tbar  = G^-1                                  Remark 1
  E     = Tbar^orth (upper triangular)          Proposition 3, Eq. (eq:125)
  E^-T  = the Theorem's map from m to a_orth    lower triangular

Numerical evaluators (``gram_np``, ``gram_det_np``, ``frame_np``) are generated from the
symbolic source; nothing else in the package writes these formulas.
"""
from __future__ import annotations

from functools import lru_cache

import casadi as ca
import numpy as np


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
