"""ArduPilot and PX4 accelerometer parameters: offset and diagonal scale, and what they lose.

Both autopilots correct each axis on its own, in the sensor frame, before rotating to the body:
  ArduPilot  libraries/AP_InertialSensor/AP_InertialSensor_Backend.cpp, _rotate_and_correct_accel:
             "accel -= offset; accel.x *= accel_scale.x" (y, z alike), then the board rotation;
             parameters INS_ACCOFFS_X/Y/Z [m/s^2] and INS_ACCSCAL_X/Y/Z.
  PX4        src/lib/sensor_calibration/Accelerometer.hpp, Correct():
             _rotation * (data - _thermal_offset - _offset).emult(_scale);
             parameters CAL_ACC0_XOFF..ZOFF [m/s^2] and CAL_ACC0_XSCALE..ZSCALE.
So a_peer = diag(k) (raw - o). The paper's model gives raw_i = s_i + b_i e_i . a (Eq. theModel),
hence o = s and k_i = 1/b_i make each axis read exactly its own projection e_i . a; what is lost
is the non-orthogonality of the axes. With a_ours = A (raw - s) (Theorem), a_peer = B a_ours,
B = diag(1/b) A^-1. A rotation between the frames is the board's orientation (AHRS_TRIM,
CAL_ACC0_ROT), not calibration, so the error is taken in the rotation R that best aligns them
(orthogonal Procrustes: the polar factor of B): d(u) = (R^T B - I) g u over unit directions u,
  max |d| = g ||R^T B - I||_2,   RMS |d| = g ||R^T B - I||_F / sqrt(3)  (uniform directions).
Temperature terms: the bias polynomial goes to INS_TCAL1_* and TC_A0_* exactly (imucal.export.tempcal);
the scale terms, which neither holds, are dropped with their error stated.

The gyroscope: both subtract an offset from the driver's reading [rad/s] in the sensor frame and
hold nothing else:
  ArduPilot  AP_InertialSensor_Backend::_rotate_and_correct_gyro: "gyro -= _imu._gyro_offset(instance)"
             (after the sensor orientation, before the board rotation); INS_GYROFFS_X/Y/Z
             (AP_InertialSensor.cpp: @Units: rad/s).
  PX4        src/lib/sensor_calibration/Gyroscope.hpp, Correct(): _rotation * (data - _thermal_offset
             - _offset); CAL_GYRO0_XOFF..ZOFF [rad/s].
The offset written is s_g / k, k the driver's sensitivity (imucal.export.gyro.OffsetFit); scale,
misalignment and g-sensitivity are lost, measured in the accelerometer's best-aligned frame R.

Units: both autopilots apply these numbers to their driver's reading in m/s^2 (INS_ACCOFFS @Units:
m/s/s; PX4 CAL_ACC0_XOFF @unit m/s^2), so a calibration of readings in c m/s^2 per raw unit (g, mg)
is written as offsets c s_i and scales 1/(c b_i) (READING_UNITS). A calibration whose unit is not
stated ("raw", the default label) is written as if its readings were m/s^2 only when its numbers are
ones an autopilot's own calibration accepts (PLAUSIBLE); a unit with no such factor (counts, LSB) is
refused, as is a stated unit whose numbers are not plausible (counts labelled m/s^2): an autopilot
would otherwise apply offsets in counts to readings in m/s^2.
Text: every comment line goes through imucal.export.escape (ArduPilot's line-length limit included).
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable

import numpy as np

from imucal import __version__
from imucal.calibration.frozen import Calibration
from imucal.constants import SI_ACCEL_UNIT, STANDARD_GRAVITY
from imucal.errors import ImucalError, short
from imucal.export.escape import ardupilot_comment, free_text, hash_comment
from imucal.export.formats import ExportOptions, Exported, affine, dropped_effects
from imucal.export.gyro import OffsetFit, offset_fit
from imucal.export import mag_autopilot, tempcal
from imucal.export.peers import AffineCalibration, ThermalOffset, _text_number, checked, checked_gyro
from imucal.files.inputs import read_input_text

AXES = ("X", "Y", "Z")
ARDUPILOT_OFFSETS = tuple(f"INS_ACCOFFS_{a}" for a in AXES)
ARDUPILOT_SCALES = tuple(f"INS_ACCSCAL_{a}" for a in AXES)
PX4_OFFSETS = tuple(f"CAL_ACC0_{a}OFF" for a in AXES)
PX4_SCALES = tuple(f"CAL_ACC0_{a}SCALE" for a in AXES)
ARDUPILOT_GYRO = tuple(f"INS_GYROFFS_{a}" for a in AXES)
PX4_GYRO = tuple(f"CAL_GYRO0_{a}OFF" for a in AXES)
#: QGroundControl's parameter file: MAV_PARAM_TYPE_REAL32 for a float parameter, _INT32 for an integer.
MAV_PARAM_TYPE_REAL32, MAV_PARAM_TYPE_INT32 = 9, 6
#: Raw units whose readings the autopilots' drivers would give in m/s^2, with the factor c [m/s^2 per
#: unit]; g is standard gravity, as the drivers convert it (ArduPilot GRAVITY_MSS, PX4 CONSTANTS_ONE_G).
READING_UNITS = {SI_ACCEL_UNIT: 1.0, "g": STANDARD_GRAVITY, "mg": STANDARD_GRAVITY / 1000.0}
#: The unit label of a recording whose unit was not given (imucal.data.spec.DataSpec.unit).
UNSTATED_UNIT = "raw"


@dataclass(frozen=True)
class Plausible:
    """Offsets and scales an autopilot's own accelerometer calibration accepts."""

    max_offset: float  #: [m/s^2]
    min_scale: float
    max_scale: float
    source: str

    def admits(self, offset: np.ndarray, scale: np.ndarray) -> bool:
        return bool(np.all(np.abs(offset) <= self.max_offset) and np.all(scale >= self.min_scale)
                    and np.all(scale <= self.max_scale))

    def text(self) -> str:
        return (f"|offset| <= {self.max_offset:g} m/s^2, scale {self.min_scale:g} to {self.max_scale:g}, "
                f"{self.source}")


