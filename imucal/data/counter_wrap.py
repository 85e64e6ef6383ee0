"""A time column that counts as an unsigned integer and wraps: Arduino's micros() every 2**32 us (71.6 min),
millis() every 2**32 ms, a 16-bit timer's ticks every 2**16. Read as numbers, such stamps step back by nearly
the counter's range once per wrap; sorting the rows (what a step back usually asks for) would scramble them.

A step back is a wrap when every stamp so far is a whole number in [0, 2**b), the stamp before it lies in the
top WRAP_EDGE of that range and the one after it in the bottom WRAP_EDGE: a counter that overflowed between two
samples, not rows out of order. Each wrap adds 2**b to the stamps after it. The readers (imucal.data.whole,
whole; imucal.data.stream, in chunks) feed the stamps through one CounterWrap, so both unwrap alike; any other
step back is left for their order check.
"""
from __future__ import annotations

import numpy as np

#: Widths [bits] of the counters a time column is unwrapped at (the smallest that holds every stamp).
COUNTER_BITS = (16, 32)
#: Share of the counter's range at its top (the stamp before a wrap) and at its bottom (the one after).
WRAP_EDGE = 0.25


class CounterWrap:
    """Unwraps the stamps of one time column fed in order, chunk by chunk."""

    def __init__(self) -> None:
        self.modulus: float | None = None  #: 2**b once a wrap was seen
        self.wraps = 0
        self.prev: float | None = None  #: the last stamp fed, as read
        self.top = 0.0  #: the largest stamp read since the last wrap
        self.counter = True  #: every stamp so far a whole number >= 0

    def feed(self, stamps: np.ndarray) -> np.ndarray:
        """``stamps`` unwrapped (the same array when no wrap has been seen)."""
        if stamps.size == 0:
            return stamps
        earlier = self.wraps  # wraps in the chunks before this one
        self.counter = self.counter and bool(np.all(stamps >= 0) and np.all(stamps == np.floor(stamps)))
        x = stamps if self.prev is None else np.concatenate([[self.prev], stamps])
        shift = 0 if self.prev is None else 1  # x[k + shift] is stamps[k]
        offsets = np.zeros(stamps.size)
        start = 0
        for k in np.flatnonzero(np.diff(x) < 0):  # a step back from x[k] to x[k + 1]
            i = k + 1 - shift  # the stamp after the step, in stamps
            self.top = max(self.top, float(np.max(stamps[start:i], initial=-np.inf)))
            if not (self.counter and self._wraps(float(x[k]), float(x[k + 1]))):
                break  # rows out of order: the caller's check names the line
            self.wraps += 1
            offsets[i:] += self.modulus
            start, self.top = i, 0.0
        self.top = max(self.top, float(np.max(stamps[start:])))
        self.prev = float(stamps[-1])
        if self.modulus is None:
            return stamps
        return stamps + (earlier * self.modulus + offsets)

    def _wraps(self, before: float, after: float) -> bool:
        """Whether a step back from ``before`` to ``after`` is a counter's overflow (module docstring)."""
        m = self.modulus
        if m is None:
            fits = [2.0 ** b for b in COUNTER_BITS if max(before, self.top) < 2.0 ** b]
            if not fits:
                return False
            m = fits[0]
        if not (before >= (1 - WRAP_EDGE) * m and after < WRAP_EDGE * m and max(before, self.top) < m):
            return False
        self.modulus = m
        return True

    @property
    def note(self) -> str:
        """What the report says of the unwrapping ("" when nothing wrapped)."""
        if not self.wraps:
            return ""
        bits = int(round(np.log2(self.modulus)))
        return (f"the time column wrapped {self.wraps} time{'s' if self.wraps != 1 else ''} as an unsigned "
                f"{bits}-bit counter (every 2**{bits} of its unit): unwrapped")
