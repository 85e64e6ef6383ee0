"""A calibration in the units of a datasheet, beside the fitted values: bias in mg or deg/s, scale as a
sensitivity (raw per g, raw per deg/s) or an error in ppm of the nominal 1, axis misalignment in mrad,
g-sensitivity in (deg/s)/g, hard iron in uT, soft iron in % and mrad, the magnetometer's alignment in
deg. Typed rows, one table per sensor the calibration holds; report/html.py
renders them.

The conversions are first order: a bias s/b has the standard error sqrt((ds/b)^2 + (s db/b^2)^2) with
the covariance of s and b neglected (b is known to ppm, so the second term is small).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from imucal.calibration.fields import ACCELEROMETER, GYROSCOPE
from imucal.model.sensor import MAGNETOMETER
from imucal.calibration.frozen import Calibration
from imucal.constants import RIGHT_ANGLE, SI_ACCEL_UNIT, STANDARD_GRAVITY

AXES = "xyz"
DEG_PER_RAD = 180.0 / math.pi
#: Raw units that are already physical: the nominal scale is 1 (a rate in deg/s: 180/pi per rad/s).
NOMINAL_SCALE = {SI_ACCEL_UNIT: 1.0, "rad/s": 1.0, "deg/s": DEG_PER_RAD}


@dataclass(frozen=True)
class DatasheetRow:
    """One quantity as a datasheet states it, and the fitted parameter it comes from."""

    quantity: str  #: e.g. "bias x"
    value: float
    std: float
    unit: str  #: mg, ppm, mrad, deg/s, raw/g ...
    parameter: str  #: the fitted parameter (or parameters) it is made from
    fitted: float
    fitted_std: float
    fitted_unit: str


def _ratio_std(s: float, ds: float, b: float, db: float) -> float:
    """First-order standard error of s / b (covariance neglected)."""
    return math.hypot(ds / b, s * db / b**2)


def _scale_rows(name: str, pname: str, b: float, db: float, unit: str, per: str, per_factor: float,
                nominal: float | None) -> DatasheetRow:
    """A scale as an error against its nominal (ppm), or as a sensitivity (raw per g or per deg/s)."""
    if nominal is not None:
        return DatasheetRow(f"scale error {name}", (b / nominal - 1) * 1e6, db / nominal * 1e6, "ppm", pname,
                            b, db, f"{unit} per {per}")
    return DatasheetRow(f"sensitivity {name}", b * per_factor, db * per_factor,
                        f"{unit}/{'g' if per == SI_ACCEL_UNIT else 'deg/s'}", pname, b, db, f"{unit} per {per}")


def accelerometer_rows(cal: Calibration) -> list[DatasheetRow]:
    v, sd, unit = cal.params.value_dict(), cal.std, cal.raw_unit
    std = {n: float(sd.get(n, math.nan)) for n in v}
    mg = 1e3 / STANDARD_GRAVITY  # [mg per m/s^2]
    rows = []
    for i, a in enumerate(AXES, 1):
        s, b, ds, db = v[f"s{i}"], v[f"b{i}"], std[f"s{i}"], std[f"b{i}"]
        rows.append(DatasheetRow(f"bias {a}", s / b * mg, _ratio_std(s, ds, b, db) * mg, "mg", f"s{i}", s, ds, unit))
    for i, a in enumerate(AXES, 1):
        b, db = v[f"b{i}"], std[f"b{i}"]
        rows.append(_scale_rows(a, f"b{i}", b, db, unit, SI_ACCEL_UNIT, STANDARD_GRAVITY, NOMINAL_SCALE.get(unit)))
    for n, pair in (("phi", "x-y"), ("psi", "x-z"), ("theta", "y-z")):
        rows.append(DatasheetRow(f"misalignment {pair} (from 90°)", (v[n] - RIGHT_ANGLE) * 1e3, std[n] * 1e3, "mrad",
                                 n, math.degrees(v[n]), math.degrees(std[n]), "deg"))
    return rows


def gyroscope_rows(cal: Calibration) -> list[DatasheetRow]:
    from imucal.gyro.result import GyroArrays  # only a calibration with a gyroscope

    g = cal.gyro
    assert g is not None
    unit, nominal = g.raw_unit, NOMINAL_SCALE.get(g.raw_unit)
    a = GyroArrays.of(g.params, g.std)
    rows = []
    for j, ax in enumerate(AXES):
        s, b, ds, db = float(a.bias[j]), float(a.scale[j]), float(a.bias_std[j]), float(a.scale_std[j])
        rows.append(DatasheetRow(f"bias {ax}", s / b * DEG_PER_RAD, _ratio_std(s, ds, b, db) * DEG_PER_RAD, "deg/s",
                                 f"s_{ax}", s, ds, unit))
    for j, ax in enumerate(AXES):
        b, db = float(a.scale[j]), float(a.scale_std[j])
        rows.append(_scale_rows(ax, f"b_{ax}", b, db, unit, "rad/s", 1.0 / DEG_PER_RAD, nominal))
    for i in range(3):
        for j in range(3):
            if i != j:
                m, dm = float(a.misalignment[i, j]), float(a.misalignment_std[i, j])
                rows.append(DatasheetRow(f"misalignment {AXES[i]}{AXES[j]}", m * 1e3, dm * 1e3, "mrad",
                                         f"m_{AXES[i]}{AXES[j]}", m, dm, "1"))
    k = DEG_PER_RAD * STANDARD_GRAVITY  # (rad/s)/(m/s^2) -> (deg/s)/g
    for i in range(3):
        if np.any(a.gsens[i]):
            for j in range(3):
                rows.append(DatasheetRow(f"g-sensitivity {AXES[i]}{AXES[j]}", float(a.gsens[i, j]) * k,
                                         float(a.gsens_std[i, j]) * k, "(deg/s)/g", f"G_{AXES[i]}{AXES[j]}",
                                         float(a.gsens[i, j]), float(a.gsens_std[i, j]), "(rad/s)/(m/s^2)"))
    return rows


def magnetometer_rows(cal: Calibration) -> list[DatasheetRow]:
    """Hard iron in uT (s_i / b_i in the field's unit), soft iron as each axis's scale against their mean (%) and
    its non-orthogonality (mrad), the rotation to the accelerometer's frame in deg."""
    from imucal.mag.units import FIELD_UNITS  # only a calibration with a magnetometer

    m = cal.sensor(MAGNETOMETER)
    assert m is not None
    v, unit, out = m.params.value_dict(), m.raw_unit, m.model.output.unit
    std = {n: float(m.std.get(n, math.nan)) for n in v}
    to_ut, shown = (FIELD_UNITS[out], "uT") if out in FIELD_UNITS else (1.0, out)
    rows = []
    for i, a in enumerate(AXES, 1):
        s, b, ds, db = v[f"s{i}"], v[f"b{i}"], std[f"s{i}"], std[f"b{i}"]
        rows.append(DatasheetRow(f"hard iron {a}", s / b * to_ut, _ratio_std(s, ds, b, db) * to_ut, shown,
                                 f"s{i}", s, ds, unit))
    mean_b = float(np.prod([v[f"b{i}"] for i in (1, 2, 3)])) ** (1 / 3)
    for i, a in enumerate(AXES, 1):
        b, db = v[f"b{i}"], std[f"b{i}"]
        rows.append(DatasheetRow(f"soft iron scale {a} (of the mean)", (b / mean_b - 1) * 100, db / mean_b * 100, "%",
                                 f"b{i}", b, db, f"{unit} per {out}"))
    for n, pair in (("phi", "x-y"), ("psi", "x-z"), ("theta", "y-z")):
        rows.append(DatasheetRow(f"soft iron skew {pair} (from 90°)", (v[n] - RIGHT_ANGLE) * 1e3, std[n] * 1e3, "mrad",
                                 n, math.degrees(v[n]), math.degrees(std[n]), "deg"))
    for n in ("rx", "ry", "rz"):
        rows.append(DatasheetRow(f"alignment about {n[1]} (to the accelerometer)", math.degrees(v[n]),
                                 math.degrees(std[n]), "deg", n, v[n], std[n], "rad"))
    return rows


#: Each sensor kind's rows: a sensor a calibration holds without an entry here shows its raw values only.
ROWS = {ACCELEROMETER: accelerometer_rows, GYROSCOPE: gyroscope_rows, MAGNETOMETER: magnetometer_rows}


def datasheet(cal: Calibration) -> dict[str, list[DatasheetRow]]:
    """Every sensor the calibration holds, in datasheet units."""
    return {s: ROWS[s](cal) for s in cal.sensors if s in ROWS}
