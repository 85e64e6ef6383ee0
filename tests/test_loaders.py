"""Loaders: CSV with header, whitespace text without header (imu_tk's t x y z), YAML overrides.

Each error path checks its message: one line, naming the file, the field and a fix.
"""
from __future__ import annotations

import hashlib
import re

import numpy as np
import pytest

from conftest import real_file
from imucal.config.run import config_from_dict, load_config
from imucal.data.load import load_recording
from imucal.data.spec import DataSpec
from imucal.errors import ImucalError


def write(tmp_path, name: str, text: str | bytes):
    p = tmp_path / name
    p.write_bytes(text.encode("utf-8") if isinstance(text, str) else text)
    return p


# --- formats --------------------------------------------------------------------------------
def test_csv_with_default_header(tmp_path):
    p = write(tmp_path, "r.csv", "t,ax,ay,az\n10.0,1,2,3\n10.0625,4,5,6\n10.125,7,8,9\n")
    rec = load_recording(p)
    np.testing.assert_array_equal(rec.t, [0.0, 0.0625, 0.125])  # time from the first sample
    np.testing.assert_array_equal(rec.raw, [[1, 2, 3], [4, 5, 6], [7, 8, 9]])
    assert rec.temp is None and rec.unit == "raw" and rec.n == 3
    assert rec.sample_rate == pytest.approx(16.0)
    assert rec.sha256 == hashlib.sha256(p.read_bytes()).hexdigest()
    assert rec.source == str(p)


def test_csv_with_temperature_and_column_order(tmp_path):
    p = write(tmp_path, "r.csv", "az,temp,t,ay,ax\n3,25.5,0,2,1\n6,25.7,0.01,5,4\n")
    rec = load_recording(p)
    np.testing.assert_array_equal(rec.raw, [[1, 2, 3], [4, 5, 6]])
    np.testing.assert_array_equal(rec.temp, [25.5, 25.7])


@pytest.mark.parametrize("sep", [",", ";", "\t"])
def test_csv_delimiters_are_sniffed(tmp_path, sep):
    p = write(tmp_path, "r.csv", sep.join("t ax ay az".split()) + "\n" + sep.join("0 1 2 3".split())
              + "\n" + sep.join("0.01 4 5 6".split()) + "\n")
    np.testing.assert_array_equal(load_recording(p).raw, [[1, 2, 3], [4, 5, 6]])


def test_csv_tolerates_bom_crlf_quotes_comments_and_blank_lines(tmp_path):
    text = '\ufeff# exported by a logger\r\n"t","ax","ay","az"\r\n0,1,2,3\r\n\r\n# pause\r\n0.01,4,5,6\r\n'
    rec = load_recording(write(tmp_path, "r.csv", text))
    np.testing.assert_array_equal(rec.raw, [[1, 2, 3], [4, 5, 6]])


def test_whitespace_imutk_format(tmp_path):
    """imu_tk's format: no header, t x y z separated by spaces or tabs."""
    p = write(tmp_path, "acc.mat", "  1.00  33124 33275   32364\n1.01 33125\t33276 32365\n1.02 33123 33274 42000\n")
    rec = load_recording(p)
    np.testing.assert_allclose(rec.t, [0.0, 0.01, 0.02])
    np.testing.assert_array_equal(rec.raw[2], [33123, 33274, 42000])


def test_whitespace_three_columns_need_a_sample_rate(tmp_path):
    p = write(tmp_path, "r.txt", "1 2 3\n4 5 6\n7 8 9\n")
    with pytest.raises(ImucalError, match="no time column and no sample rate") as ei:
        load_recording(p)
    assert ei.value.field == "data.sample_rate" and "set data.sample_rate" in str(ei.value)
    rec = load_recording(DataSpec(path=str(p), sample_rate=50.0))
    np.testing.assert_allclose(rec.t, [0.0, 0.02, 0.04])


