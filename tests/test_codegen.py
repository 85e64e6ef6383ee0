"""Generated C (imucal.export.codegen): compiled strictly, loaded back, compared with Python's apply.

Every calibration is generated in float and double, compiled once per module with
gcc -std=c99 -Wall -Wextra -Werror -pedantic (plus the warnings firmware projects enable),
loaded with ctypes and run on 10^5 raw vectors spanning the sensor's range. The example program
is built with -fsanitize=address,undefined and fed the same vectors as CSV.

Measured (seeded, so these are the numbers the assertions hold to), 2 x 10^5 vectors per calibration:
  double: max |C - Python| / |a| = 1.3e-14 (asserted: 1e-12)
  float, NAME_apply: max error 3.04 ULP of max(|a|, g) (asserted: FLOAT_ULP_BOUND = 4), and never
  above the a priori bound float_error_bound; float NAME_prepare + NAME_apply_coeffs from float
  parameters: 3.37 ULP (asserted: 4).
"""
from __future__ import annotations

import ctypes
import hashlib
import math
import re
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path

import casadi as ca
import numpy as np
import pytest
import yaml
from hypothesis import given, settings, strategies as st

from imucal.calibration.frozen import Calibration

from imucal.calibration.fileformat import OUTPUT_FRAME, validate_parameters

from imucal.calibration.frozen import load_calibration
from imucal.cli.main import main
from imucal.export.codegen import (apply_baked_function, apply_coeffs_function, c_literal, check_prefix,
                            float_error_bound, generate_c, write_c)
from imucal.errors import ImucalError
from imucal.model.sensor import Effect
from imucal.model.parameters import BASE_NAMES, Parameter, Parameters, base_parameters

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "codegen"
XSENS = ROOT / "data" / "xsens-mti-imutk" / "xsens_acc.mat"  # shipped with the repository
GCC = shutil.which("gcc")
STRICT = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic"]
#: What firmware builds commonly add; the generated code must be clean under these too.
EMBEDDED = ["-Wconversion", "-Wdouble-promotion", "-Wshadow", "-Wstrict-prototypes",
            "-Wmissing-prototypes", "-Wcast-qual", "-Wundef"]
SANITIZE = ["-fsanitize=address,undefined", "-fno-sanitize-recover=all", "-g", "-O1"]
N = 100_000
#: Max error of the float NAME_apply in ULP of max(|a|, g): measured 3.04 (Xsens, |a| = g).
FLOAT_ULP_BOUND = 4.0
#: Same for NAME_prepare + NAME_apply_coeffs from float parameters (float trig): measured 3.37.
FLOAT_PREPARE_ULP_BOUND = 4.0
DOUBLE_REL_BOUND = 1e-12

pytestmark = pytest.mark.skipif(GCC is None, reason="gcc not found: cannot compile generated C")


# --- calibrations ---------------------------------------------------------------------------
class TempBias(Effect):
    """Test-only effect: bias linear in temperature and scale linear in temperature."""

    name = "tbias_test"
    covariates = ("temp",)

    def parameters(self, base: Parameters) -> list[Parameter]:
        return [Parameter(f"tb{i+1}", 0.0, unit="raw/degC") for i in range(3)] + [
            Parameter("tk", 0.0, unit="1/degC")]

    def shift_scale(self, s, b, cov, p):
        t = cov["temp"]
        return ([s[i] + p[f"tb{i+1}"] * t for i in range(3)],
                [b[i] * (1 + p["tk"] * t) for i in range(3)])


@dataclass(frozen=True)
class EffectCalibration(Calibration):
    def effect_objects(self) -> list:
        return [TempBias()]


def _truth_calibration(sensor, gravity: float = 9.80665, unit: str = "raw") -> Calibration:
    v = sensor.values()
    params = base_parameters([v["s1"], v["s2"], v["s3"]], [v["b1"], v["b2"], v["b3"]],
                             [v["phi"], v["psi"], v["theta"]], raw_unit=unit)
    return Calibration(params=params, std={n: float("nan") for n in BASE_NAMES}, gravity=gravity,
                       raw_unit=unit, data={"file": "simulated", "sha256": "0" * 64},
                       created="2024-01-01T00:00:00+00:00")


@dataclass
class Case:
    name: str
    cal: Calibration
    path: Path
    raw: np.ndarray  #: (N, 3) raw vectors spanning the sensor's range
    raw_g: np.ndarray  #: raw vectors with |a| = g in random directions
    integer: bool  #: raw readings are integers (counts)


def _raw_at_g(cal: Calibration, rng: np.random.Generator, n: int, integer: bool) -> np.ndarray:
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    A, c = cal.linear_map()
    raw = np.linalg.solve(A, (cal.gravity * d - c).T).T
    return np.ascontiguousarray(np.round(raw) if integer else raw)


