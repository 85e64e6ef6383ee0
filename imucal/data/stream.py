"""Long recordings in bounded memory: the text parsed once, static intervals detected from a binary
spill of its numbers, only what the fit needs kept.

The rules are the whole-file reader's (imucal.data.layout: header, column roles; imucal.data.lines:
the same one-line errors for the same bad line; imucal.data.timebase: the time base) and
imucal.data.static's (the same moving variance, threshold and per-interval statistics, computed by
the same functions), so the intervals and the fit are those of the in-memory path. The text is read
in blocks of about CHUNK_BYTES (imucal.data.blocks: pandas' C parser, or line by line for anything
unusual, which names the bad line).

One pass over the text: parse, SHA-256, value and time-stamp checks, the stamps' step statistics,
and the moving variance with the window guessed from the first block; the numbers go to a binary
spill (imucal.data.spill: float64, in an unnamed temporary file). Every later pass reads the spill:
the gaps of the stamps (when they are jitter or have a long step), the moving variance again in the
rare case the guessed window or time unit was wrong (or the stamps are jitter: the times are then
made on the fitted clock), the statistics of each still interval, and after the fit the residual of
every static sample. The moving-variance series is spilled too (float32). Memory: a block, the
histograms of the threshold, and a few numbers per interval, whatever the length of the log.
"""
from __future__ import annotations

import functools
import os
from collections.abc import Iterator
import dataclasses
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from imucal.constants import TIME_UNITS
from imucal.data.blocks import TextBlocks
from imucal.data.counter_wrap import CounterWrap
from imucal.data.layout import header_spec, other_instance
from imucal.data.lines import corrupt_value, no_rows, not_increasing
from imucal.data.run_pool import batches, ordered_map, run_workers
from imucal.data.recording import MAX_ABS_VALUE, RecordingSummary, StaticSamples, TimeBase, temperature_error
from imucal.data.spec import DataSpec, as_spec, resolve_path
from imucal.data.spill import RowSpill, temporary_file
from imucal.data.static import (QUANTUM_ROWS, Intervals, MovingVariance, Segment, StaticSettings, VarianceStore,
                                at_rate, auto_threshold, candidate_runs, column_extremes, cut_runs, edge_samples,
                                intervals_from, judge_runs, quantum, window_samples)
from imucal.data.timebase import (CLOCK_SPAN, GAP_STEPS, Decision, GapFinder, LagDiffs, StepStats, ValueCounts,
                                  clock_times, decide, gap_excess, rate_time_base, refine, time_base,
                                  time_unit_from_step)
from imucal.errors import ImucalError
from imucal.model.channels import TEMPERATURE_RATE_WINDOW, temperature_rate
from imucal.solve.stats import median


class _Steps(ValueCounts):
    """The differences of a series fed in chunks (carried across chunks), counted exactly."""

    def __init__(self) -> None:
        super().__init__()
        self.last: float | None = None

    def feed(self, x: np.ndarray) -> None:
        if x.size == 0:
            return
        d = np.diff(x) if self.last is None else np.diff(np.concatenate([[self.last], x]))
        self.last = float(x[-1])
        self.add(d)


@dataclass(frozen=True)
class _Clock:
    """A jittered recording's clock (imucal.data.timebase): the decision and its gaps."""

    dec: Decision  #: refined (imucal.data.timebase.refine)
    gap_index: np.ndarray
    gap_step: np.ndarray  #: in the stamps' unit, on the refined clock

    @property
    def cum(self) -> np.ndarray:
        return gap_excess(self.dec, self.gap_step)


