"""A magnetometer calibration's results as typed values (words are made in report/, never here).

Figures of merit, each before and after:
  field-norm residual   RMS of |h| - F over the samples, in % of the field; "before" the readings as read,
                        relative to their own mean magnitude; beside it the noise floor (the readings'
                        noise propagated to |h|)
  dip-angle scatter     standard deviation over the poses of asin(a . h / |a||h|) [deg]: as read, with the
                        hard and soft iron only (no rotation: the symmetric soft iron) and aligned (the
                        rotation fitted); beside it the floor the readings' noise alone gives
and the same per pose.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from imucal.mag.checks import FieldSteps, PoseOffset
from imucal.mag.evidence import Lag, Poses
from imucal.mag.fit import MagFitResult, SoftIronTest
from imucal.mag.field_model import EarthField
from imucal.mag.frame import AxesSearch, rotation_angle
from imucal.mag.model import permutation, vectorized
from imucal.model.parameters import Parameter, Parameters


#: The field model's inclination above which its sign is trusted for the handedness check [deg] (near the
#: magnetic equator a local anomaly can tip a field of a few degrees either way).
HANDEDNESS_MIN_DIP_DEG = 5.0


@dataclass(frozen=True)
class PoseFigures:
    """One pose: where it is in the log and its figures."""

    start: int
    end: int
    norm_before_pct: float  #: mean |raw| over the log's mean |raw|, minus one [%]
    norm_after_pct: float  #: mean (|h| - F) / F [%]
    dip_before_deg: float | None  #: the dip as read, minus its mean over the poses [deg]
    dip_unaligned_deg: float | None  #: hard and soft iron only, minus the fitted dip [deg]
    dip_after_deg: float | None  #: aligned, minus the fitted dip [deg]


@dataclass(frozen=True)
class Scatter:
    """One figure before and after, and the floor the readings' noise alone gives."""

    before: float
    after: float
    floor: float
    unaligned: float = math.nan  #: dip only: after hard and soft iron, before the rotation


@dataclass(frozen=True)
class MagReport:
    norm_pct: Scatter  #: RMS of |h| - F over the samples [% of the field]
    dip_deg: Scatter | None  #: standard deviation of the dip over the poses [deg]; None without accelerometer
    poses: tuple[PoseFigures, ...]


@dataclass(frozen=True)
class MagCalibration:
    """Everything a magnetometer calibration found."""

    fit: MagFitResult  #: the chosen fit (symmetric or full soft iron)
    symmetric: MagFitResult | None  #: no rotation beyond the axis permutation (None: no accelerometer)
    soft_iron: SoftIronTest | None  #: the test that chose
    axes: AxesSearch | None  #: the mounting found (None: no accelerometer, or given)
    lag: Lag | None
    poses: Poses | None  #: the poses of the dip rows
    steps: FieldSteps | None  #: a field that steps between poses
    report: MagReport
    raw_unit: str
    field_unit: str
    field_given: bool  #: F given by the user (else fitted, the scales' size held)
    excluded: tuple[PoseOffset, ...] = ()  #: poses whose field stood out, left out of the fit
    earth: EarthField | None = None  #: the field model's values at the user's place and date

    @property
    def soft_iron_at_bound(self) -> tuple[str, ...]:
        """The soft iron's angles (phi, psi, theta) on their bound (90 deg +- MAG_ANGLE_TOL), or within 1 % of
        its half-width (a fit stopped on its way there): a field distorted more than a board's soft iron, which
        the fit cannot follow."""
        def near(p: Parameter) -> bool:
            tol = 0.01 * (p.upper - p.lower) / 2
            return min(p.value - p.lower, p.upper - p.value) <= tol
        return tuple(n for n in ("phi", "psi", "theta") if near(self.params[n]))

    @property
    def left_handed(self) -> bool | None:
        """The fitted dip has the opposite sign of the field model's: the magnetometer's axes are probably
        left-handed (one inverted), which the dip's constancy cannot see (None: no model, no dip, or a
        field too near horizontal to tell)."""
        if self.earth is None or self.report.dip_deg is None or abs(self.earth.inclination_deg) < \
                HANDEDNESS_MIN_DIP_DEG:
            return None
        return (self.params["dip"].value > 0) != (self.earth.dip > 0)

    @property
    def params(self) -> Parameters:
        return self.fit.params

    @property
    def full_soft_iron(self) -> bool:
        """The chosen fit is the full 3x3 soft iron (by the test, or as the settings asked)."""
        return self.symmetric is not None and self.fit is not self.symmetric

    @property
    def misalignment(self) -> float:
        """The rotation beyond the symmetric soft iron [rad]: the angle of Q in the polar decomposition
        M = Q S of the soft iron in the magnetometer's permuted axes, M = P^T A (0 for the symmetric fit)."""
        M = permutation(self.fit.model).T @ self.linear_map()[0]
        U, _, Vt = np.linalg.svd(M)
        return rotation_angle(U @ Vt)

    def linear_map(self) -> tuple[np.ndarray, np.ndarray]:
        """(A, c) with h = A raw + c: the calibrated field in the accelerometer's frame."""
        A, c, _ = self.fit.model.affine(np.array(self.params.values(), float))  # SensorModel.affine
        return np.asarray(A, float), np.asarray(c, float).ravel()

    def apply(self, raw: np.ndarray) -> np.ndarray:
        """Calibrated field (N x 3) in the accelerometer's frame, from the model's CasADi map."""
        p = np.array(self.params.values(), float)
        return np.asarray(vectorized(self.fit.model, "field")(np.asarray(raw, float).T, p)[0]).T
