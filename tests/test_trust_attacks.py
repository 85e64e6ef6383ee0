"""Hostile invocations found by the attack37 campaign: each case failed before its fix (an internal error,
a message without the file, a silently wrong reading) and is now one line, exit 2, nothing written.

Small files, errors raised before any fit: the whole module runs in a few seconds.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from imucal.data.blocks import TextBlocks
from imucal.data.header_names import read_name
from imucal.data.load import load_recording
from imucal.data.spec import DataSpec
from imucal.data.stream import StreamedRecording
from imucal.errors import ImucalError
from test_trust import one_line_error


def _rows(n: int = 300) -> np.ndarray:
    """``n`` rows of t [s], ax, ay, az [m/s^2] at 100 Hz."""
    return np.c_[np.arange(n) * 0.01, np.zeros(n), np.zeros(n), np.full(n, 9.81)]


def _csv(path: Path, header: str, arr: np.ndarray, above: str = "") -> Path:
    path.write_text(above + header + "\n" + "\n".join(",".join(f"{v:.6g}" for v in r) for r in arr) + "\n",
                    encoding="utf-8")
    return path


@pytest.mark.parametrize("inner", ["\u00b2", "\u00b9", "\u2460", "\u0661", "\uff11"])
def test_an_axis_index_of_other_digits_is_a_unit_refused_in_one_line(run_cli, tmp_path, unchanged, inner):
    """acc_x [²] (str.isdigit, but int() refuses it) was an internal error (exit 3); another script's digits
    were read as an axis index the name does not write. Only ASCII digits index an axis now; the rest is a
    stated unit, refused naming the column."""
    assert read_name("accelerometer_m_s2[1]").role == "ay" and read_name(f"acc_x [{inner}]").unit == inner
    src = _csv(tmp_path / "h.csv", f"t,acc_x [{inner}],acc_y,acc_z", _rows())
    with unchanged():
        r = run_cli(["calibrate", "--data", src, "--out", tmp_path / "o"])
    assert r.code == 2, r
    one_line_error(r.err, str(src), "data.columns.ax", f"'acc_x [{inner}]' states", "fix:")


@pytest.mark.parametrize("rate", ["1e-300", "1e300", "0.5"])
def test_an_implausible_rate_above_the_header_names_the_file_and_its_line(run_cli, tmp_path, unchanged, rate):
    """"Fs,1e-300" above a header without a time column was refused as data.sample_rate's value without the
    file (the user gave no rate); now the file and the line are named, with or without a rate given."""
    src = _csv(tmp_path / "fs.csv", "ax,ay,az", _rows()[:, 1:], above=f"Fs,{rate}\n")
    for extra in ([], ["--sample-rate", "100"]):
        with unchanged():
            r = run_cli(["calibrate", "--data", src, "--out", tmp_path / "o", *extra])
        assert r.code == 2, r
        one_line_error(r.err, str(src), "data.sample_rate", "the line above its header states a sample rate of",
                       "not an IMU rate", "fix: correct the line")


@pytest.mark.parametrize("stream", ["never", "always"])
def test_sensors_interleaved_past_the_head_are_refused_naming_the_line(tmp_path, stream):
    """An ArduPilot IMU log whose instance column I changes only after the rows the layout looks at was read as
    one sensor (the check saw one value in the head): every row's I is checked now, by both readers."""
    n = 400
    inst = np.where(np.arange(n) < 200, 0, np.arange(n) % 2)
    arr = _rows(n)
    src = _csv(tmp_path / "ap.csv", "TimeUS,I,AccX,AccY,AccZ", np.c_[arr[:, 0] * 1e6, inst, arr[:, 1:]])
    read = (lambda s: load_recording(s)) if stream == "never" else (lambda s: StreamedRecording(s))
    with pytest.raises(ImucalError) as ei:
        read(DataSpec(path=str(src), stream=stream))
    assert str(ei.value).endswith("ap.csv: data.path: rows of 2 sensors are interleaved from line 203 on (column 'I' "
                                  "holds '0', '1') (fix: write one sensor's rows to a file (ArduPilot: mavlogdump.py "
                                  "--types IMU --condition 'IMU.I==0' --format csv) and calibrate each)"), str(ei.value)
    one = _csv(tmp_path / "one.csv", "TimeUS,I,AccX,AccY,AccZ", np.c_[arr[:, 0] * 1e6, np.zeros(n), arr[:, 1:]])
    assert read(DataSpec(path=str(one), stream=stream)) is not None  # one instance throughout: read


