"""imucal.files.schema: one mechanism for every file imucal reads, checked on its own and through
every reader on the command line (exit 2, one line FILE: FIELD: what (fix: ...))."""
from __future__ import annotations

import copy
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Literal, Mapping

import numpy as np
import pytest
import yaml

from imucal.calibration.frozen import load_calibration
from imucal.calibration.gyro import from_arrays
from imucal.calibration.section import to_section
from imucal.config.run import RunConfig, config_from_dict
from imucal.errors import ImucalError
from imucal.files.schema import fill, keys, rule

ROOT = Path(__file__).resolve().parents[1]
V1_CALIBRATION = ROOT / "tests" / "data" / "calibration_v1_before_rename.yaml"


# --- the mechanism on its own -----------------------------------------------------------------
@dataclass(frozen=True)
class Inner:
    name: str
    axes: tuple[Literal["x", "y", "z"], ...] = ("x",)


@dataclass(frozen=True)
class Outer:
    count: int = field(default=1, metadata=rule(ge=0, le=10))
    rate: float = field(default=1.0, metadata=rule(gt=0, unit="Hz", fix="give the rate in Hz"))
    flag: bool = False
    label: str | None = None
    vec: float | tuple[float, float, float] = 0.0
    table: Mapping[str, float] = field(default_factory=dict)
    items: tuple[Inner, ...] = ()
    inner: Inner = Inner("a")
    source: str | None = field(default=None, metadata=rule(internal=True))


FILL_CASES = [
    ({"count": True}, "count", "count True must be an integer from 0 to 10"),
    ({"count": 11}, "count", "count 11 must be an integer from 0 to 10"),
    ({"rate": 0}, "rate", "rate 0 must be a positive number of Hz (fix: give the rate in Hz)"),
    ({"rate": float("nan")}, "rate", "rate is not finite (nan)"),
    ({"rate": float("inf")}, "rate", "rate is not finite (inf)"),
    ({"rate": 10 ** 400}, "rate", "is too large for a float"),
    ({"rate": "fast"}, "rate", "rate 'fast' must be a positive number of Hz"),
    ({"flag": 1}, "flag", "flag 1 must be true or false"),
    ({"label": 5}, "label", "label 5 must be text (or null)"),
    ({"vec": [1, 2]}, "vec", "vec [1, 2] must be a list of 3 values"),
    ({"vec": "up"}, "vec", "vec 'up' must be a finite number or a list of 3 values"),
    ({"table": {"a": False}}, "table.a", "a False must be a finite number"),
    ({"items": [{"name": "e", "axes": ["x", "w"]}]}, "items[0].axes[1]", "axes 'w' must be one of x, y, z"),
    ({"items": [{"axes": ["x"]}]}, "items[0].name", "missing key 'name'"),
    ({"items": {"name": "e"}}, "items", "must be a list"),
    ({"inner": {"name": "b", "colour": 1}}, "inner.colour",
     "unknown key 'colour' (fix: allowed keys here: name, axes)"),
    ({"colour": 1}, "colour", "unknown key 'colour' (fix: allowed top-level keys: count, rate, flag, label, vec,"),
    ({"source": "x"}, "source", "unknown key 'source'"),
    ([1, 2], "top level", "top level must be a mapping, got list"),
    ({"inner": 3}, "inner", "section must be a mapping, got int"),
]


@pytest.mark.parametrize("raw, where, message", FILL_CASES)
def test_fill_refuses_in_one_line_naming_the_field(raw: Any, where: str, message: str) -> None:
    with pytest.raises(ImucalError) as ei:
        fill(Outer, raw, "f.yaml")
    assert ei.value.field == where and ei.value.file == "f.yaml"
    assert message in str(ei.value) and "\n" not in str(ei.value)
    assert str(ei.value).startswith(f"f.yaml: {where}: ")


