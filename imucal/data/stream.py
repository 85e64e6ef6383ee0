"""Long recordings in bounded memory: read in blocks of lines, detect static intervals on the way,
keep only what the fit needs.

The rules are the whole-file reader's (imucal.data.layout: header, column roles; imucal.data.lines:
the same one-line errors for the same bad line; imucal.data.timebase: the time base) and
imucal.data.static's (the same moving variance, threshold and per-interval
statistics, computed by the same functions), so the intervals and the fit are those of the
in-memory path. Numbers are parsed by pandas' C parser, a block of about CHUNK_BYTES at a time;
a block it reads differently from numpy.loadtxt (anything unusual: quotes, NaN, too few columns,
exotic line breaks) is parsed line by line (imucal.data.lines.parse_block), which names the bad line.

Passes over the file: 1. parse, SHA-256, time base, moving variance (float32, 4 bytes a sample)
and its threshold; 2. the statistics of each still interval (and its samples in samples mode);
3. (means mode, after the fit) the residual of every static sample. Memory: the variance series,
one block, and a few numbers per interval.
"""
from __future__ import annotations

import csv
import hashlib
import io
import os
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from imucal.constants import TIME_UNITS
from imucal.data.layout import Layout, file_head
from imucal.data.lines import (MAX_STREAM_BYTES, check_lines, check_text, corrupt_value, lineno, no_rows,
                               not_increasing, not_utf8, parse_block, plain_text, unparsed)
from imucal.data.spec import DataSpec, as_spec, resolve_path
from imucal.data.timebase import (CLOCK_SPAN, GAP_STEPS, Decision, GapFinder, LagDiffs, StepStats, ValueCounts,
                                  clock_times, decide, gap_excess, rate_time_base, refine, time_base,
                                  time_unit_from_step)
from imucal.data.static import (QUANTUM_ROWS, Intervals, MovingVariance, Segment, StaticSettings, VarianceSeries,
                                auto_threshold, candidate_runs, edge_samples, intervals_from, quantum, still_segment,
                                window_samples)
from imucal.data.recording import MAX_ABS_VALUE, RecordingSummary, StaticSamples, TimeBase
from imucal.errors import ImucalError
from imucal.solve.stats import median
from imucal.files.inputs import open_regular
from imucal.report.progress import progress

#: Bytes parsed at a time (whole lines).
CHUNK_BYTES = 16 * 1024**2
#: Parsed samples kept after the first pass, so that the next ones need not parse the file again,
#: while they fit in this many bytes (raw, t and temperature as float64).
CACHE_BYTES = 256 * 1024**2


