"""The magnetometer in a run (issue 26): fitted when the recording has mx, my, mz, attached to the calibration.

``calibrate_imu`` (imucal.pipeline) calls ``mag_of_run`` after the accelerometer (and the gyroscope): the
magnetometer's rows read the calibrated acceleration of the same samples and the accelerometer's still
intervals are its poses; ``calibrated`` turns the result into the one value every output reads
(imucal.calibration.sensor.SensorCalibration: the file section, apply, the C and the exports).
"""
from __future__ import annotations

import datetime as dt
import math
from typing import Any

import numpy as np

from imucal.calibration.sensor import SensorCalibration
from imucal.config.run import MagConfig
from imucal.mag.calibrate import MagSettings, calibrate_mag
from imucal.mag.evidence import Poses
from imucal.mag.field_model import Place
from imucal.mag.result import MagCalibration


def settings_of(cfg: MagConfig) -> MagSettings:
    """The fit's settings from the run file's ``mag:`` section (the place's date parsed here)."""
    place = None
    if cfg.latitude is not None and cfg.longitude is not None and cfg.date is not None:
        place = Place(float(cfg.latitude), float(cfg.longitude), dt.date.fromisoformat(cfg.date), float(cfg.height))
    lag = None if cfg.lag is None else float(cfg.lag)
    return MagSettings(field=cfg.field, field_unit=cfg.field_unit, dip_deg=cfg.dip_deg, soft_iron=cfg.soft_iron,
                       window=int(cfg.window), lag=lag, place=place)


def mag_of_run(mag: np.ndarray, acc: np.ndarray, start: np.ndarray, end: np.ndarray, cfg: MagConfig,
               source: str | None = None) -> MagCalibration:
    """The magnetometer's calibration from its readings, the calibrated acceleration of the same samples and
    the accelerometer's still intervals [start, end)."""
    still = Poses(np.asarray(start, int), np.asarray(end, int), "still intervals")
    return calibrate_mag(mag, acc, still=still, settings=settings_of(cfg), raw_unit=cfg.unit, source=source)


def fit_section(cal: MagCalibration) -> dict[str, Any]:
    """The magnetometer's fit statistics as its calibration file section keeps them (plain numbers)."""
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


def calibrated(cal: MagCalibration) -> SensorCalibration:
    """The fitted magnetometer as one calibrated sensor of a Calibration."""
    return SensorCalibration(cal.fit.model, cal.params, dict(cal.fit.std), cal.raw_unit, fit_section(cal))
