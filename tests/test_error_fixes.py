"""Every refusal says what to do: ``FILE: FIELD: what is wrong (fix: what to do)``, exit 2, one line.

An AST scan holds the rule for the code: every ``ImucalError(...)`` in imucal/ has a ``fix=`` (a few internal
checks excepted, each listed with its reason), and no helper forwards a fix that may be None. The command-line
cases are those the trust38 campaign found without a fix, or naming the wrong field: the second file's
(--gyro-data) errors named the recording's data.path, an option's error named it without its dashes,
ArduPilot's instance column compared 0 and 0.0 as text, --mag-field refused 48.2µT, and
`imucal noise --config` needed --data beside a run file that names it. Each case failed before its fix.
"""
from __future__ import annotations

import ast
import errno
import os
from pathlib import Path

import numpy as np
import pytest

from imucal.data.load import load_recording
from imucal.data.spec import DataSpec
from imucal.data.stream import StreamedRecording
from imucal.errors import ImucalError
from test_trust import one_line_error

PACKAGE = Path(__file__).resolve().parents[1] / "imucal"

#: ImucalError constructions without a fix, each an internal check no input of a user reaches:
#: (file under imucal/, a substring of the message's source text, why it needs no fix).
NO_FIX = [
    ("data/stream.py", "the time step changed between passes",
     "internal: the second pass reads the times the first made (pragma: no cover)"),
    ("model/parameters.py", "duplicate parameter",
     "internal: a model's own parameter list, built by imucal"),
    ("solve/fit.py", "do not match the model's",
     "internal: the caller passes the model's own parameters"),
    ("thermal/fit.py", "parameters do not match the model",
     "internal: the caller passes the model's own parameters"),
]


