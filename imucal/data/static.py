"""Static-interval detection: a moving-variance detector with an automatic threshold.

Window and minimum duration are in seconds. The threshold comes from the data: the moving
variance of a still sensor clusters at the noise floor, motion lies orders of magnitude above,
so we split log-variance into two classes (Otsu) and never go below a multiple of the noise
floor. Unlike imu_tk we do not pick, among candidate thresholds, the one whose fit has the
lowest summed cost: that rule favours fewer intervals and generalises worse. A run's edges are then
cut where its readings leave the line of its own central half (still_span): the moving variance stays
low for up to a second after a slow, smooth motion starts; a run of hours (a temperature sweep) has
each edge judged in its own neighbourhood instead (EDGE_HORIZON_WINDOWS). Below 20 Hz the default
window holds too few samples to estimate a variance: it is stretched, and the durations with it (at_rate).
"""
from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field, replace
from typing import BinaryIO

import numpy as np

from imucal.errors import ImucalError, short
from imucal.files.schema import rule
from imucal.model.channels import hold_rates
from imucal.solve.stats import median

#: Batches per interval for the batch-means estimate of a mean's noise.
_BATCHES = 8
#: Automatic saturation test: an interval's axis is clipped when at least this fraction of its
#: samples sit exactly at the recording's extreme value of that axis ...
SATURATION_FRACTION = 0.2
#: ... and its scatter on that axis is below this fraction of the axis's median scatter over the
#: intervals (a rail flattens the noise; a genuine extreme only appears in the noise's tail).
SATURATION_STD_RATIO = 0.75
#: Scatter for that test: the standard deviation of the central samples, without this fraction
#: at each end, so that a few spikes in a pose that sits on its rail do not hide the rail.
SATURATION_TRIM = 0.02
#: Rows whose values decide whether the readings are integer counts (quantisation step 1).
QUANTUM_ROWS = 20000
#: Edge test. The moving variance stays low for up to a second after a slow, smooth motion starts,
#: so a run can end inside the motion. The rows from each point out to the run's edge are compared
#: with the straight line of the run's central half (a slow drift is not motion); their noise is
#: the larger of the white noise's and the central half's own scatter over running means of
#: EDGE_WINDOW seconds (at least EDGE_MIN_SAMPLES rows), 2, 4, 8 ... times as long while the
#: central half holds EDGE_CORE_WINDOWS of them (slow noise) ...
EDGE_WINDOW = 0.1
EDGE_MIN_SAMPLES = 3
EDGE_CORE_WINDOWS = 8
#: ... rows whose mean lies more than EDGE_Z standard errors off the line are motion (5 sigma: no
#: cut in 1000 runs of 300 rows of white noise; a bias that walks by 0.5 sigma per sqrt(s) is cut) ...
EDGE_Z = 5.0
#: ... and the run ends where the running mean over EDGE_WINDOW last came within EDGE_BACK
#: standard errors of the line, walking back from the most significant such point (the motion
#: began before it showed).
EDGE_BACK = 1.0
#: A slope of the central half this many standard errors from zero is a drift, followed to the edges.
EDGE_SLOPE_Z = 3.0
#: Most cuts per run: one edge a round (the stronger), the line refitted on what is kept.
EDGE_ROUNDS = 6
#: A motion hides beneath the moving variance for about a window: a run longer than 4 x this many
#: windows has each edge judged against its own neighbourhood (its first or last 2 x this many
#: windows), not against the line of its central half. A hold of hours drifts with temperature in a
#: way no line follows, and that drift is not motion. (Holds in the real recordings last at most
#: 52 s, 4 x 40 windows = 80 s at the default 0.5 s window: judged whole, as before.)
EDGE_HORIZON_WINDOWS = 40
#: Fewest samples a moving-variance window holds: fewer cannot estimate a variance (3 samples give
#: a chi-square of 6 degrees of freedom over 3 axes, whose 5 % floor lies 4x below its mean, so the
#: automatic threshold cuts still samples). At low rates (1 Hz: 0.5 s is under one sample) the window
#: is stretched to hold them, and the minimum duration and trim with it (``at_rate``).
MIN_WINDOW_SAMPLES = 10


@dataclass(frozen=True)
class StaticSettings:
    """Detector settings (the YAML ``static:`` section). Times in seconds."""

    window: float = field(default=0.5, metadata=rule(gt=0, unit="seconds"))  #: moving-variance window [s]
    min_duration: float = field(default=1.5, metadata=rule(gt=0, unit="seconds"))  #: shortest interval kept [s]
    #: moving-variance threshold [raw^2]; None = automatic
    threshold: float | None = field(default=None, metadata=rule(
        gt=0, fix="omit it to set it automatically from the data"))
    trim: float = field(default=0.25, metadata=rule(ge=0, unit="seconds"))  #: dropped from each end of an interval [s]
    #: times [s from the first sample] at which a still interval is cut in two: a knock or a bias step
    #: during a hold (imucal discover finds them, a bias_step term's time adds its own); each part is
    #: judged as an interval of its own (edges, minimum duration)
    split: tuple[float, ...] = field(default=(), metadata=rule(max_len=100000, unit="seconds"))

    def __post_init__(self) -> None:
        for name in ("window", "min_duration"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v) and v > 0):
                raise ImucalError(f"{name} {short(v)} must be a positive number of seconds",
                                  field=f"static.{name}", fix=f"give {name} in seconds above 0, e.g. {name}: 1.0")
        if not (isinstance(self.trim, (int, float)) and np.isfinite(self.trim) and self.trim >= 0):
            raise ImucalError(f"trim {short(self.trim)} must be a non-negative number of seconds",
                              field="static.trim", fix="give trim in seconds, 0 or more, e.g. trim: 0.2")
        if not all(isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v) for v in self.split):
            raise ImucalError(f"split {short(self.split)} must be a list of times in seconds", field="static.split",
                              fix="e.g. split: [12.5, 30.0] (seconds from the start)")
        if self.threshold is not None and not (isinstance(self.threshold, (int, float))
                                               and not isinstance(self.threshold, bool)
                                               and np.isfinite(self.threshold) and self.threshold > 0):
            raise ImucalError(f"threshold {short(self.threshold)} must be positive", field="static.threshold",
                              fix="omit it to set it automatically from the data")


