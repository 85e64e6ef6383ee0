"""The typed result of a gyroscope fit: values, standard errors, correlations, evidence."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from imucal.gyro.model import apply_rate, misalignment_entries
from imucal.solve.ipopt import CONVERGED


@dataclass(frozen=True)
class GyroResult:
    """Gyro calibration: omega = M_g^-1 (B_g^-1 (raw - s_g) - G_s a)  [rad/s, accelerometer frame]."""

    unit: str  #: raw gyro unit
    bias: np.ndarray  #: s_g (3,) [unit]
    bias_std: np.ndarray
    scale: np.ndarray  #: diag(B_g) (3,) [unit per rad/s]
    scale_std: np.ndarray
    misalignment: np.ndarray  #: M_g (3, 3), unit diagonal
    misalignment_std: np.ndarray  #: (3, 3), zero diagonal
    gsens: np.ndarray  #: G_s (3, 3) [(rad/s) per (m/s^2)], zero rows where not selected
    gsens_std: np.ndarray
    gsens_selected: np.ndarray  #: (3,) bool per gyro axis
    gsens_p_value: np.ndarray  #: (3,) likelihood-ratio test per axis
    names: tuple[str, ...]  #: free parameters of the rotation fit
    correlation: np.ndarray  #: correlation matrix of ``names``
    segments: np.ndarray  #: motion segment numbers used (k: between static intervals k and k+1)
    error_before_deg: np.ndarray  #: per segment, static bias and nominal scale only
    error_deg: np.ndarray  #: per segment, calibrated
    status: str
    iterations: int
    chi2: float
    dof: int
    redchi: float
    seconds: float  #: wall time of the fit
    lead_in_s: float = 0.0  #: [s] the segments started and ended this far inside the still poses

    @property
    def success(self) -> bool:
        """IPOPT converged (imucal.solve.ipopt.CONVERGED)."""

        return self.status in CONVERGED

    @property
    def uses_gsens(self) -> bool:
        return bool(np.any(self.gsens_selected))

    def apply(self, raw: np.ndarray, acc: np.ndarray | None = None) -> np.ndarray:
        """Calibrated rate [rad/s] of raw samples (N x 3 or (3,)); ``acc`` [m/s^2] needed with G_s."""
        if self.uses_gsens and acc is None:
            raise ValueError("this gyro calibration has a g-sensitivity: pass the calibrated acceleration")
        one = np.ndim(raw) == 1
        w = apply_rate(np.atleast_2d(raw), self.bias, self.scale, misalignment_entries(self.misalignment),
                       self.gsens if self.uses_gsens else None, None if acc is None else np.atleast_2d(acc))
        return w[0] if one else w

    @property
    def rms_direction_error_deg(self) -> dict[str, float]:
        return {"before": _rms(self.error_before_deg), "after": _rms(self.error_deg)}

    def correlations(self, threshold: float = 0.5) -> list[tuple[str, str, float]]:
        """Pairs of fitted parameters whose correlation exceeds ``threshold`` in size."""
        out = []
        for i in range(len(self.names)):
            for j in range(i + 1, len(self.names)):
                if abs(self.correlation[i, j]) > threshold:
                    out.append((self.names[i], self.names[j], float(self.correlation[i, j])))
        return out

    def to_dict(self) -> dict:
        """The JSON ``gyro`` object of issue 11."""
        return {
            "unit": self.unit, "bias": self.bias.tolist(), "scale": self.scale.tolist(),
            "misalignment": self.misalignment.tolist(), "gsens": self.gsens.tolist(),
            "gsens_selected": self.gsens_selected.tolist(), "gsens_p_value": self.gsens_p_value.tolist(),
            "std": {"bias": self.bias_std.tolist(), "scale": self.scale_std.tolist(),
                    "misalignment": self.misalignment_std.tolist(), "gsens": self.gsens_std.tolist()},
            "rms_direction_error_deg": self.rms_direction_error_deg,
            "fit": {"status": self.status, "iterations": self.iterations, "chi2": self.chi2, "dof": self.dof,
                    "redchi": self.redchi, "n_segments": int(self.segments.size)},
        }

    def report(self) -> str:
        """Parameters with standard errors, lmfit style, and the direction errors."""
        ax = "xyz"
        L = [f"gyro calibration (raw unit {self.unit}; omega = M_g^-1 (B_g^-1 (raw - s_g) - G_s a))"]
        for j in range(3):
            L.append(f"  s_{ax[j]} = {self.bias[j]:.6g} +/- {self.bias_std[j]:.2g} [{self.unit}]   "
                     f"b_{ax[j]} = {self.scale[j]:.6g} +/- {self.scale_std[j]:.2g} [{self.unit} per rad/s]")
        for i in range(3):
            for j in range(3):
                if i != j:
                    L.append(f"  m_{ax[i]}{ax[j]} = {self.misalignment[i, j]:+.5f} +/- {self.misalignment_std[i, j]:.2g}")
        for i in range(3):
            if self.gsens_selected[i]:
                row = ", ".join(f"{v:+.3g} +/- {s:.2g}" for v, s in zip(self.gsens[i], self.gsens_std[i]))
                L.append(f"  G_s row {ax[i]} [(rad/s)/(m/s^2)]: {row}  (p = {self.gsens_p_value[i]:.2g})")
            else:
                L.append(f"  G_s row {ax[i]}: not selected (p = {self.gsens_p_value[i]:.2g})")
        r = self.rms_direction_error_deg
        inside = f" (each from {self.lead_in_s:g} s inside its still poses)" if self.lead_in_s > 0 else ""
        L.append(f"  gravity-direction error over {self.segments.size} motions{inside}: "
                 f"rms {r['before']:.3f} deg before, "
                 f"{r['after']:.3f} deg after;  IPOPT {self.status}, {self.iterations} iterations, "
                 f"redchi {self.redchi:.3g}")
        for a, b, c in self.correlations():
            L.append(f"  correlation({a}, {b}) = {c:+.3f}")
        return "\n".join(L)




def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x)))) if np.size(x) else float("nan")