#: ArduPilot's (libraries/AP_AccelCal/AccelCalibrator.cpp, accept_result: |offset| <= GRAVITY_MSS,
#: 0.8 <= diag <= 1.2), applied to PX4's parameters too: the same quantities of a MEMS sensor after
#: its driver's nominal scaling (PX4's own ranges are wider, up to a scale of 3, or absent).
PLAUSIBLE = Plausible(STANDARD_GRAVITY, 0.8, 1.2, "ArduPilot's AccelCalibrator::accept_result")


@dataclass(frozen=True)
class DiagonalFit:
    """The offset + diagonal-scale map written, and the error it leaves for this sensor."""

    offset: np.ndarray  #: o = s [raw unit]
    scale: np.ndarray  #: k = 1/b [(m/s^2) per raw unit]
    max_error: float  #: [m/s^2] over all directions at |a| = g
    rms_error: float  #: [m/s^2] over uniformly distributed directions at |a| = g
    angles_deg: tuple[float, float, float]  #: phi, psi, theta [deg], 90 for orthogonal axes
    rotation: np.ndarray  #: R, the best-aligned frame: a_peer = R a_imucal to first order

    def sentence(self, what: str) -> str:
        ang = ", ".join(f"{a:.3f}" for a in self.angles_deg)
        return (f"{what} holds no misalignment (angles phi, psi, theta = {ang} deg): the error this leaves "
                f"for this sensor, |a_imucal - a_{what.lower()}| over all directions at |a| = g in the best-aligned "
                f"frame, is max {self.max_error:.3g} m/s^2, RMS {self.rms_error:.3g} m/s^2")


def diagonal_fit(cal: Calibration) -> DiagonalFit:
    """Offset s, scale 1/b and the residual of the diagonal model (module docstring)."""
    A, s = affine(cal)
    b = cal.values[3:6]
    B = np.diag(1.0 / b) @ np.linalg.inv(A)  # a_peer = B a_ours
    U, _, Vt = np.linalg.svd(B)
    R = U @ Vt  # the polar factor of B
    D = R.T @ B - np.eye(3)
    g = float(cal.gravity)
    return DiagonalFit(offset=s, scale=1.0 / b, max_error=g * float(np.linalg.norm(D, 2)),
                       rms_error=g * float(np.linalg.norm(D, "fro")) / math.sqrt(3),
                       angles_deg=tuple(math.degrees(v) for v in cal.values[6:9]), rotation=R)


def gyro_fit(cal: Calibration) -> OffsetFit | None:
    """The offset-only gyroscope ArduPilot and PX4 hold, in the accelerometer's best-aligned frame."""
    return None if cal.gyro is None else offset_fit(cal.gyro, diagonal_fit(cal).rotation, cal.gravity)


