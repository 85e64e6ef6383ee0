"""The one covariance routine, for every sensor and every evidence (lmfit computes uncertainties in one
routine for every minimiser): the inverse of the weighted Gauss-Newton matrix, from any R factor of it."""
from __future__ import annotations

import numpy as np


def unscaled_covariance(Jw: np.ndarray, rcond: float = 1e-12) -> np.ndarray:
    """(Jw^T Jw)^-1 by the SVD of the column-equilibrated Jacobian.

    ``Jw`` may be the weighted Jacobian itself or any R with R^T R = Jw^T Jw (the block QR of
    imucal.solve.least_squares): both have the same column norms and singular values.

    Columns are divided by their norms first, so the result does not depend on the units of
    the parameters (a shift in counts x 1e12 and an angle in rad differ by 1e15 in scale, and a
    cut relative to the largest singular value would drop the small columns). Directions the
    data do not determine (relative singular value below ``rcond``) get zero variance here and
    are named by imucal.solve.observability before any fit.
    """
    c = np.linalg.norm(Jw, axis=0)
    c = np.where(c > 0, c, 1.0)
    _, sv, Vt = np.linalg.svd(Jw / c, full_matrices=False)
    inv = np.where(sv > sv.max(initial=0) * rcond, 1.0 / np.maximum(sv, 1e-150) ** 2, 0.0)  # (no overflow)
    return ((Vt.T * inv) @ Vt) / np.outer(c, c)
