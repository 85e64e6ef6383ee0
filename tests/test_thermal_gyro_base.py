"""A sweep's gyroscope on fit.base's (issue 27): still poses give the bias over temperature, a multi-pose log
with rotations gives the scale, misalignment and g-sensitivity; a gyroscope in counts without such a base gets
no section, and the report says why (it was dropped silently before).

The counts are written here by the gyroscope's forward model (imucal.model.gyroscope's docstring, written
again in numpy): raw = s + bias(T) + B M omega + H a, with bias(T) the rad/s truth of test_thermal_gyro times
each axis's scale (a raw-unit bias, as the description holds it), omega each pose's Earth rate plus noise.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from test_thermal import NOMINAL
from test_thermal_gyro import EARTH, HOURS, gyro_sweep, truth
from imucal.calibration.frozen import Calibration, load_calibration
from imucal.calibration.sensor import SensorCalibration
from imucal.model.gyroscope import GSENS_NAMES, MIS_NAMES, SCALE_NAMES, gyro_model, gyro_parameters
from imucal.model.parameters import BASE_NAMES, base_parameters

SCALE = np.array([940.0, 1010.0, 1075.0])  #: [counts per rad/s]
MIS = np.array([0.012, -0.006, 0.009, 0.004, -0.007, 0.005])  #: M_g's off-diagonal entries
H = np.array([[0.3, 0.02, 0.0], [0.0, -0.2, 0.01], [0.05, 0.0, 0.25]])  #: [counts per m/s^2]
S0 = np.array([12.0, -7.0, 3.0])  #: [counts]
S_ACC = np.array([0.05, -0.1, 0.2])  #: test_thermal.sweep's accelerometer shifts [m/s^2]
HELD = ["b1", "b2", "b3", "phi", "psi", "theta"]


def _M() -> np.ndarray:
    M = np.eye(3)
    for v, (i, j) in zip(MIS, ((0, 1), (0, 2), (1, 0), (1, 2), (2, 0), (2, 1))):
        M[i, j] = v
    return M


def counts_sweep(path: Path) -> tuple[Path, np.ndarray]:
    """The sweep with gx, gy, gz in counts, and each sample's true rate [rad/s]."""
    d = np.loadtxt(gyro_sweep(path.with_suffix(".rad.csv")), delimiter=",", skiprows=1)
    acc, g, temp = d[:, 1:4], d[:, 4:7], d[:, 7]
    rate = g - truth(temp)  # the Earth's rate of each pose, with the noise
    raw = S0 + truth(temp) * SCALE + (rate @ _M().T) * SCALE + (acc - S_ACC) @ H.T
    np.savetxt(path, np.column_stack([d[:, :4], raw, temp]), delimiter=",", header="t,ax,ay,az,gx,gy,gz,temp",
               comments="", fmt="%.10g")
    return path, rate


def base_file(path: Path) -> Path:
    """A multi-pose log's calibration as fit.base: the accelerometer at nominal, the gyroscope in counts."""
    acc = base_parameters(S_ACC, [1.0, 1.0, 1.0], raw_unit="raw", gravity=9.80665)
    gp = gyro_parameters("raw", S0 + 5.0, SCALE, MIS, H.ravel())
    std = {n: 1e-3 for n in gp.names}
    gyro = SensorCalibration(gyro_model(), gp, std, "raw", {"status": "Solve_Succeeded"})
    Calibration(acc, {n: 1e-4 for n in BASE_NAMES}, 9.80665, "raw", attached=(gyro,)).save(path)
    return path


def _run_file(tmp_path: Path, fit: str, gyro_unit: str = "counts") -> tuple[Path, Path, np.ndarray]:
    """The counts sweep and a run file for it: (run file, data, true rate)."""
    data, rate = counts_sweep(tmp_path / "sweep.csv")
    run = tmp_path / "run.yaml"
    run.write_text(f"data: {{path: {data.name}, time_unit: s, gyro_unit: {gyro_unit}}}\nfit: {fit}\n")
    return run, data, rate


def _discover(run_cli, tmp_path: Path, fit: str) -> tuple:
    run, data, rate = _run_file(tmp_path, fit)
    return run_cli(["discover", "--config", run, "--out", tmp_path / "cal"]), data, rate


def _refused_one_line(run_cli, tmp_path: Path, unchanged, fit: str, gyro_unit: str, *words: str) -> None:
    run, _, _ = _run_file(tmp_path, fit, gyro_unit)
    with unchanged(tmp_path):
        r = run_cli(["discover", "--config", run, "--out", tmp_path / "cal"])
    assert r.code == 2 and r.err.count("\n") == 1 and all(w in r.err for w in words), r.err
    assert "Warning" not in r.err and not (tmp_path / "cal").exists()


def test_a_counts_gyroscope_without_a_base_gets_no_section_and_the_report_says_why(run_cli, tmp_path):
    fix = "{fix: {" + ", ".join(f"{k}: {v!r}" for k, v in NOMINAL.items()) + "}}"
    r, _, _ = _discover(run_cli, tmp_path, fix)
    assert r.code == 0, r.err
    cal = load_calibration(tmp_path / "cal" / "calibration.yaml")
    assert cal.gyro is None
    report = (tmp_path / "cal" / "report.txt").read_text()
    assert "no gyroscope section was written" in report and "fit.base" in report