def thermal(cal: Calibration) -> tempcal.TempPolynomial | None:
    """The bias polynomial in temperature to export, when the calibration has a bias term."""
    if not any(n in tempcal.BIAS_TERMS for n, _ in cal.effects):
        return None
    return tempcal.polynomial(cal)


def gyro_thermal(cal: Calibration) -> tempcal.TempPolynomial | None:
    """The gyroscope's bias polynomial in temperature [rad/s of the driver's reading: s(T) / k], when its
    description has a bias term (imucal.model.gyroscope); its range must be the accelerometer's (one per IMU)."""
    gfit = gyro_fit(cal)
    p = None if gfit is None else tempcal.sensor_polynomial(cal.gyro)
    if p is None:
        return None
    a = thermal(cal)
    if a is not None and not np.allclose([a.tmin, a.tmax], [p.tmin, p.tmax], rtol=0, atol=1e-9):
        raise ImucalError(f"the gyroscope's temperature range {p.tmin:.4g}..{p.tmax:.4g} degC is not the "
                          f"accelerometer's {a.tmin:.4g}..{a.tmax:.4g}: the autopilots hold one range per IMU",
                          field="gyroscope.fit.temperature_range",
                          fix="calibrate both sensors' temperature terms from one sweep (imucal discover)")
    k = gfit.sensitivity
    return replace(p, s_ref=p.s_ref / k, coeffs=p.coeffs / k)


def _gyro_thermal_note(cal: Calibration, what: str) -> list[str]:
    p = gyro_thermal(cal)
    if p is None:
        return []
    if what == "ArduPilot":
        return [f"gyroscope temperature: the bias terms are written exactly as INS_TCAL1_GYR* and INS_GYR1_CALTEMP "
                f"(INS_GYROFFS = the offset at T_ref = {p.tref:g} degC); ArduPilot measures INS_GYROFFS and "
                "INS_GYR1_CALTEMP again at each boot unless INS_GYR_CAL = 0, and the curve then corrects from the "
                "boot temperature"]
    return [f"gyroscope temperature: the bias terms are written exactly as TC_G_ENABLE and TC_G0_* (CAL_GYRO0_*OFF "
            f"= the offset at TC_G0_TREF = {p.tref:g} degC); set TC_G0_ID to the gyroscope's device id"]


def _thermal_notes(cal: Calibration, what: str) -> list[str]:
    """What happens to the temperature terms, and what else is dropped."""
    names = "INS_TCAL1_* and INS_ACC1_CALTEMP" if what == "ArduPilot" else "TC_A_ENABLE and TC_A0_*"
    p, notes = thermal(cal), []
    if p is not None:
        notes.append(f"temperature: the bias terms are written exactly as {names} over {p.tmin:.4g}..{p.tmax:.4g} "
                     f"degC ({p.range_note}; {what} holds the offset at the range's ends outside it); the offsets "
                     f"are s(T_ref = {p.tref:g} degC)")
    part = tempcal.polynomial(cal) if p is None else p
    if part is not None and (loss := tempcal.loss_sentence(part, what)):
        notes.append(loss)
    rest = tuple(e for e in cal.effects if e[0] not in (tempcal.BIAS_TERMS if p is not None else ()))
    return notes + _gyro_thermal_note(cal, what) + list(dropped_effects(replace(cal, effects=rest), attached=False) if rest else ())


def reading_factor(cal: Calibration, fit: DiagonalFit, what: str) -> float:
    """c [m/s^2 per raw unit] that turns this calibration into the autopilot's (module docstring);
    refused when no factor makes its numbers m/s^2 values the autopilot could hold."""
    unit = cal.raw_unit
    how = ("calibrate readings in m/s^2 or g and say so (--unit m/s^2 or --unit g, or data.unit in a run file); "
           "a calibration of counts goes to --format matrix or imutk, or to `imucal codegen`")
    if unit not in READING_UNITS and unit != UNSTATED_UNIT:
        raise ImucalError(f"input unit {short(unit)} is not an acceleration unit {what} can hold (m/s^2, or "
                          f"{', '.join(u for u in READING_UNITS if u != SI_ACCEL_UNIT)} converted)",
                          field="units.input", fix=how)
    c = READING_UNITS.get(unit, 1.0)
    p = thermal(cal)
    offset = (fit.offset if p is None else p.s_ref) * c
    if not PLAUSIBLE.admits(offset, fit.scale / c):
        got = (f"offsets {', '.join(f'{v:.4g}' for v in offset)} m/s^2 and scales "
               f"{', '.join(f'{v:.4g}' for v in fit.scale / c)}")
        said = ("is not stated ('raw'), and read as m/s^2 it gives" if unit == UNSTATED_UNIT
                else f"{short(unit)} gives")
        raise ImucalError(f"the input unit {said} {got}, outside what an autopilot's calibration accepts "
                          f"({PLAUSIBLE.text()})", field="units.input", fix=how)
    return c


