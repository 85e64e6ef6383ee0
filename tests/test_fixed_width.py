"""The fixed-width reader (imucal.data.fixed_width) gives numpy's reader's doubles bit for bit, or
leaves the text to it (None): every format it takes, every format it must refuse."""
from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from imucal.data import fixed_width

ROOT = Path(__file__).resolve().parents[1]
XSENS = ROOT / "data" / "xsens-mti-imutk"


def _numpy(blob: bytes, usecols: list[int]) -> np.ndarray:
    return np.loadtxt(io.BytesIO(blob), usecols=usecols, ndmin=2, dtype=float, comments="#")


def _same_or_declined(blob: bytes, usecols: list[int]) -> bool:
    """True when the fast reader read the text (and then gave numpy's doubles, asserted)."""
    got = fixed_width.table(blob, 0, usecols)
    if got is not None:
        want = _numpy(blob, usecols)
        assert got.shape == want.shape and got.tobytes() == want.tobytes()
    return got is not None


@pytest.mark.parametrize("name", ["xsens_acc.mat", "xsens_gyro.mat"])
def test_the_shipped_recordings_are_read_by_the_fast_path(name: str) -> None:
    assert _same_or_declined((XSENS / name).read_bytes(), [0, 1, 2, 3])
    assert _same_or_declined((XSENS / name).read_bytes(), [3, 1])


#: Fixed-width formats (every value of a column as wide as the others): MATLAB's -ascii, %e, %f.
FORMATS = ["%16.7e", "%15.7e", " % .8e", " %+.6e", "%15.7E", "%+12.4f", " %.9e", " %+.15e", " %+.17e", " %+.3e", "%12.4f"]


@settings(max_examples=200, deadline=None)
@given(fmt=st.sampled_from(FORMATS), cols=st.integers(1, 5), rows=st.integers(1, 40), scale=st.integers(-30, 30),
       data=st.data())
def test_fixed_width_text_is_read_as_numpy_reads_it(fmt: str, cols: int, rows: int, scale: int, data) -> None:
    x = np.array(data.draw(st.lists(st.floats(-1e3, 1e3, allow_nan=False), min_size=rows * cols,
                                    max_size=rows * cols))).reshape(rows, cols) * 10.0**scale
    text = "\n".join("".join(fmt % v for v in row) for row in x) + "\n"
    usecols = sorted(set(data.draw(st.lists(st.integers(0, cols - 1), min_size=1, max_size=cols))))
    _same_or_declined(text.encode(), usecols)


def test_what_it_reads_and_what_it_leaves() -> None:
    read = ["   3.3108000e+04  -3.3329000e+04\n   2.9840000e-02   3.3329000e+04\n",
            "-0.0e+00 1.0e+22\n 1.0e-21 2.5e+00\n",  # a negative zero; the largest exact powers
            "   1.5   -2.5\n  -1.5    2.5\n",  # no exponent
            "  12 -34\n  56  78\n",  # integers
            " 9007199254740992\n 0000000000000001\n"]  # 2^53, the largest M read
    for text in read:
        assert _same_or_declined(text.encode(), [0]) and _same_or_declined(text.encode(), list(range(
            len(text.split("\n")[0].split()))))
    left = ["1.5 2.5\n10.5 2.5\n",  # widths differ
            "1.5\t2.5\n1.5\t2.5\n", "1.5 2.5\r\n1.5 2.5\r\n",  # a tab, a CR
            "1.5 2.5\n1.5 2.5",  # no line end after the last
            "1.5 #c\n1.5 #c\n", "nan 1.0\nnan 1.0\n", "1.5e+24\n1.5e+24\n",  # a comment, NaN, 10^23 (not exact)
            " 1.0000000e-22\n 1.0000000e-22\n",  # 10^-29 as digits and exponent
            " 9007199254740993\n 0000000000000001\n",  # above 2^53: two roundings would be possible
            " 1.5-2.5\n 1.5 2.5\n",  # numbers touching in a line
            " .5 1\n .5 1\n", " 1. e5\n 1. e5\n", "1,5 2\n1,5 2\n", "1e 5\n1e 5\n", "1e+\n1e-\n"]
    for text in left:
        assert fixed_width.table(text.encode(), 0, [0]) is None, text
    assert fixed_width.table(b"1.5 2.5\n1.5 2.5\n", 0, [2]) is None  # a column the lines do not have
    assert fixed_width.table(b"", 0, [0]) is None
    head = b"t x\n"
    got = fixed_width.table(head + b" 1.5 2.5\n-1.5 2.5\n", len(head), [1, 0])
    assert got is not None and got.tolist() == [[2.5, 1.5], [2.5, -1.5]]
