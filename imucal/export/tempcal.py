"""Temperature terms for ArduPilot (INS_TCAL1_*) and PX4 (TC_A0_*), and what they cannot hold.

Both autopilots correct the accelerometer's offset, not its scale, with a cubic in temperature,
before their offset and diagonal scale (imucal.export.autopilot):
  ArduPilot  libraries/AP_InertialSensor/AP_InertialSensor_tempcal.cpp, TCal::correct_sensor, called
             by AP_InertialSensor_Backend::_rotate_and_correct_accel before "accel -= offset":
               v -= P(clamp(T) - 35) ;  v += P(clamp(T_cal) - 35)
             P(x) = (ACC1 x + ACC2 x^2 + ACC3 x^3) 1e-6 (polynomial_eval, SCALE_FACTOR), the clamp
             to [INS_TCAL1_TMIN, INS_TCAL1_TMAX], T_cal = INS_ACC1_CALTEMP (TEMP_REFERENCE = 35 degC).
  PX4        src/modules/temperature_compensation/TemperatureCompensation.cpp, calc_thermal_offsets_3D:
               thermal_offset_i = X0_i + X1_i dT + X2_i dT^2 + X3_i dT^3,  dT = clamp(T) - TC_A0_TREF,
             subtracted with CAL_ACC0_*OFF (Accelerometer.hpp Correct()); no thermal scale.
imucal's bias terms (bias_temperature, _temperature2, _temperature3) make the shift a polynomial
of degree <= 3 in T, s(T) (imucal.model.effects), so both hold it exactly inside [TMIN, TMAX]:
ArduPilot with INS_ACCOFFS = s(T_ref), INS_ACC1_CALTEMP = T_ref and ACCk = 1e6 d_k, d_k the
coefficients of s(T) in powers of (T - 35); PX4 with CAL_ACC0_*OFF = s(T_ref), TREF = T_ref,
X0 = 0 and Xk the coefficients in powers of (T - T_ref). s(T) is read from the calibration's own
apply map (the CasADi model), never re-derived: at each temperature the map is affine in raw,
a = A(T) (raw - s(T)), so s(T) = -A(T)^-1 a(0). Scale terms (scale_temperature...) change A(T):
the peer's a_peer = A(T_ref) A(T)^-1 a, so their loss is g ||I - A(T_ref) A(T)^-1|| over T in
[TMIN, TMAX] (max: 2-norm; RMS: Frobenius / sqrt 3, averaged over LOSS_POINTS temperatures),
stated in the file and the command's output.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Mapping, Sequence

import numpy as np

from imucal.calibration.fileformat import REGEN
from imucal.calibration.frozen import Calibration
from imucal.calibration.sensor import SensorCalibration
from imucal.errors import ImucalError
from imucal.model.channels import TEMPERATURE_RANGE
from imucal.model.effects import MIN_TEMPERATURE_SPREAD
from imucal.model.parameters import BASE_NAMES, Parameters

BIAS_TERMS = ("bias_temperature", "bias_temperature2", "bias_temperature3")
SCALE_TERMS = ("scale_temperature", "scale_temperature2", "scale_temperature3")
#: ArduPilot's fixed reference temperature (TEMP_REFERENCE) and coefficient scale (SCALE_FACTOR).
ARDUPILOT_TREF, ARDUPILOT_SCALE = 35.0, 1.0e6
#: Half-width of the range written when the calibration records none [degC].
DEFAULT_HALF_RANGE = 10.0
#: Temperatures at which s(T) is sampled to read off its cubic (Chebyshev nodes on the range).
NODES = 9
#: Temperatures, ends included, over which the scale terms' loss is taken.
LOSS_POINTS = 41


@dataclass(frozen=True)
class TempPolynomial:
    """s(T) = sum_k coeffs[k] (T - origin)^k [raw] over [tmin, tmax], and the scale terms' loss."""

    tref: float  #: the calibration's reference temperature [degC]
    tmin: float
    tmax: float
    s_ref: np.ndarray  #: s(T_ref) [raw]
    coeffs: np.ndarray  #: (4, 3) in powers of (T - tref)
    range_note: str  #: where tmin/tmax come from
    scale_max: float = 0.0  #: [m/s^2] lost by the scale terms, max over T and directions
    scale_rms: float = 0.0  #: [m/s^2] RMS over T and uniform directions

    def about(self, origin: float) -> np.ndarray:
        """(4, 3) coefficients in powers of (T - origin) (Taylor shift of the cubic)."""
        c, h = self.coeffs, origin - self.tref  # s = sum c_k (x + h)^k, x = T - origin
        out = np.zeros_like(c)
        for k in range(4):
            for j in range(k + 1):
                out[j] += c[k] * math.comb(k, j) * h ** (k - j)
        return out