def test_fill_gives_typed_values() -> None:
    o = fill(Outer, {"count": 3, "rate": 2, "vec": [1, 2.5, 3], "table": {"a": 1.5},
                     "items": [{"name": "e", "axes": ["x", "z"]}], "inner": None, "label": None})
    assert o == Outer(count=3, rate=2, vec=(1, 2.5, 3), table={"a": 1.5}, items=(Inner("e", ("x", "z")),))
    assert isinstance(o.vec, tuple) and isinstance(o.items[0].axes, tuple)
    assert fill(Outer, None) == Outer()  # an empty section is all defaults
    assert list(keys(Outer)) == ["count", "rate", "flag", "label", "vec", "table", "items", "inner"]


def test_unsupported_annotation_is_a_bug_not_a_user_error() -> None:
    @dataclass(frozen=True)
    class Odd:
        x: set = field(default_factory=set)

    with pytest.raises(TypeError, match="unsupported annotation"):
        fill(Odd, {"x": [1]})


@dataclass(frozen=True)
class Extra:
    level: int = field(default=1, metadata=rule(ge=1, le=3))


@dataclass(frozen=True)
class Extended(RunConfig):
    extra: Extra = Extra()  # the one line a new section adds to RunConfig


def test_a_new_run_file_section_is_one_dataclass_and_one_line() -> None:
    cfg = fill(Extended, {"data": {"path": "x.csv"}, "extra": {"level": 2}})
    assert cfg.extra.level == 2 and cfg.data.path == "x.csv"
    with pytest.raises(ImucalError, match=r"extra.level: level 5 must be an integer from 1 to 3"):
        fill(Extended, {"data": {"path": "x.csv"}, "extra": {"level": 5}})


def test_fit_shorthands_are_the_long_forms() -> None:
    short = config_from_dict({"data": {"path": "x.csv"}, "fit": {"fix": {"phi": 1.5}, "effects": ["bias_drift"]}})
    long = config_from_dict({"data": {"path": "x.csv"}, "fit": {"fix": ["phi"], "initial": {"phi": 1.5},
                                                                 "effects": [{"name": "bias_drift"}]}})
    assert short.fit == long.fit and short.fit.effects[0].axes == ("x", "y", "z")


# --- every reader on the command line ----------------------------------------------------------
PLAN = {"poses": [[0, 0, 1], [0, 1, 0], [1, 0, 0], [0, 0, -1], [0, -1, 0], [-1, 0, 0], [1, 1, 0], [0, 1, 1],
                  [1, 0, 1], [1, 1, 1], [-1, 1, 0], [0, -1, 1]]}
MADLAB = {"K_a": (np.eye(3) * 200).tolist(), "R_a": np.eye(3).tolist(), "b_a": [1.0, 2.0, 3.0], "cal_type": "Ferraris"}
MATRIX = {"format": "imucal-affine", "matrix": np.eye(3).tolist(), "offset": [0.0, 0.0, 0.0]}
KALIBR = {"model": "scale-misalignment", "accelerometers": {"M": [[400.0, 0.0, 0.0], [1.0, 410.0, 0.0],
                                                                 [2.0, 3.0, 405.0]]},
          "imucal_accelerometer_offset": [1.0, 2.0, 3.0]}


def _gyro_calibration_v2() -> dict:
    """A version-2 file with both sensors, as imucal wrote it before issue 26 (tests/data)."""
    return yaml.safe_load((Path(__file__).parent / "data" / "calibration_v2_xsens_gyro.yaml").read_text())


def _gyro_calibration() -> dict:
    """The v1 test calibration with an identity gyroscope added (a version-3 file with both sensors)."""
    d = yaml.safe_load(V1_CALIBRATION.read_text())
    z = np.zeros(3)
    g = from_arrays(unit="rad/s", bias=z, scale=np.ones(3), misalignment=np.eye(3), gsens=np.zeros((3, 3)),
                        std={"bias": z, "scale": z, "misalignment": np.zeros((3, 3)), "gsens": np.zeros((3, 3))})
    return {**d, "format_version": 3, "sensors": ["accelerometer", "gyroscope"], "gyroscope": to_section(g)}


