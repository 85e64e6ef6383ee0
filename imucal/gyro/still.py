"""Which static intervals are still for the gyroscope (issue 25).

The static detector judges stillness on the accelerometer. A slow turn about the vertical leaves
the specific force unchanged, so an interval can be still for the accelerometer while the sensor
turns: its gyro mean is then a turn rate, not the bias, and an unweighted mean of the intervals'
means pulls the bias by that rate over the number of intervals. Each interval is therefore also
judged on the gyro, with two tests of one shape:

- ``MEAN``: its mean rate against the static model fitted to the intervals still kept
  (bias, plus the g-sensitivity rows its test keeps: imucal.gyro.gsens);
- ``DRIFT``: the mean of its second half minus that of its first half (a turn that starts,
  stops or speeds up within it).

Each statistic is measured against its own allowed scatter per axis: the interval's standard
error from its own samples plus the spread between intervals (bias instability, correlated noise),
estimated robustly from the intervals themselves (a median absolute value: turning intervals
barely move it while they are fewer than half). The squared standardised values summed over the three axes are
chi-square(3) for a still interval. The worst interval below ``ALPHA / (2 n)`` (Bonferroni over
both tests and every interval) is rejected, the model refitted without it, and so on.

A rejected interval is dropped as a still pose altogether (``GyroData.without``): it gives no
bias, no g-sensitivity, no noise level, and no segment ends in it. The segments on both sides
become one segment from the still pose before it to the still pose after it, which integrates
the turn like any other motion. Its gravity direction (an average over a pose whose attitude
moved) and the zero rate the static model assumes in it are never used.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from enum import Enum

import numpy as np

from imucal.gyro.gsens import fit_static
from imucal.gyro.segments import GyroData
from imucal.solve.stats import chi2_sf_array, median

#: family-wise probability of rejecting a truly still interval in a recording (both tests, all
#: intervals: each test is at ALPHA / (2 n), Bonferroni)
ALPHA = 0.01
#: fewest intervals for which the spread between intervals is estimated: below it nothing is judged
MIN_INTERVALS = 6
#: at most this fraction of the intervals is rejected: the robust spread (a median) describes the
#: still ones only while they are the majority; beyond it the recording is judged as it is
MAX_REJECTED_FRACTION = 0.5
#: median |x| / MAD_NORMAL is the standard deviation of normal x of mean zero
MAD_NORMAL = 0.6744897501960817


class StillTest(str, Enum):
    """The test an interval failed."""

    MEAN = "mean rate"  #: its mean rate differs from the still intervals' bias (and G_s a)
    DRIFT = "drift"  #: its rate changes within it: second-half mean minus first-half mean


@dataclass(frozen=True)
class NotStill:
    """A static interval (still for the accelerometer) that the gyroscope shows turning."""

    interval: int  #: number among the detected static intervals (the report's interval table)
    t_start: float  #: [s]
    t_end: float  #: [s]
    rate: tuple[float, float, float]  #: mean rate minus the still intervals' static model [raw unit]
    drift: tuple[float, float, float]  #: second-half mean minus first-half mean [raw unit]
    test: StillTest  #: the test that rejected it (the smaller p-value of the two)
    statistic: float  #: chi-square (3 dof) of that test
    p_value: float
    rate_deg_s: tuple[float, float, float] | None = None  #: ``rate`` through the fitted scale [deg/s]
    drift_deg_s: tuple[float, float, float] | None = None  #: ``drift`` through the fitted scale [deg/s]

    def with_scale(self, scale: np.ndarray) -> "NotStill":
        """With the rates in deg/s, given the gyro's scale [raw unit per rad/s] per axis."""
        deg = (lambda v: tuple(float(x) for x in np.degrees(np.asarray(v) / np.asarray(scale, float))))
        return replace(self, rate_deg_s=deg(self.rate), drift_deg_s=deg(self.drift))