@dataclass(frozen=True)
class Intervals:
    """Static intervals of a recording: one row per interval.

    ``mean_std`` is the standard error of each interval mean (from the interval's own scatter,
    inflated by the pooled batch-means factor for correlated noise, floored by quantisation).
    """

    start: np.ndarray  #: first sample index
    end: np.ndarray  #: one past the last sample index
    t_start: np.ndarray  #: [s]
    t_end: np.ndarray  #: [s]
    mean: np.ndarray  #: (n, 3) interval means [raw]
    std: np.ndarray  #: (n, 3) within-interval standard deviation [raw]
    mean_std: np.ndarray  #: (n, 3) standard error of the mean [raw]
    t_mid: np.ndarray  #: mean time [s]
    temp: np.ndarray | None  #: mean temperature [deg C]
    threshold: float  #: moving-variance threshold used [raw^2]
    noise_inflation: float  #: batch-means / white-noise variance ratio (>= 1)
    window: float = 1.0
    meta: dict = field(default_factory=dict)
    #: dT/dt [degC/s] of each interval: the mean over its samples of the per-sample rate (what apply reads),
    #: when the samples were read whole (imucal.model.channels.hold_rates); None: from the interval means
    temp_rate: np.ndarray | None = None

    @property
    def n(self) -> int:
        return int(self.start.size)

    @property
    def n_samples(self) -> np.ndarray:
        return self.end - self.start

    @property
    def covariates(self) -> dict[str, np.ndarray | None]:
        """The rows' covariates: mean temperature, mean time and (read whole) the holds' dT/dt (else the
        effects derive it from the means: imucal.model.channels.temperature_rate)."""
        out = {"temp": self.temp, "time": self.t_mid}
        if self.temp_rate is not None:
            out["temp_rate"] = self.temp_rate
        return out

    def subset(self, keep: np.ndarray) -> "Intervals":
        keep = np.asarray(keep)
        return Intervals(self.start[keep], self.end[keep], self.t_start[keep], self.t_end[keep],
                         self.mean[keep], self.std[keep], self.mean_std[keep], self.t_mid[keep],
                         None if self.temp is None else self.temp[keep], self.threshold,
                         self.noise_inflation, self.window, dict(self.meta),
                         None if self.temp_rate is None else self.temp_rate[keep])

    def sample_mask(self, n: int) -> np.ndarray:
        mask = np.zeros(n, bool)
        for a, b in zip(self.start, self.end):
            mask[a:b] = True
        return mask

    def sample_index(self) -> np.ndarray:
        """Interval number of each sample inside an interval, in order."""
        return np.repeat(np.arange(self.n), self.n_samples)

    def table(self, directions: np.ndarray | None = None) -> str:
        """The interval table: start, end, duration, mean, std (and direction if given)."""
        head = f"{'#':>3} {'start':>8} {'end':>8} {'t_start':>8} {'t_end':>8} {'dur':>6} {'mean_x':>12} {'mean_y':>12} {'mean_z':>12} {'std_x':>9} {'std_y':>9} {'std_z':>9}"
        if directions is not None:
            head += f"  {'dir_x':>6} {'dir_y':>6} {'dir_z':>6}"
        rows = [head]
        for k in range(self.n):
            r = (f"{k:3d} {self.start[k]:8d} {self.end[k]:8d} {self.t_start[k]:8.2f} {self.t_end[k]:8.2f} {self.t_end[k]-self.t_start[k]:6.2f} "
                 + " ".join(f"{v:12.6g}" for v in self.mean[k]) + " "
                 + " ".join(f"{v:9.3g}" for v in self.std[k]))
            if directions is not None:
                r += "  " + " ".join(f"{v:6.3f}" for v in directions[k])
            rows.append(r)
        return "\n".join(rows)


#: Window starts per block of the moving variance. Each block's cumulative sums restart (centred on
#: the block's first sample), which bounds their round-off on long logs and gives the same numbers
#: whether the samples arrive at once or in chunks (imucal.data.stream).
VAR_BLOCK = 1 << 16
#: Values per step when the threshold is computed over a long variance series.
_SWEEP = 1 << 20


#: Columns up to which numpy adds a row's values one after the other (x0 + x1) + x2 ...; from 8 on its
#: pairwise summation groups them otherwise (``row_sums`` then leaves the sum to numpy).
_SEQUENTIAL_COLUMNS = 8


def row_sums(x: np.ndarray) -> np.ndarray:
    """``x.sum(axis=1)``, the same numbers, a column at a time: numpy reduces the three values of each
    row of a long (n, 3) array some 18 times slower (1.0 against 0.06 ms at 65,536 rows)."""
    if not 0 < x.shape[1] < _SEQUENTIAL_COLUMNS:
        return x.sum(axis=1)
    out = x[:, 0].copy()
    for j in range(1, x.shape[1]):
        out += x[:, j]
    return out


