"""A sensor is data: models declare the channels they read, recordings list the ones they carry."""
from __future__ import annotations

import numpy as np
import pytest

from imucal.data.recording import Recording
from imucal.errors import ImucalError
from imucal.gyro.model import READS as GYRO_READS
from imucal.model.channels import (ACCELERATION, ANGULAR_RATE, TEMPERATURE, TIME, covariate_matrix,
                                   covariate_values, missing, require)
from imucal.model.effects import make_effect
from imucal.model.sensor import build_model


def _rec(temp: bool, gyro: bool) -> Recording:
    n = 5
    return Recording(t=np.arange(n) * 0.01, raw=np.zeros((n, 3)), temp=np.full(n, 25.0) if temp else None,
                     unit="counts", source="rec.csv", sha256="0" * 64, gyro=np.zeros((n, 3)) if gyro else None)


def test_models_declare_what_they_read():
    assert build_model().reads == (ACCELERATION,)
    m = build_model([make_effect("bias_temperature", (0, 1, 2)), make_effect("scale_drift", (2,))])
    assert {c.role for c in m.reads} == {"acceleration", "temperature", "time"}
    assert {c.role for c in GYRO_READS} == {"angular_rate", "acceleration", "time"}


def test_recordings_list_their_channels_with_units():
    ch = _rec(temp=True, gyro=False).channels
    assert [c.role for c in ch] == ["time", "acceleration", "temperature"]
    assert ch[1].unit == "counts" and ch[2].unit == "degC"
    assert ANGULAR_RATE.role in {c.role for c in _rec(False, True).channels}


def test_missing_channel_is_named_with_the_column_to_add():
    rec = _rec(temp=False, gyro=False)
    assert missing(GYRO_READS, rec.channels) == [ANGULAR_RATE]
    with pytest.raises(ImucalError) as e:
        require(build_model([make_effect("bias_temperature", (0,))]).reads, rec.channels, rec.source)
    assert e.value.field == "data.columns.temp" and "temperature effect" in e.value.message
    with pytest.raises(ImucalError, match="reads angular rate but the data have no gx column"):
        require(GYRO_READS, rec.channels, rec.source, what="the gyroscope model")
    require(GYRO_READS, _rec(False, True).channels)  # has them all: no error


def test_covariate_values_follow_the_models_order():
    keys = build_model([make_effect("scale_drift", (0,)), make_effect("bias_temperature", (1,))]).covariates
    temp, t = np.array([20.0, 30.0]), np.array([0.0, 1.0])
    vals = covariate_values(keys, temp=temp, time=t)
    M = covariate_matrix(keys, vals, 2)
    assert M.shape == (2, 2)
    for j, k in enumerate(keys):
        np.testing.assert_array_equal(M[:, j], temp if k == "temp" else t)
    assert covariate_matrix((), {}, 3).shape == (3, 0)
    with pytest.raises(ImucalError, match="no temp column"):
        covariate_values(keys, temp=None, time=t)
    assert TIME.unit == "s" and TEMPERATURE.unit == "degC"