@dataclass(frozen=True)
class Stillness:
    """The gyro's verdict on every static interval: which are kept as still poses."""

    keep: np.ndarray  #: (n,) bool per detected static interval
    rejected: tuple[NotStill, ...]  #: in the order they were rejected
    alpha: float  #: family-wise level (ALPHA)
    tested: bool  #: False when there were too few intervals (MIN_INTERVALS) to judge

    @property
    def n_intervals(self) -> int:
        return int(self.keep.size)

    @property
    def threshold_p(self) -> float:
        """The per-test p-value below which an interval is rejected."""
        return self.alpha / (2 * max(self.n_intervals, 1))

    def with_scale(self, scale: np.ndarray) -> "Stillness":
        """The rejected intervals' rates also in deg/s (NotStill.with_scale)."""
        return replace(self, rejected=tuple(r.with_scale(scale) for r in self.rejected))


def _half_means(data: GyroData) -> tuple[np.ndarray, np.ndarray]:
    """Second-half mean minus first-half mean per interval (n, 3), and its standard error."""
    d, se = [], []
    for i0, i1 in zip(data.start, data.end):
        h = (i0 + i1) // 2
        a, b = data.gyro[i0:h], data.gyro[h:i1]
        d.append(b.mean(0) - a.mean(0))
        se.append(np.sqrt(_var(a) / len(a) + _var(b) / len(b)))
    return np.array(d), np.array(se)


def _var(x: np.ndarray) -> np.ndarray:
    return x.var(0, ddof=1) if len(x) > 1 else np.zeros(x.shape[1])


def _chi2(x: np.ndarray, se: np.ndarray, keep: np.ndarray, floor: np.ndarray) -> np.ndarray:
    """Per interval, sum over axes of x^2 / (spread^2 + se^2): chi-square(3) for a still interval.

    ``spread`` (per axis): what the kept intervals scatter beyond their own standard errors,
    from the median of |x| (robust while fewer than half turn); ``floor`` bounds the
    variance below (an interval is never judged more precisely than the whole recording's mean).
    """
    total = (np.array([median(np.abs(x[keep, j])) for j in range(3)]) / MAD_NORMAL) ** 2
    own = np.array([median(se[keep, j] ** 2) for j in range(3)])
    var = np.maximum(np.maximum(total - own, 0.0) + se**2, floor)
    with np.errstate(divide="ignore", invalid="ignore"):
        q = np.where(var > 0, x**2 / var, np.where(x == 0, 0.0, np.inf))
    return q.sum(1)


def judge(data: GyroData, gsens: str = "auto", alpha: float = ALPHA) -> Stillness:
    """Reject, one at a time, the worst interval that the gyro shows not still (module docstring)."""
    n = data.n_intervals
    keep = np.ones(n, bool)
    if n < MIN_INTERVALS:
        return Stillness(keep, (), alpha, False)
    gm, gse, am, _ = data.static_means()
    drift, dse = _half_means(data)
    floor = data.static_rate_noise() ** 2 / float(np.sum(data.end - data.start))
    p_cut = alpha / (2 * n)
    out: list[tuple[int, StillTest, float, float]] = []
    while keep.sum() - 1 >= max(math.ceil(n * (1 - MAX_REJECTED_FRACTION)), MIN_INTERVALS):
        q = {StillTest.MEAN: _chi2(_rates(gm, am, keep, gsens), gse, keep, floor),
             StillTest.DRIFT: _chi2(drift, dse, keep, 4 * floor)}  # a difference of two half-means: 4x
        p = {k: np.where(keep, chi2_sf_array(v, 3), 1.0) for k, v in q.items()}
        test = min(p, key=lambda k: float(p[k].min()))
        i = int(np.argmin(p[test]))
        if not p[test][i] < p_cut:
            break
        keep[i] = False
        out.append((i, test, float(q[test][i]), float(p[test][i])))
    rate = _rates(gm, am, keep, gsens)  # against the model of the intervals finally kept
    return Stillness(keep, tuple(NotStill(i, float(data.t[data.start[i]]), float(data.t[data.end[i] - 1]),
                                          _floats(rate[i]), _floats(drift[i]), test, qi, pi)
                                 for i, test, qi, pi in out), alpha, True)


def _rates(gm: np.ndarray, am: np.ndarray, keep: np.ndarray, gsens: str) -> np.ndarray:
    """Every interval's mean rate minus the static model fitted to the intervals ``keep`` [raw unit]."""
    st = fit_static(gm[keep], am[keep], gsens)
    return gm - st.bias - am @ st.H.T


def _floats(v: np.ndarray) -> tuple[float, float, float]:
    return (float(v[0]), float(v[1]), float(v[2]))
