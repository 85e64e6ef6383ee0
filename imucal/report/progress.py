"""Progress bars: one tqdm bar on stderr when stderr is a terminal, nothing otherwise.

Used by the batch, samples mode (the fit's passes over the samples, the passes over a file read in
chunks), discover, plan-poses and the study scripts. Off a terminal (a pipe, a log file, a test)
nothing is printed and tqdm is not even imported, so `imucal calibrate` starts no slower. A bar
appears only once its task has run for ``delay`` seconds: quick runs stay quiet on a terminal too.
"""
from __future__ import annotations

import contextlib
import sys
from collections.abc import Callable, Iterator

#: A task shorter than this [s] never shows its bar.
DELAY_S = 0.5

Step = Callable[..., None]


def _nothing(n: float = 1, note: str | None = None) -> None:
    """The step of a bar that is not shown."""


def on_terminal() -> bool:
    """stderr is a terminal (a closed or replaced stream is not)."""
    try:
        return sys.stderr.isatty()
    except (AttributeError, ValueError):
        return False


@contextlib.contextmanager
def progress(desc: str, total: float | None = None, unit: str = "it", enabled: bool | None = None,
             delay: float | None = None, scale: bool = False, leave: bool = False) -> Iterator[Step]:
    """``with progress("fits", total=n) as step: ... step()`` (or ``step(k, note="2 failed")``).

    ``enabled``: None shows the bar when stderr is a terminal; True or False forces it.
    ``delay``: [s] before the bar appears (None: DELAY_S, read at the call).
    ``total``: None when the count is not known in advance (the bar counts and shows the rate).
    ``scale``: show large counts with k, M, G prefixes (bytes read). ``leave``: keep the finished
    bar on the screen (else it is cleared).
    """
    if not (on_terminal() if enabled is None else enabled):
        yield _nothing
        return
    from tqdm import tqdm  # only on a terminal: keeps the start-up of every other run lean

    bar = tqdm(total=total, desc=desc, unit=unit, file=sys.stderr, dynamic_ncols=True,
               delay=DELAY_S if delay is None else delay,
               leave=leave, unit_scale=scale)

    def step(n: float = 1, note: str | None = None) -> None:
        if note is not None:
            bar.set_postfix_str(note, refresh=False)
        bar.update(n)

    try:
        yield step
    finally:
        bar.close()