@pytest.fixture(scope="module")
def work(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("codegen")


@pytest.fixture(scope="module")
def cases(work) -> dict[str, Case]:
    from imucal.config.run import config_from_dict
    from imucal.pipeline import calibrate_accelerometer
    from imucal.analysis.simulate import PosePlan, cube_directions, mems_counts_sensor, si_sensor, simulate

    rng = np.random.default_rng(20240601)
    out: dict[str, Case] = {}
    # Real: Xsens MTi, 16-bit offset-binary counts, fitted by the pipeline.
    if XSENS.exists():
        run = calibrate_accelerometer(config_from_dict({"data": {"path": str(XSENS)}, "gravity": {"value": 9.81744}}))
        p = work / "xsens.yaml"
        run.calibration.save(p)
        cal = load_calibration(p)
        out["xsens"] = Case("xsens", cal, p, rng.integers(0, 65536, (N, 3)).astype(float),
                            _raw_at_g(cal, rng, N, True), True)
    # Synthetic, fitted by the pipeline: a factory-scaled SI sensor (m/s^2 in, +-4 g).
    sim = simulate(si_sensor(rng), PosePlan(cube_directions()), seed=3)
    csv = work / "si.csv"
    csv.write_text(sim.to_csv_text())
    run = calibrate_accelerometer(config_from_dict({"data": {"path": str(csv), "unit": "m/s^2"}}))
    p = work / "si.yaml"
    run.calibration.save(p)
    cal = load_calibration(p)
    out["si"] = Case("si", cal, p, rng.uniform(-4, 4, (N, 3)) * 9.80665, _raw_at_g(cal, rng, N, False),
                     False)
    # Synthetic truth: a signed 16-bit MEMS (16384 LSB/g) and the 6-parameter model (right angles).
    cal = _truth_calibration(mems_counts_sensor(rng))
    p = work / "counts.yaml"
    cal.save(p)
    out["counts"] = Case("counts", load_calibration(p), p,
                         rng.integers(-32768, 32768, (N, 3)).astype(float), _raw_at_g(cal, rng, N, True),
                         True)
    sensor = mems_counts_sensor(rng)
    from imucal.analysis.simulate import SensorSpec

    cal = _truth_calibration(SensorSpec(s=sensor.s, b=sensor.b, angles=(math.pi / 2,) * 3))
    p = work / "right_angles.yaml"
    cal.save(p)
    out["right_angles"] = Case("right_angles", load_calibration(p), p,
                               rng.integers(-32768, 32768, (N, 3)).astype(float),
                               _raw_at_g(cal, rng, N, True), True)
    return out


# --- building and loading -------------------------------------------------------------------
def compile_shared(src_dir: Path, prefix: str, flags=(), tag: str = "") -> ctypes.CDLL:
    lib = src_dir / f"lib{prefix}{tag}.so"
    subprocess.run([GCC, *STRICT, *EMBEDDED, "-O2", "-fPIC", "-shared", *flags, "-o", str(lib),
                    str(src_dir / f"{prefix}.c"), "-lm"], check=True, capture_output=True, text=True)
    return ctypes.CDLL(str(lib))


class Lib:
    """ctypes view of one generated library."""

    def __init__(self, cdll: ctypes.CDLL, prefix: str, precision: str, effects: bool) -> None:
        self.dll, self.prefix = cdll, prefix
        self.dtype = np.float32 if precision == "float" else np.float64
        self.effects = effects
        P = ctypes.c_void_p
        for name, args in [("apply_batch", [P, P, ctypes.c_size_t]), ("apply", [P, P]),
                           ("prepare", [P, P]), ("apply_coeffs", [P, P, P]),
                           ("apply_coeffs_batch", [P, P, P, ctypes.c_size_t]),
                           ("apply_cov_batch", [P, P, P, ctypes.c_size_t])]:
            fn = getattr(cdll, f"{prefix}_{name}", None)
            if fn is not None:
                fn.argtypes = args
                fn.restype = ctypes.c_int if name == "prepare" else None

    def fn(self, name: str):
        return getattr(self.dll, f"{self.prefix}_{name}")

    def arr(self, x) -> np.ndarray:
        return np.ascontiguousarray(np.asarray(x, dtype=self.dtype))

    def apply_batch(self, raw: np.ndarray) -> np.ndarray:
        raw = self.arr(raw)
        acc = np.zeros_like(raw)
        self.fn("apply_batch")(raw.ctypes.data, acc.ctypes.data, raw.shape[0])
        return acc

    def apply_cov_batch(self, raw: np.ndarray, cov: np.ndarray) -> np.ndarray:
        raw, cov = self.arr(raw), self.arr(cov)
        acc = np.zeros_like(raw)
        self.fn("apply_cov_batch")(raw.ctypes.data, cov.ctypes.data, acc.ctypes.data, raw.shape[0])
        return acc

    def prepare(self, params) -> tuple[int, np.ndarray]:
        params = self.arr(params)
        coeffs = np.full(9, 12345.0, self.dtype)  # sentinel: must stay on failure
        rc = self.fn("prepare")(params.ctypes.data, coeffs.ctypes.data)
        return rc, coeffs

    def apply_coeffs_batch(self, coeffs: np.ndarray, raw: np.ndarray) -> np.ndarray:
        raw = self.arr(raw)
        acc = np.zeros_like(raw)
        self.fn("apply_coeffs_batch")(coeffs.ctypes.data, raw.ctypes.data, acc.ctypes.data, raw.shape[0])
        return acc


@pytest.fixture(scope="module")
def libs(cases, work) -> dict[tuple[str, str], Lib]:
    out = {}
    for name, case in cases.items():
        for prec in ("float", "double"):
            d = work / f"gen_{name}_{prec}"
            prefix = f"cal_{name}"
            write_c(case.cal, d, prefix=prefix, precision=prec, source=case.path)
            out[(name, prec)] = Lib(compile_shared(d, prefix), prefix, prec, False)
    return out


def ulps(err: np.ndarray, ref: np.ndarray, floor: float) -> np.ndarray:
    """Max error per sample in ULP (float32) of the output's magnitude max(|a|, floor).

    The floor is g: below 1 g the error does not shrink with |a|, because the shift rounded to
    float (0.5 ULP of s, e.g. 0.002 counts at s = 33000) is an absolute error.
    """
    mag = np.maximum(np.linalg.norm(ref, axis=1), floor)
    return np.max(np.abs(err), axis=1) / 2.0 ** (np.floor(np.log2(mag)) - 23)


def rel(err: np.ndarray, ref: np.ndarray) -> np.ndarray:
    return np.max(np.abs(err), axis=1) / np.linalg.norm(ref, axis=1)


def python_error_bound(cal: Calibration, raw: np.ndarray) -> np.ndarray:
    """Rounding of Python's own double apply, raw @ A.T + c (reference side of the comparison)."""
    A, c = cal.linear_map()
    return 4 * 2.0**-53 * (np.abs(raw) @ np.abs(A).T + np.abs(c))


# --- the kernel is what the issue asks -----------------------------------------------------------
def _c_function(source: str, name: str) -> str:
    m = re.search(rf"\nvoid {name}\([^)]*\)\n\{{\n(.*?)\n\}}\n", source, re.S)
    assert m, f"{name} not found in the generated source"
    return m.group(1)


def test_apply_is_six_multiplies_six_adds_straight_line(cases):
    for case in cases.values():
        gen = generate_c(case.cal, prefix="k")
        for fname, ops in (("k_apply", gen.apply_ops), ("k_apply_coeffs", gen.apply_coeffs_ops)):
            assert (ops.mul, ops.add, ops.div, ops.neg, ops.calls) == (6, 6, 0, 0, 0), (case.name, fname)
            body = _c_function(gen.source, fname)
            # counted independently of the generator: binary operators in the C text
            assert len(re.findall(r"\(a\d+\*a\d+\)", body)) == 6
            assert len(re.findall(r"\(a\d+[-+]a\d+\)", body)) == 6
            for banned in ("if", "for", "while", "?", "/", "sin", "cos", "sqrt", "malloc", "static", "["):
                assert banned not in re.sub(r"(raw|acc|c->[ls])\[\d\]", "", body), (case.name, banned)
    # and in CasADi's own instruction list of the kernels
    for f in (apply_coeffs_function(), apply_baked_function(cases["counts"].cal)):
        ids = [f.instruction_id(i) for i in range(f.n_instructions())]
        assert ids.count(ca.OP_MUL) == 6
        assert ids.count(ca.OP_ADD) + ids.count(ca.OP_SUB) == 6
        assert set(ids) <= {ca.OP_MUL, ca.OP_ADD, ca.OP_SUB, ca.OP_CONST, ca.OP_INPUT, ca.OP_OUTPUT}


def test_generation_is_deterministic_and_prefixed(cases):
    case = cases["counts"]
    a = generate_c(case.cal, prefix="imu_left", source=case.path)
    b = generate_c(case.cal, prefix="imu_left", source=case.path)
    assert a.files == b.files
    assert set(a.files) == {"imu_left.h", "imu_left.c"}
    # every external symbol the source defines carries the prefix
    defined = re.findall(r"^(?:void|int) (\w+)\(", a.source, re.M)
    assert defined and all(n.startswith("imu_left_") for n in defined)
    assert "#ifndef IMU_LEFT_H" in a.header and 'extern "C"' in a.header


def test_header_documents_units_frame_provenance_and_error(cases):
    case = cases["xsens"] if "xsens" in cases else cases["si"]
    gen = generate_c(case.cal, prefix="imucal", source=case.path)
    h = gen.header
    assert hashlib.sha256(case.path.read_bytes()).hexdigest() in h
    assert case.cal.data["sha256"] in h and case.cal.created in h
    assert f"imucal {case.cal.software_version}" in h
    assert "m/s^2" in h and f"[{case.cal.raw_unit}]" in h
    flat = " ".join(h.replace("\n *", " ").split())
    assert f"Frame of acc: the {OUTPUT_FRAME} (right-handed)" in flat
    assert f"{case.cal.fit['rms_residual']:.3g}" in h
    assert "float arithmetic: |error| per axis" in h
    for sig in ("void imucal_apply(const float raw[3], float acc[3]);",
                "int imucal_prepare(const float params[9], imucal_coeffs *c);",
                "void imucal_apply_coeffs(const imucal_coeffs *c, const float raw[3], float acc[3]);",
                "void imucal_apply_batch(const float *raw, float *acc, size_t n);"):
        assert sig in h
    d = generate_c(case.cal, precision="double").header
    assert "void imucal_apply(const double raw[3], double acc[3]);" in d and "float" not in d


@settings(max_examples=300, deadline=None)
@given(st.floats(allow_nan=False, allow_infinity=False, width=32))
def test_float_literals_round_trip(x):
    text = c_literal(x, "float")
    assert text.endswith("f") and re.fullmatch(r"-?\d+(\.\d*)?(e[-+]\d+)?f", text)
    assert np.float32(float(text[:-1])) == np.float32(x)


@settings(max_examples=300, deadline=None)
@given(st.floats(allow_nan=False, allow_infinity=False))
def test_double_literals_round_trip(x):
    assert float(c_literal(x, "double")) == x


# --- compiled, compared with Python ------------------------------------------------------------
@pytest.mark.parametrize("name", ["xsens", "si", "counts", "right_angles"])
def test_double_matches_python(cases, libs, name):
    if name not in cases:
        pytest.skip(f"real recording {XSENS} not present")
    case, lib = cases[name], libs[(name, "double")]
    raw = np.vstack([case.raw, case.raw_g])
    ref = case.cal.apply(raw)
    acc = lib.apply_batch(raw)
    assert rel(acc - ref, ref).max() < DOUBLE_REL_BOUND
    rc, k = lib.prepare(case.cal.values[:9])
    assert rc == 0
    acc2 = lib.apply_coeffs_batch(k, raw)
    assert rel(acc2 - ref, ref).max() < DOUBLE_REL_BOUND
    # single-sample form, on a subset, equals the batch
    one = np.zeros(3)
    for i in range(0, N, N // 200):
        lib.fn("apply")(np.ascontiguousarray(raw[i]).ctypes.data, one.ctypes.data)
        assert np.array_equal(one, acc[i])


@pytest.mark.parametrize("name", ["xsens", "si", "counts", "right_angles"])
def test_float_within_ulp_bound_and_a_priori_bound(cases, libs, name):
    if name not in cases:
        pytest.skip(f"real recording {XSENS} not present")
    case, lib = cases[name], libs[(name, "float")]
    for raw in (case.raw, case.raw_g):
        raw = raw.astype(np.float32).astype(float)  # the C API takes float raw
        ref = case.cal.apply(raw)
        acc = lib.apply_batch(raw).astype(float)
        err = acc - ref
        assert ulps(err, ref, case.cal.gravity).max() <= FLOAT_ULP_BOUND
        bound = float_error_bound(case.cal, raw) + python_error_bound(case.cal, raw)
        assert np.all(np.abs(err) <= bound)
    # run-time parameters, stored as float (as read from flash): reference uses the same floats
    p32 = case.cal.values[:9].astype(np.float32)
    rc, k = lib.prepare(p32)
    assert rc == 0
    cal32 = Calibration(params=case.cal.params.with_values(dict(zip(BASE_NAMES, p32.astype(float)))),
                        std={}, gravity=case.cal.gravity)
    raw = case.raw.astype(np.float32).astype(float)
    ref = cal32.apply(raw)
    assert ulps(lib.apply_coeffs_batch(k, raw) - ref, ref, case.cal.gravity).max() <= FLOAT_PREPARE_ULP_BOUND


def _has_fma() -> bool:
    try:
        return " fma " in Path("/proc/cpuinfo").read_text().replace("\n", " ")
    except OSError:
        return False


@pytest.mark.skipif(not _has_fma(), reason="this CPU has no FMA instructions")
def test_float_with_fused_multiply_add_stays_within_bound(cases, libs, work):
    # GNU C modes (-std=gnu99, the default of most firmware builds) contract a*b + c into one
    # fused operation (VFMA on a Cortex-M4F): fewer roundings, the same bounds must hold.
    for name in ("xsens", "counts"):
        if name not in cases:
            continue
        case = cases[name]
        d = work / f"gen_{name}_float"
        lib = Lib(compile_shared(d, f"cal_{name}", ["-std=gnu99", "-mfma", "-ffp-contract=fast"], "_fma"),
                  f"cal_{name}", "float", False)
        raw = np.vstack([case.raw, case.raw_g]).astype(np.float32).astype(float)
        ref = case.cal.apply(raw)
        acc = lib.apply_batch(raw).astype(float)
        assert not np.array_equal(acc, libs[(name, "float")].apply_batch(raw)), "no FMA was used"
        assert ulps(acc - ref, ref, case.cal.gravity).max() <= FLOAT_ULP_BOUND
        bound = float_error_bound(case.cal, raw) + python_error_bound(case.cal, raw)
        assert np.all(np.abs(acc - ref) <= bound)


def test_prepare_rejects_invalid_parameters_and_leaves_coeffs(cases, libs):
    lib = libs[("counts", "float")]
    good = cases["counts"].cal.values[:9]
    codes = {"OK": 0, "SCALE": 1, "ANGLE": 2, "FRAME": 3, "SHIFT": 4}
    bad = [("SCALE", 3, 0.0), ("SCALE", 4, -2.0), ("SCALE", 5, math.nan), ("SCALE", 3, math.inf),
           ("ANGLE", 6, 0.0), ("ANGLE", 7, math.pi + 0.01), ("ANGLE", 8, -1.0), ("ANGLE", 6, math.nan),
           ("SHIFT", 0, math.nan), ("SHIFT", 2, -math.inf)]
    for code, i, v in bad:
        p = good.copy()
        p[i] = v
        rc, k = lib.prepare(p)
        assert rc == codes[code], (code, i, v)
        assert np.all(k == 12345.0), "coefficients must stay untouched on failure"
    # angles each in (0, pi) but no frame: psi > phi + theta breaks the triangle inequality
    p = good.copy()
    p[6:9] = [0.5, 2.0, 0.5]
    rc, k = lib.prepare(p)
    assert rc == codes["FRAME"] and np.all(k == 12345.0)
    rc, _ = lib.prepare(good)
    assert rc == codes["OK"]
    h = generate_c(cases["counts"].cal).header
    for code, value in codes.items():
        assert f"#define IMUCAL_{'OK' if code == 'OK' else 'E_' + code} {value}" in h


_param = st.tuples(*[st.floats(-5e4, 5e4)] * 3, *[st.floats(-5.0, 1e3)] * 3,
                   *[st.floats(-0.5, 3.7)] * 3)


@settings(max_examples=400, deadline=None)
@given(_param)
def test_prepare_accepts_exactly_what_the_loader_accepts(libs, vals):
    lib = libs[("counts", "double")]
    c = [math.cos(v) for v in vals[6:9]]
    det = 1 - c[0]**2 - c[1]**2 - c[2]**2 + 2 * c[0] * c[1] * c[2]
    if 1e-13 < det < 1e-11:  # too close to the threshold for two orders of evaluation to agree
        return
    params = Parameters(Parameter(n, float(v)) for n, v in zip(BASE_NAMES, vals))
    try:
        validate_parameters(params)
        valid = True
    except ImucalError:
        valid = False
    rc, _ = lib.prepare(np.array(vals))
    assert (rc == 0) == valid


# --- effects: NAME_apply_cov from the same CasADi graph -----------------------------------------
@pytest.fixture(scope="module")
def effect_case(work, cases):
    base = cases["counts"].cal
    params = base.params.extended(TempBias().parameters(base.params)).with_values(
        {"tb1": 3.5, "tb2": -2.0, "tb3": 0.7, "tk": 1.5e-4})
    cal = EffectCalibration(params=params, std={n: 0.0 for n in params}, gravity=base.gravity,
                            effects=(("tbias_test", (0, 1, 2)),), fit={"rms_residual": 0.01},
                            data=base.data, created=base.created)
    return cal


def _apply_in_chunks(cal: Calibration, raw: np.ndarray, temp: np.ndarray) -> np.ndarray:
    # Calibration.apply switches to CasADi's "thread" map above 20000 samples, which starts one
    # thread per sample and aborts the process at 10^5 (reported); 20000 at a time is serial.
    return np.vstack([cal.apply(raw[i:i + 20000], {"temp": temp[i:i + 20000]})
                      for i in range(0, raw.shape[0], 20000)])


def test_effects_generate_apply_cov(effect_case, work):
    cal = effect_case
    rng = np.random.default_rng(7)
    raw = rng.integers(-32768, 32768, (N, 3)).astype(float)
    temp = rng.uniform(-20, 60, N)
    ref = _apply_in_chunks(cal, raw, temp)
    for prec in ("double", "float"):
        d = work / f"gen_effect_{prec}"
        gen = generate_c(cal, prefix="eff", precision=prec)
        assert gen.apply_ops is None and gen.apply_cov_ops.calls == 0
        assert "there is no eff_apply" in gen.header and "cov[0] = temp [degC]" in gen.header
        assert "#define EFF_N_COV 1" in gen.header
        assert "void eff_apply(" not in gen.source
        write_c(cal, d, prefix="eff", precision=prec)
        lib = Lib(compile_shared(d, "eff"), "eff", prec, True)
        with pytest.raises(AttributeError):
            lib.fn("apply")
        if prec == "double":
            acc = lib.apply_cov_batch(raw, temp[:, None])
            assert rel(acc - ref, ref).max() < DOUBLE_REL_BOUND
        else:
            r32, t32 = raw.astype(np.float32), temp.astype(np.float32)
            ref32 = _apply_in_chunks(cal, r32.astype(float), t32.astype(float))
            acc = lib.apply_cov_batch(r32, t32[:, None]).astype(float)
            assert rel(acc - ref32, ref32).max() < 2e-6  # measured 4e-7: float, with divisions


def _library_effects() -> list:
    try:
        from imucal.model.effects import EFFECTS
    except ModuleNotFoundError:
        return [pytest.param(None, marks=pytest.mark.skip(reason="imucal.model.effects not in this build"))]
    return list(EFFECTS)


@pytest.mark.parametrize("effect", _library_effects())
def test_each_library_effect_through_the_cli(cases, work, effect, capsys):
    from imucal.model.effects import make_effect

    base = cases["counts"].cal
    eff = make_effect(effect, (0, 1, 2))
    extra = eff.parameters(base.params)
    values = {q.name: (float(np.clip(3 * q.scale * (-1) ** i, q.lower, q.upper)) if not q.fixed else q.value)
              for i, q in enumerate(extra)}
    values.update({n: 40.0 for n in eff.shape_names})  # the warm-up's tau [s]
    values.update({n: 1800.0 for n in eff.given_names})  # a bias step's time [s]
    cov_values = {"temp": np.random.default_rng(12).uniform(-10, 60, 20_000),
                  "time": np.random.default_rng(13).uniform(0, 3600, 20_000),
                  "temp_rate": np.random.default_rng(14).uniform(-0.05, 0.05, 20_000)}
    if getattr(eff, "target", None) == "scale":  # b_i (1 + c f) stays a correction (|c f| <= 0.2), not a sign flip
        f = np.abs(eff.basis.value(cov_values[eff.basis.covariate], values, effect)).max()
        values.update({n: float(np.clip(values[n], -0.2 / f, 0.2 / f)) for n in eff.coefficient_names})
    params = base.params.extended(extra).with_values(values)
    cal = Calibration(params=params, std={n: 0.0 for n in params}, gravity=base.gravity,
                      effects=((effect, (0, 1, 2)),), data=base.data, created=base.created)
    path = work / f"effect_{effect}.yaml"
    cal.save(path)
    cal = load_calibration(path)
    rng = np.random.default_rng(11)
    n = 20_000
    raw = rng.integers(-32768, 32768, (n, 3)).astype(float)
    covs = {c: cov_values[c] for c in cal.covariates}
    ref = cal.apply(raw, covs)
    for prec in ("double", "float"):
        d = work / f"gen_effect_{effect}_{prec}"
        assert main(["codegen", str(path), "--out", str(d), "--precision", prec, "--prefix", "e"]) == 0
        header = (d / "e.h").read_text()
        assert effect in header and "effects are not included" in header
        lib = Lib(compile_shared(d, "e"), "e", prec, True)
        r = raw.astype(lib.dtype)
        if covs:
            C = np.column_stack([covs[c] for c in cal.covariates]).astype(lib.dtype)
            acc = lib.apply_cov_batch(r, C)
            assert "there is no e_apply" in header
        else:
            acc = lib.apply_batch(r)
            assert "void e_apply(const" in header
        if prec == "double":
            assert rel(acc - ref, ref).max() < DOUBLE_REL_BOUND
        else:
            ref32 = cal.apply(r.astype(float), {c: v.astype(np.float32).astype(float) for c, v in covs.items()})
            assert rel(acc - ref32, ref32).max() < 2e-6
    capsys.readouterr()


# --- the example program, with sanitizers ------------------------------------------------------
@pytest.fixture(scope="module")
def example_asan(cases, work):
    case = cases["xsens"] if "xsens" in cases else cases["counts"]
    d = work / "example"
    write_c(case.cal, d, precision="float", source=case.path)  # default NAME imucal
    exe = d / "imucal_example_asan"
    subprocess.run([GCC, *STRICT, *EMBEDDED, *SANITIZE, f"-I{d}", "-o", str(exe),
                    str(EXAMPLE / "example.c"), str(d / "imucal.c"), "-lm"], check=True,
                   capture_output=True, text=True)
    return case, exe


def _run_example(exe: Path, raw: np.ndarray, args=(), header: str = "x,y,z\n"):
    text = header + "\n".join(f"{x:.9g},{y:.9g},{z:.9g}" for x, y, z in raw) + "\n"
    return subprocess.run([str(exe), *args], input=text, capture_output=True, text=True, timeout=60)


def test_example_under_sanitizers_matches_python(example_asan, libs):
    case, exe = example_asan
    raw = case.raw.astype(np.float32)
    res = _run_example(exe, raw)
    assert res.returncode == 0, res.stderr
    lines = res.stdout.splitlines()
    assert lines[0] == "ax,ay,az" and len(lines) == N + 1
    acc = np.loadtxt(lines[1:], delimiter=",", dtype=np.float32)
    # the same numbers as the -O2 library (printed with 9 digits: float round-trips) ...
    assert np.array_equal(acc, libs[(case.name, "float")].apply_batch(raw))
    ref = case.cal.apply(raw.astype(float))
    assert ulps(acc.astype(float) - ref, ref, case.cal.gravity).max() <= FLOAT_ULP_BOUND  # ... and Python
    # run-time parameters on the command line: imucal_prepare + imucal_apply_coeffs
    res = _run_example(exe, raw[:2000], [repr(float(v)) for v in case.cal.values[:9]])
    assert res.returncode == 0, res.stderr
    acc = np.loadtxt(res.stdout.splitlines()[1:], delimiter=",")
    ref = case.cal.apply(raw[:2000].astype(float))
    assert ulps(acc - ref, ref, case.cal.gravity).max() <= FLOAT_ULP_BOUND


def test_example_refuses_bad_lines_and_bad_parameters(example_asan):
    case, exe = example_asan
    res = subprocess.run([str(exe)], input="1,2\n", capture_output=True, text=True, timeout=30)
    assert res.returncode == 1 and "line 1: expected 3 numbers, got 2" in res.stderr
    bad = [str(v) for v in case.cal.values[:9]]
    bad[3] = "-1"
    res = subprocess.run([str(exe), *bad], input="1,2,3\n", capture_output=True, text=True, timeout=30)
    assert res.returncode == 2 and "imucal_prepare returned 1" in res.stderr


@pytest.mark.parametrize("prefix", ["imucal", "acc_board7"])
def test_example_builds_with_its_makefile(cases, work, prefix):
    """Any --prefix (PREFIX=), an output folder that does not exist yet (OUT=, created), and
    imucal's own CSV layout: header t,ax,ay,az with t first; t is passed through as it was."""
    make = shutil.which("make")
    if make is None:
        pytest.skip("make not found")
    gen = work / f"make_{prefix}" / "gen"
    out = work / f"make_{prefix}" / "build" / "deeper"
    write_c(cases["counts"].cal, gen, prefix=prefix, precision="double")
    assert not out.exists()
    res = subprocess.run([make, "-C", str(EXAMPLE), f"GEN={gen}", f"OUT={out}", f"PREFIX={prefix}"],
                         capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    exe = out / f"{prefix}_example"
    raw = np.array([[100.0, -200.0, 16000.0], [-15000.0, 300.0, 20.0]])
    ref = cases["counts"].cal.apply(raw)
    t = ["1700000000.123", "1700000000.133"]
    layouts = {  # imucal's CSV (as apply and simulate write it), other orders, no header
        "t,ax,ay,az\n": [f"{t[i]},{x:g},{y:g},{z:g}" for i, (x, y, z) in enumerate(raw)],
        "az;temp;ay;t;ax\n": [f"{z:g};25;{y:g};{t[i]};{x:g}" for i, (x, y, z) in enumerate(raw)],
        "": [f"{t[i]} {x:g} {y:g} {z:g}" for i, (x, y, z) in enumerate(raw)],
    }
    for header, rows in layouts.items():
        res = subprocess.run([str(exe)], input=header + "\n".join(rows) + "\n", capture_output=True,
                             text=True, timeout=30)
        assert res.returncode == 0, res.stderr
        lines = res.stdout.splitlines()
        assert lines[0] == "t,ax,ay,az"
        assert [ln.split(",")[0] for ln in lines[1:]] == t  # time kept as it was
        got = np.array([[float(x) for x in ln.split(",")[1:]] for ln in lines[1:]])
        assert rel(got - ref, ref).max() < DOUBLE_REL_BOUND
    # the first three columns would be t, ax, ay: a different answer, which the example must not give
    assert not np.allclose(cases["counts"].cal.apply(np.array([[1.7e9, 100.0, -200.0]]))[0], ref[0])


def test_example_feeds_temp_column_to_a_temperature_calibration(effect_case, work):
    """With a temperature effect the example reads temp by name from imucal's layout."""
    if shutil.which("make") is None:
        pytest.skip("make not found")
    gen, out = work / "make_eff" / "gen", work / "make_eff" / "build"
    write_c(effect_case, gen, prefix="eff_t", precision="double")
    res = subprocess.run(["make", "-C", str(EXAMPLE), f"GEN={gen}", f"OUT={out}", "PREFIX=eff_t"],
                         capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    raw = np.array([[100.0, -200.0, 16000.0], [-15000.0, 300.0, 20.0]])
    temp = np.array([-10.0, 45.0])
    ref = effect_case.apply(raw, {"temp": temp})
    text = "t,ax,ay,az,temp\n" + "".join(f"{i},{x:g},{y:g},{z:g},{tc:g}\n"
                                          for i, ((x, y, z), tc) in enumerate(zip(raw, temp)))
    res = subprocess.run([str(out / "eff_t_example")], input=text, capture_output=True, text=True, timeout=30)
    assert res.returncode == 0, res.stderr
    got = np.array([[float(x) for x in ln.split(",")[1:]] for ln in res.stdout.splitlines()[1:]])
    assert rel(got - ref, ref).max() < DOUBLE_REL_BOUND
    res = subprocess.run([str(out / "eff_t_example")], input="t,ax,ay,az\n0,1,2,3\n", capture_output=True,
                         text=True, timeout=30)
    assert res.returncode == 1 and "the calibration needs a temp column [degC]" in res.stderr


def test_example_refuses_a_header_without_axes(example_asan):
    _, exe = example_asan
    res = subprocess.run([str(exe)], input="t,gx,gy,gz\n1,2,3,4\n", capture_output=True, text=True, timeout=30)
    assert res.returncode == 1 and "line 1: header names no ax, ay, az columns" in res.stderr
    res = subprocess.run([str(exe)], input="t,ax,ay,az\n1,2,x,4\n", capture_output=True, text=True, timeout=30)
    assert res.returncode == 1 and "line 2: expected a number in column 3" in res.stderr


def test_header_compiles_as_cpp(cases, work):
    gxx = shutil.which("g++")
    if gxx is None:
        pytest.skip("g++ not found")
    d = work / "cpp"
    write_c(cases["counts"].cal, d)
    (d / "use.cpp").write_text('#include "imucal.h"\nint main() { float r[3] = {1, 2, 3}, a[3];\n'
                               "  imucal_apply(r, a); return a[0] == a[0] ? 0 : 1; }\n")
    # compile the C file as C and the C++ file as C++, then link (Arduino builds it this way)
    subprocess.run([GCC, *STRICT, "-c", "-o", str(d / "imucal.o"), str(d / "imucal.c")], check=True)
    res = subprocess.run([gxx, "-std=c++11", "-Wall", "-Wextra", "-Werror", "-pedantic", f"-I{d}", "-o",
                          str(d / "use"), str(d / "use.cpp"), str(d / "imucal.o"), "-lm"],
                         capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert subprocess.run([str(d / "use")]).returncode == 0


# --- the command line, and bad input -------------------------------------------------------------
def test_cli_writes_both_files(cases, tmp_path, capsys):
    case = cases["counts"]
    out = tmp_path / "fw"
    assert main(["codegen", str(case.path), "--out", str(out), "--precision", "double",
                 "--prefix", "imu_a"]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["imu_a.c", "imu_a.h"]
    assert "wrote" in capsys.readouterr().out
    assert "double imu_a_real" in (out / "imu_a.h").read_text().replace("typedef ", "")


def _bad_file(tmp_path: Path, case: Case, edit) -> Path:
    d = yaml.safe_load(case.path.read_text())
    edit(d)
    p = tmp_path / "bad.yaml"
    p.write_text(yaml.safe_dump(d))
    return p


def _set(path: list, value):
    def edit(d):
        for k in path[:-1]:
            d = d[k]
        d[path[-1]] = value
    return edit


def _delete(path: list):
    def edit(d):
        for k in path[:-1]:
            d = d[k]
        del d[path[-1]]
    return edit


@pytest.mark.parametrize("edit, message", [
    (_set(["format_version"], 99), "format_version: unknown format version 99 (this imucal reads versions 1, 2, 3)"),
    (_delete(["parameters", "theta"]), "parameters.theta: missing key 'theta'"),
    (_delete(["gravity"]), "gravity: missing key 'gravity'"),
    (_set(["parameters", "b2", "value"], -400.0), "parameters.b2.value: scale b2 = -400.0 must be positive"),
    (_set(["parameters", "psi", "value"], 3.5), "parameters.psi.value: angle psi = 3.5 rad is outside (0, pi)"),
    (_set(["format"], "something-else"), "format: format 'something-else' is not 'imucal-calibration'"),
])
def test_cli_refuses_bad_calibration_files(cases, tmp_path, capsys, edit, message):
    bad = _bad_file(tmp_path, cases["counts"], edit)
    out = tmp_path / "fw"
    assert main(["codegen", str(bad), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"imucal: error: {bad}: ") and message in err
    assert not out.exists() or not any(out.iterdir())


@pytest.mark.parametrize("prefix", ["1imu", "imu-left", "imu left", "static", "", "_imu", "imü"])
def test_cli_refuses_prefix_that_is_not_a_c_identifier(cases, tmp_path, capsys, prefix):
    out = tmp_path / "fw"
    assert main(["codegen", str(cases["counts"].path), "--out", str(out), "--prefix", prefix]) == 2
    err = capsys.readouterr().err
    assert err == (f"imucal: error: --prefix: {prefix!r} is not a C identifier (fix: use letters, digits "
                   "and _, starting with a letter, e.g. imucal_xsens)\n")
    assert not out.exists()


def test_cli_refuses_output_that_is_a_file(cases, tmp_path, capsys):
    out = tmp_path / "fw"
    out.write_text("not a directory")
    assert main(["codegen", str(cases["counts"].path), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err == f"imucal: error: {out}: --out: is not a directory (fix: give a directory for the .h and .c files)\n"
    assert out.read_text() == "not a directory"


def test_cli_refuses_missing_file_and_bad_precision(tmp_path, capsys):
    out = tmp_path / "fw"
    assert main(["codegen", str(tmp_path / "none.yaml"), "--out", str(out)]) == 2
    assert "none.yaml: calibration: file not found" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        main(["codegen", str(tmp_path / "none.yaml"), "--out", str(out), "--precision", "half"])
    assert exc.value.code == 2
    assert "invalid choice: 'half'" in capsys.readouterr().err
    assert not out.exists()


def test_library_refuses_bad_precision_and_prefix(cases):
    with pytest.raises(ImucalError, match=r"^precision: 'half' is not a precision \(fix: use one of float, double\)$"):
        generate_c(cases["counts"].cal, precision="half")
    with pytest.raises(ImucalError, match="is not a C identifier"):
        check_prefix("int")
    assert check_prefix("imucal_xsens2") == "imucal_xsens2"
