"""Issue 25: a recording whose file name has bytes that are not UTF-8 (b'log\\xff.csv' on Linux)
ended `imucal calibrate` with exit 3 (report.txt was written as strict UTF-8). Every text output
is written by imucal.files.output with what UTF-8 cannot hold escaped: the name appears as
log\\udcff.csv, every file stays UTF-8, and the commands that read the calibration work on it."""
from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from conftest import write_simulation
from imucal.analysis.simulate import cube_directions, si_sensor
from imucal.files.output import encode_text

pytestmark = pytest.mark.skipif(sys.platform != "linux", reason="a name of arbitrary bytes needs Linux")
#: the name on disk, and as it reaches the text (Python decodes file names with surrogateescape)
RAW_NAME = b"log\xff.csv"
SHOWN = "log\\udcff.csv"


@pytest.fixture
def odd_name(tmp_path) -> Path:
    """A simulated m/s^2 recording whose file name is not UTF-8."""
    write_simulation(tmp_path / "sim.csv", si_sensor(np.random.default_rng(1)), cube_directions(), 1)
    os.rename(os.fsencode(tmp_path / "sim.csv"), os.fsencode(tmp_path) + b"/" + RAW_NAME)
    return Path(os.fsdecode(os.fsencode(tmp_path) + b"/" + RAW_NAME))


def utf8(path: Path) -> str:
    """The file's text; fails unless it is UTF-8."""
    return path.read_bytes().decode("utf-8")


def test_encoding_escapes_what_utf8_cannot_hold():
    assert encode_text("log\udcff.csv µ") == b"log\\udcff.csv \xc2\xb5"  # UTF-8 kept, the surrogate escaped


def test_calibrate_then_apply_export_codegen_on_a_name_that_is_not_utf8(odd_name, run_cli, tmp_path):
    out = tmp_path / "cal"
    r = run_cli(["calibrate", "--data", odd_name, "--out", out, "--json", out / "summary.json"])
    assert r.code == 0, r.err
    report = utf8(out / "report.txt")
    assert f"/{SHOWN} (" in report and f"/{SHOWN} (" in r.out  # the file and the terminal (strict UTF-8 here)
    assert SHOWN in utf8(out / "report.html")
    assert json.loads(utf8(out / "summary.json"))  # JSON, UTF-8
    assert yaml.safe_load(utf8(out / "calibration.yaml"))["data"]["file"] == "log\udcff.csv"  # YAML's own escape
    cal = out / "calibration.yaml"
    r = run_cli(["apply", cal, "--data", odd_name, "--out", tmp_path / "applied.csv"])
    assert r.code == 0, r.err
    rows = np.loadtxt(tmp_path / "applied.csv", delimiter=",", skiprows=1)
    assert rows.shape[1] == 4 and np.median(np.linalg.norm(rows[:, 1:], axis=1)) == pytest.approx(9.81, abs=0.02)
    for fmt in ("imutk", "madlab", "matrix", "kalibr", "ardupilot", "px4"):
        dest = tmp_path / f"export.{fmt}"
        r = run_cli(["export", cal, "--format", fmt, "--out", dest])
        assert r.code == 0, (fmt, r.err)
        utf8(dest)
    assert "log" in utf8(tmp_path / "export.ardupilot")  # the name is in the comments, escaped by the format
    r = run_cli(["codegen", cal, "--out", tmp_path / "fw"])
    assert r.code == 0, r.err
    for f in (tmp_path / "fw").iterdir():
        utf8(f)


@pytest.mark.filterwarnings("error")
@pytest.mark.parametrize("name", ["a\rb.csv", "a\x01b.csv", "a\x7fb.csv"])
def test_a_control_character_in_a_name_leaves_no_font_warning(name, run_cli, tmp_path):
    """The figures' titles drew the name: matplotlib printed 'UserWarning: Glyph 13 (\\r) missing from font(s)'
    on stderr (calibrate and discover alike). Figure text escapes what no font draws (report.figures.plain)."""
    from imucal.report.figures import plain

    assert plain("a\rb\x01$x\u202e.csv") == "a\\rb\\x01\\$x\\u202e.csv" and plain("é µ") == "é µ"
    write_simulation(tmp_path / name, si_sensor(np.random.default_rng(1)), cube_directions(), 1)
    r = run_cli(["calibrate", "--data", tmp_path / name, "--out", tmp_path / "cal"])
    assert r.code == 0 and "Glyph" not in r.err, r.err


def test_surrogate_escapes_in_a_run_file_are_one_character_or_one_line(run_cli, tmp_path):
    """data.path: "log\\ud83d\\ude00.csv" (JSON's UTF-16 escapes of one emoji) ended as an internal error
    (UnicodeEncodeError at os.stat): a pair is the character it encodes, a lone surrogate is refused; a file
    name's undecodable byte (\\udcff, as imucal writes it) stays."""
    from imucal.files.yamlio import parse_scalar

    assert parse_scalar('"log\\ud83d\\ude00.csv"') == "log\U0001F600.csv"
    assert parse_scalar('"log\\udcff.csv"') == "log\udcff.csv"
    write_simulation(tmp_path / "log\U0001F600.csv", si_sensor(np.random.default_rng(1)), cube_directions(), 1)
    run = tmp_path / "run.yaml"
    run.write_text('data: {path: "log\\ud83d\\ude00.csv", unit: m/s^2}\n')
    r = run_cli(["calibrate", run, "--out", tmp_path / "cal", "--no-figures"])
    assert r.code == 0, r.err
    run.write_text('data: {path: "log\\ud83d.csv", unit: m/s^2}\n')
    r = run_cli(["calibrate", run, "--out", tmp_path / "cal2"])
    assert r.code == 2 and r.err.count("\n") == 1 and "lone UTF-16 surrogate" in r.err, r.err
    assert not (tmp_path / "cal2").exists()
