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


# --- the reader: a duplicated column, a line without end, a sparse file ----------------------------
STREAM_HOW = ["never", "always"]  # the whole-file reader and the chunked one


def rows_text(n: int, rate: float = 100.0) -> str:
    """n rows of a still sensor (t, ax, ay, az), 100 Hz."""
    return "".join(f"{k / rate:.2f},12,-7,16384\n" for k in range(n))


@pytest.mark.parametrize("how", STREAM_HOW)
@pytest.mark.parametrize("header, name, cols", [
    ("t,ax,ay,az,ax", "'ax' (read as ax)", "columns 2 and 5"),
    ("t,AX,ay,az,ax", "'ax' (read as ax)", "columns 2 and 5"),  # default names are matched in any case
    ("t,acc_x,ay,az,acc_x", "'acc_x' (read as ax)", "columns 2 and 5"),
])
def test_duplicated_header_column_is_refused_naming_both_positions(tmp_path, run_cli, unchanged, how, header,
                                                                     name, cols):
    src = tmp_path / "dup.csv"
    src.write_text(header + "\n" + "".join(f"{k / 100:.2f},1,2,3,4\n" for k in range(50)))
    with unchanged():
        r = run_cli(["calibrate", "--data", src, "--out", tmp_path / "o", "--stream", how])
    assert r.code == 2
    one_line_error(r.err, f"dup.csv: data.columns.ax: the header names column {name} twice: {cols}",
                   "(fix: rename one of them, or map ax to a 0-based column index (e.g. --columns ax=1))")


def test_mapped_duplicated_column_is_refused_and_an_index_reads_it(tmp_path):
    src = tmp_path / "dup.csv"
    src.write_text("t,x,y,z,x\n" + rows_text(20).replace("\n", ",5\n"))
    with pytest.raises(ImucalError, match=r"data.columns.ax: the header names column 'x' \(read as ax\) twice: "
                                          r"columns 2 and 5"):
        load_recording(DataSpec(path=str(src), columns={"ax": "x", "ay": "y", "az": "z"}))
    rec = load_recording(DataSpec(path=str(src), columns={"ax": 4, "ay": "y", "az": "z"}))  # the fix given
    assert rec.raw[0].tolist() == [5.0, -7.0, 16384.0]


@pytest.mark.parametrize("how", STREAM_HOW)
def test_line_without_end_is_refused_naming_its_line(tmp_path, run_cli, unchanged, how):
    """A file whose text stops in one enormous line (here just past MAX_LINE_BYTES; the same rule
    holds a 20 GB one back) is refused at that line, not read on to its end."""
    from imucal.data.load import MAX_LINE_BYTES

    src = tmp_path / "long.csv"
    src.write_text("t,ax,ay,az\n" + rows_text(300) + "1" * (MAX_LINE_BYTES + 1))
    with unchanged():
        r = run_cli(["calibrate", "--data", src, "--out", tmp_path / "o", "--stream", how])
    assert r.code == 2
    one_line_error(r.err, f"long.csv: data: line 302 is longer than {MAX_LINE_BYTES} bytes (no line end)",
                   "(fix: check that the file is a text recording")
    src.write_text("t,ax,ay,az\n" + rows_text(300) + "1" * MAX_LINE_BYTES)  # at the limit: only its value is bad
    r = run_cli(["calibrate", "--data", src, "--out", tmp_path / "o", "--stream", how])
    assert r.code == 2 and "line 302" in r.err and "longer than" not in r.err


@pytest.mark.parametrize("how, size", [("auto", 20 * 1024**3), ("always", 20 * 1024**3), ("never", 3 * 1024**3)])
def test_sparse_file_whose_text_stops_is_refused_at_the_text_end(tmp_path, run_cli, how, size):
    """600 KB of text, then holes to 20 GB (3 GB for the whole-file reader, under its 4 GB limit):
    refused as binary from the line where the NUL bytes start, without reading the holes (the
    file system's SEEK_HOLE for the whole-file reader, the first block's NUL for the chunked one)."""
    src = tmp_path / "w" / "sparse.csv"
    src.parent.mkdir()
    text = ("t,ax,ay,az\n" + rows_text(40000)).encode()[:600_000]
    with open(src, "wb") as f:
        f.write(text)
        f.truncate(size)  # costs no disk
    line = text.count(b"\n") + 1
    out = tmp_path / "o"
    r = run_cli(["calibrate", "--data", src, "--out", out, "--stream", how])
    assert r.code == 2
    one_line_error(r.err, f"sparse.csv: data.path: is a binary file (NUL bytes) from line {line} on (a sparse or "
                          "corrupt file), not a text recording")
    # nothing left behind, the input untouched (not hashed whole: that would read the holes)
    assert sorted(os.listdir(tmp_path)) == ["w"] and os.listdir(src.parent) == ["sparse.csv"]
    with open(src, "rb") as f:
        assert f.read(len(text) + 1) == text + b"\0" and os.fstat(f.fileno()).st_size == size
