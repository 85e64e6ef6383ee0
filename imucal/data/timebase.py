"""A recording's time base: its time unit, its one sample step, and its times, from the stamps as
read or, where the stamps are jitter, from a clock fitted to them; gaps kept as gaps.

Judged on the steps between stamps, in the stamps' own unit (no unit is needed to judge them):

- the clock step: the median over k of (s[k + CLOCK_SPAN] - s[k]) / CLOCK_SPAN, a robust fit of
  stamp against sample index. A logger's bursts shorter than CLOCK_SPAN samples average out in
  it, and a gap touches only the CLOCK_SPAN spans across it.
- jitter: more than JITTER_FRACTION of the steps are shorter than SHORT_STEP clock steps. A sensor
  sampling at a steady rate never takes two samples a quarter of its period apart; a logger that
  stamps samples when they arrive, in bursts, does.
- a gap: a step longer than GAP_STEPS sample steps after which the stamps stay late (samples are
  missing: the logger paused, or lost one): the median offset of the stamps from the clock over
  the CLOCK_SPAN samples after the step exceeds that over the CLOCK_SPAN samples before it by at
  least half a sample step and half the step's excess. A stamp that was only late (jitter, or a
  good clock's scatter) is followed by early ones and leaves the offset where it was. Long steps
  closer together than 2 x CLOCK_SPAN samples are judged together, the longest first, each jump
  found taken out before the next: a shift is counted once (two gaps that close may be counted
  as one, at the longer step).

The recording's one sample step is the clock step refined end to end (refine): the rate the
report prints, the note names and a given rate is checked against. Stamps
that are not jitter are kept exactly: t = (s - s[0]) x unit. Jittered stamps are re-timed on the
fitted clock: t_k = (k x clock step + the gaps before k) x unit, each gap as long as the jump of the
stamps' offset from the clock across it.

The readers (imucal.data.whole and imucal.data.rosbag, whole; imucal.data.stream, in chunks) feed the same pieces: the
step statistics (StepStats), the decision (decide), the gaps (GapFinder) and the times
(clock_times), so that they give the same times to the bit.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from imucal.constants import TIME_UNITS
from imucal.data.recording import MAX_RATE_HZ, MIN_RATE_HZ, TimeBase, TimeSource
from imucal.errors import ImucalError
from imucal.solve.stats import median

#: Samples over which the clock step is measured [samples]: bursts of fewer samples average out.
CLOCK_SPAN = 64
#: A step shorter than this fraction of the clock step is no sampler's period: a stamp that was
#: taken on arrival (in a burst), not at sampling.
SHORT_STEP = 0.25
#: Stamps are jitter when more than this fraction of their steps are short (SHORT_STEP): real
#: loggers' good stamps have none (the Xsens and ROS recordings: none shorter than 0.5 steps).
JITTER_FRACTION = 0.01
#: A step longer than this many sample steps may be a gap (one lost sample makes a step of 2);
#: it is one when the stamps after it stay late by at least GAP_JUMP sample steps.
GAP_STEPS = 1.5
#: The least lasting jump of the stamps' offset from the clock that is a gap [sample steps]: half a
#: lost sample (the scatter of good stamps and the delays of jittered ones do not last).
GAP_JUMP = 0.5
#: Fewest stamps on either side of a step its jump is told from [samples]: within this many of
#: either end of a recording a lasting jump cannot be told from a late or early stamp.
GAP_WINDOW_MIN = CLOCK_SPAN // 4
#: Most candidate steps judged together (a dense run of long steps is judged in pieces of this
#: many, so that memory and time stay bounded) [steps].
MAX_CLUSTER = 1024
#: The sample rate [Hz] a time unit is judged by when several give an IMU's: the unit whose rate
#: lies closest to it on a log scale (MEMS loggers record at about 50 Hz to 1 kHz; 200 Hz is
#: their middle). One rule for integer and fractional stamps: 0.9995 is milliseconds (1 kHz),
#: not seconds (1 Hz).
TYPICAL_RATE_HZ = 200.0
#: Two units whose rates are within this many decades of equally close to TYPICAL_RATE_HZ are not
#: told apart by the step (a step of 0.2: 5 Hz in s or 5 kHz in ms): --time-unit is asked for.
AMBIGUOUS_DECADES = 0.3
#: A sample rate given beside a time column is checked against the column's rate: they may differ
#: by this fraction (a nominal rate against the sensor's clock; MEMS oscillators are specified to
#: a few per cent), not more (a wrong rate, or the wrong column, is off by a factor).
RATE_TOLERANCE = 0.05
#: Time stamps this large, read in a unit, are epoch times (1998 .. 2103) [s].
_EPOCH_S = (9.0e8, 4.2e9)
#: The units a time column's unit is inferred among. Minutes are not: a 100 Hz log stamped in
#: minutes steps like a 6 kHz one in seconds (minutes_hint names them when they are the answer).
INFERRED_UNITS = ("s", "ms", "us", "ns")


def _distinct(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``np.unique(x, return_counts=True)`` of finite values (steps of a chunked reader's stamps), the
    same arrays, counted in pandas' hash table and then sorted: some 3 times faster on a block of
    steps, which hold few distinct values. pandas is loaded already: it parsed the block."""
    import pandas as pd

    vc = pd.Series(x, copy=False).value_counts(sort=False)
    v, c = vc.index.to_numpy(np.float64), vc.to_numpy(np.int64)
    order = np.argsort(v)
    return v[order], c[order]