#: reader -> (file name, the good mapping, write(mapping) -> text, command line given the file and tmp)
READERS: dict[str, tuple[str, Callable[[], Any], Callable[[Any], str], Callable[[Path, Path], list]]] = {
    "run config": ("run.yaml", lambda: {"data": {"path": "x.csv"}}, yaml.safe_dump,
                   lambda f, tmp: ["calibrate", f, "--out", tmp / "o", "--no-figures"]),
    "simulation": ("sim.yaml", lambda: yaml.safe_load((ROOT / "configs" / "simulate_example.yaml").read_text()),
                   yaml.safe_dump, lambda f, tmp: ["simulate", f, "--out", tmp / "s.csv"]),
    "plan": ("plan.json", lambda: copy.deepcopy(PLAN), json.dumps,
             lambda f, tmp: ["plan-poses", "--evaluate", f, "--no-compare"]),
    "calibration v1": ("cal.yaml", lambda: yaml.safe_load(V1_CALIBRATION.read_text()), yaml.safe_dump,
                       lambda f, tmp: ["apply", f, "--data", tmp / "never.csv", "--out", tmp / "a.csv"]),
    "calibration v2 gyroscope": ("cal.yaml", _gyro_calibration_v2, yaml.safe_dump,
                                 lambda f, tmp: ["apply", f, "--data", tmp / "never.csv", "--out", tmp / "a.csv"]),
    "calibration v3 sensor section": ("cal.yaml", _gyro_calibration, yaml.safe_dump,
                                      lambda f, tmp: ["apply", f, "--data", tmp / "never.csv", "--out", tmp / "a.csv"]),
    "fleet manifest": ("fleet.yaml", lambda: {"units": [{"id": "U1", "data": "a.csv"}], "tolerances": {}},
                       yaml.safe_dump, lambda f, tmp: ["batch", f, "--out", tmp / "b"]),
    "kalibr imu.yaml": ("imu.yaml", lambda: copy.deepcopy(KALIBR), yaml.safe_dump,
                        lambda f, tmp: ["compare", V1_CALIBRATION, f, "--format", "kalibr", "--data",
                                        tmp / "never.csv"]),
    "mad-lab-fau/imucal JSON": ("x.json", lambda: copy.deepcopy(MADLAB), json.dumps,
                                lambda f, tmp: ["compare", V1_CALIBRATION, f, "--format", "madlab", "--data",
                                                tmp / "never.csv"]),
    "imucal matrix JSON": ("m.json", lambda: copy.deepcopy(MATRIX), json.dumps,
                           lambda f, tmp: ["compare", V1_CALIBRATION, f, "--format", "matrix", "--data",
                                           tmp / "never.csv"]),
}


def _set(d: dict, where: str, value: Any) -> None:
    *head, last = where.split(".")
    for k in head:
        d = d[int(k)] if isinstance(d, list) else d[k]
    if value is _DELETE:
        del d[last]
    else:
        d[last] = value


