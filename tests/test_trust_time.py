"""Issue 25, trust in time stamps and the reader: a jittered logger's stamps re-timed on a fitted
clock, gaps kept, one sample rate; a sample rate given beside a time column checked; fractional
millisecond stamps; refusals that name the real problem (minutes, a long gap, a duplicated
column, a line without end, a sparse file); a symbolic-link loop given to any command.

Every recording is generated here. The streamed reader (imucal.data.stream) is run on the same
files as the whole-file reader and must agree with it.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
import yaml

from conftest import write_simulation
from imucal.analysis.simulate import cube_directions, mems_counts_sensor
from imucal.data.load import DataSpec, load_recording
from imucal.errors import ImucalError

ROOT = Path(__file__).resolve().parents[1]


def one_line_error(err: str, *parts: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("imucal: error: "), err
    for p in parts:
        assert p in lines[0], (p, lines[0])
    return lines[0]


def simulated(tmp_path: Path, name: str = "sim.csv", seed: int = 7, **kw):
    """A 100 Hz counts recording of 26 cube poses (t, ax, ay, az)."""
    sensor = mems_counts_sensor(np.random.default_rng(seed))
    return write_simulation(tmp_path / name, sensor, cube_directions(), seed=seed, **kw)


# --- a loop of symbolic links given to every command that reads a file ---------------------------
@pytest.fixture
def loop(tmp_path) -> Path:
    """work/a -> b -> a: a path that never reaches a file."""
    work = tmp_path / "work"
    work.mkdir()
    os.symlink(work / "b", work / "a")
    os.symlink(work / "a", work / "b")
    return work / "a"


@pytest.fixture
def calibration(tmp_path, run_cli) -> Path:
    r = simulated(tmp_path)
    out = tmp_path / "cal"
    res = run_cli(["calibrate", "--data", r.path, "--out", out, "--no-figures", "--quiet"])
    assert res.code == 0, res.err
    return out / "calibration.yaml"


LOOP_COMMANDS = {
    "calibrate": lambda lp, cal, w: ["calibrate", "--data", lp, "--out", w / "o"],
    "discover-config": lambda lp, cal, w: ["discover", "--config", ROOT / "configs" / "xsens-mti-imutk.yaml",
                                           "--data", lp, "--json", w / "d.json"],
    "calibrate-gyro-data": lambda lp, cal, w: ["calibrate", "--data", cal.parent.parent / "sim.csv",
                                               "--gyro-data", lp, "--out", w / "o"],
    "calibrate-noise": lambda lp, cal, w: ["calibrate", "--data", cal.parent.parent / "sim.csv",
                                           "--noise", lp, "--out", w / "o"],
    "apply": lambda lp, cal, w: ["apply", cal, "--data", lp, "--out", w / "o.csv"],
    "noise": lambda lp, cal, w: ["noise", "--data", lp, "--json", w / "n.json"],
    "discover": lambda lp, cal, w: ["discover", "--data", lp, "--json", w / "d.json"],
    "drift": lambda lp, cal, w: ["drift", "--calibration", cal, "--recording", lp, "--json", w / "d.json"],
    "compare": lambda lp, cal, w: ["compare", cal, cal, "--data", lp, "--json", w / "c.json"],
    "export": lambda lp, cal, w: ["export", cal, "--format", "kalibr", "--data", lp, "--out", w / "imu.yaml"],
    "apply-calibration": lambda lp, cal, w: ["apply", lp, "--data", cal.parent.parent / "sim.csv",
                                             "--out", w / "o.csv"],
    "simulate-out": lambda lp, cal, w: ["simulate", ROOT / "configs" / "simulate_example.yaml", "--out", lp],
    "batch-manifest": lambda lp, cal, w: ["batch", lp, "--out", w / "res"],
}


@pytest.mark.parametrize("name", list(LOOP_COMMANDS))
def test_symlink_loop_is_one_line_exit_2_in_every_command(tmp_path, run_cli, unchanged, loop, calibration, name):
    work = loop.parent
    with unchanged(work):
        r = run_cli(LOOP_COMMANDS[name](loop, calibration, work))
    assert r.code == 2, (r.code, r.err)
    line = one_line_error(r.err, str(loop))
    assert "Traceback" not in r.err and "internal error" not in r.err
    assert ("is a loop of symbolic links" in line) or ("is a symbolic link" in line), line


def test_symlink_loop_in_a_batch_manifest_names_the_unit(tmp_path, run_cli, unchanged, loop):
    work = loop.parent
    manifest = work / "manifest.yaml"
    manifest.write_text("units: [{id: U1, data: a}]\n")
    with unchanged(work):
        r = run_cli(["batch", manifest, "--out", work / "res"])
    assert r.code == 2
    one_line_error(r.err, f"{loop}: units[0].data: is a loop of symbolic links",
                   "(fix: give the path of the file itself")
