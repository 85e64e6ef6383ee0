"""One evaluation formula for every tool: the gravity-direction error of each motion segment.

Given calibrated rates [rad/s] (whoever calibrated them) and the gravity directions measured at
the two ends of each segment, integrate the rate with imu_tk's quaternion RK4 step and report the
angle between the carried start direction R^T u0 and the measured end direction u1 [deg]. The
increments and their products are the fit's own (imucal.gyro.attitude, numpy generated from the
CasADi model); tests/test_gyro.py pins them to an independent numpy integration.
"""
from __future__ import annotations

import numpy as np

from imucal.gyro.attitude import rate_directions
from imucal.gyro.segments import Segments


def direction_errors_deg(t: np.ndarray, rate: np.ndarray, segments: Segments) -> np.ndarray:
    """Angle [deg] between R^T u0 and u1 for every segment (rate in rad/s, any calibration)."""
    return rate_directions(np.asarray(t, float), np.asarray(rate, float), segments)


def rms(x: np.ndarray) -> float:
    """Root mean square of per-segment errors."""
    return float(np.sqrt(np.mean(np.square(x))))