class _File:
    """A recording's body in blocks of whole lines (with their byte offsets and parsed rows); the
    file is refused if it changes between passes."""

    def __init__(self, spec: DataSpec, path: Path) -> None:
        self.spec, self.path = spec, path
        fd, self.size = open_regular(path, field="data.path", max_bytes=MAX_STREAM_BYTES,
                                     fix="check the path (relative paths are relative to the YAML file)")
        st = os.fstat(fd)
        self.stamp = (st.st_size, st.st_mtime_ns, st.st_ino)
        os.close(fd)
        self.sha = ""
        #: numbers numpy could not read in an earlier block, no line found wrong there: later
        #: lines are checked one by one for a message naming one (as the loader does), else this
        self.unparsed: ImucalError | None = None
        self.lay, self.offset = self._head()
        self._counted = (self.offset, self.lay.body_first)

    def _open(self) -> io.BufferedReader:
        fd, _ = open_regular(self.path, field="data.path", max_bytes=MAX_STREAM_BYTES)
        st = os.fstat(fd)
        if (st.st_size, st.st_mtime_ns, st.st_ino) != self.stamp:
            os.close(fd)
            raise ImucalError("changed while it was being read", file=str(self.path), field="data.path",
                              fix="calibrate a copy that no program is writing to")
        return os.fdopen(fd, "rb")

    def _head(self) -> tuple[Layout, int]:
        """Header and layout from the head of the file; byte offset of the body."""
        with self._open() as f:
            return file_head(f, self.spec, self.path)

    def line_at(self, offset: int) -> int:
        """Line number of the line starting at byte ``offset`` of the body (counted when a message
        needs it, from the last one counted)."""
        at, line = self._counted
        if offset < at:
            at, line = self.offset, self.lay.body_first
        with self._open() as f:
            f.seek(at)
            while at < offset:
                data = f.read(min(CHUNK_BYTES, offset - at))
                if not data:
                    break
                line += data.count(b"\n")
                at += len(data)
        self._counted = (offset, line)
        return line

    def blocks(self, hash_it: bool = False) -> Iterator[tuple[int, bytes]]:
        """(byte offset, bytes of whole lines) from the body on; the SHA-256 of the whole file is
        left in ``self.sha`` when ``hash_it``."""
        h = hashlib.sha256() if hash_it else None
        at = self.offset
        shown = progress(f"reading {self.path.name}", total=self.stamp[0], unit="B", scale=True)
        with self._open() as f, shown as step:
            if h is not None:
                h.update(f.read(self.offset))
            else:
                f.seek(self.offset)
            carry = b""
            while True:
                data = f.read(CHUNK_BYTES)
                step(len(data))  # a bar on a terminal (imucal.report.progress)
                if h is not None:
                    h.update(data)
                if not data:
                    if carry.strip():
                        yield at, carry
                    break
                buf = carry + data
                check_text(buf, self.path, lambda: self.line_at(at))  # a sparse tail or a line without end stops here
                cut = buf.rfind(b"\n") + 1
                if cut == 0:
                    carry = buf
                    continue
                block, carry = buf[:cut], buf[cut:]
                yield at, block
                at += cut
            if f.tell() != self.stamp[0]:
                raise ImucalError("changed while it was being read", file=str(self.path), field="data.path",
                                  fix="calibrate a copy that no program is writing to")
        if h is not None:
            self.sha = h.hexdigest()

    def parse(self, block: bytes, offset: int) -> np.ndarray:
        """The used columns of a block's rows (roles order), or the loader's message for its first bad line."""
        lay = self.lay
        if self.unparsed is not None:
            check_lines(self._lines(block), self.line_at(offset), lay.delimiter, lay.usecols, self.path)
            return np.empty((0, len(lay.usecols)))
        if plain_text(block):
            # imported here: pandas adds about 0.3 s to start-up, which a short recording read whole
            # never pays (the measured start-up of `imucal calibrate` in docs/benchmarks.md)
            import pandas as pd

            try:
                df = pd.read_csv(io.BytesIO(block), sep=lay.delimiter or r"\s+", header=None, usecols=lay.usecols,
                                 dtype=np.float64, comment="#", skip_blank_lines=True, quoting=csv.QUOTE_NONE,
                                 engine="c")
                arr = df[lay.usecols].to_numpy(dtype=np.float64)
                if np.isfinite(arr).all():
                    return arr
            except (ValueError, IndexError, pd.errors.ParserError, pd.errors.EmptyDataError):
                pass
        lines = self._lines(block)
        if not any(ln.strip() and not ln.lstrip().startswith("#") for ln in lines):
            return np.empty((0, len(lay.usecols)))
        try:
            return parse_block(lines, self.line_at(offset), lay.delimiter, lay.usecols, self.path)
        except ImucalError as exc:
            if exc.message != unparsed(self.path).message:
                raise
            self.unparsed = exc
            return np.empty((0, len(lay.usecols)))

    def _lines(self, block: bytes) -> list[str]:
        try:
            return block.decode("utf-8").splitlines()
        except UnicodeDecodeError:
            raise not_utf8(self.path) from None

    def rows(self, hash_it: bool = False) -> Iterator[tuple[int, bytes, np.ndarray]]:
        """(byte offset, block, its rows) of every block."""
        for offset, block in self.blocks(hash_it):
            yield offset, block, self.parse(block, offset)

    def line_of(self, block: bytes, offset: int, k: int) -> int:
        """File line of data row ``k`` of the block at ``offset``."""
        return lineno(block.decode("utf-8").splitlines(), k, self.line_at(offset))


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
    decided: Decision  #: before refinement: a later pass that decides the same reuses the gaps

    @property
    def cum(self) -> np.ndarray:
        return gap_excess(self.dec, self.gap_step)


@dataclass
class _Scan:
    """What pass 1 learnt."""

    n: int
    unit: str
    note: str
    t_first: float  #: first stamp as read (0 without stamps)
    t_last: float  #: last sample's time [s] from the first
    dt: float  #: median step of t [s]
    w: int
    q: float
    lows: np.ndarray
    highs: np.ndarray
    unit_guess: str  #: the unit the times of this pass were computed in
    w_guess: int  #: the window the moving variance of this pass used
    mv: MovingVariance | None
    time_base: TimeBase
    clock: _Clock | None = None  #: the clock the times are to be made on (jittered stamps)
    clock_guess: _Clock | None = None  #: the clock the times of this pass were made on
    var: VarianceSeries | None = None

    @property
    def consistent(self) -> bool:
        return (self.unit, self.w) == (self.unit_guess, self.w_guess) and (self.clock is None) == (
            self.clock_guess is None)


