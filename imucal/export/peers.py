"""Other tools' calibration conventions, converted to the paper's nine parameters.

Every peer model is affine, a = M (raw - o). Inverting, raw - o = M^-1 a, and row i of M^-1
is b_i e_i^T (Eq. theModel with Lemma 1: raw_i = s_i + b_i e_i . a). Hence
  s = o,  b_i = |row_i(M^-1)|,  e_i = row_i / b_i,  cos(angle_ij) = e_i . e_j.
The frame of a peer's output differs from the Theorem's by a rotation, which leaves |a| and
the nine parameters unchanged.
"""
from __future__ import annotations

import io

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from imucal.errors import ImucalError
from imucal.files.inputs import read_input_text


@dataclass(frozen=True)
class AffineCalibration:
    """a = M (raw - o): a peer's calibration, with the nine parameters it implies."""

    M: np.ndarray
    o: np.ndarray
    source: str = ""

    def apply(self, raw: np.ndarray) -> np.ndarray:
        return (np.asarray(raw, float) - self.o) @ self.M.T

    def nine_parameters(self) -> dict[str, float]:
        Minv = np.linalg.inv(self.M)
        b = np.linalg.norm(Minv, axis=1)
        e = Minv / b[:, None]
        ang = np.arccos(np.clip([e[0] @ e[1], e[0] @ e[2], e[1] @ e[2]], -1, 1))
        out = {f"s{i+1}": float(self.o[i]) for i in range(3)}
        out.update({f"b{i+1}": float(b[i]) for i in range(3)})
        out.update(dict(zip(("phi", "psi", "theta"), map(float, ang))))
        return out


def read_imutk_calib(path: str | Path) -> AffineCalibration:
    """imu_tk's .calib text: T (3x3), blank, K (3x3), blank, b (3 lines); a = T K (raw - b)."""
    try:
        nums = [float(x) for x in read_input_text(path, field='imu_tk calib').split()]
    except (OSError, ValueError) as exc:
        raise ImucalError(f"cannot read imu_tk calibration: {exc}", file=str(path), field="calib") from None
    if len(nums) != 21:
        raise ImucalError(f"expected 21 numbers (T, K, b), found {len(nums)}", file=str(path), field="calib")
    T = np.array(nums[:9]).reshape(3, 3)
    K = np.array(nums[9:18]).reshape(3, 3)
    return AffineCalibration(M=T @ K, o=np.array(nums[18:]), source=str(path))


def read_tomisuarez_params(path: str | Path) -> AffineCalibration:
    """tomisuarez2/ImuCalibration params_acc.csv: a_yz, a_zy, a_zx [rad], K (3) [m/s^2 per count],
    b (3) [counts]; a = T K (raw + b) with T = [[1, -a_yz, a_zy], [0, 1, -a_zx], [0, 0, 1]]."""
    try:
        v = np.loadtxt(io.StringIO(read_input_text(path, field="params")), delimiter=",").ravel()
    except (OSError, ValueError) as exc:
        raise ImucalError(f"cannot read: {exc}", file=str(path), field="params") from None
    if v.size != 9:
        raise ImucalError(f"expected 9 numbers, found {v.size}", file=str(path), field="params")
    a_yz, a_zy, a_zx = v[:3]
    T = np.array([[1, -a_yz, a_zy], [0, 1, -a_zx], [0, 0, 1]])
    return AffineCalibration(M=T @ np.diag(v[3:6]), o=-v[6:9], source=str(path))  # "+ b": offset is -b


def read_madlab_calibration(path: str | Path) -> AffineCalibration:
    """mad-lab-fau/imucal calibration JSON (accelerometer part): a = R_a^-1 K_a^-1 (raw - b_a)."""
    import json

    try:
        d = json.loads(read_input_text(path, field='calibration'))
        K, R, b = (np.asarray(d[k], float) for k in ("K_a", "R_a", "b_a"))
    except (OSError, ValueError, KeyError) as exc:
        raise ImucalError(f"cannot read mad-lab-fau calibration: {exc}", file=str(path), field="K_a/R_a/b_a") from None
    return AffineCalibration(M=np.linalg.inv(R) @ np.linalg.inv(K), o=b.ravel(), source=str(path))