@pytest.mark.parametrize("header, units, words", [
    ("t,acc_x [g],acc_y [g],acc_z [g]", "s,m/s^2,m/s^2,m/s^2", "column 'acc_x [g]' states 'g' in its name and 'm/s^2'"),
    ("time (ms),ax,ay,az", "s,g,g,g", "column 'time (ms)' states 'ms' in its name and 's'")])
def test_a_unit_the_name_and_the_units_line_state_differently_is_refused(run_cli, tmp_path, unchanged, header, units,
                                                                          words):
    """acc_x [g] over a line of units saying m/s^2 was read in g, the line's unit dropped in silence: the file
    says both, so neither is taken. Two spellings of one unit (g over G) are read."""
    src = _csv(tmp_path / "u.csv", header, _rows(), above="")
    src.write_text(src.read_text().replace("\n", f"\n{units}\n", 1))
    with unchanged():
        r = run_cli(["calibrate", "--data", src, "--out", tmp_path / "o"])
    assert r.code == 2, r
    one_line_error(r.err, str(src), "data.columns", words, "in the line of units under the header", "fix:")
    src.write_text(src.read_text().replace(units, "s,G,g,g" if "acc_x" in header else "ms,g,g,g"))
    assert load_recording(DataSpec(path=str(src))).raw.shape == (300, 3)


@pytest.mark.parametrize("encoding", ["utf-16", "utf-16-le", "utf-16-be", "utf-32"])
def test_a_utf16_recording_is_named_with_the_fix_that_reads_it(run_cli, tmp_path, unchanged, encoding):
    """A spreadsheet's "Unicode text" (UTF-16) was called a binary file to export as CSV, which it already is
    (a run file in UTF-16: a binary file): now the encoding is named and the fix says to save it as UTF-8."""
    src = tmp_path / "wide.csv"
    src.write_bytes(_csv(tmp_path / "plain.csv", "t,ax,ay,az", _rows()).read_text().encode(encoding))
    with unchanged():
        r = run_cli(["calibrate", "--data", src, "--out", tmp_path / "o"])
    assert r.code == 2, r
    one_line_error(r.err, str(src), "data.path: is UTF-16 or UTF-32 text, not UTF-8", "fix: save it as UTF-8 text")
    run = tmp_path / "run.yaml"  # a run file alike (every text file imucal reads: imucal.files.inputs)
    run.write_bytes("data: {path: plain.csv}\n".encode(encoding))
    with unchanged():
        r = run_cli(["calibrate", run, "--out", tmp_path / "o"])
    assert r.code == 2, r
    one_line_error(r.err, str(run), "is UTF-16 or UTF-32 text, not UTF-8", "fix: save it as UTF-8 text")


@pytest.mark.parametrize("delim", [";", "\t"])
def test_a_decimal_comma_is_read_alike_by_both_readers(tmp_path, delim):
    """0,01;9,81 was read by the whole-file reader and refused by the streaming one (a file above 64 MB, or
    data.stream: always): both read it now, to the same numbers."""
    arr = _rows()
    arr[:, 1] = 0.125 + np.sin(np.arange(arr.shape[0])) * 1e-3
    text = "t;ax;ay;az\n" + "\n".join(";".join(f"{v:.6g}" for v in r) for r in arr) + "\n"
    src = tmp_path / "comma.csv"
    src.write_text(text.replace(",", "").replace(".", ",").replace(";", delim))
    whole = load_recording(DataSpec(path=str(src), stream="never"))
    np.testing.assert_allclose(whole.raw, arr[:, 1:], rtol=1e-5)
    blocks = TextBlocks(DataSpec(path=str(src), stream="always"), src)  # the streaming reader's rows
    np.testing.assert_array_equal(np.concatenate([a for _, _, a in blocks.rows()])[:, 1:], whole.raw)


