"""What the text fields of a calibration file may look like (they reach generated C, exports and
reports). Each rule is checked once where the value enters (a raw unit at ``data.unit`` / ``--unit``)
and again by the calibration file's reader, by the same function, so calibrate never writes a file
that apply, codegen or export refuse."""
from __future__ import annotations

import re

from imucal.errors import ImucalError, short

UNIT_PATTERN = re.compile(r"[A-Za-z0-9^.%()/ -]{0,40}\Z")
#: What UNIT_PATTERN admits, in words (messages).
UNIT_RULE = "letters, digits, ^ . % ( ) / - space; at most 40"
#: The scales' unit, the longest a raw unit begets (imucal.model.parameters.base_parameters; an
#: effect's coefficient adds at most /degC^3): a raw unit must leave it a unit too.
SCALE_UNIT = "{raw}/(m/s^2)"
#: Longest raw unit: its scales' unit within UNIT_PATTERN's 40 characters.
MAX_RAW_UNIT = 40 - len(SCALE_UNIT.format(raw=""))
VERSION_PATTERN = re.compile(r"[0-9A-Za-z][0-9A-Za-z.+_-]{0,39}\Z")
NAME_PATTERN = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,39}\Z")
SHA256_PATTERN = re.compile(r"[0-9a-f]{64}\Z")
#: The characters of an ISO 8601 date and time (digits, - : . , + T W Z and the space of RFC 3339),
#: at most 64: Python's datetime.fromisoformat takes any character between date and time.
DATE_PATTERN = re.compile(r"[0-9][0-9TWZ:.,+ -]{0,63}\Z")

#: The sensor kinds a calibration file holds: the paper's model, and the gyroscope's
#: (imucal.calibration.gyro).
ACCELEROMETER, GYROSCOPE = "accelerometer", "gyroscope"


def is_unit(value: object) -> bool:
    """A unit as imucal writes and reads it: UNIT_PATTERN, no "//" (a C comment opener)."""
    return isinstance(value, str) and UNIT_PATTERN.match(value) is not None and "//" not in value


def check_raw_unit(value: object, field: str, file: str | None = None,
                   fix: str = "write e.g. counts, m/s^2 or g") -> str:
    """``value`` when it is a unit of raw readings: a unit whose scales' unit (SCALE_UNIT) is one
    too, so every parameter unit a calibration derives from it reads back; else the refusal."""
    if not (is_unit(value) and is_unit(SCALE_UNIT.format(raw=value))):
        raise ImucalError(f"{short(value)} is not a unit ({UNIT_RULE[:-2]}{MAX_RAW_UNIT}, not ending in /)",
                          file=file, field=field, fix=fix)
    return value  # type: ignore[return-value]


def check_unit(value: object, field: str, file: str | None = None,
               fix: str = "write e.g. counts, m/s^2 or g") -> str:
    """``value`` when it is a unit (is_unit); else the one-line refusal naming ``field``."""
    if not is_unit(value):
        raise ImucalError(f"{short(value)} is not a unit ({UNIT_RULE})", file=file, field=field, fix=fix)
    return value  # type: ignore[return-value]
