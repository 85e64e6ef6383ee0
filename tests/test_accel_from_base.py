"""fit.base with every accelerometer parameter held (issue 26 follow-up): the accelerometer is taken from the
base calibration, not fitted, so a hand-turned compass log (rarely still) still calibrates its magnetometer;
this log's still intervals, if any, only check the base. Or every value given in fit.fix (no base): the
accelerometer is taken as stated (a log its device already corrected), checked alike."""
from __future__ import annotations

import hashlib
import html

import numpy as np
import pytest

from imucal.calibration.frozen import Calibration, load_calibration
from imucal.config.run import config_from_dict
from imucal.constants import STANDARD_GRAVITY
from imucal.errors import ImucalError
from imucal.mag.simulate import simulate_mag, truth_from_soft_iron
from imucal.model.parameters import BASE_NAMES, base_parameters
from imucal.model.sensor import MAGNETOMETER
from imucal.pipeline import calibrate_accelerometer

SOFT = np.array([[1.05, 0.03, -0.02], [0.03, 0.97, 0.01], [-0.02, 0.01, 1.01]])
HARD = (10.0, -5.0, 3.0)  #: [raw]
ACC_SCALE, ACC_SHIFT = np.array([1.02, 0.98, 1.01]), np.array([0.02, -0.01, 0.03])  #: raw [g] = scale a + shift
RATE = 50.0  #: [Hz]
ALL = list(BASE_NAMES)


def write_log(path, hold: int, seed: int = 3) -> np.ndarray:
    """A 9-axis log in g without a time column; ``hold`` 0: turned by hand the whole time."""
    truth = truth_from_soft_iron(SOFT, s=HARD, field=48.0, noise=0.1, acc_noise=0.002)
    sim = simulate_mag(truth, n_poses=30, hold=hold, transition=200 if hold == 0 else 40, seed=seed)
    acc = sim.acc * ACC_SCALE + ACC_SHIFT
    np.savetxt(path, np.column_stack([acc, sim.mag]), delimiter=",", header="ax,ay,az,mx,my,mz", comments="",
               fmt="%.8g")
    return np.asarray(truth.s)


def write_base(path, unit: str = "g") -> Calibration:
    """The accelerometer's true calibration, as a still-pose log's calibration.yaml would hold it."""
    params = base_parameters(ACC_SHIFT, ACC_SCALE / STANDARD_GRAVITY, [np.pi / 2] * 3, raw_unit=unit,
                             gravity=STANDARD_GRAVITY)
    std = {n: 1e-4 * params[n].scale for n in params.names}
    cal = Calibration(params=params, std=std, gravity=STANDARD_GRAVITY, raw_unit=unit,
                      fit={"status": "Solve_Succeeded"}, data={"file": "still.csv"})
    cal.save(path)
    return cal


def run_file(tmp_path, base: str = "base.yaml", fix=ALL) -> object:
    run = tmp_path / "run.yaml"
    run.write_text(f"data: {{path: log.csv, unit: g, sample_rate: {RATE:g}}}\n"
                   f"fit: {{base: {base}, fix: [{', '.join(fix)}]}}\nmag: {{field: 48, field_unit: uT}}\n")
    return run


def test_the_held_accelerometer_is_the_bases_values_and_std(tmp_path):
    base = write_base(tmp_path / "base.yaml")
    write_log(tmp_path / "log.csv", hold=150)
    cfg = config_from_dict({"data": {"path": str(tmp_path / "log.csv"), "unit": "g", "sample_rate": RATE},
                            "fit": {"base": str(tmp_path / "base.yaml"), "fix": ALL}})
    run = calibrate_accelerometer(cfg)
    cal = run.calibration
    assert cal.params.value_dict() == base.params.value_dict()
    assert {n: cal.std[n] for n in BASE_NAMES} == {n: base.std[n] for n in BASE_NAMES}
    assert cal.fit["taken"] == {"base": "base.yaml",
                                "sha256": hashlib.sha256((tmp_path / "base.yaml").read_bytes()).hexdigest()}
    assert run.result.free_names == () and run.intervals.n >= 20
    assert cal.fit["redchi"] < 3 and not cal.fit["warnings"]  # the check agrees: the base is this sensor's
    # a base of another sensor (scales 3 % off) is named by the check
    params = base.params.with_values({n: base.params[n].value * 1.03 for n in ("b1", "b2", "b3")})
    Calibration(params=params, std=base.std, gravity=base.gravity, raw_unit="g").save(tmp_path / "other.yaml")
    other = calibrate_accelerometer(config_from_dict({**cfg_dict(tmp_path), "fit": {"base": str(tmp_path / "other.yaml"),
                                                                                    "fix": ALL}}))
    assert any("disagree with the accelerometer taken from other.yaml" in w for w in other.calibration.fit["warnings"])


