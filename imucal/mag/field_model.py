"""The Earth's field at a place and date, from the IGRF (optional: ``pip install imucal-nlp[mag]``).

The International Geomagnetic Reference Field (IGRF-14, valid 1900-2030) through ``ppigrf`` (pure Python,
numpy and pandas; maintained with each IGRF generation). It gives the field's magnitude F for the fit, and
its inclination, whose sign tells the hemisphere: the fitted dip must have the opposite sign (the dip is
asin(a . h / |a||h|), a the accelerometer's upward specific force, the inclination is positive downward).
A dip of the wrong sign with a proper mounting means a left-handed magnetometer (one axis inverted),
which the dip's constancy alone cannot see (imucal.mag.frame).

Local anomalies (steel in a building, a car) move the local field by a few per cent from the model's:
give the measured value instead when there is one.
"""
from __future__ import annotations

import datetime as dt
import math
from dataclasses import dataclass

from imucal.errors import ImucalError

#: Years the IGRF-14 coefficients cover (definitive and secular-variation terms).
IGRF_YEARS = (1900, 2030)
#: Heights the model is meant for [m]: the surface to low orbit.
HEIGHT_RANGE_M = (-1000.0, 600_000.0)


@dataclass(frozen=True)
class EarthField:
    """The model's field at one place and date."""

    intensity_uT: float
    inclination_deg: float  #: positive downward (the geomagnetic convention)
    declination_deg: float  #: positive east of true north
    model: str

    @property
    def dip(self) -> float:
        """The model's value of the fit's ``dip`` [rad]: minus the inclination."""
        return -math.radians(self.inclination_deg)


@dataclass(frozen=True)
class Place:
    """Where and when the log was recorded: the field model's input."""

    latitude: float  #: [deg]
    longitude: float  #: [deg], east positive
    date: dt.date
    height: float = 0.0  #: [m] above sea level

    def field(self) -> EarthField:
        return earth_field(self.latitude, self.longitude, self.height, self.date)


def _check(latitude: float, longitude: float, height_m: float, date: dt.date) -> None:
    for name, v, lo, hi in (("latitude", latitude, -90.0, 90.0), ("longitude", longitude, -180.0, 360.0),
                            ("height", height_m, *HEIGHT_RANGE_M)):
        if not (isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and lo <= v <= hi):
            raise ImucalError(f"{name} {v!r} is outside {lo:g} .. {hi:g}", field=f"mag.place.{name}",
                              fix="latitude and longitude in degrees, height in metres")
    if not isinstance(date, dt.date) or not IGRF_YEARS[0] <= date.year <= IGRF_YEARS[1]:
        raise ImucalError(f"date {date!r} is outside the IGRF's {IGRF_YEARS[0]}-{IGRF_YEARS[1]}",
                          field="mag.place.date", fix="give the recording's date, e.g. 2024-05-17")


def earth_field(latitude: float, longitude: float, height_m: float, date: dt.date) -> EarthField:
    """F, inclination and declination from the IGRF at a place [deg, deg, m above sea level] and date."""
    _check(latitude, longitude, height_m, date)
    try:
        import ppigrf  # optional extra: imucal-nlp[mag]
    except ImportError:
        raise ImucalError("the field model needs the ppigrf package", field="mag.place",
                          fix="pip install imucal-nlp[mag], or give the field's magnitude (mag.field)") from None
    when = dt.datetime(date.year, date.month, date.day)
    east, north, up = (float(v.ravel()[0]) for v in ppigrf.igrf(longitude, latitude, height_m / 1000.0, when))
    horizontal = math.hypot(east, north)
    return EarthField(intensity_uT=math.sqrt(horizontal**2 + up**2) / 1000.0,
                      inclination_deg=math.degrees(math.atan2(-up, horizontal)),
                      declination_deg=math.degrees(math.atan2(east, north)),
                      model=f"IGRF-14 (ppigrf {_version()})")


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("ppigrf")
    except PackageNotFoundError:
        return "?"