class ValueCounts:
    """Distinct values with their counts, fed in chunks: the exact median of all values (as
    imucal.solve.stats.median) and how many lie below or above a bound."""

    def __init__(self) -> None:
        self.values = np.empty(0)
        self.counts = np.empty(0, np.int64)

    def add(self, x: np.ndarray) -> None:
        if x.size == 0:
            return
        v, c = _distinct(x)
        u, inv = np.unique(np.concatenate([self.values, v]), return_inverse=True)
        cnt = np.zeros(u.size, np.int64)
        np.add.at(cnt, inv, np.concatenate([self.counts, c]))
        self.values, self.counts = u, cnt

    def median(self) -> float:
        m = int(self.counts.sum())
        if m == 0:
            return float("nan")
        cum = np.cumsum(self.counts)
        lo = self.values[np.searchsorted(cum, (m - 1) // 2, side="right")]
        hi = self.values[np.searchsorted(cum, m // 2, side="right")]
        return float(np.mean([lo, hi]))

    def below(self, bound: float) -> int:
        return int(self.counts[self.values < bound].sum())

    def above(self, bound: float) -> int:
        return int(self.counts[self.values > bound].sum())


class LagDiffs:
    """s[k + lag] - s[k] of a series fed in chunks (the clock step's spans), into ValueCounts."""

    def __init__(self, lag: int = CLOCK_SPAN) -> None:
        self.lag, self.tail, self.counts = lag, np.empty(0), ValueCounts()

    def add(self, x: np.ndarray) -> None:
        y = np.concatenate([self.tail, x])
        if y.size > self.lag:
            self.counts.add(y[self.lag:] - y[:-self.lag])
        self.tail = y[-self.lag:]


@dataclass(frozen=True)
class StepStats:
    """What a time base is decided on, in the stamps' unit (one pass over the stamps)."""

    n: int
    first: float  #: the first stamp
    last: float  #: the last stamp
    median_step: float
    span_median: float  #: median of s[k + CLOCK_SPAN] - s[k] (nan with too few stamps)
    head: np.ndarray  #: the first CLOCK_SPAN stamps (all, with fewer)
    tail: np.ndarray  #: the last CLOCK_SPAN stamps (all, with fewer)
    short: Callable[[float], int]  #: number of steps below a bound
    long: Callable[[float], int]  #: number of steps above a bound

    @property
    def clock_step(self) -> float:
        """The robust fit's step: the span median / CLOCK_SPAN (the mean step with fewer stamps)."""
        if math.isfinite(self.span_median):
            return self.span_median / CLOCK_SPAN
        return (self.last - self.first) / (self.n - 1) if self.n > 1 else float("nan")


def step_stats(stamps: np.ndarray) -> StepStats:
    """StepStats of stamps read whole (the chunked reader fills the same from ValueCounts)."""
    d = np.diff(stamps)
    span = stamps[CLOCK_SPAN:] - stamps[:-CLOCK_SPAN] if stamps.size > CLOCK_SPAN else np.empty(0)
    return StepStats(n=int(stamps.size), first=float(stamps[0]), last=float(stamps[-1]),
                     median_step=median(d) if d.size else float("nan"),
                     span_median=median(span) if span.size else float("nan"),
                     head=stamps[:CLOCK_SPAN].copy(), tail=stamps[-CLOCK_SPAN:].copy(),
                     short=lambda b: int(np.count_nonzero(d < b)), long=lambda b: int(np.count_nonzero(d > b)))


@dataclass(frozen=True)
class Decision:
    """The time base decided from StepStats: unit, note, and the step the times are made from."""

    unit: str
    note: str
    jittered: bool
    #: the sample step in the stamps' unit: a jittered clock's (StepStats.clock_step), good stamps' median step (lost
    #: samples lengthen the clock's span median: a logger dropping every 10th sample read as 0.9 of its rate, the
    #: losses not named as gaps); refine fits either end to end
    step: float
    gap_ref: float  #: steps longer than GAP_STEPS x this are gap candidates
    short_fraction: float
    rate_given: float | None
    time_unit: str  #: the unit asked for (data.time_unit: "auto" or a unit; or the one the column's name states)
    column: str = ""  #: the time column's name

    @property
    def rate(self) -> float:
        return 1.0 / (self.step * TIME_UNITS[self.unit]) if self.step > 0 else float("nan")


#: Names of a time column (lower case), and the units a name may state after one of them: t, time,
#: timestamp, stamp with a suffix such as _ms, _s, (us), [ns] or " sec" (timestamp_ms, time_s, t_ms).
TIME_NAMES = ("timestamp", "time_stamp", "stamp", "time", "t")
TIME_NAME_UNITS = {"s": "s", "sec": "s", "secs": "s", "second": "s", "seconds": "s",
                   "ms": "ms", "msec": "ms", "millis": "ms", "millisecond": "ms", "milliseconds": "ms",
                   "us": "us", "\u00b5s": "us", "\u03bcs": "us", "usec": "us", "micros": "us", "microsecond": "us",
                   "microseconds": "us", "ns": "ns", "nsec": "ns", "nanos": "ns", "nanosecond": "ns",
                   "nanoseconds": "ns", "min": "min", "minute": "min", "minutes": "min"}


def time_column_name(name: str) -> tuple[bool, str | None]:
    """Whether a column ``name`` names time (TIME_NAMES), and the unit it states (None: none stated)."""
    n = name.strip().strip("\"'").lower().lstrip("#%").strip()  # "#timestamp [ns]" (EuRoC), "%time" (rostopic)
    for base in TIME_NAMES:
        if n.startswith(base):
            rest = n[len(base):].strip(" _-.:()[]{}")
            if not rest:
                return True, None
            if rest in TIME_NAME_UNITS:
                return True, TIME_NAME_UNITS[rest]
    return False, None


def decide(st: StepStats, time_unit: str, rate_given: float | None, column: str, path: Path) -> Decision:
    """Jitter or not, the unit (given, stated by the column's name, or inferred from the step), the step,
    the rate check."""
    named = time_column_name(column)[1]
    if time_unit == "auto" and named is not None:  # timestamp_ms: the column says its unit
        time_unit = named
    clock = st.clock_step
    short = st.short(SHORT_STEP * clock) if st.n > 1 and clock > 0 else 0
    frac = short / (st.n - 1) if st.n > 1 else 0.0
    jittered = frac > JITTER_FRACTION
    shown, what = _shown(jittered, st.median_step, clock)
    unit, note = _unit_and_note(shown, what, st.first, time_unit, rate_given, path, column)
    if st.n > 1:  # good stamps' own step: lost samples (a logger's dropouts) lengthen the clock's span median
        check_rate(clock if jittered else st.median_step, unit, path)
    dec = Decision(unit=unit, note=note, jittered=jittered, step=clock if jittered else st.median_step, gap_ref=clock if jittered else st.median_step,
                   short_fraction=frac, rate_given=rate_given, time_unit=time_unit, column=column)
    if rate_given is not None and st.n > 1 and abs(dec.rate / rate_given - 1.0) > RATE_TOLERANCE:
        raise ImucalError(f"sample rate {rate_given:g} Hz given, but the time column {column} steps at "
                          f"{dec.rate:.4g} Hz ({what} {shown:g} {unit}): two sources of time disagree",
                          file=str(path), field="data.sample_rate",
                          fix=f"drop --sample-rate (data.sample_rate) to use the time column, or map the right "
                              f"time column (--columns t=...); they may differ by {100 * RATE_TOLERANCE:g} %")
    return dec


def _unit_and_note(step: float, what: str, first: float, time_unit: str, rate_given: float | None,
                   path: Path, column: str = "") -> tuple[str, str]:
    """The unit (given, or stated by the column's name; or the one the given rate names; or inferred
    from the step) and its note."""
    if time_unit != "auto":
        if time_column_name(column)[1] == time_unit:
            return time_unit, f"time unit from the column name {column}: {time_unit}"
        return time_unit, f"time unit given: {time_unit}"
    if rate_given is not None and (unit := _unit_of_rate(step, rate_given)) is not None:
        return unit, (f"time unit inferred: {unit} ({what} {step:g} -> {1.0 / (step * TIME_UNITS[unit]):.4g} Hz, "
                      f"the sample rate given)")
    return time_unit_from_step(step, first, what, path)


def refine(dec: Decision, st: StepStats, gap_index: np.ndarray, gap_step: np.ndarray, path: Path
           ) -> tuple[Decision, np.ndarray]:
    """The clock step fitted end to end: the offset of the last CLOCK_SPAN stamps from the clock,
    less that of the first and less the gaps between, over the samples between (each end's
    offset a median). The span median the gaps were found with is robust but not exact: biased by
    uneven bursts, blind to the odd short step of a good clock (the Xsens log's: 100.000 Hz for
    its 100.010). Returns the refined decision (its note names the refined rate) and the gaps'
    steps (a jittered clock's on the refined step; good stamps' as read)."""
    between = (st.n - st.tail.size) + (st.tail.size - st.head.size) / 2  # from the middle of one end to the other's
    if st.n < 2 or between <= 0:
        return dec, gap_step
    T = dec.step
    jumps = np.concatenate([[0.0], np.cumsum(gap_step - T)])

    def offset(stamps: np.ndarray, i0: int) -> float:
        i = np.arange(i0, i0 + stamps.size)
        return median(stamps - i * T - jumps[np.searchsorted(gap_index, i, side="right")])

    step = T + (offset(st.tail, st.n - st.tail.size) - offset(st.head, 0)) / between
    unit, note = _unit_and_note(*_shown(dec.jittered, st.median_step, step), st.first, dec.time_unit,
                                dec.rate_given, path, dec.column)
    if unit != dec.unit or not step > 0:  # pragma: no cover - a step moved by a unit's factor: keep the decision
        return dec, gap_step
    return replace(dec, step=step, note=note), (gap_step - T + step if dec.jittered else gap_step)


def _shown(jittered: bool, median_step: float, step: float) -> tuple[float, str]:
    """The step a note names: the median step where it prints the clock's rate (good stamps: the
    words they always had), else the clock step (jitter; stamps rounded coarser than their step,
    as 3, 3, 4 ms for 3.33 ms)."""
    if not jittered and f"{1 / median_step:.4g}" == f"{1 / step:.4g}":
        return median_step, "median step"
    return step, "clock step"


def _unit_of_rate(step: float, rate: float) -> str | None:
    """The one unit in which ``step`` gives ``rate`` within RATE_TOLERANCE, else None."""
    if not (math.isfinite(step) and step > 0):
        return None
    hits = [u for u, f in TIME_UNITS.items() if abs(1.0 / (step * f) / rate - 1.0) <= RATE_TOLERANCE]
    return hits[0] if len(hits) == 1 else None


def time_unit_from_step(dt: float, first: float, what: str = "median step", path: Path | None = None
                        ) -> tuple[str, str]:
    """The unit (s, ms, us, ns) of time stamps with sample step ``dt`` and first stamp ``first``,
    and a sentence saying why; refused when the step cannot tell two units apart.

    The sample rate must be an IMU's (1 Hz to 100 kHz). Among the units that give one, epoch time
    decides when the stamps look like it (1.7e9 s = 1.7e12 ms = ...); otherwise the unit whose
    rate is closest to TYPICAL_RATE_HZ on a log scale, unless another is within AMBIGUOUS_DECADES
    of as close. A second plausible unit is named in the note.
    """
    if not (math.isfinite(dt) and dt > 0):
        return "s", "time unit assumed: s (too few distinct time stamps to infer it)"

    def rate(u: str) -> float:
        return 1.0 / (dt * TIME_UNITS[u])

    plausible = [u for u in INFERRED_UNITS if MIN_RATE_HZ <= rate(u) <= MAX_RATE_HZ]
    if not plausible:
        return "s", ""  # refused by check_rate with the rate in the message
    epoch = [u for u in plausible if _EPOCH_S[0] <= abs(first) * TIME_UNITS[u] <= _EPOCH_S[1]]
    if epoch:
        unit = epoch[0]
        return unit, f"time unit inferred: {unit} (epoch time stamps; {what} {dt:g} {unit} -> {rate(unit):.4g} Hz)"

    def distance(u: str) -> float:
        return decades_from_typical(rate(u))

    plausible.sort(key=distance)
    unit = plausible[0]
    if len(plausible) > 1 and distance(plausible[1]) - distance(unit) < AMBIGUOUS_DECADES:
        alt = plausible[1]
        raise ImucalError(f"the time stamps step by {dt:g}: {rate(unit):.4g} Hz in {unit} or {rate(alt):.4g} Hz in "
                          f"{alt}, which the step alone cannot tell apart", file=None if path is None else str(path),
                          field="data.time_unit",
                          fix=f"give --time-unit {unit} or --time-unit {alt} (data.time_unit)")
    note = f"time unit inferred: {unit} ({what} {dt:g} -> {rate(unit):.4g} Hz"
    if len(plausible) > 1:
        alt = plausible[1]
        note += f"; {alt} would give {rate(alt):.4g} Hz: give --time-unit if that is right"
    return unit, note + ")"


def decades_from_typical(rate: float) -> float:
    return abs(math.log10(rate / TYPICAL_RATE_HZ))


def check_rate(step: float, unit: str, path: Path) -> None:
    """Refuse a sample step (in ``unit``) that gives no IMU sample rate, naming the likely unit.
    The step is the time base's, so a gap (a logger's pause) does not make a unit look wrong."""
    rate = 1.0 / (step * TIME_UNITS[unit])
    if MIN_RATE_HZ <= rate <= MAX_RATE_HZ:
        return
    likely = [u for u, f in TIME_UNITS.items() if MIN_RATE_HZ <= 1.0 / (step * f) <= MAX_RATE_HZ]
    fix = (f"the time column looks like {likely[0]}: give --time-unit {likely[0]} (data.time_unit: {likely[0]})"
           if likely else "check the time column (or drop it and give --sample-rate)")
    raise ImucalError(f"time in {unit} gives {rate:.4g} Hz, not an IMU sample rate "
                      f"({MIN_RATE_HZ:g} Hz to {MAX_RATE_HZ:g} Hz)", file=str(path), field="data.time_unit", fix=fix)


class GapFinder:
    """The gaps of stamps fed in chunks: (index of the sample after each gap, the step across it in
    the time base, in the stamps' unit). The same gaps whatever the chunks.

    Candidates (steps over GAP_STEPS sample steps) closer than 2 x CLOCK_SPAN samples form a
    cluster (of at most MAX_CLUSTER), judged once the stamps after it are in: its longest step
    first (a logger's pause), every accepted gap's jump taken out of the offsets before the next
    step is judged, so that a shift is counted once however many long steps share its windows."""

    def __init__(self, dec: Decision) -> None:
        self.dec = dec
        self.base = 0  #: global index of buf[0]
        self.buf = np.empty(0)
        self.scanned = 0  #: steps below this (step k: samples k to k + 1) are searched for candidates
        self.pending: list[int] = []  #: candidates not yet judged
        self.index: list[int] = []  #: accepted gaps, cluster by cluster
        self.jump: list[float] = []
        self.step: list[float] = []

    def add(self, stamps: np.ndarray, final: bool = False) -> None:
        buf = np.concatenate([self.buf, stamps])
        end = self.base + buf.size  # stamps in so far
        if end - 1 > self.scanned:
            k = np.arange(self.scanned, end - 1)
            d = buf[k + 1 - self.base] - buf[k - self.base]
            self.pending += k[d > GAP_STEPS * self.dec.gap_ref].tolist()
            self.scanned = end - 1
        while self.pending:
            p = self.pending[:MAX_CLUSTER + 1]
            n = next((i + 1 for i in range(len(p) - 1) if p[i + 1] - p[i] >= 2 * CLOCK_SPAN), min(len(p), MAX_CLUSTER))
            after = end - 1 - p[n - 1]  # stamps in after the cluster's last step
            closed = n < len(p) or after >= 2 * CLOCK_SPAN  # no later step can join it
            if not final and not (closed and after >= CLOCK_SPAN):
                break  # the cluster may grow, or its last windows are not in yet
            self._judge(p[:n], buf, end)
            del self.pending[:n]
        first = min([self.scanned, *self.pending]) + 1 - CLOCK_SPAN  # the next windows start here
        keep = max(0, min(first, end) - self.base)
        self.base, self.buf = self.base + keep, buf[keep:]

    def _judge(self, ks: list[int], buf: np.ndarray, end: int) -> None:
        """Judge one cluster of candidate steps (global indices ``ks``), the longest first."""
        T = self.dec.step
        lo, hi = max(ks[0] + 1 - CLOCK_SPAN, 0), min(ks[-1] + 1 + CLOCK_SPAN, end)
        i = np.arange(lo, hi)
        r = buf[i - self.base] - i * T  # the stamps' offset from the clock ...
        for g, jump in zip(self.index[::-1], self.jump[::-1]):  # ... less the gaps already found in it
            if g <= lo:
                break
            r[g - lo:] -= jump
        k = np.array(ks)
        d = buf[k + 1 - self.base] - buf[k - self.base]
        for j in np.argsort(-d, kind="stable"):
            at = k[j] + 1 - lo  # the first sample after the step, in r
            after, before = r[at:at + CLOCK_SPAN], r[max(at - CLOCK_SPAN, 0):at]
            if min(after.size, before.size) < GAP_WINDOW_MIN:
                continue  # too near an end of the recording to tell from jitter
            jump = median(after) - median(before)
            if jump > 0.5 * (d[j] - T) and jump > GAP_JUMP * T:
                r[at:] -= jump  # counted once: the later windows see it taken out
                self.index.append(int(k[j]) + 1)
                self.jump.append(float(jump))
                # the step across the gap: the stamps' own (kept as read), or the clock's
                self.step.append(T + jump if self.dec.jittered else float(d[j]))

    def finish(self) -> tuple[np.ndarray, np.ndarray]:
        self.add(np.empty(0), final=True)
        order = np.argsort(self.index, kind="stable")
        return np.array(self.index, np.int64)[order], np.array(self.step, float)[order]


def clock_times(row0: int, m: int, dec: Decision, gap_index: np.ndarray, gap_cum: np.ndarray) -> np.ndarray:
    """Times [s] of samples row0 .. row0 + m - 1 on a jittered recording's clock:
    (k x step + the gaps' excess before k) x unit. ``gap_cum``: cumulative excess (gap step - step)."""
    k = np.arange(row0, row0 + m)
    j = np.searchsorted(gap_index, k, side="right")  # gaps at or before k
    extra = np.concatenate([[0.0], gap_cum])[j]
    return (k * dec.step + extra) * TIME_UNITS[dec.unit]


def gap_excess(dec: Decision, gap_step: np.ndarray) -> np.ndarray:
    """Cumulative time (stamps' unit) the gaps add to a clock of one step per sample."""
    return np.cumsum(gap_step - dec.step)


def time_base(dec: Decision, st: StepStats, gap_index: np.ndarray, gap_step: np.ndarray,
              line_of: Callable[[int], int] | None) -> TimeBase:
    """The typed record of a stamped recording's time base (rendered by imucal.report)."""
    f = TIME_UNITS[dec.unit]
    longest = int(gap_index[np.argmax(gap_step)]) if gap_index.size else -1
    return TimeBase(source=TimeSource.CLOCK if dec.jittered else TimeSource.STAMPS, rate=dec.rate,
                    gap_index=gap_index, gap_seconds=gap_step * f,
                    longest_gap_line=line_of(longest) if line_of is not None and longest >= 0 else 0,
                    short_fraction=dec.short_fraction, median_step=st.median_step * f, rate_given=dec.rate_given)


def stamped_times(stamps: np.ndarray, time_unit: str, rate_given: float | None, column: str, path: Path,
                  line_of: Callable[[int], int] | None = None) -> tuple[np.ndarray, str, str, TimeBase]:
    """Times [s] from 0, unit, note and time base of stamps read whole (strictly increasing)."""
    st = step_stats(stamps)
    dec = decide(st, time_unit, rate_given, column, path)
    if dec.jittered or (st.n > 1 and st.long(GAP_STEPS * dec.gap_ref) > 0):
        finder = GapFinder(dec)
        finder.add(stamps)
        gi, gs = finder.finish()
    else:
        gi, gs = np.empty(0, np.int64), np.empty(0)
    dec, gs = refine(dec, st, gi, gs, path)
    if dec.jittered:
        t = clock_times(0, stamps.size, dec, gi, gap_excess(dec, gs))
    else:
        t = (stamps - stamps[0]) * TIME_UNITS[dec.unit]
    return t, dec.unit, dec.note, time_base(dec, st, gi, gs, line_of)


def rate_time_base(rate: float, source: str = "given") -> tuple[str, str, TimeBase]:
    """Unit, note and time base of a recording without a time column, at the rate [Hz] ``source`` names
    (given; or stated by the file: a metadata line above the header)."""
    return "s", f"no time column: {float(rate):g} Hz {source}", TimeBase(source=TimeSource.RATE, rate=float(rate))
