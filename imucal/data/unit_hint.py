"""The time unit a run's stamps look like when it finds too few still poses: the refusal that
names it (minutes read as seconds find one long pose). Above the readers: it detects the poses
again with the stamps read in another unit (imucal.data.static, or imucal.data.stream for a file
read in chunks).
"""
from __future__ import annotations

import math
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from imucal.constants import TIME_UNITS
from imucal.data.recording import MAX_RATE_HZ, MIN_RATE_HZ, Recording, RecordingSummary, TimeSource
from imucal.data.static import detect_static
from imucal.data.timebase import JITTER_FRACTION, decades_from_typical
from imucal.errors import ImucalError
from imucal.solve.observability import distinct_directions

if TYPE_CHECKING:
    from imucal.config.run import RunConfig

#: Distinct orientations the stamps read in another unit must show before that unit is named as
#: the likely one: a single pose read on a wrong time scale may split into runs, all one way.
HINT_MIN_POSES = 3
#: ... and read in a unit that gives a less usual rate than the one inferred (1 Hz in seconds where a step
#: of 1 was inferred as 1 kHz in milliseconds: a temperature logger's): as many as a calibration needs, since
#: a slowly moving log read on a slower time scale may look still in short runs.
HINT_MIN_POSES_LESS_USUAL = 6
#: Words for a unit in a message.
_UNIT_WORDS = {"min": "minutes", "s": "seconds", "ms": "milliseconds", "us": "microseconds", "ns": "nanoseconds"}


def unit_hint(config: RunConfig, rec: Recording | RecordingSummary, found: int,
              rails: dict | None = None) -> ImucalError | None:
    """The refusal to give when a run finds fewer than two still poses (``found``) on a stamped
    recording but HINT_MIN_POSES or more distinct ones with its stamps read in another unit that
    gives a more usual rate (closer to TYPICAL_RATE_HZ: minutes, which are never inferred, or
    another), or, when the unit was inferred, HINT_MIN_POSES_LESS_USUAL with the stamps read in a unit that
    gives a less usual one (a 1 Hz logger's seconds read as milliseconds): the time unit looks like that one.
    None otherwise (a log that only moves, read 60 times slower, may look still).
    Only on that failure: each unit tried costs one more detection (a re-read for a file read in
    chunks)."""
    tb = rec.time_base
    if tb is None or tb.source is TimeSource.RATE or not math.isfinite(tb.rate):
        return None
    best: tuple[int, str, float] | None = None
    # good stamps' own rate: lost samples (a logger's dropouts) slow the clock's (imucal.data.timebase.check_rate)
    own = tb.rate if tb.short_fraction > JITTER_FRACTION or not tb.median_step > 0 else 1.0 / tb.median_step
    for unit, f in TIME_UNITS.items():
        rate = own * TIME_UNITS[rec.time_unit] / f
        usual = decades_from_typical(rate) < decades_from_typical(own)
        if unit == rec.time_unit or not MIN_RATE_HZ <= rate <= MAX_RATE_HZ or not (
                usual or config.data.time_unit == "auto"):
            continue  # a unit that gives a more usual rate (the inference's rule), or any, when it was inferred
        poses = _poses_in(config, rec, unit, f / TIME_UNITS[rec.time_unit], rails)
        least = HINT_MIN_POSES if usual else HINT_MIN_POSES_LESS_USUAL
        if poses >= max(least, found + 1) and (best is None or poses > best[0]):
            best = (poses, unit, rate)
    if best is None:
        return None
    poses, unit, rate = best
    return ImucalError(f"the time column read in {rec.time_unit} gives {own:.4g} Hz and {found} still pose(s); "
                       f"read in {unit} it gives {rate:.4g} Hz and {poses} distinct still poses: the time unit looks "
                       f"like {_UNIT_WORDS[unit]}", file=rec.source, field="data.time_unit",
                       fix=f"give --time-unit {unit} (data.time_unit: {unit})"
                           + (", or write the time column in seconds" if unit == "min" else ""))


def _poses_in(config: RunConfig, rec: Recording | RecordingSummary, unit: str, scale: float,
              rails: dict | None) -> int:
    """Distinct orientations of the still intervals found with the stamps read in ``unit``
    (``scale``: that unit's factor over the one read)."""
    try:
        if rec.t is not None:  # read whole: the same time base on another scale
            iv = detect_static(rec.t * scale, rec.raw, config.static, rec.temp, source=rec.source, rails=rails)
        else:
            from imucal.data.stream import StreamedRecording  # measured start-up: a file read in chunks

            iv = StreamedRecording(replace(config.data, time_unit=unit), config.static, config.base_dir,
                                   rails).intervals
    except ImucalError:
        return 0
    if iv.n == 0:
        return 0
    norm = np.linalg.norm(iv.mean, axis=1, keepdims=True)
    return distinct_directions(iv.mean[norm[:, 0] > 0] / norm[norm[:, 0] > 0])[0]
