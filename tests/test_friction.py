"""Issue 29, the friction list: what a new user types first works, or is answered in one line
(a bag's one IMU topic: tests/test_rosbag.py; the gyroscope in `imucal noise`: tests/test_noise.py)."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest


def one_line_error(r, *parts: str) -> None:
    lines = r.err.strip().splitlines()
    assert r.code == 2 and len(lines) == 1 and lines[0].startswith("imucal: error: "), r.err
    for p in parts:
        assert p in lines[0], (p, lines[0])


def _summary(run_cli, tmp_path: Path, *args) -> dict:
    js = tmp_path / "s.json"
    r = run_cli(["calibrate", *args, "--out", tmp_path / "o", "--no-figures", "--quiet", "--json", js])
    assert r.code == 0, r.err
    return json.loads(js.read_text())


def test_a_recording_as_the_positional_argument_is_read_as_data(run_cli, tmp_path, counts_recording):
    """`imucal calibrate my.csv` (was: "top level must be a mapping") calibrates as --data does."""
    as_data = _summary(run_cli, tmp_path / "a", "--data", counts_recording.path)
    positional = _summary(run_cli, tmp_path / "b", counts_recording.path)
    assert positional["params"] == as_data["params"] and positional["data"]["file"] == as_data["data"]["file"]
    r = run_cli(["calibrate", counts_recording.path, "--data", counts_recording.path, "--out", tmp_path / "c"])
    one_line_error(r, "arguments", "is a recording and --data names another")
    assert not (tmp_path / "c").exists()


def test_fix_holds_any_parameter_on_the_command_line(run_cli, tmp_path, counts_recording):
    """--fix NAME (repeated, or NAME,NAME) holds parameters at their start; NAME=VALUE at a value."""
    d = _summary(run_cli, tmp_path / "a", counts_recording.path, "--fix", "s1", "--fix", "s2,s3")
    assert d["model"].endswith("(s1, s2, s3 held fixed)")
    free = _summary(run_cli, tmp_path / "f", counts_recording.path)
    phi, psi = free["params"]["phi"], free["params"]["psi"]
    d = _summary(run_cli, tmp_path / "b", counts_recording.path, "--fix", f"phi={phi!r},psi={psi!r}")
    assert (d["params"]["phi"], d["params"]["psi"]) == (phi, psi) and d["model"].endswith("(phi, psi held fixed)")
    for bad, what in (("bogus", "cannot fix 'bogus'"), ("s1=x", "'x' is not a number to hold s1 at")):
        r = run_cli(["calibrate", counts_recording.path, "--fix", bad, "--out", tmp_path / "c"])
        one_line_error(r, "--fix", what)
        assert not (tmp_path / "c").exists()


def test_json_dash_writes_the_summary_to_stdout(run_cli, tmp_path, counts_recording, monkeypatch):
    """`--json -` prints the summary, alone, on stdout (the report goes to stderr); no file named '-'."""
    monkeypatch.chdir(tmp_path)
    want = _summary(run_cli, tmp_path / "a", counts_recording.path)
    r = run_cli(["calibrate", counts_recording.path, "--out", tmp_path / "b", "--no-figures", "--json", "-"])
    assert r.code == 0, r.err
    got = json.loads(r.out)
    assert got["params"] == want["params"] and "[[Calibration]]" in r.err
    assert not (tmp_path / "-").exists() and (tmp_path / "b" / "calibration.yaml").exists()


def test_json_dash_prints_nothing_when_the_run_fails(run_cli, tmp_path, counts_recording):
    r = run_cli(["calibrate", counts_recording.path, "--fix", "s1,s2,s3,b1,b2,b3,phi,psi,theta",
                 "--out", tmp_path / "o", "--json", "-"])
    one_line_error(r, "nothing is left to fit")
    assert r.out == "" and not (tmp_path / "o").exists()


@pytest.mark.parametrize("command", [["plan-poses", "--scheme", "edges", "--no-compare"]])
def test_json_dash_for_every_command_that_writes_json(run_cli, tmp_path, command, monkeypatch):
    monkeypatch.chdir(tmp_path)
    r = run_cli([*command, "--json", "-"])
    assert r.code == 0, r.err
    assert isinstance(json.loads(r.out), dict) and not (tmp_path / "-").exists()


@pytest.mark.parametrize("name, factor, unit", [
    ("timestamp_ms", 1e3, "ms"), ("time_s", 1.0, "s"), ("t_ms", 1e3, "ms"), ("Time [us]", 1e6, "us"),
    ("stamp_ns", 1e9, "ns"), ("TIME (sec)", 1.0, "s"), ("stamp", 1.0, None), ("time", 1e3, None),
])
@pytest.mark.parametrize("stream", ["never", "always"])
def test_a_time_column_is_found_by_its_name_with_its_unit(run_cli, tmp_path, counts_recording, name, factor, unit,
                                                          stream):
    """timestamp_ms (and time, timestamp, time_s, t_ms, stamp ...) is the time column, in the unit its name
    states (else inferred from the step), whole or read in chunks: the calibration of the same samples."""
    t, raw = counts_recording.sim.t, counts_recording.sim.raw
    src = tmp_path / "named.csv"
    src.write_text(f"{name},ax,ay,az\n" + "".join(f"{a:.17g},{x:.17g},{y:.17g},{z:.17g}\n" for a, (x, y, z)
                                                  in zip(t * factor, raw)))
    want = _summary(run_cli, tmp_path / "a", counts_recording.path)
    got = _summary(run_cli, tmp_path / "b", src, "--stream", stream)
    flat = [(k, i, v) for k, vs in want["params"].items() for i, v in enumerate(np.atleast_1d(vs))]
    for k, i, v in flat:
        assert np.atleast_1d(got["params"][k])[i] == pytest.approx(v, rel=1e-8), (k, i)
    note = got["data"]["time"]
    assert (f"time unit from the column name {name}: {unit}" in note) if unit else "time unit inferred" in note


def test_a_name_that_only_starts_like_time_is_not_time(tmp_path):
    from imucal.data.timebase import time_column_name

    assert [time_column_name(n) for n in ("t_c", "temp", "temperature", "tilt", "times_x", "t")] == [
        (False, None), (False, None), (False, None), (False, None), (False, None), (True, None)]