def test_whitespace_five_columns_are_t_xyz_temp(tmp_path):
    rec = load_recording(write(tmp_path, "r.txt", "0 1 2 3 20.5\n0.1 4 5 6 20.6\n"))
    np.testing.assert_array_equal(rec.temp, [20.5, 20.6])


def test_yaml_column_mapping_unit_time_unit_and_delimiter(tmp_path):
    write(tmp_path, "log.csv", "time_ms;accX;accY;accZ;T\n0;1;2;3;30\n10;4;5;6;31\n20;7;8;9;32\n")
    run = write(tmp_path, "run.yaml", """
data:
  path: log.csv
  delimiter: ";"
  columns: {t: time_ms, ax: accX, ay: accY, az: accZ, temp: T}
  time_unit: ms
  unit: m/s^2
""")
    cfg = load_config(run)
    rec = load_recording(cfg.data, cfg.base_dir)  # relative to the YAML file
    np.testing.assert_allclose(rec.t, [0.0, 0.01, 0.02])
    np.testing.assert_array_equal(rec.raw[:, 0], [1, 4, 7])
    np.testing.assert_array_equal(rec.temp, [30, 31, 32])
    assert rec.unit == "m/s^2"


def test_yaml_index_mapping_without_header(tmp_path):
    p = write(tmp_path, "r.txt", "9 3 2 1 0.00\n9 6 5 4 0.01\n")
    cfg = config_from_dict({"data": {"path": str(p), "format": "whitespace",
                                     "columns": {"t": 4, "ax": 3, "ay": 2, "az": 1}}})
    rec = load_recording(cfg.data)
    np.testing.assert_array_equal(rec.raw, [[1, 2, 3], [4, 5, 6]])
    np.testing.assert_allclose(rec.t, [0, 0.01])


def test_sample_rate_beside_a_time_column_is_checked_not_used(tmp_path):
    """Issue 25: a given rate no longer drops a time column (found by name or mapped): the stamps
    are used and the rate checked against them (tests/test_trust_time.py)."""
    p = write(tmp_path, "r.csv", "t,ax,ay,az\n0,1,2,3\n0.013,4,5,6\n0.019,7,8,9\n")  # 105 Hz
    for cols in ({}, {"t": "t"}):
        with pytest.raises(ImucalError, match="sample rate 100 Hz given, but the time column t steps at 105.3 Hz"):
            load_recording(DataSpec(path=str(p), sample_rate=100.0, columns=cols))
        rec = load_recording(DataSpec(path=str(p), sample_rate=104.0, columns=cols))
        np.testing.assert_allclose(rec.t, [0.0, 0.013, 0.019])


def test_skip_rows(tmp_path):
    p = write(tmp_path, "r.csv", "garbage line one\nmore: garbage\nt,ax,ay,az\n0,1,2,3\n0.01,4,5,6\n")
    rec = load_recording(DataSpec(path=str(p), skip_rows=2))
    assert rec.n == 2


def test_metadata_lines_before_the_header(tmp_path):
    """tomisuarez's logs start with "Fs,100" and similar lines before the header."""
    p = write(tmp_path, "r.csv", "Fs,100\nLogging Type,0\nax,ay,az,gx,gy,gz\n1,2,3,0,0,0\n4,5,6,0,0,0\n")
    rec = load_recording(DataSpec(path=str(p), sample_rate=100.0))
    np.testing.assert_array_equal(rec.raw, [[1, 2, 3], [4, 5, 6]])


def test_simulation_csv_round_trips(counts_recording):
    rec = load_recording(counts_recording.path)
    np.testing.assert_array_equal(rec.raw, counts_recording.sim.raw)
    np.testing.assert_allclose(rec.t, counts_recording.sim.t, atol=1e-6)
    assert rec.sample_rate == pytest.approx(100.0, rel=1e-6)


