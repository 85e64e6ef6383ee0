"""Issue 25 (outside audit): exported text, injection, and files that must read back.

Every exported text format is parsed back here by its consumer's rules, written from the
consumers' sources (not from imucal.export): ArduPilot's .param as Mission Planner and MAVProxy
read it (lines, '#' comments, NAME,VALUE or NAME VALUE) and as the firmware's defaults-file reader
reads it (AP_Param.cpp: fgets into char line[100], so 98 characters at a time; a line not starting
with '#' is tokenised on ", =\\t\\r\\n"); PX4's as QGroundControl reads it (lines, '#', five tab-
separated fields); YAML by yaml.safe_load; JSON by json.loads; the matrix CSV as numpy reads it.
A hypothesis property puts hostile text (line breaks of every kind, NUL, quotes, comment
delimiters, separators, surrogates, very long) in every text field that reaches an export.
Also: ArduPilot/PX4 refuse or convert units their m/s^2 parameters cannot hold; a unit is refused
where it enters, by the reader's own rule; a calibration file's gravity, standard errors and
YAML 1.1 numbers; codegen prefixes that name a system header.
"""
from __future__ import annotations

import dataclasses
import functools
import json
import math
import re
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings, strategies as st

from conftest import write_simulation
from imucal.analysis.simulate import cube_directions, mems_counts_sensor, si_sensor
from imucal.calibration.fileformat import GRAVITY_MAX, GRAVITY_MIN, to_dict
from imucal.calibration.frozen import from_dict, load_calibration
from imucal.calibration.frozen import Calibration
from imucal.calibration.gyro import from_arrays
from imucal.constants import STANDARD_GRAVITY
from imucal.errors import ImucalError
from imucal.export.codegen import SYSTEM_HEADERS, generate_c
from imucal.export.formats import ExportOptions, KalibrNoise
from imucal.export.registry import FORMATS, export
from imucal.model.effects import make_effect
from imucal.model.gravity import normal_gravity
from imucal.model.parameters import base_parameters

AP_SEPARATORS = ", =\t\r\n"  # AP_Param::parse_param_line's strtok delimiters
AP_CHUNK = 98  # fgets(line, sizeof(line) - 1) with char line[100]: 98 characters per read


def one_line_error(err: str, *parts: str) -> None:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("imucal: error: "), err
    for p in parts:
        assert p in lines[0], (p, lines[0])
    assert "Traceback" not in err


# --- the consumers' readers ---------------------------------------------------------------------
def ardupilot_gcs_params(text: str) -> dict[str, float]:
    """Mission Planner / MAVProxy: every line (any line break Python knows), '#' comments,
    NAME,VALUE or NAME VALUE; anything else is an error here (they would skip or misread it)."""
    out = {}
    for ln in text.splitlines():
        ln = ln.strip()
        if not ln or ln.startswith("#"):
            continue
        parts = re.split(r"[,\s]+", ln)
        assert len(parts) == 2, ln
        assert parts[0] not in out
        out[parts[0]] = float(parts[1])
    return out


def ardupilot_firmware_params(text: str) -> dict[str, float]:
    """AP_Param::read_param_defaults_file: 98-character reads of the bytes, '#' at the start of a
    read skips it, else the first two tokens on ", =\\t\\r\\n" are NAME and VALUE."""
    out = {}
    for line in text.encode("utf-8", "surrogateescape").split(b"\n"):
        line += b"\n"
        for i in range(0, len(line), AP_CHUNK):
            chunk = line[i:i + AP_CHUNK].decode("ascii")  # every exported byte is ASCII
            if chunk.startswith("#"):
                continue
            tokens = [t for t in re.split(f"[{re.escape(AP_SEPARATORS)}]", chunk) if t]
            if len(tokens) >= 2:
                out[tokens[0]] = float(tokens[1])
    return out


def px4_params(text: str) -> dict[str, float]:
    """QGroundControl's parameter file: '#' comments, else vehicle, component, name, value, type."""
    out = {}
    for ln in text.splitlines():
        if not ln or ln.startswith("#"):
            continue
        f = ln.split("\t")
        assert len(f) == 5 and f[0] == f[1] == "1", ln
        out[f[2]] = float(f[3])
    assert text.split("\n")[:-1] == text.splitlines()  # no line break but \n: every reader sees these lines
    return out


