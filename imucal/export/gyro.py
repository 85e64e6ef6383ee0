"""The gyroscope part of the exports: imucal's rate map factored into each peer's convention, and
what a format cannot hold, measured.

imucal's gyroscope applies omega = C raw + c - D a [rad/s] in the accelerometer's output frame, a the
calibrated acceleration [m/s^2]: its map read through the one accessor of every calibrated sensor
(imucal.calibration.sensor.SensorCalibration.affine: C = A, D = -B; ``forward``). Forward, as the peers
write it:
    raw - s = P omega + F a,     P = C^-1 = B_g M_g,   F = P D = B_g G_s,   s = -C^-1 c = s_g.
Each peer's formula (cited where it is written, imucal.export.formats, kalibr, autopilot) is one
factoring of P, F and s:
  kalibr     measurement = M C_gyro_i omega + A C_gyro_i a + b  (M lower triangular, C_gyro_i a
             rotation): P = M C_gyro_i is an RQ factoring (QR of P^T), A = F C_gyro_i^T.
  madlab     gyr = R_g^-1 K_g^-1 (raw - K_ga a - b_g) in deg/s: K_g R_g = (pi/180) P with unit rows
             in R_g, K_ga = F, b_g = s.
  imutk      omega = T K (raw - b), T unit diagonal: K = diag(C), T = C K^-1, b = s; no G_s term,
             so imu_tk leaves D a, at |a| = g at most g ||D||_2 (RMS over directions g ||D||_F / sqrt 3).
  ardupilot, px4: omega = reading - offset, the reading in rad/s from the driver's own sensitivity
             k [raw per rad/s]: the offset s / k is all they hold (see offset_fit).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from imucal.calibration.sensor import SensorCalibration
from imucal.constants import RATE_UNITS


@dataclass(frozen=True)
class Forward:
    """raw - s = P omega + F a (module docstring); C, D the apply map's."""

    P: np.ndarray  #: [raw per rad/s]
    F: np.ndarray  #: [raw per m/s^2]
    s: np.ndarray  #: [raw]
    C: np.ndarray  #: [rad/s per raw]
    D: np.ndarray  #: [(rad/s) per (m/s^2)]


def forward(g: SensorCalibration) -> Forward:
    r = g.at_reference()  # bias(T) terms at T_ref: the peers hold none (imucal.export.tempcal writes them)
    a, f = r.affine(), r.forward()
    return Forward(P=f.P, F=f.F, s=f.s, C=a.A, D=-a.B)


def kalibr_factors(g: SensorCalibration) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(M, C_gyro_i, A) with P = M C_gyro_i (M lower triangular, positive diagonal when det P > 0,
    C_gyro_i a rotation) and A = F C_gyro_i^T."""
    f = forward(g)
    Q, U = np.linalg.qr(f.P.T)  # P^T = Q U  ->  P = U^T Q^T
    S = np.diag(np.where(np.diag(U) < 0, -1.0, 1.0))
    M, R = U.T @ S, S @ Q.T  # S S = I; M's diagonal positive
    if np.linalg.det(R) < 0:  # a reflection (det P < 0): move the sign into M's last column
        flip = np.diag([1.0, 1.0, -1.0])
        M, R = M @ flip, flip @ R
    M[np.triu_indices(3, 1)] = 0.0  # structural zeros of the triangular factor
    return M, R, f.F @ R.T


def imutk_factors(g: SensorCalibration) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(T, K, b) with T K = C, T unit diagonal, K diagonal."""
    C = forward(g).C
    K = np.diag(np.diag(C))
    return C @ np.linalg.inv(K), K, forward(g).s


#: mad-lab-fau/imucal's Ferraris output unit (FerrarisCalibration.OUT_GYR_UNIT).
MADLAB_GYR_UNIT = "deg/s"


