"""Headers as lab scripts and phone apps write them (found on a public six-position MPU-9250 log): the axes named
alone with their unit (``x (g)``), a title line above the header, a header that names fewer columns than the
rows hold. Each was "missing column for ax" before."""
from __future__ import annotations

import numpy as np
import pytest

from imucal.data.load import load_recording
from imucal.errors import ImucalError

G = 9.80665


@pytest.fixture(scope="module")
def rows(counts_recording):
    rec = load_recording(counts_recording.path)
    return rec.t, rec.raw / 16384.0  # in g, as the log's numbers


def _write(path, head: str, t, a, sep: str = ",") -> None:
    body = "".join(f"{x:.3f}{sep}{p:.6f}{sep}{q:.6f}{sep}{r:.6f}\n" for x, (p, q, r) in zip(t, a))
    path.write_text(head + body)


@pytest.mark.parametrize("head", [
    "time (s),x (g),y (g),z (g)\n",
    "Acceleration Data Collected on Level Surface. Z up.\ntime (s),x (g),y (g),z (g)\n",
    "t,X [g],Y [g],Z [g]\n",
])
def test_axes_named_alone_are_the_accelerometer_in_their_stated_unit(tmp_path, rows, head):
    p = tmp_path / "log.csv"
    _write(p, head, *rows)
    rec = load_recording(p)
    assert rec.unit == "g" and rec.n == rows[0].size
    np.testing.assert_allclose(rec.raw, np.round(rows[1], 6), atol=1e-9)
    assert rec.columns["ax"].lower().startswith("x")


def test_axes_named_alone_with_a_rate_unit_are_not_read_as_the_accelerometer(tmp_path, rows):
    p = tmp_path / "log.csv"
    _write(p, "t,x (deg/s),y (deg/s),z (deg/s)\n", *rows)
    with pytest.raises(ImucalError, match="missing column for ax"):
        load_recording(p)


def test_a_header_that_names_fewer_columns_than_the_rows_hold_says_so(tmp_path, rows):
    """The log's own header lost a comma ("time (s)x (g),y (g),z (g)"): the count is the problem, not ax."""
    p = tmp_path / "log.csv"
    _write(p, "Acceleration Data Collected on Level Surface. Z up.\ntime (s)x (g),y (g),z (g)\n", *rows)
    with pytest.raises(ImucalError) as e:
        load_recording(p)
    msg = str(e.value)
    assert "line 3 has 4 fields, the header names 3" in msg and "give the header one name per column" in msg
    assert "decimal comma" not in msg  # the numbers have decimal points: no comma is a decimal one
