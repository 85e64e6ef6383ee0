"""Property tests (hypothesis).

* The loaders (load_recording, load_config, load_calibration) never crash: arbitrary bytes,
  malformed CSV and malformed YAML either load or raise ImucalError with a one-line message,
  never anything else.
* apply(calibrate(x)) round trips: data made from known accelerations by a known sensor come
  back as those accelerations (exactly for the forward model; within noise after a fit).
"""
from __future__ import annotations

import math

import numpy as np
import yaml
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from imucal.calibration.frozen import Calibration

from imucal.calibration.frozen import load_calibration
from imucal.config.run import load_config
from imucal.data.load import load_recording
from imucal.data.spec import DataSpec
from imucal.errors import ImucalError
from imucal.solve.fit import FitData, fit
from imucal.model.sensor import build_model
from imucal.model.parameters import base_parameters
from imucal.analysis.simulate import cube_directions, frame_matrix

HALF_PI = math.pi / 2
SETTINGS = settings(max_examples=150, deadline=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])


def _one_line_error(exc: ImucalError) -> None:
    text = str(exc)
    assert text and "\n" not in text and "Traceback" not in text


def _write(tmp_path, name: str, blob: bytes):
    p = tmp_path / name
    p.write_bytes(blob)
    return p


# --- strategies -----------------------------------------------------------------------------
_cell = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(-10**6, 10**6).map(str),
    st.sampled_from(["", " ", "nan", "inf", "-inf", "abc", "1e999", "0x10", "1_0", '"', "'", "#", "1,5",
                     "t", "ax", "ay", "az", "temp", "\t", "\x00", "é", "1.0.0", "--1", "+", "."]),
    st.text(max_size=6),
)
_row = st.lists(_cell, min_size=0, max_size=7)
_sep = st.sampled_from([",", ";", "\t", " ", "  ", ", "])
_header = st.one_of(
    st.just(["t", "ax", "ay", "az"]), st.just(["t", "ax", "ay", "az", "temp"]), st.just(["ax", "ay", "az"]),
    st.just(["time", "acc_x", "acc_y", "acc_z"]), st.lists(st.sampled_from(["t", "ax", "ay", "az", "x", "q"]),
                                                          max_size=6), st.just([]))


@st.composite
def malformed_csv(draw) -> bytes:
    sep = draw(_sep)
    lines = []
    hdr = draw(_header)
    if hdr:
        lines.append(sep.join(hdr))
    good = draw(st.integers(0, 6))
    for k in range(good):  # some plausible rows, so the parser gets past the header
        lines.append(sep.join(str(v) for v in [k * 0.01, 1.0 + k, 2.0, 3.0][: max(len(hdr), 3)]))
    lines += [sep.join(r) for r in draw(st.lists(_row, max_size=6))]
    if draw(st.booleans()):
        draw_idx = draw(st.integers(0, max(len(lines) - 1, 0)))
        lines.insert(draw_idx, draw(st.sampled_from(["# comment", "", "   ", "\ufeff", "\r"])))
    end = draw(st.sampled_from(["\n", "\r\n", "\r"]))
    return end.join(lines).encode("utf-8", errors="surrogatepass") if draw(st.booleans()) \
        else end.join(lines).encode("utf-8", errors="replace")


def _yaml_scalar():
    return st.one_of(st.none(), st.booleans(), st.integers(-10**9, 10**9), st.floats(),
                     st.text(max_size=8), st.sampled_from(["x.csv", "t", "ax", "phi", "means", "samples",
                                                           "csv", "whitespace", "s", "ms", ".nan", "1e999"]))


_yaml_value = st.recursive(_yaml_scalar(), lambda inner: st.one_of(
    st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=6), inner, max_size=4)), max_leaves=8)

_CONFIG_KEYS = {
    "data": ["path", "format", "columns", "delimiter", "skip_rows", "sample_rate", "time_unit", "unit", "bogus"],
    "static": ["window", "min_duration", "threshold", "trim", "bogus"],
    "gravity": ["value", "latitude", "height", "bogus"],
    "fit": ["mode", "angle_tolerance", "fix", "initial", "effects", "bogus"],
    "output": ["dir", "figures", "bogus"],
}


@st.composite
def config_like(draw) -> object:
    """Mostly well-shaped configs with wrong values, sometimes wrong shapes."""
    d = {}
    for sec, keys in _CONFIG_KEYS.items():
        if draw(st.booleans()):
            if draw(st.integers(0, 9)) == 0:
                d[sec] = draw(_yaml_value)
            else:
                d[sec] = {k: draw(_yaml_value) for k in draw(st.lists(st.sampled_from(keys), max_size=4,
                                                                       unique=True))}
    if draw(st.integers(0, 4)) == 0:
        d[draw(st.text(max_size=5))] = draw(_yaml_value)
    return d


def _calibration_dict() -> dict:
    params = base_parameters([1.0, 2.0, 3.0], [1.0, 1.01, 0.99], [1.57, 1.571, 1.5705])
    return Calibration(params=params, std={n: 0.1 for n in params}, gravity=9.81).to_dict()