def test_a_counts_gyroscope_takes_its_scale_misalignment_and_gsens_from_the_base(run_cli, tmp_path):
    """The section holds the base's scale, M_g and H with their standard errors, the sweep's bias at T_ref and its
    bias(T) in counts; ``apply`` on the counts gives each pose's Earth rate at every temperature."""
    base = base_file(tmp_path / "base.yaml")
    r, data, rate = _discover(run_cli, tmp_path, f"{{base: {base.name}, fix: [{', '.join(HELD)}]}}")
    assert r.code == 0, r.err
    cal = load_calibration(tmp_path / "cal" / "calibration.yaml")
    g = cal.gyro
    assert g is not None and g.raw_unit == "raw"
    v = g.params.value_dict()
    assert [v[n] for n in SCALE_NAMES] == SCALE.tolist() and [v[n] for n in MIS_NAMES] == MIS.tolist()
    assert [v[n] for n in GSENS_NAMES] == H.ravel().tolist()
    assert all(g.std[n] == 1e-3 for n in SCALE_NAMES)
    assert g.fit["base"]["file"] == "base.yaml" and len(g.fit["base"]["sha256"]) == 64
    assert "bias_temperature_x" in v and g.params["bias_temperature_x"].unit == "raw/degC"
    d = np.loadtxt(data, delimiter=",", skiprows=1)
    out = cal.apply_all({"accelerometer": d[:, 1:4], "gyroscope": d[:, 4:7]}, {"temp": d[:, 7]})
    err = out["gyroscope"] - rate
    # ``rate`` holds the noise, so what is left is the fit's: the Earth's rate averaged into the bias (at most
    # 0.073 mrad/s) and the bias(T) misfit
    assert np.abs(np.median(err, axis=0)).max() < 1e-4, np.median(err, axis=0)
    hold = int(HOURS * 3600)
    for k in range(3):  # no trend with temperature left within a pose
        seg = slice(k * (hold + 120) + 600, k * (hold + 120) + hold)
        for i in range(3):  # the truth: x linear (3 mrad/s over 10 degC), y quadratic
            smooth = np.convolve(err[seg, i], np.ones(600) / 600, mode="valid")
            assert np.ptp(smooth) < 1e-5, (k, i, np.ptp(smooth))
    report = (tmp_path / "cal" / "report.txt").read_text()
    assert "taken from fit.base 'base.yaml'" in report


def test_a_base_gyroscope_in_another_unit_is_one_line(run_cli, tmp_path, unchanged):
    base = base_file(tmp_path / "base.yaml")
    _refused_one_line(run_cli, tmp_path, unchanged, f"{{base: {base.name}, fix: [{', '.join(HELD)}]}}", "deg/s",
                      "fit.base", "deg/s")


@pytest.mark.parametrize("axis", [0])
def test_the_bias_over_temperature_is_the_truth_in_counts(run_cli, tmp_path, axis):
    """x's linear term in counts per degC is the truth's 3e-4 rad/s per degC times the x scale (to 3 %)."""
    base = base_file(tmp_path / "base.yaml")
    r, _, _ = _discover(run_cli, tmp_path, f"{{base: {base.name}, fix: [{', '.join(HELD)}]}}")
    assert r.code == 0, r.err
    g = load_calibration(tmp_path / "cal" / "calibration.yaml").gyro
    assert g is not None
    assert g.params["bias_temperature_x"].value == pytest.approx(3e-4 * SCALE[axis], rel=0.03)


@pytest.mark.parametrize("scale", [0.0, -940.0, 1e-300, float("nan")])
def test_a_hostile_base_gyroscope_scale_is_one_line(run_cli, tmp_path, unchanged, scale, recwarn):
    """A base whose gyroscope scale is zero, negative, tiny enough to overflow the map's check, or NaN: one line
    naming fit.base, exit 2, no numpy warning, nothing written."""
    import yaml

    d = yaml.safe_load(base_file(tmp_path / "good.yaml").read_text())
    d["gyroscope"]["parameters"]["scale_x"]["value"] = scale
    (tmp_path / "base.yaml").write_text(yaml.safe_dump(d))
    _refused_one_line(run_cli, tmp_path, unchanged, f"{{base: base.yaml, fix: [{', '.join(HELD)}]}}", "counts",
                      "fit.base")
    assert not [w for w in recwarn if issubclass(w.category, RuntimeWarning)], [str(w.message) for w in recwarn]


def test_a_base_named_with_a_newline_stays_one_line_in_the_report(run_cli, tmp_path):
    """The base's file name reaches the report's text through the gyroscope section: quoted (imucal.errors.short),
    so a newline in it cannot start a line of its own; the YAML keeps it exactly."""
    name = 'b*\nx".yaml'
    base = base_file(tmp_path / name)
    r, _, _ = _discover(run_cli, tmp_path, "{base: " + '"b*\\nx\\".yaml"' + f", fix: [{', '.join(HELD)}]}}")
    assert r.code == 0, r.err
    lines = (tmp_path / "cal" / "report.txt").read_text().splitlines()
    assert any("taken from fit.base 'b*\\nx\".yaml'" in ln for ln in lines), [ln for ln in lines if "fit.base" in ln]
    assert load_calibration(tmp_path / "cal" / "calibration.yaml").gyro.fit["base"]["file"] == base.name
