"""The gyroscope of a temperature sweep (issue 27): its bias(T) from the still poses, on what fit.base holds.

Still poses turn nothing, so a sweep determines the gyroscope's bias over temperature only
(imucal.gyro.thermal). Its scale, misalignment and g-sensitivity come from fit.base when that calibration has
a gyroscope section (``imucal calibrate`` on a log with rotations between the poses), else the scale is the
nominal one of a rate unit and the misalignment and g-sensitivity zero. A gyroscope read in counts without
such a base has no scale to read a rate with: the sweep then writes no gyroscope section and says so (a note
of ``SweepGyro``), it never drops one silently.

The bias terms sit in raw units (imucal.model.gyroscope: s_g + c_i p_k(T)), so they are fitted per axis on the
raw readings less the g-sensitivity H a of each row, divided by the axis's scale (rad/s for the report; the
order test is the same in any unit), and multiplied back.
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from imucal.calibration.sensor import SensorCalibration
from imucal.config.run import RunConfig, base_path, load_base
from imucal.constants import RATE_UNITS
from imucal.errors import ImucalError, short
from imucal.gyro.thermal import ALPHA, GyroThermal, gyro_bias_temperature
from imucal.model.gyroscope import BIAS_NAMES, GSENS_NAMES, MIS_NAMES, SCALE_NAMES, gyro_model, gyro_parameters, \
    term_parameters, values
from imucal.thermal.evidence import ThermalRows


@dataclass(frozen=True)
class GyroBase:
    """The gyroscope section fit.base holds, and which file it came from."""

    sensor: SensorCalibration
    name: str  #: the base file's name
    sha256: str


@dataclass(frozen=True)
class SweepGyro:
    """The sweep's gyroscope: its bias(T) fit and section, or why there is none."""

    fit: GyroThermal | None = None
    section: SensorCalibration | None = None
    note: str = ""  #: why no section was written (a gyroscope in counts without a base), else ""


def gyro_base(config: RunConfig, unit: str) -> GyroBase | None:
    """fit.base's gyroscope section (None: no base, or a base without one), checked against the data's gyro
    ``unit``; a base gyroscope with covariate terms is refused (this sweep determines them)."""
    if config.fit.base is None:
        return None
    g = load_base(config, config.source).gyro
    if g is None:
        return None
    name = Path(config.fit.base).name
    if g.raw_unit != unit:
        raise ImucalError(f"the base calibration's gyroscope reads {short(g.raw_unit)}, this recording's gyroscope "
                          f"{short(unit)}", file=config.source, field="fit.base",
                          fix="set data.gyro_unit to the base's unit, or calibrate the base from a log in this unit")
    if g.covariates:
        raise ImucalError(f"the base calibration {short(name)} has a gyroscope with temperature or time terms, which "
                          "this sweep determines itself", file=config.source, field="fit.base",
                          fix="give the calibration of a multi-pose log at one temperature")
    return GyroBase(g, name, hashlib.sha256(base_path(config).read_bytes()).hexdigest())


def sweep_gyro(rows: ThermalRows, unit: str, acc: np.ndarray, base: GyroBase | None, temperature_range: list[float],
               alpha: float = ALPHA) -> SweepGyro:
    """The gyroscope's bias(T) of a sweep's ``rows`` (their ``gyro`` in ``unit``), ``acc`` (n, 3) the rows'
    calibrated specific force [m/s^2] (for the base's g-sensitivity), and the section that carries it."""
    if rows.gyro is None:
        return SweepGyro()
    if base is None and unit not in RATE_UNITS:
        return SweepGyro(note=f"the gyroscope reads {short(unit)} (counts): its bias over temperature needs a scale to "
                              "be read in rad/s, so no gyroscope section was written; give fit.base the calibration "
                              "of a log with rotations (its gyroscope section), or set data.gyro_unit to rad/s or "
                              "deg/s if the readings are rates")
    v = None if base is None else values(base.sensor.params)
    k = np.full(3, 1.0 / RATE_UNITS[unit]) if v is None else v["scale"]  # [unit per rad/s] per axis
    raw = rows.gyro if v is None else rows.gyro - acc @ v["H"].T
    fit = gyro_bias_temperature(replace(rows, gyro=raw / k), alpha)
    return SweepGyro(fit, gyro_calibration(fit, unit, k, temperature_range, base))


def gyro_calibration(g: GyroThermal, unit: str, k: np.ndarray, temperature_range: list[float],
                     base: GyroBase | None = None) -> SensorCalibration:
    """The gyroscope a sweep calibrates: its bias(T) terms (fitted in rad/s, ``k`` [unit per rad/s] per axis
    back to ``unit``) on the bias at the terms' zero; the scale, misalignment and g-sensitivity held at the
    base's values and standard errors, or at nominal and zero without a base (still poses turn nothing)."""
    effects = g.effects()
    axis = {"x": 0, "y": 1, "z": 2}
    terms = {n: (p.value if p.fixed else p.value * k[axis[n[-1]]]) for n, p in g.params.items()}
    bias = g.offset * k
    if base is None:
        params = gyro_parameters(unit, bias, k, nominal=float(np.mean(k)))
        held: dict[str, float] = {}
        evidence = "scale, misalignment and g-sensitivity held at nominal (no rotations)"
        origin: dict[str, Any] = {}
    else:
        bv = base.sensor.params.value_dict()
        params = base.sensor.params.with_values(dict(zip(BIAS_NAMES, map(float, bias))))  # the sweep's bias at T_ref
        held = {n: float(base.sensor.std.get(n, np.nan)) for n in (*SCALE_NAMES, *MIS_NAMES, *GSENS_NAMES)}
        evidence = f"scale, misalignment and g-sensitivity taken from fit.base {short(base.name)}"  # one line
        origin = {"base": {"file": base.name, "sha256": base.sha256, "scale": [bv[n] for n in SCALE_NAMES]}}
    params = params.with_fixed(params.names).extended(term_parameters(effects, unit, terms, nominal=float(np.mean(k))))
    std = {**{n: float(s) for n, s in zip(BIAS_NAMES, g.offset_std * k)}, **held,
           **{n: float(s * k[axis[n[-1]]]) for n, s in g.std.items()}}
    fit = {"evidence": "still poses over a temperature sweep (imucal.gyro.thermal): bias(T) per axis", "held": evidence,
           "orders": list(g.orders), "temperature_range": temperature_range,
           "drift_per_day": (g.drift * k).tolist(), "drift_std_per_day": (g.drift_std * k).tolist(), **origin}
    return SensorCalibration(gyro_model(effects), params, std, unit, fit)
