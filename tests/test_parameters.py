"""Named parameters: units, bounds, fixed/free flags, scales; the angle box pi/2 (1 +- tol)."""
from __future__ import annotations

import dataclasses
import math

import pytest

from imucal.config.run import FitSettings, config_from_dict
from imucal.errors import ImucalError
from imucal.model.parameters import ANGLE_NAMES, BASE_NAMES, Parameter, Parameters, base_parameters

HALF_PI = math.pi / 2


@pytest.fixture
def params() -> Parameters:
    return base_parameters([100.0, -50.0, 20.0], [1670.0, 1700.0, 1650.0], [1.58, 1.56, 1.57],
                           raw_unit="counts")


def test_nine_named_parameters_in_paper_order(params):
    assert params.names == BASE_NAMES == ("s1", "s2", "s3", "b1", "b2", "b3", "phi", "psi", "theta")
    assert len(params) == 9
    assert params.free_names == BASE_NAMES
    assert params["s2"].value == -50.0
    assert params.value_dict()["b3"] == 1650.0


def test_units(params):
    for i in (1, 2, 3):
        assert params[f"s{i}"].unit == "counts"
        assert params[f"b{i}"].unit == "counts/(m/s^2)"
    for a in ANGLE_NAMES:
        assert params[a].unit == "rad"
    assert all(params[n].description for n in params)


def test_bounds_default_tolerance(params):
    lo, hi = HALF_PI * 0.98, HALF_PI * 1.02
    for a in ANGLE_NAMES:
        assert params[a].lower == pytest.approx(lo, rel=1e-15)
        assert params[a].upper == pytest.approx(hi, rel=1e-15)
    for i in (1, 2, 3):
        assert params[f"b{i}"].lower == 0.0  # scales are positive
        assert params[f"b{i}"].upper == math.inf
        assert params[f"s{i}"].lower == -math.inf and params[f"s{i}"].upper == math.inf


@pytest.mark.parametrize("tol", [0.005, 0.02, 0.1])
def test_angle_tolerance_is_configurable(tol):
    p = base_parameters([0, 0, 0], [1, 1, 1], angle_tol=tol)
    for a in ANGLE_NAMES:
        assert p[a].lower == pytest.approx(HALF_PI * (1 - tol))
        assert p[a].upper == pytest.approx(HALF_PI * (1 + tol))


def test_angle_tolerance_from_yaml():
    cfg = config_from_dict({"data": {"path": "x.csv"}, "fit": {"angle_tolerance": 0.05}})
    assert cfg.fit.angle_tolerance == 0.05
    assert FitSettings().angle_tolerance == 0.02


@pytest.mark.parametrize("tol", [0.0, -0.1, 1.0, 2.0])
def test_angle_tolerance_out_of_range_is_refused(tol):
    with pytest.raises(ImucalError, match=r"angle tolerance .* must lie in \(0, 1\)") as ei:
        base_parameters([0, 0, 0], [1, 1, 1], angle_tol=tol)
    assert ei.value.field == "angle_tolerance"


@pytest.mark.parametrize("tol", [0, 0.5, -1, "x", None])
def test_yaml_angle_tolerance_out_of_range_is_refused(tol):
    with pytest.raises(ImucalError, match="angle_tolerance") as ei:
        config_from_dict({"data": {"path": "x.csv"}, "fit": {"angle_tolerance": tol}}, "run.yaml")
    assert ei.value.field == "fit.angle_tolerance"
    assert "run.yaml" in str(ei.value)


def test_initial_angles_are_clamped_into_the_box():
    p = base_parameters([0, 0, 0], [1, 1, 1], [1.0, 2.0, HALF_PI])
    assert p["phi"].value == pytest.approx(HALF_PI * 0.98)
    assert p["psi"].value == pytest.approx(HALF_PI * 1.02)
    assert p["theta"].value == HALF_PI


