"""A calibration holds a list of sensors (issue 26): format version 3 writes one section per sensor from its
Parameters, version 2's gyroscope section (plain arrays) still reads into the same value, and apply
evaluates every sensor through its description's map."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from conftest import gyro_rate
from imucal.calibration.frozen import Calibration, load_calibration
from imucal.errors import ImucalError
from imucal.model.gyroscope import GSENS_NAMES, MIS_NAMES, SCALE_NAMES, misalignment_entries

V2 = Path(__file__).parent / "data" / "calibration_v2_xsens_gyro.yaml"  # written by imucal before issue 26


@pytest.fixture(scope="module")
def v2() -> tuple[dict, Calibration]:
    return yaml.safe_load(V2.read_text()), load_calibration(V2)


def test_a_version_2_gyroscope_section_reads_into_the_named_parameters(v2):
    d, cal = v2
    g2 = d["gyroscope"]
    gy = cal.gyro
    assert cal.sensors == ("accelerometer", "gyroscope") and gy.kind == "gyroscope" and gy.raw_unit == "raw"
    np.testing.assert_array_equal(gy.vector(SCALE_NAMES), g2["parameters"]["scale"])
    mis = misalignment_entries(np.array(g2["parameters"]["misalignment"]))
    np.testing.assert_array_equal(gy.vector(MIS_NAMES), mis)
    scale = np.array(g2["parameters"]["scale"])
    H = scale[:, None] * np.array(g2["parameters"]["gsens"])
    np.testing.assert_allclose(gy.vector(GSENS_NAMES).reshape(3, 3), H, rtol=1e-15)
    np.testing.assert_array_equal(gy.vector(SCALE_NAMES, std=True), g2["std"]["scale"])
    assert dict(gy.fit) == g2["fit"]
    # its map is the file's own derived map, omega = C raw + c - D a, and the model's (conftest.gyro_rate)
    rng = np.random.default_rng(1)
    raw, acc = 32500 + rng.normal(size=(40, 3)) * 3000, rng.normal(size=(40, 3)) * 9.8
    C, c, D = (np.array(g2["apply"][k]) for k in ("matrix", "offset", "acc_matrix"))
    want = raw @ C.T + c - acc @ D.T
    np.testing.assert_allclose(gy.apply(raw, acc), want, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(gy.apply(raw, acc), gyro_rate(raw, g2["parameters"]["bias"], scale, gy.vector(MIS_NAMES),
                                                          g2["parameters"]["gsens"], acc), rtol=1e-10, atol=1e-13)


def test_version_3_writes_one_section_per_sensor_and_reads_back_losslessly(v2, tmp_path):
    _, cal = v2
    p = tmp_path / "c3.yaml"
    cal.save(p)
    d = yaml.safe_load(p.read_text())
    assert d["format_version"] == 3 and d["sensors"] == ["accelerometer", "gyroscope"]
    g = d["gyroscope"]
    assert set(g) == {"kind", "model", "units", "inputs", "parameters", "apply", "fit"}
    assert g["inputs"] == ["ax", "ay", "az"] and g["units"] == {"input": "raw", "output": "rad/s"}
    assert list(g["parameters"]) == list(cal.gyro.params.names)
    assert set(g["parameters"]["scale_x"]) == {"value", "std", "unit", "lower", "upper", "fixed", "solver_scale"}
    back = load_calibration(p)
    back.save(tmp_path / "again.yaml")
    assert (tmp_path / "again.yaml").read_bytes() == p.read_bytes()
    rng = np.random.default_rng(2)
    raw_a, raw_g = 33000 + rng.normal(size=(30, 3)) * 4000, 32500 + rng.normal(size=(30, 3)) * 3000
    for x, y in zip(back.apply_imu(raw_a, raw_g), cal.apply_imu(raw_a, raw_g)):
        np.testing.assert_array_equal(x, y)


def test_apply_evaluates_every_sensor_in_order_and_names_a_missing_input(v2):
    _, cal = v2
    rng = np.random.default_rng(3)
    raw_a, raw_g = 33000 + rng.normal(size=(20, 3)) * 4000, 32500 + rng.normal(size=(20, 3)) * 3000
    out = cal.apply_all({"accelerometer": raw_a, "gyroscope": raw_g})
    np.testing.assert_array_equal(out["accelerometer"], cal.apply(raw_a))
    np.testing.assert_array_equal(out["gyroscope"], cal.gyro.apply(raw_g, cal.apply(raw_a)))
    with pytest.raises(ImucalError) as ei:  # the gyroscope reads the calibrated acceleration
        cal.apply_all({"gyroscope": raw_g})
    assert ei.value.field == "data.columns.ax" and "the gyroscope calibration reads ax, ay, az" in str(ei.value)
    with pytest.raises(ImucalError, match="this gyroscope calibration reads ax, ay, az"):
        cal.gyro.apply(raw_g)


@pytest.mark.parametrize("edit, field, words", [
    (lambda d: d.__setitem__("compass", d["gyroscope"]), "compass", "unknown key"),
    (lambda d: d["gyroscope"].__setitem__("kind", "accelerometer"), "gyroscope.kind", "is not 'gyroscope'"),
    (lambda d: d["gyroscope"]["parameters"]["scale_x"].__setitem__("value", -1.0),
     "gyroscope.parameters.scale_x.value", "outside the file's bounds"),
    (lambda d: d["gyroscope"]["parameters"]["scale_x"].__setitem__("std", -1.0),
     "gyroscope.parameters.scale_x.std", "is not a standard error"),
    (lambda d: d["gyroscope"].__setitem__("inputs", ["ax", "ay"]), "gyroscope.inputs", "are not the model's"),
    (lambda d: d["gyroscope"]["apply"]["offset"].__setitem__(0, 1.0), "gyroscope.apply.offset", "edited by hand"),
    (lambda d: d.__setitem__("sensors", ["accelerometer"]), "sensors", "does not list the file's sensors"),
])
def test_an_edited_section_is_refused_in_one_line(v2, tmp_path, edit, field, words):
    _, cal = v2
    d = cal.to_dict()
    edit(d)
    p = tmp_path / "bad.yaml"
    p.write_text(yaml.safe_dump(d))
    with pytest.raises(ImucalError) as ei:
        load_calibration(p)
    assert ei.value.field == field and words in str(ei.value) and str(ei.value).startswith(str(p)), str(ei.value)
    assert "\n" not in str(ei.value)


def test_a_version_2_file_holds_no_version_3_section(v2, tmp_path):
    d, _ = v2
    d = {**d, "gyroscope": {**d["gyroscope"], "inputs": ["ax", "ay", "az"]}}
    p = tmp_path / "mixed.yaml"
    p.write_text(yaml.safe_dump(d))
    with pytest.raises(ImucalError) as ei:
        load_calibration(p)
    assert ei.value.field == "gyroscope.inputs" and "unknown key" in str(ei.value), str(ei.value)