def column_extremes(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``x.min(axis=0)`` and ``x.max(axis=0)`` of a non-empty (n, k) array, a column at a time: numpy
    reduces a long C-ordered (n, 3) array along its rows some 25 times slower (7.3 against 0.28 ms
    at 280,000 rows)."""
    return (np.array([x[:, j].min() for j in range(x.shape[1])]),
            np.array([x[:, j].max() for j in range(x.shape[1])]))


def _window_variance(seg: np.ndarray, w: int) -> np.ndarray:
    """Variance (ddof 1, summed over columns) of every window ``seg[j:j + w]``, by differences of
    cumulative sums (slices, no index arrays)."""
    m, k = seg.shape[0] - w + 1, seg.shape[1]
    xc = seg - seg[0]
    c1 = np.empty((m + w, k))
    c2 = np.empty((m + w, k))
    c1[0] = c2[0] = 0.0
    np.cumsum(xc, axis=0, out=c1[1:])
    np.cumsum(np.square(xc, out=xc), axis=0, out=c2[1:])
    # var = max(s2 / w - (s1 / w)^2, 0) * w / (w - 1), in place: each temporary is a block of memory
    # the process touches for the first time (page faults cost more than the arithmetic here).
    s1, s2 = c1[w:] - c1[:m], xc[:m]
    np.subtract(c2[w:], c2[:m], out=s2)
    np.divide(s2, w, out=s2)
    np.square(np.divide(s1, w, out=s1), out=s1)
    np.maximum(np.subtract(s2, s1, out=s2), 0.0, out=s2)
    np.divide(np.multiply(s2, w, out=s2), w - 1, out=s2)
    return row_sums(s2)


_F32_MAX = float(np.finfo(np.float32).max)


def _f32(v: np.ndarray) -> np.ndarray:
    return np.minimum(v, _F32_MAX).astype(np.float32)  # a variance beyond float32 saturates


class VarianceStore:
    """Where a moving-variance series' blocks (float32) go as they are computed: a list in memory,
    or (``spill``) an unnamed temporary file, so that a long log's series takes no memory
    (imucal.data.stream). Read back in steps of at most _SWEEP values."""

    def __init__(self, spill: BinaryIO | None = None) -> None:
        self.spill = spill
        self.parts: list[np.ndarray] = []
        self.size = 0

    def append(self, x: np.ndarray) -> None:
        x = np.ascontiguousarray(x, np.float32)
        if self.spill is None:
            self.parts.append(x)
        else:
            self.spill.write(memoryview(x).cast("B"))
        self.size += x.size

    def first(self) -> float:
        """The first value stored (a series' head padding)."""
        if self.spill is None:
            return float(self.parts[0][0])
        self.spill.seek(0)
        return float(np.frombuffer(self.spill.read(4), np.float32)[0])

    def close(self) -> None:
        """Release the spill (its file has no name: nothing is left behind)."""
        if self.spill is not None:
            self.spill.close()

    def steps(self) -> Iterator[np.ndarray]:
        if self.spill is None:
            for p in self.parts:
                for i in range(0, p.size, _SWEEP):
                    yield p[i:i + _SWEEP]
            return
        self.spill.flush()
        self.spill.seek(0)
        left = self.size
        while left:
            x = np.empty(min(left, _SWEEP), np.float32)
            if self.spill.readinto(memoryview(x).cast("B")) != x.nbytes:  # pragma: no cover - the file is ours
                raise OSError("the moving-variance spill ended early")
            left -= x.size
            yield x


class VarianceSeries:
    """A moving-variance series (float32): a head and a tail of padding around the computed values
    (in memory or spilled: VarianceStore), never joined, so a long log needs no copy of it. Order
    statistics by a radix select over the float32 bit patterns."""

    def __init__(self, store: VarianceStore | None = None, head: np.ndarray | None = None,
                 tail: np.ndarray | None = None) -> None:
        empty = np.empty(0, np.float32)
        self.store = store if store is not None else VarianceStore()
        self.head = empty if head is None else head
        self.tail = empty if tail is None else tail
        self.size = self.head.size + self.store.size + self.tail.size

    def steps(self) -> Iterator[np.ndarray]:
        """The series in order, at most _SWEEP values a step."""
        for i in range(0, self.head.size, _SWEEP):
            yield self.head[i:i + _SWEEP]
        yield from self.store.steps()
        for i in range(0, self.tail.size, _SWEEP):
            yield self.tail[i:i + _SWEEP]

    def array(self) -> np.ndarray:
        parts = list(self.steps())
        return np.concatenate(parts) if parts else np.empty(0, np.float32)

    def _order_statistics(self, ks: list[int]) -> list[float]:
        """The values at 0-based ranks ``ks`` (exact) in two steps of 16 bits of the (non-negative,
        so monotonic) bit patterns: a histogram of the top 16 bits finds each rank's bin, a
        histogram of the low 16 bits of the values in that bin finds the value. Two passes, memory
        a few histograms, whatever the length."""
        hist = np.zeros(1 << 16, np.int64)
        for x in self.steps():
            hist += np.bincount(x.view(np.uint32) >> 16, minlength=1 << 16)
        cum = np.cumsum(hist)
        bins = {k: int(np.searchsorted(cum, k, side="right")) for k in ks}
        low = {b: np.zeros(1 << 16, np.int64) for b in set(bins.values())}
        for x in self.steps():
            bits = x.view(np.uint32)
            for b, h in low.items():
                h += np.bincount(bits[(bits >> 16) == b] & 0xFFFF, minlength=1 << 16)
        out = []
        for k in ks:
            b = bins[k]
            c = int(np.searchsorted(np.cumsum(low[b]), k - (int(cum[b - 1]) if b else 0), side="right"))
            out.append(float(np.array([(b << 16) | c], np.uint32).view(np.float32)[0]))
        return out

    def percentile(self, q: float) -> float:
        """The q-th percentile, linear between order statistics (numpy's default method)."""
        h = (self.size - 1) * (q / 100.0)
        lo = int(np.floor(h))
        a, b = self._order_statistics([lo, min(lo + 1, self.size - 1)])
        return a + (b - a) * (h - lo)


class MovingVariance:
    """Centred moving variance of a recording fed in chunks of rows (float32, one value a sample),
    into ``store`` (memory by default).

    The window of sample i is ``x[lo:lo + w]`` with ``lo = clip(i - w // 2, 0, n - w)``: the
    variance of the windows that fit, padded with the first and last at the ends.
    """

    def __init__(self, w: int, store: VarianceStore | None = None) -> None:
        self.w = int(w)
        self.n = 0
        self._buf: np.ndarray | None = None  # samples from the next window start on
        self._store = store if store is not None else VarianceStore()
        self._last: np.ndarray | None = None  # the last block computed

    def _put(self, block: np.ndarray) -> None:
        self._store.append(block)
        self._last = block

    def add(self, x: np.ndarray) -> None:
        self.n += x.shape[0]
        self._buf = x if self._buf is None else np.concatenate([self._buf, x])
        span = VAR_BLOCK + self.w - 1
        k = 0
        while self._buf.shape[0] - k >= span:
            self._put(_f32(_window_variance(self._buf[k:k + span], self.w)))
            k += VAR_BLOCK
        if k:
            self._buf = self._buf[k:].copy()

    def finish(self) -> VarianceSeries:
        n, buf = self.n, self._buf
        if buf is None or n == 0:
            return VarianceSeries()
        w = max(2, min(self.w, n))
        if w != self.w:  # fewer samples than a window: nothing was computed yet
            self._store = VarianceStore(self._store.spill)
        for j0 in range(0, buf.shape[0] - w + 1, VAR_BLOCK):
            self._put(_f32(_window_variance(buf[j0:j0 + VAR_BLOCK + w - 1], w)))
        self._buf = None
        half = w // 2
        store, self._store = self._store, VarianceStore()
        tail = n - half - store.size
        return VarianceSeries(store, np.full(half, store.first(), np.float32),
                              np.full(tail, self._last[-1], np.float32))


def moving_variance(x: np.ndarray, w: int) -> np.ndarray:
    """Centred moving variance of each column over ``w`` samples, summed over columns (float32)."""
    mv = MovingVariance(w)
    mv.add(np.asarray(x, float))
    return mv.finish().array()


def _otsu(hist: np.ndarray, edges: np.ndarray) -> float:
    centers = 0.5 * (edges[:-1] + edges[1:])
    w0 = np.cumsum(hist)
    w1 = w0[-1] - w0
    m0 = np.cumsum(hist * centers)
    mt = m0[-1]
    with np.errstate(divide="ignore", invalid="ignore"):
        between = (mt * w0 / w0[-1] - m0) ** 2 / (w0 * w1)
    between[~np.isfinite(between)] = -1
    return float(centers[int(np.argmax(between))])


def _log_histogram(var: VarianceSeries, clip: float, bins: int = 256) -> tuple[np.ndarray, np.ndarray]:
    """Histogram of log10(max(var, clip)) over its own range, in steps (no float64 copy of var)."""
    lo, hi = np.inf, -np.inf
    for x in var.steps():
        lv = np.log10(np.maximum(x.astype(np.float64), clip))
        lo, hi = min(lo, float(lv.min())), max(hi, float(lv.max()))
    hist = np.zeros(bins, np.int64)
    edges = np.histogram_bin_edges(np.array([lo, hi]), bins=bins, range=(lo, hi))
    for x in var.steps():
        lv = np.log10(np.maximum(x.astype(np.float64), clip))
        hist += np.histogram(lv, bins=bins, range=(lo, hi))[0]
    return hist, edges


def auto_threshold(var: VarianceSeries, quantum: float) -> float:
    """Threshold on the moving variance, set from the data.

    Noise floor: the 5th percentile of the moving variance (any log that is still at least
    5 % of the time). The threshold is the Otsu split of log-variance between still and moving,
    kept within [4, 100] times the floor so that a log that is mostly still, or mostly moving,
    still gets a sensible cut.
    """
    floor = max(var.percentile(5), quantum**2 / 12 * 3, 1e-300)
    split = 10 ** _otsu(*_log_histogram(var, floor * 1e-3))
    return float(min(max(split, 4 * floor), 100 * floor))


def at_rate(settings: StaticSettings, dt: float) -> StaticSettings:
    """The settings for a sample step ``dt`` [s]: a window of fewer than MIN_WINDOW_SAMPLES samples is
    stretched to hold them, and the minimum duration and the trim by the same factor (at 1 Hz the
    defaults 0.5 s, 1.5 s, 0.25 s become 10 s, 30 s, 5 s). Unchanged from 20 Hz up at the default window."""
    r = MIN_WINDOW_SAMPLES * dt / settings.window if dt > 0 else 0.0
    if not r > 1:
        return settings
    return replace(settings, window=settings.window * r, min_duration=settings.min_duration * r,
                   trim=settings.trim * r)


def window_samples(settings: StaticSettings, dt: float) -> int:
    """Moving-variance window [samples] for a sample step ``dt`` [s] (``at_rate``)."""
    return max(3, int(round(at_rate(settings, dt).window / dt)))


def candidate_runs(var: VarianceSeries, threshold: float, trim: int) -> tuple[np.ndarray, np.ndarray]:
    """Runs of samples at or below the threshold, ``trim`` samples cut from each end, 3 or more
    left: (first, one past last). The minimum duration is checked on their time stamps. One pass
    over the series in steps: memory a step and the runs."""
    starts, ends = [], []
    at, before = 0, np.zeros(1, np.int8)  # the sample before the step: still (1) or not (0)
    for x in var.steps():
        still = (x <= np.float64(threshold)).view(np.int8)  # compared in double precision
        edges = np.diff(np.concatenate([before, still]))
        starts.append(np.flatnonzero(edges == 1) + at)
        ends.append(np.flatnonzero(edges == -1) + at)
        at, before = at + x.size, still[-1:]
    if before[0]:
        ends.append(np.array([at]))
    a = np.concatenate(starts or [np.empty(0, np.int64)]).astype(np.int64) + trim
    b = np.concatenate(ends or [np.empty(0, np.int64)]).astype(np.int64) - trim
    ok = b - a >= 3
    return a[ok], b[ok]


def edge_samples(dt: float) -> int:
    """Rows of the edge test's shortest running mean for a sample step ``dt`` [s]."""
    return max(EDGE_MIN_SAMPLES, int(round(EDGE_WINDOW / dt)))


def _mean_rows(x: np.ndarray) -> np.ndarray:
    """``x.mean(axis=0)``, the same numbers without numpy's Python wrapper (tens of thousands of
    intervals call it)."""
    return np.add.reduce(x, axis=0) / x.shape[0]


def _std_rows(x: np.ndarray, ddof: int = 0) -> np.ndarray:
    """``x.std(axis=0, ddof=ddof)``, the same numbers (numpy's own steps) without its Python wrapper."""
    n = x.shape[0]
    d = x - np.add.reduce(x, axis=0, keepdims=True) / n
    np.square(d, out=d)
    return np.sqrt(np.add.reduce(d, axis=0) / max(n - ddof, 0))


@dataclass(frozen=True)
class _Line:
    """A run's rows less the line of its central half, with what that line is worth: its mean, and
    on an axis whose slope there is EDGE_SLOPE_Z standard errors from zero (a drift), its slope."""

    res: np.ndarray  #: (n, k) rows minus the line
    r: np.ndarray  #: (n,) row positions from the run's centre
    white: np.ndarray  #: (k,) white noise of one row (first differences of the central half)
    floor: np.ndarray  #: (k,) least noise of one row (quantisation, round-off)
    lever: np.ndarray  #: (k,) sum of r^2 over the central half where the slope is kept, else inf
    nc: int  #: rows in the central half

    @staticmethod
    def of(x: np.ndarray, q: float) -> "_Line":
        n = x.shape[0]
        r = np.arange(n) - (n - 1) / 2
        c = slice(n // 4, n - n // 4)
        core, rc = x[c], r[c]
        lever = float(rc @ rc)
        mu = _mean_rows(core)
        beta = (rc @ (core - mu)) / lever
        white = _std_rows(core[1:] - core[:-1], ddof=1) / np.sqrt(2)
        floor = np.maximum(q / np.sqrt(12), 64 * np.finfo(float).eps * (np.abs(mu) + 1))
        drift = np.abs(beta) * np.sqrt(lever) > EDGE_SLOPE_Z * np.maximum(white, floor)
        # without a drift the line is its mean (the slope's term, +-0, changes no value but a zero's sign,
        # which nothing after reads: sums, squares and magnitudes)
        res = x - mu - r[:, None] * np.where(drift, beta, 0.0) if drift.any() else x - mu
        return _Line(res, r, white, floor, np.where(drift, lever, np.inf), core.shape[0])

    def sigma(self, row: np.ndarray, at: np.ndarray, size: np.ndarray | float) -> np.ndarray:
        """Standard error of a mean over ``size`` rows (an array, or one count for all) centred at ``at``,
        for a row noise ``row``: the mean's own and the line's (its level and slope, there)."""
        own = 1 / size[:, None] + 1 / self.nc if isinstance(size, np.ndarray) else 1 / size + 1 / self.nc
        return row * np.sqrt(own + at[:, None] ** 2 / self.lever)


def _running(cs: np.ndarray, w: int) -> np.ndarray:
    """Means of every ``w`` consecutive rows, from the cumulative sums ``cs`` (with a leading 0)."""
    return (cs[w:] - cs[:-w]) / w


def _row_max(x: np.ndarray) -> np.ndarray:
    """``x.max(axis=1)`` of an (n, k) array, a column at a time (the same values, NaN too; numpy
    reduces the few values of each row of a long array some 10 times slower)."""
    out = x[:, 0].copy()
    for j in range(1, x.shape[1]):
        np.maximum(out, x[:, j], out=out)
    return out


def _row_all(x: np.ndarray) -> np.ndarray:
    """``x.all(axis=1)`` of an (n, k) boolean array, a column at a time."""
    out = x[:, 0].copy()
    for j in range(1, x.shape[1]):
        out &= x[:, j]
    return out


def _edge_cut(line: _Line, m: int, sides: str = "both") -> tuple[int, int] | None:
    """The rows [lo, hi) kept after cutting the run's edge whose rows depart most from the line,
    or None when neither departs by EDGE_Z standard errors. ``sides``: "both", or only the "start"
    or the "end" edge (a long run's neighbourhood of one edge, ``still_span``)."""
    res, r = line.res, line.r
    n = res.shape[0]
    c0, c1 = n // 4, n - n // 4
    cs = np.empty((n + 1, res.shape[1]))
    cs[0] = 0.0
    np.cumsum(res, axis=0, out=cs[1:])
    scales, rows, w = [], [], m
    while w * EDGE_CORE_WINDOWS <= line.nc or not scales:  # one row's noise at each scale
        rows.append(np.maximum(_std_rows(_running(cs[c0:c1 + 1], w)) * np.sqrt(w),
                               np.maximum(line.white, line.floor) if not rows else rows[-1]))
        scales.append(w)
        w *= 2
    # the means of rows i..n-1 (i >= c1) and of rows 0..j-1 (j <= c0), and the z of each, in one go
    i, j = np.arange(c1, n), np.arange(1, c0 + 1)
    size = np.concatenate([n - i, j])
    at = np.concatenate([(r[i] + r[-1]) / 2, (r[0] + r[j - 1]) / 2])
    mean = np.concatenate([cs[n] - cs[i], cs[j]]) / size[:, None]
    row = np.array(rows)[np.maximum(np.searchsorted(scales, size, side="right") - 1, 0)]
    z = _row_max(np.abs(mean) / line.sigma(row, at, size.astype(float)))
    z_end, z_start = z[:i.size], z[i.size:]
    top_end = z_end.max(initial=0.0) if sides != "start" else 0.0
    top_start = z_start.max(initial=0.0) if sides != "end" else 0.0
    if max(top_end, top_start) <= EDGE_Z:
        return None
    dev = _running(cs, m)  # dev[k]: mean of rows k..k+m-1 less the line
    near = _row_all(np.abs(dev) <= EDGE_BACK * line.sigma(rows[0], r[:n - m + 1] + (m - 1) / 2, float(m)))
    if top_end >= top_start:
        k = int(i[np.argmax(z_end)])  # walk back to the last window near the line
        back = np.flatnonzero(near[:max(k - m + 1, 0)])
        return 0, (int(back[-1]) + m if back.size else k)
    k = int(j[np.argmax(z_start)])
    ahead = np.flatnonzero(near[k:])
    return (k + int(ahead[0]) if ahead.size else k), n


def still_span(seg: np.ndarray, m: int, q: float = 0.0, horizon: int | None = None) -> tuple[int, int]:
    """Rows [lo, hi) of a still run ``seg`` whose edges agree with its own central half (the EDGE_
    constants): a slow start of motion is cut off. ``m``: rows of the shortest running mean
    (edge_samples); ``q``: the quantisation step (0: none); ``horizon``: a run longer than 4 x this
    many rows has each edge judged within its first or last 2 x horizon rows (EDGE_HORIZON_WINDOWS)."""
    lo, hi = 0, seg.shape[0]
    for _ in range(EDGE_ROUNDS):
        if hi - lo < 4 * m:  # too short to tell a central half from its edges
            break
        if horizon is not None and hi - lo > 4 * horizon:
            k = 2 * horizon
            head = _edge_cut(_Line.of(seg[lo:lo + k], q), m, "start")
            tail = _edge_cut(_Line.of(seg[hi - k:hi], q), m, "end")
            if head is None and tail is None:
                break
            lo, hi = lo + (head[0] if head else 0), hi - k + (tail[1] if tail else k)
            continue
        cut = _edge_cut(_Line.of(seg[lo:hi], q), m)
        if cut is None:
            break
        lo, hi = lo + cut[0], lo + cut[1]
    return lo, hi


def still_segment(start: int, seg: np.ndarray, t: np.ndarray, temp: np.ndarray | None, lows: np.ndarray,
                  highs: np.ndarray, declared: dict | None, settings: StaticSettings, m: int,
                  q: float) -> Segment | None:
    """The Segment of a candidate run (rows start..start+len) after its edges are cut to what is
    still (still_span), or None when less than the minimum duration is left."""
    n = seg.shape[0]
    dt = float(t[-1] - t[0]) / (n - 1) if n > 1 else 0.0  # the run's step (a gap inside lengthens it)
    lo, hi = still_span(seg, m, q, EDGE_HORIZON_WINDOWS * window_samples(settings, dt) if dt > 0 else None)
    if hi - lo < 3 or t[hi - 1] - t[lo] < at_rate(settings, dt).min_duration:
        return None
    return segment(start + lo, seg[lo:hi], t[lo:hi], None if temp is None else temp[lo:hi], lows, highs, declared)


def cut_runs(runs: Iterable[tuple], times: tuple[float, ...]) -> Iterator[tuple]:
    """The candidate runs (first row, raw, t, temp), each cut in two at every time of ``times`` inside
    it (StaticSettings.split): the sample at a cut's time starts the second part."""
    cuts = np.sort(np.asarray(times, float))
    for start, raw, t, temp in runs:
        k = np.unique(np.searchsorted(t, cuts[(cuts > t[0]) & (cuts <= t[-1])])) if cuts.size else ()
        for lo, hi in zip((0, *k), (*k, t.size)):  # (two cuts between the same two samples make one)
            yield start + int(lo), raw[lo:hi], t[lo:hi], None if temp is None else temp[lo:hi]


def judge_runs(batch: list[tuple], args: tuple) -> list[Segment | None]:
    """still_segment of each candidate run (first row, raw, t, temp) of a batch, None for one shorter
    than the minimum duration (``args``: still_segment's lows, highs, declared, settings, m, q). A
    function of its arguments alone: imucal.data.run_pool sends batches to worker processes."""
    settings = args[3]
    return [still_segment(start, raw, t, temp, *args) if t[-1] - t[0] >= settings.min_duration else None
            for start, raw, t, temp in batch]


def quantum(x: np.ndarray) -> float:
    """Quantisation step when the readings (their first 20000 rows) are integer counts, else 0."""
    sample = x[: min(x.shape[0], QUANTUM_ROWS)]
    if np.all(sample == np.round(sample)):
        return 1.0
    return 0.0


def central_scatter(seg: np.ndarray, trim: float = SATURATION_TRIM) -> np.ndarray:
    """Per-column standard deviation of ``seg`` without the ``trim`` fraction at each end."""
    n = seg.shape[0]
    cut = int(np.floor(trim * n))
    core = np.sort(seg, axis=0)[cut:n - cut]
    return core.std(axis=0, ddof=1) if core.shape[0] > 1 else np.zeros(seg.shape[1])


@dataclass(frozen=True)
class Segment:
    """What detection keeps of one still interval: its statistics and its rail evidence."""

    start: int
    end: int
    t_start: float
    t_end: float
    mean: np.ndarray  #: (3,)
    std: np.ndarray  #: (3,) ddof 1
    ratios: list  #: batch-means / white-noise variance ratio per axis with enough samples
    t_mid: float
    temp: float | None
    scatter: np.ndarray  #: (3,) central_scatter
    at_low: np.ndarray  #: (3,) fraction of samples exactly at the recording's minimum, per axis
    at_high: np.ndarray  #: (3,) ... at its maximum
    hit_low: np.ndarray  #: (3,) bool: a sample at or below the declared low rail
    hit_high: np.ndarray  #: (3,) bool: ... at or above the declared high rail


def _std(x: np.ndarray, mean: np.ndarray) -> np.ndarray:
    """Column standard deviation (ddof 1) about ``mean``."""
    d = x - mean
    return np.sqrt(np.einsum("ij,ij->j", d, d) / (x.shape[0] - 1))


def segment(start: int, seg: np.ndarray, t: np.ndarray, temp: np.ndarray | None, lows: np.ndarray,
            highs: np.ndarray, declared: dict | None) -> Segment:
    """Statistics of the still samples ``seg`` (rows start..start+len) with their times and
    temperatures; ``lows``/``highs``: the recording's extreme value of each axis. Few numpy calls
    per interval: a long log holds tens of thousands."""
    n = seg.shape[0]
    mean = _mean_rows(seg)
    std = _std(seg, mean)
    ratios: list = []
    nb = n // _BATCHES
    if nb >= 2:
        bm = np.add.reduce(seg[: nb * _BATCHES].reshape(_BATCHES, nb, 3), axis=1) / nb  # batch means
        white = std ** 2 / nb
        ok = white > 0
        ratios = (_std(bm, _mean_rows(bm))[ok] ** 2 / white[ok]).tolist()
    srt = np.sort(seg, axis=0)
    cut = int(np.floor(SATURATION_TRIM * n))
    core = srt[cut:n - cut]
    scatter = _std(core, _mean_rows(core)) if core.shape[0] > 1 else np.zeros(3)
    lo_, hi_ = srt[0], srt[-1]
    at_low, at_high = np.zeros(3), np.zeros(3)
    for j in range(3):  # only an interval that reaches an extreme counts its samples there
        if lo_[j] == lows[j]:
            at_low[j] = np.count_nonzero(srt[:, j] == lows[j]) / n
        if hi_[j] == highs[j]:
            at_high[j] = np.count_nonzero(srt[:, j] == highs[j]) / n
    rl, rh = (declared or {}).get("low"), (declared or {}).get("high")
    no = np.zeros(3, bool)
    return Segment(start=start, end=start + n, t_start=float(t[0]), t_end=float(t[-1]), mean=mean, std=std,
                   ratios=ratios, t_mid=float(np.add.reduce(t) / t.size),
                   temp=None if temp is None else float(np.add.reduce(temp) / temp.size),
                   scatter=scatter, at_low=at_low, at_high=at_high,
                   hit_low=no if rl is None else lo_ <= rl, hit_high=no if rh is None else hi_ >= rh)


def _on_rail(frac: np.ndarray, scatter: np.ndarray, j: int) -> np.ndarray:
    """Intervals sitting on a suspect rail of axis ``j`` (the recording's extreme value).

    Candidates hold SATURATION_FRACTION of their samples exactly on the rail (``frac``); they are
    clipped when their central scatter is flattened below SATURATION_STD_RATIO of the axis's
    scatter in the other intervals (or, when every interval is a candidate, of the other axes'
    scatter). A sensor that reads one constant value in every pose (scatter 0 everywhere) gives no
    verdict.
    """
    cand = frac >= SATURATION_FRACTION
    if not cand.any():
        return cand
    pool = scatter[~cand, j] if (~cand).any() else np.delete(scatter, j, axis=1).ravel()
    ref = median(pool)
    return cand & (scatter[:, j] <= SATURATION_STD_RATIO * ref) & (ref > 0)


def saturation(segs: list[Segment], lows: np.ndarray, highs: np.ndarray,
               declared: dict | None = None) -> tuple[np.ndarray, list[dict], dict]:
    """Intervals with a clipped axis: (keep mask, one record per drop, the rails per axis).

    Declared rails (``data.saturation``): any sample at or beyond one clips its interval.
    Otherwise, per axis, the recording's extreme values are suspect rails, and an interval is
    clipped on that axis when a large share of its samples sit exactly on one while its scatter
    there is flattened (SATURATION_FRACTION, SATURATION_STD_RATIO).
    """
    k = len(segs)
    keep = np.ones(k, bool)
    drops: list[dict] = []
    found: dict = {}
    if k == 0:
        return keep, drops, found
    scatter = np.array([g.scatter for g in segs])
    for j, axis in enumerate("xyz"):
        rails_j = []
        if declared is not None:
            for side in ("low", "high"):
                if declared.get(side) is not None:
                    rails_j.append((side, float(declared[side][j]), "declared"))
        else:
            rails_j = [("low", float(lows[j]), "detected"), ("high", float(highs[j]), "detected")]
        for side, rail, how in rails_j:
            if how == "declared":
                hits = np.array([(g.hit_low if side == "low" else g.hit_high)[j] for g in segs])
            else:
                hits = _on_rail(np.array([(g.at_low if side == "low" else g.at_high)[j] for g in segs]), scatter, j)
            for i, clipped in enumerate(hits):
                if clipped:
                    found.setdefault(axis, {"low": None, "high": None, "source": how})[side] = rail
                    if keep[i]:
                        drops.append({"interval": i, "axis": axis, "rail": rail, "side": side,
                                      "reason": f"axis {axis} at its {side} rail {rail:g} ({how})"})
                    keep[i] = False
    return keep, drops, found


def intervals_from(segs: list[Segment], threshold: float, q: float, settings: StaticSettings,
                   lows: np.ndarray, highs: np.ndarray, rails: dict | None, has_temp: bool) -> Intervals:
    """The Intervals of the kept segments: noise of the means, clipped ones dropped."""
    k = len(segs)
    start = np.array([g.start for g in segs], dtype=int)
    end = np.array([g.end for g in segs], dtype=int)
    mean = np.array([g.mean for g in segs]).reshape(k, 3)
    std = np.array([g.std for g in segs]).reshape(k, 3)
    ratios = [r for g in segs for r in g.ratios]
    # Pooled over all intervals and axes: robust to the few degrees of freedom per interval.
    inflation = max(1.0, median(ratios)) if ratios else 1.0
    nn = (end - start)[:, None].astype(float)
    var_mean = std**2 / nn * inflation
    if q > 0:
        var_mean = np.maximum(var_mean, q**2 / 12 / nn)
    temps = [g.temp for g in segs]
    iv = Intervals(start=start, end=end, t_start=np.array([g.t_start for g in segs], float),
                   t_end=np.array([g.t_end for g in segs], float), mean=mean, std=std,
                   mean_std=np.sqrt(var_mean), t_mid=np.array([g.t_mid for g in segs], float),
                   temp=np.array(temps, float) if has_temp else None,
                   threshold=threshold, noise_inflation=inflation, window=settings.window)
    keep, drops, found = saturation(segs, lows, highs, rails)
    for d in drops:
        i = d.pop("interval")
        d["t_start"], d["t_end"] = float(iv.t_start[i]), float(iv.t_end[i])
    if drops:
        iv = iv.subset(np.flatnonzero(keep))
    iv.meta.update({"dropped": drops, "saturation": found})
    return iv


def detect_static(t: np.ndarray, raw: np.ndarray, settings: StaticSettings = StaticSettings(),
                  temp: np.ndarray | None = None, source: str | None = None,
                  rails: dict | None = None) -> Intervals:
    """Find the intervals in which the sensor is still; drop those with a clipped axis.

    Dropped intervals are listed in ``meta["dropped"]`` (t_start, t_end, axis, rail, reason).
    imucal.data.stream does the same on a file read in chunks.

    Args:
        t: (N,) times [s].
        raw: (N, 3) raw readings.
        settings: window, minimum duration, threshold and trim (the run file's ``static:``).
        temp: (N,) temperatures [deg C], or None.
        source: the recording's name, for messages.
        rails: declared rails (imucal.data.spec.rails); None detects clipping from the data.

    Returns:
        The Intervals: one row per still interval, its mean and the mean's standard error.
    """
    n = raw.shape[0]
    if n < 3:
        raise ImucalError(f"only {n} samples", file=source, field="data",
                          fix="record several seconds in each orientation")
    dt = median(np.diff(t))
    settings = at_rate(settings, dt)  # a window of too few samples stretched, and the durations with it
    mv = MovingVariance(window_samples(settings, dt))
    mv.add(np.asarray(raw, float))
    var = mv.finish()
    q = quantum(raw)
    thr = settings.threshold if settings.threshold is not None else auto_threshold(var, q)
    a, b = candidate_runs(var, thr, int(round(settings.trim / dt)))
    del var
    lows, highs = column_extremes(raw)
    m = edge_samples(dt)
    runs = cut_runs(((int(i), raw[i:j], t[i:j], None if temp is None else temp[i:j]) for i, j in zip(a, b)),
                    settings.split)
    segs = [g for i, seg, ts, tp in runs if ts[-1] - ts[0] >= settings.min_duration
            and (g := still_segment(i, seg, ts, tp, lows, highs, rails, settings, m, q)) is not None]
    iv = intervals_from(segs, thr, q, settings, lows, highs, rails, temp is not None)
    if temp is None or iv.n == 0:
        return iv
    return replace(iv, temp_rate=hold_rates(t, temp, iv.start, iv.end))
