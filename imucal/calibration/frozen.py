"""A frozen calibration: values plus the apply map (saving and loading: imucal.calibration.fileformat).

The apply map is the Theorem: a_orth = E^-T diag(1/b) (raw - s) = A raw + c, with A lower
triangular (structural zeros above the diagonal). Effects, when present, make A and c depend
on covariates (temperature, time) and the map is evaluated through the CasADi model.
"""
from __future__ import annotations

import datetime as _dt
import os
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Mapping

import numpy as np

from imucal import __version__
from imucal.calibration import fileformat
from imucal.calibration.fields import ACCELEROMETER, GYROSCOPE
from imucal.errors import ImucalError
from imucal.model.parameters import BASE_NAMES, Parameters
from imucal.model.sensor import SensorModel, build_model
from imucal.model.effects import make_effect

if TYPE_CHECKING:  # the gyroscope's modules load only for a file or run that has one (docs/architecture.md)
    from imucal.calibration.gyro import GyroCalibration



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
    gyro: GyroCalibration | None = None  #: the gyroscope part, in the same output frame

    @property
    def sensors(self) -> tuple[str, ...]:
        """The sensor kinds this calibration holds."""
        return (ACCELEROMETER,) + ((GYROSCOPE,) if self.gyro is not None else ())

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
            raise ImucalError(f"raw data must have shape (N, 3) or (3,), got {raw.shape}", field="raw")
        if not self.effects:
            A, c = self.linear_map()
            out = (A @ raw.T).T  # one BLAS call; half the peak memory of raw @ A.T + c
            out += c
            return out
        covs = self.covariates
        covariates = covariates or {}
        missing = [c for c in covs if c not in covariates]
        if missing:
            raise ImucalError(f"this calibration needs covariate(s) {missing}", field="covariates",
                              fix="load a recording with those columns (temp in deg C, time in s)")
        n = raw.shape[0]
        C = np.column_stack([np.broadcast_to(np.asarray(covariates[c], float), (n,)) for c in covs]) if covs \
            else np.zeros((n, 0))  # effects without covariates (scale_nonlinearity)
        # Serial map: CasADi's "thread" map aborts the process for large n (one thread per call).
        f = self.model.accel.map(n, "serial")
        return np.asarray(f(raw.T, C.T, self.values)).T

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
        acc = self.apply(raw_acc, covariates)
        return acc, self.gyro.apply(raw_gyro, acc)

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
