"""Issue 25: a gap in the time stamps inside a gyroscope motion (samples missing: a logger's pause)
cannot be integrated. The motion is left out of the gyro fit and named (report, JSON, calibration
file); too few motions left is one line, exit 2, nothing written. Before, a 0.5 s gap inside one
motion skewed the scales by several standard errors with exit 0.

Every recording is simulated here (imucal.gyro.simulate) with known truth."""
from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
import yaml

from imucal.gyro.result import arrays, motions
from imucal.gyro.fit import GyroOptions, fit_gyro
from imucal.gyro.segments import GyroData, gap_spans, motion_segments
from imucal.gyro.simulate import GyroTruth, hand_held

TRUTH = GyroTruth(bias=np.array([0.01, -0.02, 0.005]), scale=np.array([1.01, 0.99, 1.005]),
                  mis=np.array([1e-3, -2e-3, 3e-3, 0.0, 1e-3, -1e-3]), gsens=np.zeros((3, 3)), noise=0.003)
#: [samples] cut out of a motion: 0.5 s at the simulation's 100 Hz
CUT = 50
MOTION = 2


def session(seed: int = 3, n_poses: int = 20) -> GyroData:
    return hand_held(TRUTH, n_poses=n_poses, seed=seed, unit="rad/s", still=(3.0, 4.0))