# --- real recordings ------------------------------------------------------------------------
@pytest.mark.parametrize("parts, spec, n, first", [
    (("xsens-mti-imutk", "xsens_acc.mat"), {}, 51175, None),
    (("ros-imu-getovermassif", "data2", "acc_data.txt"), {}, 17589, None),
    (("mpu6050-tomisuarez", "example_data_calibration.csv"), {"sample_rate": 100.0}, 10245, None),
    (("imucal-ferraris", "annotated_session.csv"), {"sample_rate": 204.8}, 9414, None),
])
def test_real_recordings_load(parts, spec, n, first):
    p = real_file(*parts)
    rec = load_recording(DataSpec(path=str(p), **spec))
    assert rec.n == n
    assert np.isfinite(rec.raw).all() and (np.diff(rec.t) > 0).all()
    assert rec.sha256 == hashlib.sha256(p.read_bytes()).hexdigest()


def test_xsens_counts_and_rate():
    rec = load_recording(real_file("xsens-mti-imutk", "xsens_acc.mat"))
    assert 99 < rec.sample_rate < 101
    assert 500 < rec.duration < 520
    assert np.all(rec.raw == np.round(rec.raw)) and 20000 < rec.raw.mean() < 45000  # offset-binary counts


# --- errors, with their messages -------------------------------------------------------------
def expect_error(spec, match: str, field: str | None = None, file=None) -> ImucalError:
    with pytest.raises(ImucalError, match=match) as ei:
        load_recording(spec)
    msg = str(ei.value)
    assert "\n" not in msg
    if field is not None:
        assert ei.value.field == field
    if file is not None:
        assert msg.startswith(str(file))
    return ei.value


def test_missing_file(tmp_path):
    e = expect_error(tmp_path / "nope.csv", "file not found", "data.path", tmp_path / "nope.csv")
    assert "fix: check the path" in str(e)


def test_directory_instead_of_file(tmp_path):
    expect_error(tmp_path, "is a directory, not a file", "data.path", tmp_path)


def test_not_utf8(tmp_path):
    p = write(tmp_path, "r.csv", b"t,ax,ay,az\n0,1,2,\xff\xfe\n")
    expect_error(p, "is not UTF-8 text", "data.path", p)


@pytest.mark.parametrize("text", ["", "\n\n  \n", "# only a comment\n"])
def test_empty_file(tmp_path, text):
    p = write(tmp_path, "r.csv", text)
    expect_error(p, "is empty", "data.path", p)


def test_header_without_rows(tmp_path):
    for body in ("t,ax,ay,az\n", "t,ax,ay,az\n\n# nothing\n"):
        p = write(tmp_path, "r.csv", body)
        expect_error(p, "has no data rows", "data", p)


def test_missing_column(tmp_path):
    p = write(tmp_path, "r.csv", "t,ax,ay\n0,1,2\n0.01,1,2\n")
    e = expect_error(p, "missing column for az", "data.columns.az", p)
    assert "add a column named az" in str(e)


def test_mapped_column_not_in_header(tmp_path):
    p = write(tmp_path, "r.csv", "t,ax,ay,az\n0,1,2,3\n")
    e = expect_error(DataSpec(path=str(p), columns={"ax": "acc_x", "ay": "ay", "az": "az"}),
                     r"mapped column\(s\) \['acc_x'\] not in header \['t', 'ax', 'ay', 'az'\]",
                     "data.columns", p)
    assert "map the roles to the header's names" in str(e)
    p = write(tmp_path, "r.csv", "t,ax,ay,az\n0,1,2,3\n")
    expect_error(DataSpec(path=str(p), format="csv", columns={"ax": "acc_x"}), "not in header", "data.columns", p)


def test_unknown_header_names(tmp_path):
    p = write(tmp_path, "r.csv", "a,b,c,d\n0,1,2,3\n")
    expect_error(p, "line 1 is neither a header with known column names nor numbers", "data.columns", p)


def test_column_names_for_headerless_file(tmp_path):
    p = write(tmp_path, "r.txt", "0 1 2 3\n")
    expect_error(DataSpec(path=str(p), format="whitespace", columns={"ax": "x"}),
                 "column names given but the file has no header", "data.columns", p)