def _notes(cal: Calibration, fit: DiagonalFit, what: str, units: str, c: float) -> tuple[str, ...]:
    notes = [fit.sentence(what)]
    gfit = gyro_fit(cal)
    if gfit is not None:
        notes.append(gfit.sentence(what, cal.gyro.raw_unit))
    notes += _thermal_notes(cal, what)
    if cal.raw_unit == UNSTATED_UNIT:
        notes.append(f"{what} applies {units} to its driver's readings in m/s^2 (offsets in m/s^2, scales "
                     f"near 1); this calibration's input unit is {cal.raw_unit!r}, so these numbers reproduce it "
                     f"only on readings in {cal.raw_unit}")
    elif c != 1.0:
        notes.append(f"{what} applies {units} to its driver's readings in m/s^2: this calibration's readings in "
                     f"{cal.raw_unit} are converted at {c:.10g} m/s^2 per {cal.raw_unit} (offsets c s_i, scales "
                     "1/(c b_i), temperature terms c times theirs)")
    return tuple(notes)


def _header(cal: Calibration, title: str, formula: list[str], notes: tuple[str, ...],
            comment: Callable[[str], list[str]]) -> list[str]:
    """The comment lines above the parameters, each through the format's ``comment`` (escape.py)."""
    src = free_text((cal.data or {}).get("file", "?"))
    lines = [f"{title}, exported by imucal {__version__} from a calibration of {src} ({cal.created or 'no date'})"]
    lines += formula + [f"NOTE: {n}." for n in notes]
    return [out for ln in lines for out in comment(ln)]


def _gyro_header(cal: Calibration, fit: OffsetFit | None, label: str, formula: str) -> list[str]:
    if fit is None:
        return []
    k = "" if fit.exact_unit else " (assumed: your driver's datasheet sensitivity replaces it)"
    return [f"Gyroscope ({formula}):", f"{label} = s_g / k [rad/s], the driver's sensitivity "
            f"k = {fit.sensitivity!r} {cal.gyro.raw_unit} per rad/s{k}."]


def _offset_formula(cal: Calibration, offsets: str, scales: str, c: float) -> str:
    if c == 1.0:
        return f"{offsets} = the shifts s_i [{cal.raw_unit}], {scales} = 1/b_i of the paper's model."
    return (f"{offsets} = c s_i [m/s^2], {scales} = 1/(c b_i) of the paper's model, c = {c!r} m/s^2 per "
            f"{cal.raw_unit}.")


def _values(cal: Calibration, fit: DiagonalFit, acc_names: tuple[str, ...], gyro_names: tuple[str, ...],
            c: float) -> list[tuple[str, float]]:
    p = thermal(cal)
    offset = fit.offset if p is None else p.s_ref  # with temperature terms: s at the reference temperature
    out = list(zip(acc_names, [*map(float, offset * c), *map(float, fit.scale / c)]))
    if p is not None:
        p = replace(p, s_ref=p.s_ref * c, coeffs=p.coeffs * c)  # offsets in m/s^2 of the reading
        out += tempcal.ardupilot_lines(p) if acc_names[0].startswith("INS_") else tempcal.px4_lines(p)
    gfit = gyro_fit(cal)
    if gfit is not None:
        out += list(zip(gyro_names, map(float, gfit.offset)))
    gp = gyro_thermal(cal)
    if gp is not None:  # the gyroscope's curve in the driver's rad/s; ArduPilot's range is the IMU's, written once
        out += (tempcal.ardupilot_lines(gp, "GYR", shared=p is None) if acc_names[0].startswith("INS_")
                else tempcal.px4_lines(gp, "G"))
    return out


