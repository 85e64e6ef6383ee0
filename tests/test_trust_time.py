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
from imucal.data.load import load_recording
from imucal.data.spec import DataSpec
from imucal.errors import ImucalError

ROOT = Path(__file__).resolve().parents[1]


def one_line_error(err: str, *parts: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("imucal: error: "), err
    for p in parts:
        assert p in lines[0], (p, lines[0])
    return lines[0]


def refused(run_cli, unchanged, args: list, *parts: str) -> str:
    """``imucal ARGS`` changes nothing, exits 2 and says one line holding ``parts``."""
    with unchanged():
        res = run_cli(args)
    assert res.code == 2
    return one_line_error(res.err, *parts)


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
    "calibrate-stream": lambda lp, cal, w: ["calibrate", "--data", lp, "--stream", "always", "--out", w / "o"],
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
    from imucal.data.lines import MAX_LINE_BYTES

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


# --- time stamps: jitter, gaps, one rate ------------------------------------------------------------
def bursty_stamps(true: np.ndarray, seed: int, poll: float = 0.011, within: float = 4e-4,
                  latency: float = 0.002) -> np.ndarray:
    """A logger that polls a sampler's FIFO every ``poll`` s (+-20 %) and stamps what it finds on
    arrival, ``within`` s apart: steps of about ``poll``, and about 10 % under 0.8 ms."""
    rng = np.random.default_rng(seed)
    polls = np.cumsum(rng.uniform(0.8, 1.2, int(true[-1] / poll * 1.3) + 10) * poll)
    at = np.searchsorted(polls, true + latency)  # the first poll after the sample is ready
    first = np.r_[True, at[1:] != at[:-1]]
    rank = np.arange(true.size) - np.flatnonzero(first)[np.cumsum(first) - 1]
    return polls[at] + rank * within


def with_stamps(src: Path, dst: Path, stamps: np.ndarray, fmt: str = "%.6f") -> Path:
    """``src`` (t, ax, ay, az CSV) with its time column replaced."""
    d = np.loadtxt(src, delimiter=",", skiprows=1)
    d[:, 0] = stamps
    np.savetxt(dst, d, delimiter=",", fmt=[fmt, "%.0f", "%.0f", "%.0f"], header="t,ax,ay,az", comments="")
    return dst


def streamed(path: Path, **spec):
    from imucal.data.stream import StreamedRecording

    return StreamedRecording(DataSpec(path=str(path), **spec), keep_samples=True)


def same_time_base(a, b) -> None:
    """The whole-file and the chunked reader's time bases agree field by field."""
    assert (a.source, a.rate, a.longest_gap_line, a.short_fraction, a.median_step, a.rate_given) == (
        b.source, b.rate, b.longest_gap_line, b.short_fraction, b.median_step, b.rate_given)
    np.testing.assert_array_equal(a.gap_index, b.gap_index)
    np.testing.assert_array_equal(a.gap_seconds, b.gap_seconds)


@pytest.fixture
def small_chunks(monkeypatch):
    """Blocks of a few hundred lines: every file spans many of them (as tests/test_stream.py)."""
    import imucal.data.blocks as blocks_mod
    import imucal.data.spill as spill_mod

    monkeypatch.setattr(blocks_mod, "CHUNK_BYTES", 20_000)
    monkeypatch.setattr(spill_mod, "SPILL_ROWS", 997)


@pytest.fixture
def bursty(tmp_path):
    """A 100 Hz recording stamped by a bursty logger that paused for 2 s in a transition; the clean
    file (true sample times) beside it."""
    r = simulated(tmp_path, "clean.csv")
    n = r.sim.t.size
    pause = int(r.sim.hold_bounds[12, 1] + 20)  # in the motion after pose 12
    true = np.arange(n) * 0.01 + np.where(np.arange(n) >= pause, 2.0, 0.0)
    clean = with_stamps(r.path, tmp_path / "clean.csv", true)
    return clean, with_stamps(r.path, tmp_path / "bursty.csv", bursty_stamps(true, seed=1)), true, pause


def test_bursty_stamps_are_jitter_and_are_retimed_on_a_fitted_clock(bursty, small_chunks):
    clean, path, true, pause = bursty
    stamps = np.loadtxt(path, delimiter=",", skiprows=1)[:, 0]
    d = np.diff(stamps)
    assert np.mean(d < 8e-4) > 0.08 and np.median(d) > 0.0105  # the audit's logger: bursts, median 11 ms
    rec = load_recording(path)
    tb = rec.time_base
    assert tb.source.value == "clock" and tb.short_fraction == pytest.approx(np.mean(d < 0.0025), abs=1e-12)
    assert rec.time_note == f"time unit inferred: s (clock step {1 / rec.sample_rate:g} -> 100 Hz)"
    assert rec.sample_rate == pytest.approx(100.0, rel=5e-5)  # one rate: the clock's (the median step's is 93 Hz)
    # the logger's pause is kept as a gap: 2 s plus one step, named at its line (header + 1-based)
    assert tb.gap_index.tolist() == [pause] and tb.longest_gap_line == pause + 2
    assert tb.gap_seconds[0] == pytest.approx(2.01, abs=2e-3)
    # the clean clock steps as the true sample times do; the stamps' steps were off by up to 11 ms
    err = np.delete(np.diff(rec.t) - np.diff(true), pause - 1)
    assert np.abs(err).max() < 1e-6 and np.abs(np.delete(d - np.diff(true), pause - 1)).max() > 0.009
    assert np.ptp(rec.t - (true - true[0])) < 3e-3  # and over the whole recording, across the gap
    np.testing.assert_array_equal(rec.t_source, stamps)  # the stamps as read are kept (apply writes them back)
    # the chunked reader: the same time base, times and intervals
    s = streamed(path)
    same_time_base(tb, s.recording.time_base)
    assert (s.recording.time_note, s.recording.sample_rate, s.recording.t_last) == (rec.time_note,
                                                                                      rec.sample_rate, rec.t[-1])
    from imucal.data.static import detect_static

    iv = detect_static(rec.t, rec.raw)
    np.testing.assert_array_equal(iv.start, s.intervals.start)
    np.testing.assert_array_equal(iv.t_start, s.intervals.t_start)


def test_bursty_stamps_calibrate_as_the_true_times_and_report_one_rate(bursty, run_cli, tmp_path):
    clean, path, true, pause = bursty
    runs = {}
    for name, src in (("clean", clean), ("bursty", path)):
        out = tmp_path / f"o_{name}"
        r = run_cli(["calibrate", "--data", src, "--out", out, "--no-figures", "--quiet"])
        assert r.code == 0, r.err
        runs[name] = yaml.safe_load((out / "calibration.yaml").read_text()), (out / "report.txt").read_text()
        html = (out / "report.html").read_text()  # both have the pause; the bursty one is re-timed
        assert "<td>time base</td>" in html and ("re-timed on a clock fitted" in html) == (name == "bursty")
    (c, _), (b, report) = runs["clean"], runs["bursty"]
    assert b["fit"]["n_intervals"] == c["fit"]["n_intervals"] == 26
    for k, v in c["parameters"].items():
        assert b["parameters"][k]["value"] == pytest.approx(v["value"], rel=1e-9, abs=1e-12), k
    # one rate, the clock's, in the data line, the time note and the time base (before: 98.3 Hz from the
    # span, 92.7 Hz from the median step)
    rate = f"{load_recording(path).sample_rate:.4g} Hz"
    head = report.split("[[Fit Statistics]]")[0]
    assert rate == "100 Hz" and __import__("re").findall(r" ([0-9.]+ Hz)", head) == [rate] * 3, head
    assert (f"samples, 117.5 s, {rate}, unit raw)" in head and f"(clock step 0.00999984 -> {rate})" in head
            and "    time base          = the time stamps are jitter (10.7 % of their steps are shorter than 0.25 of "
                "the sample step, median step 10.8 ms): the samples are re-timed on a clock fitted to the stamps, "
                f"{rate}; 1 gap(s) in the time stamps (samples missing: steps over 1.5 sample steps that the later "
                "stamps do not make up) kept as gaps, the longest "
                f"2.01 s at line {pause + 2}" in head), head


def test_the_gyroscope_integrates_on_the_clean_clock(tmp_path):
    """A hand-held gyro session stamped by the bursty logger: on the re-timed clock the gyro fit is
    the true times' fit; on the stamps as read (what the readers gave before) it is worse."""
    import dataclasses

    from imucal.config.run import config_from_dict
    from imucal.gyro.result import motions
    from imucal.gyro.simulate import GyroTruth, hand_held
    from imucal.pipeline import calibrate_imu

    truth = GyroTruth(bias=np.array([0.01, -0.02, 0.005]), scale=np.array([1.01, 0.99, 1.005]),
                      mis=np.array([1e-3, -2e-3, 3e-3, 0.0, 1e-3, -1e-3]), gsens=np.zeros((3, 3)), noise=0.003)
    d = hand_held(truth, n_poses=20, seed=3, unit="rad/s", still=(3.0, 4.0))
    errors = {}
    for name, t in (("true", d.t), ("bursty", bursty_stamps(d.t, seed=1))):
        p = tmp_path / f"{name}.csv"
        np.savetxt(p, np.column_stack([t, d.acc, d.gyro]), fmt="%.9f", delimiter=",",
                   header="t,ax,ay,az,gx,gy,gz", comments="")
        cfg = config_from_dict({"data": {"path": str(p), "unit": "m/s^2", "gyro_unit": "rad/s"},
                                "gravity": {"value": 9.81}})
        rec = load_recording(cfg.data)
        errors[name] = motions(calibrate_imu(cfg, rec).gyro).rms_direction_error_deg["after"]
        if name == "bursty":
            assert rec.time_base.source.value == "clock"
            as_read = dataclasses.replace(rec, t=rec.t_source - rec.t_source[0], time_base=None)
            errors["as read"] = motions(calibrate_imu(cfg, as_read).gyro).rms_direction_error_deg["after"]
    assert errors["bursty"] == pytest.approx(errors["true"], rel=0.02)
    assert errors["as read"] > 2 * errors["true"], errors


@pytest.mark.parametrize("how", STREAM_HOW)
def test_good_stamps_are_left_exactly_and_their_gaps_named(tmp_path, how, small_chunks):
    """Stamps with a crystal's scatter (0.1 step rms) and two dropped samples: no jitter; the times
    are the stamps as read, to the bit; the two gaps are listed."""
    r = simulated(tmp_path)
    n = r.sim.t.size
    rng = np.random.default_rng(5)
    true = np.arange(n) * 0.01
    true[3000:] += 0.01  # one sample lost ...
    true[7000:] += 0.02  # ... then two
    stamps = 1.7e3 + true + rng.normal(0, 1e-3, n)
    path = with_stamps(r.path, tmp_path / "good.csv", stamps, fmt="%.7f")
    read = np.loadtxt(path, delimiter=",", skiprows=1)[:, 0]
    rec = load_recording(path)
    tb = rec.time_base
    np.testing.assert_array_equal(rec.t, read - read[0])
    assert tb.source.value == "stamps" and tb.short_fraction == 0.0 and rec.time_note.startswith(
        "time unit inferred: s (median step 0.01")
    assert tb.gap_index.tolist() == [3000, 7000] and tb.longest_gap_line == 7002
    np.testing.assert_allclose(tb.gap_seconds, read[[3000, 7000]] - read[[2999, 6999]])
    if how == "always":
        same_time_base(tb, streamed(path).recording.time_base)


# --- a sample rate beside a time column ------------------------------------------------------------
@pytest.mark.parametrize("how", STREAM_HOW)
@pytest.mark.parametrize("where", ["option", "yaml"])
def test_sample_rate_disagreeing_with_the_time_column_is_refused(tmp_path, run_cli, unchanged, how, where):
    """Before: --sample-rate dropped the time column silently (a gyro scale of 2.0 for a true 1.0
    at half the rate). Now both are read and compared."""
    r = simulated(tmp_path)
    if where == "option":
        args = ["calibrate", "--data", r.path, "--sample-rate", "50", "--stream", how]
    else:
        run = tmp_path / "run.yaml"
        run.write_text(yaml.safe_dump({"data": {"path": r.path.name, "sample_rate": 50, "stream": how}}))
        args = ["calibrate", run]
    with unchanged():
        res = run_cli([*args, "--out", tmp_path / "o"])
    assert res.code == 2
    one_line_error(res.err, "sim.csv: data.sample_rate: sample rate 50 Hz given, but the time column t steps at 100 Hz "
                            "(median step 0.01 s): two sources of time disagree",
                   "(fix: drop --sample-rate (data.sample_rate) to use the time column, or map the right time column "
                   "(--columns t=...); they may differ by 5 %)")


@pytest.mark.parametrize("how", STREAM_HOW)
def test_sample_rate_agreeing_with_the_time_column_is_checked_and_named(tmp_path, run_cli, how):
    r = simulated(tmp_path)
    js = tmp_path / "s.json"
    res = run_cli(["calibrate", "--data", r.path, "--sample-rate", "102", "--stream", how, "--out", tmp_path / "o",
                   "--no-figures", "--quiet", "--json", js])
    assert res.code == 0, res.err
    report = (tmp_path / "o" / "report.txt").read_text()
    assert ("time base          = the sample rate given, 102 Hz, agrees with the time column (100 Hz)"
            in report)
    rec = load_recording(DataSpec(path=str(r.path), sample_rate=102.0))
    np.testing.assert_array_equal(rec.t, load_recording(r.path).t)  # the stamps are the time base


def test_sample_rate_and_time_in_the_library_are_checked_too():
    from imucal.api import recording_from_arrays

    t = np.arange(300) * 0.01
    acc = np.tile([0.0, 0.0, 9.81], (300, 1))
    with pytest.raises(ImucalError, match="sample rate 200 Hz given, but the time column t steps at 100 Hz"):
        recording_from_arrays(acc, t=t, fs=200.0)
    assert recording_from_arrays(acc, t=t, fs=100.0).time_base.rate_given == 100.0


def test_a_given_rate_reads_the_unit_of_a_time_column():
    """A rate given beside stamps in minutes (which are never inferred) names their unit."""
    from imucal.api import recording_from_arrays

    acc = np.tile([0.0, 0.0, 9.81], (300, 1))
    rec = recording_from_arrays(acc, t=np.arange(300) * 0.01 / 60, fs=100.0)
    assert rec.time_unit == "min" and rec.time_note.endswith("-> 100 Hz, the sample rate given)")


# --- fractional milliseconds, ambiguous steps ------------------------------------------------------
@pytest.mark.parametrize("how", STREAM_HOW)
def test_fractional_millisecond_stamps_at_1khz_are_read_as_ms(tmp_path, how, small_chunks):
    """A 1 kHz sensor whose clock runs 0.05 % fast, stamped in ms with sub-ms digits (step 0.9995):
    read as ms (1000.5 Hz), not as seconds at 1 Hz; the intervals those of the same stamps in s."""
    r = simulated(tmp_path, rate=1000.0, transition=1.0)
    k = np.arange(r.sim.t.size)
    ms = with_stamps(r.path, tmp_path / "ms.csv", 12.25 + 0.9995 * k, fmt="%.4f")
    s = with_stamps(r.path, tmp_path / "s.csv", (12.25 + 0.9995 * k) / 1e3, fmt="%.7f")
    if how == "never":
        rec = load_recording(ms)
        assert rec.time_unit == "ms" and rec.time_note == ("time unit inferred: ms (median step 0.9995 -> 1001 Hz; "
                                                           "s would give 1.001 Hz: give --time-unit if that is right)")
        assert rec.sample_rate == pytest.approx(1000.5)
        from imucal.data.static import detect_static

        a, b = detect_static(rec.t, rec.raw), detect_static(load_recording(s).t, rec.raw)
    else:
        a, b = streamed(ms).intervals, streamed(s).intervals
        assert streamed(ms).recording.time_unit == "ms"
    assert a.n == 26
    np.testing.assert_array_equal(a.start, b.start)
    np.testing.assert_array_equal(a.end, b.end)


@pytest.mark.parametrize("how", STREAM_HOW)
def test_a_step_that_cannot_tell_two_units_apart_is_refused(tmp_path, run_cli, unchanged, how):
    """A step of 0.2: 5 kHz in ms or 5 Hz in s, equally far from an IMU's usual rates."""
    src = tmp_path / "r.csv"
    src.write_text("t,ax,ay,az\n" + "".join(f"{0.2 * k:.1f},1,2,{16384 + k % 3}\n" for k in range(400)))
    refused(run_cli, unchanged, ["calibrate", "--data", src, "--stream", how, "--out", tmp_path / "o"],
            "r.csv: data.time_unit: the time stamps step by 0.2: 5000 Hz in ms or 5 Hz in s, which "
            "the step alone cannot tell apart (fix: give --time-unit ms or --time-unit s (data.time_unit))")
    assert load_recording(DataSpec(path=str(src), time_unit="s")).sample_rate == pytest.approx(5.0)


# --- refusals that name the real problem ----------------------------------------------------------
@pytest.mark.parametrize("how", STREAM_HOW)
def test_time_in_minutes_is_named(tmp_path, run_cli, unchanged, how):
    """Before: "record 12 to 50 orientations" (or no static interval). The poses are found when the
    stamps are read in minutes, and the message says so; --time-unit min then calibrates."""
    r = simulated(tmp_path)
    src = with_stamps(r.path, tmp_path / "min.csv", r.sim.t / 60.0, fmt="%.9f")
    with unchanged():
        res = run_cli(["calibrate", "--data", src, "--stream", how, "--out", tmp_path / "o"])
    assert res.code == 2
    one_line_error(res.err, "min.csv: data.time_unit: the time column read in s gives 6000 Hz and 0 still pose(s); "
                            "read in min it gives 100 Hz and 26 distinct still poses: the time unit looks like minutes "
                            "(fix: give --time-unit min (data.time_unit: min), or write the time column in seconds)")
    js = tmp_path / "s.json"
    res = run_cli(["calibrate", "--data", src, "--stream", how, "--time-unit", "min", "--out", tmp_path / "o",
                   "--no-figures", "--quiet", "--json", js])
    assert res.code == 0, res.err


@pytest.mark.parametrize("how", STREAM_HOW)
@pytest.mark.parametrize("lost", [False, True])
def test_a_one_hertz_log_in_seconds_is_named_and_its_lost_samples_do_not_refuse_it(tmp_path, run_cli, unchanged,
                                                                                   how, lost):
    """A temperature logger's 1 Hz stamps in seconds: a step of 1 is inferred as milliseconds (1 kHz, the more usual
    rate), where no pose is still; before: "no static intervals found". Now the seconds are named (at least
    HINT_MIN_POSES_LESS_USUAL poses read in s). With every 10th sample lost, --time-unit s was refused ("0.9014 Hz,
    not an IMU sample rate ... looks like ms": the clock's span median counts the lost samples); the good stamps'
    own step is 1 s, so it calibrates."""
    r = simulated(tmp_path)
    keep = (np.arange(r.sim.t.size) % 10 != 9) if lost else np.ones(r.sim.t.size, bool)
    src = with_stamps(r.path, tmp_path / "all.csv", np.round(r.sim.t * 100.0))
    d = np.loadtxt(src, delimiter=",", skiprows=1)[keep]
    src = tmp_path / "hz.csv"
    np.savetxt(src, d, delimiter=",", fmt=["%.0f", "%.0f", "%.0f", "%.0f"], header="t,ax,ay,az", comments="")
    refused(run_cli, unchanged, ["calibrate", "--data", src, "--stream", how, "--out", tmp_path / "o"],
            "hz.csv: data.time_unit: the time column read in ms gives 1000 Hz and 0 still pose(s); "
            "read in s it gives 1 Hz and 26 distinct still poses: the time unit looks like seconds "
            "(fix: give --time-unit s (data.time_unit: s))")
    res = run_cli(["calibrate", "--data", src, "--stream", how, "--time-unit", "s", "--out", tmp_path / "o",
                   "--no-figures", "--quiet"])
    assert res.code == 0, res.err
    assert yaml.safe_load((tmp_path / "o" / "calibration.yaml").read_text())["fit"]["n_intervals"] == 26
    report = (tmp_path / "o" / "report.txt").read_text()
    assert "s, 1 Hz, unit raw)" in report  # the sample rate, not the clock's 0.9 Hz with the lost samples in it
    assert ("gap(s) in the time stamps (samples missing" in report) == lost  # the lost samples are named


def test_a_single_pose_on_a_wrong_time_scale_is_not_called_minutes(tmp_path, run_cli):
    """One pose tapped every 10 s (a noise log): read in minutes it splits into runs between the
    taps, but all point one way, so minutes are not named."""
    from imucal.data.static import detect_static
    from imucal.data.unit_hint import HINT_MIN_POSES

    n = 18000
    rng = np.random.default_rng(2)
    raw = rng.normal(0, 4, (n, 3)).round() + [10, -20, 16384]
    tap = (np.arange(n) % 1000) < 20
    raw[tap] += rng.normal(0, 3000, (tap.sum(), 3)).round()
    src = tmp_path / "still.csv"
    np.savetxt(src, np.column_stack([np.arange(n) * 0.01 / 60, raw]), delimiter=",",
               fmt=["%.9f", "%.0f", "%.0f", "%.0f"], header="t,ax,ay,az", comments="")
    runs = detect_static(load_recording(src).t * 60, raw)
    assert runs.n > HINT_MIN_POSES  # the runs between taps, read in minutes: one direction
    res = run_cli(["calibrate", "--data", src, "--out", tmp_path / "o"])
    assert res.code == 2 and "minutes" not in res.err, res.err
    assert "only one static interval found: the log holds a single still pose" in res.err


@pytest.mark.parametrize("how", STREAM_HOW)
def test_a_five_hour_gap_is_kept_and_named_not_read_as_a_wrong_unit(tmp_path, run_cli, how):
    """Before: "give --time-unit ms" (the span's rate, 0.6 Hz). The stamps' step gives 100 Hz; the
    pause is a gap, named in the report with its line, and the poses on both sides are found."""
    r = simulated(tmp_path)
    t = r.sim.t.copy()
    cut = int(r.sim.hold_bounds[13, 1] + 30)  # in a motion
    t[cut:] += 5 * 3600.0
    src = with_stamps(r.path, tmp_path / "gap.csv", t)
    res = run_cli(["calibrate", "--data", src, "--stream", how, "--out", tmp_path / "o", "--no-figures", "--quiet"])
    assert res.code == 0, res.err
    report = (tmp_path / "o" / "report.txt").read_text()
    assert ("time base          = 1 gap(s) in the time stamps (samples missing: steps over 1.5 sample steps that the "
            "later stamps do not make up) kept as gaps, "
            f"the longest 5 h at line {cut + 2}") in report
    assert "100 Hz, unit raw)" in report and yaml.safe_load(
        (tmp_path / "o" / "calibration.yaml").read_text())["fit"]["n_intervals"] == 26


@pytest.mark.parametrize("kind", ["bursty", "good"])
def test_gaps_do_not_depend_on_how_the_stamps_are_split(kind):
    """GapFinder (the chunked reader feeds it a block at a time) finds the same gaps, to the bit,
    whatever the blocks: every step is judged on the same windows."""
    from imucal.data.timebase import GapFinder, decide, step_stats

    rng = np.random.default_rng(4)
    n = 5000
    true = np.arange(n) * 0.01
    for at, pause in ((700, 0.01), (710, 0.05), (2500, 3.0), (4960, 0.2)):  # two close together, one near the end
        true[at:] += pause
    stamps = bursty_stamps(true, seed=3) if kind == "bursty" else true + rng.normal(0, 5e-4, n)
    dec = decide(step_stats(stamps), "auto", None, "t", Path("x"))
    assert dec.jittered == (kind == "bursty")
    whole = GapFinder(dec)
    whole.add(stamps)
    want = whole.finish()
    assert want[0].size >= 3 and 2500 in want[0]
    for trial in range(5):
        cuts = np.sort(rng.choice(np.arange(1, n), size=rng.integers(1, 60), replace=False))
        parts = GapFinder(dec)
        for block in np.split(stamps, cuts):
            parts.add(block)
        got = parts.finish()
        np.testing.assert_array_equal(got[0], want[0])
        np.testing.assert_array_equal(got[1], want[1])


@pytest.mark.parametrize("how", STREAM_HOW)
def test_stamps_rounded_coarser_than_their_step_give_one_rate(tmp_path, how, small_chunks):
    """A 300 Hz sensor stamped in whole milliseconds (steps 3, 3, 4, ...): the median step says
    333 Hz, the clock 300 Hz. Before, the report printed both; now the note and the rate are the
    clock's, and the stamps (no jitter: no step under a quarter of the clock's) are kept as read."""
    n = 3000
    stamps = np.round(np.arange(n) * 10 / 3 + 5000)
    src = tmp_path / "ms.csv"
    src.write_text("t,ax,ay,az\n" + "".join(f"{s:.0f},1,2,{16384 + k % 3}\n" for k, s in enumerate(stamps)))
    rec = load_recording(src) if how == "never" else streamed(src).recording
    assert rec.time_unit == "ms" and rec.sample_rate == pytest.approx(300.0, rel=1e-4)
    assert rec.time_note.startswith("time unit inferred: ms (clock step 3.33") and "-> 300 Hz" in rec.time_note
    assert rec.time_base.source.value == "stamps" and rec.time_base.n_gaps == 0
    if how == "never":
        np.testing.assert_array_equal(rec.t, (stamps - stamps[0]) * 1e-3)
