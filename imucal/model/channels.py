"""Channels: what a recording carries and what a model reads (a sensor is data).

A channel has a role (what it measures), the columns that hold it and its unit. A model declares the
channels it reads (``SensorModel.reads``, ``gyro.model.READS``); a recording lists the channels it
has (``Recording.channels``); ``missing`` compares the two, so a calibration that needs temperature
and data without it fail with one message, wherever the check happens.

Covariates are the scalar channels the effects depend on (Section 5 of the docs: temperature, time);
their keys (``temp``, ``time``) are the ones effects declare in ``Effect.covariates``.
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
TIME = Channel("time", ("t",), "s", "time from the first sample")

#: covariate key (as effects declare it) -> channel
COVARIATES: Mapping[str, Channel] = {"temp": TEMPERATURE, "time": TIME}


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
                     source: str | None = None, what: str = "the model") -> dict[str, np.ndarray]:
    """{key: values} for the covariates ``keys`` from the temperature and time of some rows.

    The one place that turns covariate keys into arrays; a temperature effect without a temperature
    channel is refused here with the column to add.
    """
    given = {"temp": temp, "time": time}
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
