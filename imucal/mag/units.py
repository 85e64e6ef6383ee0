"""Magnetic field units and the field magnitude F a user gives.

A magnetometer reads in counts or in a field unit. F (the local field's magnitude, e.g. from the
WMM/IGRF for the place and date) may be given in the sensor's own unit or in any field unit below;
when both are field units it is converted, otherwise the calibrated field is in F's unit.
"""
from __future__ import annotations

import math
import re

from imucal.calibration.fields import SCALE_UNIT, is_unit
from imucal.errors import ImucalError

#: Field units and their factor to microtesla (SI: 1 gauss = 1e-4 T = 100 uT).
FIELD_UNITS = {"uT": 1.0, "nT": 1e-3, "mT": 1e3, "T": 1e6, "gauss": 100.0, "G": 100.0, "mG": 0.1,
               "mgauss": 0.1, "Oe": 100.0}
#: The micro prefix as typed (MICRO SIGN, GREEK SMALL LETTER MU); FIELD_UNITS writes it u.
MICRO = ("\u00b5", "\u03bc")


def ascii_micro(unit: object) -> object:
    """A unit typed with the micro sign (µT, μT) as FIELD_UNITS writes it (uT); anything else as given."""
    return "u" + unit[1:] if isinstance(unit, str) and unit[:1] in MICRO else unit


#: Earth's field magnitude spans about 22 to 67 uT (IGRF-13 main field, 2020, at the surface); a value
#: outside this range by more than this factor is refused as a unit mix-up.
EARTH_FIELD_UT = (22.0, 67.0)
EARTH_FIELD_SLACK = 3.0


#: A field magnitude given in the readings' own unit (counts) more than this factor off the readings' field (the
#: ellipsoid's mean radius) is refused: a sensor's scale error is a few per cent (tens on a poor board), so such
#: a value is in another unit (uT typed for counts) or a typing error, and would scale the calibrated field by it.
MAX_FIELD_RATIO = 10.0


def field_ratio_error(value: float, unit: str, readings: float, source: str | None = None) -> ImucalError | None:
    """The refusal of a field magnitude ``value`` in the readings' own ``unit`` (no field unit) that is more than
    MAX_FIELD_RATIO off the readings' field ``readings`` [unit]; None when within it."""
    ratio = value / readings if readings > 0 else math.inf
    if 1.0 / MAX_FIELD_RATIO <= ratio <= MAX_FIELD_RATIO:
        return None
    return ImucalError(f"field magnitude {value:g} {unit} is {ratio:.3g} times the readings' field (about "
                       f"{readings:.4g} {unit}): not the field in the readings' unit", file=source, field="mag.field",
                       fix="give the field with its unit and the readings' unit (e.g. --mag-field 48.2uT --mag-unit "
                           f"uT), or in the readings' own unit (about {readings:.4g})")


#: A magnetometer's unit as its model's name carries it (imucal.mag.model.LABEL_PATTERN, less "_" and "*": no units).
SENSOR_UNIT = re.compile(r"[A-Za-z0-9/^.()-]{1,32}\Z")


def is_sensor_unit(unit: object) -> bool:
    """A unit a magnetometer's readings (or its field) may be in: one its model's name carries, a raw unit the
    calibration file's reader takes (its scales' unit a unit too: imucal.calibration.fields), and the scales'
    unit when the field is fitted in it (unit/unit) a unit too; so calibrate writes no file apply refuses."""
    return (isinstance(unit, str) and SENSOR_UNIT.match(unit) is not None and is_unit(unit)
            and is_unit(SCALE_UNIT.format(raw=unit)) and is_unit(f"{unit}/{unit}"))


#: Readings in a field unit have scales near 1 there (soft iron: a few per cent, tens on a poor board): scales
#: beyond this factor of it mean the readings are in another unit than the one stated (a factor 10 or 100).
UNIT_SCALE_FACTOR = 2.0


def stated_unit_mismatch(raw_unit: str, field_unit: str, scale: float) -> str | None:
    """The field unit readings stated in ``raw_unit`` look like, from their scales' geometric mean ``scale``
    [raw_unit per field_unit]: None when it is near 1 field_unit in raw_unit (or either is no field unit), else
    the field unit whose conversion it is within UNIT_SCALE_FACTOR, or "" for none (counts)."""
    if raw_unit not in FIELD_UNITS or field_unit not in FIELD_UNITS or not scale > 0:
        return None
    if abs(math.log(scale / convert(1.0, field_unit, raw_unit))) <= math.log(UNIT_SCALE_FACTOR):
        return None
    near = min(FIELD_UNITS, key=lambda u: abs(math.log(scale / convert(1.0, field_unit, u))))
    return near if abs(math.log(scale / convert(1.0, field_unit, near))) <= math.log(UNIT_SCALE_FACTOR) else ""


def is_field_unit(unit: str) -> bool:
    return unit in FIELD_UNITS


def convert(value: float, unit: str, to: str) -> float:
    """``value`` in ``unit`` expressed in ``to`` (both field units)."""
    return value * FIELD_UNITS[unit] / FIELD_UNITS[to]


def field_magnitude(value: float, unit: str | None, sensor_unit: str, source: str | None = None
                    ) -> tuple[float, str]:
    """(F, the calibrated field's unit) from a magnitude the user gives.

    ``unit`` None: F is in the sensor's unit. A field unit beside a sensor in a field unit: F is converted
    to the sensor's unit; beside a sensor in counts: the calibrated field comes out in F's unit. A value
    in a field unit far outside Earth's range is refused (a unit mix-up, e.g. nT given as uT).
    """
    if not (isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) and value > 0):
        raise ImucalError(f"field magnitude {value!r} must be a positive number", file=source,
                          field="mag.field", fix="give the local field's magnitude, e.g. 48.2 uT (WMM for your place)")
    unit = unit or sensor_unit
    if unit not in FIELD_UNITS:
        if unit != sensor_unit:
            raise ImucalError(f"unknown field unit {unit!r}", file=source, field="mag.field_unit",
                              fix=f"use one of {', '.join(FIELD_UNITS)}")
        return float(value), unit
    ut = convert(value, unit, "uT")
    lo, hi = EARTH_FIELD_UT
    if not lo / EARTH_FIELD_SLACK <= ut <= hi * EARTH_FIELD_SLACK:
        raise ImucalError(f"field magnitude {value:g} {unit} ({ut:.4g} uT) is not Earth's field", file=source,
                          field="mag.field", fix=f"Earth's field is {lo:g} to {hi:g} uT: check the unit")
    if is_field_unit(sensor_unit):
        return convert(value, unit, sensor_unit), sensor_unit
    return float(value), unit