def cfg_dict(tmp_path) -> dict:
    return {"data": {"path": str(tmp_path / "log.csv"), "unit": "g", "sample_rate": RATE}}


def test_a_hand_turned_log_calibrates_its_magnetometer_through_the_cli(tmp_path, run_cli):
    write_base(tmp_path / "base.yaml")
    hard = write_log(tmp_path / "log.csv", hold=0)
    r = run_cli(["calibrate", run_file(tmp_path), "--out", tmp_path / "out"])
    assert r.code == 0, r.err
    assert "taken from base.yaml" in r.out and "no still interval" in r.out
    cal = load_calibration(tmp_path / "out" / "calibration.yaml")
    assert cal.fit["n_intervals"] == 0 and cal.fit["taken"]["base"] == "base.yaml"
    mag = cal.sensor(MAGNETOMETER)
    assert mag is not None
    got = np.array([mag.params[f"s{i}"].value for i in (1, 2, 3)])
    assert np.max(np.abs(got - hard)) < 0.1  # hard iron within a tenth of a count of the truth
    assert "taken from base.yaml" in (tmp_path / "out" / "report.txt").read_text()
    assert "taken from base.yaml" in (tmp_path / "out" / "report.html").read_text()
    r = run_cli(["apply", tmp_path / "out" / "calibration.yaml", "--data", tmp_path / "log.csv", "--unit", "g", "--sample-rate", "50",
                 "--out", tmp_path / "applied.csv"])
    assert r.code == 0, r.err
    h = np.loadtxt(tmp_path / "applied.csv", delimiter=",", skiprows=1)[:, 4:7]  # t, ax, ay, az, mx, my, mz
    assert np.sqrt(np.mean((np.linalg.norm(h, axis=1) / 48.0 - 1) ** 2)) < 0.01


@pytest.mark.parametrize("case", ["missing", "unit"])
def test_a_missing_or_wrong_unit_base_is_one_line_and_nothing_is_written(tmp_path, run_cli, unchanged, case):
    write_log(tmp_path / "log.csv", hold=0)
    if case == "unit":
        write_base(tmp_path / "base.yaml", unit="m/s^2")
    run = run_file(tmp_path, "nowhere.yaml" if case == "missing" else "base.yaml")
    with unchanged():
        r = run_cli(["calibrate", run, "--out", tmp_path / "out"])
    assert r.code == 2 and r.err.count("\n") == 1 and "fit.base" in r.err, r.err
    assert ("nowhere.yaml" if case == "missing" else "raw unit") in r.err
    assert not (tmp_path / "out").exists()


def test_all_nine_held_without_a_base_or_values_stays_refused():
    with pytest.raises(ImucalError, match="nothing is left to fit") as e:
        config_from_dict({"data": {"path": "log.csv"}, "fit": {"fix": ALL}})
    assert "fit.base" in str(e.value) and "give all nine values" in str(e.value) and "\n" not in str(e.value)
    with pytest.raises(ImucalError, match="nothing is left to fit"):  # eight values are not nine
        config_from_dict({"data": {"path": "log.csv"}, "fit": {"fix": ALL, "initial": {n: 1.0 for n in ALL[:8]}}})


def as_logged(tmp_path, scale=(1.0, 1.0, 1.0)) -> object:
    """A run file stating the accelerometer of a log in g that its device corrected: s 0, b = scale / g."""
    b = {f"b{i + 1}": v / STANDARD_GRAVITY for i, v in enumerate(scale)}
    fix = {"s1": 0.0, "s2": 0.0, "s3": 0.0, **b, "phi": np.pi / 2, "psi": np.pi / 2, "theta": np.pi / 2}
    run = tmp_path / "run.yaml"
    run.write_text(f"data: {{path: log.csv, unit: g, sample_rate: {RATE:g}}}\n"
                   f"fit: {{fix: {{{', '.join(f'{k}: {v!r}' for k, v in fix.items())}}}}}\n"
                   "mag: {field: 48, field_unit: uT}\ngravity: {value: 9.80665}\n")
    return run