_DELETE = object()
#: reader -> [(kind, key path, value, field named, words of the message)]
BAD = {
    "run config": [
        ("wrong type", "static", {"window": "half"}, "static.window", "window 'half' must be a positive number"),
        ("unknown key", "fit", {"mode": "means", "modes": 1}, "fit.modes", "unknown key 'modes'"),
        ("bool for number", "static", {"trim": True}, "static.trim", "trim True must be a non-negative number"),
        ("NaN", "gravity", {"latitude": float("nan")}, "gravity.latitude", "latitude is not finite (nan)"),
        ("missing required", "data", {"unit": "raw"}, "data.path", "missing key 'path'"),
    ],
    "simulation": [
        ("wrong type", "plan.n_random", "many", "plan.n_random", "n_random 'many' must be an integer from 0 to"),
        ("unknown key", "sensor.colour", "red", "sensor.colour", "unknown key 'colour'"),
        ("bool for number", "seed", True, "seed", "seed True must be an integer"),
        ("NaN", "temperature.start", float("nan"), "temperature.start", "start is not finite (nan)"),
        ("missing required", "sensor.effects", {"bias_temperature": 5}, "sensor.effects.bias_temperature",
         "5 must be a mapping"),
    ],
    "plan": [
        ("wrong type", "poses", "up", "poses", "poses must be a non-empty list"),
        ("unknown key", "posse", 1, "posse", "unknown key 'posse'"),
        ("bool for number", "format_version", True, "format_version", "unknown format_version True"),
        ("NaN", "poses", [[0, 0, 1e999]] + PLAN["poses"], "poses[0][2]", "poses is not finite (inf)"),
        ("missing required", "poses", _DELETE, "poses", "missing key 'poses'"),
    ],
    "calibration v1": [
        ("wrong type", "parameters.s1.value", "big", "parameters.s1.value", "'big' is not a number"),
        ("unknown key", "parameters.s1.colour", "red", "parameters.s1.colour", "unknown key 'colour'"),
        ("bool for number", "gravity", True, "gravity", "gravity True is not a local gravity on Earth"),
        ("NaN", "parameters.b1.value", float("nan"), "parameters.b1.value", "value is not finite (nan)"),
        ("missing required", "parameters.s1.value", _DELETE, "parameters.s1.value", "missing key 'value'"),
    ],
    "calibration v2 gyroscope": [
        ("wrong type", "gyroscope.parameters.bias", "zero", "gyroscope.parameters.bias", "must be a list of 3 values"),
        ("unknown key", "gyroscope.colour", "red", "gyroscope.colour", "unknown key 'colour'"),
        ("bool for number", "gyroscope.parameters.scale", [True, 1.0, 1.0], "gyroscope.parameters.scale[0]",
         "scale True must be a number from"),
        ("NaN", "gyroscope.parameters.scale", [1.0, float("nan"), 1.0], "gyroscope.parameters.scale[1]",
         "scale is not finite (nan)"),
        ("missing required", "gyroscope.units", _DELETE, "gyroscope.units", "missing section 'units'"),
    ],
    "calibration v3 sensor section": [
        ("wrong type", "gyroscope.parameters.bias_x", "zero", "gyroscope.parameters.bias_x", "must be a mapping"),
        ("unknown key", "gyroscope.colour", "red", "gyroscope.colour", "unknown key 'colour'"),
        ("bool for number", "gyroscope.parameters.scale_x.value", True, "gyroscope.parameters.scale_x.value",
         "True is not a number"),
        ("NaN", "gyroscope.parameters.scale_y.value", float("nan"), "gyroscope.parameters.scale_y.value",
         "value is not finite (nan)"),
        ("missing required", "gyroscope.units", _DELETE, "gyroscope.units", "missing section 'units'"),
    ],
    "fleet manifest": [
        ("wrong type", "units", 5, "units", "units must be a list or a CSV file name, got 5"),
        ("unknown key", "unit", [], "unit", "unknown key 'unit'"),
        ("bool for number", "tolerances", {"rms_max": True}, "tolerances.rms_max", "True must be a non-negative"),
        ("NaN", "tolerances", {"rms_max": float("nan")}, "tolerances.rms_max", "rms_max is not finite (nan)"),
        ("missing required", "units", [{"data": "a.csv"}], "units[0].id", "missing key 'id'"),
    ],
    "kalibr imu.yaml": [
        ("wrong type", "rostopic", 5, "rostopic", "5 is not a topic name"),
        ("unknown key", "accelerometers.B", 1, "accelerometers.B", "unknown key 'B'"),
        ("bool for number", "update_rate", True, "update_rate", "update_rate True must be a positive number"),
        ("NaN", "imucal_accelerometer_offset", [0.0, float("nan"), 0.0], "imucal_accelerometer_offset[1]",
         "imucal_accelerometer_offset is not finite (nan)"),
        ("missing required", "accelerometers", _DELETE, "accelerometers", "missing section 'accelerometers'"),
    ],
    "mad-lab-fau/imucal JSON": [
        ("wrong type", "K_a", "identity", "K_a", "K_a 'identity' must be a list of 3 values"),
        ("unknown key", "K_x", 1, "K_x", "unknown key 'K_x'"),
        ("bool for number", "b_a", [1.0, False, 3.0], "b_a[1]", "b_a False must be a number from"),
        ("NaN", "b_a", [1.0, 1e999, 3.0], "calibration", "Infinity is not a JSON number"),  # refused by the parser
        ("missing required", "R_a", _DELETE, "R_a", "missing key 'R_a'"),
    ],
    "imucal matrix JSON": [
        ("wrong type", "gyroscope", 5, "gyroscope", "gyroscope 5 must be a mapping (or null)"),
        ("unknown key", "matrx", 1, "matrx", "unknown key 'matrx'"),
        ("bool for number", "offset", [True, 0.0, 0.0], "offset[0]", "offset True must be a number from"),
        ("NaN", "offset", [0.0, 0.0, 1e999], "matrix", "Infinity is not a JSON number"),
        ("missing required", "format", _DELETE, "format", "missing key 'format'"),
    ],
}
CASES = [(reader, *case) for reader, cases in BAD.items() for case in cases]


