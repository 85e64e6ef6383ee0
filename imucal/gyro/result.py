"""What the gyroscope's evidence says beyond its parameters: a typed summary attached to the one result
(imucal.solve.fit.FitResult.summary), and the parameters seen as the model's arrays.

A gyroscope fit returns a FitResult like every sensor (values, standard errors, covariance, chi-square,
status); its motion segments add the direction errors before and after, which static intervals were
still poses, the lead-in, the motions left out at a gap and the still poses' g-sensitivity test
(``MotionSummary``). Words are written in imucal.report.gyro.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Mapping

import numpy as np

from imucal.calibration.sensor import SensorCalibration
from imucal.gyro.segments import GapMotion
from imucal.gyro.still import NotStill, Stillness
from imucal.model.gyroscope import BIAS_NAMES, GSENS_NAMES, MIS_NAMES, SCALE_NAMES, misalignment_matrix
from imucal.model.parameters import Parameters
from imucal.solve.fit import FitResult
from imucal.solve.misfit import ExcessResiduals, excess_residuals


@dataclass(frozen=True)
class MotionSummary:
    """The gyroscope's motion segments at the fit (FitResult.summary)."""

    unit: str  #: raw gyro unit
    segments: np.ndarray  #: motion segment numbers used (k: between still poses k and k+1)
    error_before_deg: np.ndarray  #: per segment: static bias and nominal scale only [deg]
    error_deg: np.ndarray  #: per segment, calibrated [deg]
    gsens_selected: np.ndarray  #: (3,) bool per gyro axis: its g-sensitivity row kept by the still poses' test
    gsens_p_value: np.ndarray  #: (3,) likelihood-ratio test per axis (imucal.gyro.gsens)
    seconds: float  #: wall time of the whole gyro fit [s]
    lead_in_s: float = 0.0  #: [s] the segments started and ended this far inside the still poses
    #: which static intervals the gyro showed still (imucal.gyro.still); None when not judged
    still: Stillness | None = None
    #: the motions left out because a gap of the time stamps lies inside them (imucal.gyro.segments)
    gapped: tuple[GapMotion, ...] = ()

    @property
    def rms_direction_error_deg(self) -> dict[str, float]:
        return {"before": _rms(self.error_before_deg), "after": _rms(self.error_deg)}


@dataclass(frozen=True)
class GyroArrays:
    """The gyroscope's named parameters as the model's arrays, with their standard errors:
    omega = M_g^-1 (B_g^-1 (raw - s_g) - G_s a), G_s = B_g^-1 H (imucal.model.gyroscope)."""

    bias: np.ndarray  #: s_g (3,) [raw unit]
    bias_std: np.ndarray
    scale: np.ndarray  #: diag(B_g) (3,) [raw unit per rad/s]
    scale_std: np.ndarray
    misalignment: np.ndarray  #: M_g (3, 3), unit diagonal
    misalignment_std: np.ndarray  #: (3, 3), zero diagonal
    gsens: np.ndarray  #: G_s (3, 3) [(rad/s) per (m/s^2)], zero rows where not selected
    gsens_std: np.ndarray  #: H's standard errors over the scale (the scale's own error neglected)
    H: np.ndarray  #: B_g G_s (3, 3) [raw unit per m/s^2]: the parameters gsens_xx .. gsens_zz

    @classmethod
    def of(cls, params: Parameters, std: Mapping[str, float]) -> "GyroArrays":
        v = params.value_dict()
        s = {n: float(std.get(n, float("nan"))) for n in params.names}
        vec = (lambda names, d: np.array([d[n] for n in names]))
        scale, H, H_std = vec(SCALE_NAMES, v), vec(GSENS_NAMES, v).reshape(3, 3), vec(GSENS_NAMES, s).reshape(3, 3)
        return cls(bias=vec(BIAS_NAMES, v), bias_std=vec(BIAS_NAMES, s), scale=scale, scale_std=vec(SCALE_NAMES, s),
                   misalignment=misalignment_matrix(vec(MIS_NAMES, v)),
                   misalignment_std=misalignment_matrix(vec(MIS_NAMES, s)) - np.eye(3),
                   gsens=H / scale[:, None], gsens_std=H_std / scale[:, None], H=H)


def arrays(res: FitResult) -> GyroArrays:
    """A gyroscope fit's parameters as the model's arrays."""
    return GyroArrays.of(res.params, res.std)


def motions(res: FitResult) -> MotionSummary:
    """A gyroscope fit's evidence summary."""
    if not isinstance(res.summary, MotionSummary):
        raise TypeError(f"a {res.kind} fit has no motion segments")
    return res.summary


def uses_gsens(res: FitResult) -> bool:
    """The fit holds a g-sensitivity (some row selected by the still poses' test)."""
    return bool(np.any(motions(res).gsens_selected))


def excess(res: FitResult) -> ExcessResiduals | None:
    """The residuals exceed the noise (the rule of every sensor's fit, imucal.solve.misfit), or None."""
    return excess_residuals(res.chi2, res.dof)


def to_dict(res: FitResult) -> dict:
    """The JSON ``gyro`` object of issue 11."""
    a, m = arrays(res), motions(res)
    return {
        "unit": m.unit, "bias": a.bias.tolist(), "scale": a.scale.tolist(), "misalignment": a.misalignment.tolist(),
        "gsens": a.gsens.tolist(), "gsens_selected": m.gsens_selected.tolist(),
        "gsens_p_value": m.gsens_p_value.tolist(),
        "std": {"bias": a.bias_std.tolist(), "scale": a.scale_std.tolist(), "misalignment": a.misalignment_std.tolist(),
                "gsens": a.gsens_std.tolist()},
        "rms_direction_error_deg": m.rms_direction_error_deg,
        "fit": {"status": res.status, "iterations": res.iterations, "chi2": res.chi2, "dof": res.dof,
                "redchi": res.redchi, "n_segments": int(m.segments.size)},
        "not_still": [] if m.still is None else [not_still_dict(r) for r in m.still.rejected],
        "gap_motions": [gap_dict(g) for g in m.gapped],
    }


def fit_section(res: FitResult) -> dict:
    """The gyroscope's fit statistics as its calibration file section keeps them."""
    d, m = to_dict(res), motions(res)
    return {**d["fit"], "rms_direction_error_deg": m.rms_direction_error_deg,
            "gsens_p_value": [float(v) for v in m.gsens_p_value],
            **({"not_still": d["not_still"]} if m.still and m.still.rejected else {}),
            **({"gap_motions": d["gap_motions"]} if m.gapped else {})}


def calibrated(res: FitResult) -> SensorCalibration:
    """The fitted gyroscope as one calibrated sensor of a Calibration."""
    return SensorCalibration(res.model, res.params, dict(res.std), motions(res).unit, fit_section(res))


def not_still_dict(r: NotStill) -> dict:
    """A rejected interval as plain numbers and text (JSON, the calibration file)."""
    return {"interval": r.interval, "t_start": r.t_start, "t_end": r.t_end, "rate_deg_s": list(r.rate_deg_s or ()),
            "drift_deg_s": list(r.drift_deg_s or ()), "test": r.test.value, "p_value": r.p_value}


def gap_dict(g: GapMotion) -> dict:
    """A motion left out at a gap as plain numbers (JSON, the calibration file)."""
    return asdict(g)


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x)))) if np.size(x) else float("nan")
