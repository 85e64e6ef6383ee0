"""The gyroscope's raw unit is its own (data.gyro_unit, --gyro-unit), not the accelerometer's:
deg/s and rad/s start the fit from the nominal scale with no scale search; counts keep the search."""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from conftest import real_file
from imucal.config.run import config_from_dict, load_config
from imucal.data.spec import DataSpec, gyro_unit
from imucal.errors import ImucalError
from imucal.gyro import fit as gyro_fit
from imucal.gyro.evaluate import rms
from imucal.gyro.run import gyro_data
from imucal.pipeline import calibrate_accelerometer

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("given, bag, used", [("auto", False, "raw"), ("auto", True, "rad/s"), ("counts", False, "raw"),
                                              ("raw", False, "raw"), ("deg/s", False, "deg/s"),
                                              ("rad/s", False, "rad/s")])
def test_gyro_unit_is_resolved_on_its_own(given, bag, used):
    assert gyro_unit(DataSpec(path="x", unit="m/s^2", gyro_unit=given), bag) == used


def test_an_unknown_gyro_unit_is_refused_in_the_yaml():
    with pytest.raises(ImucalError, match=r"data.gyro_unit: unknown gyro unit 'dps'"):
        config_from_dict({"data": {"path": "x.csv", "gyro_unit": "dps"}}, "run.yaml")


@pytest.fixture(scope="module")
def ros_data2():
    """ROS data2 (accelerometer in m/s^2, gyro in rad/s) read with data.gyro_unit: rad/s."""
    g = real_file("ros-imu-getovermassif", "data2", "gyro_data.txt")
    cfg = load_config(ROOT / "configs" / "ros-imu-data2.yaml")
    cfg = dataclasses.replace(cfg, data=dataclasses.replace(cfg.data, gyro_unit="rad/s"))
    data, _ = gyro_data(calibrate_accelerometer(cfg), str(g))
    return data


def test_a_gyro_in_rad_per_s_is_fitted_without_a_scale_search(ros_data2, monkeypatch):
    """The accelerometer is in m/s^2 (the old default took that as the gyro's unit and searched)."""
    searched = []
    real_search = gyro_fit._search_scale
    monkeypatch.setattr(gyro_fit, "_search_scale", lambda *a: searched.append(1) or real_search(*a))
    assert ros_data2.unit == "rad/s"
    nominal = gyro_fit.fit_gyro(ros_data2, gyro_fit.GyroOptions(gsens="off"))
    assert searched == []
    counts = gyro_fit.fit_gyro(dataclasses.replace(ros_data2, unit="raw"), gyro_fit.GyroOptions(gsens="off"))
    assert searched == [1]  # counts keep the search
    from imucal.gyro.result import arrays, motions

    assert rms(motions(nominal).error_deg) <= rms(motions(counts).error_deg) + 1e-6
    assert np.all(np.abs(arrays(nominal).scale - 1) < 0.02)  # rad/s: scale near 1 rad/s per rad/s
