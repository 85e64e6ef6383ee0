"""Channels: what a recording carries and what a model reads (a sensor is data).

A channel has a role (what it measures), the columns that hold it and its unit. A model declares the
channels it reads (``SensorModel.reads``, ``gyro.model.READS``); a recording lists the channels it
has (``Recording.channels``); ``missing`` compares the two, so a calibration that needs temperature
and data without it fail with one message, wherever the check happens.

Covariates are the scalar channels the effects depend on (Section 5 of the docs: temperature, time);
their keys (``temp``, ``time``) are the ones effects declare in ``Effect.covariates``. ``temp_rate`` is
derived from the temperature: its rate of change dT/dt [degC/s] (``temperature_rate``), the covariate of
a hysteresis (a bias that differs between warming and cooling).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np

from imucal.errors import ImucalError


@dataclass(frozen=True)
class Channel:
    """One measured quantity of a recording: role, columns (the roles of ``data.columns``), unit."""

    role: str
    columns: tuple[str, ...]
    unit: str
    description: str = ""

    def with_unit(self, unit: str) -> "Channel":
        return Channel(self.role, self.columns, unit, self.description)


ACCELERATION = Channel("acceleration", ("ax", "ay", "az"), "raw", "specific force, the accelerometer's reading")
ANGULAR_RATE = Channel("angular_rate", ("gx", "gy", "gz"), "raw", "angular rate, the gyroscope's reading")
MAGNETIC_FIELD = Channel("magnetic_field", ("mx", "my", "mz"), "raw", "magnetic field, the magnetometer's reading")
TEMPERATURE = Channel("temperature", ("temp",), "degC", "sensor temperature")
#: [degC] A sensor temperature: above absolute zero, below where any electronics survives (a reading outside is
#: corrupt, or in another unit: K read as degC is 273 too warm, which this range cannot tell).
TEMPERATURE_RANGE = (-273.15, 1000.0)
#: [degC] Above any MEMS sensor's operating range: AEC-Q100 grade 0, the widest automotive grade, ends at 150 degC
#: ambient (50 degC of margin for a die's self-heating). A recording whose median temperature lies above it is in
#: kelvin (25 degC is 298.15 K, -40 degC 233 K) or corrupt; degF (41..77 for 5..25 degC) cannot be told from degC.
MAX_OPERATING_TEMPERATURE = 200.0
TIME = Channel("time", ("t",), "s", "time from the first sample")

#: covariate key (as effects declare it) -> the channel it is read from
COVARIATES: Mapping[str, Channel] = {"temp": TEMPERATURE, "time": TIME, "temp_rate": TEMPERATURE}
#: Units of the covariates (temp_rate is derived from the temperature channel).
COVARIATE_UNITS: Mapping[str, str] = {"temp": "degC", "time": "s", "temp_rate": "degC/s"}
#: The window of ``temperature_rate`` [s]: the slope of the temperature over +-10 s of each row. Long
#: enough that a temperature's noise (0.02 degC at 100 Hz) moves the slope by 1e-4 degC/s, short enough
#: to follow a swing of a few minutes; a firmware gives dT/dt over the last 20 s.
TEMPERATURE_RATE_WINDOW = 20.0
#: How a covariate derived from another channel is computed, for a firmware that must compute it (the C header).
COVARIATE_DEFINITIONS: Mapping[str, str] = {
    "temp_rate": f"dT/dt: the least-squares slope of temp against time over the {TEMPERATURE_RATE_WINDOW:g} s "
                 "centred on the sample (imucal.model.channels.temperature_rate); a firmware's slope over the last "
                 f"{TEMPERATURE_RATE_WINDOW:g} s lags it by {TEMPERATURE_RATE_WINDOW / 2:g} s"}
#: Rows the slope of ``temperature_rate`` takes at least (the nearest in time when the window holds fewer).
_RATE_MIN_ROWS = 3


def covariate_channels(keys: tuple[str, ...]) -> tuple[Channel, ...]:
    """The channels behind an effect set's covariate keys."""
    unknown = [k for k in keys if k not in COVARIATES]
    if unknown:
        raise ImucalError(f"unknown covariate {unknown[0]!r}", field="fit.effects",
                          fix=f"effects may depend on {', '.join(COVARIATES)}")
    return tuple(COVARIATES[k] for k in keys)


def missing(reads: tuple[Channel, ...], has: tuple[Channel, ...]) -> list[Channel]:
    """The channels a model reads that a recording does not have (compared by role)."""
    roles = {c.role for c in has}
    return [c for c in reads if c.role not in roles]


