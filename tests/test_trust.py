"""Issue 9, trust: no silent wrong calibration, no lost file, no traceback.

Each case runs the exact command, checks the exit status and the one-line message, and (where
files are involved) that no input changed and nothing was left behind. Real recordings get
clipping and millisecond time stamps injected here, and their untouched versions must raise no
alarm.
"""
from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from conftest import RATE, calibrate_file, real_file, write_simulation
from imucal.solve.ipopt import CONVERGED
from imucal.data.load import load_recording
from imucal.data.spec import parse_columns
from imucal.cli.main import main
from imucal.errors import EXIT_INTERNAL, ImucalError
from imucal.analysis.simulate import SensorSpec, cube_directions
from imucal.data.static import detect_static

ROOT = Path(__file__).resolve().parents[1]
XSENS = ("xsens-mti-imutk", "xsens_acc.mat")
REAL = [XSENS] + [("ros-imu-getovermassif", f"data{i}", "acc_data.txt") for i in (1, 2, 3, 4)]


def one_line_error(err: str, *parts: str) -> None:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("imucal: "), err
    for p in parts:
        assert p in lines[0], (p, lines[0])
    assert "Traceback" not in err


def xsens_array() -> np.ndarray:
    return np.loadtxt(real_file(*XSENS))


def save(path: Path, arr: np.ndarray, fmt: str = "%.17g") -> Path:
    np.savetxt(path, arr, fmt=fmt)
    return path


# --- inputs that are not regular files -------------------------------------------------------
@pytest.mark.parametrize("kind", ["fifo", "device", "sparse"])
def test_data_that_is_not_a_text_file_is_refused_at_once(run_cli, tmp_path, unchanged, kind):
    if kind == "fifo":
        src = tmp_path / "pipe.csv"
        os.mkfifo(src)
        want = "is a FIFO, not a regular file"
    elif kind == "device":
        src, want = Path("/dev/zero"), "is a device, not a regular file"
    else:
        src = tmp_path / "sparse.csv"
        with open(src, "wb") as f:
            f.truncate(2 * 1024**3)  # 2 GB of holes: must not be read whole
        want = "is a binary file (NUL bytes)"
    out = tmp_path / "w"  # the check hashes files: not the 2 GB input, which is only opened
    out.mkdir()
    with unchanged(out):
        r = run_cli(["calibrate", "--data", src, "--out", out / "o"])
    assert r.code == 2
    one_line_error(r.err, str(src), "data.path", want)
    assert src.is_fifo() if kind == "fifo" else True


# --- time unit ------------------------------------------------------------------------------
@pytest.mark.parametrize("parts", REAL, ids=lambda p: "/".join(p[:-1]))
def test_untouched_real_recordings_read_in_seconds_without_clipping(parts):
    rec = load_recording(real_file(*parts))
    assert rec.time_unit == "s" and "inferred: s" in rec.time_note
    iv = detect_static(rec.t, rec.raw)
    assert iv.meta["dropped"] == [] and iv.meta["saturation"] == {}


@pytest.mark.parametrize("stamps, unit", [
    (lambda t: np.round(t * 1e3) + 1700000000123, "ms"),  # epoch milliseconds
    (lambda t: t * 1e3 + 123.0, "ms"),                    # 123.0, 133.0, ...
    (lambda t: np.round(t * 1e6), "us"),
    (lambda t: np.round(t * 1e9) + 1.7e18, "ns"),
], ids=["epoch-ms", "float-ms", "us", "epoch-ns"])
@pytest.mark.parametrize("parts", [XSENS, REAL[2]], ids=["xsens", "ros-data2"])
def test_time_unit_is_inferred_and_intervals_unchanged(tmp_path, stamps, unit, parts):
    d = np.loadtxt(real_file(*parts))
    ref = load_recording(real_file(*parts))
    rec = load_recording(save(tmp_path / "r.txt", np.column_stack([stamps(d[:, 0] - d[0, 0]), d[:, 1:]])))
    assert rec.time_unit == unit and f"time unit inferred: {unit}" in rec.time_note
    a, b = detect_static(ref.t, ref.raw), detect_static(rec.t, rec.raw)
    np.testing.assert_array_equal(a.start, b.start)
    np.testing.assert_allclose(rec.t, ref.t, atol=5.1e-4)  # stamps rounded to whole ms at most


def test_given_wrong_time_unit_is_refused_naming_the_likely_one(run_cli, tmp_path, unchanged):
    d = xsens_array()
    src = save(tmp_path / "ms.txt", np.column_stack([d[:, 0] * 1e3, d[:, 1:]]))
    with unchanged():
        r = run_cli(["calibrate", "--data", src, "--time-unit", "s", "--out", tmp_path / "o"])
    assert r.code == 2
    one_line_error(r.err, "ms.txt", "data.time_unit", "time in s gives 0.1 Hz, not an IMU sample rate",
                   "--time-unit ms")


