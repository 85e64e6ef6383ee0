"""Issue 9, trust in the data layer: time unit, column layout, corrupt values, clipped axes.

Complements tests/test_trust.py: here every real recording in ../shared/data/real (accelerometer
and gyroscope files, counts and m/s^2) must raise no alarm untouched, and every one with two or
more poses must have a pose pushed onto a rail caught, on each axis and each side. Messages are
checked word for word; hypothesis feeds the loader numeric-looking text.
"""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from conftest import real_file, write_simulation
from imucal.data.load import load_recording
from imucal.data.spec import DataSpec, parse_columns, rails
from imucal.errors import ImucalError
from imucal.analysis.simulate import cube_directions, mems_counts_sensor
from imucal.data.static import detect_static

# (folder..., file), extra DataSpec fields: every recording in ../shared/data/real.
ACC = [
    (("xsens-mti-imutk", "xsens_acc.mat"), {}),
    (("mpu6050-tomisuarez", "example_data_calibration.csv"), {"sample_rate": 100.0}),
    (("imucal-ferraris", "annotated_session.csv"),
     {"sample_rate": 204.8, "columns": {"ax": "acc_x", "ay": "acc_y", "az": "acc_z"}}),
    (("imucal-ferraris", "example_ferraris_session.csv"), {"sample_rate": 102.4}),
] + [(("ros-imu-getovermassif", f"data{i}", "acc_data.txt"), {}) for i in (1, 2, 3, 4)]
OTHER = [
    (("xsens-mti-imutk", "xsens_gyro.mat"), {}),
    (("mpu6050-tomisuarez", "example_data_tinit_calc.csv"), {"sample_rate": 100.0}),  # one pose
] + [(("ros-imu-getovermassif", f"data{i}", "gyro_data.txt"), {}) for i in (1, 2, 3, 4)]


def ids(case) -> str:
    return "/".join(case[0])


def load(case) -> "object":
    parts, extra = case
    return load_recording(DataSpec(path=str(real_file(*parts)), **extra))


def one_line(exc: ImucalError, *parts: str) -> str:
    msg = str(exc)
    assert "\n" not in msg
    for p in parts:
        assert p in msg, (p, msg)
    return msg


# --- untouched recordings: no false inference, no false alarm ----------------------------------
@pytest.mark.parametrize("case", ACC + OTHER, ids=ids)
def test_untouched_real_recording_raises_no_alarm(case):
    rec = load(case)
    assert rec.time_unit == "s"
    if "sample_rate" in case[1]:
        assert rec.time_note == f"no time column: {case[1]['sample_rate']:g} Hz given" and rec.t_source is None
    else:
        assert rec.time_note.startswith("time unit inferred: s (median step 0.0")
        assert rec.time_note.endswith(" -> 100 Hz)")
    iv = detect_static(rec.t, rec.raw)
    assert iv.n >= 1 and iv.meta["dropped"] == [] and iv.meta["saturation"] == {}


@pytest.mark.parametrize("noise", [0.3, 1.0])
def test_quiet_counts_sensor_raises_no_alarm(tmp_path, noise):
    """Counts with noise at or below 1 LSB: the pose at an axis's extreme sits on few values."""
    sensor = mems_counts_sensor(np.random.default_rng(11), noise_counts=noise)
    r = write_simulation(tmp_path / "q.csv", sensor, cube_directions("faces+edges"), seed=12)
    rec = load_recording(r.path)
    iv = detect_static(rec.t, rec.raw)
    assert iv.n == 18 and iv.meta["dropped"] == []


