"""Static-interval detection: a moving-variance detector with an automatic threshold.

Window and minimum duration are in seconds. The threshold comes from the data: the moving
variance of a still sensor clusters at the noise floor, motion lies orders of magnitude above,
so we split log-variance into two classes (Otsu) and never go below a multiple of the noise
floor. Unlike imu_tk we do not pick, among candidate thresholds, the one whose fit has the
lowest summed cost: that rule favours fewer intervals and generalises worse.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from imucal.errors import ImucalError, short

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


@dataclass(frozen=True)
class StaticSettings:
    """Detector settings (the YAML ``static:`` section). Times in seconds."""

    window: float = 0.5  #: moving-variance window [s]
    min_duration: float = 1.5  #: shortest interval kept [s]
    threshold: float | None = None  #: moving-variance threshold [raw^2]; None = automatic
    trim: float = 0.25  #: dropped from each end of an interval [s]

    def __post_init__(self) -> None:
        for name in ("window", "min_duration"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v) and v > 0):
                raise ImucalError(f"{name} {short(v)} must be a positive number of seconds",
                                  field=f"static.{name}")
        if not (isinstance(self.trim, (int, float)) and np.isfinite(self.trim) and self.trim >= 0):
            raise ImucalError(f"trim {short(self.trim)} must be a non-negative number of seconds",
                              field="static.trim")
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

    @property
    def n(self) -> int:
        return int(self.start.size)

    @property
    def n_samples(self) -> np.ndarray:
        return self.end - self.start

    def subset(self, keep: np.ndarray) -> "Intervals":
        keep = np.asarray(keep)
        return Intervals(self.start[keep], self.end[keep], self.t_start[keep], self.t_end[keep],
                         self.mean[keep], self.std[keep], self.mean_std[keep], self.t_mid[keep],
                         None if self.temp is None else self.temp[keep], self.threshold,
                         self.noise_inflation, self.window, dict(self.meta))

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


def moving_variance(x: np.ndarray, w: int) -> np.ndarray:
    """Centred moving variance of each column over ``w`` samples, summed over columns."""
    n = x.shape[0]
    w = max(2, min(int(w), n))
    xc = x - x.mean(axis=0)  # conditioning of the cumulative sums
    c1 = np.vstack([np.zeros((1, x.shape[1])), np.cumsum(xc, axis=0)])
    c2 = np.vstack([np.zeros((1, x.shape[1])), np.cumsum(xc * xc, axis=0)])
    half = w // 2
    lo = np.clip(np.arange(n) - half, 0, n - w)
    hi = lo + w
    s1 = c1[hi] - c1[lo]
    s2 = c2[hi] - c2[lo]
    var = np.maximum(s2 / w - (s1 / w) ** 2, 0.0) * w / (w - 1)
    return var.sum(axis=1)


def _otsu(values: np.ndarray, bins: int = 256) -> float:
    hist, edges = np.histogram(values, bins=bins)
    centers = 0.5 * (edges[:-1] + edges[1:])
    w0 = np.cumsum(hist)
    w1 = w0[-1] - w0
    m0 = np.cumsum(hist * centers)
    mt = m0[-1]
    with np.errstate(divide="ignore", invalid="ignore"):
        between = (mt * w0 / w0[-1] - m0) ** 2 / (w0 * w1)
    between[~np.isfinite(between)] = -1
    return float(centers[int(np.argmax(between))])


def auto_threshold(var: np.ndarray, quantum: float) -> float:
    """Threshold on the moving variance, set from the data.

    Noise floor: the 5th percentile of the moving variance (any log that is still at least
    5 % of the time). The threshold is the Otsu split of log-variance between still and moving,
    kept within [4, 100] times the floor so that a log that is mostly still, or mostly moving,
    still gets a sensible cut.
    """
    floor = max(float(np.percentile(var, 5)), quantum**2 / 12 * 3, 1e-300)
    lv = np.log10(np.maximum(var, floor * 1e-3))
    split = 10 ** _otsu(lv)
    return float(min(max(split, 4 * floor), 100 * floor))


def _quantum(x: np.ndarray) -> float:
    """Quantisation step when the readings are integer counts, else 0."""
    sample = x[: min(x.shape[0], 20000)]
    if np.all(sample == np.round(sample)):
        return 1.0
    return 0.0


def central_scatter(seg: np.ndarray, trim: float = SATURATION_TRIM) -> np.ndarray:
    """Per-column standard deviation of ``seg`` without the ``trim`` fraction at each end."""
    n = seg.shape[0]
    cut = int(np.floor(trim * n))
    core = np.sort(seg, axis=0)[cut:n - cut]
    return core.std(axis=0, ddof=1) if core.shape[0] > 1 else np.zeros(seg.shape[1])


def _on_rail(col: np.ndarray, rail: float, start: np.ndarray, end: np.ndarray, scatter: np.ndarray,
             j: int) -> list[bool]:
    """Intervals sitting on a suspect rail of axis ``j`` (the recording's extreme value).

    Candidates hold SATURATION_FRACTION of their samples exactly on the rail; they are clipped
    when their central scatter is flattened below SATURATION_STD_RATIO of the axis's scatter in
    the other intervals (or, when every interval is a candidate, of the other axes' scatter). A
    sensor that reads one constant value in every pose (scatter 0 everywhere) gives no verdict.
    """
    cand = np.array([np.mean(col[a:b] == rail) >= SATURATION_FRACTION for a, b in zip(start, end)])
    if not cand.any():
        return [False] * cand.size
    pool = scatter[~cand, j] if (~cand).any() else np.delete(scatter, j, axis=1).ravel()
    ref = float(np.median(pool))
    return list(cand & (scatter[:, j] <= SATURATION_STD_RATIO * ref) & (ref > 0))


def saturation(raw: np.ndarray, start: np.ndarray, end: np.ndarray,
               declared: dict | None = None) -> tuple[np.ndarray, list[dict], dict]:
    """Intervals with a clipped axis: (keep mask, one record per drop, the rails per axis).

    Declared rails (``data.saturation``): any sample at or beyond one clips its interval.
    Otherwise, per axis, the recording's extreme values are suspect rails, and an interval is
    clipped on that axis when a large share of its samples sit exactly on one while its scatter
    there is flattened (SATURATION_FRACTION, SATURATION_STD_RATIO).
    """
    k = start.size
    keep = np.ones(k, bool)
    drops: list[dict] = []
    found: dict = {}
    if k == 0:
        return keep, drops, found
    scatter = np.array([central_scatter(raw[a:b]) for a, b in zip(start, end)])
    for j, axis in enumerate("xyz"):
        col = raw[:, j]
        rails_j = []
        if declared is not None:
            for side in ("low", "high"):
                if declared.get(side) is not None:
                    rails_j.append((side, float(declared[side][j]), "declared"))
        else:
            rails_j = [("low", float(col.min()), "detected"), ("high", float(col.max()), "detected")]
        for side, rail, how in rails_j:
            if how == "declared":
                hits = [bool(np.any(col[a:b] <= rail if side == "low" else col[a:b] >= rail))
                        for a, b in zip(start, end)]
            else:
                hits = _on_rail(col, rail, start, end, scatter, j)
            for i, clipped in enumerate(hits):
                if clipped:
                    found.setdefault(axis, {"low": None, "high": None, "source": how})[side] = rail
                    if keep[i]:
                        drops.append({"interval": i, "axis": axis, "rail": rail, "side": side,
                                      "reason": f"axis {axis} at its {side} rail {rail:g} ({how})"})
                    keep[i] = False
    return keep, drops, found


def detect_static(t: np.ndarray, raw: np.ndarray, settings: StaticSettings = StaticSettings(),
                  temp: np.ndarray | None = None, source: str | None = None,
                  rails: dict | None = None) -> Intervals:
    """Find the intervals in which the sensor is still; drop those with a clipped axis.

    ``rails``: declared rails (imucal.data.load.rails); None detects clipping from the data.
    Dropped intervals are listed in ``meta["dropped"]`` (t_start, t_end, axis, rail, reason).
    """
    n = raw.shape[0]
    if n < 3:
        raise ImucalError(f"only {n} samples", file=source, field="data",
                          fix="record several seconds in each orientation")
    dt = float(np.median(np.diff(t)))
    w = max(3, int(round(settings.window / dt)))
    var = moving_variance(raw, w)
    q = _quantum(raw)
    thr = settings.threshold if settings.threshold is not None else auto_threshold(var, q)
    still = var <= thr
    edges = np.diff(np.concatenate([[0], still.view(np.int8), [0]]))
    starts = np.flatnonzero(edges == 1)
    ends = np.flatnonzero(edges == -1)
    trim = int(round(settings.trim / dt))
    keep_s, keep_e = [], []
    for a, b in zip(starts, ends):
        a2, b2 = a + trim, b - trim
        if b2 - a2 >= 3 and t[b2 - 1] - t[a2] >= settings.min_duration:
            keep_s.append(a2)
            keep_e.append(b2)
    start = np.array(keep_s, dtype=int)
    end = np.array(keep_e, dtype=int)
    k = start.size
    mean = np.empty((k, 3))
    std = np.empty((k, 3))
    ratios = []
    for i, (a, b) in enumerate(zip(start, end)):
        seg = raw[a:b]
        mean[i] = seg.mean(axis=0)
        std[i] = seg.std(axis=0, ddof=1)
        nb = (b - a) // _BATCHES
        if nb >= 2:
            bm = seg[: nb * _BATCHES].reshape(_BATCHES, nb, 3).mean(axis=1)
            white = std[i] ** 2 / nb
            ok = white > 0
            ratios.extend((bm.var(axis=0, ddof=1)[ok] / white[ok]).tolist())
    # Pooled over all intervals and axes: robust to the few degrees of freedom per interval.
    inflation = float(max(1.0, np.median(ratios))) if ratios else 1.0
    nn = (end - start)[:, None].astype(float)
    var_mean = std**2 / nn * inflation
    if q > 0:
        var_mean = np.maximum(var_mean, q**2 / 12 / nn)
    iv = Intervals(start=start, end=end, t_start=t[start] if k else np.empty(0),
                   t_end=t[end - 1] if k else np.empty(0), mean=mean, std=std,
                   mean_std=np.sqrt(var_mean),
                   t_mid=np.array([t[a:b].mean() for a, b in zip(start, end)]),
                   temp=None if temp is None else np.array([temp[a:b].mean() for a, b in zip(start, end)]),
                   threshold=thr, noise_inflation=inflation, window=settings.window)
    keep, drops, found = saturation(raw, start, end, rails)
    for d in drops:
        i = d.pop("interval")
        d["t_start"], d["t_end"] = float(iv.t_start[i]), float(iv.t_end[i])
    if drops:
        iv = iv.subset(np.flatnonzero(keep))
    iv.meta.update({"dropped": drops, "saturation": found})
    return iv