def test_time_unit_option_is_used(run_cli, tmp_path):
    d = xsens_array()
    src = save(tmp_path / "ms.txt", np.column_stack([d[:, 0] * 1e3, d[:, 1:]]))
    js = tmp_path / "s.json"
    r = run_cli(["calibrate", "--data", src, "--time-unit", "ms", "--gravity", "9.81744", "--out",
                 tmp_path / "o", "--no-figures", "--quiet", "--json", js])
    assert r.code == 0, r.err
    d = json.loads(js.read_text())
    assert d["n_intervals"] == 38 and d["data"]["time"] == "time unit given: ms"


@pytest.mark.parametrize("rate", ["1e-310", "1e9", "0.5"])
def test_implausible_sample_rate_is_refused(run_cli, tmp_path, rate):
    src = tmp_path / "r.txt"
    src.write_text("1 2 3\n4 5 6\n")
    r = run_cli(["calibrate", "--data", src, "--sample-rate", rate, "--out", tmp_path / "o"])
    assert r.code == 2
    one_line_error(r.err, "data.sample_rate", "is not an IMU rate")


# --- columns ------------------------------------------------------------------------------
def _imutk_seven_columns(tmp_path: Path) -> Path:
    acc = xsens_array()
    gyr = np.loadtxt(real_file("xsens-mti-imutk", "xsens_gyro.mat"))
    return save(tmp_path / "imu.txt", np.column_stack([acc[:, 0], gyr[:, 1:], acc[:, 1:]]))


def test_seven_columns_are_ambiguous_then_mapped(run_cli, tmp_path, unchanged):
    src = _imutk_seven_columns(tmp_path)
    with unchanged():
        r = run_cli(["calibrate", "--data", src, "--out", tmp_path / "o"])
    assert r.code == 2
    one_line_error(r.err, "imu.txt", "data.columns", "has 7 columns and no header: the layout is ambiguous",
                   "t gx gy gz ax ay az", "--columns t=0,ax=4,ay=5,az=6")
    js = tmp_path / "s.json"
    r = run_cli(["calibrate", "--data", src, "--columns", "t=0,ax=4,ay=5,az=6", "--gravity", "9.81744",
                 "--out", tmp_path / "o", "--no-figures", "--quiet", "--json", js])
    assert r.code == 0, r.err
    assert json.loads(js.read_text())["n_intervals"] == 38


def test_gyro_columns_by_header_load_beside_the_accelerometer(tmp_path):
    src = tmp_path / "imu.csv"
    src.write_text("t,gx,gy,gz,ax,ay,az\n0,1,2,3,4,5,6\n0.01,1,2,3,7,8,9\n")
    rec = load_recording(src)
    np.testing.assert_array_equal(rec.raw, [[4, 5, 6], [7, 8, 9]])
    np.testing.assert_array_equal(rec.gyro, [[1, 2, 3], [1, 2, 3]])


@pytest.mark.parametrize("text, msg", [
    ("t=0,ax", "'ax' is not ROLE=COLUMN"), ("q=1", "unknown role 'q'"), ("ax=1,ax=2", "role ax given twice"),
    ("", "give ROLE=COLUMN pairs")])
def test_bad_column_maps(text, msg):
    with pytest.raises(ImucalError, match=msg):
        parse_columns(text)


def test_column_map_by_names_and_indices():
    assert parse_columns("t=0, ax=4,ay=acc y") == {"t": 0, "ax": 4, "ay": "acc y"}


def test_corrupt_magnitude_is_refused_with_its_line(run_cli, tmp_path):
    src = tmp_path / "r.csv"
    src.write_text("t,ax,ay,az\n0,1,2,3\n0.01,1e300,2,3\n")
    r = run_cli(["calibrate", "--data", src, "--out", tmp_path / "o"])
    assert r.code == 2
    one_line_error(r.err, "r.csv", "line 3 holds a value beyond +-1e+30 (corrupt)")


# --- clipped axes ---------------------------------------------------------------------------
def _clipped_xsens(tmp_path: Path, axis: int = 2, depth: float = 200.0) -> tuple[Path, int]:
    """The Xsens log with one axis clipped ``depth`` counts (0.48 m/s^2 at 200) below its top pose."""
    d = xsens_array()
    rec = load_recording(real_file(*XSENS))
    means = detect_static(rec.t, rec.raw).mean[:, axis]
    cut = float(np.round(means.max() - depth))
    d[:, 1 + axis] = np.minimum(d[:, 1 + axis], cut)
    return save(tmp_path / "clipped.txt", d), int(np.sum(means > cut))