def _calls() -> list[tuple[str, int, ast.Call, str, ast.AST | None]]:
    """(file, line, call, the message's source text, the enclosing function) of every ImucalError(...)."""
    out = []
    for path in sorted(PACKAGE.rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        parents = {child: node for node in ast.walk(tree) for child in ast.iter_child_nodes(node)}
        for node in ast.walk(tree):
            if not isinstance(node, ast.Call):
                continue
            f = node.func
            if (f.id if isinstance(f, ast.Name) else f.attr if isinstance(f, ast.Attribute) else None) != "ImucalError":
                continue
            message = ast.unparse(node.args[0]) if node.args else ""
            up = parents.get(node)
            while up is not None and not isinstance(up, (ast.FunctionDef, ast.AsyncFunctionDef)):
                up = parents.get(up)
            out.append((path.relative_to(PACKAGE).as_posix(), node.lineno, node, message, up))
    return out


def _fix(call: ast.Call) -> ast.expr | None:
    return next((k.value for k in call.keywords if k.arg == "fix"), None)


def _allowed(file: str, message: str) -> bool:
    return any(file == f and text in message for f, text, _ in NO_FIX)


def test_every_error_says_what_to_do():
    """An ImucalError without fix= (or with fix=None) is a finding, unless it is an internal check on NO_FIX."""
    missing = [f"imucal/{f}:{line}: {msg[:80]}" for f, line, call, msg, _ in _calls()
               if (_fix(call) is None or (isinstance(_fix(call), ast.Constant) and _fix(call).value is None))
               and not _allowed(f, msg)]
    assert not missing, "ImucalError without fix= (add a true, specific fix, or list it in NO_FIX):\n" + \
        "\n".join(missing)


def test_the_no_fix_list_names_only_errors_that_exist():
    """Each NO_FIX entry still matches an ImucalError without a fix: the list cannot outlive its code."""
    bare = [(f, msg) for f, _, call, msg, _ in _calls() if _fix(call) is None]
    for file, text, reason in NO_FIX:
        assert reason.startswith("internal:"), (file, reason)
        assert any(f == file and text in msg for f, msg in bare), f"NO_FIX entry {file}: {text!r} matches no error"


def test_no_helper_forwards_a_fix_that_may_be_none():
    """fix=fix passes a helper's own parameter on: the parameter is then required, or given a value when None
    (``fix or "..."``, or assigned in the helper), so a caller cannot leave the fix out."""
    found = []
    for f, line, call, msg, func in _calls():
        value = _fix(call)
        if not (isinstance(value, ast.Name) and func is not None):
            continue
        args = func.args
        params = args.posonlyargs + args.args
        defaults = dict(zip([a.arg for a in params][len(params) - len(args.defaults):], args.defaults))
        defaults.update({a.arg: d for a, d in zip(args.kwonlyargs, args.kw_defaults) if d is not None})
        default = defaults.get(value.id)
        assigned = any(isinstance(n, ast.Assign)
                       and any(isinstance(t, ast.Name) and t.id == value.id for t in n.targets) for n in ast.walk(func))
        if isinstance(default, ast.Constant) and default.value is None and not assigned:
            found.append(f"imucal/{f}:{line}: fix={value.id} may be None ({func.name})")
    assert not found, "\n".join(found)


# --- the command line ---------------------------------------------------------------------------------
def _rows(n: int = 300) -> np.ndarray:
    """``n`` rows of t [s], ax, ay, az [m/s^2] at 100 Hz."""
    return np.c_[np.arange(n) * 0.01, np.zeros(n), np.zeros(n), np.full(n, 9.81)]


def _write(path: Path, text: str | bytes) -> Path:
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_text(text, encoding="utf-8")
    return path


def _refused(r, *parts: str) -> None:
    """Exit 2, one line with every part and a fix, no traceback."""
    assert r.code == 2, r
    one_line_error(r.err, *parts, "(fix: ")


@pytest.fixture
def cal_file(counts_run, tmp_path) -> Path:
    p = tmp_path / "cal.yaml"
    counts_run.calibration.save(p)
    return p


GYRO_FILES = {
    "missing": None,
    "empty": "",
    "binary": bytes(range(256)) * 8,
    "wrong columns": "foo,bar\n1,2\n3,4\n",
    "NaN": "t,gx,gy,gz\n" + "".join(f"{k * 0.01:.2f},{'nan' if k == 5 else 0},0,0\n" for k in range(300)),
}


@pytest.mark.parametrize("kind", list(GYRO_FILES))
def test_a_bad_gyro_file_is_named_as_gyro_data(run_cli, counts_recording, tmp_path, kind):
    """The second file's errors named the recording's field, data.path (or data.columns, data): the user gave no
    such thing for it. They name --gyro-data now, and a header's fix says how to name a gyroscope's columns."""
    g = tmp_path / "gyro.csv"
    if GYRO_FILES[kind] is not None:
        _write(g, GYRO_FILES[kind])
    r = run_cli(["calibrate", "--data", counts_recording.path, "--gyro-data", g, "--out", tmp_path / "o",
                 "--no-figures"])
    _refused(r, str(g), ": --gyro-data: ")
    assert "data.path" not in r.err and "data.columns" not in r.err, r.err
    if kind == "wrong columns":
        assert "gx, gy, gz" in r.err


def _ardupilot(path: Path, instances: list[str]) -> Path:
    arr = _rows(len(instances))
    return _write(path, "TimeUS,I,AccX,AccY,AccZ\n" + "".join(
        f"{r[0] * 1e6:.6g},{i},{r[1]:.6g},{r[2]:.6g},{r[3]:.6g}\n" for r, i in zip(arr, instances)))


@pytest.mark.parametrize("stream", ["never", "always"])
@pytest.mark.parametrize("instances", [["0"] * 200 + ["0.0"] * 200, ["0", "0.0"] * 200, ["1", "1.0", "1e0"] * 100])
def test_an_instance_column_is_compared_as_a_number(tmp_path, stream, instances):
    """ArduPilot's I compared as text: 0 and 0.0 (one IMU, as a tool that rewrote the CSV writes it) were two
    sensors, refused as interleaved; past the head or within it, by both readers."""
    src = _ardupilot(tmp_path / "ap.csv", instances)
    read = load_recording if stream == "never" else StreamedRecording
    assert read(DataSpec(path=str(src), stream=stream)) is not None


@pytest.mark.parametrize("stream", ["never", "always"])
def test_two_numbers_in_the_instance_column_are_still_two_sensors(tmp_path, stream):
    src = _ardupilot(tmp_path / "ap.csv", ["0.0"] * 300 + ["1"] * 100)
    read = load_recording if stream == "never" else StreamedRecording
    with pytest.raises(ImucalError, match=r"rows of 2 sensors are interleaved from line 302 on \(column 'I' holds "
                                          r"'0.0', '1'\)"):
        read(DataSpec(path=str(src), stream=stream))


@pytest.mark.parametrize("at", [0, 250])
def test_a_text_instance_is_one_line_naming_the_line(run_cli, tmp_path, unchanged, at):
    src = _ardupilot(tmp_path / "ap.csv", ["0"] * at + ["IMU0"] + ["0"] * (300 - at))
    with unchanged():
        r = run_cli(["calibrate", "--data", src, "--out", tmp_path / "o"])
    _refused(r, str(src), "data.path", f"column 'I' holds 'IMU0' at line {at + 2}, not an IMU instance number",
             "IMU number (0, 1, ...)")


@pytest.mark.parametrize("text, value", [("48.2µT", (48.2, "uT")), ("48.2\u03bcT", (48.2, "uT")),
                                         ("48.2 uT", (48.2, "uT")), ("0.482 G", (0.482, "G")),
                                         ("48.2uT", (48.2, "uT")), ("480", (480.0, None))])
def test_mag_field_takes_the_micro_sign(text, value):
    """--mag-field 48.2µT (the sign the WMM calculators print) was refused as not a field magnitude."""
    from imucal.cli.commands.options import mag_field

    assert mag_field(text) == value


def test_mag_field_with_the_micro_sign_calibrates_as_with_u(run_cli, tmp_path):
    """The whole run: 48µT gives the calibration 48uT gives."""
    from test_mag_plugin import write_log

    log = tmp_path / "log.csv"
    write_log(log)
    out = {}
    for unit in ("uT", "µT"):
        r = run_cli(["calibrate", "--data", log, "--mag-field", f"48{unit}", "--out", tmp_path / unit, "--no-figures",
                     "--quiet"])
        assert r.code in (0, 1), r.err
        out[unit] = [ln for ln in (tmp_path / unit / "calibration.yaml").read_text().splitlines()
                     if not ln.startswith("created: ")]
    assert out["uT"] == out["µT"] and any(ln.strip().startswith("mx") or "magnetometer" in ln for ln in out["uT"])


def test_a_run_files_mag_units_take_the_micro_sign(run_cli, tmp_path):
    """mag.field_unit: µT (and mag.unit, --mag-unit) was refused as 'not a unit name' (fix: uT) while --mag-field
    took 48.2µT: a run file's µT is uT, and the calibration is the one uT gives."""
    from test_mag_plugin import write_log

    log = tmp_path / "log.csv"
    write_log(log)
    out = {}
    for unit in ("uT", "\u00b5T", "\u03bcT"):
        run = _write(tmp_path / f"run{len(out)}.yaml", f"data:\n  path: {log.name}\nmag:\n  field: 48\n  field_unit: {unit}\n")
        r = run_cli(["calibrate", run, "--out", tmp_path / f"o{len(out)}", "--no-figures", "--quiet"])
        assert r.code in (0, 1), r.err
        out[unit] = [ln for ln in (tmp_path / f"o{len(out)}" / "calibration.yaml").read_text().splitlines()
                     if not ln.startswith("created: ")]
    assert out["uT"] == out["\u00b5T"] == out["\u03bcT"]
    r = run_cli(["calibrate", "--data", log, "--mag-unit", "\u00b5T", "--mag-field", "48uT", "--out", tmp_path / "cli",
                 "--no-figures", "--quiet"])
    assert r.code in (0, 1, 2) and "is not a unit name" not in r.err, r.err


@pytest.mark.parametrize("text", ["48.2 tesla-ish", "forty uT", "48.2T2"])
def test_a_bad_mag_field_says_how_to_write_one(run_cli, tmp_path, text):
    r = run_cli(["calibrate", "--data", tmp_path / "x.csv", "--mag-field", text])
    _refused(r, "--mag-field: ", "is not a field magnitude", "fix: write a number and one of uT, nT", "48.2µT")


def test_noise_reads_the_run_files_data(run_cli, counts_recording, tmp_path):
    """`imucal noise --config run.yaml` refused without --data, though the run file names data.path; it reads
    the run file's data as `calibrate` does (relative to the run file), with the same result as --data."""
    run = _write(tmp_path / "run.yaml", f"data:\n  path: {os.path.relpath(counts_recording.path, tmp_path)}\n")
    by_config = run_cli(["noise", "--config", run])
    assert by_config.code == 0, by_config.err
    by_data = run_cli(["noise", "--data", counts_recording.path])
    assert by_data.code == 0 and by_config.out == by_data.out


def test_noise_without_data_or_run_file_is_one_line(run_cli):
    _refused(run_cli(["noise"]), "arguments: nothing to read", "--data")


@pytest.mark.parametrize("args, field", [
    (["error-map", "--angles", "1.5", "1.6", "1.6", "--bins", "1"], "--bins: bins 1 must be between 5 and 2000"),
    (["error-map", "--angles", "1.5", "1.6", "1.6", "--grid", "1"], "--grid: grid 1 must be between 2 and 40"),
    (["worst-case", "--tolerance", "-1"], "--tolerance: "),
    (["worst-case", "--range-g=-1"], "--range-g: "),
    (["plan-poses", "--n", "12", "--noise", "-1"], "--noise: noise -1.0 must be a positive number of m/s^2"),
])
def test_an_option_is_named_as_typed(run_cli, tmp_path, args, field):
    """The errors of --bins, --grid, --tolerance, --noise ... named the field without its dashes ("bins: bins 1
    must be ...") and --bins and --grid had no fix."""
    extra = ["--out", tmp_path / "o"] if args[0] == "error-map" else []
    _refused(run_cli([*args, *extra]), "imucal: error: " + field)


def test_widen_is_named_as_typed(run_cli, cal_file):
    _refused(run_cli(["worst-case", "--calibration", cal_file, "--widen", "-1"]),
             "--widen: widening -1.0 must be a non-negative number of standard errors", "e.g. 2")


@pytest.mark.parametrize("args, field", [(["--alpha", "2"], "--alpha: alpha_noise 2.0 must lie in (0, 1)"),
                                         (["--max-effects", "0"], "--max-effects: "),
                                         (["--candidates", "nonsense"], "--candidates: unknown effect")])
def test_discover_options_are_named_as_typed(run_cli, counts_recording, args, field):
    _refused(run_cli(["discover", "--data", counts_recording.path, *args]), field)


@pytest.mark.parametrize("text, field, words", [
    ("data:\n  path: x.csv\n  skip_rows: -1\n", "data.skip_rows", "whole number"),
    ("- data\n- fit\n", "top level: top level must be a mapping, got list", "mapping of keys to values"),
    ("data: [1]\n", "data: section must be a mapping", "write data as a mapping of keys to values"),
    ("data:\n  path: x.csv\ngravity:\n  value: 9.81\n  latitude: 45\n", "gravity: give either", "drop the other"),
    ("data:\n  path: x.csv\nstatic:\n  window: 0\n", "static.window", "give static.window as a positive number"),
    ("data:\n  path: x.csv\nfit:\n  effects: [{name: bias_temperature, axes: [w]}]\n", "fit.effects[0].axes",
     "e.g. axes: [x, z]"),
])
def test_run_file_errors_say_what_to_do(run_cli, tmp_path, text, field, words):
    run = _write(tmp_path / "run.yaml", text)
    _refused(run_cli(["calibrate", run, "--out", tmp_path / "o"]), str(run), field, words)


def test_a_json_input_that_is_no_mapping_says_what_to_do(run_cli, counts_recording, tmp_path):
    noise = _write(tmp_path / "noise.json", "[1, 2]\n")
    _refused(run_cli(["calibrate", "--data", counts_recording.path, "--noise", noise, "--out", tmp_path / "o"]),
             str(noise), "must be a mapping")


def test_a_run_file_beside_a_manifest_that_is_no_mapping(run_cli, counts_recording, tmp_path):
    m = _write(tmp_path / "m.yaml", f"units: [{{id: U1, data: {counts_recording.path}}}]\n")
    run = _write(tmp_path / "run.yaml", "- a\n")
    _refused(run_cli(["batch", m, "--config", run, "--out", tmp_path / "res"]), str(run),
             "top level: top level must be a mapping, got list", "as for `imucal calibrate`")


def test_a_folder_pattern_without_a_folder(run_cli, tmp_path):
    m = _write(tmp_path / "m.yaml", "units: [{id: U1, data: a.csv}]\npattern: '*.csv'\n")
    _refused(run_cli(["batch", m, "--out", tmp_path / "res"]), str(m), "pattern: pattern is used only with folder:",
             "add folder: DIR")


@pytest.mark.parametrize("name, fmt, text, words", [
    ("x.calib", "imutk", "1 " * 20, "calib: expected 21 numbers (T, K, b), found 20 (fix: give imu_tk's"),
    ("x.calib", "imutk", "1 " * 20 + "one", "calib: 'one' is not a number (fix: "),
    ("m.csv", "matrix", "1,0,0,0\n0,1,0,0\n", "matrix: expected 3 rows of 4 numbers"),
    ("p.csv", "tomisuarez", "1,2,3\n", "params: expected 9 numbers, found 3 (fix: "),
    ("imu.yaml", "kalibr", "model: scale-misalignment\naccelerometers:\n  M: [[400.0, 0.5, 0.0], [1.0, 410.0, 0.0], "
                           "[2.0, 3.0, 405.0]]\n", "accelerometers.M: is not lower triangular"),
])
def test_peer_files_say_what_to_do(run_cli, cal_file, tmp_path, name, fmt, text, words):
    other = _write(tmp_path / name, text)
    _refused(run_cli(["compare", cal_file, other, "--format", fmt, "--data", tmp_path / "never-read.csv"]),
             str(other), words)


def test_a_file_the_system_will_not_read_says_what_to_do(run_cli, tmp_path, monkeypatch):
    """An OSError other than not-found (EACCES, EIO) was 'cannot read: ...' without a fix (root ignores the mode
    bits, so the refusal is simulated)."""
    src = _write(tmp_path / "log.csv", "t,ax,ay,az\n0,0,0,1\n")
    real = os.open

    def refusing(path, *a, **kw):
        if str(path) == str(src):
            raise PermissionError(errno.EACCES, "Permission denied", str(path))
        return real(path, *a, **kw)

    monkeypatch.setattr(os, "open", refusing)
    _refused(run_cli(["calibrate", "--data", src, "--out", tmp_path / "o"]), str(src), "data.path",
             "cannot read: Permission denied", "chmod u+r")


# --- the library: the same rule for a notebook user ---------------------------------------------------------
def test_library_refusals_say_what_to_do(counts_run):
    import imucal
    from imucal.analysis.error_map import compute_error_map
    from imucal.mag.calibrate import MagSettings
    from imucal.model.parameters import Parameter

    acc = np.tile([0.0, 0.0, 9.81], (10, 1))
    cases = [
        (lambda: imucal.calibrate(acc, t=np.zeros(10)), "t: t must be N finite", "or drop t and give fs"),
        (lambda: imucal.calibrate(acc[:, :2], fs=100.0), "acc: acc must be an (N, 3) array", "three readings"),
        (lambda: counts_run.calibration.apply(np.zeros((4, 2))), "raw: raw data must have shape", "per sample"),
        (lambda: compute_error_map([1.5, 1.6]), "angles: need 3 angles", "in radians"),
        (lambda: MagSettings(window=2), "mag.window", "4 or more"),
        (lambda: Parameter("s1", 0.0, lower=1.0, upper=-1.0), "parameters.s1: lower bound", "at or below"),
    ]
    for call, where, fix in cases:
        with pytest.raises(ImucalError) as ei:
            call()
        text = str(ei.value)
        assert where in text and "(fix: " in text and fix in text, text


@pytest.mark.parametrize("args, words", [
    (["error-map", "--angles", "1", "2", "3", "--out", "o", "--bins", "x"],
     "argument --bins: invalid int value: 'x' (fix: give --bins a whole number)"),
    (["worst-case", "--widen", "x"], "argument --widen: invalid float value: 'x' (fix: give --widen a number"),
    (["error-map", "--angles", "1", "2"], "argument --angles: expected 3 arguments (fix: give --angles 3 values"),
    (["calibrate", "--data"], "argument --data: expected one argument (fix: give --data a value after it)"),
    (["error-map", "--out", "o"], "the following arguments are required: --angles (fix: add --angles)"),
    (["calibrate", "--bogus"], "unrecognized arguments: --bogus (fix: `imucal COMMAND --help` lists the options"),
])
def test_a_refused_command_line_says_what_to_do(run_cli, args, words):
    """argparse's own refusals (a word for a number, a missing value or option, an unknown option) had no fix."""
    r = run_cli(args)
    assert r.code == 2 and r.err.count("\n") == 1 and "Traceback" not in r.err, r
    assert words in r.err, r.err