def _names(effects: tuple[str, ...], params: Parameters) -> list[str]:
    suffixes = ("x", "y", "z", "tref", "a2", "b2", "a3", "b3")
    return [n for n in params.names if n in BASE_NAMES
            or any(n.startswith(e + "_") and n[len(e) + 1:] in suffixes for e in effects)]


def temperature_part(cal: Calibration) -> Calibration | None:
    """The calibration with its temperature terms only (None without any)."""
    effs = tuple((n, ax) for n, ax in cal.effects if n in BIAS_TERMS + SCALE_TERMS)
    if not effs:
        return None
    params = Parameters([cal.params[n] for n in _names(tuple(n for n, _ in effs), cal.params)])
    return Calibration(params=params, std={}, gravity=cal.gravity, raw_unit=cal.raw_unit, effects=effs)


def _affine_at(cal: Calibration, temp: float, probe: float) -> tuple[np.ndarray, np.ndarray]:
    """A(T) and s(T) with a = A(T) (raw - s(T)), read from the apply map at four raw points."""
    raw = np.vstack([np.zeros(3), probe * np.eye(3)])
    a = cal.apply(raw, {"temp": np.full(4, temp)})
    A = (a[1:] - a[0]).T / probe
    return A, _shift(A, a[0], temp)


#: A(T) more ill-conditioned than this is no calibration's (theirs are near 1): its terms swamp the map.
MAX_CONDITION = 1e8


def _shift(A: np.ndarray, y0: np.ndarray, temp: float) -> np.ndarray:
    """s(T) = -A(T)^-1 y(0) of a map read at ``temp``; refused when A(T) lost a direction: temperature terms or
    a T_ref so large that the map's rounding swamps it (an edited file)."""
    if not (np.isfinite(A).all() and np.linalg.cond(A) <= MAX_CONDITION):
        raise ImucalError(f"the temperature terms leave no invertible map at {temp:.4g} degC (a coefficient or "
                          "T_ref far beyond a calibration's)", field="parameters", fix=REGEN)
    return -np.linalg.solve(A, y0)


#: Temperatures the exports accept [degC] (the peers' parameters are in degC).
ABSOLUTE_ZERO, MAX_TEMPERATURE = TEMPERATURE_RANGE


def _range(fit: object, tref: float) -> tuple[float, float, str]:
    """[degC] the range the terms were fitted over (the calibration's ``temperature_range``), checked."""
    rng = fit.get("temperature_range") if isinstance(fit, Mapping) else None
    if rng:
        tmin, tmax, note = float(rng[0]), float(rng[1]), "the calibration data's temperature range"
        if not (ABSOLUTE_ZERO <= tmin and tmax <= MAX_TEMPERATURE):  # the peers' parameters are in degC
            raise ImucalError(f"temperature range {tmin:g}..{tmax:g} degC is not a temperature in degC "
                              f"({ABSOLUTE_ZERO:g} to {MAX_TEMPERATURE:g})", field="fit.temperature_range",
                              fix="record the temperature column in degC and recalibrate")
        if not tmax - tmin >= MIN_TEMPERATURE_SPREAD:  # the fit needs that much: this file was edited
            raise ImucalError(f"temperature range {tmin:g}..{tmax:g} degC is narrower than the "
                              f"{MIN_TEMPERATURE_SPREAD:g} degC its temperature terms were fitted over",
                              field="fit.temperature_range",
                              fix="regenerate the file with `imucal calibrate`")
    else:
        tmin, tmax = tref - DEFAULT_HALF_RANGE, tref + DEFAULT_HALF_RANGE
        note = f"no temperature range recorded: T_ref +- {DEFAULT_HALF_RANGE:g} degC"
    return tmin, tmax, note


def _cubic(affine_at: Callable[[float], tuple[np.ndarray, np.ndarray]], effects: Sequence[str], tref: float,
           fit: object, size: float) -> TempPolynomial:
    """s(T) read from a map's ``affine_at(T)`` -> (A(T), s(T)) at NODES temperatures (exact: a polynomial of
    the terms' degree), and the scale terms' loss at a reading of ``size`` (module docstring)."""
    tmin, tmax, note = _range(fit, tref)
    temps = tref + (tmax - tmin) / 2 * np.cos(np.pi * (np.arange(NODES) + 0.5) / NODES) + (tmin + tmax) / 2 - tref
    S = np.array([affine_at(float(t))[1] for t in temps])
    degree = max((BIAS_TERMS.index(n) + 1 for n in effects if n in BIAS_TERMS), default=0)
    coeffs = np.zeros((4, 3))
    coeffs[:degree + 1] = np.linalg.lstsq(np.vander(temps - tref, degree + 1, increasing=True), S, rcond=None)[0]
    A_ref, s_ref = affine_at(tref)
    if not any(n in SCALE_TERMS for n in effects):  # nothing dropped (not rounding's 1e-15 m/s^2)
        return TempPolynomial(tref=tref, tmin=tmin, tmax=tmax, s_ref=s_ref, coeffs=coeffs, range_note=note)
    grid = np.linspace(tmin, tmax, LOSS_POINTS)  # the ends included: a scale term's loss peaks there
    lost = [np.eye(3) - A_ref @ np.linalg.inv(affine_at(float(t))[0]) for t in grid]
    return TempPolynomial(tref=tref, tmin=tmin, tmax=tmax, s_ref=s_ref, coeffs=coeffs, range_note=note,
                          scale_max=size * max(float(np.linalg.norm(D, 2)) for D in lost),
                          scale_rms=size * math.sqrt(float(np.mean([np.sum(D**2) for D in lost])) / 3))