def test_clipped_axis_drops_its_intervals_and_says_so(run_cli, tmp_path):
    src, n_clipped = _clipped_xsens(tmp_path)
    js = tmp_path / "s.json"
    r = run_cli(["calibrate", "--data", src, "--gravity", "9.81744", "--out", tmp_path / "o",
                 "--no-figures", "--quiet", "--json", js])
    assert r.code == 0, r.err
    assert "imucal: warning:" in r.err and "dropped because an axis was clipped (axis z)" in r.err
    d = json.loads(js.read_text())
    dropped = d["data"]["dropped_intervals"]
    assert len(dropped) >= n_clipped >= 1 and {x["axis"] for x in dropped} == {"z"}
    assert d["n_intervals"] == 38 - len(dropped)
    cal = yaml.safe_load((tmp_path / "o" / "calibration.yaml").read_text())
    assert cal["data"]["dropped_intervals"] == dropped
    assert "dropped" in (tmp_path / "o" / "report.txt").read_text()
    # The clipped poses no longer bias the fit: the RMS stays at the untouched recording's level.
    assert d["rms_residual"] < 0.0015


def test_clipping_without_the_check_would_have_biased_the_fit(tmp_path):
    """The test above can fail: with the clipped intervals kept, the fit is so wrong that the
    absurd-fit rule refuses it (the second line of defence)."""
    from imucal.data import static

    src, _ = _clipped_xsens(tmp_path)
    old = static.SATURATION_FRACTION
    static.SATURATION_FRACTION = 2.0  # disables the automatic check
    try:
        with pytest.raises(ImucalError, match=r"reduced chi-square .* the model cannot describe these data"):
            calibrate_file(src, gravity={"value": 9.81744})
    finally:
        static.SATURATION_FRACTION = old


def test_declared_rails_are_used(tmp_path):
    src, _ = _clipped_xsens(tmp_path, axis=0, depth=50.0)
    hi = float(np.loadtxt(src)[:, 1].max())
    run = calibrate_file(src, gravity={"value": 9.81744},
                         data={"saturation": {"high": [hi, 70000, 70000]}})
    dropped = run.calibration.data["dropped_intervals"]
    assert dropped and all(x["axis"] == "x" and "declared" in x["reason"] for x in dropped)


@pytest.mark.parametrize("rails, msg", [({"top": 1}, "must map low and/or high"),
                                        ({"low": [1, 2]}, "must be a finite number or [x, y, z]"),
                                        ({"low": 5, "high": 1}, "low rail must lie below")])
def test_bad_rails_are_refused(rails, msg):
    with pytest.raises(ImucalError, match=msg.replace("[", r"\[").replace("]", r"\]")):
        calibrate_file("x.csv", data={"saturation": rails})


def test_everything_clipped_is_refused_naming_the_reason(run_cli, tmp_path):
    d = xsens_array()
    d[:, 1] = 40000.0  # a dead x axis, stuck at one value
    src = save(tmp_path / "dead.txt", d)
    r = run_cli(["calibrate", "--data", src, "--out", tmp_path / "o"])
    assert r.code == 2
    one_line_error(r.err, "dead.txt", "dropped because an axis was clipped (axis x)")


# --- the fit says what is true -----------------------------------------------------------------
def test_poor_fit_warns_with_the_command_that_investigates(run_cli, tmp_path):
    js = tmp_path / "s.json"
    r = run_cli(["calibrate", str(ROOT / "configs" / "xsens-mti-imutk.yaml"), "--out", tmp_path / "o",
                 "--no-figures", "--quiet", "--json", js])
    assert r.code == 0
    s = json.loads(js.read_text())
    red = s["redchi_noise"]  # against the noise alone, at the default (weights: auto) solution
    assert red > 3  # the residuals exceed the noise: the warning's case (a number computed, never typed in)
    assert f"imucal: warning: reduced chi-square {red:.3g} against the noise (29 dof" in r.err
    assert f"bias_instability, {s['bias_instability']:.3g} m/s^2 rms" in r.err
    assert "imucal discover --config" in r.err and "--gravity 9.81744" in r.err
    w = s["warnings"]
    assert len(w) == 1 and f"reduced chi-square {red:.3g}" in w[0]
    js2 = tmp_path / "n.json"
    r2 = run_cli(["calibrate", str(ROOT / "configs" / "xsens-mti-imutk.yaml"), "--out", tmp_path / "n",
                  "--no-figures", "--quiet", "--weights", "noise", "--json", js2])
    red2 = json.loads(js2.read_text())["redchi_noise"]
    assert f"imucal: warning: reduced chi-square {red2:.3g} against the noise (29 dof" in r2.err
    assert red >= red2  # that fit minimises it
    assert "bias_instability" not in r2.err
    assert yaml.safe_load((tmp_path / "o" / "calibration.yaml").read_text())["fit"]["warnings"] == w
    assert json.loads(js.read_text())["solver_status"] in CONVERGED


def test_clean_fit_has_no_warning(si_run):
    assert si_run.calibration.fit["warnings"] == []


