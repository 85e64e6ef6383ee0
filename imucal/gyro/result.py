"""The typed result of a gyroscope fit: values, standard errors, correlations, evidence."""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from imucal.model.gyroscope import gyro_model
from imucal.model.parameters import Parameters
from imucal.solve.vectorize import apply_values
from imucal.gyro.segments import GapMotion
from imucal.gyro.still import NotStill, Stillness
from imucal.solve.misfit import ExcessResiduals, excess_residuals
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
    #: which static intervals the gyro showed still (imucal.gyro.still); None when not judged
    still: Stillness | None = None
    #: the motions left out because a gap of the time stamps lies inside them (imucal.gyro.segments)
    gapped: tuple[GapMotion, ...] = ()
    #: the description's named parameters as fitted (imucal.model.gyroscope)
    params: Parameters | None = None

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
        w = apply_values(gyro_model(), self.params.values(), raw, None if acc is None else np.atleast_2d(acc))
        return w[0] if one else w

    @property
    def excess(self) -> ExcessResiduals | None:
        """The residuals exceed the noise (the rule of every sensor's fit, imucal.solve.misfit), or None."""
        return excess_residuals(self.chi2, self.dof)

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
            "not_still": [] if self.still is None else [not_still_dict(r) for r in self.still.rejected],
            "gap_motions": [asdict(g) for g in self.gapped],
        }

    def report(self) -> str:
        """Parameters with standard errors, lmfit style, the direction errors and the poses not still
        for the gyro (written by imucal.report.gyro)."""
        from imucal.report.gyro import gyro_report  # report/ writes the words; it imports this module

        return gyro_report(self)


def not_still_dict(r: NotStill) -> dict:
    """A rejected interval as plain numbers and text (JSON, the calibration file)."""
    return {"interval": r.interval, "t_start": r.t_start, "t_end": r.t_end, "rate_deg_s": list(r.rate_deg_s or ()),
            "drift_deg_s": list(r.drift_deg_s or ()), "test": r.test.value, "p_value": r.p_value}


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x)))) if np.size(x) else float("nan")