@dataclass
class _Parsed:
    """What the one pass over the text learnt, besides the numbers it spilled."""

    n: int = 0
    t_first: float = 0.0  #: first stamp as read (0 without stamps)
    last_stamp: float | None = None
    big: ImucalError | None = None  #: the first value beyond MAX_ABS_VALUE
    order: ImucalError | None = None  #: the first stamp that does not increase
    lows: np.ndarray = field(default_factory=lambda: np.full(3, np.inf))
    highs: np.ndarray = field(default_factory=lambda: np.full(3, -np.inf))
    stamp_steps: _Steps = field(default_factory=_Steps)
    spans: LagDiffs = field(default_factory=LagDiffs)  #: its tail: the last CLOCK_SPAN stamps
    head_stamps: list = field(default_factory=list)  #: the first CLOCK_SPAN stamps
    wrap: CounterWrap = field(default_factory=CounterWrap)  #: the time column unwrapped (a counter's)
    head_raw: list = field(default_factory=list)  #: the first QUANTUM_ROWS readings
    blocks: list = field(default_factory=list)  #: (byte offset, bytes, first row) of each block with rows


@dataclass
class _Timing:
    """The times of every sample in one unit (on one clock) and the moving variance with one window,
    accumulated block by block: the window is guessed from the first block when not given."""

    unit: str | None
    w: int | None
    clock: _Clock | None
    t_steps: _Steps = field(default_factory=_Steps)
    t_last: float = 0.0
    mv: MovingVariance | None = None


@dataclass
class _Scan:
    """The time base and the detector's inputs, decided from the whole file."""

    n: int
    unit: str
    note: str
    t_first: float
    t_last: float  #: last sample's time [s] from the first
    dt: float  #: median step of t [s]
    w: int
    q: float
    lows: np.ndarray
    highs: np.ndarray
    time_base: TimeBase
    clock: _Clock | None  #: the clock the times are made on (jittered stamps)


#: Rows beyond the rate's window taken from a neighbouring block (temperature_rate takes the nearest rows
#: when its window holds fewer than its least: a log below 0.1 Hz).
RATE_CONTEXT = 3


