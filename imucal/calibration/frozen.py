"""A frozen calibration: the accelerometer, and every sensor calibrated in its frame (saving and loading:
imucal.calibration.fileformat).

The accelerometer's apply map is the Theorem: a_orth = E^-T diag(1/b) (raw - s) = A raw + c, with A lower
triangular (structural zeros above the diagonal). Effects, when present, make A and c depend
on covariates (temperature, time). Every sensor's map, the accelerometer's included, is evaluated by
numpy generated from its description's CasADi ``apply`` (imucal.calibration.sensor); the other sensors
(the gyroscope) are ``attached``, each a SensorCalibration read through that one value.
"""
from __future__ import annotations

import datetime as _dt
import os
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

from imucal import __version__
from imucal.calibration import fileformat
from imucal.calibration.sensor import SensorCalibration, apply_sensors
from imucal.errors import ImucalError
from imucal.model.parameters import BASE_NAMES, Parameters
from imucal.model.sensor import ACCELEROMETER, GYROSCOPE, SensorModel, build_model
from imucal.model.effects import make_effect


@dataclass(frozen=True)
class Calibration:
    """Parameters of a fitted sensor model and everything needed to apply and trace them."""

    params: Parameters
    std: Mapping[str, float]
    gravity: float
    raw_unit: str = "raw"
    effects: tuple[tuple[str, tuple[int, ...]], ...] = ()
    fit: Mapping[str, Any] = field(default_factory=dict)  #: rms, chi2, dof, status, ...
    data: Mapping[str, Any] = field(default_factory=dict)  #: file name, sha256
    created: str = ""
    software_version: str = __version__
    #: the other sensors calibrated in the accelerometer's output frame (the gyroscope), in KINDS order
    attached: tuple[SensorCalibration, ...] = ()

    @property
    def sensors(self) -> tuple[str, ...]:
        """The sensor kinds this calibration holds."""
        return (ACCELEROMETER,) + tuple(s.kind for s in self.attached)

    @property
    def accelerometer(self) -> SensorCalibration:
        """The accelerometer as one calibrated sensor (its description, parameters, standard errors, fit)."""
        return SensorCalibration(self.model, self.params, self.std, self.raw_unit, self.fit)

    @property
    def all_sensors(self) -> tuple[SensorCalibration, ...]:
        """Every sensor, the accelerometer first."""
        return (self.accelerometer, *self.attached)

    def sensor(self, kind: str) -> SensorCalibration | None:
        """The sensor ``kind``, or None when this calibration has none."""
        return next((s for s in self.all_sensors if s.kind == kind), None)

    @property
    def gyro(self) -> SensorCalibration | None:
        """The gyroscope, or None."""
        return self.sensor(GYROSCOPE)

    # --- the model -------------------------------------------------------------------------
    @property
    def model(self) -> SensorModel:

        return build_model(self.effect_objects())

    def effect_objects(self) -> list:
        if not self.effects:
            return []

        return [make_effect(name, axes) for name, axes in self.effects]

    @property
    def covariates(self) -> tuple[str, ...]:
        return self.model.covariates if self.effects else ()

    @property
    def model_name(self) -> str:
        return self.model.name

    @property
    def values(self) -> np.ndarray:
        return np.array(self.params.values(), float)

    def linear_map(self) -> tuple[np.ndarray, np.ndarray]:
        """The accelerometer's map as a matrix and an offset: a_orth = A raw + c (the Theorem).

        With effects, the map at covariates zero (reference temperature, t = 0).

        Returns:
            A (3, 3), lower triangular [(m/s^2) per raw unit], and c (3,) [m/s^2].
        """

        base = build_model()
        A, c = base.linear_map(self.values[: len(BASE_NAMES)])
        return np.asarray(A), np.asarray(c).ravel()

    @property
    def rms_residual(self) -> float:
        return float(self.fit.get("rms_residual", float("nan")))

    # --- apply -------------------------------------------------------------------------------
    def apply(self, raw: np.ndarray, covariates: Mapping[str, np.ndarray] | None = None) -> np.ndarray:
        """Calibrated acceleration in the Theorem's orthonormal frame.

        Args:
            raw: (N, 3) raw readings, or one (3,) sample.
            covariates: {"temp": (N,), "time": (N,)} when the calibration has effects that read them.

        Returns:
            (N, 3) (or (3,)) acceleration [m/s^2].
        """
        raw = np.asarray(raw, float)
        if raw.shape == (3,):  # one sample
            return self.apply(raw[None, :], covariates)[0]
        if raw.ndim != 2 or raw.shape[1] != 3:
            raise ImucalError(f"raw data must have shape (N, 3) or (3,), got {raw.shape}", field="raw",
                              fix="pass one row of three raw readings (x, y, z) per sample")
        covs = self.covariates
        covariates = covariates or {}
        missing = [c for c in covs if c not in covariates]
        if missing:
            raise ImucalError(f"this calibration needs covariate(s) {missing}", field="covariates",
                              fix="load a recording with those columns (temp in deg C, time in s)")
        n = raw.shape[0]
        C = np.column_stack([np.broadcast_to(np.asarray(covariates[c], float), (n,)) for c in covs]) if covs \
            else np.zeros((n, 0))  # effects without covariates (scale_nonlinearity)
        return self.accelerometer.apply(raw, C)

    def apply_all(self, raw: Mapping[str, np.ndarray | None], covariates: Mapping[str, np.ndarray] | None = None,
                  acc: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """Every sensor whose raw readings ``raw`` holds by kind ({"accelerometer": (N, 3), "gyroscope": ...}),
        each in the accelerometer's frame: {kind: calibrated (N, 3)} (imucal.calibration.sensor.apply_sensors).
        ``acc``: the accelerometer's calibrated readings when already computed (``apply``)."""
        raw_acc = raw.get(ACCELEROMETER)
        if acc is None and raw_acc is not None:  # its checks and covariates as ``apply``'s
            acc = self.apply(raw_acc, covariates)
        if acc is None:
            return apply_sensors(self.attached, raw, covariates)
        columns = {**(covariates or {}), **dict(zip(self.accelerometer.model.output.columns, np.atleast_2d(acc).T))}
        return {ACCELEROMETER: acc, **apply_sensors(self.attached, raw, columns)}

    def apply_imu(self, raw_acc: np.ndarray, raw_gyro: np.ndarray,
                  covariates: Mapping[str, np.ndarray] | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Calibrated acceleration and angular rate of the same samples, in one frame.

        Args:
            raw_acc: (N, 3) raw accelerometer readings.
            raw_gyro: (N, 3) raw gyroscope readings of the same samples.
            covariates: as for :meth:`apply`.

        Returns:
            (acceleration [m/s^2], angular rate [rad/s]), each (N, 3).
        """
        if self.gyro is None:
            raise ImucalError("this calibration has no gyroscope part", field="gyroscope",
                              fix="calibrate with gyro columns (gx, gy, gz) or --gyro-data")
        out = self.apply_all({ACCELEROMETER: np.atleast_2d(raw_acc), GYROSCOPE: np.atleast_2d(raw_gyro)}, covariates)
        one = np.ndim(raw_acc) == 1
        return (out[ACCELEROMETER][0], out[GYROSCOPE][0]) if one else (out[ACCELEROMETER], out[GYROSCOPE])

    @property
    def equation(self) -> str:
        """The accelerometer's apply equation as actually applied."""
        if not self.effects:
            return "a = matrix @ raw + offset (matrix lower triangular)"
        covs = ", ".join(self.covariates)
        terms = ", ".join(f"{n}[{''.join('xyz'[i] for i in ax)}]" for n, ax in self.effects)
        return (f"a = E^-T m with m_i = (raw_i - s_i) / b_i (Eq. theModel) extended by {terms}"
                + (f", evaluated at each sample's {covs}" if covs else "")
                + "; matrix and offset are the map with every effect term at zero"
                + (f" ({covs} at their reference)" if covs else ""))

    # --- files -------------------------------------------------------------------------------
    @classmethod
    def load(cls, path: str | os.PathLike) -> "Calibration":
        """Read a calibration file written by :meth:`save` (unknown versions are refused).

        Args:
            path: the calibration YAML.

        Returns:
            The Calibration, as saved.
        """
        return load_calibration(path)

    def to_dict(self) -> dict[str, Any]:
        """The calibration file's mapping (imucal.calibration.fileformat)."""
        return fileformat.to_dict(self)

    def save(self, path: str | os.PathLike) -> None:
        """Write the calibration file atomically (imucal.calibration.fileformat).

        Args:
            path: the calibration YAML to write (replaced whole, or left as it was).
        """
        fileformat.save(self, path)


def from_dict(d: Mapping[str, Any], path: str = "<calibration>") -> Calibration:
    """Validate a calibration file's mapping (imucal.calibration.fileformat) and rebuild the Calibration."""
    content = fileformat.read_mapping(d, path)
    cal = Calibration(**content.values)
    fileformat.check_built(cal, content, path)
    return cal


def load_calibration(path: str | os.PathLike) -> Calibration:
    """Read a calibration YAML written by :meth:`Calibration.save`; refuses unknown versions.

    Args:
        path: the calibration file.

    Returns:
        The Calibration of every sensor the file holds.
    """
    return from_dict(fileformat.read_file(path), str(path))


def now_utc() -> str:
    return _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat()
