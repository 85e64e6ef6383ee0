"""Every input used or refused, bounded resources (issue 9): run configs, simulation configs, plans.

* Hypothesis feeds config_from_dict / load_config, simulation_from_dict / load_simulation_config
  and plan-poses' plan reader with arbitrary YAML-like structures (nested dicts, lists, strings,
  ints, floats, bools, None; huge integers, NaN, infinities) and with mutations of the shipped
  configs/*.yaml: only ImucalError, with a one-line bounded message, never another exception.
* Each refusal found that way has a CLI test: exact message, exit status 2, nothing changed.
"""
from __future__ import annotations

import copy
import json
import math
import warnings
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from imucal.analysis.plan_file import read_plan as _read_plan
from imucal.config.run import config_from_dict, load_config
from imucal.analysis.design import compare, evaluate, optimal_design
from imucal.errors import ImucalError
from imucal.analysis.simulate import load_simulation_config, simulation_from_dict
from imucal.files.yamlio import read_yaml

ROOT = Path(__file__).resolve().parents[1]
RUN_CONFIGS = sorted(p for p in (ROOT / "configs").glob("*.yaml") if not p.name.startswith("simulate_"))
SIM_CONFIG = ROOT / "configs" / "simulate_example.yaml"
SETTINGS = settings(max_examples=200, deadline=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
#: Longest message a refusal may print: values in it are cut (imucal.errors.short).
MAX_MESSAGE = 600


def _refused(exc: ImucalError) -> None:
    text = str(exc)
    assert text and "\n" not in text and len(text) < MAX_MESSAGE, (len(text), text[:400])


def one_line_error(err: str, *parts: str) -> None:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("imucal: "), err
    for p in parts:
        assert p in lines[0], (p, lines[0])


# --- strategies -----------------------------------------------------------------------------
WEIRD = [None, True, False, 0, -1, 1, 2**63, 10**400, -(10**400), float("nan"), float("inf"), -float("inf"),
         1e300, -1e300, 5e-324, -0.0, 1.5708, 9.81, 100.0, 1e9, "", "x" * 5000, "*/", "\x00", "phi", "raw",
         "m/s^2", "faces", "random", "means", "samples", "s", "ms", [], {}, [1, 2, 3], [[0, 0, 1]], {"phi": 1}]
scalars = st.one_of(st.sampled_from(WEIRD).map(copy.deepcopy), st.integers(), st.floats(), st.text(max_size=12), st.booleans())
structures = st.recursive(scalars, lambda kids: st.one_of(
    st.lists(kids, max_size=4), st.dictionaries(st.one_of(st.text(max_size=8), st.sampled_from(
        ["data", "path", "fit", "fix", "gravity", "height", "latitude", "value", "sensor", "plan", "rate",
         "n_random", "hold", "seed", "poses", "format", "effects", "columns", "initial"])), kids, max_size=4)),
    max_leaves=12)


def _paths(obj, prefix=()):
    """Every place in a nested structure (to mutate)."""
    yield prefix
    if isinstance(obj, dict):
        for k, v in obj.items():
            yield from _paths(v, prefix + (k,))
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            yield from _paths(v, prefix + (i,))


def _set(obj, path, value):
    if not path:
        return value
    parent = obj
    for k in path[:-1]:
        parent = parent[k]
    parent[path[-1]] = value
    return obj


@st.composite
def mutated(draw, original):
    """The original structure with a few values replaced, keys dropped or unknown keys added."""
    obj = copy.deepcopy(original)
    for _ in range(draw(st.integers(1, 3))):
        path = draw(st.sampled_from(list(_paths(obj))))
        action = draw(st.sampled_from(["replace", "replace", "drop", "add"]))
        if action == "replace":
            obj = _set(obj, path, draw(structures))
        elif action == "drop" and path:
            parent = obj
            for k in path[:-1]:
                parent = parent[k]
            del parent[path[-1]]
        elif action == "add":
            target = obj
            for k in path:
                target = target[k]
            if isinstance(target, dict):
                target[draw(st.text(max_size=6))] = draw(structures)
    return obj


def _dump(obj) -> str:
    return yaml.safe_dump(obj, allow_unicode=True)


# --- run configs ----------------------------------------------------------------------------
@SETTINGS
@given(d=structures)
@example(d={"data": {"path": "a.csv"}, "gravity": {"height": 10**400}})
@example(d={"data": {"path": "a.csv"}, "fit": {"fix": {"phi": 10**400}}})
@example(d={"data": {"path": "a.csv", "sample_rate": 10**400}})
@example(d={"data": {"path": "a.csv"}, "static": {"window": float("nan")}})
def test_config_from_any_structure_is_loaded_or_refused(d):
    try:
        config_from_dict(d, "run.yaml")
    except ImucalError as exc:
        _refused(exc)


@pytest.mark.parametrize("name", [p.name for p in RUN_CONFIGS])
def test_shipped_configs_still_load(name):
    cfg = load_config(ROOT / "configs" / name)
    assert cfg.data.path


@SETTINGS
@given(data=st.data())
def test_mutated_shipped_configs_are_loaded_or_refused(tmp_path, data):
    src = data.draw(st.sampled_from(RUN_CONFIGS))
    d = data.draw(mutated(yaml.safe_load(src.read_text())))
    p = tmp_path / "run.yaml"
    p.write_text(_dump(d))
    for load in (lambda: load_config(p), lambda: config_from_dict(d, str(p))):
        try:
            load()
        except ImucalError as exc:
            _refused(exc)


# --- simulation configs ---------------------------------------------------------------------
@SETTINGS
@given(d=structures)
@example(d={"plan": {"n_random": 10**12, "directions": "random"}})
@example(d={"plan": {"directions": [["a", 1, 2]]}})
@example(d={"plan": {"directions": [[10**400, 0, 1]]}})
@example(d={"seed": 10**400})
@example(d={"sensor": {"unit": ["x"]}})
@example(d={"sensor": {"effects": {"nope": {"a": 1}}}})
@example(d={"temperature": {"start": 10**400}})
def test_simulation_config_from_any_structure_is_loaded_or_refused(d):
    try:
        simulation_from_dict(d, "sim.yaml")
    except ImucalError as exc:
        _refused(exc)


@SETTINGS
@given(data=st.data())
def test_mutated_simulation_config_is_loaded_or_refused(tmp_path, data):
    d = data.draw(mutated(yaml.safe_load(SIM_CONFIG.read_text())))
    p = tmp_path / "sim.yaml"
    p.write_text(_dump(d))
    for load in (lambda: load_simulation_config(str(p)), lambda: simulation_from_dict(d, str(p))):
        try:
            load()
        except ImucalError as exc:
            _refused(exc)


# --- plan files -------------------------------------------------------------------------------
PLAN = {"format": "imucal-pose-plan", "format_version": 1,
        "poses": [[0, 0, 1], [0, 1, 0], [1, 0, 0], [0, 0, -1], [0, -1, 0], [-1, 0, 0],
                  [1, 1, 0], [1, 0, 1], [0, 1, 1], [-1, 1, 0], [1, 0, -1], [0, -1, 1]]}


@SETTINGS
@given(d=st.one_of(structures, mutated(PLAN)))
@example(d={"poses": [[1e308, 1e308, 1e308]] + PLAN["poses"]})
@example(d={"poses": [[1e-320, 0, 0]] + PLAN["poses"]})
def test_plan_from_any_structure_is_scored_or_refused(tmp_path, d):
    p = tmp_path / "plan.json"
    try:
        p.write_text(json.dumps(d, allow_nan=True))
    except (ValueError, OverflowError):
        return  # not JSON-serialisable: nothing to read
    try:
        evaluate(_read_plan(str(p)), "D", 0.002)
    except ImucalError as exc:
        _refused(exc)


@SETTINGS
@given(blob=st.binary(max_size=300))
@example(blob=b"[" * 5000)
@example(blob=b'{"poses": [[0, 0, 1]], "poses": [[1, 0, 0]]}')
def test_plan_from_any_bytes_is_read_or_refused(tmp_path, blob):
    p = tmp_path / "plan.json"
    p.write_bytes(blob)
    try:
        _read_plan(str(p))
    except ImucalError as exc:
        _refused(exc)


# --- each case on the command line: exact message, status 2, nothing changed -----------------
@pytest.mark.parametrize("text, field, msg", [
    ("data: {path: a.csv}\ngravity: {height: 300, value: 9.81}\n", "gravity.height",
     "is used only with a latitude (fix: drop gravity.height: gravity.value already sets g)"),
    ("data: {path: a.csv}\nfit: {fix: [1, 2]}\n", "fit.fix", "is not a parameter name, a list of names"),
    ("data: {path: a.csv}\nfit: {fix: {phi: [1]}}\n", "fit.fix.phi", "value [1] to hold phi at is not a finite"),
    ("data: {path: a.csv}\n" + "k" * 1000 + ": 1\n", "unknown key 'kkkk", "allowed top-level keys"),
    ("data: {path: " + "p" * 5000 + "}\ngravity: {value: " + "g" * 5000 + "}\n", "gravity.value",
     "is not a local gravity on Earth"),
    ("data: {path: a.csv, sample_rate: " + "1" * 330 + "}\n", "data.sample_rate",
     "integer is too large for a float"),
])
def test_bad_run_file_values_are_refused_in_one_short_line(run_cli, tmp_path, unchanged, text, field, msg):
    cfg = tmp_path / "run.yaml"
    cfg.write_text(text)
    with unchanged():
        r = run_cli(["calibrate", cfg, "--out", tmp_path / "o"])
    assert r.code == 2
    one_line_error(r.err, field, msg)
    assert len(r.err) < MAX_MESSAGE


@pytest.mark.parametrize("plan, field, msg", [
    ("plan: {directions: random, n_random: 1000000000000}\n", "plan.n_random",
     "n_random 1000000000000 must be an integer from 0 to 10000"),
    ("plan: {directions: [[a, 1, 2]]}\n", "plan.directions", "a list of at most 10000 [x, y, z]"),
    ("seed: -1\n", "seed", "must be an integer from 0 to"),
    ("sensor: {unit: [m]}\n", "sensor.unit", "must be a short name"),
    ("plan: {" + "q" * 1000 + ": 1}\n", "plan.'qqq", "unknown key"),
])
def test_bad_simulation_files_are_refused_before_allocating(run_cli, tmp_path, unchanged, plan, field, msg):
    cfg = tmp_path / "sim.yaml"
    cfg.write_text(plan)
    with unchanged():
        r = run_cli(["simulate", cfg, "--out", tmp_path / "s.csv"])
    assert r.code == 2
    one_line_error(r.err, "sim.yaml", field, msg)
    assert len(r.err) < MAX_MESSAGE


def test_simulate_seed_override_is_checked(run_cli, tmp_path, unchanged):
    cfg = tmp_path / "sim.yaml"
    cfg.write_text("seed: 1\n")
    with unchanged():
        r = run_cli(["simulate", cfg, "--out", tmp_path / "s.csv", "--seed", "-5"])
    assert r.code == 2
    one_line_error(r.err, "--seed", "-5 must be an integer from 0 to")


def test_a_listed_simulation_pose_of_huge_numbers_is_a_direction(tmp_path):
    """[1e308, 1e308, 0] overflowed the norm; scaled first, it is the direction of [1, 1, 0]."""
    cfg = simulation_from_dict({"plan": {"directions": [[1e308, 1e308, 0], [0, 0, 1]], "hold": 1.0,
                                         "transition": 1.0}})
    assert cfg.plan.directions[0] == pytest.approx([math.sqrt(0.5), math.sqrt(0.5), 0.0])


PLAN_CASES = [
    ('{"poses": [[0, 0, 1]], "poses": [[1, 0, 0]]}', "evaluate", "duplicate key 'poses'"),
    ('{"poses": [[0, 0, 1]], "posse": 1}', "posse", "unknown key 'posse'"),
    ("[" * 5000, "evaluate", "is nested too deeply"),
    (json.dumps({"poses": [[0, 0, 1]] * 10001}), "poses", "10001 entries, above the limit of 10000"),
    (json.dumps({"poses": [[1, 0, 0]] * 12, "format_version": True}), "format_version", "unknown format_version"),
]


@pytest.mark.parametrize("text, field, msg", PLAN_CASES)
def test_bad_plan_files_are_refused_in_one_line(run_cli, tmp_path, unchanged, text, field, msg):
    plan = tmp_path / "plan.json"
    plan.write_text(text)
    with unchanged():
        r = run_cli(["plan-poses", "--evaluate", plan, "--no-compare"])
    assert r.code == 2
    one_line_error(r.err, "plan.json", field, msg)


def test_plan_poses_json_output_is_read_back(run_cli, tmp_path):
    """Every key plan-poses --json writes is one the plan reader accepts."""
    out = tmp_path / "plan.json"
    r = run_cli(["plan-poses", "--scheme", "faces+edges", "--json", out])
    assert r.code == 0, r.err
    r = run_cli(["plan-poses", "--evaluate", out, "--no-compare"])
    assert r.code == 0, r.err


def test_a_plan_pose_of_huge_numbers_is_a_direction(tmp_path):
    plan = tmp_path / "plan.json"
    plan.write_text(json.dumps({"poses": [[1e308, 1e308, 0]] + PLAN["poses"]}))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # numpy's overflow RuntimeWarning was printed before
        d = evaluate(_read_plan(str(plan)), "D", 0.002)
    assert d.directions[0] == pytest.approx([math.sqrt(0.5), math.sqrt(0.5), 0.0])


@pytest.mark.parametrize("call, field, msg", [
    (lambda: optimal_design(12, starts=10**9), "starts", "must be an integer from 1 to 10000"),
    (lambda: optimal_design(12, grid=10**9), "grid", "must be an integer from 1 to 100000"),
    (lambda: optimal_design(12, seed=-1), "seed", "must be an integer from 0 to"),
    (lambda: compare(evaluate(PLAN["poses"]), n_random=10**9), "n_random", "must be an integer from 0 to 10000"),
])
def test_design_counts_are_bounded(call, field, msg):
    with pytest.raises(ImucalError) as exc:
        call()
    assert exc.value.field == field and msg in str(exc.value)


def test_read_yaml_and_config_from_dict_refuse_the_same_huge_integer(tmp_path):
    p = tmp_path / "run.yaml"
    p.write_text("data: {path: a.csv}\nfit: {fix: {phi: " + "9" * 400 + "}}\n")
    with pytest.raises(ImucalError, match="fit.fix.phi: integer is too large for a float"):
        load_config(p)
    with pytest.raises(ImucalError, match="fit.fix.phi: integer is too large for a float"):
        config_from_dict({"data": {"path": "a.csv"}, "fit": {"fix": {"phi": 10**400}}})
    assert read_yaml(ROOT / "configs" / "xsens-mti-imutk.yaml", "config", "")["data"]


@pytest.mark.parametrize("fit, field, words", [
    ({"effects": [{"name": "bias_warmup", "axes": ["x"]}, {"name": "bias_warmup", "axes": ["y"]}]},
     "fit.effects[1]", "is listed twice"),
    ({"effects": ["bias_warmup"], "initial": {"bias_warmup_tau": -5.0}}, "fit.initial.bias_warmup_tau",
     "is outside its bounds"),
    ({"effects": ["scale_drift2"], "initial": {"scale_drift2_x": -1.0}}, "fit.initial.scale_drift2_x",
     "is outside its bounds")])
def test_effect_settings_are_blamed_not_the_poses(si_recording, tmp_path, run_cli, fit, field, words):
    """An effect listed twice was 'parameters: duplicate parameter' with no file or fix; a start outside
    its bounds made the observability check blame the orientations."""
    cfg = tmp_path / "run.yaml"
    cfg.write_text(yaml.safe_dump({"data": {"path": str(si_recording.path), "unit": "m/s^2"}, "fit": fit}))
    r = run_cli(["calibrate", str(cfg), "--out", str(tmp_path / "o")])
    assert r.code == 2 and r.err.startswith(f"imucal: error: {cfg}: {field}: ") and words in r.err, r.err
    assert len(r.err.strip().splitlines()) == 1 and not (tmp_path / "o").exists()
