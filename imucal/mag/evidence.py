"""The rows of a magnetometer fit: what each kind of evidence sees, and the noise of each row.

  NORM rows   every sample: |h| - F (the field's magnitude holds still or moving; a lag does not matter)
  DIP rows    one per pose: the means of the magnetometer and of the calibrated accelerometer over a still
              interval's core, or over a short window of a moving log in which the sensor turns little
  SIZE row    F fitted: the scales' overall size held (imucal.mag.model)
  SKEW rows   the symmetric soft iron: the soft iron in the magnetometer's axes held symmetric

The noise of a reading is measured from the log itself, still or moving: the second difference of a
smooth motion is small, that of white noise has variance 6 sigma^2 (robust: the median absolute
deviation). A pose mean's variance is that over its number of samples.

A magnetometer often lags the accelerometer (its own filter, a slower output rate): ``estimate_lag``
cross-correlates how fast each sensor's direction turns, and ``shift`` moves the magnetometer by it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from imucal.errors import ImucalError
from imucal.mag.model import DIP, NORM, SIZE, SKEW_KINDS

#: Robust standard deviation from the median absolute deviation (normal distribution: 1 / Phi^-1(3/4)).
MAD_TO_STD = 1.4826
#: Variance of the second difference of white noise, in units of its variance: 1 + 4 + 1.
SECOND_DIFFERENCE_GAIN = 6.0
#: A window of a moving log is a pose when the field's direction turns less than this across it [deg]:
#: the mean directions of two sensors turning together keep their angle to second order in the turn.
MAX_TURN_DEG = 10.0
#: Samples averaged before directions are differentiated for the lag (the accelerometer is noisy).
LAG_SMOOTH = 5
#: Largest lag searched, in samples either way.
MAX_LAG = 50
#: A lag is estimated only when the motion signals correlate at least this well at the peak.
MIN_LAG_CORRELATION = 0.3


@dataclass(frozen=True)
class Poses:
    """Still poses or quiet windows: sample ranges [start, end) whose means give DIP rows."""

    start: np.ndarray
    end: np.ndarray
    source: str  #: "still intervals" or "windows of N samples"

    @property
    def n(self) -> int:
        return int(self.start.size)

    def means(self, x: np.ndarray) -> np.ndarray:
        cs = np.vstack([np.zeros((1, x.shape[1])), np.cumsum(x, axis=0)])
        return (cs[self.end] - cs[self.start]) / (self.end - self.start)[:, None]

    def subset(self, keep: np.ndarray) -> "Poses":
        return Poses(self.start[keep], self.end[keep], self.source)

    def inside(self, mask: np.ndarray) -> np.ndarray:
        """Which poses lie wholly within the samples of ``mask``."""
        out = np.concatenate([[0], np.cumsum(~np.asarray(mask, bool))])
        return out[self.end] == out[self.start]


@dataclass(frozen=True)
class MagRows:
    """The rows of one fit: readings, covariates (kind, calibrated accelerometer), variances, targets."""

    raw: np.ndarray  #: (N, 3) magnetometer readings or pose means [raw]
    cov: np.ndarray  #: (N, 4) kind, ax, ay, az (the accelerometer's calibrated pose mean on DIP rows)
    var_raw: np.ndarray  #: (N, 3) variance of raw [raw^2]
    var_acc: np.ndarray  #: (N, 3) variance of the accelerometer's mean [its unit^2]
    target: np.ndarray  #: (N,) each row's target (0; the SIZE row's: ln of the held size)
    pose: np.ndarray  #: (N,) the pose of a DIP row, the sample of a NORM row, -1 for SIZE

    @property
    def n(self) -> int:
        return int(self.raw.shape[0])

    @property
    def kind(self) -> np.ndarray:
        return self.cov[:, 0].astype(int)

    def count(self, kind: int) -> int:
        return int(np.sum(self.kind == kind))

    def subset(self, keep: np.ndarray) -> "MagRows":
        return MagRows(self.raw[keep], self.cov[keep], self.var_raw[keep], self.var_acc[keep], self.target[keep],
                       self.pose[keep])

    def without(self, kind: int) -> "MagRows":
        return self.subset(self.kind != kind)

    @staticmethod
    def stack(*parts: "MagRows") -> "MagRows":
        return MagRows(*(np.concatenate([getattr(p, f) for p in parts]) for f in
                         ("raw", "cov", "var_raw", "var_acc", "target", "pose")))


def sample_variance(x: np.ndarray) -> np.ndarray:
    """Per-axis white-noise variance of a log, still or moving, from its second difference (robust)."""
    x = np.asarray(x, float)
    if x.shape[0] < 5:
        return np.zeros(x.shape[1])
    d2 = np.diff(x, 2, axis=0)
    mad = np.median(np.abs(d2 - np.median(d2, axis=0)), axis=0)
    var = (MAD_TO_STD * mad) ** 2 / SECOND_DIFFERENCE_GAIN
    for i in np.flatnonzero(var == 0):  # noise below one step of a coarse quantiser: at least its q^2 / 12
        steps = np.diff(np.unique(x[:, i]))
        var[i] = float(steps.min()) ** 2 / 12 if steps.size else 0.0
    return var


def norm_rows(raw: np.ndarray, var: np.ndarray) -> MagRows:
    """One NORM row per sample."""
    n = raw.shape[0]
    cov = np.zeros((n, 4))
    cov[:, 0] = NORM
    return MagRows(np.asarray(raw, float), cov, np.broadcast_to(var, (n, 3)).copy(), np.zeros((n, 3)), np.zeros(n),
                   np.arange(n))


def dip_rows(raw: np.ndarray, acc: np.ndarray, poses: Poses, var_raw: np.ndarray, var_acc: np.ndarray) -> MagRows:
    """One DIP row per pose: the pose means of both sensors, their variance the sample's over the count."""
    n = poses.end - poses.start
    cov = np.column_stack([np.full(poses.n, float(DIP)), poses.means(acc)])
    return MagRows(poses.means(raw), cov, var_raw[None, :] / n[:, None], var_acc[None, :] / n[:, None],
                   np.zeros(poses.n), np.arange(poses.n))