def to_ardupilot(cal: Calibration, opts: ExportOptions) -> Exported:
    """An ArduPilot parameter file (NAME,VALUE lines, as Mission Planner and MAVProxy load)."""
    fit = diagonal_fit(cal)
    c = reading_factor(cal, fit, "ArduPilot")
    mag_head, mag_values, mag_notes = mag_autopilot.ardupilot(cal)  # the magnetometer's part, when it has one
    notes = _notes(cal, fit, "ArduPilot", "INS_ACCOFFS and INS_ACCSCAL", c) + mag_notes
    lines = _header(cal, "ArduPilot accelerometer" + (" and gyroscope" if cal.gyro else "") + " calibration", [
        "ArduPilot corrects each axis in the sensor frame (AP_InertialSensor_Backend.cpp,",
        "_rotate_and_correct_accel): a = (raw - INS_ACCOFFS) * INS_ACCSCAL, then rotates to the body.",
        _offset_formula(cal, "INS_ACCOFFS", "INS_ACCSCAL", c),
        *_gyro_header(cal, gyro_fit(cal), "INS_GYROFFS", "_rotate_and_correct_gyro: omega = reading - INS_GYROFFS, "
                      "reading = raw / k"), *mag_head], notes, ardupilot_comment)
    lines += [f"{n},{v!r}" for n, v in [*_values(cal, fit, ARDUPILOT_OFFSETS + ARDUPILOT_SCALES, ARDUPILOT_GYRO, c),
                                        *mag_values]]
    return Exported("\n".join(lines) + "\n", notes)


def to_px4(cal: Calibration, opts: ExportOptions) -> Exported:
    """A QGroundControl parameter file (vehicle, component, name, value, type; tab separated)."""
    fit = diagonal_fit(cal)
    c = reading_factor(cal, fit, "PX4")
    mag_head, mag_values, mag_notes = mag_autopilot.px4(cal)  # the magnetometer's part, when it has one
    notes = _notes(cal, fit, "PX4", "CAL_ACC0_*OFF and CAL_ACC0_*SCALE", c) + mag_notes + (
        "set CAL_ACC0_ID" + (" and CAL_GYRO0_ID" if cal.gyro else "") + " to your sensors' device ids (PX4 uses a "
        "calibration only for its device)",)
    lines = _header(cal, "PX4 accelerometer" + (" and gyroscope" if cal.gyro else "")
                    + " calibration (QGroundControl parameter file)", [
        "PX4 corrects each axis in the sensor frame (src/lib/sensor_calibration/Accelerometer.hpp,",
        "Correct()): a = rotation * ((raw - thermal_offset - CAL_ACC0_*OFF) .* CAL_ACC0_*SCALE).",
        _offset_formula(cal, "CAL_ACC0_*OFF", "CAL_ACC0_*SCALE", c),
        *_gyro_header(cal, gyro_fit(cal), "CAL_GYRO0_*OFF", "Gyroscope.hpp Correct(): omega = rotation * (reading - "
                      "thermal_offset - CAL_GYRO0_*OFF), reading = raw / k"), *mag_head], notes,
                    lambda t: [hash_comment(t)])
    lines.append("# Vehicle-Id\tComponent-Id\tName\tValue\tType")  # fixed text: QGroundControl's header
    lines += [f"1\t1\t{n}\t{v!r}\t{MAV_PARAM_TYPE_INT32 if isinstance(v, int) else MAV_PARAM_TYPE_REAL32}"
              for n, v in [*_values(cal, fit, PX4_OFFSETS + PX4_SCALES, PX4_GYRO, c), *mag_values]]
    return Exported("\n".join(lines) + "\n", notes)


# --- reading back -------------------------------------------------------------------------------
_NAME = re.compile(r"[A-Z][A-Z0-9_]{0,31}\Z")


def _params(pairs: list[tuple[int, str, str]], path: str, offsets: tuple[str, ...], scales: tuple[str, ...],
            gyro: tuple[str, ...], fmt: str) -> AffineCalibration:
    values: dict[str, float] = {}
    for line, name, tok in pairs:
        where = f"line {line}"
        if not _NAME.match(name):
            raise ImucalError(f"{short(name)} is not a parameter name", file=path, field=where,
                              fix="write NAME,VALUE with an upper-case name")
        if name in values:
            raise ImucalError(f"parameter {name} is given twice", file=path, field=where, fix="keep one")
        values[name] = _text_number(tok, path, name)
    missing = [n for n in offsets + scales if n not in values]
    if missing:
        raise ImucalError("missing", file=path, field=missing[0],
                          fix=f"the file needs {', '.join(offsets + scales)}")
    o = np.array([values[n] for n in offsets])
    k = np.array([values[n] for n in scales])
    out = replace(checked(np.diag(k), o, path, "/".join(scales), fmt), thermal=_thermal_in(values, path, fmt))
    held = [n for n in gyro if n in values]
    if not held:
        return out
    if len(held) != 3:
        raise ImucalError("missing", file=path, field=next(n for n in gyro if n not in values),
                          fix=f"give all of {', '.join(gyro)} or none")
    # omega = reading - offset, the reading in rad/s: what the file holds of a gyroscope
    return replace(out, gyro=checked_gyro(np.eye(3), np.array([values[n] for n in gyro]), np.zeros((3, 3)),
                                          path, gyro[0]))