# --- clipping injected into every real recording with poses -----------------------------------
@pytest.mark.parametrize("case", ACC, ids=ids)
def test_pose_pushed_onto_a_rail_is_dropped_on_every_axis_and_side(case):
    """Clip each axis 3 standard deviations inside its extreme pose (the pose sits on the rail,
    as a +-2 g part does beyond 2 g): that pose, and only clipped ones, must be dropped."""
    rec = load(case)
    iv = detect_static(rec.t, rec.raw)
    if iv.n < 2:
        pytest.skip("a single pose")
    for j, axis in enumerate("xyz"):
        for side in ("high", "low"):
            i = int(np.argmax(iv.mean[:, j]) if side == "high" else np.argmin(iv.mean[:, j]))
            sign = 1.0 if side == "high" else -1.0
            rail = iv.mean[i, j] - sign * 3.0 * iv.std[i, j]
            if np.all(rec.raw == np.round(rec.raw)):
                rail = float(np.round(rail))
            raw = rec.raw.copy()
            raw[:, j] = np.minimum(raw[:, j], rail) if side == "high" else np.maximum(raw[:, j], rail)
            seg = raw[iv.start[i]:iv.end[i], j]
            assert abs(seg.mean() - iv.mean[i, j]) > 2.5 * iv.std[i, j]  # the clip matters
            got = detect_static(rec.t, raw)
            drops = got.meta["dropped"]
            assert drops, (axis, side)
            assert {(d["axis"], d["side"], d["rail"]) for d in drops} == {(axis, side, rail)}
            assert got.meta["saturation"] == {axis: {"low": rail if side == "low" else None,
                                                     "high": rail if side == "high" else None,
                                                     "source": "detected"}}
            assert any(d["t_start"] <= rec.t[(iv.start[i] + iv.end[i]) // 2] <= d["t_end"] for d in drops)
            assert got.n == iv.n - len(drops)
            for d in drops:  # H4's contract: these keys, times in seconds, a reason in words
                assert {"t_start", "t_end", "axis", "rail", "reason"} <= set(d)
                assert d["reason"] == f"axis {axis} at its {side} rail {rail:g} (detected)"


def _unsigned_xsens(tmp_path) -> tuple[np.ndarray, object]:
    """The Xsens log shifted so that its lowest x pose lies 60 counts below 0 and its highest z
    pose 60 counts above 65535, then clipped to 0..65535 (an unsigned 16-bit sensor)."""
    d = np.loadtxt(real_file("xsens-mti-imutk", "xsens_acc.mat"))
    rec = load_recording(real_file("xsens-mti-imutk", "xsens_acc.mat"))
    iv = detect_static(rec.t, rec.raw)
    d[:, 1] -= np.round(iv.mean[:, 0].min()) + 60
    d[:, 3] += 65535 + 60 - np.round(iv.mean[:, 2].max())
    d[:, 1:] = np.clip(d[:, 1:], 0, 65535)
    p = tmp_path / "unsigned.txt"
    np.savetxt(p, d, fmt=["%.6f", "%.0f", "%.0f", "%.0f"])
    return d, p


def test_unsigned_rails_0_and_65535_are_found(tmp_path):
    _, p = _unsigned_xsens(tmp_path)
    rec = load_recording(p)
    iv = detect_static(rec.t, rec.raw)
    sat = iv.meta["saturation"]
    assert sat["x"]["low"] == 0.0 and sat["z"]["high"] == 65535.0 and set(sat) == {"x", "z"}
    axes = {(d["axis"], d["rail"]) for d in iv.meta["dropped"]}
    assert axes == {("x", 0.0), ("z", 65535.0)}
    assert iv.n + len(iv.meta["dropped"]) == 38


def test_declared_unsigned_rails_drop_the_same_intervals(tmp_path):
    _, p = _unsigned_xsens(tmp_path)
    rec = load_recording(p)
    auto = detect_static(rec.t, rec.raw)
    declared = detect_static(rec.t, rec.raw, rails=rails({"low": 0, "high": 65535}))
    assert [d["t_start"] for d in declared.meta["dropped"]] == [d["t_start"] for d in auto.meta["dropped"]]
    assert all(d["reason"].endswith("(declared)") for d in declared.meta["dropped"])


def test_too_few_poses_after_dropping_says_why(run_cli, tmp_path, unchanged):
    """7 poses, 2 of them clipped: the remaining 5 are too few, and the refusal says clipping
    took the others."""
    dirs = np.vstack([cube_directions("faces"), [[0.6, 0.0, 0.8]]])
    sensor = mems_counts_sensor(np.random.default_rng(3))
    r = write_simulation(tmp_path / "seven.csv", sensor, dirs, seed=3)
    d = np.loadtxt(r.path, delimiter=",", skiprows=1)
    top = [d[a:b, 3].mean() for a, b in r.sim.hold_bounds]
    d[:, 3] = np.minimum(d[:, 3], np.round(sorted(top)[-2] - 30))  # the two highest z poses
    np.savetxt(r.path, d, delimiter=",", fmt=["%.6f", "%.0f", "%.0f", "%.0f"], header="t,ax,ay,az", comments="")
    with unchanged(tmp_path):
        code, out, err = run_cli(["calibrate", "--data", r.path, "--out", tmp_path / "o"])
    assert code == 2 and len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert "intervals: only 5 distinct orientations" in err
    assert "; 2 static interval(s) were dropped because an axis was clipped (axis z)" in err


# --- time unit -----------------------------------------------------------------------------------
@pytest.mark.parametrize("stamps, first, note", [
    (lambda t: np.round(t * 1e3) + 1700000000123, 1700000000123.0,
     "time unit inferred: ms (epoch time stamps; median step 10 ms -> 100 Hz)"),
    (lambda t: t * 1e3 + 123.0, 123.0, "time unit inferred: ms (median step 10 -> 100 Hz)"),
], ids=["epoch-ms", "float-ms"])
def test_millisecond_stamps_in_a_simulated_csv(tmp_path, counts_recording, stamps, first, note):
    d = np.loadtxt(counts_recording.path, delimiter=",", skiprows=1)
    ref = load_recording(counts_recording.path)
    d[:, 0] = stamps(d[:, 0])
    p = tmp_path / "ms.csv"
    np.savetxt(p, d, delimiter=",", fmt=["%.6f", "%.0f", "%.0f", "%.0f"], header="t,ax,ay,az", comments="")
    rec = load_recording(p)
    assert rec.time_unit == "ms" and rec.time_note == note
    assert rec.t_source[0] == first and np.array_equal(rec.t_source, np.loadtxt(p, delimiter=",", skiprows=1)[:, 0])
    np.testing.assert_allclose(rec.t, ref.t, atol=5.1e-4)
    a, b = detect_static(ref.t, ref.raw), detect_static(rec.t, rec.raw)
    np.testing.assert_array_equal(a.start, b.start)
    np.testing.assert_array_equal(a.end, b.end)


def test_two_plausible_units_name_the_one_assumed(tmp_path):
    p = tmp_path / "r.txt"
    p.write_text("".join(f"{0.5 * k:.1f} 1 2 3\n" for k in range(20)))  # 2 Hz in s, 2 kHz in ms
    rec = load_recording(p)  # issue 25: one rule for fractional and integer stamps (closest to 200 Hz)
    assert rec.time_unit == "ms"
    assert rec.time_note == ("time unit inferred: ms (median step 0.5 -> 2000 Hz; s would give 2 Hz: "
                             "give --time-unit if that is right)")
    p.write_text("".join(f"{k} 1 2 3\n" for k in range(20)))  # integer ticks: 1 Hz in s, 1 kHz in ms
    assert load_recording(p).time_unit == "ms"


def test_given_unit_with_an_implausible_rate_names_the_likely_one(tmp_path):
    p = tmp_path / "r.txt"
    p.write_text("".join(f"{123.0 + 10 * k:.1f} 1 2 3\n" for k in range(20)))
    with pytest.raises(ImucalError) as ei:
        load_recording(DataSpec(path=str(p), time_unit="s"))
    one_line(ei.value, "r.txt: data.time_unit: time in s gives 0.1 Hz, not an IMU sample rate (1 Hz to 100000 Hz)",
             "(fix: the time column looks like ms: give --time-unit ms (data.time_unit: ms))")


# --- specification values -----------------------------------------------------------------------
@pytest.mark.parametrize("kw, field, text", [
    ({"sample_rate": 10**400}, "data.sample_rate", "Hz is not an IMU rate"),
    ({"sample_rate": 1e-310}, "data.sample_rate", "sample rate 1e-310 Hz is not an IMU rate"),
    ({"sample_rate": 1e9}, "data.sample_rate", "sample rate 1000000000.0 Hz is not an IMU rate"),
    ({"saturation": {"low": 10**400}}, "data.saturation.low", "must be a finite number or [x, y, z]"),
    ({"saturation": {"high": [1, 2, float("nan")]}}, "data.saturation.high", "must be a finite number"),
    ({"delimiter": "ab"}, "data.delimiter", "delimiter 'ab' must be one character"),
    ({"skip_rows": 10**30}, "data.skip_rows", "must be a non-negative integer below 1e9"),
    ({"columns": {"ax": 1, "ay": 1}}, "data.columns", "two roles map to the same column"),
])
def test_bad_spec_values_are_one_line(kw, field, text):
    with pytest.raises(ImucalError) as ei:
        DataSpec(path="x.csv", **kw)
    assert ei.value.field == field
    one_line(ei.value, text)


@pytest.mark.parametrize("text, msg", [
    ("ax=123456", "--columns: column index '123456' for ax is out of range"),
    ("t=0,ax=1,ay=1", "--columns: roles ax and ay both map to column '1'"),
    ("ax=acc,az=acc", "--columns: roles ax and az both map to column 'acc'"),
    ("gx=1,gx=2", "--columns: role gx given twice"),
    ("temp=", "--columns: 'temp=' is not ROLE=COLUMN"),
])
def test_column_map_errors(text, msg):
    with pytest.raises(ImucalError) as ei:
        parse_columns(text)
    one_line(ei.value, msg)


def test_column_map_takes_gyro_roles_and_never_reads_unicode_digits_as_indices():
    assert parse_columns("t=0,gx=1,gy=2,gz=3,ax=4,ay=5,az=6") == {
        "t": 0, "gx": 1, "gy": 2, "gz": 3, "ax": 4, "ay": 5, "az": 6}
    assert parse_columns("ax=\u00b2,ay=\u0661,az=z") == {"ax": "\u00b2", "ay": "\u0661", "az": "z"}


@given(text=st.text(max_size=60))
@settings(max_examples=200, deadline=None)
def test_column_map_raises_only_imucal_errors(text):
    try:
        out = parse_columns(text)
    except ImucalError as exc:
        assert "\n" not in str(exc)
        return
    assert set(out) <= {"t", "ax", "ay", "az", "gx", "gy", "gz", "temp"}


# --- column layouts -------------------------------------------------------------------------------
def test_six_columns_without_header_suggest_the_mpu_layout(tmp_path):
    p = tmp_path / "six.txt"
    p.write_text("1 2 3 4 5 6\n7 8 9 10 11 12\n")
    with pytest.raises(ImucalError) as ei:
        load_recording(p)
    one_line(ei.value, "six.txt: data.columns: has 6 columns and no header: the layout is ambiguous "
             "(logs like the MPU-6050's hold ax ay az gx gy gz)", "--columns ax=0,ay=1,az=2")


def test_gyro_columns_before_the_accelerometer_by_name():
    """mad-lab-fau's session: n_samples, gyr_x..z, acc_x..z. The acc columns are found by name;
    gyr_* are not default gyro names (their sessions are concatenated segments, not one motion
    a gyroscope could be calibrated on), so the gyroscope is read only when mapped."""
    p = real_file("imucal-ferraris", "example_ferraris_session.csv")
    d = np.loadtxt(p, delimiter=",", skiprows=1)
    rec = load_recording(DataSpec(path=str(p), sample_rate=102.4))
    np.testing.assert_array_equal(rec.raw, d[:, 4:7])
    assert rec.gyro is None
    rec = load_recording(DataSpec(path=str(p), sample_rate=102.4,
                                  columns=parse_columns("gx=gyr_x,gy=gyr_y,gz=gyr_z")))
    np.testing.assert_array_equal(rec.raw, d[:, 4:7])
    np.testing.assert_array_equal(rec.gyro, d[:, 1:4])


def test_corrupt_value_in_a_used_column_names_its_line(tmp_path):
    p = tmp_path / "r.txt"
    p.write_text("0 1 2 3\n0.01 1 -1e300 3\n0.02 1 2 3\n")
    with pytest.raises(ImucalError) as ei:
        load_recording(p)
    one_line(ei.value, "r.txt: data: line 2 holds a value beyond +-1e+30 (corrupt)")


# --- fuzzing: numeric-looking text never escapes as another exception ---------------------------
_TOKENS = st.sampled_from(["0", "1", "-1", "0.01", "10", "123.0", "1700000000123", "1.7e18", "1e300",
                           "-1e31", "nan", "inf", "65535", "1e-310", "x", "t", "ax", "", "  "])
_LINE = st.lists(_TOKENS, min_size=1, max_size=8).flatmap(
    lambda toks: st.sampled_from([" ", ",", ";", "\t"]).map(lambda sep: sep.join(toks)))


@given(lines=st.lists(_LINE, min_size=1, max_size=40), rate=st.sampled_from([None, 100.0]),
       unit=st.sampled_from(["auto", "s", "ms", "ns"]))
@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
def test_numeric_text_raises_only_imucal_errors(tmp_path, lines, rate, unit):
    p = tmp_path / "f.txt"
    p.write_text("\n".join(lines) + "\n")
    try:
        rec = load_recording(DataSpec(path=str(p), sample_rate=rate, time_unit=unit))
        iv = detect_static(rec.t, rec.raw)
    except ImucalError as exc:
        assert "\n" not in str(exc)
        return
    assert np.isfinite(rec.raw).all() and (np.abs(rec.raw) <= 1e30).all()
    assert rec.n < 2 or 1.0 <= rec.sample_rate <= 1e5
    assert iv.n >= 0
