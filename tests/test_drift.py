"""Navigation drift p(t) = e t^2 / 2: the formula, the three treatments of a calibration, the CLI."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from imucal.cli.main import main
from imucal.constants import STANDARD_GRAVITY
from imucal.analysis.drift import TABLE_TIMES, calibration_cases, position_error, sphere_directions
from imucal.analysis.worst_case import AngleBox, gram_np, max_abs_error

ANGLES = (1.55, 1.59, 1.56)
S = (0.3, -0.2, 0.5)
B = (1.02, 0.97, 1.01)


def _calibration(gravity=9.81, rms=0.004):
    from imucal.calibration import frozen as cal_mod
    from imucal.model.parameters import base_parameters

    params = base_parameters(S, B, ANGLES, raw_unit="m/s^2")
    return cal_mod.Calibration(params=params, std={n: 1e-3 for n in params}, gravity=gravity,
                               raw_unit="m/s^2", fit={"rms_residual": rms})


def _one_line_error(capsys, needle):
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("imucal: error:") and needle in err, err


def test_position_error_is_half_e_t_squared():
    assert position_error(0.2, 10.0) == pytest.approx(10.0)
    t = np.array(TABLE_TIMES)
    assert np.allclose(position_error(0.3130303, t), 0.3130303 * t**2 / 2)
    # Against a numerical double integration of a constant error.
    dt = 1e-3
    v = np.cumsum(np.full(10000, 0.05)) * dt
    p = np.cumsum(v) * dt
    assert p[-1] == pytest.approx(position_error(0.05, 10.0), rel=1e-3)


def test_sphere_directions_are_unit_and_balanced():
    d = sphere_directions(2000)
    assert np.allclose(np.linalg.norm(d, axis=1), 1)
    assert np.allclose(d.mean(axis=0), 0, atol=1e-3)


def test_treatments_without_recording():
    cal = _calibration()
    raw, ign, calib = calibration_cases(cal, 9.81)
    assert [c.name for c in (raw, ign, calib)] == ["raw", "angles ignored", "calibrated"]
    assert calib.error == 0.004  # the fit's RMS residual
    # Angles ignored: the largest error over directions is problem 1 at this sensor's angles.
    cert = max_abs_error(AngleBox.around(ANGLES), 9.81).value
    assert ign.error_max == pytest.approx(cert, rel=2e-3) and ign.error_max <= cert + 1e-9
    assert 0 < ign.error < ign.error_max
    assert raw.error > ign.error > calib.error  # per-axis shift/scale errors add to it


def test_treatments_on_a_simulated_recording(tmp_path):
    from imucal.analysis import simulate as sim
    from imucal.data.load import load_recording

    cal = _calibration()
    dirs = sim.cube_directions()
    sensor = sim.SensorSpec(s=S, b=B, angles=ANGLES, noise=(1e-4,) * 3)
    rec_sim = sim.simulate(sensor, sim.PosePlan(dirs, hold=2.5, transition=1.0), gravity=9.81, seed=1)
    path = tmp_path / "rec.csv"
    path.write_text(rec_sim.to_csv_text())
    raw, ign, calib = calibration_cases(cal, 9.81, load_recording(path))
    assert calib.error < 1e-3  # the true model: only noise remains
    # Angles ignored, by hand: |m| - g with m = E^T a for each pose direction (Lemma 1).
    lam_err = []
    for d in dirs / np.linalg.norm(dirs, axis=1, keepdims=True):
        m = 9.81 * d @ sim.frame_matrix(np.array(ANGLES))
        lam_err.append(abs(np.linalg.norm(m) - 9.81))
    assert ign.error == pytest.approx(math.sqrt(np.mean(np.square(lam_err))), rel=0.05)
    assert "static intervals" in ign.statistic


def test_cli_drift_given_error(tmp_path, capsys):
    out, png = tmp_path / "d.json", tmp_path / "d.png"
    assert main(["drift", "--error", "0.05", "--json", str(out), "--plot", str(png)]) == 0
    text = capsys.readouterr().out
    assert "p(60 s) [m]" in text and "worst case" in text
    d = json.loads(out.read_text())
    assert d["times"] == [1.0, 5.0, 10.0, 60.0]
    worst, given = d["cases"]
    assert abs(worst["error"] - 0.3130299) < 1e-6
    assert given["position_error"] == pytest.approx([0.025, 0.625, 2.5, 90.0])
    assert worst["position_error"][-1] == pytest.approx(worst["error"] * 1800)
    import matplotlib.image as mpimg

    img = mpimg.imread(png)
    assert img.shape[1] >= 800 and img[..., :3].std() > 0.05


def test_cli_drift_calibration_and_duration(tmp_path, capsys):
    cal = _calibration(gravity=9.80665)
    cal.save(tmp_path / "cal.yaml")
    out = tmp_path / "d.json"
    assert main(["drift", "--calibration", str(tmp_path / "cal.yaml"), "--duration", "30",
                 "--json", str(out)]) == 0
    d = json.loads(out.read_text())
    assert d["times"] == [1.0, 5.0, 10.0, 30.0]  # no column beyond the duration asked
    assert [c["name"] for c in d["cases"]] == ["worst case", "raw", "angles ignored", "calibrated"]
    assert d["gravity"] == 9.80665


@pytest.mark.parametrize("args, needle", [
    (["--duration", "0"], "duration 0 s must be positive"),
    (["--duration", "-5"], "must be positive"),
    (["--error", "-0.1"], "must be a non-negative number"),
    (["--error", "nan"], "must be a non-negative number"),
    (["--tolerance", "0"], "must be positive"),
    (["--tolerance", "0.4"], "degenerate frame"),
    (["--recording", "x.csv"], "--recording needs --calibration"),
    (["--calibration", "missing.yaml"], "file not found"),
])
def test_cli_drift_bad_input(tmp_path, capsys, args, needle):
    out, png = tmp_path / "d.json", tmp_path / "d.png"
    assert main(["drift", *args, "--json", str(out), "--plot", str(png)]) == 2
    _one_line_error(capsys, needle)
    assert list(tmp_path.iterdir()) == []


def test_cli_drift_calibration_and_error_are_exclusive(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["drift", "--error", "0.1", "--calibration", "c.yaml"])
    assert exc.value.code == 2
    assert "not allowed with argument" in capsys.readouterr().err


def test_worst_case_row_uses_problem_1():
    e = max_abs_error(AngleBox.from_tolerance(0.02), STANDARD_GRAVITY).value
    lam = np.linalg.eigvalsh(gram_np([math.pi / 2 * 1.02] * 3))[0]
    assert e == pytest.approx(STANDARD_GRAVITY * (1 - math.sqrt(lam)), rel=1e-12)


def test_cli_drift_table_stops_at_the_duration(run_cli):
    code, out, _ = run_cli(["drift", "--duration", "10"])
    assert code == 0 and "p(10 s)" in out and "p(60 s)" not in out