def test_every_reader_has_every_kind_of_bad_input() -> None:
    kinds = {"wrong type", "unknown key", "bool for number", "NaN", "missing required"}
    assert set(BAD) == set(READERS) and all({c[0] for c in cases} == kinds for cases in BAD.values())


@pytest.mark.parametrize("reader", list(READERS))
def test_the_good_file_of_each_reader_passes_its_schema(reader: str, tmp_path: Path) -> None:
    """The bad cases differ from a file the reader accepts by the one edit."""
    from imucal.analysis.plan_file import read_plan
    from imucal.analysis.simulate import load_simulation_config
    from imucal.export.registry import read_peer
    from imucal.export.kalibr import read_kalibr_yaml
    from imucal.fleet.manifest import manifest_from_dict

    name, good, dump, _ = READERS[reader]
    p = tmp_path / name
    p.write_text(dump(good()))
    read = {"run config": lambda: config_from_dict(yaml.safe_load(p.read_text()), str(p)),
            "simulation": lambda: load_simulation_config(str(p)), "plan": lambda: read_plan(str(p)),
            "calibration v1": lambda: load_calibration(p), "calibration v2 gyroscope": lambda: load_calibration(p),
            "calibration v3 sensor section": lambda: load_calibration(p),
            "fleet manifest": lambda: manifest_from_dict(yaml.safe_load(p.read_text()), str(p)),
            "kalibr imu.yaml": lambda: read_kalibr_yaml(p), "mad-lab-fau/imucal JSON": lambda: read_peer(p, "madlab"),
            "imucal matrix JSON": lambda: read_peer(p, "matrix")}[reader]
    assert read() is not None


@pytest.mark.parametrize("reader, kind, where, value, field_, words", CASES,
                         ids=[f"{c[0]}: {c[1]}" for c in CASES])
def test_bad_input_exits_2_with_one_line(run_cli, tmp_path: Path, reader: str, kind: str, where: str, value: Any,
                                         field_: str, words: str) -> None:
    name, good, dump, argv = READERS[reader]
    d = good()
    _set(d, where, value if value is _DELETE else copy.deepcopy(value))
    p = tmp_path / name
    p.write_text(dump(d))
    r = run_cli(argv(p, tmp_path))
    assert r.code == 2, (r.code, r.err, r.out)
    assert "Traceback" not in r.err and len(r.err.splitlines()) == 1, r.err
    assert r.err.startswith(f"imucal: error: {p}: {field_}: "), r.err
    assert words in r.err, r.err