def madlab_factors(g: SensorCalibration) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(K_g, R_g, b_g, K_ga) for an output in deg/s: K_g R_g = (pi/180) P, rows of R_g unit vectors."""
    f = forward(g)
    KR = f.P * RATE_UNITS[MADLAB_GYR_UNIT]  # raw per (deg/s)
    k = np.linalg.norm(KR, axis=1)
    return np.diag(k), KR / k[:, None], f.s, f.F


@dataclass(frozen=True)
class RateError:
    """max and RMS over uniformly distributed directions of |E u| x size, in deg/s."""

    max_deg_s: float
    rms_deg_s: float

    @classmethod
    def of(cls, E: np.ndarray, size: float) -> "RateError":
        # max over unit u of |E u| is the spectral norm; the mean of |E u|^2 over the sphere is ||E||_F^2 / 3
        return cls(math.degrees(size * float(np.linalg.norm(E, 2))),
                   math.degrees(size * float(np.linalg.norm(E, "fro")) / math.sqrt(3)))

    def text(self) -> str:
        return f"max {self.max_deg_s:.3g} deg/s, RMS {self.rms_deg_s:.3g} deg/s"


def gsens_residual(g: SensorCalibration, gravity: float) -> RateError:
    """What a format without a g-sensitivity term leaves at rest: D a at |a| = g, all directions."""
    return RateError.of(forward(g).D, gravity)


def gsens_sentence(what: str, g: SensorCalibration, gravity: float) -> str:
    return (f"{what} has no gyroscope g-sensitivity term: imucal's G_s leaves a rate error at |a| = g over all "
            f"directions of {gsens_residual(g, gravity).text()}")


#: The rate range the offset-only formats are judged over: |omega| = 1 rad/s in every direction.
RATE_RANGE = 1.0  # rad/s


@dataclass(frozen=True)
class OffsetFit:
    """What an offset-only gyro calibration (ArduPilot, PX4) holds of imucal's, and what it loses.

    The autopilot computes omega = reading - offset with reading = raw / k, k the driver's
    sensitivity [raw per rad/s]: exactly 1 or 180/pi for a calibration of readings in rad/s or
    deg/s; for raw counts the driver's datasheet value, which imucal cannot know, so the single
    sensitivity that best matches this calibration stands in (least squares, Frobenius). Errors
    are taken in the accelerometer's best-aligned frame R (a_peer = R a_imucal; the board rotation
    turns both sensors alike): e = R^T omega_peer - omega = (R^T P / k - I) omega + R^T F a / k.
    """

    offset: np.ndarray  #: s / k [rad/s]
    sensitivity: float  #: k [raw per rad/s]
    exact_unit: bool  #: k follows from the raw unit (rad/s, deg/s), not assumed
    rate: RateError  #: scale and misalignment lost, at |omega| = RATE_RANGE
    gsens: RateError  #: G_s lost, at rest with |a| = g

    def sentence(self, what: str, unit: str) -> str:
        k = (f"readings in {unit} (k = {self.sensitivity:.12g} {unit} per rad/s)" if self.exact_unit else
             f"the driver's readings in rad/s, assuming its sensitivity is k = {self.sensitivity:.12g} {unit} per "
             "rad/s (the single value that best fits this calibration; with your driver's, the offsets are s_g / k)")
        return (f"{what} holds only the gyroscope offset, for {k}: scale, misalignment and g-sensitivity are lost; "
                f"in the accelerometer's best-aligned frame the rate error at |omega| = {RATE_RANGE:g} rad/s over "
                f"all directions is {self.rate.text()}, and at rest with |a| = g over all directions "
                f"{self.gsens.text()}")


def offset_fit(g: SensorCalibration, R: np.ndarray, gravity: float) -> OffsetFit:
    """The offset-only model of ``g`` (OffsetFit), R the accelerometer's best-aligned rotation."""
    f = forward(g)
    RP = R.T @ f.P
    exact = g.raw_unit in RATE_UNITS
    k = 1.0 / RATE_UNITS[g.raw_unit] if exact else float(np.sum(RP * RP) / np.trace(RP))  # argmin ||RP/k - I||_F
    return OffsetFit(offset=f.s / k, sensitivity=k, exact_unit=exact,
                     rate=RateError.of(RP / k - np.eye(3), RATE_RANGE), gsens=RateError.of(f.F / k, gravity))

