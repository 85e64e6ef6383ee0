"""The magnetometer in a run (issue 26): fitted when the recording has mx, my, mz, attached to the calibration.

``calibrate_imu`` (imucal.pipeline) calls ``mag_of_run`` after the accelerometer (and the gyroscope): the
magnetometer's rows read the calibrated acceleration of the same samples and the accelerometer's still
intervals are its poses; ``calibrated`` turns the result into the one value every output reads
(imucal.calibration.sensor.SensorCalibration: the file section, apply, the C and the exports).
"""
from __future__ import annotations

import dataclasses
import datetime as dt
import math
from typing import Any, Mapping

import numpy as np

from imucal.calibration.sensor import SensorCalibration
from imucal.config.run import MagConfig
from imucal.mag.calibrate import MagSettings, calibrate_mag
from imucal.mag.evidence import Poses
from imucal.mag.field_model import Place
from imucal.errors import ImucalError
from imucal.mag.result import MagCalibration
from imucal.mag.units import UNIT_SCALE_FACTOR, convert, is_field_unit


def settings_of(cfg: MagConfig) -> MagSettings:
    """The fit's settings from the run file's ``mag:`` section (the place's date parsed here)."""
    place = None
    if cfg.latitude is not None and cfg.longitude is not None and cfg.date is not None:
        place = Place(float(cfg.latitude), float(cfg.longitude), dt.date.fromisoformat(cfg.date), float(cfg.height))
    lag = None if cfg.lag is None else float(cfg.lag)
    return MagSettings(field=cfg.field, field_unit=cfg.field_unit, dip_deg=cfg.dip_deg, soft_iron=cfg.soft_iron,
                       window=int(cfg.window), lag=lag, place=place)


def stated_mag(cfg: MagConfig, rec: Any) -> MagConfig:
    """The run file's ``mag:`` section with the readings' unit the file states (a netCDF variable's units:
    ``rec.mag_unit``) when the section leaves it raw; refused when the two name different units."""
    unit = getattr(rec, "mag_unit", "raw")
    if unit == "raw" or cfg.unit == unit:
        return cfg
    if cfg.unit != "raw":
        raise ImucalError(f"mag.unit {cfg.unit} disagrees with the file's {unit} for mx, my, mz", file=rec.source,
                          field="mag.unit", fix="drop mag.unit (--mag-unit): the variable's units attribute gives it")
    return dataclasses.replace(cfg, unit=unit)


def mag_of_run(mag: np.ndarray, acc: np.ndarray, start: np.ndarray, end: np.ndarray, cfg: MagConfig,
               source: str | None = None) -> MagCalibration:
    """The magnetometer's calibration from its readings, the calibrated acceleration of the same samples and
    the accelerometer's still intervals [start, end)."""
    still = Poses(np.asarray(start, int), np.asarray(end, int), "still intervals")
    return calibrate_mag(mag, acc, still=still, settings=settings_of(cfg), raw_unit=cfg.unit, source=source)


def fit_section(cal: MagCalibration, rate: float | None = None) -> dict[str, Any]:
    """The magnetometer's fit statistics as its calibration file section keeps them (plain numbers); ``rate``
    [Hz] the log's, for the lag in seconds (what ``apply`` shifts a log at another rate by)."""
    r, f = cal.report, cal.fit
    out: dict[str, Any] = {
        "status": f.status, "iterations": f.iterations, "chi2": f.chi2, "dof": f.dof,
        "field_given": cal.field_given, "field_unit": cal.field_unit,
        "soft_iron": "full" if cal.full_soft_iron else ("symmetric" if cal.soft_iron is not None else "ellipsoid"),
        "misalignment_deg": math.degrees(cal.misalignment),
        "norm_residual_pct": {"before": r.norm_pct.before, "after": r.norm_pct.after, "floor": r.norm_pct.floor},
        "n_poses": len(r.poses),
    }
    if r.dip_deg is not None:
        out["dip_scatter_deg"] = {"before": r.dip_deg.before, "unaligned": r.dip_deg.unaligned,
                                  "after": r.dip_deg.after, "floor": r.dip_deg.floor}
    if cal.soft_iron is not None:
        out["soft_iron_test"] = {"f": cal.soft_iron.f, "p": cal.soft_iron.p, "level": cal.soft_iron.level}
    if cal.lag is not None:
        out["lag_samples"] = cal.lag.samples
        if rate is not None and math.isfinite(rate) and rate > 0:
            out["lag_s"] = cal.lag.samples / rate
    if cal.axes is not None:
        out["mounting_agrees_with_closed_form"] = bool(cal.axes.agrees)
    if cal.steps is not None and cal.steps.disturbed:
        out["field_step_after_pose"] = cal.steps.step_after
        out["field_step_pct"] = 100.0 * cal.steps.step
    if cal.excluded:
        out["excluded_poses"] = [[int(o.start), int(o.end)] for o in cal.excluded]
    if cal.left_handed is not None:
        out["left_handed"] = bool(cal.left_handed)
    return out