#: ArduPilot's and PX4's defaults for a temperature parameter a file leaves out (their param tables).
_AP_DEFAULTS = {"INS_TCAL1_TMIN": 0.0, "INS_TCAL1_TMAX": 70.0, "INS_ACC1_CALTEMP": -300.0}
_PX4_DEFAULTS = {"TC_A0_TREF": 25.0, "TC_A0_TMIN": 0.0, "TC_A0_TMAX": 100.0}


def _thermal_in(values: dict[str, float], path: str, fmt: str) -> ThermalOffset | None:
    """The temperature offset the file enables (INS_TCAL1_ENABLE = 1, TC_A_ENABLE = 1), else None;
    parameters left out take the autopilot's defaults (coefficients 0)."""
    if fmt == "ardupilot":
        if values.get("INS_TCAL1_ENABLE", 0.0) != 1.0:
            return None
        v = {**_AP_DEFAULTS, **values}
        c = np.zeros((4, 3))
        for k in (1, 2, 3):
            c[k] = [v.get(f"INS_TCAL1_ACC{k}_{a}", 0.0) / tempcal.ARDUPILOT_SCALE for a in AXES]
        lo, hi, tc = v["INS_TCAL1_TMIN"], v["INS_TCAL1_TMAX"], v["INS_ACC1_CALTEMP"]
        origin, names = tempcal.ARDUPILOT_TREF, ("INS_TCAL1_TMIN", "INS_TCAL1_TMAX")
    else:
        if values.get("TC_A_ENABLE", 0.0) != 1.0:
            return None
        v = {**_PX4_DEFAULTS, **values}
        c = np.array([[v.get(f"TC_A0_X{k}_{i}", 0.0) for i in range(3)] for k in range(4)])
        lo, hi, tc, origin = v["TC_A0_TMIN"], v["TC_A0_TMAX"], None, v["TC_A0_TREF"]
        names = ("TC_A0_TMIN", "TC_A0_TMAX")
    if not lo <= hi:
        raise ImucalError(f"{lo:g} is above {names[1]} = {hi:g}", file=path, field=names[0],
                          fix="the temperature range's minimum must not exceed its maximum")
    return ThermalOffset(coeffs=c, origin=float(origin), tmin=float(lo), tmax=float(hi), t_cal=tc)


def _parameter_lines(path: str):
    """(line number, text) of every non-empty line of a parameter file, # comments removed."""
    for i, ln in enumerate(read_input_text(path, field="parameters").splitlines(), 1):
        ln = ln.split("#", 1)[0].strip()
        if ln:
            yield i, ln


def read_ardupilot_params(path: str | Path) -> AffineCalibration:
    """NAME,VALUE (or NAME VALUE) lines, # comments; other parameters of a full dump are ignored."""
    p = str(path)
    pairs = []
    for i, ln in _parameter_lines(p):
        parts = re.split(r"[,\s]+", ln)
        if len(parts) != 2:
            raise ImucalError(f"{short(ln)} is not NAME,VALUE", file=p, field=f"line {i}",
                              fix="one parameter per line: NAME,VALUE")
        pairs.append((i, parts[0], parts[1]))
    return _params(pairs, p, ARDUPILOT_OFFSETS, ARDUPILOT_SCALES, ARDUPILOT_GYRO, "ardupilot")


def read_px4_params(path: str | Path) -> AffineCalibration:
    """QGroundControl's lines: vehicle, component, name, value, type; # comments."""
    p = str(path)
    pairs = []
    for i, ln in _parameter_lines(p):
        parts = ln.split()
        if len(parts) != 5:
            raise ImucalError(f"{short(ln)} is not vehicle, component, name, value, type", file=p,
                              field=f"line {i}", fix="one parameter per line as QGroundControl saves them")
        pairs.append((i, parts[2], parts[3]))
    return _params(pairs, p, PX4_OFFSETS, PX4_SCALES, PX4_GYRO, "px4")
