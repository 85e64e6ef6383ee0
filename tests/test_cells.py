"""A cell that is not a number says why, for the two causes real files show: a decimal comma (a
spreadsheet saved in a European locale) and empty cells (sensors logged apart at their own rates)."""
from __future__ import annotations

import pytest

from imucal.data.load import load_recording
from imucal.data.spec import DataSpec
from imucal.errors import ImucalError


@pytest.mark.parametrize("stream", ["never", "always"])
@pytest.mark.parametrize("text, words", [
    ("t;ax;ay;az\n0,00;0,1;0,2;9,81\n0,01;0,1;0,2;9,81\n",
     "data: line 2 column 1: '0,00' is not a number (fix: the numbers have a decimal comma: write them with a "
     "decimal point (a spreadsheet in an English locale))"),
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
        load_recording(DataSpec(path=str(p), stream=stream, sample_rate=None))
    msg = str(ei.value)
    assert "\n" not in msg and msg.endswith("/c.csv: " + words), msg
