"""Issue 10: the library is usable without files, and gives the CLI's answer."""
from __future__ import annotations

import json

import numpy as np
import pytest

import imucal
from conftest import real_file
from imucal.errors import ImucalError

XSENS = ("xsens-mti-imutk", "xsens_acc.mat")


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
    pd = pytest.importorskip("pandas")
    df = pd.DataFrame({"t": xsens[:, 0], "ax": xsens[:, 1], "ay": xsens[:, 2], "az": xsens[:, 3]})
    run = imucal.calibrate(df, gravity=9.81744)
    assert run.intervals.n == 38
