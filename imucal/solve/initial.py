"""Initial guess from a linear (algebraic) ellipsoid fit.

At rest, (raw - s)^T H (raw - s) = g^2 with H = D G^-1 D, D = diag(1/b) (Proposition 2 with
Eq. theModel). Fitting the general quadric  x^T Q x + l^T x = 1  by linear least squares gives
the centre s = -Q^-1 l / 2 and H up to scale; then H^-1 = D^-1 G D^-1 yields in closed form
  b_i = sqrt((H^-1)_ii),   cos(angle_ij) = (H^-1)_ij / (b_i b_j).
With fewer than 9 distinct directions the general quadric is undetermined and the axis-aligned
quadric (6 unknowns: angles at pi/2) is used instead.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from imucal.constants import RIGHT_ANGLE
from imucal.errors import ImucalError


@dataclass(frozen=True)
class InitialGuess:
    s: np.ndarray  #: shifts [raw]
    b: np.ndarray  #: scales [raw per m/s^2]
    angles: np.ndarray  #: phi, psi, theta [rad]
    method: str  #: "ellipsoid-9" or "ellipsoid-6"


def ellipsoid_guess(means: np.ndarray, gravity: float, general: bool = True,
                    source: str | None = None) -> InitialGuess:
    """Algebraic ellipsoid fit to interval means (n x 3)."""
    x = np.asarray(means, float)
    n = x.shape[0]
    # Normalise for conditioning: centre and scale the data.
    c0 = x.mean(axis=0)
    sc = float(np.abs(x - c0).max()) or 1.0
    y = (x - c0) / sc
    X, Y, Z = y.T
    if general and n >= 9:
        M = np.column_stack([X * X, Y * Y, Z * Z, 2 * X * Y, 2 * X * Z, 2 * Y * Z, X, Y, Z])
    else:
        general = False
        if n < 6:
            raise ImucalError(f"only {n} static intervals; at least 6 orientations are needed even "
                              "for the 6-parameter model", file=source, field="intervals",
                              fix="hold the sensor still in more orientations (>= 9 distinct for 9 parameters)")
        M = np.column_stack([X * X, Y * Y, Z * Z, X, Y, Z])
    coef, _, rank, sv = np.linalg.lstsq(M, np.ones(n), rcond=None)
    if rank < M.shape[1] or sv[-1] < 1e-3 * sv[0]:
        # The points do not pin down a quadric (e.g. all directions in one plane).
        raise _degenerate(source)
    if general:
        a, bq, cq, d, e, f, gx, gy, gz = coef
        Q = np.array([[a, d, e], [d, bq, f], [e, f, cq]])
    else:
        a, bq, cq, gx, gy, gz = coef
        Q = np.diag([a, bq, cq])
    lvec = np.array([gx, gy, gz])
    try:
        centre = -0.5 * np.linalg.solve(Q, lvec)
    except np.linalg.LinAlgError:
        raise _degenerate(source) from None
    k = 1.0 + centre @ Q @ centre  # (y - c)^T Q (y - c) = k
    H_y = Q / k
    if not np.all(np.linalg.eigvalsh(H_y) > 0):
        raise _degenerate(source)
    # Back to raw units: y = (x - c0)/sc.
    s = c0 + sc * centre
    H = H_y / sc**2 * gravity**2  # (x - s)^T H (x - s) = g^2
    Hinv = np.linalg.inv(H)
    b = np.sqrt(np.diag(Hinv))
    cosm = Hinv / np.outer(b, b)
    angles = np.arccos(np.clip([cosm[0, 1], cosm[0, 2], cosm[1, 2]], -1, 1))
    if not general:
        angles = np.full(3, RIGHT_ANGLE)
    return InitialGuess(s=s, b=b, angles=np.asarray(angles), method="ellipsoid-9" if general else "ellipsoid-6")


def _degenerate(source: str | None) -> ImucalError:
    return ImucalError("the static intervals do not span an ellipsoid (orientations are degenerate, "
                       "e.g. all about one axis)", file=source, field="intervals",
                       fix="hold the sensor still in orientations spread over the whole sphere")
