"""What the text fields of a calibration file may look like (they reach generated C, exports and
reports). Each rule is checked once where the value enters (a unit at ``data.unit`` / ``--unit``)
and again by the calibration file's reader, by the same function, so calibrate never writes a file
that apply, codegen or export refuse."""
from __future__ import annotations

import re

from imucal.errors import ImucalError, short

UNIT_PATTERN = re.compile(r"[A-Za-z0-9^.%()/ -]{0,40}\Z")
#: What UNIT_PATTERN admits, in words (messages).
UNIT_RULE = "letters, digits, ^ . % ( ) / - space; at most 40"
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


def check_unit(value: object, field: str, file: str | None = None,
               fix: str = "write e.g. counts, m/s^2 or g") -> str:
    """``value`` when it is a unit (is_unit); else the one-line refusal naming ``field``."""
    if not is_unit(value):
        raise ImucalError(f"{short(value)} is not a unit ({UNIT_RULE})", file=file, field=field, fix=fix)
    return value  # type: ignore[return-value]