class StreamedRecording:
    """A recording read in chunks: its summary, static intervals, and (samples mode) static samples."""

    def __init__(self, spec: DataSpec | str | os.PathLike, settings: StaticSettings = StaticSettings(),
                 base_dir: str | os.PathLike | None = None, rails: dict | None = None,
                 keep_samples: bool = False) -> None:
        """``keep_samples``: keep the static samples (samples mode). Gyroscope columns are not read."""
        self.spec = as_spec(spec)
        self.settings, self.rails = settings, rails
        self.file = TextBlocks(self.spec, resolve_path(self.spec, base_dir))
        self.path: Path = self.file.path
        self._rate_source = "given" if self.spec.sample_rate is not None else "stated above the header"
        self.spec = header_spec(self.spec, self.file.lay, self.path)  # units the header states, a rate above it
        self._it = {r: i for i, r in enumerate(self.file.lay.roles)}
        self.spill = RowSpill(len(self._it))
        parsed, timing = self._parse()
        scan, timing = self._decide(parsed, timing)
        self._scan = scan
        self.recording = RecordingSummary(n=scan.n, t_last=scan.t_last, unit=self.spec.unit, source=str(self.path),
                                          sha256=self.file.sha, time_unit=scan.unit, time_note=scan.note,
                                          time_column=self.file.lay.time_column, time_base=scan.time_base,
                                          columns=self.file.lay.names, unit_stated_by=self.file.lay.names.get(
                                              "ax", "") if "unit" in self.file.lay.units else "")
        self.intervals, self.samples = self._intervals(scan, timing.mv.finish(), keep_samples)

    # --- columns of a block -------------------------------------------------------------------
    def _times(self, arr: np.ndarray, row0: int, unit: str, t_first: float, clock: _Clock | None) -> np.ndarray:
        if "t" in self._it:
            if clock is not None:
                return clock_times(row0, arr.shape[0], clock.dec, clock.gap_index, clock.cum)
            return (arr[:, self._it["t"]] - t_first) * TIME_UNITS[unit]
        return np.arange(row0, row0 + arr.shape[0]) / float(self.spec.sample_rate)

    def _temp(self, arr: np.ndarray) -> np.ndarray | None:
        return arr[:, self._it["temp"]].copy() if "temp" in self._it else None

    def _raw(self, arr: np.ndarray) -> np.ndarray:
        i = self._it
        return np.column_stack([arr[:, i["ax"]], arr[:, i["ay"]], arr[:, i["az"]]])

    # --- the one pass over the text -----------------------------------------------------------
    def _parse(self) -> tuple[_Parsed, _Timing]:
        """Parse every block once: hash, check values and time stamps, step statistics, spill, and
        the times and moving variance with the time unit and window guessed from the first block."""
        p = _Parsed()
        timing: _Timing | None = None
        for first, block, arr in self.file.rows(hash_it=True):
            if arr.shape[0] == 0:
                continue
            p.blocks.append((first, len(block), p.n))
            self._check_block(p, first, block, arr)
            if p.big is None and p.order is None:
                self.spill.add(arr)
                raw = self._raw(arr)
                lo, hi = column_extremes(raw)
                p.lows, p.highs = np.minimum(p.lows, lo), np.maximum(p.highs, hi)
                if sum(h.shape[0] for h in p.head_raw) < QUANTUM_ROWS:
                    p.head_raw.append(raw[:QUANTUM_ROWS])
                if timing is None:  # a guess from the first block, checked once the file is read
                    unit = _guess_unit(self.spec, arr[:, self._it["t"]]) if "t" in self._it else "s"
                    timing = _Timing(unit, None, None)
                self._time_block(timing, p.n, arr, raw, p.t_first)
            p.n += arr.shape[0]
        if self.file.unparsed is not None:
            raise self.file.unparsed
        if p.n == 0:
            raise no_rows(self.path)
        for err in (p.big, p.order):
            if err is not None:
                raise err
        return p, timing

    def _check_block(self, p: _Parsed, first: int, block: bytes, arr: np.ndarray) -> None:
        """Values beyond MAX_ABS_VALUE and time stamps that do not increase (the first of each is
        kept); the stamps' step statistics."""
        if p.big is None and (arr.max() > MAX_ABS_VALUE or arr.min() < -MAX_ABS_VALUE):  # no copy of the block
            bad = (np.abs(arr) > MAX_ABS_VALUE).any(axis=1)
            p.big = corrupt_value(self.file.line_of(block, first, int(np.flatnonzero(bad)[0])), self.path)
        if p.big is None and self.file.lay.instance is not None:  # one sensor's rows, past the head too
            try:
                other_instance(block.decode("utf-8", errors="replace").splitlines(), self.file.lay, self.path,
                               lambda k: self.file.line_of(block, first, k))
            except ImucalError as exc:
                p.big = exc
        if p.big is None and "temp" in self._it:  # as the whole file's Recording refuses it
            p.big = temperature_error(arr[:, self._it["temp"]], str(self.path), p.n)
        if "t" not in self._it:
            return
        stamps = p.wrap.feed(arr[:, self._it["t"]])  # a counter that wrapped (micros()), unwrapped
        arr[:, self._it["t"]] = stamps  # (the spill and every later pass read them so)
        if p.n == 0:
            p.t_first = float(stamps[0])
        if p.order is None:
            prev = p.last_stamp
            x = stamps if prev is None else np.concatenate([[prev], stamps])
            bad = ~(np.diff(x) > 0)
            if bad.any():
                j = int(np.flatnonzero(bad)[0])  # x[j] -> x[j + 1]
                k = j + (1 if prev is None else 0)
                p.order = not_increasing(self.file.line_of(block, first, k), self.path, float(x[j]), float(x[j + 1]))
        p.last_stamp = float(stamps[-1])
        p.stamp_steps.feed(stamps)
        p.spans.add(stamps)
        if sum(h.size for h in p.head_stamps) < CLOCK_SPAN:
            p.head_stamps.append(stamps[:CLOCK_SPAN].copy())

    def _time_block(self, timing: _Timing, row0: int, arr: np.ndarray, raw: np.ndarray, t_first: float) -> None:
        """The times of a block in the timing's unit (on its clock) and its moving variance."""
        t = self._times(arr, row0, timing.unit, t_first, timing.clock)
        timing.t_steps.feed(t)
        if timing.w is None:
            timing.w = window_samples(self.settings, median(np.diff(t))) if t.size > 1 else 3
        if timing.mv is None:
            timing.mv = MovingVariance(timing.w, VarianceStore(temporary_file("the moving variance")))
        timing.mv.add(raw)
        timing.t_last = float(t[-1])

    def _retime(self, unit: str, w: int, clock: _Clock | None, t_first: float) -> _Timing:
        """The times and moving variance again, from the spill, in ``unit`` with window ``w``."""
        timing = _Timing(unit, w, clock)
        for row0, arr in self.spill.blocks():
            self._time_block(timing, row0, arr, self._raw(arr), t_first)
        return timing

    # --- the time base --------------------------------------------------------------------------
    def _decide(self, p: _Parsed, timing: _Timing) -> tuple[_Scan, _Timing]:
        """The time base decided on every stamp; the times and moving variance redone from the spill
        when the guessed unit or window was wrong, or on the fitted clock (jittered stamps)."""
        n, spec = p.n, self.spec
        clock = None
        if "t" in self._it:
            stats = StepStats(n=n, first=p.t_first, last=p.last_stamp, median_step=p.stamp_steps.median(),
                              span_median=p.spans.counts.median(),
                              head=np.concatenate(p.head_stamps)[:CLOCK_SPAN], tail=p.spans.tail[-CLOCK_SPAN:],
                              short=p.stamp_steps.below, long=p.stamp_steps.above)
            dec = decide(stats, spec.time_unit, spec.sample_rate, self.file.lay.time_column, self.path)
            if dec.jittered or (n > 1 and stats.long(GAP_STEPS * dec.gap_ref) > 0):
                gi, gs = self._gaps(dec)
            else:
                gi, gs = np.empty(0, np.int64), np.empty(0)
            dec, gs = refine(dec, stats, gi, gs, self.path)
            clock = _Clock(dec, gi, gs) if dec.jittered else None
            unit, note = dec.unit, "; ".join(x for x in (dec.note, p.wrap.note) if x)
            tb = dataclasses.replace(time_base(dec, stats, gi, gs, lambda k: self._row_line(p.blocks, k)),
                                     wraps=p.wrap.wraps)
        else:
            unit, note, tb = rate_time_base(spec.sample_rate, self._rate_source)
        if n < 3:  # as detect_static
            raise ImucalError(f"only {n} samples", file=str(self.path), field="data",
                              fix="record several seconds in each orientation")
        # The window comes from the median step of the whole file's times: those of the parse, when they
        # were made in the right unit (and clock); else from the stamps' step, and the times made again.
        for attempt in range(3):
            same = timing.unit == unit and (timing.clock is None) == (clock is None)
            w = window_samples(self.settings, timing.t_steps.median() if same else tb.step)
            if same and w == timing.w:
                break
            if attempt == 2:  # pragma: no cover - the times made in the right unit give their own window
                raise ImucalError("the time step changed between passes", file=str(self.path), field="data.path")
            timing = self._retime(unit, w, clock, p.t_first)
        dt = timing.t_steps.median()
        return _Scan(n=n, unit=unit, note=note, t_first=p.t_first, t_last=timing.t_last, dt=dt, w=timing.w,
                     q=quantum(np.concatenate(p.head_raw)), lows=p.lows, highs=p.highs, time_base=tb,
                     clock=clock), timing

    def _gaps(self, dec: Decision) -> tuple[np.ndarray, np.ndarray]:
        """The gaps of the stamps (imucal.data.timebase.GapFinder), from the spill."""
        finder = GapFinder(dec)
        for stamps in self.spill.column_blocks(self._it["t"]):
            finder.add(stamps)
        return finder.finish()

    def _row_line(self, blocks: list, k: int) -> int:
        """The file's line of data row ``k`` (blocks: the parse's (offset, bytes, first row))."""
        i = max(0, np.searchsorted([b[2] for b in blocks], k, side="right") - 1)
        offset, size, row0 = blocks[i]
        with self.file._open() as f:
            f.seek(offset)
            block = f.read(size)
        return self.file.line_of(block, offset, k - row0)

    # --- intervals ------------------------------------------------------------------------------
    def _intervals(self, scan: _Scan, var, keep_samples: bool) -> tuple[Intervals, StaticSamples | None]:
        st = at_rate(self.settings, scan.dt)  # as detect_static
        thr = st.threshold if st.threshold is not None else auto_threshold(var, scan.q)
        a, b = candidate_runs(var, thr, int(round(st.trim / scan.dt)))
        var.store.close()
        has_temp = "temp" in self._it
        segs: list[Segment] = []
        kept: dict[int, tuple] = {}
        m = edge_samples(scan.dt)

        judge = functools.partial(judge_runs, args=(scan.lows, scan.highs, self.rails, st, m, scan.q))
        runs = batches(cut_runs(self._pieces(a, b), st.split), lambda piece: piece[1].shape[0])
        for batch, found in ordered_map(judge, runs, run_workers(a.size)):
            for (start, raw, t, temp), g in zip(batch, found):
                if g is not None:
                    segs.append(g)
                    if keep_samples:
                        lo, hi = g.start - start, g.end - start
                        kept[g.start] = (raw[lo:hi], t[lo:hi], None if temp is None else temp[lo:hi])
        iv = intervals_from(segs, thr, scan.q, st, scan.lows, scan.highs, self.rails, has_temp)
        if has_temp and iv.n:  # each hold's dT/dt as the whole file's reader gives it (detect_static)
            iv = dataclasses.replace(iv, temp_rate=self._hold_rates(iv))
        if not keep_samples:
            return iv, None
        parts = [kept[int(s)] for s in iv.start]
        return iv, _samples(parts, has_temp)

    def _hold_rates(self, iv: Intervals) -> np.ndarray:
        """imucal.model.channels.hold_rates of the intervals, a block of the spill at a time: each block's
        per-sample rates from its samples and the rows within the rate's window (and RATE_CONTEXT more) before
        and after it, summed over the intervals' samples."""
        sums = np.zeros(iv.n)
        half = TEMPERATURE_RATE_WINDOW / 2
        stream = ((row0, t, temp) for row0, _, t, temp in self._arrays())
        back_t, back_T = np.empty(0), np.empty(0)  # the rows before the block, within its window
        ahead: list[tuple] = []  # blocks read ahead
        cur = next(stream, None)
        while cur is not None:
            row0, t, temp = cur
            while not ahead or (ahead[-1] is not None and ahead[-1][1][-1] <= t[-1] + half):
                ahead.append(next(stream, None))
                if ahead[-1] is None:
                    break
            nxt = [b for b in ahead if b is not None]
            fwd_t = np.concatenate([b[1] for b in nxt]) if nxt else np.empty(0)
            fwd_T = np.concatenate([b[2] for b in nxt]) if nxt else np.empty(0)
            i1 = min(fwd_t.size, int(np.searchsorted(fwd_t, t[-1] + half, "right")) + RATE_CONTEXT)
            i0 = max(0, int(np.searchsorted(back_t, t[0] - half)) - RATE_CONTEXT)
            tt = np.concatenate([back_t[i0:], t, fwd_t[:i1]])
            TT = np.concatenate([back_T[i0:], temp, fwd_T[:i1]])
            skip = back_t.size - i0
            c = np.concatenate([[0.0], np.cumsum(temperature_rate(tt, TT)[skip:skip + t.size])])
            row1 = row0 + t.size
            for j in np.flatnonzero((iv.start < row1) & (iv.end > row0)):
                sums[j] += c[min(iv.end[j], row1) - row0] - c[max(iv.start[j], row0) - row0]
            back_t, back_T = np.concatenate([back_t[i0:], t]), np.concatenate([back_T[i0:], temp])
            keep = max(0, int(np.searchsorted(back_t, back_t[-1] - half)) - RATE_CONTEXT)
            back_t, back_T = back_t[keep:], back_T[keep:]
            cur = ahead.pop(0) if ahead else None
        return sums / np.maximum(iv.end - iv.start, 1)

    def _arrays(self) -> Iterator[tuple[int, np.ndarray, np.ndarray, np.ndarray | None]]:
        """(first row, raw, t, temp) of every block of the spill."""
        s = self._scan
        for row0, arr in self.spill.blocks():
            yield row0, self._raw(arr), self._times(arr, row0, s.unit, s.t_first, s.clock), self._temp(arr)

    def _pieces(self, a: np.ndarray, b: np.ndarray) -> Iterator[tuple[int, np.ndarray, np.ndarray, np.ndarray | None]]:
        """(first row, raw, t, temp) of each row range [a_i, b_i), in order, from one pass."""
        k = 0
        acc: list[tuple] = []
        if a.size == 0:
            return
        for row0, raw, t, temp in self._arrays():
            row1 = row0 + raw.shape[0]
            while k < a.size and a[k] < row1:
                lo, hi = max(a[k], row0) - row0, min(b[k], row1) - row0
                acc.append((raw[lo:hi], t[lo:hi], None if temp is None else temp[lo:hi]))
                if b[k] > row1:
                    break
                yield int(a[k]), *_join(acc)
                acc = []
                k += 1
            if k == a.size:
                break

    # --- after the fit --------------------------------------------------------------------------
    def static_blocks(self) -> Iterator[StaticSamples]:
        """The static samples of ``self.intervals`` (in order), a block of the spill at a time."""
        if self.samples is not None:
            yield self.samples
            return
        iv = self.intervals
        if iv.n == 0:
            return
        for row0, raw, t, temp in self._arrays():
            row1 = row0 + raw.shape[0]
            k0, k1 = np.searchsorted(iv.end, row0, "right"), np.searchsorted(iv.start, row1, "left")
            if k1 <= k0:
                continue
            idx = np.concatenate([np.arange(max(a, row0), min(b, row1)) - row0
                                  for a, b in zip(iv.start[k0:k1], iv.end[k0:k1])])
            yield StaticSamples(raw[idx], t[idx], None if temp is None else temp[idx])


def _guess_unit(spec: DataSpec, stamps: np.ndarray) -> str:
    """The time unit from a first block's stamps: only a guess (the times are made again when the
    whole file decides another), so a block the step cannot read is guessed s, not refused."""
    if spec.time_unit != "auto":
        return spec.time_unit
    try:
        return time_unit_from_step(median(np.diff(stamps)) if stamps.size > 1 else float("nan"),
                                   float(stamps[0]))[0]
    except ImucalError:
        return "s"


def _join(parts: list[tuple]) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    if len(parts) == 1:
        return parts[0]
    raw = np.concatenate([p[0] for p in parts])
    t = np.concatenate([p[1] for p in parts])
    temp = None if parts[0][2] is None else np.concatenate([p[2] for p in parts])
    return raw, t, temp


def _samples(parts: list[tuple], has_temp: bool) -> StaticSamples:
    if not parts:
        return StaticSamples(np.empty((0, 3)), np.empty(0), np.empty(0) if has_temp else None)
    raw, t, temp = _join(parts)
    return StaticSamples(raw, t, temp)
