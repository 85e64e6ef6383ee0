"""What the text fields of a calibration file may look like (they reach generated C and reports)."""
from __future__ import annotations

import re

UNIT_PATTERN = re.compile(r"[A-Za-z0-9^.%()/ -]{0,40}\Z")
VERSION_PATTERN = re.compile(r"[0-9A-Za-z][0-9A-Za-z.+_-]{0,39}\Z")
NAME_PATTERN = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,39}\Z")
SHA256_PATTERN = re.compile(r"[0-9a-f]{64}\Z")

#: The sensor kinds a calibration file holds: the paper's model, and the gyroscope's
#: (imucal.calibration.gyro).
ACCELEROMETER, GYROSCOPE = "accelerometer", "gyroscope"