@pytest.mark.parametrize("ncol", [1, 2])
def test_too_few_columns_to_guess(tmp_path, ncol):
    p = write(tmp_path, "r.txt", " ".join(["1"] * ncol) + "\n")
    expect_error(p, f"has {ncol} column\\(s\\): an accelerometer recording needs at least ax ay az",
                 "data.columns", p)


@pytest.mark.parametrize("bad", ["nan", "NaN", "inf", "-inf", "1e999"])
def test_nan_inf_rows_name_the_line(tmp_path, bad):
    p = write(tmp_path, "r.csv", f"t,ax,ay,az\n0,1,2,3\n0.01,1,{bad},3\n0.02,1,2,3\n")
    e = expect_error(p, "line 3 holds NaN or Inf", "data", p)
    assert "remove or repair" in str(e)


def test_non_numeric_text_names_line_and_column(tmp_path):
    p = write(tmp_path, "r.csv", "t,ax,ay,az\n0,1,2,3\n0.01,1,2,3\n0.02,1,two,3\n")
    expect_error(p, r"line 4 column 3: 'two' is not a number", "data", p)


def test_ragged_row(tmp_path):
    p = write(tmp_path, "r.csv", "t,ax,ay,az\n0,1,2,3\n0.01,1,2\n")
    expect_error(p, "line 3 has 3 columns, expected at least 4", "data", p)


@pytest.mark.parametrize("times, words, fix", [
    ("0 0.01 0.01", "time stamp 0.01 repeats at line 4", "enough digits for each sample to have its own"),
    ("0 0.02 0.01", "time goes back at line 4 (0.01 after 0.02)", "sort the rows by time"),
    ("0.5 0.2 0.3", "time goes back at line 3 (0.2 after 0.5)", "sort the rows by time")])
def test_time_not_increasing(tmp_path, times, words, fix):
    rows = "".join(f"{t},1,2,3\n" for t in times.split())
    p = write(tmp_path, "r.csv", "t,ax,ay,az\n" + rows)
    e = expect_error(p, re.escape(words), "data.columns.t", p)
    assert fix in str(e)


@pytest.mark.parametrize("kw, field, match", [
    ({"format": "xlsx"}, "data.format", "unknown format 'xlsx'"),
    ({"time_unit": "h"}, "data.time_unit", "unknown time unit 'h'"),  # min is one since issue 25
    ({"sample_rate": 0.0}, "data.sample_rate", "sample rate 0.0 Hz is not an IMU rate"),
    ({"sample_rate": float("nan")}, "data.sample_rate", "is not an IMU rate"),
    ({"sample_rate": "fast"}, "data.sample_rate", "is not an IMU rate"),
    ({"skip_rows": -1}, "data.skip_rows", "skip_rows -1 must be a non-negative integer"),
    ({"skip_rows": 1.5}, "data.skip_rows", "must be a non-negative integer"),
    ({"columns": {"gyro": 1}}, "data.columns", r"unknown column role\(s\) \['gyro'\]"),
    ({"columns": {"ax": -1}}, "data.columns.ax", "must be a header name or a 0-based index"),
    ({"columns": {"ax": 1.5}}, "data.columns.ax", "must be a header name or a 0-based index"),
    ({"delimiter": ""}, "data.delimiter", "must be one character"),
    ({"delimiter": 5}, "data.delimiter", "must be one character"),
    ({"time_unit": ["s"]}, "data.time_unit", "must be text"),
])
def test_bad_data_spec_values(kw, field, match):
    with pytest.raises(ImucalError, match=match) as ei:
        DataSpec(path="x.csv", **kw)
    assert ei.value.field == field


@pytest.mark.parametrize("path", [None, 5, ""])
def test_bad_path_value(path):
    with pytest.raises(ImucalError, match="must be a file name") as ei:
        config_from_dict({"data": {"path": path}}, "run.yaml")
    assert ei.value.field == "data.path" and str(ei.value).startswith("run.yaml: data.path:")
