"""What a header's column names say: each column's role (t, ax .. mz, temp) and the unit it states.

Exporters name their columns their own way; these are read without a mapping (--columns), their
units taken from the names:
- imucal and imu_tk: ``t ax ay az gx gy gz temp mx my mz`` (acc_x, gyro_x, mag_x, ...); a unit in
  brackets or parentheses after any name: ``time (s)``, ``acc_x [m/s^2]``, ``temperature [degC]``;
- PX4 (ulog2csv, sensor_combined): ``timestamp``, ``accelerometer_m_s2[0..2]``, ``gyro_rad[0..2]``;
- ArduPilot (mavlogdump --types IMU): ``TimeUS``, ``AccX``, ``GyrX``, ``T`` (the IMU's temperature in
  degC) and ``I`` (which IMU: several interleaved are refused, the fix names the instance filter);
- EuRoC and Kalibr: ``#timestamp [ns]``, ``w_RS_S_x [rad s^-1]``, ``a_RS_S_x [m s^-2]``;
- ROS (``rostopic echo -p`` of sensor_msgs/Imu): ``%time``, ``field.angular_velocity.x`` (rad/s),
  ``field.linear_acceleration.x`` (m/s^2: REP 103's units);
- phyphox: ``Time (s)``, ``Acceleration x (m/s^2)``, ``Gyroscope x (rad/s)``;
- an accelerometer's axes alone: ``x, y, z`` or ``x (g)`` (phone apps, lab scripts), when no other
  column names the accelerometer;
- Xsens MT Manager: ``Acc_X``, ``Mag_X`` (``Gyr_X`` only mapped: below); Arduino MPU-6050 sketches:
  ``AcX``, ``GyX`` (their ``Tmp`` is the sensor's raw count, not degC: not read as a temperature).
A name is read as: an optional unit or axis index in brackets at its end, then words (split at
space, ``_``, ``.``, ``-``), the last word (or the last letter of a word) the axis.
"""
from __future__ import annotations

import re
from dataclasses import dataclass

from imucal.data.timebase import TIME_NAME_UNITS, time_column_name
from imucal.data.unit_names import ACCELERATION_UNITS, FIELD_UNITS, RATE_UNITS, TEMPERATURE_UNITS

#: Word stems of each sensor's axis columns (the words before the axis, joined by "_").
ACC_STEMS = ("a", "ac", "acc", "accel", "accelerometer", "acceleration", "linear_acceleration",
             "accelerometer_m_s2", "a_rs_s")
GYRO_STEMS = ("g", "gy", "gyr", "gyro", "gyroscope", "angular_velocity", "gyro_rad", "w", "omega", "w_rs_s")
#: Stems read only with the axis letter joined (ArduPilot's GyrX): mad-lab-fau's sessions name gyr_x
#: columns that hold concatenated segments, not one motion a gyroscope could be calibrated on (mapped, read).
JOINED_ONLY = ("gyr",)
MAG_STEMS = ("m", "mag", "magnetometer", "magnetic_field")
#: Stems that state their unit (PX4's field names; ROS's sensor_msgs/Imu fields, REP 103).
STEM_UNITS = {"accelerometer_m_s2": "m/s^2", "linear_acceleration": "m/s^2", "gyro_rad": "rad/s",
              "angular_velocity": "rad/s"}
#: ArduPilot's IMU message (a header with TimeUS): AccX.. in m/s^2, GyrX.. in rad/s (its log documentation).
ARDUPILOT_UNITS = {**{f"acc{a}": "m/s^2" for a in "xyz"}, **{f"gyr{a}": "rad/s" for a in "xyz"}}
TEMP_STEMS = ("temp", "temperature", "t_c", "imu_temp", "temp_c")
#: Raw readings (counts), a unit any sensor's column may state.
RAW_UNITS = ("counts", "count", "lsb", "raw", "adc")
#: Per sensor, the unit spellings a text header may state (imucal.data.unit_names, plus milli-g): only those
#: read as they are (factor 1, no offset); a text file's numbers are not converted.
SENSOR_UNITS = {"a": {**ACCELERATION_UNITS, "mg": ("mg", 1.0, 0.0)}, "g": RATE_UNITS, "m": FIELD_UNITS}
#: What a text header may state, in words (messages).
TEXT_UNITS = {"a": "m/s^2, g, mg or counts", "g": "rad/s, deg/s or counts", "m": "uT, nT, gauss, milligauss or counts"}

_SUFFIX = re.compile(r"^(?P<base>.*?)\s*[\[(](?P<inner>[^\[\]()]*)[\])]\s*$")


@dataclass(frozen=True)
class Name:
    """One header name, read: its role (None: none of ours) and the unit it states (None: none)."""

    role: str | None
    unit: str | None = None
    words: tuple[str, ...] = ()  #: the name's words (lower case), without unit or axis


def _is_index(text: str) -> bool:
    """An axis index in brackets (accelerometer_m_s2[0]): ASCII digits only, not "²" or another script's digits
    (which int() refuses or reads as a number the name does not write)."""
    return text.isascii() and text.isdigit()


