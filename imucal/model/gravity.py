"""Local gravity from latitude and height: WGS84 normal gravity."""
from __future__ import annotations

import math

from imucal.constants import (WGS84_A, WGS84_E2, WGS84_F, WGS84_GAMMA_E, WGS84_K, WGS84_M)
from imucal.errors import ImucalError


def normal_gravity(latitude_deg: float, height_m: float = 0.0) -> float:
    """Normal gravity [m/s^2] on the WGS84 ellipsoid at geodetic latitude and ellipsoidal height.

    Somigliana's closed form (NIMA TR8350.2 Eq. 4-1) with the second-order height
    correction (Eq. 4-3).

    Args:
        latitude_deg: geodetic latitude [deg], -90 to 90.
        height_m: height above the ellipsoid [m].

    Returns:
        Normal gravity [m/s^2].
    """
    if not -90.0 <= latitude_deg <= 90.0 or not math.isfinite(latitude_deg):
        raise ImucalError(f"latitude {latitude_deg} is outside [-90, 90] degrees",
                          field="gravity.latitude", fix="give the geodetic latitude in degrees")
    if not math.isfinite(height_m) or not -1.0e4 < height_m < 1.0e5:
        raise ImucalError(f"height {height_m} m is not a plausible ellipsoidal height",
                          field="gravity.height", fix="give the height above the ellipsoid in metres")
    s2 = math.sin(math.radians(latitude_deg)) ** 2
    g0 = WGS84_GAMMA_E * (1.0 + WGS84_K * s2) / math.sqrt(1.0 - WGS84_E2 * s2)
    h = height_m
    return g0 * (1.0 - 2.0 / WGS84_A * (1.0 + WGS84_F + WGS84_M - 2.0 * WGS84_F * s2) * h
                 + 3.0 * h * h / WGS84_A**2)