def csv_rows(text: str) -> list[list[float]]:
    rows = [ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    assert text.split("\n")[:-1] == text.splitlines()
    return [[float(x) for x in r.split(",")] for r in rows]


def parsed(fmt: str, name: str, text: str):
    """The exported file as its consumer reads it."""
    if fmt == "ardupilot":
        gcs, fw = ardupilot_gcs_params(text), ardupilot_firmware_params(text)
        assert gcs == fw and all(len(ln) < AP_CHUNK for ln in text.split("\n"))
        return gcs
    if fmt == "px4":
        return px4_params(text)
    if fmt == "kalibr":
        return yaml.safe_load(text)
    if fmt == "imutk":
        return [float(x) for x in text.split()]
    return csv_rows(text) if name.endswith(".csv") else json.loads(text)


# --- calibrations with text in every field ------------------------------------------------------
def calibration(unit: str = "m/s^2", gyro_unit: str = "LSB", thermal: bool = True, file: str = "plain.csv",
                created: str = "2024-05-01T12:00:00+00:00") -> Calibration:
    """A misaligned sensor reading ``unit`` (m/s^2, g or mg scaled alike), a gyroscope (in counts:
    the autopilots' offsets then take the sensitivity that fits, whatever the unit's name), and a
    temperature bias term over 15..45 degC: every comment an export writes is written."""
    c = {"m/s^2": 1.0, "g": 1 / STANDARD_GRAVITY, "mg": 1000 / STANDARD_GRAVITY}.get(unit, 1.0)
    s, b = [c * v for v in (0.12, -0.07, 0.04)], [c * v for v in (1.012, 0.993, 1.004)]
    angles = (1.556, 1.585, 1.562)
    params = base_parameters(s, b, angles, raw_unit=unit)
    effects = (("bias_temperature", (0, 1, 2)),) if thermal else ()
    for name, axes in effects:
        params = params.extended(make_effect(name, axes).parameters(params))
    params = params.with_values({"bias_temperature_x": 2e-3 * c, "bias_temperature_y": -1e-3 * c,
                                 "bias_temperature_z": 5e-4 * c, "bias_temperature_tref": 30.0} if thermal else {})
    f = {"rad/s": 1.0, "deg/s": 180 / math.pi}.get(gyro_unit, 1000.0)
    gv = {"bias": np.array([0.02, -0.013, 0.007]) * f, "scale": np.array([1.013, 0.987, 1.004]) * f,
          "misalignment": np.array([[1.0, 0.012, -0.02], [0.008, 1.0, 0.015], [-0.011, 0.025, 1.0]]),
          "gsens": np.array([[2e-4, -1e-4, 3e-4], [1e-4, 4e-4, -2e-4], [-3e-4, 2e-4, 1e-4]])}
    gyro = from_arrays(unit=gyro_unit, std={k: np.zeros_like(v) for k, v in gv.items()}, **gv)
    return Calibration(params=params, std={n: 0.01 for n in params.names}, gravity=9.80665, raw_unit=unit,
                       effects=effects, fit={"temperature_range": [15.0, 45.0]} if thermal else {},
                       data={"file": file}, created=created, attached=(gyro,))


#: (format, file name) of every export, the matrix twice (JSON and CSV).
EXPORTS = [(f, {"imutk": "x.calib", "madlab": "x.json", "matrix": "x.json", "kalibr": "imu.yaml",
                "ardupilot": "x.param", "px4": "x.params"}[f]) for f in FORMATS] + [("matrix", "x.csv")]
NOISE = KalibrNoise(0.002, 4e-5, 100.0, "the longest still interval", 1e-4, None)

#: Pieces of hostile text: every line break a reader knows, NUL, quotes, comment delimiters and
#: separators of the formats, a live parameter line, YAML structure, a surrogate, long text.
PIECES = ["\n", "\r", "\r\n", "\v", "\f", "\x1c", "\x85", "\u2028", "\u2029", "\x00", "\t", "'", '"', "*/", "/*",
          "#", ",", " ", "=", "\\", "ARMING_CHECK,0", "ARMING_CHECK 0", "INS_ACCSCAL_X 0", "key: value", "---",
          "...", "- x", "{a: 1}", "&a", "*a", "\udcff", "\ufeff", "é", "x" * 300, "y" * 5000]
HOSTILE = st.lists(st.sampled_from(PIECES) | st.text(max_size=4), min_size=1, max_size=8).map("".join)


@pytest.mark.parametrize("value", ["=...", "\\...", "/imu...", "...", "a\n...", "x..."])
def test_yaml_flow_keeps_a_value_that_ends_in_three_dots(value):
    """yaml_flow cut PyYAML's document end marker with removesuffix("..."), which also cut the value's own: a
    Kalibr rostopic "/imu..." was written as "/imu", and "=..." as "=", which YAML refuses (hypothesis found it)."""
    from imucal.export.escape import yaml_flow

    text = yaml_flow(value)
    assert "\n" not in text and yaml.safe_load(f"rostopic: {text}") == {"rostopic": value}


@functools.lru_cache(maxsize=None)
def clean_export(thermal: bool, fmt: str, name: str) -> str:
    return export(calibration(thermal=thermal), fmt, ExportOptions(filename=name, noise=NOISE)).text


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(file=HOSTILE, created=HOSTILE, unit=HOSTILE, gyro_unit=HOSTILE, topic=HOSTILE, segment=HOSTILE,
       thermal=st.booleans())
def test_hostile_text_in_every_field_never_changes_what_the_consumer_reads(file, created, unit, gyro_unit, topic,
                                                                           segment, thermal):
    """Each export, with hostile text in every field, reads back to exactly what the same export
    with plain text reads to (the parameters, keys and numbers), or is refused in one line."""
    clean = calibration(thermal=thermal)
    opts = ExportOptions(rostopic=topic, noise=dataclasses.replace(NOISE, segment=segment))
    texts = dataclasses.replace(clean, data={"file": file}, created=created,
                                attached=(dataclasses.replace(clean.gyro, raw_unit=gyro_unit),))
    for bad in (texts, dataclasses.replace(texts, raw_unit=unit)):
        for fmt, name in EXPORTS:
            want = parsed(fmt, name, clean_export(thermal, fmt, name))
            try:
                got = parsed(fmt, name, export(bad, fmt, dataclasses.replace(opts, filename=name)).text)
            except ImucalError as exc:  # a unit an autopilot cannot hold: refused by name
                assert fmt in ("ardupilot", "px4") and exc.field == "units.input" and "\n" not in str(exc)
                continue
            if fmt == "kalibr":
                assert got.pop("rostopic") == topic and want.pop("rostopic") == "/imu0"
            if fmt == "madlab":  # text fields of its own: held as given
                assert got.pop("from_acc_unit") == bad.raw_unit and got.pop("from_gyr_unit") == gyro_unit
                assert got.pop("comment") == want.pop("comment").replace("[LSB per", f"[{gyro_unit} per")
                want.pop("from_acc_unit"), want.pop("from_gyr_unit")
            if fmt == "matrix" and name.endswith(".json"):
                assert got.pop("input_unit") == bad.raw_unit and want.pop("input_unit") == clean.raw_unit
                assert got["gyroscope"].pop("input_unit") == gyro_unit
                want["gyroscope"].pop("input_unit")
            assert got == want, (fmt, name)


@settings(max_examples=60, deadline=None)
@given(file=HOSTILE)
def test_a_calibration_file_with_any_recording_name_reads_back(tmp_path_factory, file):
    cal = calibration(file=file)
    p = tmp_path_factory.mktemp("cal") / "calibration.yaml"
    cal.save(p)
    back = load_calibration(p)
    assert back.data["file"] == file and set(yaml.safe_load(p.read_text())) == set(to_dict(cal))


def test_injected_recording_name_from_calibrate_to_every_export(run_cli, tmp_path):
    """The audit's file name: a live ARMING_CHECK line in ArduPilot's and PX4's files, a new
    top-level key in Kalibr's; now the same parameters and keys as any other name gives."""
    name = "log\nARMING_CHECK,0\n#.csv"
    rec = write_simulation(tmp_path / name, si_sensor(np.random.default_rng(3)), cube_directions(), seed=8)
    r = run_cli(["calibrate", "--data", rec.path, "--unit", "m/s^2", "--out", tmp_path / "cal", "--no-figures"])
    assert r.code == 0, r.err
    cal = tmp_path / "cal" / "calibration.yaml"
    assert load_calibration(cal).data["file"] == name
    for fmt, out in EXPORTS:
        r = run_cli(["export", cal, "--format", fmt, "--out", tmp_path / out])
        assert r.code == 0, r.err
        text = (tmp_path / out).read_text()
        got = parsed(fmt, out, text)
        assert "ARMING_CHECK" not in json.dumps(got)
        if fmt in ("ardupilot", "px4", "kalibr"):  # the name is shown, escaped
            assert "log\\nARMING_CHECK,0\\n#.csv" in text
    assert set(parsed("kalibr", "imu.yaml", (tmp_path / "imu.yaml").read_text())) == {
        "accelerometer_noise_density", "accelerometer_random_walk", "gyroscope_noise_density",
        "gyroscope_random_walk", "rostopic", "update_rate", "model", "accelerometers", "gyroscopes",
        "imucal_accelerometer_offset"}


def test_ardupilot_comments_fit_the_firmware_reader_and_ordinary_files_keep_their_text():
    """Lines of at most 97 characters (98 with the newline, one fgets): the text is the same words."""
    cal = calibration()
    text = export(cal, "ardupilot").text
    assert max(len(ln) for ln in text.splitlines()) <= AP_CHUNK - 1
    words = " ".join(ln[2:] for ln in text.splitlines() if ln.startswith("# "))
    assert "from a calibration of plain.csv (2024-05-01T12:00:00+00:00)" in words
    assert all(f"NOTE: {n}." in words for n in export(cal, "ardupilot").notes)
    # PX4, Kalibr and the matrix CSV keep their lines as they were: one comment per line
    assert "# PX4 accelerometer and gyroscope calibration (QGroundControl parameter file), exported by imucal" in \
        export(cal, "px4").text


# --- units: what an autopilot's m/s^2 parameters can hold -----------------------------------------
def ardupilot_apply(params: dict[str, float], reading: np.ndarray) -> np.ndarray:
    """AP_InertialSensor_Backend::_rotate_and_correct_accel: accel -= offset; accel *= scale, on the
    driver's reading in m/s^2 (no temperature terms)."""
    off = np.array([params[f"INS_ACCOFFS_{a}"] for a in "XYZ"])
    return (reading - off) * np.array([params[f"INS_ACCSCAL_{a}"] for a in "XYZ"])


def px4_apply(params: dict[str, float], reading: np.ndarray) -> np.ndarray:
    """PX4 Accelerometer.hpp Correct(): (data - offset) .* scale, data in m/s^2."""
    off = np.array([params[f"CAL_ACC0_{a}OFF"] for a in "XYZ"])
    return (reading - off) * np.array([params[f"CAL_ACC0_{a}SCALE"] for a in "XYZ"])


def orthogonal(cal: Calibration) -> Calibration:
    return dataclasses.replace(cal, params=cal.params.with_values({a: math.pi / 2 for a in ("phi", "psi", "theta")}))


@pytest.mark.parametrize("unit, per_unit", [("m/s^2", 1.0), ("g", STANDARD_GRAVITY), ("mg", STANDARD_GRAVITY / 1000)])
@pytest.mark.parametrize("fmt", ["ardupilot", "px4"])
def test_readings_in_g_or_mg_are_converted_to_the_drivers_m_per_s2(unit, per_unit, fmt):
    """With orthogonal axes the diagonal model is exact: the autopilot's formula on the driver's
    reading (raw x 9.80665 for g) gives imucal's acceleration."""
    cal = orthogonal(calibration(unit, thermal=False))
    raw = np.random.default_rng(1).normal(0.0, 1.0, (200, 3)) * cal.values[3:6] * 9.8 + cal.values[0:3]
    p = parsed(fmt, "x", export(cal, fmt).text)
    got = (ardupilot_apply if fmt == "ardupilot" else px4_apply)(p, raw * per_unit)
    np.testing.assert_allclose(got, cal.apply(raw), rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("unit", ["g", "mg"])
def test_temperature_terms_are_converted_too(unit):
    from test_export_tempcal import ardupilot_apply as ap_thermal, px4_apply as px4_thermal

    cal = orthogonal(calibration(unit))  # the diagonal model holds it: exact
    per_unit = {"g": STANDARD_GRAVITY, "mg": STANDARD_GRAVITY / 1000}[unit]
    rng = np.random.default_rng(2)
    raw = rng.normal(0.0, 1.0, (300, 3)) * cal.values[3:6] * 9.8 + cal.values[0:3]
    temps = rng.uniform(15.0, 45.0, 300)
    ours = cal.apply(raw, {"temp": temps})
    cal_si = orthogonal(calibration("m/s^2"))  # the same sensor read in m/s^2: the same file
    for fmt, peer in (("ardupilot", ap_thermal), ("px4", px4_thermal)):
        theirs = peer(export(cal, fmt).text, raw * per_unit, temps)
        assert np.abs(theirs - ours).max() <= 1e-9 * np.abs(ours).max()
        a, b = parsed(fmt, "x", export(cal, fmt).text), parsed(fmt, "x", export(cal_si, fmt).text)
        assert a.keys() == b.keys() and np.allclose(list(a.values()), list(b.values()), rtol=1e-12, atol=1e-15)


def test_counts_calibration_is_refused_by_the_autopilots_naming_the_unit(run_cli, tmp_path, unchanged):
    """The audit: INS_ACCOFFS_X,33123.85 with exit 0. A counts calibration labelled 'raw' (the
    default) or 'counts' is refused; the formats that hold any unit still export. Labelled, wrongly, 'm/s^2', its
    readings at rest (16540) are refused by calibrate already (imucal.analysis.rest.stated_unit_error)."""
    rec = write_simulation(tmp_path / "c.csv", mems_counts_sensor(np.random.default_rng(4)), cube_directions(),
                           seed=5)
    with unchanged():
        r = run_cli(["calibrate", "--data", rec.path, "--unit", "m/s^2", "--out", tmp_path / "si", "--no-figures"])
    assert r.code == 2
    one_line_error(r.err, f"{rec.path}: data.unit: the readings at rest are ", "where readings in m/s^2 are 9.80665: "
                   "they are not in m/s^2", "(fix: give data.unit raw for counts)")
    for label, words in (("raw", "the input unit is not stated ('raw'), and read as m/s^2 it gives offsets"),
                         ("counts", "input unit 'counts' is not an acceleration unit")):
        out = tmp_path / label.replace("/", "_")
        r = run_cli(["calibrate", "--data", rec.path, "--unit", label, "--out", out, "--no-figures"])
        assert r.code == 0, r.err
        cal = out / "calibration.yaml"
        for fmt, name in (("ardupilot", "x.param"), ("px4", "x.params")):
            with unchanged():
                r = run_cli(["export", cal, "--format", fmt, "--out", tmp_path / name])
            assert r.code == 2
            one_line_error(r.err, f"{cal}: units.input: ", words, "(fix: calibrate readings in m/s^2 or g",
                           "--format matrix or imutk")
        assert run_cli(["export", cal, "--format", "matrix", "--out", tmp_path / "m.json"]).code == 0


def test_unstated_unit_with_m_per_s2_numbers_still_exports_and_says_so():
    cal = dataclasses.replace(calibration(thermal=False), raw_unit="raw")
    out = export(cal, "ardupilot")
    assert any("input unit is 'raw', so these numbers reproduce it only on readings in raw" in n for n in out.notes)


# --- a unit is refused where it enters, by the reader's rule -------------------------------------
@pytest.mark.parametrize("unit", ["m/s$^2$", "x" * 5000, "m/s^2\nARMING_CHECK", "a//b", "m/s²", "<b>LSB</b>",
                                  "x" * 33])
def test_calibrate_refuses_a_unit_its_readers_would_refuse(run_cli, tmp_path, unchanged, unit):
    rec = write_simulation(tmp_path / "s.csv", si_sensor(np.random.default_rng(6)), cube_directions(), seed=6)
    with unchanged():
        r = run_cli(["calibrate", "--data", rec.path, "--unit", unit, "--out", tmp_path / "o"])
    assert r.code == 2
    one_line_error(r.err, "data.unit: ",
                   "is not a unit (letters, digits, ^ . % ( ) / - space; at most 32, not ending in /)",
                   "(fix: write e.g. counts, m/s^2 or g)")
    (tmp_path / "run.yaml").write_text(yaml.safe_dump({"data": {"path": "s.csv", "unit": unit}}))
    with unchanged():
        r = run_cli(["calibrate", tmp_path / "run.yaml", "--out", tmp_path / "o"])
    assert r.code == 2 and "data.unit: " in r.err


@pytest.mark.parametrize("unit", ["m/s$^2$", "<b>LSB</b>", "m/"])
def test_simulate_refuses_a_unit_calibrate_would_refuse(run_cli, tmp_path, unchanged, unit):
    cfg = tmp_path / "sim.yaml"
    cfg.write_text(yaml.safe_dump({"sensor": {"unit": unit}}))
    with unchanged():
        r = run_cli(["simulate", cfg, "--out", tmp_path / "sim.csv"])
    assert r.code == 2
    one_line_error(r.err, f"{cfg}: sensor.unit: ", "is not a unit")


@settings(max_examples=200, deadline=None)
@given(unit=st.text(max_size=45) | st.sampled_from(["m/s^2", "g", "counts", "LSB", "m/s$^2$", "a//b", "m/", "x" * 32,
                                                    "x" * 33, "x" * 41]))
def test_the_option_and_the_file_take_the_same_units(unit):
    """data.unit is accepted exactly when a calibration file with that unit loads."""
    from imucal.data.spec import DataSpec

    try:
        DataSpec(path="x.csv", unit=unit)
        entered = True
    except ImucalError:
        entered = False
    d = to_dict(calibration(thermal=False))
    d["units"]["input"] = unit
    for n in ("s1", "s2", "s3"):
        d["parameters"][n]["unit"] = unit
    d["parameters"].update({n: {**d["parameters"][n], "unit": f"{unit}/(m/s^2)"} for n in ("b1", "b2", "b3")})
    try:
        from_dict(d)
        loads = True
    except ImucalError:
        loads = False
    assert entered == loads


# --- a calibration file's gravity, standard errors and numbers -----------------------------------
def cal_text(tmp_path: Path, edit) -> Path:
    d = to_dict(calibration(thermal=False))
    edit(d)
    p = tmp_path / "cal.yaml"
    p.write_text(yaml.safe_dump(d, sort_keys=False))
    return p


@pytest.mark.parametrize("edit, field, words", [
    (lambda d: d.update(gravity=588.0), "gravity",
     "gravity 588.0 is not a local gravity on Earth in m/s^2 (9.4 to 9.9)"),
    (lambda d: d.update(gravity=9.3), "gravity", "gravity 9.3 is not a local gravity"),
    (lambda d: d.update(gravity=float("nan")), "gravity", "gravity is not finite"),
    (lambda d: d["parameters"]["s2"].update(std=-0.01), "parameters.s2.std", "-0.01 is not a standard error"),
    (lambda d: d["parameters"]["b1"].update(std=float("nan")), "parameters.b1.std", "std is not finite"),
    (lambda d: d["parameters"]["phi"].update(value=float("nan")), "parameters.phi.value", "value is not finite"),
    (lambda d: d["gyroscope"]["parameters"]["bias_y"].update(std=-1e-3), "gyroscope.parameters.bias_y.std",
     "is not a standard error"),
    (lambda d: d.update(created="2024-05-01\n12:00:00"), "created", "is not an ISO 8601 date"),
])
@pytest.mark.parametrize("command", ["export", "codegen", "apply"])
def test_bad_numbers_in_a_calibration_file_are_refused_by_every_reader(run_cli, tmp_path, unchanged, edit, field,
                                                                       words, command):
    p = cal_text(tmp_path, edit)
    (tmp_path / "d.csv").write_text("t,ax,ay,az\n0,0,0,9.8\n")
    args = {"export": ["--format", "kalibr", "--out", tmp_path / "x.yaml"], "codegen": ["--out", tmp_path / "gen"],
            "apply": ["--data", tmp_path / "d.csv", "--out", tmp_path / "o.csv"]}[command]
    with unchanged():
        r = run_cli([command, p, *args])
    assert r.code == 2
    one_line_error(r.err, f"{p}: {field}: ", words)


def test_sexagesimal_gravity_is_refused_not_read_as_588(run_cli, tmp_path, unchanged):
    """YAML 1.1 reads 9:48 as 9 * 60 + 48 = 588; here it stays text, which a number field refuses."""
    text = yaml.safe_dump(to_dict(calibration(thermal=False)), sort_keys=False)
    p = tmp_path / "cal.yaml"
    p.write_text(re.sub(r"^gravity: .*$", "gravity: 9:48", text, flags=re.M))
    assert yaml.safe_load(p.read_text())["gravity"] == 588  # what plain safe_load makes of it
    with unchanged():
        r = run_cli(["export", p, "--format", "kalibr", "--out", tmp_path / "x.yaml"])
    assert r.code == 2
    one_line_error(r.err, f"{p}: gravity: gravity '9:48' is not a local gravity")
    p.write_text(re.sub(r"^gravity: .*$", "gravity: !!float 9:48.0", text, flags=re.M))
    with unchanged():
        r = run_cli(["export", p, "--format", "kalibr", "--out", tmp_path / "x.yaml"])
    one_line_error(r.err, "'9:48.0' at line", "is a YAML 1.1 base-60 number (fix: write the number in decimal)")


@pytest.mark.parametrize("text, field", [("gravity: {value: 9:48}", "gravity.value"),
                                         ("static: {window: 0:30}", "static.window"),
                                         ("data: {path: s.csv, skip_rows: 010}", "data.skip_rows")])
def test_no_run_file_number_is_read_in_base_60_or_octal(run_cli, tmp_path, unchanged, text, field):
    (tmp_path / "s.csv").write_text("t,ax,ay,az\n0,0,0,9.8\n")
    (tmp_path / "run.yaml").write_text(("data: {path: s.csv}\n" if not text.startswith("data") else "") + text + "\n")
    with unchanged():
        r = run_cli(["calibrate", tmp_path / "run.yaml", "--out", tmp_path / "o"])
    assert r.code == 2
    one_line_error(r.err, f"{field}: ")


def test_fleet_csv_cells_read_numbers_as_files_do(tmp_path):
    from imucal.fleet.manifest import load_manifest

    (tmp_path / "a.csv").write_text("t,ax,ay,az\n0,0,0,9.8\n")
    m = tmp_path / "units.csv"
    m.write_text("unit,data,gravity.value\nU1,a.csv,9.81\n")
    assert load_manifest(m).units[0].config.gravity.value == 9.81
    m.write_text("unit,data,gravity.value\nU1,a.csv,9:48\n")
    with pytest.raises(ImucalError, match="gravity"):
        load_manifest(m)


def test_the_gravity_bound_admits_every_gravity_calibrate_writes():
    from imucal.config.run import GravitySpec

    assert GRAVITY_MIN <= normal_gravity(0.0, 99_999.0) and normal_gravity(90.0, -9_999.0) <= GRAVITY_MAX
    for g in (9.7001, 9.8999):
        GravitySpec(value=g)  # the run's own range, inside the file's
        assert GRAVITY_MIN <= g <= GRAVITY_MAX
    with pytest.raises(ImucalError):
        GravitySpec(value=GRAVITY_MAX + 0.001)


# --- codegen prefixes ---------------------------------------------------------------------------
@pytest.mark.parametrize("prefix, where", [("stdio", "the C standard library"), ("STDIO", "the C standard library"),
                                           ("math", "the C standard library"), ("unistd", "POSIX"),
                                           ("Wire", "Arduino"), ("arduino", "Arduino")])
@pytest.mark.parametrize("layout", ["flat", "arduino"])
def test_codegen_refuses_a_prefix_that_names_a_system_header(run_cli, tmp_path, unchanged, prefix, where, layout):
    p = tmp_path / "cal.yaml"
    calibration(thermal=False).save(p)
    with unchanged():
        r = run_cli(["codegen", p, "--out", tmp_path / "gen", "--prefix", prefix, "--layout", layout])
    assert r.code == 2
    one_line_error(r.err, f"prefix: '{prefix}' would write {prefix}.h, a header of {where}",
                   f"(fix: choose another prefix, e.g. imucal_{prefix})")
    with pytest.raises(ImucalError, match="a header of"):
        generate_c(calibration(thermal=False), prefix=prefix)
    assert run_cli(["codegen", p, "--out", tmp_path / "gen", "--prefix", f"imucal_{prefix}",
                    "--layout", layout]).code == 0


def test_every_listed_header_is_a_name_a_prefix_could_take():
    """The list holds header names a C identifier can spell (others cannot collide)."""
    names = [n for ns in SYSTEM_HEADERS.values() for n in ns]
    assert all(re.fullmatch(r"[A-Za-z][A-Za-z0-9_]*", n) for n in names) and len(names) == len(set(names))
