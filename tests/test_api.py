"""Issue 10: the library is usable without files, and gives the CLI's answer."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import imucal
from conftest import real_file
from imucal.errors import ImucalError

XSENS = ("xsens-mti-imutk", "xsens_acc.mat")
ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def xsens():
    return np.loadtxt(real_file(*XSENS))


def test_arrays_give_the_files_calibration(xsens, run_cli, tmp_path):
    run = imucal.calibrate(xsens[:, 1:], t=xsens[:, 0], gravity=9.81744)
    js = tmp_path / "s.json"
    r = run_cli(["calibrate", "--data", real_file(*XSENS), "--gravity", "9.81744", "--out", tmp_path / "o",
                 "--no-figures", "--quiet", "--json", js])
    assert r.code == 0
    cli = json.loads(js.read_text())
    lib = imucal.summary(run)
    assert lib["params"] == cli["params"] and lib["std"] == cli["std"]
    assert [w.split("investigate")[0] for w in lib["warnings"]] == [w.split("investigate")[0] for w in cli["warnings"]]
    one = run.calibration.apply(xsens[0, 1:])
    assert one.shape == (3,)
    np.testing.assert_array_equal(one, run.calibration.apply(xsens[:1, 1:])[0])
    back = imucal.Calibration.load(tmp_path / "o" / "calibration.yaml")
    np.testing.assert_allclose(back.apply(xsens[:, 1:]), run.calibration.apply(xsens[:, 1:]), rtol=1e-12)


def test_a_rate_instead_of_time_and_fit_options(xsens):
    run = imucal.calibrate(xsens[:, 1:], fs=100.0, gravity=9.81744, weights="uniform")
    assert run.calibration.fit["weights"] == "uniform" and run.intervals.n == 38


@pytest.mark.parametrize("kw, msg", [
    ({}, "no time stamps and no sample rate"),
    ({"fs": 1e9}, "is not an IMU rate"),
    ({"t": np.zeros(51175)}, "strictly increasing"),
])
def test_bad_arrays_are_refused_in_one_line(xsens, kw, msg):
    with pytest.raises(ImucalError, match=msg):
        imucal.calibrate(xsens[:, 1:], **kw)


def test_dataframe_input(xsens):
    import pandas as pd
    df = pd.DataFrame({"t": xsens[:, 0], "ax": xsens[:, 1], "ay": xsens[:, 2], "az": xsens[:, 3]})
    run = imucal.calibrate(df, gravity=9.81744)
    assert run.intervals.n == 38


# --- issue 29: a library that fits scientific Python ------------------------------------------------------

GYR = ("xsens-mti-imutk", "xsens_gyro.mat")


def test_the_dataframe_calibrates_the_gyroscope_as_the_command_line_does(xsens, run_cli, tmp_path):
    """Columns gx, gy, gz of a DataFrame are the gyroscope: the same calibration as `imucal calibrate`
    with the accelerometer and gyroscope files, and a result with .report(), .to_file(), .write()."""
    import pandas as pd
    gyr = np.loadtxt(real_file(*GYR))
    df = pd.DataFrame({"t": xsens[:, 0], **{c: xsens[:, i + 1] for i, c in enumerate(("ax", "ay", "az"))},
                       **{c: gyr[:, i + 1] for i, c in enumerate(("gx", "gy", "gz"))}})
    with pytest.warns(imucal.ImucalWarning, match="reduced chi-square"):
        res = imucal.calibrate(df, gravity=9.81744)
    js = tmp_path / "s.json"
    r = run_cli(["calibrate", "--data", real_file(*XSENS), "--gyro-data", real_file(*GYR), "--gravity", "9.81744",
                 "--out", tmp_path / "o", "--no-figures", "--quiet", "--json", js])
    assert r.code == 0, r.err
    cli = json.loads(js.read_text())["gyro"]
    assert res.calibration.sensors == ("accelerometer", "gyroscope") and res.success
    np.testing.assert_allclose(res.summary()["gyro"]["scale"], cli["scale"], rtol=1e-9)
    np.testing.assert_allclose(res.summary()["gyro"]["misalignment"], cli["misalignment"], atol=1e-9)
    assert "[[Gyroscope]]" in res.report() and res.report().startswith("[[Calibration]]")
    back = imucal.load_calibration(res.to_file(tmp_path / "cal.yaml"))
    assert back.sensors == ("accelerometer", "gyroscope")
    written = res.write(tmp_path / "lib", figures=False)
    assert sorted(p.name for p in written) == ["calibration.yaml", "report.html", "report.txt"]


def test_gyro_arrays_take_their_unit(xsens):
    """``gyro=`` beside ``acc``: rad/s readings start from the nominal scale (1 raw per rad/s)."""
    gyr = np.loadtxt(real_file(*GYR))
    res = imucal.calibrate(xsens[:, 1:], gyr[:, 1:] / 4776.0, t=xsens[:, 0], gravity=9.81744, gyro_unit="rad/s")
    np.testing.assert_allclose(res.summary()["gyro"]["scale"], 1.0, atol=0.01)
    assert res.calibration.gyro is not None


@pytest.mark.parametrize("kw, field, msg", [
    ({"mag": np.zeros((5, 3))}, "mag", "mag has 5 rows, acc has 51175"),
    ({"mag": np.zeros((51175, 3)), "mag_field": -1.0}, "mag.field", "field -1.0 is not a field magnitude"),
    ({"gyro": np.zeros((7, 3))}, "gyro", "gyro has 7 rows, acc has 51175"),
    ({"gyro": np.zeros((51175, 2))}, "gyro", "gyro must be an (N, 3) array"),
    ({"gyro_unit": "rpm"}, "gyro_unit", "unknown gyro unit 'rpm'"),
    ({"fix": ["bogus"]}, "fit.fix", "cannot fix 'bogus'"),
    ({"gravity": 9.81, "latitude": 45.0}, "gravity", "give either gravity.value or gravity.latitude"),
])
def test_bad_library_arguments_are_one_line(xsens, kw, field, msg):
    with pytest.raises(ImucalError) as exc:
        imucal.calibrate(xsens[:, 1:], fs=100.0, **kw)
    assert exc.value.field == field and msg in str(exc.value) and "\n" not in str(exc.value)


def test_fix_holds_any_parameter_at_its_start_or_a_value(xsens):
    res = imucal.calibrate(xsens[:, 1:], t=xsens[:, 0], gravity=9.81744, fix=["phi"], weights="uniform")
    assert res.result.params["phi"].fixed and not res.result.params["psi"].fixed
    at = {n: res.result.params[n].value + 1e-9 for n in ("s1", "theta")}  # held at values of our choosing
    held = imucal.calibrate(xsens[:, 1:], t=xsens[:, 0], gravity=9.81744, fix=at)
    assert {n: held.result.params[n].value for n in at} == at
    assert {n for n in held.result.params.names if held.result.params[n].fixed} == set(at)


def test_warnings_reach_a_notebook_and_the_steps_a_logger(xsens, caplog):
    """A fit's warnings through `warnings` (ImucalWarning, a UserWarning), never printed; its steps on
    the `imucal` logger at INFO."""
    import logging
    import warnings

    with warnings.catch_warnings(record=True) as seen, caplog.at_level(logging.INFO, logger="imucal"):
        warnings.simplefilter("always")
        res = imucal.calibrate(xsens[:, 1:], t=xsens[:, 0], gravity=9.81744)
    got = [str(w.message) for w in seen if issubclass(w.category, imucal.ImucalWarning)]
    assert got == list(res.warnings) and got and issubclass(imucal.ImucalWarning, UserWarning)
    assert seen[0].filename == __file__  # points at the caller's line
    assert any("38 still intervals" in r.getMessage() for r in caplog.records)


def test_the_package_namespace(tmp_path):
    """`from imucal import *` gives the documented names, `dir(imucal)` lists them, and `import imucal`
    loads none of them (PEP 562): numpy and CasADi stay unimported until a name is used."""
    import subprocess
    import sys

    ns: dict = {}
    exec("from imucal import *", ns)
    assert sorted(n for n in ns if n != "__builtins__") == sorted(imucal.__all__)
    assert set(imucal.__all__) <= set(dir(imucal))
    assert all(callable(ns[n]) for n in imucal.__all__ if n != "__version__")
    code = "import sys, imucal; print(sorted(m for m in ('numpy', 'casadi', 'imucal.api') if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path, timeout=60,
                         env={**__import__("os").environ, "PYTHONPATH": str(ROOT)})
    assert out.stdout.strip() == "[]", out.stderr


def test_one_function_is_called_calibrate():
    """imucal.calibrate is the only `calibrate`: the pipeline's steps are named for what they fit."""
    import ast

    found = [f"{p.relative_to(ROOT)}" for p in (ROOT / "imucal").rglob("*.py")
             for node in ast.walk(ast.parse(p.read_text(encoding="utf-8")))
             if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and node.name == "calibrate"]
    assert found == ["imucal/api.py"]


def test_mag_arrays_calibrate_the_magnetometer_into_the_same_calibration(tmp_path):
    """``mag=`` beside ``acc`` (issue 26): the magnetometer fitted in the accelerometer's frame, the field given."""
    from test_mag_plugin import FIELD_UT, write_log

    write_log(tmp_path / "log.csv")
    d = np.loadtxt(tmp_path / "log.csv", delimiter=",", skiprows=1)
    res = imucal.calibrate(d[:, 1:4], mag=d[:, 4:7], t=d[:, 0], mag_field=FIELD_UT, mag_field_unit="uT")
    assert res.calibration.sensors == ("accelerometer", "magnetometer") and res.success
    h = res.calibration.apply_all({"accelerometer": d[:, 1:4], "magnetometer": d[:, 4:7]})["magnetometer"]
    assert np.sqrt(np.mean((np.linalg.norm(h, axis=1) / FIELD_UT - 1) ** 2)) < 0.005
    assert res.summary()["mag"]["fit"]["dip_scatter_deg"]["after"] < 0.1