def test_zero_degrees_of_freedom_reports_no_standard_errors(run_cli, tmp_path):
    sensor = SensorSpec(s=(0.1, -0.2, 0.05), b=(1.01, 0.99, 1.0), noise=(0.01,) * 3)
    rec = write_simulation(tmp_path / "six.csv", sensor, cube_directions("faces"), seed=3)
    js = tmp_path / "s.json"
    r = run_cli(["calibrate", "--data", rec.path, "--fix-angles", "--out", tmp_path / "o", "--no-figures",
                 "--json", js])
    assert r.code == 0, r.err
    assert "0 degrees of freedom: the standard errors cannot be estimated" in r.err
    d = json.loads(js.read_text())
    assert d["dof"] == 0 and all(v is None for v in d["std"]["s"] + d["std"]["b"])
    assert "+/- n/a (not estimable: 0 dof)" in (tmp_path / "o" / "report.txt").read_text()


@pytest.mark.parametrize("factor", [1e-6, 1e9, 1e12])
def test_the_unit_of_the_readings_does_not_change_the_answer(tmp_path, factor):
    d = xsens_array()
    ref = calibrate_file(real_file(*XSENS), gravity={"value": 9.81744}).result
    src = save(tmp_path / "k.txt", np.column_stack([d[:, 0], d[:, 1:] * factor]))
    res = calibrate_file(src, gravity={"value": 9.81744}).result
    assert res.success and res.status in CONVERGED and ref.status in CONVERGED  # which criterion stops IPOPT may differ
    for n, p in ref.params.items():
        k = factor if n[0] in "sb" else 1.0
        assert res.params[n].value / k == pytest.approx(p.value, rel=1e-9), n
        assert res.std[n] / k == pytest.approx(ref.std[n], rel=1e-6), n


def test_fixed_angles_are_named_in_the_model(tmp_path):
    sensor = SensorSpec(noise=(0.01,) * 3)
    rec = write_simulation(tmp_path / "ortho.csv", sensor, cube_directions(), seed=1)
    run = calibrate_file(rec.path, fit={"fix": ["phi", "psi", "theta"]})
    assert run.result.model_name == "nakov-ivanov-6"