def calibrated(cal: MagCalibration, rate: float | None = None) -> SensorCalibration:
    """The fitted magnetometer as one calibrated sensor of a Calibration (``rate`` [Hz]: the log's)."""
    return SensorCalibration(cal.fit.model, cal.params, dict(cal.fit.std), cal.raw_unit, fit_section(cal, rate))


def lag_samples(fit: Mapping[str, Any], rate: float) -> int:
    """The whole samples a log at ``rate`` [Hz] lags the accelerometer by, from a calibration's magnetometer
    ``fit`` section: its lag in seconds at ``rate``, else (a file without ``lag_s``) its lag in samples; 0 without
    a lag (no accelerometer) or below half a sample."""
    sec = fit.get("lag_s")
    if isinstance(sec, (int, float)) and math.isfinite(sec) and math.isfinite(rate) and rate > 0:
        samples = sec * rate
    else:
        samples = fit.get("lag_samples", 0.0)
    return int(round(samples)) if isinstance(samples, (int, float)) and math.isfinite(samples) else 0


def aligned(sensor: SensorCalibration, mag: np.ndarray, rate: float, unit: str = "raw") -> tuple[np.ndarray, int]:
    """A log's mx, my, mz on the accelerometer's samples (``imucal apply``): in the calibration's input unit when
    both the log (``unit``, a netCDF variable's) and the calibration name field units, moved earlier by the
    calibration's lag in whole samples at ``rate`` [Hz] (``lag_samples``), and that count (0: unchanged)."""
    if is_field_unit(unit) and is_field_unit(sensor.raw_unit) and unit != sensor.raw_unit:
        mag = np.asarray(mag, float) * convert(1.0, unit, sensor.raw_unit)
    samples = lag_samples(sensor.fit, rate)
    return (shift_lag(np.asarray(mag, float), samples) if samples else mag), samples


def field_error(sensor: SensorCalibration, calibrated: np.ndarray, source: str | None = None) -> ImucalError | None:
    """The refusal of a log whose calibrated |h| (median over its samples) is more than UNIT_SCALE_FACTOR off the
    calibration's field F: its readings are in another unit than the calibration takes (nT for uT: a factor 1000;
    Earth's field differs between places by less, imucal.mag.units.EARTH_FIELD_UT); None when it fits."""
    h = np.linalg.norm(np.asarray(calibrated, float), axis=1)
    h = h[np.isfinite(h)]
    F, unit = float(sensor.params["F"].value), sensor.model.output.unit
    if h.size == 0 or not F > 0:
        return None
    med = float(np.median(h))
    if 1.0 / UNIT_SCALE_FACTOR <= med / F <= UNIT_SCALE_FACTOR:
        return None
    return ImucalError(f"|h| after calibration is {med:.4g} {unit} (median of {h.size} samples), where the "
                       f"calibration's field is {F:.4g} {unit}: mx, my, mz are not in its input unit {sensor.raw_unit}",
                       file=source, field="data.columns.mx",
                       fix=f"give mx, my, mz in {sensor.raw_unit}, or apply the calibration made for data in their "
                           "unit; --no-gravity-check writes the output anyway")


def shift_lag(mag: np.ndarray, samples: int) -> np.ndarray:
    """mx, my, mz moved ``samples`` earlier (mag[k] belongs with acc[k - samples]: imucal.mag.evidence.Lag): row k
    holds mag[k + samples]; rows with no reading that late (or early) are NaN, never a reading repeated."""
    out = np.full(mag.shape, np.nan)
    n = len(mag)
    if abs(samples) >= n:
        return out
    if samples >= 0:
        out[:n - samples] = mag[samples:]
    else:
        out[-samples:] = mag[:n + samples]
    return out