def absent(ch: Channel, source: str | None, what: str) -> ImucalError:
    """The one message for a channel a model needs and the data lack."""
    needs = (f"reads {ch.role.replace('_', ' ')}" if ch in (ACCELERATION, ANGULAR_RATE, MAGNETIC_FIELD)
             else f"has a {ch.role} effect")
    return ImucalError(f"{what} {needs} but the data have no {ch.columns[0]} column", file=source,
                       field=f"data.columns.{ch.columns[0]}",
                       fix=f"add {'/'.join(ch.columns)} ({ch.unit}) or drop what needs {ch.role}")


def require(reads: tuple[Channel, ...], has: tuple[Channel, ...], source: str | None = None,
            what: str = "the model") -> None:
    """Refuse, naming the first missing channel, when ``has`` lacks a channel of ``reads``."""
    lack = missing(reads, has)
    if lack:
        raise absent(lack[0], source, what)


def covariate_values(keys: tuple[str, ...], *, temp: np.ndarray | None, time: np.ndarray,
                     source: str | None = None, what: str = "the model",
                     temp_rate: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """{key: values} for the covariates ``keys`` from the temperature and time of some rows.

    The one place that turns covariate keys into arrays; a temperature effect without a temperature
    channel is refused here with the column to add.
    """
    given = {"temp": temp, "time": time,
             "temp_rate": None if temp is None or "temp_rate" not in keys else
             temp_rate if temp_rate is not None else temperature_rate(time, temp)}
    out: dict[str, np.ndarray] = {}
    for ch, key in zip(covariate_channels(keys), keys):
        v = given[key]
        if v is None:
            raise absent(ch, source, what)
        out[key] = np.asarray(v, float)
    return out


def covariate_matrix(keys: tuple[str, ...], values: Mapping[str, np.ndarray], n: int) -> np.ndarray:
    """Rows x len(keys), the layout of the CasADi model's ``cov`` input."""
    return np.column_stack([values[k] for k in keys]) if keys else np.zeros((n, 0))


def hold_rates(time: np.ndarray, temp: np.ndarray, start: np.ndarray, end: np.ndarray) -> np.ndarray:
    """dT/dt [degC/s] of each hold [start, end) of a recording's samples: the mean over its samples of
    ``temperature_rate``, what the hold's mean reading holds of an effect linear in it. The slope across the
    interval means (``temperature_rate`` of them) stands for it only while several holds fit in the window: a
    hold of 10 s or more has no neighbour within it, and a swing that turns within a hold averages out."""
    r = temperature_rate(time, temp)
    c = np.concatenate([[0.0], np.cumsum(r)])
    start, end = np.asarray(start, int), np.asarray(end, int)
    return (c[end] - c[start]) / np.maximum(end - start, 1)


def temperature_rate(time: np.ndarray, temp: np.ndarray, window: float = TEMPERATURE_RATE_WINDOW) -> np.ndarray:
    """dT/dt [degC/s] at each row: the least-squares slope of the temperature against time over the rows
    within +-window/2 [s] of it (at least the ``_RATE_MIN_ROWS`` nearest in time). The same definition for
    interval means and for samples, so a fit on the means and the apply on samples read one covariate."""
    t, T = np.asarray(time, float), np.asarray(temp, float)
    if t.size < 2:
        return np.zeros(t.size)
    order = np.argsort(t, kind="stable")
    ta = t[order]  # the windows on the times as given: a part of the rows (a block read in chunks) finds the same
    lo = np.searchsorted(ta, ta - window / 2, side="left")
    hi = np.searchsorted(ta, ta + window / 2, side="right")
    ts, Ts = ta - ta[0], T[order] - T[order[0]]  # (sums about the first row: fewer digits lost)
    k = np.arange(t.size)
    need = np.minimum(_RATE_MIN_ROWS, t.size)
    short = hi - lo < need
    lo = np.where(short, np.clip(k - need // 2, 0, t.size - need), lo)
    hi = np.where(short, lo + need, hi)
    c = [np.concatenate([[0.0], np.cumsum(v)]) for v in (np.ones_like(ts), ts, Ts, ts * ts, ts * Ts)]
    n, st, sT, stt, stT = (v[hi] - v[lo] for v in c)
    var = stt - st * st / n
    slope = np.where(var > 0, (stT - st * sT / n) / np.where(var > 0, var, 1.0), 0.0)
    out = np.empty(t.size)
    out[order] = slope
    return out
