"""The gyroscope's evidence: the motion segments between still poses, as the one fit sees them.

Per motion k, imu_tk's residual R_k^T u0 - u1 (three components; the one along u1 is of second order,
so two degrees of freedom per motion) after integrating the description's calibrated rate with the RK4
step (imucal.gyro.attitude); its noise the static directions' standard error and the angle random walk
of the gyro noise over the motion's duration. The observability check reads the geometry alone (unit
noise): a scale is determined when the motions turn gravity about its axis by an effective
``min_angle_deg`` (its parameter's threshold, 1/rad(min_angle_deg) of the nominal scale), and the refusal
names the axes and the rotations to add.
"""
from __future__ import annotations

import numpy as np

from imucal.errors import ImucalError
from imucal.gyro.attitude import SegmentSteps
from imucal.model.gyroscope import AXES, SCALE_NAMES
from imucal.model.sensor import SensorModel
from imucal.solve.evidence import JacobianEvidence
from imucal.solve.observability import Determination


class MotionEvidence(JacobianEvidence):
    """Motion segments (imucal.solve.evidence.FitEvidence) of one gyroscope description and set of free
    parameters; ``sigma_segment`` the noise of one residual component of each motion [rad]."""

    def __init__(self, model: SensorModel, free: tuple[str, ...], steps: SegmentSteps, sigma_segment: np.ndarray,
                 min_angle_deg: float, source: str | None = None) -> None:
        self.model, self.free, self.steps = model, tuple(free), steps
        self.n_free = len(self.free)
        self.sigma = np.repeat(np.asarray(sigma_segment, float), 3)
        self.dof = 2 * steps.n - self.n_free  # the residual's component along u1 is of second order
        self.min_angle_deg, self.source = float(min_angle_deg), source

    _r_key: bytes | None = None
    _r: np.ndarray = np.zeros(0)

    def residuals(self, pfree: np.ndarray, pfix: np.ndarray) -> np.ndarray:
        """The residuals at a point, kept: the fit asks for them again at the point before its Jacobian."""
        key = np.asarray(pfree, float).tobytes() + np.asarray(pfix, float).tobytes()
        if self._key == key:
            return self._rj[0]
        if self._r_key != key:
            self._r = self.steps.residuals(self.model, self.free, pfree, pfix).ravel()
            self._r_key = key
        return self._r

    def jacobian(self, pfree: np.ndarray, pfix: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        r, J = self.steps.jacobian(self.model, self.free, pfree, pfix)
        return r.ravel(), J

    def observability_rows(self, pfree: np.ndarray, pfix: np.ndarray) -> np.ndarray:
        """The Jacobian at unit noise: how far the motions turn gravity [rad] per unit of each parameter."""
        return self._at(pfree, pfix)[1]

    def require_determined(self, det: Determination) -> None:
        """Refuse, naming the axes, when the motions hardly turn gravity about some gyro axis.

        First every axis about which the motions turn gravity by less than ``min_angle_deg`` in all (the
        scale's predicted error with the others known, as an angle: root sum square over motions); then,
        with correlations, a null direction of the information or a scale whose standard error, as an
        angle, is below ``min_angle_deg``."""
        idx = [det.names.index(n) for n in SCALE_NAMES]
        with np.errstate(divide="ignore"):
            alone = self.min_angle_deg / det.alone[idx]  # effective rotation [deg] about each axis
        weak = [k for k in range(3) if not alone[k] >= self.min_angle_deg]
        if weak:
            _refuse_scales(weak, alone, self.min_angle_deg, self.source)
        null = det.null
        loads = np.abs(det.eigenvectors[idx][:, null])
        weak = [int(np.argmax(loads[:, i])) for i in range(loads.shape[1]) if loads[:, i].max() > 0.1]
        if null.any() and not weak:
            raise ImucalError("the gyro misalignment is not determined by these motions", file=self.source,
                              field="gyro.misalignment", fix="rotate about all three axes, each in several poses")
        eff = np.zeros(3)
        if not null.any():
            with np.errstate(divide="ignore"):
                eff = self.min_angle_deg / det.together[idx]
        k = weak[0] if weak else int(np.argmin(eff))
        if weak or not eff[k] >= self.min_angle_deg:
            _refuse_scales([k], eff, self.min_angle_deg, self.source)


def _refuse_scales(axes: list[int], eff: np.ndarray, min_deg: float, source: str | None) -> None:
    """The refusal naming every gyro axis in ``axes`` and the rotations to add."""
    ax = [AXES[k] for k in axes]
    which = ax[0] if len(ax) == 1 else ", ".join(ax[:-1]) + " and " + ax[-1]
    turned = "; ".join(f"about {AXES[k]} by an effective {eff[k]:.3g} deg" for k in axes)
    if len(ax) == 1:
        msg, fix = (f"the gyro {which} scale is not determined", f"add rotations about the {which} axis between "
                    f"still poses, with the {which} axis horizontal (e.g. 90 deg turns about {which})")
    else:
        msg, fix = (f"the gyro scale is not determined for the {which} axes", f"add rotations about the {which} "
                    f"axes between still poses, each with its axis horizontal (e.g. 90 deg turns about "
                    f"{', then '.join(ax)})")
    raise ImucalError(f"{msg}: the motions turn the gravity direction {turned} (need at least {min_deg:g} deg)",
                      file=source, field="gyro.scale", fix=fix)