def _axis_of(words: list[str], index: str | None) -> tuple[str | None, list[str]]:
    """The axis (x, y, z) and the words before it: an index [0..2], a last word x/y/z, or a last
    letter x/y/z after a known stem (AccX, gyrx, mx)."""
    if index is not None:
        return ("xyz"[int(index)] if int(index) < 3 else None), words
    if len(words) > 1 and words[-1] in ("x", "y", "z"):
        return (None if "_".join(words[:-1]) in JOINED_ONLY else words[-1]), words[:-1]
    if words and len(words[-1]) > 1 and words[-1][-1] in "xyz":
        head = [*words[:-1], words[-1][:-1]]
        if "_".join(head) in ACC_STEMS + GYRO_STEMS + MAG_STEMS:
            return words[-1][-1], head
    return None, words


def read_name(name: str) -> Name:
    """The role and unit a column name states (see the module's list of exporters)."""
    text = name.strip().strip("\"'").strip()
    unit = index = None
    m = _SUFFIX.match(text)
    if m:
        inner = m["inner"].strip()
        index, unit = (inner, None) if _is_index(inner) else (None, inner or None)
        text = m["base"]
    text = text.lower().lstrip("#%").strip()
    if text.startswith("field."):  # rostopic echo -p
        text = text[len("field."):]
    words = [w for w in re.split(r"[\s._\-]+", text) if w]
    unit_l = None if unit is None else unit.lower()
    is_time, time_unit = time_column_name(text)
    if is_time and index is None and (unit_l is None or unit_l in TIME_NAME_UNITS):
        return Name("t", time_unit if unit_l is None else TIME_NAME_UNITS[unit_l], tuple(words))
    if "_".join(words) in TEMP_STEMS and index is None:
        return Name("temp", unit, tuple(words))
    axis, stem_words = _axis_of(words, index)
    stem = "_".join(stem_words)
    if axis is None:
        return Name(None, unit, tuple(words))
    for kind, stems in (("a", ACC_STEMS), ("g", GYRO_STEMS), ("m", MAG_STEMS)):
        if stem in stems:
            return Name(kind + axis, unit if unit is not None else STEM_UNITS.get(stem), tuple(stem_words))
    return Name(None, unit, tuple(words))


def bare_axes(names: list[str]) -> dict[str, int]:
    """ax, ay, az -> column of a header that names an accelerometer's columns by the axis alone (``x, y, z``,
    ``x (g)``, ``X [m/s^2]``: phone apps, lab scripts), when those are its only accelerometer columns; none
    when a stated unit is not an acceleration's (``x (deg/s)``), an axis is named twice or one is missing."""
    read = [read_name(n) for n in names]
    if any(r.role in ("ax", "ay", "az") for r in read):
        return {}
    at: dict[str, int] = {}
    for i, r in enumerate(read):
        if r.role is None and r.words in (("x",), ("y",), ("z",)):
            axis = r.words[0]
            if axis in at or (r.unit is not None and sensor_unit("ax", r.unit) is None):
                return {}
            at[axis] = i
    return {f"a{a}": at[a] for a in "xyz"} if len(at) == 3 else {}


def sensor_unit(role: str, unit: str | None) -> str | None:
    """The unit a name states for a role's sensor, in imucal's spelling ("raw" for counts); None when none is
    stated, or it is one a text file is not read in (the caller names it)."""
    if unit is None:
        return None
    u = unit.strip().lower()
    if u in RAW_UNITS:
        return "raw"
    ours = SENSOR_UNITS[role[0]].get(u)
    return ours[0] if ours is not None and ours[1:] == (1.0, 0.0) else None


def is_celsius(unit: str) -> bool:
    """Whether a temperature column's stated unit is degrees Celsius (read as it is)."""
    return TEMPERATURE_UNITS.get(unit.strip().lower()) == ("degC", 1.0, 0.0)


def implied_unit(name: str, names: list[str]) -> str | None:
    """The unit a column's exporter implies without stating it: ArduPilot's IMU message (TimeUS in the
    header) logs AccX in m/s^2 and GyrX in rad/s."""
    if "timeus" in (n.strip().lower() for n in names):
        return ARDUPILOT_UNITS.get(name.strip().lower())
    return None


def is_unit_name(text: str) -> bool:
    """Whether ``text`` is a unit of time, acceleration, angular rate, temperature or field a name may state."""
    u = text.strip().lower()
    return u in TIME_NAME_UNITS or u in RAW_UNITS or u in TEMPERATURE_UNITS or any(u in t for t in SENSOR_UNITS.values())


def unit_meaning(text: str) -> tuple:
    """What a unit spelling means, to tell two spellings of one unit (m/s^2, m s^-2) from two units: (unit, factor,
    offset) from the tables a name's unit is read with; the lower-case text for one they do not hold."""
    u = text.strip().lower()
    if u in TIME_NAME_UNITS:
        return TIME_NAME_UNITS[u], 1.0, 0.0
    if u in RAW_UNITS:
        return "raw", 1.0, 0.0
    return next((t[u] for t in (*SENSOR_UNITS.values(), TEMPERATURE_UNITS) if u in t), (u,))


def without_unit(name: str) -> str:
    """A column name without the unit in brackets or parentheses at its end ("acc_x [m/s^2]" -> "acc_x")."""
    m = _SUFFIX.match(name.strip())
    return m["base"] if m and not _is_index(m["inner"].strip()) else name.strip()