# --- nothing is lost ---------------------------------------------------------------------------
@pytest.fixture
def work(tmp_path, si_recording):
    """A folder with a recording, a config and a calibration of it."""
    (tmp_path / "rec.csv").write_bytes(Path(si_recording.path).read_bytes())
    r = subprocess.run([sys.executable, "-m", "imucal", "calibrate", "--data", "rec.csv", "--out", "cal",
                        "--no-figures", "--quiet"], cwd=tmp_path, capture_output=True, text=True,
                       env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert r.returncode == 0, r.stderr
    return tmp_path


@pytest.mark.parametrize("args, culprit", [
    (["calibrate", "--data", "report.txt", "--out", "."], "would overwrite the input"),
    (["calibrate", "--data", "rec.csv", "--out", "o", "--json", "rec.csv"], "would overwrite the input"),
    (["calibrate", "--data", "rec.csv", "--out", "o", "--json", "o/calibration.yaml"], "is also the output"),
    (["calibrate", "calibration.yaml"], "would overwrite the input"),
    (["apply", "cal/calibration.yaml", "--data", "rec.csv", "--out", "rec.csv"], "would overwrite the input"),
    (["apply", "cal/calibration.yaml", "--data", "rec.csv", "--out", "cal/calibration.yaml"],
     "would overwrite the input"),
    (["codegen", "cal/x.c", "--out", "cal", "--prefix", "x"], "would overwrite the input"),
    (["discover", "--data", "rec.csv", "--json", "rec.csv"], "would overwrite the input"),
    (["simulate", "sim.yaml", "--out", "sim.yaml"], "would overwrite the input"),
    (["simulate", "sim.yaml", "--out", "s.csv", "--truth", "s.csv"], "is also the output"),
    (["worst-case", "--calibration", "cal/calibration.yaml", "--json", "cal/calibration.yaml"],
     "would overwrite the input"),
    (["plan-poses", "--evaluate", "plan.json", "--json", "plan.json"], "would overwrite the input"),
    (["drift", "--calibration", "cal/calibration.yaml", "--json", "cal/calibration.yaml"],
     "would overwrite the input"),
])
def test_outputs_never_overwrite_inputs(run_cli, work, unchanged, monkeypatch, args, culprit):
    monkeypatch.chdir(work)
    (work / "report.txt").write_bytes((work / "rec.csv").read_bytes())
    (work / "cal" / "x.c").write_bytes((work / "cal" / "calibration.yaml").read_bytes())
    (work / "calibration.yaml").write_text(yaml.safe_dump({"data": {"path": "rec.csv"}, "output": {"dir": "."}}))
    (work / "sim.yaml").write_text("seed: 1\n")
    (work / "plan.json").write_text(json.dumps({"poses": [[0, 0, 1], [1, 0, 0], [0, 1, 0]]}))
    with unchanged(work):
        r = run_cli(args)
    assert r.code == 2
    one_line_error(r.err, "output", culprit)


@pytest.mark.parametrize("kind", ["fifo", "dir", "symlink-to-fifo"])
def test_only_regular_files_are_replaced(run_cli, work, unchanged, kind):
    target = work / "target"
    if kind == "fifo":
        os.mkfifo(target)
    elif kind == "dir":
        target.mkdir()
    else:
        os.mkfifo(work / "fifo")
        target.symlink_to(work / "fifo")
    with unchanged(work):
        r = run_cli(["apply", work / "cal" / "calibration.yaml", "--data", work / "rec.csv", "--out", target])
    assert r.code == 2
    one_line_error(r.err, str(target), "output")


def test_outputs_follow_the_umask(run_cli, work):
    old = os.umask(0o022)
    try:
        r = run_cli(["apply", work / "cal" / "calibration.yaml", "--data", work / "rec.csv", "--out", work / "a.csv"])
        r2 = run_cli(["calibrate", "--data", work / "rec.csv", "--out", work / "c2", "--no-figures", "--quiet"])
    finally:
        os.umask(old)
    assert r.code == 0 and r2.code == 0
    assert (work / "a.csv").stat().st_mode & 0o777 == 0o644
    assert (work / "c2" / "calibration.yaml").stat().st_mode & 0o777 == 0o644


def test_write_error_is_one_line_and_publishes_nothing(run_cli, work, unchanged, monkeypatch):
    import errno

    real_replace = os.replace

    def full(src, dst, *a, **k):
        if str(dst).endswith("report.txt"):
            raise OSError(errno.ENOSPC, "No space left on device")
        return real_replace(src, dst, *a, **k)

    monkeypatch.setattr(os, "replace", full)
    with unchanged(work):
        r = run_cli(["calibrate", "--data", work / "rec.csv", "--out", work / "new", "--no-figures", "--quiet"])
    assert r.code == 2
    one_line_error(r.err, "report.txt", "cannot write: disk full")


def test_file_name_too_long_is_one_line(run_cli, work, unchanged):
    with unchanged(work):
        r = run_cli(["apply", work / "cal" / "calibration.yaml", "--data", work / "rec.csv",
                     "--out", work / ("x" * 300 + ".csv")])
    assert r.code == 2
    one_line_error(r.err, "file name too long")


def test_stale_staging_of_a_killed_run_is_removed(run_cli, work):
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True,
                          text=True).stdout.strip()
    stale = work / "cal" / f".imucal-{dead}-abcd"
    stale.mkdir()
    (stale / "calibration.yaml").write_text("half")
    r = run_cli(["calibrate", "--data", work / "rec.csv", "--out", work / "cal", "--no-figures", "--quiet"])
    assert r.code == 0 and not stale.exists()
    assert not list((work / "cal").glob(".imucal-*"))


def _imucal(args, cwd, **kw):
    return subprocess.Popen([sys.executable, "-m", "imucal", *map(str, args)], cwd=cwd, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            env={**os.environ, "PYTHONPATH": str(ROOT)}, **kw)


def test_a_reader_that_leaves_ends_the_run_quietly_with_its_files(work):
    """`imucal ... | head -1`: stdout's reader is gone before the report is printed. The run ends as a
    pipe tool killed by SIGPIPE (141), with no internal error and the files already written."""
    p = _imucal(["calibrate", "--data", "rec.csv", "--out", "piped", "--no-figures"], work)
    p.stdout.close()  # the reader leaves before anything is printed
    err = p.stderr.read()
    assert p.wait(timeout=120) == 141, err
    assert "internal error" not in err and "Traceback" not in err and "Exception ignored" not in err, err
    assert (work / "piped" / "calibration.yaml").is_file()


@pytest.mark.parametrize("nth", [1, 2, 3])
def test_a_signal_while_the_set_is_placed_leaves_the_old_set(work, monkeypatch, nth):
    """SIGTERM right after the nth file of the set is moved into place (of the calibration, its
    report and the JSON): the run says nothing was written, and the old files are all there, none
    replaced and none lost (an interrupt there deleted old files with the staging folder)."""
    import imucal.files.output as output

    out = work / "pub"
    out.mkdir()
    old = {out / "calibration.yaml": "old cal", out / "report.txt": "old report", work / "pub.json": "old json"}
    for f, text in old.items():
        f.write_text(text)
    real, moved = os.replace, []

    def replace(a, b):
        real(a, b)
        moved.append(b)
        if len(moved) == 2 * nth:  # each file: the old one to its backup, then the new one in place
            os.kill(os.getpid(), signal.SIGTERM)

    monkeypatch.setattr(output.os, "replace", replace)
    monkeypatch.chdir(work)
    assert main(["calibrate", "--data", "rec.csv", "--out", "pub", "--json", "pub.json", "--no-figures",
                 "--quiet"]) == 130, moved
    assert {f: f.read_text() for f in old} == old, moved
    assert not list(work.glob("**/.imucal-*")) and not list(work.glob("**/.previous-*"))