@pytest.mark.parametrize("text, field", [('data: {path: "in\\0.csv"}', "data.path"),
                                         ('data: {path: in.csv}\noutput: {dir: "o\\0ut"}', "output.dir"),
                                         ('data: {path: in.csv}\nfit: {base: "b\\0.yaml"}', "fit.base")])
def test_a_nul_escaped_in_a_run_files_text_is_refused(run_cli, tmp_path, unchanged, text, field):
    """"in\\0.csv" (a YAML escape: the file holds no NUL byte) reached os.stat as an internal error (exit 3);
    now any text of a YAML file holding a NUL is refused naming its field, and a notebook's mapping alike."""
    from imucal.config.run import config_from_dict

    _csv(tmp_path / "in.csv", "t,ax,ay,az", _rows())
    run = tmp_path / "run.yaml"
    run.write_text(text + "\n")
    with unchanged():
        r = run_cli(["calibrate", run, "--no-figures"])
    assert r.code == 2, r
    one_line_error(r.err, str(run), f"the text of '{field}' holds a NUL character", "fix: remove it")
    with pytest.raises(ImucalError, match="'data.path' holds a NUL character"):
        config_from_dict({"data": {"path": "in\0.csv"}})


@pytest.mark.parametrize("text, field, fix", [("static: {window: 1e-1}", "static.window", "write 1.0e-1"),
                                              ("static: {threshold: 1E5}", "static.threshold", "write 1.0e+5"),
                                              ("fit: {initial: {b1: 4.1e2}}", "fit.initial.b1", "write 4.1e+2")])
def test_a_number_yaml_reads_as_text_says_so_and_how_to_write_it(run_cli, tmp_path, unchanged, text, field, fix):
    """window: 1e-1 is the text '1e-1' to YAML 1.1, refused as "must be a positive number of seconds", which it
    looks like: the message now says YAML read it as text, and the fix writes it as a number."""
    _csv(tmp_path / "in.csv", "t,ax,ay,az", _rows())
    run = tmp_path / "run.yaml"
    run.write_text(f"data: {{path: in.csv}}\n{text}\n")
    with unchanged():
        r = run_cli(["calibrate", run, "--no-figures"])
    assert r.code == 2, r
    one_line_error(r.err, str(run), field, "as text, not a number", f"(fix: {fix}: a decimal point and a signed")


_CONTROLS = ("\x1b", "\x07", "\u202e")  #: ESC (cursor, colours), BEL (ends an OSC title), a bidi override


def test_control_characters_of_a_file_name_reach_no_terminal_or_report(run_cli, tmp_path, si_recording):
    """A recording named e\\x1b]0;pwned\\x07\\u202e.csv retitled the terminal and reordered its line: the name was
    written raw into calibrate's and compare's output, the error line and report.txt and report.html. Every one
    now shows the characters as escapes (imucal.errors.printable)."""
    from imucal.errors import printable

    assert printable("e\x1b]0;x\x07\u202e\udcff.csv µ") == "e\\x1b]0;x\\x07\\u202e\\udcff.csv µ"
    src = tmp_path / "e\x1b]0;pwned\x07\u202e.csv"
    src.write_bytes(Path(si_recording.path).read_bytes())
    r = run_cli(["calibrate", "--data", src, "--out", tmp_path / "cal", "--no-figures"])
    assert r.code == 0, r.err
    r2 = run_cli(["compare", tmp_path / "cal" / "calibration.yaml", tmp_path / "cal" / "calibration.yaml",
                  "--data", src])
    r3 = run_cli(["calibrate", "--data", src, "--columns", "t=nope,ax=ax,ay=ay,az=az", "--out", tmp_path / "o"])
    assert r2.code == 0 and r3.code == 2, (r2.err, r3.err)
    shown = [r.out, r.err, r2.out, r3.err] + [(tmp_path / "cal" / f).read_text() for f in ("report.txt", "report.html")]
    assert not [c for c in _CONTROLS for text in shown if c in text]
    assert "e\\x1b]0;pwned\\x07\\u202e.csv" in r.out and "e\\x1b]0;pwned\\x07\\u202e.csv" in r3.err