def polynomial(cal: Calibration) -> TempPolynomial | None:
    """The accelerometer's s(T) of the temperature terms, exactly (a cubic through NODES samples; module
    docstring); the scale terms' loss at |a| = g."""
    part = temperature_part(cal)
    if part is None:
        return None
    tref = float(next(part.params[n].value for n in part.params.names if n.endswith("_tref")))
    probe = float(np.max(np.abs(cal.values[3:6])))
    return _cubic(lambda t: _affine_at(part, t, probe), [n for n, _ in part.effects], tref, cal.fit,
                  float(cal.gravity))


def _sensor_affine_at(s: SensorCalibration, temp: float, probe: float) -> tuple[np.ndarray, np.ndarray]:
    """A(T), s(T) of an attached sensor's map y = A(T) (raw - s(T)) + B inputs, its other inputs at 0."""
    raw = np.vstack([np.zeros(3), probe * np.eye(3)])
    inputs = np.array([[temp if k == "temp" else 0.0 for k in s.model.inputs]] * 4)
    y = s.apply(raw, inputs)
    A = (y[1:] - y[0]).T / probe
    return A, _shift(A, y[0], temp)


def sensor_polynomial(s: SensorCalibration, size: float = 1.0) -> TempPolynomial | None:
    """An attached sensor's (the gyroscope's) bias s(T) [its raw unit], read from its own map as the
    accelerometer's is; None without a temperature bias term. The scale terms' loss at a reading of ``size``
    [its output unit] (the gyroscope: 1 rad/s)."""
    names = [e.name for e in s.model.effects if "temp" in e.covariates]
    if not any(n in BIAS_TERMS for n in names):
        return None
    tref = s.reference_inputs()["temp"]
    probe = 1.0 / float(np.max(np.abs(s.at_reference().affine().A)))  # one output unit of raw reading
    return _cubic(lambda t: _sensor_affine_at(s, t, probe), names, tref, s.fit, size)


def loss_sentence(p: TempPolynomial, what: str) -> str | None:
    """The scale terms' loss in words (None when the calibration has none)."""
    if p.scale_max == 0.0:
        return None
    return (f"{what} holds no temperature scale term: the scale_temperature terms are dropped, an error of max "
            f"{p.scale_max:.3g} m/s^2, RMS {p.scale_rms:.3g} m/s^2 over {p.tmin:.4g}..{p.tmax:.4g} degC at |a| = g")


def ardupilot_lines(p: TempPolynomial, sensor: str = "ACC", shared: bool = True) -> list[tuple[str, float]]:
    """INS_TCAL1_<sensor>k_* and INS_<sensor>1_CALTEMP (module docstring; ``sensor`` ACC or GYR), after the
    instance's INS_TCAL1_ENABLE, _TMIN, _TMAX when ``shared`` (one range per IMU: the accelerometer's and the
    gyroscope's curves share it); the enable flag is an integer."""
    d = p.about(ARDUPILOT_TREF)
    out: list[tuple[str, float]] = [("INS_TCAL1_ENABLE", 1), ("INS_TCAL1_TMIN", p.tmin),
                                    ("INS_TCAL1_TMAX", p.tmax)] if shared else []
    out.append((f"INS_{sensor}1_CALTEMP", p.tref))
    for k in (1, 2, 3):
        out += [(f"INS_TCAL1_{sensor}{k}_{a}", float(d[k, i] * ARDUPILOT_SCALE)) for i, a in enumerate("XYZ")]
    return out


def px4_lines(p: TempPolynomial, sensor: str = "A") -> list[tuple[str, float]]:
    """TC_<sensor>_ENABLE and TC_<sensor>0_* (module docstring; ``sensor`` A or G); TC_<sensor>0_ID 0: the user
    sets the device id. The enable flag and the id are integers (int32 in PX4)."""
    t = f"TC_{sensor}0"
    out: list[tuple[str, float]] = [(f"TC_{sensor}_ENABLE", 1), (f"{t}_ID", 0), (f"{t}_TREF", p.tref),
                                    (f"{t}_TMIN", p.tmin), (f"{t}_TMAX", p.tmax)]
    for k in range(4):
        out += [(f"{t}_X{k}_{i}", 0.0 if k == 0 else float(p.coeffs[k, i])) for i in range(3)]
    return out