@pytest.mark.parametrize("when", ["after", "ignored"])
def test_a_signal_after_the_set_is_complete_or_ignored_keeps_the_new_set(tmp_path, monkeypatch, when):
    """A SIGINT while the staging is removed, after the set is in place, is dropped (the run is
    complete; it said "nothing was written" with the new files in place); an ignored SIGINT (a job
    started with &) stays ignored (it rolled the set back silently)."""
    import shutil

    import imucal.files.output as output

    (tmp_path / "a.txt").write_text("old")
    real_rm, real_replace, fired = shutil.rmtree, os.replace, []

    def rm(*a, **k):
        if not fired:
            fired.append(1)
            os.kill(os.getpid(), signal.SIGINT)
        return real_rm(*a, **k)

    def replace(a, b):
        real_replace(a, b)
        if not fired:
            fired.append(1)
            os.kill(os.getpid(), signal.SIGINT)

    before = signal.getsignal(signal.SIGINT)
    try:
        if when == "after":
            monkeypatch.setattr(output.shutil, "rmtree", rm)
        else:
            signal.signal(signal.SIGINT, signal.SIG_IGN)
            monkeypatch.setattr(output.os, "replace", replace)
        with output.OutputSet() as o:
            o.text(tmp_path / "a.txt", "new")
    finally:
        signal.signal(signal.SIGINT, before)
    assert fired and (tmp_path / "a.txt").read_text() == "new"
    assert not list(tmp_path.glob(".imucal-*"))


def test_sigterm_removes_staged_outputs(work):
    """SIGTERM while the figures are staged: exit 130, nothing published, no staging left. The staging lasts a
    fraction of a second on a quiet machine: up to five tries to catch it."""
    for _ in range(5):
        shutil.rmtree(work / "sig", ignore_errors=True)
        p = _imucal(["calibrate", "--data", "rec.csv", "--out", "sig"], work)
        deadline = time.time() + 60
        while time.time() < deadline and p.poll() is None:
            if (work / "sig").exists() and list((work / "sig").glob(".imucal-*")):
                p.send_signal(signal.SIGTERM)
                break
            time.sleep(0.001)
        _, err = p.communicate(timeout=60)
        if p.returncode != 0:
            break
    if p.returncode == 0:
        pytest.skip("five runs finished before they could be interrupted")
    assert p.returncode == 130, err
    assert "terminated by SIGTERM; nothing was written" in err and "Traceback" not in err
    assert not (work / "sig").exists() or not any((work / "sig").iterdir())


def test_two_runs_into_one_folder_publish_whole_sets(work):
    """Two concurrent runs with different gravity: the published set is one run's, whole."""
    runs = [_imucal(["calibrate", "--data", "rec.csv", "--out", "both", "--no-figures", "--quiet",
                     "--gravity", g, "--json", "both/summary.json"], work) for g in ("9.80", "9.83")]
    for p in runs:
        p.communicate(timeout=120)
        assert p.returncode == 0
    cal = yaml.safe_load((work / "both" / "calibration.yaml").read_text())
    summary = json.loads((work / "both" / "summary.json").read_text())
    assert cal["gravity"] == summary["gravity"]
    assert f"gravity            = {cal['gravity']:.6f}" in (work / "both" / "report.txt").read_text()


# --- never a traceback ---------------------------------------------------------------------------
def test_unexpected_exception_is_one_line_with_its_own_status(run_cli, monkeypatch, tmp_path):
    import imucal.cli.commands.drift as drift

    def boom(args):
        raise RuntimeError("x" * 5000)

    monkeypatch.setattr(drift, "run", boom)
    r = run_cli(["drift"])
    assert r.code == EXIT_INTERNAL == 3
    one_line_error(r.err, "imucal: internal error: RuntimeError:", "rerun with --debug for the traceback")
    assert len(r.err) < 400
    r = run_cli(["--debug", "drift"])
    assert r.code == 3 and "Traceback" in r.err


def test_height_without_latitude_is_refused(run_cli, si_recording, tmp_path):
    r = run_cli(["calibrate", "--data", si_recording.path, "--height", "500", "--out", tmp_path / "o"])
    assert r.code == 2
    one_line_error(r.err, "--height", "is used only with --latitude")


def test_discover_takes_the_same_gravity_options(run_cli, si_recording):
    r = run_cli(["discover", "--data", si_recording.path, "--latitude", "48.1", "--height", "500", "--quiet"])
    assert r.code == 0 and "verdict" in r.out