@dataclass
class _ScanState:
    """Pass 1's running state, block to block."""

    unit: str | None
    w: int | None
    clock: _Clock | None = None  #: the times are made on this clock (None: from the stamps as read)
    n: int = 0
    t_first: float = 0.0
    t_last: float = 0.0
    last_stamp: float | None = None
    big: ImucalError | None = None  #: the first value beyond MAX_ABS_VALUE
    order: ImucalError | None = None  #: the first stamp that does not increase
    mv: MovingVariance | None = None
    lows: np.ndarray = field(default_factory=lambda: np.full(3, np.inf))
    highs: np.ndarray = field(default_factory=lambda: np.full(3, -np.inf))
    stamp_steps: "_Steps" = field(default_factory=lambda: _Steps())
    spans: LagDiffs = field(default_factory=lambda: LagDiffs())  #: its tail: the last CLOCK_SPAN stamps
    head_stamps: list = field(default_factory=list)  #: the first CLOCK_SPAN stamps
    t_steps: "_Steps" = field(default_factory=lambda: _Steps())
    head_raw: list = field(default_factory=list)
    blocks: list = field(default_factory=list)  #: (byte offset, bytes, first row) of each block with rows
    cached: int = 0


class StreamedRecording:
    """A recording read in chunks: its summary, static intervals, and (samples mode) static samples."""

    def __init__(self, spec: DataSpec | str | os.PathLike, settings: StaticSettings = StaticSettings(),
                 base_dir: str | os.PathLike | None = None, rails: dict | None = None,
                 keep_samples: bool = False) -> None:
        """``keep_samples``: keep the static samples (samples mode). Gyroscope columns are not read."""
        self.spec = as_spec(spec)
        self.settings, self.rails = settings, rails
        self.file = _File(self.spec, resolve_path(self.spec, base_dir))
        self.path = self.file.path
        roles = self.file.lay.roles
        self._it = {r: i for i, r in enumerate(roles)}
        # The window comes from the median step of the whole file: guessed from the first block, and
        # the pass repeated in the rare case the guess (or the time unit) was wrong, or when the
        # stamps are jitter (the times are then made on the clock fitted in the first pass).
        scan = self._scan(None, None, None)
        for _ in range(2):
            if scan.consistent:
                break
            scan = self._scan(scan.unit, scan.w, scan.clock)
        self._finish_scan(scan)
        self.recording = RecordingSummary(n=scan.n, t_last=scan.t_last, unit=self.spec.unit, source=str(self.path),
                                          sha256=self.file.sha, time_unit=scan.unit, time_note=scan.note,
                                          time_column=self.file.lay.time_column, time_base=scan.time_base)
        self.intervals, self.samples = self._intervals(scan, keep_samples)

    # --- pass 1 ---------------------------------------------------------------------------------
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

    def _scan(self, unit_given: str | None, w_given: int | None, clock: _Clock | None) -> _Scan:
        """Pass 1: parse every block, hash, check values and time stamps, moving variance."""
        st = _ScanState(unit=unit_given, w=w_given, clock=clock)
        self._cache: list[tuple] | None = []
        for first, block, arr in self.file.rows(hash_it=True):
            if arr.shape[0] == 0:
                continue
            st.blocks.append((first, len(block), st.n))
            self._check_block(st, first, block, arr)
            if st.big is None and st.order is None:
                self._accumulate(st, arr)
            st.n += arr.shape[0]
        return self._scan_result(st)

    def _check_block(self, st: "_ScanState", first: int, block: object, arr: np.ndarray) -> None:
        """Values beyond MAX_ABS_VALUE and time stamps that do not increase (the first of each is kept)."""
        if st.big is None:
            bad = (np.abs(arr) > MAX_ABS_VALUE).any(axis=1)
            if bad.any():
                st.big = corrupt_value(self.file.line_of(block, first, int(np.flatnonzero(bad)[0])), self.path)
        if "t" not in self._it:
            return
        stamps = arr[:, self._it["t"]]
        if st.n == 0:
            st.t_first = float(stamps[0])
        if st.order is None:
            prev = st.last_stamp
            d = np.diff(stamps) if prev is None else np.diff(np.concatenate([[prev], stamps]))
            bad = ~(d > 0)
            if bad.any():
                k = int(np.flatnonzero(bad)[0]) + (1 if prev is None else 0)
                st.order = not_increasing(self.file.line_of(block, first, k), self.path)
        st.last_stamp = float(stamps[-1])
        st.stamp_steps.feed(stamps)
        st.spans.add(stamps)
        if sum(h.size for h in st.head_stamps) < CLOCK_SPAN:
            st.head_stamps.append(stamps[:CLOCK_SPAN].copy())

    def _accumulate(self, st: "_ScanState", arr: np.ndarray) -> None:
        """Times in the (guessed) unit, moving variance, ranges, the quantum's head, the memory cache."""
        if st.unit is None:  # a guess from the first block, checked at the end
            st.unit = _guess_unit(self.spec, arr[:, self._it["t"]]) if "t" in self._it else "s"
        t = self._times(arr, st.n, st.unit, st.t_first, st.clock)
        st.t_steps.feed(t)
        if st.w is None:
            st.w = window_samples(self.settings, median(np.diff(t))) if t.size > 1 else 3
        if st.mv is None:
            st.mv = MovingVariance(st.w)
        raw = self._raw(arr)
        st.mv.add(raw)
        st.lows, st.highs = np.minimum(st.lows, raw.min(axis=0)), np.maximum(st.highs, raw.max(axis=0))
        if sum(h.shape[0] for h in st.head_raw) < QUANTUM_ROWS:
            st.head_raw.append(raw[:QUANTUM_ROWS])
        st.t_last = float(t[-1])
        if self._cache is not None:  # the next passes read memory while the file fits in CACHE_BYTES
            temp = self._temp(arr)
            stamps = arr[:, self._it["t"]].copy() if "t" in self._it else None
            st.cached += raw.nbytes + t.nbytes + sum(0 if x is None else x.nbytes for x in (temp, stamps))
            if st.cached <= CACHE_BYTES:
                self._cache.append((st.n, raw, t, temp, stamps))
            else:
                self._cache = None

    def _scan_result(self, st: "_ScanState") -> _Scan:
        """The first error met, or what pass 1 learnt with the time base decided on every stamp."""
        path, spec, n = self.path, self.spec, st.n
        if self.file.unparsed is not None:
            raise self.file.unparsed
        if n == 0:
            raise no_rows(path)
        for err in (st.big, st.order):
            if err is not None:
                raise err
        clock = None
        if "t" in self._it:
            stats = StepStats(n=n, first=st.t_first, last=st.last_stamp, median_step=st.stamp_steps.median(),
                              span_median=st.spans.counts.median(),
                              head=np.concatenate(st.head_stamps)[:CLOCK_SPAN], tail=st.spans.tail[-CLOCK_SPAN:],
                              short=st.stamp_steps.below, long=st.stamp_steps.above)
            dec = decide(stats, spec.time_unit, spec.sample_rate, self.file.lay.time_column, path)
            if st.clock is not None and st.clock.decided == dec:
                clock = st.clock
                dec, gi, gs = clock.dec, clock.gap_index, clock.gap_step
            else:
                if dec.jittered or (n > 1 and stats.long(GAP_STEPS * dec.gap_ref) > 0):
                    gi, gs = self._gaps(dec)
                else:
                    gi, gs = np.empty(0, np.int64), np.empty(0)
                decided = dec
                dec, gs = refine(dec, stats, gi, gs, path)
                clock = _Clock(dec, gi, gs, decided) if dec.jittered else None
            unit_exact, note = dec.unit, dec.note
            tb = time_base(dec, stats, gi, gs, lambda k: self._row_line(st.blocks, k))
        else:
            unit_exact, note, tb = rate_time_base(spec.sample_rate)
        if n < 3:  # as detect_static
            raise ImucalError(f"only {n} samples", file=str(path), field="data",
                              fix="record several seconds in each orientation")
        # the times of this pass are in the guessed unit (on the guessed clock); if either was wrong,
        # the next pass's window comes from the stamps' step in the right one
        same = unit_exact == st.unit and (clock is None) == (st.clock is None)
        dt = st.t_steps.median() if same else tb.step
        return _Scan(n=n, unit=unit_exact, note=note, t_first=st.t_first, t_last=st.t_last, dt=dt,
                     w=window_samples(self.settings, dt), q=quantum(np.concatenate(st.head_raw)), lows=st.lows,
                     highs=st.highs, unit_guess=st.unit, w_guess=st.w, mv=st.mv, time_base=tb, clock=clock,
                     clock_guess=st.clock)

    def _stamp_blocks(self) -> Iterator[np.ndarray]:
        """The time stamps, a block at a time: from pass 1's cache when the file fitted in it."""
        if self._cache is not None:
            for entry in self._cache:
                yield entry[4]
            return
        for _, _, arr in self.file.rows():
            if arr.shape[0]:
                yield arr[:, self._it["t"]]

    def _gaps(self, dec: Decision) -> tuple[np.ndarray, np.ndarray]:
        """The gaps of the stamps (imucal.data.timebase.GapFinder), found in one more pass."""
        finder = GapFinder(dec)
        for stamps in self._stamp_blocks():
            finder.add(stamps)
        return finder.finish()

    def _row_line(self, blocks: list, k: int) -> int:
        """The file's line of data row ``k`` (blocks: pass 1's (offset, bytes, first row))."""
        i = max(0, np.searchsorted([b[2] for b in blocks], k, side="right") - 1)
        offset, size, row0 = blocks[i]
        with self.file._open() as f:
            f.seek(offset)
            block = f.read(size)
        return self.file.line_of(block, offset, k - row0)

    def _finish_scan(self, scan: _Scan) -> None:
        if not scan.consistent:  # pragma: no cover - the third pass uses the exact unit and window
            raise ImucalError("the time step changed between passes", file=str(self.path), field="data.path")
        scan.var = scan.mv.finish()
        scan.mv = None

    # --- pass 2 ---------------------------------------------------------------------------------
    def _intervals(self, scan: _Scan, keep_samples: bool) -> tuple[Intervals, StaticSamples | None]:
        st = self.settings
        thr = st.threshold if st.threshold is not None else auto_threshold(scan.var, scan.q)
        a, b = candidate_runs(scan.var, thr, int(round(st.trim / scan.dt)))
        scan.var = None
        has_temp = "temp" in self._it
        segs: list[Segment] = []
        kept: dict[int, tuple] = {}
        m = edge_samples(scan.dt)
        for start, raw, t, temp in self._pieces(a, b, scan):
            g = (still_segment(start, raw, t, temp, scan.lows, scan.highs, self.rails, st, m, scan.q)
                 if t[-1] - t[0] >= st.min_duration else None)  # its edges cut to what is still
            if g is not None:
                segs.append(g)
                if keep_samples:
                    lo, hi = g.start - start, g.end - start
                    kept[g.start] = (raw[lo:hi], t[lo:hi], None if temp is None else temp[lo:hi])
        iv = intervals_from(segs, thr, scan.q, st, scan.lows, scan.highs, self.rails, has_temp)
        self._scan_result = scan
        if not keep_samples:
            return iv, None
        parts = [kept[int(s)] for s in iv.start]
        return iv, _samples(parts, has_temp)

    def _arrays(self, scan: _Scan) -> Iterator[tuple[int, np.ndarray, np.ndarray, np.ndarray | None]]:
        """(first row, raw, t, temp) of every block: from pass 1's cache when the file fitted in it,
        else parsed again."""
        if self._cache is not None:
            for entry in self._cache:
                yield entry[:4]
            return
        row0 = 0
        for _, _, arr in self.file.rows():
            yield row0, self._raw(arr), self._times(arr, row0, scan.unit, scan.t_first, scan.clock), self._temp(arr)
            row0 += arr.shape[0]

    def _pieces(self, a: np.ndarray, b: np.ndarray, scan: _Scan
                ) -> Iterator[tuple[int, np.ndarray, np.ndarray, np.ndarray | None]]:
        """(first row, raw, t, temp) of each row range [a_i, b_i), in order, from one pass."""
        k = 0
        acc: list[tuple] = []
        if a.size == 0:
            return
        for row0, raw, t, temp in self._arrays(scan):
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

    # --- pass 3 ---------------------------------------------------------------------------------
    def static_blocks(self) -> Iterator[StaticSamples]:
        """The static samples of ``self.intervals`` (in order), a block of the file at a time."""
        if self.samples is not None:
            yield self.samples
            return
        iv = self.intervals
        if iv.n == 0:
            return
        for row0, raw, t, temp in self._arrays(self._scan_result):
            row1 = row0 + raw.shape[0]
            k0, k1 = np.searchsorted(iv.end, row0, "right"), np.searchsorted(iv.start, row1, "left")
            if k1 <= k0:
                continue
            idx = np.concatenate([np.arange(max(a, row0), min(b, row1)) - row0
                                  for a, b in zip(iv.start[k0:k1], iv.end[k0:k1])])
            yield StaticSamples(raw[idx], t[idx], None if temp is None else temp[idx])


def _guess_unit(spec: DataSpec, stamps: np.ndarray) -> str:
    """The time unit from a first block's stamps: only a guess (the pass is repeated when the whole
    file decides another), so a block the step cannot read is guessed s, not refused."""
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
