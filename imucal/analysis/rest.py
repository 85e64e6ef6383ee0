"""Does a calibration fit the data it is applied to? |a| at rest against the calibration's gravity.

A calibration maps readings in one unit (raw counts, m/s^2, g ...) to m/s^2. Applied to readings in
another unit it still gives numbers, off by the ratio of the units. Where the data hold still spans,
the calibrated |a| there must be the calibration's gravity; a unit mistake misses it by a factor
(9.81, 1000, 2^14 ...), a sensor that aged since its calibration by a few per cent.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from imucal.constants import STANDARD_GRAVITY
from imucal.data.header_names import without_unit
from imucal.data.static import Intervals, quantum
from imucal.errors import ImucalError, key_text
from imucal.solve.stats import median

#: Largest relative difference between |a| at rest after calibration and the calibration's gravity
#: that passes (10 %): a unit mistake is a factor of 9.81 or more, a calibration that aged or a
#: gravity of another place a few per cent at most.
REST_TOLERANCE = 0.10
#: Units a reading's |value| at rest reveals (that value in each), tried in this order.
REST_UNITS: tuple[tuple[str, float], ...] = (("m/s^2", STANDARD_GRAVITY), ("g", 1.0), ("mg", 1000.0))


@dataclass(frozen=True)
class RestCheck:
    """|a| at rest after a calibration, over the still intervals of the data it was applied to."""

    at_rest: float  #: median over the intervals of |mean calibrated a| [m/s^2]
    gravity: float  #: the calibration's gravity [m/s^2]
    intervals: int  #: still intervals it was measured on
    raw_at_rest: float  #: median over the intervals of |mean reading| [the data's unit]
    integer: bool  #: the readings are whole numbers (counts)
    cal_unit: str  #: the unit the calibration takes

    @property
    def ratio(self) -> float:
        return self.at_rest / self.gravity

    @property
    def ok(self) -> bool:
        return bool(abs(self.ratio - 1.0) <= REST_TOLERANCE)

    @property
    def data_looks_like(self) -> str | None:
        """The unit whose gravity the readings' |value| at rest is (within REST_TOLERANCE), "raw
        counts" for whole numbers that are none of them, else None."""
        for unit, g in REST_UNITS:
            if abs(self.raw_at_rest / g - 1.0) <= REST_TOLERANCE:
                return unit
        return "raw counts" if self.integer else None


#: A recording stated in a unit of acceleration whose |reading| at rest is more than this factor off that unit's
#: gravity is in another unit: a sensor's scale and offset errors move it by per cent (10 % on a poor one), a unit
#: mistake by 9.81 or 1000.
STATED_UNIT_FACTOR = 2.0


#: |reading| at rest below this fraction of the stated unit's gravity, in no unit's gravity: gravity removed.
NO_GRAVITY = 0.05


def stated_unit_error(unit: str, means: np.ndarray, source: str | None = None,
                      stated_by: str = "") -> ImucalError | None:
    """The refusal of readings stated in ``unit`` (one of REST_UNITS: m/s^2, g, mg) whose |reading| at rest (the
    median |mean| of still intervals ``means``) is not that unit's gravity within STATED_UNIT_FACTOR: the fit would
    be fine in the readings' unit, but the calibration would carry the wrong one into apply and the exports (PX4's
    and ArduPilot's convert g to m/s^2); None when it fits or the unit is not one of them (raw counts).
    ``stated_by``: the header's column that stated the unit (its fix is then the header's, not data.unit)."""
    g = dict(REST_UNITS).get(unit)
    if g is None or len(means) == 0:
        return None
    at_rest = median([float(np.linalg.norm(m)) for m in np.asarray(means, float)])
    if 1.0 / STATED_UNIT_FACTOR <= at_rest / g <= STATED_UNIT_FACTOR:
        return None
    looks = next((u for u, gu in REST_UNITS if abs(at_rest / gu - 1.0) <= REST_TOLERANCE), None)
    if not looks and at_rest / g < NO_GRAVITY:
        hint = ("still readings without gravity are an acceleration with gravity removed (a phone's or a filter's "
                "linear acceleration), which cannot calibrate an accelerometer: record the sensor's own readings "
                "(phyphox: Acceleration with g)")
    elif stated_by:  # the header's names state the unit: only the file can be corrected
        hint = (f"the header states {unit} (column {key_text(stated_by)}): correct the header's unit, e.g. "
                f"{key_text(without_unit(stated_by))} [{looks or 'counts'}]")
    elif looks:
        hint = (f"they look like {looks}: give data.unit {looks} (--unit {looks}; a netCDF file: its variable's units "
                "attribute)")
    else:
        hint = "give data.unit raw for counts"
    return ImucalError(f"the readings at rest are {at_rest:.4g} {unit} (median |mean| of {len(means)} still intervals), "
                       f"where readings in {unit} are {g:g}: they are not in {unit}", file=source, field="data.unit",
                       fix=hint)


def rest_check(calibrated: np.ndarray, raw: np.ndarray, intervals: Intervals, gravity: float,
               cal_unit: str) -> RestCheck | None:
    """The check of ``calibrated`` (the calibration applied to ``raw``, one row per sample) on the
    still ``intervals`` of ``raw``; None when there is none."""
    if intervals.n == 0:
        return None
    spans = list(zip(intervals.start, intervals.end))
    a = [float(np.linalg.norm(calibrated[s:e].mean(axis=0))) for s, e in spans]
    r = [float(np.linalg.norm(raw[s:e].mean(axis=0))) for s, e in spans]
    return RestCheck(at_rest=median(a), gravity=float(gravity), intervals=len(spans), raw_at_rest=median(r),
                     integer=quantum(raw) == 1.0, cal_unit=cal_unit)


#: Samples beyond the fitted temperature range by more than this fraction of it are named: the range is the rows'
#: mean temperatures, single samples stray a little beyond it (a tenth of a degree on a 20 degC sweep).
SPAN_MARGIN = 0.1


@dataclass(frozen=True)
class TemperatureSpan:
    """The data's temperatures against the range a calibration's temperature terms were fitted over (its
    sensors' ``fit.temperature_range``, the narrowest): outside it the terms are extrapolated, where the
    autopilots hold the end value (imucal.export.tempcal)."""

    tmin: float  #: [degC] the fitted range
    tmax: float
    outside: int  #: samples outside it by more than SPAN_MARGIN of it
    low: float  #: [degC] the data's lowest and highest temperature
    high: float


def temperature_span(fits: list[object], temp: np.ndarray | None) -> TemperatureSpan | None:
    """The span check of ``temp`` against the fitted ranges in ``fits`` (the sensors' fit sections); None
    without temperatures or a range."""
    ranges = [f["temperature_range"] for f in fits if isinstance(f, dict) and f.get("temperature_range")]
    if temp is None or not len(temp) or not ranges:
        return None
    tmin, tmax = max(float(r[0]) for r in ranges), min(float(r[1]) for r in ranges)
    margin = SPAN_MARGIN * max(tmax - tmin, 0.0)
    outside = int(np.count_nonzero((temp < tmin - margin) | (temp > tmax + margin)))
    return TemperatureSpan(tmin, tmax, outside, float(np.min(temp)), float(np.max(temp)))