# --- apply fits the recording it calibrated --------------------------------------------------------
def test_apply_keeps_epoch_time_and_takes_the_column_map(run_cli, tmp_path):
    src = _imutk_seven_columns(tmp_path)
    d = np.loadtxt(src)
    stamps = (np.round((d[:, 0] - d[0, 0]) * 1e3) + 1700000000123).astype(np.int64)
    lines = [f"{s} " + " ".join(f"{v:.17g}" for v in row[1:]) for s, row in zip(stamps, d)]
    src.write_text("\n".join(lines) + "\n")
    cols = "t=0,ax=4,ay=5,az=6"
    r = run_cli(["calibrate", "--data", src, "--columns", cols, "--gravity", "9.81744", "--out", tmp_path / "c",
                 "--no-figures", "--quiet"])
    assert r.code == 0, r.err
    r = run_cli(["apply", tmp_path / "c" / "calibration.yaml", "--data", src, "--out", tmp_path / "a.csv"])
    assert r.code == 2 and "ambiguous" in r.err  # apply needs the same column map as calibrate
    r = run_cli(["apply", tmp_path / "c" / "calibration.yaml", "--data", src, "--columns", cols,
                 "--out", tmp_path / "a.csv"])
    assert r.code == 0, r.err
    out = (tmp_path / "a.csv").read_text().splitlines()
    assert out[0] == "t,ax,ay,az"
    assert [int(x.split(",")[0]) for x in out[1:4]] == stamps[:3].tolist()  # exactly as read
    a = np.loadtxt(tmp_path / "a.csv", delimiter=",", skiprows=1)
    assert np.median(np.linalg.norm(a[:, 1:], axis=1)) == pytest.approx(9.81744, abs=0.01)


def test_apply_reuses_a_run_files_data_section(run_cli, tmp_path):
    src = _imutk_seven_columns(tmp_path)
    cfg = tmp_path / "run.yaml"
    cfg.write_text(yaml.safe_dump({"data": {"path": "imu.txt", "columns": {"t": 0, "ax": 4, "ay": 5, "az": 6}},
                                   "gravity": {"value": 9.81744}}))
    assert run_cli(["calibrate", cfg, "--out", tmp_path / "c", "--no-figures", "--quiet"]).code == 0
    r = run_cli(["apply", tmp_path / "c" / "calibration.yaml", "--config", cfg, "--out", tmp_path / "a.csv"])
    assert r.code == 0, r.err
    assert len((tmp_path / "a.csv").read_text().splitlines()) == 51176


# --- every input used or refused; bounded resources ------------------------------------------------
BOMB = "".join(f"{c}: &{c} [" + ",".join([f"*{p}"] * 9) + "]\n" for p, c in zip("abcdefgh", "bcdefghi"))


@pytest.mark.parametrize("text, field, msg", [
    ("data: {path: a.csv}\ndata: {path: b.csv}\n", "config", "duplicate key 'data' at line 2"),
    ("a: &a [x, x, x, x, x, x, x, x, x]\n" + BOMB + "data: {path: *i}\n", "config",
     "more than 10 aliases (an alias bomb?)"),
    ("data: {path: a.csv, skip_rows: " + "9" * 400 + "}\n", "data.skip_rows", "integer is too large for a float"),
    ("data: {path: a.csv}\ngravity: {height: 300}\n", "gravity.height", "is used only with a latitude"),
    ("data: {path: a.csv}\nfit: {fix: 5}\n", "fit.fix", "is not a parameter name, a list of names or a mapping"),
    ("data: {path: a.csv}\nfit: {fix: {phi: .nan}}\n", "fit.fix.phi", "is not a finite number"),
    ("data: {path: a.csv, delimiter: ';;'}\n", "data.delimiter", "must be one character"),
])
def test_bad_run_files_are_refused_in_one_line(run_cli, tmp_path, unchanged, text, field, msg):
    cfg = tmp_path / "run.yaml"
    cfg.write_text(text)
    with unchanged():
        r = run_cli(["calibrate", cfg])
    assert r.code == 2
    one_line_error(r.err, field, msg)
    assert len(r.err) < 400


def test_fix_mapping_holds_the_parameter_at_the_value(tmp_path):
    run = calibrate_file(real_file(*XSENS), gravity={"value": 9.81744}, fit={"fix": {"phi": 1.58}})
    assert run.result.params["phi"].value == 1.58 and run.result.params["phi"].fixed
    assert run.result.model_name == "nakov-ivanov-9 (phi held fixed)"
    with pytest.raises(ImucalError, match=r"fit.fix.phi: phi = 1 rad is outside its bounds"):
        calibrate_file(real_file(*XSENS), fit={"fix": {"phi": 1}})


