"""Every bad-input path through the command line: exit status 2, ONE line on stderr starting
with "imucal: error:" that names the file and/or field, no traceback, and no output left behind
(neither the --out directory nor the --json file, nor apply's --out file)."""
from __future__ import annotations

from pathlib import Path
from typing import Callable

import numpy as np
import pytest
import yaml

from conftest import real_file, write_simulation
from imucal.analysis.simulate import cube_directions, mems_counts_sensor


def check_refusal(r, *must_name: str) -> str:
    assert r.code == 2, (r.code, r.err)
    assert "Traceback" not in r.err and "Traceback" not in r.out
    lines = r.err.splitlines()
    assert len(lines) == 1, r.err
    assert lines[0].startswith("imucal: error: "), r.err
    for s in must_name:
        assert s in lines[0], (s, lines[0])
    return lines[0]


def write(tmp: Path, name: str, content: str | bytes) -> Path:
    p = tmp / name
    p.write_bytes(content.encode("utf-8") if isinstance(content, str) else content)
    return p


def yaml_cfg(tmp: Path, d: dict, name: str = "run.yaml") -> Path:
    return write(tmp, name, yaml.safe_dump(d))


# --- simulated recordings for the pipeline-level refusals --------------------------------------
@pytest.fixture(scope="module")
def bad_recordings(tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("badrec")
    rng = np.random.default_rng(8)
    sensor = mems_counts_sensor(rng)
    ang = np.linspace(0, 2 * np.pi, 13)[:-1]
    plane = np.column_stack([np.cos(ang), np.sin(ang), np.zeros_like(ang)])
    out = {
        "five": write_simulation(root / "five.csv", sensor, cube_directions("faces")[:5], seed=1).path,
        "six": write_simulation(root / "six.csv", sensor, cube_directions("faces"), seed=2).path,
        "plane": write_simulation(root / "plane.csv", sensor, plane, seed=3).path,
        "still": write_simulation(root / "still.csv", sensor, np.array([[0.3, -0.2, 0.93]]), seed=4,
                                  hold=40.0).path,
    }
    t = np.arange(4000) / 100.0
    raw = 1000 * np.column_stack([np.sin(0.7 * t), np.cos(1.1 * t), np.sin(0.3 * t + 1)])
    moving = root / "moving.csv"
    np.savetxt(moving, np.column_stack([t, raw]), delimiter=",", header="t,ax,ay,az", comments="", fmt="%.4f")
    out["moving"] = moving
    return out


# --- the cases: (name, make(tmp, recs, good) -> (args, names the message must contain)) ---------
Case = Callable[[Path, dict, Path], tuple[list, tuple[str, ...]]]

CSV_HEAD = "t,ax,ay,az\n"


def _rows(n: int = 5) -> str:
    return "".join(f"{k * 0.01:.2f},{k},2,3\n" for k in range(n))


CALIBRATE_CASES: dict[str, Case] = {
    "missing file": lambda tmp, recs, good: (
        ["--data", tmp / "nope.csv"], ("nope.csv", "data.path", "file not found")),
    "missing config": lambda tmp, recs, good: (
        [tmp / "nope.yaml"], ("nope.yaml", "config", "file not found")),
    "unknown YAML key": lambda tmp, recs, good: (
        [yaml_cfg(tmp, {"data": {"path": str(good)}, "fitt": {}})],
        ("run.yaml", "fitt", "unknown key 'fitt'", "allowed top-level keys: data, static")),
    "unknown nested YAML key": lambda tmp, recs, good: (
        [yaml_cfg(tmp, {"data": {"path": str(good), "colums": {"ax": "x"}}})],
        ("run.yaml", "data.colums", "unknown key 'colums'", "allowed keys here: path, format, columns")),
    "YAML syntax": lambda tmp, recs, good: (
        [write(tmp, "run.yaml", "data:\n  path: [x.csv\n")], ("run.yaml", "config", "is not valid YAML")),
    "YAML bad tag value": lambda tmp, recs, good: (
        [write(tmp, "run.yaml", "data: {path: x.csv}\nstatic: {window: !!int half}\n")],
        ("run.yaml", "is not valid YAML")),
    "YAML not a mapping": lambda tmp, recs, good: (
        [write(tmp, "run.yaml", "- data\n- fit\n")], ("run.yaml", "top level must be a mapping")),
    "YAML missing data": lambda tmp, recs, good: (
        [yaml_cfg(tmp, {"fit": {"mode": "means"}})], ("run.yaml", "data", "missing section 'data'")),
    "YAML missing path": lambda tmp, recs, good: (
        [yaml_cfg(tmp, {"data": {"unit": "raw"}})], ("run.yaml", "data.path", "missing key 'path'")),
    "YAML bad window": lambda tmp, recs, good: (
        [yaml_cfg(tmp, {"data": {"path": str(good)}, "static": {"window": -1}})],
        ("run.yaml", "static.window", "must be a positive number of seconds")),
    "YAML bad threshold": lambda tmp, recs, good: (
        [yaml_cfg(tmp, {"data": {"path": str(good)}, "static": {"threshold": "auto"}})],
        ("run.yaml", "static.threshold", "'auto' must be a positive number")),
    "YAML bad fit mode": lambda tmp, recs, good: (
        [yaml_cfg(tmp, {"data": {"path": str(good)}, "fit": {"mode": "fast"}})],
        ("run.yaml", "fit.mode", "unknown fit mode 'fast'", "means, samples")),
    "YAML bad fix": lambda tmp, recs, good: (
        [yaml_cfg(tmp, {"data": {"path": str(good)}, "fit": {"fix": ["gamma"]}})],
        ("run.yaml", "fit.fix", "cannot fix 'gamma'")),
    "YAML bad angle tolerance": lambda tmp, recs, good: (
        [yaml_cfg(tmp, {"data": {"path": str(good)}, "fit": {"angle_tolerance": 0.9}})],
        ("run.yaml", "fit.angle_tolerance", "must lie in (0, 0.5)")),
    "YAML unknown effect": lambda tmp, recs, good: (
        [yaml_cfg(tmp, {"data": {"path": str(good)}, "fit": {"effects": ["warp_drive"]}})],
        ("run.yaml", "fit.effects[0].name", "unknown effect 'warp_drive'")),
    "YAML effects not a list": lambda tmp, recs, good: (
        [yaml_cfg(tmp, {"data": {"path": str(good)}, "fit": {"effects": 5}})],
        ("run.yaml", "fit.effects", "must be a list")),
    "YAML bad sample rate": lambda tmp, recs, good: (
        [yaml_cfg(tmp, {"data": {"path": str(good), "sample_rate": "fast"}})],
        ("run.yaml", "data.sample_rate", "is not an IMU rate")),
    "YAML bad column mapping": lambda tmp, recs, good: (
        [yaml_cfg(tmp, {"data": {"path": str(good), "columns": ["t", "ax"]}})],
        ("run.yaml", "data.columns", "must map roles to columns")),
    "YAML bad output dir": lambda tmp, recs, good: (
        [yaml_cfg(tmp, {"data": {"path": str(good)}, "output": {"dir": 5}})],
        ("run.yaml", "output.dir", "must be a directory name")),
    "YAML gravity value": lambda tmp, recs, good: (
        [yaml_cfg(tmp, {"data": {"path": str(good)}, "gravity": {"value": 98.1}})],
        ("run.yaml", "gravity.value", "is not a local gravity on Earth")),
    "YAML gravity and latitude": lambda tmp, recs, good: (
        [yaml_cfg(tmp, {"data": {"path": str(good)}, "gravity": {"value": 9.81, "latitude": 45}})],
        ("run.yaml", "gravity", "give either gravity.value or gravity.latitude")),
    "YAML latitude out of range": lambda tmp, recs, good: (
        [yaml_cfg(tmp, {"data": {"path": str(good)}, "gravity": {"latitude": 100}})],
        ("run.yaml", "gravity.latitude", "latitude 100 is outside [-90, 90] degrees")),
    "YAML latitude not a number": lambda tmp, recs, good: (
        [yaml_cfg(tmp, {"data": {"path": str(good)}, "gravity": {"latitude": "north"}})],
        ("run.yaml", "gravity.latitude", "is not a number")),
    "YAML height implausible": lambda tmp, recs, good: (
        [yaml_cfg(tmp, {"data": {"path": str(good)}, "gravity": {"latitude": 45, "height": 1e7}})],
        ("run.yaml", "gravity.height", "not a plausible ellipsoidal height")),
    "YAML data file missing (relative to YAML)": lambda tmp, recs, good: (
        [yaml_cfg(tmp, {"data": {"path": "logs/none.csv"}})],
        (str(tmp / "logs" / "none.csv"), "data.path", "file not found")),
    "gravity option": lambda tmp, recs, good: (
        ["--data", good, "--gravity", "20"], ("gravity.value", "gravity 20.0 m/s^2 is not a local gravity")),
    "gravity option nan": lambda tmp, recs, good: (
        ["--data", good, "--gravity", "nan"], ("gravity.value",)),
    "latitude option": lambda tmp, recs, good: (
        ["--data", good, "--latitude", "91"], ("gravity.latitude", "outside [-90, 90]")),
    "latitude option inf": lambda tmp, recs, good: (
        ["--data", good, "--latitude", "inf"], ("gravity.latitude",)),
    "gravity and latitude options": lambda tmp, recs, good: (
        ["--data", good, "--gravity", "9.81", "--latitude", "45"], ("gravity", "either")),
    "sample rate option": lambda tmp, recs, good: (
        ["--data", good, "--sample-rate", "-100"], ("data.sample_rate", "is not an IMU rate")),
    "CONFIG and --data": lambda tmp, recs, good: (
        [yaml_cfg(tmp, {"data": {"path": str(good)}}), "--data", good],
        ("arguments", "give either CONFIG or --data, not both")),
    "nothing to calibrate": lambda tmp, recs, good: ([], ("arguments", "nothing to calibrate")),
    "missing column": lambda tmp, recs, good: (
        ["--data", write(tmp, "r.csv", "t,ax,ay\n0,1,2\n0.01,1,2\n")], ("r.csv", "data.columns.az")),
    "NaN row": lambda tmp, recs, good: (
        ["--data", write(tmp, "r.csv", CSV_HEAD + _rows(3) + "0.03,nan,2,3\n" + "0.04,1,2,3\n")],
        ("r.csv", "data", "line 5 holds NaN or Inf")),
    "Inf row": lambda tmp, recs, good: (
        ["--data", write(tmp, "r.csv", CSV_HEAD + "0,1,2,3\n0.01,1,-inf,3\n")],
        ("r.csv", "line 3 holds NaN or Inf")),
    "non-numeric text": lambda tmp, recs, good: (
        ["--data", write(tmp, "r.csv", CSV_HEAD + _rows(2) + "0.02,1,2,three\n")],
        ("r.csv", "data", "line 4 column 4: 'three' is not a number")),
    "ragged row": lambda tmp, recs, good: (
        ["--data", write(tmp, "r.csv", CSV_HEAD + _rows(2) + "0.02,1\n")], ("r.csv", "line 4 has 2 columns")),
    "non-UTF-8 file": lambda tmp, recs, good: (
        ["--data", write(tmp, "r.csv", b"t,ax,ay,az\n0,1,2,3\n\x93quoted\x94\n")], ("r.csv", "is not UTF-8 text")),
    "binary file": lambda tmp, recs, good: (
        ["--data", write(tmp, "r.bin", bytes(range(256)) * 4)], ("r.bin", "data")),
    "empty file": lambda tmp, recs, good: (["--data", write(tmp, "r.csv", "")], ("r.csv", "data.path", "is empty")),
    "header only": lambda tmp, recs, good: (
        ["--data", write(tmp, "r.csv", CSV_HEAD)], ("r.csv", "has no data rows")),
    "directory as file": lambda tmp, recs, good: (
        ["--data", tmp], (str(tmp), "data.path", "is a directory, not a file")),
    "time not increasing": lambda tmp, recs, good: (
        ["--data", write(tmp, "r.csv", CSV_HEAD + "0,1,2,3\n0.02,1,2,3\n0.01,1,2,3\n")],
        ("r.csv", "data.columns.t", "time goes back at line 4 (0.01 after 0.02)")),
    "too few samples": lambda tmp, recs, good: (
        ["--data", write(tmp, "r.csv", CSV_HEAD + "0,1,2,3\n0.01,1,2,3\n")], ("r.csv", "only 2 samples")),
    "no time, no rate": lambda tmp, recs, good: (
        ["--data", write(tmp, "r.txt", "1 2 3\n4 5 6\n")], ("r.txt", "data.sample_rate", "no time column")),
    "too few intervals": lambda tmp, recs, good: (
        ["--data", recs["five"]], ("five.csv", "intervals", "only 5 distinct orientations for 9 free parameters")),
    "six poses, nine parameters": lambda tmp, recs, good: (
        ["--data", recs["six"]], ("six.csv", "phi, psi, theta undetermined", "--fix-angles")),
    "degenerate orientations": lambda tmp, recs, good: (
        ["--data", recs["plane"]], ("plane.csv", "intervals", "undetermined")),
    "still-only log": lambda tmp, recs, good: (
        ["--data", recs["still"]], ("still.csv", "only one static interval found")),
    "motion-only log": lambda tmp, recs, good: (
        ["--data", recs["moving"]], ("moving.csv", "static", "no static intervals found")),
    "--json is a directory": lambda tmp, recs, good: (
        ["--data", good, "--json", (tmp / "jdir").mkdir() or tmp / "jdir"], ("jdir", "output", "is a directory")),
    "--out under a file": lambda tmp, recs, good: (
        ["--data", good, "--out", write(tmp, "plain", "x") / "sub"], ("plain", "parent is not a directory")),
}


@pytest.mark.parametrize("case", list(CALIBRATE_CASES), ids=list(CALIBRATE_CASES))
def test_calibrate_refuses(case, run_cli, tmp_path, bad_recordings, si_recording):
    work = tmp_path / "work"
    work.mkdir()
    args, names = CALIBRATE_CASES[case](work, bad_recordings, si_recording.path)
    out, js = tmp_path / "results", tmp_path / "summary.json"
    extra = [] if "--out" in args else ["--out", out]
    extra += [] if "--json" in args else ["--json", js]
    r = run_cli(["calibrate", *args, *extra, "--no-figures"])
    check_refusal(r, *names)
    assert not out.exists() and not js.exists()
    if "--out" in args:
        assert not Path(args[args.index("--out") + 1]).exists()
    leftovers = [p for p in tmp_path.rglob("*") if p.name.startswith((".imucal-", ".calibration", ".summary"))]
    assert leftovers == []


def test_ferraris_six_pose_session_is_refused_with_the_offer(run_cli, tmp_path):
    p = real_file("imucal-ferraris", "annotated_session.csv")
    r = run_cli(["calibrate", "--data", p, "--sample-rate", "204.8", "--out", tmp_path / "o",
                 "--json", tmp_path / "s.json"])
    check_refusal(r, "annotated_session.csv", "only 6 distinct orientations", "phi", "psi", "theta",
                  "--fix-angles")
    assert not (tmp_path / "o").exists() and not (tmp_path / "s.json").exists()


@pytest.mark.parametrize("args", [["--gravity", "abc"], ["--mode", "fast"], ["--bogus"]])
def test_usage_errors_are_one_line_exit_2(run_cli, si_recording, tmp_path, args):
    """argparse's own errors: one line, status 2 (prefix "imucal calibrate: error:")."""
    r = run_cli(["calibrate", "--data", si_recording.path, "--out", tmp_path / "o", *args])
    assert r.code == 2 and "Traceback" not in r.err
    lines = r.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("imucal") and "error:" in lines[0]
    assert not (tmp_path / "o").exists()


# --- apply -------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def good_calibration(si_run, tmp_path_factory) -> Path:
    p = tmp_path_factory.mktemp("cal") / "calibration.yaml"
    si_run.calibration.save(p)
    return p


def _cal_variant(tmp: Path, good: Path, change: Callable[[dict], None]) -> Path:
    d = yaml.safe_load(good.read_text())
    change(d)
    return yaml_cfg(tmp, d, "cal.yaml")


APPLY_CASES: dict[str, Callable[[Path, Path, Path], tuple[list, tuple[str, ...]]]] = {
    "missing calibration": lambda tmp, cal, data: (
        [tmp / "none.yaml", "--data", data], ("none.yaml", "calibration", "file not found")),
    "calibration not YAML": lambda tmp, cal, data: (
        [write(tmp, "cal.yaml", "format: [\n"), "--data", data], ("cal.yaml", "is not valid YAML")),
    "calibration not UTF-8": lambda tmp, cal, data: (
        [write(tmp, "cal.yaml", b"\xff\xfe\x00"), "--data", data], ("cal.yaml", "is UTF-16 or UTF-32 text, not UTF-8")),
    "config instead of calibration": lambda tmp, cal, data: (
        [yaml_cfg(tmp, {"data": {"path": "x.csv"}}, "cal.yaml"), "--data", data], ("cal.yaml", "format")),
    "unknown version": lambda tmp, cal, data: (
        [_cal_variant(tmp, cal, lambda d: d.update(format_version=7)), "--data", data],
        ("cal.yaml", "format_version", "unknown format version 7")),
    "negative scale": lambda tmp, cal, data: (
        [_cal_variant(tmp, cal, lambda d: d["parameters"]["b3"].update(value=-1.0)), "--data", data],
        ("cal.yaml", "parameters.b3.value", "must be positive")),
    "missing data": lambda tmp, cal, data: (
        [cal, "--data", tmp / "none.csv"], ("none.csv", "data.path", "file not found")),
    "NaN in data": lambda tmp, cal, data: (
        [cal, "--data", write(tmp, "r.csv", CSV_HEAD + "0,1,2,3\n0.01,NaN,2,3\n")], ("r.csv", "line 3 holds NaN")),
    "data is a directory": lambda tmp, cal, data: (
        [cal, "--data", tmp], ("data.path", "is a directory")),
    "bad sample rate": lambda tmp, cal, data: (
        [cal, "--data", data, "--sample-rate", "0"], ("data.sample_rate",)),
}


@pytest.mark.parametrize("case", list(APPLY_CASES), ids=list(APPLY_CASES))
def test_apply_refuses(case, run_cli, tmp_path, good_calibration, si_recording):
    work = tmp_path / "work"
    work.mkdir()
    args, names = APPLY_CASES[case](work, good_calibration, si_recording.path)
    out = tmp_path / "sub" / "acc.csv"
    check_refusal(run_cli(["apply", *args, "--out", out]), *names)
    assert not out.exists() and not out.parent.exists()


@pytest.mark.parametrize("where", ["directory", "under a file"])
def test_apply_refuses_bad_out(run_cli, tmp_path, good_calibration, si_recording, where):
    if where == "directory":
        out = tmp_path / "d"
        out.mkdir()
        names = ("d", "output", "is a directory")
    else:
        out = write(tmp_path, "f", "x") / "acc.csv"
        names = ("acc.csv", "output", "parent is not a directory")
    check_refusal(run_cli(["apply", good_calibration, "--data", si_recording.path, "--out", out]), *names)
    assert sorted(p.name for p in tmp_path.iterdir()) == (["d"] if where == "directory" else ["f"])


@pytest.mark.parametrize("parts, extra, names", [
    (("mpu6050-tomisuarez", "example_data_tinit_calc.csv"), ["--sample-rate", "100"],
     ("example_data_tinit_calc.csv", "only one static interval found")),  # a real still-only log
    (("ros-imu-getovermassif", "data1", "acc_data.txt"), [],  # a real log that is mostly motion: its two
     ("acc_data.txt", "only 1 distinct orientation for")),  # still intervals lie 0.06 deg apart, one orientation
])
def test_real_logs_that_cannot_calibrate(run_cli, tmp_path, parts, extra, names):
    r = run_cli(["calibrate", "--data", real_file(*parts), *extra, "--out", tmp_path / "o",
                 "--json", tmp_path / "s.json"])
    check_refusal(r, *names)
    assert list(tmp_path.iterdir()) == []