def test_a_log_its_device_corrected_takes_the_stated_accelerometer(tmp_path, run_cli):
    """fit.fix giving all nine values: taken as stated (errors 0), the magnetometer calibrated beside it; the still
    intervals check it and name a statement that disagrees (a 3 % scale)."""
    truth = truth_from_soft_iron(SOFT, s=HARD, field=48.0, noise=0.1, acc_noise=0.002)
    sim = simulate_mag(truth, n_poses=30, hold=150, transition=40, seed=3)
    np.savetxt(tmp_path / "log.csv", np.column_stack([sim.acc, sim.mag]), delimiter=",",
               header="ax,ay,az,mx,my,mz", comments="", fmt="%.8g")  # acc in g, already corrected
    r = run_cli(["calibrate", as_logged(tmp_path), "--out", tmp_path / "out"])
    assert r.code == 0, r.err
    cal = load_calibration(tmp_path / "out" / "calibration.yaml")
    assert cal.fit["taken"] == {"run_file": "fit.fix"} and all(cal.std[n] == 0.0 for n in BASE_NAMES)
    assert cal.params["b1"].value == pytest.approx(1 / STANDARD_GRAVITY) and cal.params["s2"].value == 0.0
    assert cal.fit["redchi"] < 3 and not cal.fit["warnings"]
    assert cal.sensor(MAGNETOMETER) is not None
    text = (tmp_path / "out" / "report.txt").read_text()
    assert "taken from the run file's fit.fix values" in text and "sha256" not in text.split("[[Taken")[1][:200]
    assert html.escape("the run file's fit.fix values") in (tmp_path / "out" / "report.html").read_text()
    r = run_cli(["calibrate", as_logged(tmp_path, scale=(1.03, 1.0, 1.0)), "--out", tmp_path / "off"])
    assert r.code == 0, r.err
    warn = load_calibration(tmp_path / "off" / "calibration.yaml").fit["warnings"]
    assert any("disagree with the accelerometer taken from the run file's fit.fix values" in w for w in warn), warn


def test_a_fit_setting_beside_stated_values_is_refused():
    fix = {n: (1.5707963267948966 if n in ("phi", "psi", "theta") else 0.1) for n in ALL}
    with pytest.raises(ImucalError, match="taken from fit.fix's values") as e:
        config_from_dict({"data": {"path": "log.csv", "unit": "g"}, "fit": {"fix": fix, "mode": "samples"}})
    assert e.value.field == "fit.mode"


def test_a_value_given_beside_a_taken_base_is_refused(tmp_path):
    write_base(tmp_path / "base.yaml")
    with pytest.raises(ImucalError, match="taken from fit.base"):
        config_from_dict({"data": {"path": "log.csv", "unit": "g"},
                          "fit": {"base": str(tmp_path / "base.yaml"), "fix": {n: 0.5 for n in ALL}}})
    with pytest.raises(ImucalError, match="taken from fit.base"):
        config_from_dict({"data": {"path": "log.csv", "unit": "g"},
                          "fit": {"base": str(tmp_path / "base.yaml"), "fix": ALL,
                                  "initial": {"s1": 0.5}}})


@pytest.mark.parametrize("extra", [{"mode": "samples"}, {"noise": "still.json"}])
def test_a_fit_setting_beside_a_taken_base_is_refused(tmp_path, extra):
    """Nothing is fitted when the accelerometer is taken whole: a weighting or a mode would be silently ignored."""
    write_base(tmp_path / "base.yaml")
    key = "fit." + next(iter(extra))
    with pytest.raises(ImucalError, match="taken from fit.base") as e:
        config_from_dict({"data": {"path": "log.csv", "unit": "g"},
                          "fit": {"base": str(tmp_path / "base.yaml"), "fix": ALL, **extra}})
    assert e.value.field == key and "\n" not in str(e.value)


@pytest.mark.parametrize("bad, field, words", [({"b1": 0.0}, "fit.fix.b1", "must be positive"),
                                               ({"b2": -0.1}, "fit.fix.b2", "must be positive"),
                                               ({"phi": 1.0}, "fit.fix.phi", "outside its bounds")])
def test_stated_values_a_fit_would_refuse_are_refused(tmp_path, run_cli, unchanged, bad, field, words):
    """A stated scale of zero or below, or an angle outside 90 deg +- 2 %: one line, exit 2, nothing written."""
    write_log(tmp_path / "log.csv", hold=150)
    fix = {"s1": 0.0, "s2": 0.0, "s3": 0.0, "b1": 0.1, "b2": 0.1, "b3": 0.1, "phi": np.pi / 2, "psi": np.pi / 2,
           "theta": np.pi / 2, **bad}
    run = tmp_path / "run.yaml"
    run.write_text(f"data: {{path: log.csv, unit: g, sample_rate: {RATE:g}}}\n"
                   f"fit: {{fix: {{{', '.join(f'{k}: {v!r}' for k, v in fix.items())}}}}}\n")
    with unchanged():
        r = run_cli(["calibrate", run, "--out", tmp_path / "out"])
    assert r.code == 2 and r.err.count("\n") == 1 and field in r.err and words in r.err, r.err
