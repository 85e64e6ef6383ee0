"""The data of a gyro fit: one time base, static intervals, and the motion segments between them.

A motion that holds a gap of the time stamps (samples missing: imucal.data.timebase) cannot be
integrated: the rotation during the gap is unknown. ``motion_segments`` leaves every such motion
out of the segments and names it (``GapMotion``), so that no fit or score integrates across a gap.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np

from imucal.errors import ImucalError
from imucal.solve.stats import median


@dataclass(frozen=True)
class GyroData:
    """Gyro and calibrated accelerometer samples on one time base, with the static intervals.

    ``acc`` is the calibrated specific force [m/s^2] in the accelerometer's orthonormal output
    frame; it gives the gravity direction of each static interval and feeds the g-sensitivity.
    """

    t: np.ndarray  #: (N,) [s]
    gyro: np.ndarray  #: (N, 3) gyro readings [``unit``]
    acc: np.ndarray  #: (N, 3) calibrated acceleration [m/s^2]
    start: np.ndarray  #: first sample index of each static interval
    end: np.ndarray  #: one past the last sample index of each static interval
    unit: str = "raw"  #: gyro unit: raw, rad/s or deg/s
    source: str | None = None
    #: (k, 2) the gaps in the time stamps (samples missing: Recording.time_base), each as the times [s]
    #: of the samples on either side of it, on ``t``'s time base (``gap_spans``)
    gaps: np.ndarray = field(default_factory=lambda: np.empty((0, 2)))

    def __post_init__(self) -> None:
        n = self.t.shape[0]
        if self.gyro.shape != (n, 3) or self.acc.shape != (n, 3):
            raise ImucalError(f"gyro {self.gyro.shape} and acc {self.acc.shape} must both be ({n}, 3)",
                              file=self.source, field="gyro", fix="give both sensors on one time base")
        if self.start.size < 2:
            raise ImucalError("a gyro fit needs at least two static intervals with a motion between them",
                              file=self.source, field="intervals",
                              fix="record several still poses with rotations between them")

    @property
    def n_intervals(self) -> int:
        return int(self.start.size)

    def static_means(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Per static interval: gyro mean, its standard error, acceleration mean and its standard error
        (read-only arrays, computed once: the stillness test, the static fit and the segments ask)."""
        return self._static_means

    @cached_property
    def _static_means(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        g, gs, a, as_ = [], [], [], []
        for i0, i1 in zip(self.start, self.end):
            n = i1 - i0
            g.append(self.gyro[i0:i1].mean(0))
            gs.append(self.gyro[i0:i1].std(0, ddof=1) / np.sqrt(n))
            a.append(self.acc[i0:i1].mean(0))
            as_.append(self.acc[i0:i1].std(0, ddof=1) / np.sqrt(n))
        out = np.array(g), np.array(gs), np.array(a), np.array(as_)
        for x in out:
            x.flags.writeable = False
        return out

    def without(self, keep: np.ndarray) -> "GyroData":
        """The same samples with only the static intervals ``keep`` (bool per interval) as still poses."""
        keep = np.asarray(keep, bool)
        return replace(self, start=self.start[keep], end=self.end[keep])

    def static_rate_noise(self) -> np.ndarray:
        """Within-interval standard deviation of the gyro readings, pooled over intervals [``unit``]."""
        dev = np.concatenate([self.gyro[i0:i1] - self.gyro[i0:i1].mean(0) for i0, i1 in zip(self.start, self.end)])
        return dev.std(0)


@dataclass(frozen=True)
class GapMotion:
    """A motion left out of the gyro fit: its time stamps have a gap (samples missing) inside it."""

    segment: int  #: k: the motion between still poses k and k+1 (of those the fit kept)
    t_start: float  #: [s] where its integration would have started
    t_end: float  #: [s] where it would have ended
    n_gaps: int  #: gaps inside it
    longest_gap: float  #: [s] the longest step across one of them


@dataclass(frozen=True)
class Segments:
    """Motion segments k: from the last sample of static interval k to the first of interval k+1."""

    first: np.ndarray  #: first sample index of each segment
    last: np.ndarray  #: last sample index of each segment
    u0: np.ndarray  #: (n, 3) gravity direction at the start (unit, accelerometer frame)
    u1: np.ndarray  #: (n, 3) gravity direction at the end
    sigma_u: np.ndarray  #: (n,) standard error of one component of u0 - u1 from the static means [rad]
    index: np.ndarray  #: segment numbers (k: between intervals k and k+1)
    gapped: tuple[GapMotion, ...] = ()  #: the motions left out because a gap lies inside them

    @property
    def n(self) -> int:
        return int(self.first.size)

    @property
    def lengths(self) -> tuple[int, ...]:
        """Number of integration steps per segment: the shape of the NLP."""
        return tuple(int(v) for v in self.last - self.first)

    def subset(self, keep: np.ndarray) -> "Segments":
        return Segments(self.first[keep], self.last[keep], self.u0[keep], self.u1[keep], self.sigma_u[keep],
                        self.index[keep], self.gapped)


def motion_segments(data: GyroData, lead_in: float = 0.0) -> Segments:
    """All motion segments between consecutive static intervals, with the measured gravity directions.

    ``lead_in`` [s]: integrate from this far before the end of a still pose to this far after the
    start of the next (at most a quarter of each pose), since a static detector's window can hold
    a motion's first or last moments; the directions stay the whole poses' means. A motion whose
    integration span t[first]..t[last] overlaps a gap of ``data.gaps`` is left out and named in
    ``Segments.gapped``.
    """
    _, _, a, a_se = data.static_means()
    norm = np.linalg.norm(a, axis=1)
    u = a / norm[:, None]
    sig = np.sqrt(np.mean(a_se**2, axis=1)) / norm  # one component of a direction's error [rad]
    k = np.zeros(data.start.size, int)
    if lead_in > 0:
        k = np.minimum(int(round(lead_in / median(np.diff(data.t)))), (data.end - data.start) // 4)
    first = data.end[:-1] - 1 - k[:-1]
    last = data.start[1:] + k[1:]
    if np.any(last <= first):
        raise ImucalError("static intervals overlap or are out of order", file=data.source, field="intervals",
                          fix="give intervals sorted by time and disjoint")
    k = np.arange(first.size)
    seg = Segments(first, last, u[:-1], u[1:], np.sqrt(sig[:-1] ** 2 + sig[1:] ** 2), k)
    return _without_gaps(seg, data)


def _without_gaps(seg: Segments, data: GyroData) -> Segments:
    """``seg`` less the motions whose integration span overlaps a gap (a gap's span lies between two
    samples: one inside a motion's steps overlaps it, one that ends at its first sample does not)."""
    gaps = np.asarray(data.gaps, float).reshape(-1, 2)
    if gaps.size == 0:
        return seg
    t0, t1 = data.t[seg.first], data.t[seg.last]  # both increasing: the motions are disjoint, in order
    lo = np.searchsorted(t1, gaps[:, 0], side="right")  # the first motion ending after the gap starts
    hi = np.searchsorted(t0, gaps[:, 1], side="left")  # past the last motion starting before it ends
    some = np.flatnonzero(hi > lo)  # the gaps inside some motion (most lie in still poses)
    if some.size == 0:
        return seg
    motion = np.concatenate([np.arange(lo[j], hi[j]) for j in some])
    length = np.repeat(gaps[some, 1] - gaps[some, 0], hi[some] - lo[some])
    count, longest = np.zeros(seg.n, int), np.zeros(seg.n)
    np.add.at(count, motion, 1)
    np.maximum.at(longest, motion, length)
    hit = count > 0
    gapped = tuple(GapMotion(int(seg.index[k]), float(t0[k]), float(t1[k]), int(count[k]), float(longest[k]))
                   for k in np.flatnonzero(hit))
    return replace(seg.subset(~hit), gapped=gapped)


def gap_spans(t: np.ndarray, after: np.ndarray) -> np.ndarray:
    """(k, 2) the times [s] on either side of each gap, from the samples ``after`` the gaps."""
    i = np.asarray(after, np.int64)
    return np.column_stack([t[i - 1], t[i]]) if i.size else np.empty((0, 2))


def interpolate(t_target: np.ndarray, t_src: np.ndarray, x_src: np.ndarray) -> np.ndarray:
    """Linear interpolation of (N, 3) samples onto another time base (a gyro at another rate)."""
    if np.any(np.diff(t_src) <= 0):
        raise ImucalError("time stamps must increase strictly", field="t", fix="sort the samples by time")
    if t_target[0] < t_src[0] or t_target[-1] > t_src[-1]:
        raise ImucalError("the other sensor does not cover the whole time span", field="t",
                          fix="trim the recording to the time both sensors were sampled")
    return np.column_stack([np.interp(t_target, t_src, x_src[:, j]) for j in range(x_src.shape[1])])


def gyro_data_from_run(run, gyro_t: np.ndarray, gyro_raw: np.ndarray, unit: str = "raw",
                       acc_t0: float | None = None, gyro_gaps: np.ndarray | None = None) -> GyroData:
    """GyroData from an accelerometer ``CalibrationRun`` and the gyro channel.

    The loader starts the accelerometer's time at 0; ``acc_t0`` is its first time stamp in the
    gyro's clock (default: the gyro's first time stamp). A gyro with as many samples as the
    accelerometer is taken sample by sample (same time stamps); otherwise it is interpolated.
    The gaps are the accelerometer's time base's and, for an interpolated gyro, its own
    (``gyro_gaps``: its samples after a gap), on the accelerometer's clock.
    """
    t = run.recording.t
    acc = run.calibration.apply(run.recording.raw)
    g = np.asarray(gyro_raw, float)
    tb = getattr(run.recording, "time_base", None)
    gaps = gap_spans(t, np.empty(0, np.int64) if tb is None else tb.gap_index)
    if g.shape[0] != t.shape[0]:
        tg = np.asarray(gyro_t, float) - (gyro_t[0] if acc_t0 is None else acc_t0)
        g = interpolate(t, tg, g)
        if gyro_gaps is not None:
            gaps = np.vstack([gaps, gap_spans(tg, gyro_gaps)])
    return GyroData(t=t, gyro=g, acc=acc, start=run.intervals.start, end=run.intervals.end, unit=unit,
                    source=run.recording.source, gaps=gaps)
