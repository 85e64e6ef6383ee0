"""Is the default gyro fit no worse than the fit without the intervals it found not still? (issue 25)

For one recording: the default fit (static intervals judged on the gyro too, imucal.gyro.still),
the fit of the same recording with the rejected intervals removed before fitting (every remaining
interval taken as still), and the fit that takes every static interval as still (``still="off"``,
the behaviour before issue 25). All three are scored by one formula (imucal.gyro.evaluate) on the
same motions: those between the intervals kept, whose both ends are still for the gyro, with the
default fit's lead-in.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from imucal.gyro.evaluate import direction_errors_deg, rms
from imucal.gyro.fit import GyroOptions, fit_gyro
from imucal.gyro.result import motions
from imucal.solve.fit import FitResult
from imucal.gyro.run import gyro_data
from imucal.gyro.segments import GyroData, motion_segments
from imucal.gyro.still import NotStill

#: "no worse" allows this relative excess [1]: the two fits solve the same problem, so they agree
#: to rounding; anything beyond is a real difference
SAME_RTOL = 1e-9


@dataclass(frozen=True)
class StillCheck:
    """RMS gravity-direction errors [deg] of three gyro fits of one recording on the same motions."""

    source: str | None
    n_intervals: int  #: static intervals found (on the accelerometer)
    rejected: tuple[NotStill, ...]  #: those the default fit found not still for the gyro
    n_segments: int  #: motions scored: between the intervals kept
    default_deg: float  #: the default fit
    removed_deg: float  #: the fit with the rejected intervals removed from the recording's still poses
    all_still_deg: float  #: the fit taking every static interval as still (gyro still "off")

    @property
    def no_worse(self) -> bool:
        """The default fit's error is no worse than the fit without the rejected intervals."""
        return bool(self.default_deg <= self.removed_deg * (1 + SAME_RTOL))


def _score(data: GyroData, res: FitResult, scored: GyroData, lead_in: float) -> float:
    return rms(direction_errors_deg(data.t, res.apply(data.gyro, data.acc), motion_segments(scored, lead_in)))


def still_check(data: GyroData, options: GyroOptions = GyroOptions()) -> StillCheck:
    """The three fits of ``data`` (``options`` as the run's, stillness judged as its ``still`` says)."""
    default = fit_gyro(data, replace(options, still="auto"))
    still = motions(default).still
    keep = still.keep if still is not None else np.ones(data.n_intervals, bool)
    kept = data.without(keep)
    removed = fit_gyro(kept, replace(options, still="off"))
    every = fit_gyro(data, replace(options, still="off"))
    lead = motions(default).lead_in_s
    return StillCheck(data.source, data.n_intervals, () if still is None else still.rejected,
                      int(keep.sum()) - 1, _score(data, default, kept, lead), _score(data, removed, kept, lead),
                      _score(data, every, kept, lead))


def run_still_check(run, gyro_file: str | None = None) -> StillCheck | None:
    """``still_check`` of an accelerometer run (imucal.pipeline.calibrate_accelerometer's CalibrationRun) with the
    gyro options of its configuration; None when the recording has no gyroscope. ``gyro_file``:
    imu_tk's second file; default the configuration's ``data.gyro_path`` (relative to the YAML file)."""
    cfg = run.config
    if gyro_file is None and cfg.data.gyro_path is not None:
        p = Path(cfg.data.gyro_path)
        gyro_file = str(p if p.is_absolute() or cfg.base_dir is None else cfg.base_dir / p)
    got = gyro_data(run, gyro_file)
    if got is None:
        return None
    return still_check(got[0], GyroOptions(**cfg.gyro.fit_choices))