def test_scales_make_unknowns_near_one(params):
    """x = p / scale is O(1): shifts by one g of raw units, scales by themselves, angles by pi/2."""
    g = 9.80665
    assert params["s1"].scale == pytest.approx(1670.0 * g)
    assert params["b2"].scale == pytest.approx(1700.0)
    assert params["phi"].scale == pytest.approx(HALF_PI)
    for n in params:
        assert abs(params[n].value / params[n].scale) < 10


def test_fix_any_subset(params):
    six = params.with_fixed(ANGLE_NAMES, values={a: HALF_PI for a in ANGLE_NAMES})
    assert six.free_names == ("s1", "s2", "s3", "b1", "b2", "b3")
    assert all(six[a].fixed and six[a].value == HALF_PI for a in ANGLE_NAMES)
    one = params.with_fixed(["s2"])
    assert one.free_names == tuple(n for n in BASE_NAMES if n != "s2")
    assert one["s2"].value == -50.0
    back = six.with_fixed(["phi"], fixed=False)
    assert back["phi"].free and back["psi"].fixed
    none_free = params.with_fixed(BASE_NAMES)
    assert none_free.free_names == ()


def test_fix_unknown_parameter_is_refused(params):
    with pytest.raises(ImucalError, match=r"cannot fix unknown parameter\(s\) \['alpha'\]") as ei:
        params.with_fixed(["alpha", "phi"])
    assert "s1, s2, s3" in str(ei.value)


def test_unknown_parameter_lookup_names_the_choices(params):
    with pytest.raises(ImucalError, match=r"unknown parameter 'b4'.*use one of s1, s2"):
        params["b4"]


def test_duplicate_parameter_is_refused():
    with pytest.raises(ImucalError, match="duplicate parameter 's1'"):
        Parameters([Parameter("s1", 0.0), Parameter("s1", 1.0)])


@pytest.mark.parametrize("scale", [0.0, -1.0, math.inf, math.nan])
def test_bad_scale_is_refused(scale):
    with pytest.raises(ImucalError, match="scale must be positive and finite") as ei:
        Parameter("b1", 1.0, scale=scale)
    assert ei.value.field == "parameters.b1.scale"


def test_inverted_bounds_are_refused():
    with pytest.raises(ImucalError, match="lower bound 2.0 exceeds upper bound 1.0"):
        Parameter("phi", 1.5, lower=2.0, upper=1.0)


def test_at_bound_flags():
    p = Parameter("phi", HALF_PI * 1.02, lower=HALF_PI * 0.98, upper=HALF_PI * 1.02, scale=HALF_PI)
    assert p.at_bound() == "upper"
    assert dataclasses.replace(p, value=HALF_PI * 0.98).at_bound() == "lower"
    assert dataclasses.replace(p, value=HALF_PI).at_bound() is None
    assert Parameter("s1", 1e9).at_bound() is None  # no finite bounds


def test_parameters_are_immutable(params):
    with pytest.raises(dataclasses.FrozenInstanceError):
        params["s1"].value = 3.0  # type: ignore[misc]
    moved = params.with_values({"s1": 3.0})
    assert moved["s1"].value == 3.0 and params["s1"].value == 100.0


def test_yaml_fix_and_initial():
    cfg = config_from_dict({"data": {"path": "x.csv"},
                            "fit": {"fix": "phi", "initial": {"phi": 1.5708}}})
    assert cfg.fit.fix == ("phi",)
    assert cfg.fit.initial == {"phi": 1.5708}
    with pytest.raises(ImucalError, match=r"cannot fix 'omega'.*choose from s1"):
        config_from_dict({"data": {"path": "x.csv"}, "fit": {"fix": ["omega"]}})
    with pytest.raises(ImucalError, match=r"initial value 'a' is not a finite number") as ei:
        config_from_dict({"data": {"path": "x.csv"}, "fit": {"initial": {"s1": "a"}}})
    assert ei.value.field == "fit.initial.s1"