@st.composite
def calibration_like(draw) -> object:
    """A valid calibration dict with a few entries replaced by arbitrary YAML values."""
    d = _calibration_dict()
    for _ in range(draw(st.integers(1, 3))):
        where = draw(st.sampled_from(["top", "param", "effects", "remove"]))
        if where == "top":
            d[draw(st.sampled_from(list(d)))] = draw(_yaml_value)
        elif where == "param" and isinstance(d.get("parameters"), dict) and d["parameters"]:
            name = draw(st.sampled_from(sorted(d["parameters"])))
            entry = d["parameters"][name]
            if isinstance(entry, dict):
                entry[draw(st.sampled_from(["value", "std", "lower", "upper", "fixed", "scale", "unit"]))] = \
                    draw(_yaml_value)
            else:
                d["parameters"][name] = draw(_yaml_value)
        elif where == "effects":
            d["effects"] = draw(st.one_of(_yaml_value, st.lists(st.fixed_dictionaries(
                {"name": _yaml_scalar(), "axes": _yaml_value}), max_size=2)))
        else:
            d.pop(draw(st.sampled_from(sorted(d))), None)
    return d


def _dump(obj) -> bytes:
    try:
        return yaml.safe_dump(obj, allow_unicode=True).encode("utf-8", errors="surrogatepass")
    except (yaml.YAMLError, UnicodeEncodeError):
        return b"{}"


# --- loaders never crash --------------------------------------------------------------------
@SETTINGS
@given(blob=st.binary(max_size=400))
@example(blob=b"\xff\xfe\x00\x01")
@example(blob=b"t,ax,ay,az\n0,1,2,3\n0,1,2,3\n")
@example(blob=b"0 1 2 3\n")
@example(blob=b"1_0 2 3\n")
def test_load_recording_arbitrary_bytes(tmp_path, blob):
    p = _write(tmp_path, "rec.csv", blob)
    try:
        rec = load_recording(p)
    except ImucalError as exc:
        _one_line_error(exc)
    else:
        assert rec.raw.ndim == 2 and rec.raw.shape[1] == 3 and rec.t.shape == (rec.n,)
        assert np.isfinite(rec.raw).all() and np.isfinite(rec.t).all()


@SETTINGS
@given(blob=malformed_csv(),
       spec=st.fixed_dictionaries({}, optional={
           "format": st.sampled_from(["auto", "csv", "whitespace"]),
           "sample_rate": st.sampled_from([100.0, 0.5]),
           "skip_rows": st.integers(0, 3),
           "delimiter": st.sampled_from([",", ";", "\t", " "]),
           "time_unit": st.sampled_from(["s", "ms"]),
           "columns": st.dictionaries(st.sampled_from(["t", "ax", "ay", "az", "temp"]),
                                      st.one_of(st.integers(0, 6), st.sampled_from(["t", "ax", "q", "x"])),
                                      max_size=5)}))
@example(blob=b"t,ax,ay,az", spec={"format": "auto", "columns": {"t": 4}})  # an index past the header: IndexError
def test_load_recording_malformed_csv(tmp_path, blob, spec):
    p = _write(tmp_path, "rec.csv", blob)
    try:
        rec = load_recording(DataSpec(path=str(p), **spec))
    except ImucalError as exc:
        _one_line_error(exc)
    else:
        assert rec.raw.shape == (rec.n, 3) and np.isfinite(rec.raw).all()
        assert rec.n == 1 or (np.diff(rec.t) > 0).all()


@SETTINGS
@given(blob=st.one_of(st.binary(max_size=300), st.text(max_size=300).map(
    lambda s: s.encode("utf-8", errors="surrogatepass"))))
@example(blob=b"data: [\n")
@example(blob=b"!!python/object:os.system {}")
@example(blob=b"data: !!int abc")
@example(blob=b"data: !!timestamp 2001-02-30")
@example(blob=b"? [1]\n: 2")
@example(blob=b"data: !!binary '%%%'")
@example(blob=b"[" * 200)
def test_load_config_arbitrary_bytes(tmp_path, blob):
    p = _write(tmp_path, "run.yaml", blob)
    try:
        load_config(p)
    except ImucalError as exc:
        _one_line_error(exc)


