"""Physical constants, each with its unit and source. Nothing else in imucal writes 9.8."""
from __future__ import annotations

import math

#: Standard gravity [m/s^2], 3rd CGPM (1901); ISO 80000-3.
STANDARD_GRAVITY = 9.80665

#: imu_tk's default local gravity [m/s^2] (imu_tk/calibration.h), used by its published outputs.
IMUTK_GRAVITY = 9.81744

# WGS84 normal gravity (Somigliana), NIMA TR8350.2, 3rd ed., Eq. 4-1 and 4-3.
WGS84_A = 6378137.0  #: semi-major axis [m]
WGS84_F = 1.0 / 298.257223563  #: flattening [-]
WGS84_GAMMA_E = 9.7803253359  #: normal gravity at the equator [m/s^2]
WGS84_K = 0.00193185265241  #: Somigliana constant [-]
WGS84_E2 = 0.00669437999013  #: first eccentricity squared [-]
WGS84_M = 0.00344978650684  #: omega^2 a^2 b / GM [-]

#: Nominal angle between sensor axes [rad].
RIGHT_ANGLE = math.pi / 2

#: Default relative tolerance on the axis angles: 90 deg +- 2 % (paper, Section 1).
DEFAULT_ANGLE_TOL = 0.02

#: Time units of a time column, with their factor to seconds ("auto": inferred from the stamps;
#: minutes are never inferred, only given or named when a run finds its poses only in minutes).
TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9, "min": 60.0}
TIME_UNIT_CHOICES = ("auto", *TIME_UNITS)
#: A gyroscope's raw units (data.gyro_unit): auto, counts (= raw: the scale is searched), deg/s, rad/s.
GYRO_UNIT_CHOICES = ("auto", "raw", "counts", "deg/s", "rad/s")

#: SI unit of the calibrated output.
SI_ACCEL_UNIT = "m/s^2"

#: SI unit of a calibrated angular rate, and the rate units a raw reading may already be in,
#: with their factor to rad/s (anything else, counts or LSB, needs the sensor's sensitivity).
SI_RATE_UNIT = "rad/s"
RATE_UNITS = {"rad/s": 1.0, "deg/s": math.pi / 180.0}