@pytest.mark.parametrize("args, field, msg", [
    (["worst-case", "--seed", "-1"], "seed", "must be an integer from 0 to"),
    (["worst-case", "--starts", "100000000"], "starts", "must be an integer from 1 to 10000"),
    (["error-map", "--angles", "1.5", "1.5", "1.5", "--samples", "10000000000", "--out", "em"], "samples",
     "must be an integer from 1000 to 20000000"),
    (["plan-poses", "--n", "12", "--seed", "-1"], "--seed", "must be an integer from 0 to"),
    (["drift", "--duration", "1e300"], "duration", "must be positive (at most 1e7 s)"),
])
def test_resource_bombs_are_refused_before_allocating(run_cli, tmp_path, unchanged, monkeypatch, args, field, msg):
    monkeypatch.chdir(tmp_path)
    with unchanged():
        r = run_cli(args)
    assert r.code == 2
    one_line_error(r.err, field, msg)


@pytest.mark.parametrize("plan, msg", [("{rate: 1.0e+9}", "is not an IMU sample rate"),
                                       ("{hold: 1.0e+8}", "samples, above the limit of 5e+07")])
def test_simulation_size_is_bounded(run_cli, tmp_path, unchanged, plan, msg):
    cfg = tmp_path / "sim.yaml"
    cfg.write_text(f"plan: {plan}\n")
    with unchanged():
        r = run_cli(["simulate", cfg, "--out", tmp_path / "s.csv"])
    assert r.code == 2
    one_line_error(r.err, "sim.yaml", msg)


def test_a_device_node_is_never_replaced(run_cli, work):
    """`--out /dev/null` as root replaced the device node; a node of our own stands in for it."""
    import stat as st

    node = work / "null"
    try:
        os.mknod(node, 0o666 | st.S_IFCHR, os.makedev(1, 3))
    except PermissionError:
        pytest.skip("mknod needs root")
    r = run_cli(["apply", work / "cal" / "calibration.yaml", "--data", work / "rec.csv", "--out", node])
    assert r.code == 2
    one_line_error(r.err, str(node), "output", "is a device: only regular files are replaced")
    assert st.S_ISCHR(node.stat().st_mode)


def test_the_finished_program_ignores_sigterm_until_it_exits(monkeypatch, tmp_path):
    """As the program (argv None), main leaves SIGTERM ignored: the interpreter's shutdown after a
    complete run took ~0.1 s with the default action back, and a signal then exited -15 (CI)."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "argv", ["imucal", "calibrate", "--data", "missing.csv", "--out", "o"])
    from imucal.errors import INTERRUPTING

    saved = {s: h for s in INTERRUPTING if (h := signal.getsignal(s)) is not None}  # left ignored: later subprocesses
    before = saved[signal.SIGTERM]
    try:
        assert main() == 2  # a refused run ends by the same path as a complete one
        assert signal.getsignal(signal.SIGTERM) is signal.SIG_IGN and signal.getsignal(signal.SIGHUP) is signal.SIG_IGN
        for s, h in saved.items():
            signal.signal(s, h)
        assert main(["calibrate", "--data", "missing.csv", "--out", "o"]) == 2  # from code: handler given back
        assert signal.getsignal(signal.SIGTERM) is before
    finally:
        for s, h in saved.items():
            signal.signal(s, h)


def _wait_until_caught(p: subprocess.Popen, sig: int, limit: float = 60.0) -> None:
    """Until process ``p`` catches ``sig`` (its SigCgt mask in /proc: main() has set its handlers), so a
    signal sent after it reaches the run, not an interpreter still importing on a loaded machine."""
    status = Path(f"/proc/{p.pid}/status")
    if not status.exists():
        return  # no /proc: the delay alone
    deadline = time.monotonic() + limit
    while p.poll() is None and time.monotonic() < deadline:
        try:
            masks = [ln.split()[1] for ln in status.read_text().splitlines() if ln.startswith("SigCgt:")]
        except OSError:  # it ended meanwhile
            return
        if masks and int(masks[0], 16) >> (sig - 1) & 1:
            return
        time.sleep(0.005)


@pytest.mark.parametrize("delay", [0.3, 0.5, 0.7])
def test_sigterm_at_any_moment_is_an_interruption_never_an_internal_error(work, delay):
    """A signal inside CasADi's C code comes back as SystemError with the interrupt in its context."""
    p = _imucal(["calibrate", "--data", "rec.csv", "--out", "s"], work)
    _wait_until_caught(p, signal.SIGTERM)  # the run has begun: before, the interpreter is still starting
    time.sleep(delay)
    p.send_signal(signal.SIGTERM)
    _, err = p.communicate(timeout=60)
    assert p.returncode in (0, 130), err
    assert "internal error" not in err and "Traceback" not in err
    if p.returncode == 130:
        assert not (work / "s").exists() or not any((work / "s").iterdir())