def test_the_command_a_warning_suggests_quotes_the_file_name():
    """"investigate with: imucal discover --data x.csv; rm -rf ~" was a command to copy that runs another:
    the file name is quoted for the shell now."""
    from types import SimpleNamespace

    from imucal.config.run import config_from_dict
    from imucal.pipeline import discover_command

    cfg = config_from_dict({"data": {"path": "x.csv"}, "gravity": {"value": 9.81}})
    cmd = discover_command(cfg, SimpleNamespace(source="x.csv; rm -rf ~"))
    assert cmd == "imucal discover --data 'x.csv; rm -rf ~' --gravity 9.81", cmd


@pytest.mark.parametrize("command", [["worst-case", "--starts", "2"], ["drift", "--error", "0.01"]])
@pytest.mark.parametrize("g", ["1e26", "1e-308", "\uff11"])
def test_a_gravity_option_no_earth_has_is_refused_as_calibrates_is(run_cli, tmp_path, unchanged, command, g):
    """worst-case and drift took --gravity 1e26, 1e-308 or a full-width 1 (float() reads it: 1 m/s^2) and
    analysed it; calibrate refuses those. One check (imucal.config.run.check_gravity) for all three now."""
    with unchanged():
        r = run_cli([*command, "--gravity", g, "--json", tmp_path / "o.json"])
    assert r.code == 2, r
    one_line_error(r.err, "--gravity: gravity", "is not a local gravity on Earth", "(fix: give local g")


@pytest.mark.parametrize("text", ['{"a": NaN}', '{"a": 1, "a": 2}', "[" * 100000 + "]" * 100000, "a: 1",
                                  '{"a": ' + "9" * 5000 + "}"])
def test_a_json_input_that_is_not_json_says_what_to_do(tmp_path, text):
    """A noise file, a mad-lab or matrix JSON, or a pose plan that was not plain JSON was refused without a fix;
    each now says what to give."""
    from imucal.analysis.plan_file import read_plan
    from imucal.files.inputs import read_json

    p = tmp_path / "x.json"
    p.write_text(text)
    for read, fix in ((lambda: read_json(str(p), "noise"), "(fix: give the JSON file as its tool wrote it"),
                      (lambda: read_plan(str(p)), "(fix: ")):
        with pytest.raises(ImucalError) as ei:
            read()
        assert fix in str(ei.value) and "\n" not in str(ei.value), str(ei.value)


def test_nanosecond_stamps_since_1970_are_written_back_as_the_file_holds_them(run_cli, tmp_path, si_recording):
    """apply's t is "the input's time column as read": EuRoC's 1403636579758555399 ns came out as
    1.4036365797585554e+18 (a double holds 2**53 exactly, these stamps to 256 ns), so no row joined the camera's
    stamps. Integer stamps beyond 2**53 are now written as the file writes them; the samples are unchanged."""
    d = np.loadtxt(si_recording.path, delimiter=",", skiprows=1)
    stamps = [str(1403636579758555392 + round(t * 1e9) + 7) for t in d[:, 0]]
    src = tmp_path / "euroc.csv"
    src.write_text("#timestamp [ns],ax,ay,az\n" + "".join(f"{s},{r[1]:.17g},{r[2]:.17g},{r[3]:.17g}\n"
                                                          for s, r in zip(stamps, d)))
    plain = tmp_path / "plain.csv"
    plain.write_text("t,ax,ay,az\n" + "".join(f"{r[0]:.17g},{r[1]:.17g},{r[2]:.17g},{r[3]:.17g}\n" for r in d))
    r0 = run_cli(["calibrate", "--data", si_recording.path, "--out", tmp_path / "c", "--no-figures"])
    assert r0.code == 0, r0.err
    out = {}
    for name, data in (("euroc", src), ("plain", plain)):
        r = run_cli(["apply", tmp_path / "c" / "calibration.yaml", "--data", data, "--out", tmp_path / f"{name}.out"])
        assert r.code == 0, r.err
        out[name] = (tmp_path / f"{name}.out").read_text().splitlines()
    assert [ln.split(",", 1)[0] for ln in out["euroc"][1:]] == stamps
    assert [ln.split(",", 1)[1] for ln in out["euroc"]] == [ln.split(",", 1)[1] for ln in out["plain"]]
