"""The evidence of a temperature sweep: still intervals cut into rows at temperature steps.

A row is a run of still samples within TEMPERATURE_STEP of its first sample's temperature (and
never across a gap of the time base): one point of the pose's reading against temperature. A
cold soak of twelve hours is one row, a warm-up of ten degrees forty: the rows weigh temperature,
not time, so a slow drift during a soak (which no temperature term can explain) is not counted
hundreds of times. Each row keeps its interval: the pose, whose gravity vector is one unknown.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from imucal.data.recording import Recording
from imucal.data.static import Intervals
from imucal.model.effects import MIN_TEMPERATURE_SPREAD

#: A row spans at most this change of temperature [degC]: well below the curvature of a MEMS part's
#: bias(T) (a few mg over 20 degC), well above a temperature sensor's resolution. Closer rows are
#: alike in their misfit (the slow drift): on the real sweep, consecutive 0.25 degC rows' residuals
#: correlate at 0.8-0.9, and the order test then took drift for curvature (docs/thermal.md).
TEMPERATURE_STEP = 0.5
#: Fewest samples of a row: shorter runs join the next row (a fast cool-down at a low rate).
MIN_ROW_SAMPLES = 10
#: A pose carries temperature evidence when its rows span at least this [degC] (the grammar's own
#: threshold of a temperature effect, imucal.model.effects.MIN_TEMPERATURE_SPREAD).
POSE_SPREAD = MIN_TEMPERATURE_SPREAD
#: A recording is a temperature sweep (its calibration's temperature terms come from its poses' own
#: constancy, imucal.thermal.run) when one still pose spans at least this [degC], four rows: a term of a
#: few mg per degC then moves the pose's reading far above its noise. A multi-pose log whose holds of
#: seconds drift through a few tenths of a degree while warming is calibrated on |a| = g instead
#: (imucal.analysis.discover): there the temperature changes between poses, not within them.
SWEEP_SPAN = 4 * TEMPERATURE_STEP


@dataclass(frozen=True)
class ThermalRows:
    """Rows of still samples at nearly one temperature each, with the pose each belongs to."""

    raw: np.ndarray  #: (n, 3) mean raw reading
    temp: np.ndarray  #: (n,) mean temperature [degC]
    t: np.ndarray  #: (n,) mean time [s]
    pose: np.ndarray  #: (n,) index of the still interval (pose) of each row
    n_samples: np.ndarray  #: (n,)
    var: np.ndarray  #: (n, 3) variance of each mean [raw^2] (its samples' scatter / count)
    gyro: np.ndarray | None  #: (n, 3) mean angular rate, when the recording has one
    start: np.ndarray  #: (n,) first sample of each row
    end: np.ndarray  #: (n,) one past its last sample

    @property
    def n(self) -> int:
        return int(self.temp.size)

    @property
    def poses(self) -> np.ndarray:
        """The pose indices that have rows, ascending."""
        return np.unique(self.pose)

    def span(self, pose: int) -> tuple[float, float]:
        """[degC] the temperature range of a pose's rows."""
        t = self.temp[self.pose == pose]
        return float(t.min()), float(t.max())

    @property
    def is_sweep(self) -> bool:
        """Whether one pose's rows span SWEEP_SPAN or more."""
        return any(np.ptp(self.temp[self.pose == p]) >= SWEEP_SPAN for p in self.poses)

    def sweeping(self) -> np.ndarray:
        """The poses whose rows span at least POSE_SPREAD: those that carry temperature evidence."""
        return np.array([p for p in self.poses if np.ptp(self.temp[self.pose == p]) >= POSE_SPREAD], int)

    def subset(self, keep: np.ndarray) -> "ThermalRows":
        k = np.asarray(keep)
        return ThermalRows(self.raw[k], self.temp[k], self.t[k], self.pose[k], self.n_samples[k], self.var[k],
                           None if self.gyro is None else self.gyro[k], self.start[k], self.end[k])


def _runs(idx: np.ndarray, temp: np.ndarray, t: np.ndarray, gap: float, step: float) -> list[tuple[int, int]]:
    """Rows [s, e) within one interval's samples ``idx``: a new row where the temperature left the
    row's first by ``step``, or at a gap (of the time base, or of samples left out); rows of fewer
    than MIN_ROW_SAMPLES join the next, and end short at a gap (dropped)."""
    out, k0 = [], 0
    for k in range(1, idx.size + 1):
        broken = k == idx.size or idx[k] - idx[k - 1] > 1 or t[idx[k]] - t[idx[k - 1]] > gap
        if broken or (abs(temp[idx[k]] - temp[idx[k0]]) >= step and k - k0 >= MIN_ROW_SAMPLES):
            if k - k0 >= MIN_ROW_SAMPLES:
                out.append((k0, k))
            k0 = k
    return out


def thermal_rows(rec: Recording, iv: Intervals, step: float = TEMPERATURE_STEP,
                 keep: np.ndarray | None = None) -> ThermalRows | None:
    """The rows of every still interval of ``rec`` (None without a temperature channel);
    ``keep``: a mask of the samples to use (a study's fit part), the others are gaps."""
    if rec.temp is None:
        return None
    dt = 1.0 / rec.sample_rate if np.isfinite(rec.sample_rate) and rec.sample_rate > 0 else np.inf
    gap = 1.5 * dt  # a step longer than 1.5 samples is a gap (imucal.data.timebase.GAP_STEPS)
    cols: dict[str, list] = {k: [] for k in ("raw", "temp", "t", "pose", "n", "var", "gyro", "start", "end")}
    for p, (a, b) in enumerate(zip(iv.start, iv.end)):
        idx = np.arange(a, b) if keep is None else a + np.flatnonzero(keep[a:b])
        for s, e in _runs(idx, rec.temp, rec.t, gap, step):
            rows = idx[s:e]  # consecutive samples
            i0, i1 = int(rows[0]), int(rows[-1]) + 1
            x = rec.raw[i0:i1]
            cols["raw"].append(x.mean(axis=0))
            cols["var"].append(x.var(axis=0, ddof=1) / (i1 - i0))
            cols["temp"].append(float(rec.temp[i0:i1].mean()))
            cols["t"].append(float(rec.t[i0:i1].mean()))
            cols["pose"].append(p)
            cols["n"].append(i1 - i0)
            cols["start"].append(i0)
            cols["end"].append(i1)
            if rec.gyro is not None:
                cols["gyro"].append(rec.gyro[i0:i1].mean(axis=0))
    if not cols["temp"]:
        return None
    return ThermalRows(raw=np.array(cols["raw"]), temp=np.array(cols["temp"]), t=np.array(cols["t"]),
                       pose=np.array(cols["pose"], int), n_samples=np.array(cols["n"], int),
                       var=np.array(cols["var"]), gyro=np.array(cols["gyro"]) if cols["gyro"] else None,
                       start=np.array(cols["start"], int), end=np.array(cols["end"], int))