def cut_rows(d: GyroData, motions: list[int], n: int = CUT) -> np.ndarray:
    """Row indices of ``d`` less ``n`` samples from the middle of each motion in ``motions``."""
    keep = np.ones(d.t.size, bool)
    for k in motions:
        mid = (d.end[k] + d.start[k + 1]) // 2
        keep[mid - n // 2:mid + n - n // 2] = False
    return np.flatnonzero(keep)


def write_csv(d: GyroData, rows: np.ndarray, path) -> None:
    np.savetxt(path, np.column_stack([d.t[rows], d.acc[rows], d.gyro[rows]]), delimiter=",",
               header="t,ax,ay,az,gx,gy,gz", comments="", fmt="%.10g")


def calibrate_args(src, out, *more) -> list:
    return ["calibrate", "--data", src, "--unit", "m/s^2", "--gyro-unit", "rad/s", "--gravity", "9.81",
            "--out", out, "--no-figures", *more]


# --- the rule: a motion holding a gap is no motion segment ---------------------------------------
def test_a_motion_with_a_gap_is_left_out_and_named():
    d = session()
    i = (d.end[MOTION] + d.start[MOTION + 1]) // 2
    t = d.t.copy()
    t[i:] += 0.5  # samples missing from i on: the step into i is a gap
    seg = motion_segments(replace(d, t=t, gaps=gap_spans(t, [i])))
    assert seg.n == d.n_intervals - 2 and MOTION not in seg.index.tolist()
    (g,) = seg.gapped
    assert (g.segment, g.n_gaps) == (MOTION, 1) and g.longest_gap == pytest.approx(0.51)
    assert g.t_start == t[d.end[MOTION] - 1] and g.t_end == t[d.start[MOTION + 1]]


def test_a_gap_inside_a_still_pose_leaves_every_motion():
    """Only the steps a motion integrates matter: a gap in the middle of a still pose (beyond any
    lead-in) costs no motion."""
    d = session()
    i = (d.start[MOTION] + d.end[MOTION]) // 2
    seg = motion_segments(replace(d, gaps=gap_spans(d.t, [i])), lead_in=0.5)
    assert seg.n == d.n_intervals - 1 and seg.gapped == ()


def test_a_gap_at_the_edge_of_a_lead_in_is_inside_the_motion():
    """With a lead-in the motion is integrated from inside the still pose: a gap there is inside it."""
    d = session()
    i = d.end[MOTION] - 10  # 0.1 s before the pose ends: inside a 0.5 s lead-in
    assert motion_segments(replace(d, gaps=gap_spans(d.t, [i]))).gapped == ()
    (g,) = motion_segments(replace(d, gaps=gap_spans(d.t, [i])), lead_in=0.5).gapped
    assert g.segment == MOTION


# --- end to end: the gap that skewed the scales ------------------------------------------------
def test_a_gap_inside_a_motion_no_longer_skews_the_gyro_fit(run_cli, tmp_path):
    d = session()
    write_csv(d, np.arange(d.t.size), tmp_path / "whole.csv")
    write_csv(d, cut_rows(d, [MOTION]), tmp_path / "gap.csv")
    js = {}
    for name in ("whole", "gap"):
        r = run_cli(calibrate_args(tmp_path / f"{name}.csv", tmp_path / name, "--json", tmp_path / f"{name}.json"))
        assert r.code == 0, r.err
        js[name] = json.loads((tmp_path / f"{name}.json").read_text())["gyro"]
    whole, gap = js["whole"], js["gap"]
    assert whole["gap_motions"] == [] and whole["fit"]["n_segments"] == d.n_intervals - 1
    (g,) = gap["gap_motions"]
    assert gap["fit"]["n_segments"] == d.n_intervals - 2 and g["n_gaps"] == 1
    assert g["longest_gap"] == pytest.approx((CUT + 1) * 0.01, abs=1e-6)
    mid = d.t[(d.end[MOTION] + d.start[MOTION + 1]) // 2]  # the gap lies inside the motion named
    assert d.t[d.end[MOTION] - 1] - 0.5 <= g["t_start"] < mid < g["t_end"] <= d.t[d.start[MOTION + 1]] + 0.5
    # the fit without that motion: the truth within its standard errors, the whole recording's error
    scale, sd = np.array(gap["scale"]), np.array(gap["std"]["scale"])
    assert np.all(np.abs(scale - TRUTH.scale) < 4 * sd), (scale, sd)
    after = {k: v["rms_direction_error_deg"]["after"] for k, v in js.items()}
    assert after["gap"] == pytest.approx(after["whole"], rel=0.2), after
    # said in the report, and kept in the calibration file
    line = f"    {g['t_start']:.2f}..{g['t_end']:.2f} s: 1 gap(s), the longest {g['longest_gap']:.3g} s"
    report = (tmp_path / "gap" / "report.txt").read_text()
    assert "  motions left out: 1, each with a gap in the time stamps inside it" in report and line in report
    f = yaml.safe_load((tmp_path / "gap" / "calibration.yaml").read_text())
    assert f["gyroscope"]["fit"]["gap_motions"] == [g] and "gap_motions" not in yaml.safe_load(
        (tmp_path / "whole" / "calibration.yaml").read_text())["gyroscope"]["fit"]


def test_the_gap_skewed_the_fit_when_integrated_across():
    """What the rule prevents, on the same data: integrating across the gap (the samples as read,
    no gap known) moves the scales and the direction error well beyond the fit without it."""
    d = session()
    rows = cut_rows(d, [MOTION])
    cut = replace(d, t=d.t[rows], gyro=d.gyro[rows], acc=d.acc[rows],
                  start=np.searchsorted(rows, d.start), end=np.searchsorted(rows, d.end))
    gap = int(np.flatnonzero(np.diff(rows) > 1)[0]) + 1
    blind, kept = fit_gyro(cut, GyroOptions()), fit_gyro(replace(cut, gaps=gap_spans(cut.t, [gap])), GyroOptions())
    assert motions(blind).gapped == () and [g.segment for g in motions(kept).gapped] == [MOTION]
    assert np.max(np.abs(arrays(blind).scale - TRUTH.scale) / arrays(kept).scale_std) > 10
    assert np.all(np.abs(arrays(kept).scale - TRUTH.scale) < 4 * arrays(kept).scale_std)
    assert motions(blind).rms_direction_error_deg["after"] > 5 * motions(kept).rms_direction_error_deg["after"]


def test_a_gap_in_a_second_gyro_file_leaves_its_motion_out(run_cli, tmp_path):
    """imu_tk's two files: the gyro file (t x y z) lost samples inside a motion, the accelerometer's did
    not. The gyro is interpolated onto the accelerometer's stamps, so the accelerometer steps that
    overlap the gyro's gap are the gap."""
    d = session()
    np.savetxt(tmp_path / "acc.txt", np.column_stack([d.t, d.acc]), fmt="%.10g")
    rows = cut_rows(d, [MOTION])
    np.savetxt(tmp_path / "gyro.txt", np.column_stack([d.t[rows], d.gyro[rows]]), fmt="%.10g")
    r = run_cli(calibrate_args(tmp_path / "acc.txt", tmp_path / "o", "--gyro-data", tmp_path / "gyro.txt",
                               "--json", tmp_path / "s.json"))
    assert r.code == 0, r.err
    gyro = json.loads((tmp_path / "s.json").read_text())["gyro"]
    (g,) = gyro["gap_motions"]
    assert g["longest_gap"] == pytest.approx((CUT + 1) * 0.01, abs=1e-6)  # the gyro's own step across it
    assert g["n_gaps"] == 1 and gyro["fit"]["n_segments"] == d.n_intervals - 2
    assert np.all(np.abs(np.array(gyro["scale"]) - TRUTH.scale) < 4 * np.array(gyro["std"]["scale"]))


# --- too few motions left ----------------------------------------------------------------------
def test_too_few_motions_left_is_one_line_exit_2_nothing_written(run_cli, unchanged, tmp_path):
    d = session(n_poses=12)  # 11 motions; gaps in 8 of them leave 3, too few for 9 unknowns
    write_csv(d, cut_rows(d, [0, 1, 2, 4, 5, 6, 8, 9]), tmp_path / "gaps.csv")
    with unchanged():
        r = run_cli(calibrate_args(tmp_path / "gaps.csv", tmp_path / "o"))
    assert r.code == 2, r
    lines = r.err.strip().splitlines()
    assert len(lines) == 1, r.err
    assert lines[0] == (f"imucal: error: {tmp_path / 'gaps.csv'}: t: 3 motions left for the gyro fit's 9 unknowns "
                        "(at least 5 needed): 8 of 11 motions left out: a gap in the time stamps lies inside each, "
                        "the longest 0.51 s (fix: record again without pauses of the logger during motions (or cut "
                        "the recording at the gaps and calibrate the longest part); or calibrate the accelerometer "
                        "alone: --no-gyro (gyro.calibrate: false))")


def test_an_axis_turned_only_in_motions_with_gaps_is_refused_naming_the_gaps():
    """Enough motions are left, but only those with a gap turned gravity about y and z: the
    observability refusal names the axes, and says that motions were left out for gaps."""
    from imucal.errors import ImucalError
    from imucal.gyro.simulate import simulate

    q = np.pi / 2  # from z up: about y (gravity to x), about z and back, back about y; then x only
    turns = [(1, q), (2, q), (2, -q), (1, -q)] + [(0, q), (0, -q)] * 3
    d = simulate(TRUTH, turns, unit="rad/s")
    first = [int(d.end[k] + d.start[k + 1]) // 2 for k in range(4)]
    assert motions(fit_gyro(d, GyroOptions(still="off"))).segments.size == 10  # every axis turned: fits
    with pytest.raises(ImucalError) as e:
        fit_gyro(replace(d, gaps=gap_spans(d.t, first)), GyroOptions(still="off"))
    msg = str(e.value)
    assert msg.startswith("<simulated>: gyro.scale: the gyro scale is not determined for the y and z axes: ") and (
        " (4 of 10 motions left out: a gap in the time stamps lies inside each, the longest 0.01 s) (fix: add "
        "rotations about the y and z axes" in msg), msg