def size_row(size: float) -> MagRows:
    """The SIZE row: the scales' geometric mean held at ``size`` [raw per field unit]."""
    cov = np.array([[float(SIZE), 0.0, 0.0, 0.0]])
    return MagRows(np.zeros((1, 3)), cov, np.zeros((1, 3)), np.zeros((1, 3)), np.array([np.log(size)]),
                   np.array([-1]))


def skew_rows() -> MagRows:
    """The three SKEW rows: the soft iron held symmetric in the magnetometer's own (permuted) axes."""
    k = len(SKEW_KINDS)
    cov = np.zeros((k, 4))
    cov[:, 0] = SKEW_KINDS
    return MagRows(np.zeros((k, 3)), cov, np.zeros((k, 3)), np.zeros((k, 3)), np.zeros(k), np.full(k, -1))


def windows(n: int, length: int) -> Poses:
    """Consecutive windows of ``length`` samples (the last partial one dropped)."""
    k = n // length
    start = np.arange(k) * length
    return Poses(start, start + length, f"windows of {length} samples")


def quiet_windows(directions: np.ndarray, length: int, max_turn_deg: float = MAX_TURN_DEG) -> Poses:
    """Windows in which the unit vectors ``directions`` (the field's, hard iron removed) turn less than
    ``max_turn_deg`` between the window's first and last quarter."""
    w = windows(directions.shape[0], length)
    q = max(length // 4, 1)
    first = Poses(w.start, w.start + q, "").means(directions)
    last = Poses(w.end - q, w.end, "").means(directions)
    cosang = np.sum(first * last, axis=1) / (np.linalg.norm(first, axis=1) * np.linalg.norm(last, axis=1))
    keep = cosang >= np.cos(np.radians(max_turn_deg))
    return w.subset(keep)


def _unit(x: np.ndarray) -> np.ndarray:
    return x / np.maximum(np.linalg.norm(x, axis=1, keepdims=True), 1e-300)


def _turn_speed(x: np.ndarray) -> np.ndarray:
    """How fast the direction of x turns, per sample (central difference of the smoothed unit vector)."""
    k = np.ones(LAG_SMOOTH) / LAG_SMOOTH
    sm = np.column_stack([np.convolve(x[:, j], k, mode="same") for j in range(3)])
    u = _unit(sm)
    v = np.zeros(len(u))
    v[1:-1] = np.linalg.norm(u[2:] - u[:-2], axis=1)
    return v


@dataclass(frozen=True)
class Lag:
    """The magnetometer's delay behind the accelerometer, from the two sensors' motion."""

    samples: float  #: mag[k] belongs with acc[k - samples]; 0 when not estimated
    correlation: float  #: of the two turn speeds at the peak
    estimated: bool


def estimate_lag(mag_centred: np.ndarray, acc: np.ndarray, max_lag: int = MAX_LAG) -> Lag:
    """Cross-correlate how fast each sensor's direction turns; the peak (refined by a parabola) is the lag.

    ``mag_centred``: the readings with the hard iron taken out (the field's direction needs no more)."""
    a, m = _turn_speed(np.asarray(acc, float)), _turn_speed(np.asarray(mag_centred, float))
    a, m = a - a.mean(), m - m.mean()
    n = len(a)
    max_lag = int(min(max_lag, n // 4))
    den = np.sqrt(np.sum(a * a) * np.sum(m * m))
    if den <= 0 or max_lag < 1:
        return Lag(0.0, 0.0, False)
    lags = np.arange(-max_lag, max_lag + 1)
    # mag lagging by k: m[j] goes with a[j - k]
    c = np.array([np.dot(a[:n - k], m[k:]) if k >= 0 else np.dot(a[-k:], m[:n + k]) for k in lags]) / den
    i = int(np.argmax(c))
    if c[i] < MIN_LAG_CORRELATION:
        return Lag(0.0, float(c[i]), False)
    frac = 0.0
    if 0 < i < len(c) - 1:  # parabola through the peak and its neighbours
        den2 = c[i - 1] - 2 * c[i] + c[i + 1]
        frac = 0.5 * (c[i - 1] - c[i + 1]) / den2 if den2 < 0 else 0.0
    return Lag(float(lags[i] + frac), float(c[i]), True)


def shift(x: np.ndarray, lag: float) -> np.ndarray:
    """x moved earlier by ``lag`` samples (linear interpolation, the ends held): x'[k] = x(k + lag)."""
    if lag == 0:
        return np.asarray(x, float)
    k = np.arange(x.shape[0], dtype=float)
    return np.column_stack([np.interp(k + lag, k, x[:, j]) for j in range(x.shape[1])])


def check_lengths(mag: np.ndarray, acc: np.ndarray | None, source: str | None) -> None:
    if mag.ndim != 2 or mag.shape[1] != 3:
        raise ImucalError(f"magnetometer readings must be N x 3, got {mag.shape}", file=source, field="mx, my, mz",
                          fix="give one row of three field readings (mx, my, mz) per sample")
    for name, x in (("mx, my, mz", mag), ("ax, ay, az", acc)):
        if x is not None and not np.isfinite(x).all():
            raise ImucalError(f"row {int(np.flatnonzero(~np.isfinite(x).all(axis=1))[0])} holds NaN or Inf", file=source,
                              field=name, fix="remove or repair the non-finite rows before calibrating")
    if acc is not None and acc.shape != mag.shape:
        raise ImucalError(f"accelerometer ({acc.shape[0]} rows) and magnetometer ({mag.shape[0]} rows) differ",
                          file=source, field="ax, ay, az", fix="give both sensors on one time base")
