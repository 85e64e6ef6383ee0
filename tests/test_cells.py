"""A cell that is not a number says why, for the two causes real files show: a decimal comma (a
spreadsheet saved in a European locale: read when the fields are split by ";" or a tab) and empty cells
(sensors logged apart at their own rates)."""
from __future__ import annotations

import pytest

from imucal.data.load import load_recording
from imucal.data.spec import DataSpec
from imucal.data.stream import StreamedRecording
from imucal.errors import ImucalError


@pytest.mark.parametrize("stream", ["never", "always"])
@pytest.mark.parametrize("text, words", [
    ("t;ax;ay;az\n0,00;0,1;0,2;9,81\n0,01;0,1;0,2;9,81\n0,02;0,1;0,2;x\n",
     "data: line 4 column 4: 'x' is not a number (fix: remove non-numeric rows or map the right columns)"),
    ("t,ax,ay,az,gx,gy,gz\n0.000,0.1,0.2,9.81,,,\n0.005,,,,0.01,0.02,0.03\n",
     "data: line 2 column 5: '' is not a number (fix: an empty cell: a logger that writes each sensor's rows "
     "apart (at its own rate) leaves the other sensors' cells empty; write each sensor to its own file, or "
     "fill the rows, before calibrating)"),
    ("t,ax,ay,az\n0.0,0.1,abc,9.81\n", "data: line 2 column 3: 'abc' is not a number (fix: remove non-numeric rows "
                                       "or map the right columns)"),
])
def test_a_cell_that_is_not_a_number_says_why(tmp_path, text, words, stream):
    p = tmp_path / "c.csv"
    p.write_text(text)
    with pytest.raises(ImucalError) as ei:
        spec = DataSpec(path=str(p), stream=stream)
        load_recording(spec) if stream == "never" else StreamedRecording(spec)
    msg = str(ei.value)
    assert "\n" not in msg and msg.endswith("/c.csv: " + words), msg


@pytest.mark.parametrize("delimiter", [";", "\t"])
def test_a_decimal_comma_is_read_as_the_decimal_point(tmp_path, delimiter):
    """phyphox's and spreadsheets' European exports (0,01;9,81): the same numbers as with decimal points; a
    comma before three digits alone (1,234) may be a thousands separator: refused, not guessed."""
    rows = [(k * 0.01, 0.1 + k * 1e-4, -0.25, 9.81) for k in range(40)]
    point = tmp_path / "point.csv"
    point.write_text("t,ax,ay,az\n" + "\n".join(",".join(repr(v) for v in r) for r in rows) + "\n")
    comma = tmp_path / "comma.csv"
    comma.write_text(delimiter.join(("t", "ax", "ay", "az")) + "\n"
                     + "\n".join(delimiter.join(repr(v).replace(".", ",") for v in r) for r in rows) + "\n")
    a, b = load_recording(DataSpec(path=str(point))), load_recording(DataSpec(path=str(comma)))
    assert (a.raw == b.raw).all() and (a.t == b.t).all()
    thousands = tmp_path / "thousands.csv"
    thousands.write_text("t;ax;ay;az\n" + "\n".join(f"{k};1,234;2,345;9,810" for k in range(40)) + "\n")
    with pytest.raises(ImucalError, match="'1,234' is not a number \\(fix: the numbers have a decimal comma"):
        load_recording(DataSpec(path=str(thousands)))


def test_rows_with_more_fields_than_the_header_names_are_refused(tmp_path):
    """0,01,9,81 under t,ax,ay,az used to be read as t=0, ax=1 (the first four fields): the header does not
    describe such rows. A trailing delimiter (an empty last field) is no extra column."""
    p = tmp_path / "c.csv"
    p.write_text("t,ax,ay,az\n" + "\n".join(f"0,{k:02d},0,1,0,2,9,81" for k in range(20)) + "\n")
    with pytest.raises(ImucalError) as ei:
        load_recording(DataSpec(path=str(p)))
    assert str(ei.value).endswith("c.csv: data.columns: line 2 has 8 fields, the header names 4 (numbers with a "
                                  "decimal comma, and commas between them?) (fix: give the header one name per "
                                  "column, and write the numbers with a decimal point or split the fields by ;)")
    p.write_text("t,ax,ay,az\n" + "\n".join(f"{k * 0.01:.2f},0.1,0.2,9.81," for k in range(20)) + "\n")
    assert load_recording(DataSpec(path=str(p))).raw.shape == (20, 3)