@SETTINGS
@given(d=config_like())
@example(d={"data": {"path": "x.csv"}, "fit": {"effects": 5}})
@example(d={"data": {"path": None}})
@example(d={"data": {"path": 5}})
@example(d={"data": {"path": "x.csv", "delimiter": 5}})
@example(d={"data": {"path": "x.csv", "time_unit": []}})
@example(d={"data": {"path": "x.csv"}, "gravity": {"latitude": "abc"}})
@example(d={"data": {"path": "x.csv"}, "gravity": {"latitude": 100}})
@example(d={"data": {"path": "x.csv"}, "output": {"dir": 5}})
@example(d={"data": {"path": "x.csv"}, "fit": {"effects": [{"name": ["a"]}]}})
@example(d={"data": {"path": "x.csv"}, "static": {"threshold": "abc"}})
def test_load_config_malformed_yaml(tmp_path, d):
    p = _write(tmp_path, "run.yaml", _dump(d))
    try:
        cfg = load_config(p)
    except ImucalError as exc:
        _one_line_error(exc)
        return
    # What loads is well-typed enough for the pipeline's first steps.
    assert isinstance(cfg.data.path, str) and cfg.data.path
    assert cfg.static.window > 0 and cfg.static.min_duration > 0
    g, _ = cfg.gravity.resolve()
    assert 9.7 < g < 9.9
    assert isinstance(cfg.output.dir, str)
    assert all(isinstance(n, str) for n in cfg.fit.fix)


@SETTINGS
@given(blob=st.binary(max_size=300))
@example(blob=b"format: imucal-calibration\nformat_version: 1\n")
@example(blob=b"[1, 2]")
def test_load_calibration_arbitrary_bytes(tmp_path, blob):
    p = _write(tmp_path, "cal.yaml", blob)
    try:
        load_calibration(p)
    except ImucalError as exc:
        _one_line_error(exc)


@SETTINGS
@given(d=calibration_like())
def test_load_calibration_malformed_yaml(tmp_path, d):
    p = _write(tmp_path, "cal.yaml", _dump(d))
    try:
        cal = load_calibration(p)
    except ImucalError as exc:
        _one_line_error(exc)
        return
    # Whatever loads applies: a finite map of finite readings.
    a = cal.apply(np.array([[0.1, 0.2, 9.8]]), {c: np.zeros(1) for c in cal.covariates})
    assert np.isfinite(a).all()


# --- apply(calibrate(x)) round trips ---------------------------------------------------------
finite = dict(allow_nan=False, allow_infinity=False)
sensor_params = st.fixed_dictionaries({
    "s": st.lists(st.floats(-1000, 1000, **finite), min_size=3, max_size=3),
    "b": st.lists(st.floats(0.05, 5000, **finite), min_size=3, max_size=3),
    "dang": st.lists(st.floats(-0.018, 0.018, **finite), min_size=3, max_size=3),
})


def _params(sp):
    return base_parameters(sp["s"], sp["b"], HALF_PI * (1 + np.array(sp["dang"])))


@settings(max_examples=150, deadline=None)
@given(sp=sensor_params, acc=st.lists(st.lists(st.floats(-50, 50, **finite), min_size=3, max_size=3),
                                      min_size=1, max_size=20))
def test_apply_inverts_the_forward_model(sp, acc):
    """raw = s + b * E^T a (Lemma 1, Eq. theModel) -> apply(raw) = a, exactly up to rounding."""
    params = _params(sp)
    cal = Calibration(params=params, std={}, gravity=9.80665)
    a = np.array(acc)
    E = frame_matrix(np.array([params[n].value for n in ("phi", "psi", "theta")]))
    raw = np.array(sp["s"]) + np.array(sp["b"]) * (a @ E)
    back = cal.apply(raw)
    np.testing.assert_allclose(back, a, atol=1e-8 * (1 + np.abs(a).max()))
    A, _ = cal.linear_map()
    assert np.all(np.triu(A, 1) == 0.0)


@settings(max_examples=40, deadline=None)
@given(sp=sensor_params, seed=st.integers(0, 2**32 - 1),
       rel_noise=st.sampled_from([1e-5, 1e-4, 3e-4]))
def test_apply_of_calibrate_round_trips(sp, seed, rel_noise):
    """Fit interval means made by a random sensor, then apply: directions and |a| come back."""
    model = build_model()
    truth = _params(sp)
    g = 9.80665
    rng = np.random.default_rng(seed)
    dirs = cube_directions()
    E = frame_matrix(np.array([truth[n].value for n in ("phi", "psi", "theta")]))
    b = np.array(sp["b"])
    noise = rel_noise * b * g  # std of each interval mean [raw]
    means = np.array(sp["s"]) + b * (g * dirs @ E) + rng.normal(0, 1, dirs.shape) * noise
    data = FitData(raw=means, cov=np.zeros((len(dirs), 0)), raw_var=np.tile(noise**2, (len(dirs), 1)),
                   group=np.arange(len(dirs)), mode="means")
    # Start from a perturbed guess (within the angle box), as the ellipsoid fit would.
    start = base_parameters(np.array(sp["s"]) + 0.01 * b * g, b * 1.01, [HALF_PI] * 3)
    res = fit(data, start, model, g)  # (convergence status is tested in test_fit.py)
    cal = Calibration(params=res.params, std=res.std, gravity=g)
    a = cal.apply(means)
    np.testing.assert_allclose(np.linalg.norm(a, axis=1), g, atol=8 * rel_noise * g)
    np.testing.assert_allclose(a / np.linalg.norm(a, axis=1, keepdims=True), dirs, atol=20 * rel_noise)
