"""Generated C for the gyroscope part (issue 11): NAME_apply_gyro, NAME_apply_imu and their
batch and integer forms, compiled strictly, loaded back and compared with ``Calibration.apply_imu``.

The calibrations: the Xsens MTi recording (accelerometer and gyroscope, g-sensitivity selected by
the fit) and a synthetic signed 16-bit IMU with and without g-sensitivity. The comparison holds
each sample to the a priori bound (``affine_float_error_bound``, with the accelerometer's
``float_error_bound`` carried through D for NAME_apply_imu) plus the rounding of Python's own
double apply.

Measured (Xsens, the 51175 recorded samples and 10^5 random 16-bit vectors; also written by
studies/codegen_gyro_accuracy.py into docs/codegen_gyro.md):
  float apply_imu: max |omega - Python| 1.3e-06 rad/s, at most 0.41 of the bound per sample
  double apply_imu: max 3.6e-15 rad/s, at most 0.21 of the bound.
"""
from __future__ import annotations

import ctypes
import dataclasses
import re
import shutil
import subprocess

import casadi as ca
import numpy as np
import pytest

from conftest import real_file
from imucal.calibration.frozen import load_calibration
from imucal.calibration.frozen import Calibration
from imucal.calibration.gyro import from_arrays
from imucal.calibration.sensor import SensorCalibration
from imucal.cli.main import main
from imucal.errors import ImucalError
from imucal.export.codegen import (sensor_function, float_error_bound, generate_c,
                                   affine_float_error_bound, write_c)
from test_codegen import EMBEDDED, EXAMPLE, GCC, SANITIZE, STRICT, compile_shared, python_error_bound

pytestmark = pytest.mark.skipif(GCC is None, reason="gcc not found: cannot compile generated C")

U53 = 2.0**-53
P = ctypes.c_void_p


# --- calibrations ---------------------------------------------------------------------------
@pytest.fixture(scope="module")
def xsens(tmp_path_factory):
    """The Xsens calibration (both sensors, via its file) and the recording's raw samples."""
    from imucal.config.run import config_from_dict
    from imucal.pipeline import calibrate_imu

    acc_file = real_file("xsens-mti-imutk", "xsens_acc.mat")
    gyro_file = real_file("xsens-mti-imutk", "xsens_gyro.mat")
    run = calibrate_imu(config_from_dict({"data": {"path": str(acc_file)}, "gravity": {"value": 9.81744}}),
                        gyro_file=str(gyro_file))
    path = tmp_path_factory.mktemp("gyro_xsens") / "calibration.yaml"
    run.calibration.save(path)
    raw_a = np.loadtxt(acc_file)[:, 1:]
    raw_g = np.loadtxt(gyro_file)[:, 1:]
    return load_calibration(path), path, raw_a, raw_g


def _gyro(gsens: bool) -> SensorCalibration:
    """A +-2000 deg/s 16-bit gyro (16.4 LSB per deg/s) with bias, scale errors, misalignment."""
    rng = np.random.default_rng(11)
    mis = np.eye(3) + np.where(np.eye(3) == 1, 0.0, rng.normal(0, 0.01, (3, 3)))
    G = rng.normal(0, 2e-4, (3, 3)) if gsens else np.zeros((3, 3))
    zero = {"bias": np.zeros(3), "scale": np.zeros(3), "misalignment": np.zeros((3, 3)), "gsens": np.zeros((3, 3))}
    return from_arrays(unit="raw", bias=np.array([23.4, -57.1, 11.9]),
                           scale=16.4 * 180 / np.pi * np.array([1.01, 0.98, 1.005]), misalignment=mis,
                           gsens=G, std=zero, fit={"rms_direction_error_deg": {"before": 2.5, "after": 0.2}})


@pytest.fixture(scope="module")
def synthetic(counts_run, tmp_path_factory) -> dict[str, Calibration]:
    """The signed 16-bit accelerometer of conftest with a gyro, with and without G_s (via files)."""
    d = tmp_path_factory.mktemp("gyro_syn")
    out = {}
    for name, gs in (("gsens", True), ("plain", False)):
        p = d / f"{name}.yaml"
        dataclasses.replace(counts_run.calibration, attached=(_gyro(gs),)).save(p)
        out[name] = load_calibration(p)
    return out


# --- ctypes ---------------------------------------------------------------------------------
class GyroLib:
    def __init__(self, dll: ctypes.CDLL, prefix: str, precision: str) -> None:
        self.dll, self.prefix = dll, prefix
        self.dtype = np.float32 if precision == "float" else np.float64
        sig = {"apply_batch": [P, P, ctypes.c_size_t], "apply_gyro_batch": [P, P, P, ctypes.c_size_t],
               "apply_imu_batch": [P, P, P, P, ctypes.c_size_t], "apply_gyro": [P, P, P],
               "apply_imu": [P, P, P, P]}
        for suffix in ("i16", "u16"):
            sig[f"apply_gyro_{suffix}"] = [P, P, P]
            sig[f"apply_imu_{suffix}"] = [P, P, P, P]
        for name, args in sig.items():
            fn = getattr(dll, f"{prefix}_{name}", None)
            if fn is not None:
                fn.argtypes, fn.restype = args, None

    def fn(self, name: str):
        return getattr(self.dll, f"{self.prefix}_{name}")

    def arr(self, x) -> np.ndarray:
        return np.ascontiguousarray(np.asarray(x, dtype=self.dtype))

    def imu_batch(self, raw_a, raw_g) -> tuple[np.ndarray, np.ndarray]:
        raw_a, raw_g = self.arr(raw_a), self.arr(raw_g)
        acc, omega = np.zeros_like(raw_a), np.zeros_like(raw_g)
        self.fn("apply_imu_batch")(raw_a.ctypes.data, raw_g.ctypes.data, acc.ctypes.data, omega.ctypes.data,
                                   raw_a.shape[0])
        return acc, omega

    def gyro_batch(self, raw_g, acc) -> np.ndarray:
        raw_g = self.arr(raw_g)
        acc = None if acc is None else self.arr(acc)
        omega = np.zeros_like(raw_g)
        self.fn("apply_gyro_batch")(raw_g.ctypes.data, None if acc is None else acc.ctypes.data,
                                    omega.ctypes.data, raw_g.shape[0])
        return omega

    def apply_batch(self, raw) -> np.ndarray:
        raw = self.arr(raw)
        acc = np.zeros_like(raw)
        self.fn("apply_batch")(raw.ctypes.data, acc.ctypes.data, raw.shape[0])
        return acc


def _build(cal: Calibration, d, prefix: str, precision: str, source=None) -> GyroLib:
    write_c(cal, d, prefix=prefix, precision=precision, source=source)
    return GyroLib(compile_shared(d, prefix), prefix, precision)


@pytest.fixture(scope="module")
def xsens_libs(xsens, tmp_path_factory) -> dict[str, GyroLib]:
    cal, path, _, _ = xsens
    d = tmp_path_factory.mktemp("gyro_xsens_c")
    return {prec: _build(cal, d / prec, "xs", prec, source=path) for prec in ("float", "double")}


def _rate_map(g) -> tuple:
    """(C, c, D) with omega = C raw + c - D a: the gyroscope's map through the one accessor (affine)."""
    a = g.affine()
    return a.A, a.c, -a.B


# --- reference bounds -----------------------------------------------------------------------
def python_gyro_bound(cal: Calibration, raw_g: np.ndarray, acc: np.ndarray, acc_error: np.ndarray) -> np.ndarray:
    """Rounding of Python's double apply_imu: raw @ C.T + c (c = -C s_g rounded) - acc @ D.T,
    plus what the error of Python's own acc does through D."""
    C, _, D = _rate_map(cal.gyro)
    return (6 * U53 * (np.abs(raw_g) @ np.abs(C).T + np.abs(C) @ np.abs(cal.gyro.forward().s) + np.abs(acc) @ np.abs(D).T)
            + acc_error @ np.abs(D).T)


def imu_bound(cal: Calibration, raw_a: np.ndarray, raw_g: np.ndarray, acc_ref: np.ndarray,
              precision: str) -> np.ndarray:
    """|NAME_apply_imu's omega - Python's| <= the C's a priori bound + Python's rounding."""
    py_acc = python_error_bound(cal, raw_a)
    c_acc = float_error_bound(cal, raw_a, precision) + py_acc  # the C acc against Python's
    return (affine_float_error_bound(cal.gyro, raw_g, acc_ref, precision, input_error=c_acc)
            + python_gyro_bound(cal, raw_g, acc_ref, py_acc))


def _c_body(source: str, name: str) -> str:
    m = re.search(rf"\nvoid {name}\([^)]*\)\n\{{\n(.*?)\n\}}\n", source, re.S)
    assert m, f"{name} not found"
    return m.group(1)


# --- the kernel -----------------------------------------------------------------------------
def test_gyro_kernel_is_straight_line_without_division_or_libm(xsens, synthetic):
    cases = {"xsens": (xsens[0], (18, 18)), "gsens": (synthetic["gsens"], (18, 18)),
             "plain": (synthetic["plain"], (9, 9))}  # D = 0: 3 sub + 6 add, acc never read
    for name, (cal, (mul, add)) in cases.items():
        for prec in ("float", "double"):
            gen = generate_c(cal, prefix="k", precision=prec)
            ops = gen.apply_gyro_ops
            assert (ops.mul, ops.add, ops.div, ops.neg, ops.calls) == (mul, add, 0, 0, 0), (name, prec)
            body = _c_body(gen.source, "k_apply_gyro")
            # counted independently of the generator, in the C text
            assert len(re.findall(r"\(a\d+\*a\d+\)", body)) == mul
            assert len(re.findall(r"\(a\d+[-+]a\d+\)", body)) == add
            stripped = re.sub(r"(raw_g|acc|omega)\[\d\]", "", body)
            for banned in ("if", "for", "while", "?", "/", "sin", "cos", "sqrt", "malloc", "static", "["):
                assert banned not in stripped.replace("/* inputs first: omega may alias them */", "").replace(
                    "/* B = 0: not read */", ""), (name, banned)
            assert ("acc[" in body) == (name != "plain")
        f = sensor_function(cal.gyro)
        ids = [f.instruction_id(i) for i in range(f.n_instructions())]
        assert set(ids) <= {ca.OP_MUL, ca.OP_ADD, ca.OP_SUB, ca.OP_CONST, ca.OP_INPUT, ca.OP_OUTPUT}
        assert ids.count(ca.OP_MUL) == mul


def test_casadi_kernel_is_pythons_apply(xsens):
    """The CasADi function (before any C) evaluates Python's GyroCalibration.apply."""
    cal, _, raw_a, raw_g = xsens
    acc, omega = cal.apply_imu(raw_a[::50], raw_g[::50])
    got = np.asarray(sensor_function(cal.gyro).map(acc.shape[0])(raw_g[::50].T, acc.T)).T
    np.testing.assert_allclose(got, omega, rtol=0, atol=1e-13)


# --- compiled, compared with Python ---------------------------------------------------------
@pytest.mark.parametrize("precision", ["float", "double"])
def test_apply_imu_matches_python_within_the_a_priori_bound(xsens, xsens_libs, precision, record_property):
    cal, _, raw_a, raw_g = xsens
    lib = xsens_libs[precision]
    rng = np.random.default_rng(3)
    sets = {"recording": (raw_a, raw_g),  # integer counts: exact in float
            "random": (rng.integers(0, 65536, (100_000, 3)).astype(float),
                       rng.integers(0, 65536, (100_000, 3)).astype(float))}
    for name, (ra, rg) in sets.items():
        acc_ref, omega_ref = cal.apply_imu(ra, rg)
        acc, omega = lib.imu_batch(ra, rg)
        acc, omega = acc.astype(float), omega.astype(float)
        assert np.all(np.abs(acc - acc_ref) <= float_error_bound(cal, ra, precision) + python_error_bound(cal, ra))
        bound = imu_bound(cal, ra, rg, acc_ref, precision)
        err = np.abs(omega - omega_ref)
        assert np.all(err <= bound), (name, (err / bound).max())
        record_property(f"{name}_max_err_rad_s", float(err.max()))
        record_property(f"{name}_max_err_over_bound", float((err / bound).max()))
        # apply_imu is apply then apply_gyro on the C's own acc: the same bits
        assert np.array_equal(lib.gyro_batch(rg, lib.apply_batch(ra)), omega.astype(lib.dtype))
    # NAME_apply_gyro alone, fed Python's acc rounded to the precision
    acc_ref, omega_ref = cal.apply_imu(raw_a, raw_g)
    acc_in = acc_ref.astype(lib.dtype).astype(float)
    omega = lib.gyro_batch(raw_g, acc_in).astype(float)
    e_in = np.abs(acc_in - acc_ref) + python_error_bound(cal, raw_a)
    bound = (affine_float_error_bound(cal.gyro, raw_g, acc_ref, precision, input_error=e_in)
             + python_gyro_bound(cal, raw_g, acc_ref, python_error_bound(cal, raw_a)))
    assert np.all(np.abs(omega - omega_ref) <= bound)


def test_bound_is_not_vacuous(xsens):
    """The bound is a few float ULP of the rate, far below the calibration's own accuracy."""
    cal, _, raw_a, raw_g = xsens
    acc, omega = cal.apply_imu(raw_a, raw_g)
    b = affine_float_error_bound(cal.gyro, raw_g, acc, "float", input_error=float_error_bound(cal, raw_a))
    assert b.max() < 2e-5  # rad/s; the recording turns at up to about 5 rad/s
    rest = np.abs(omega).max(axis=1) < 0.05
    assert rest.sum() > 10_000 and b[rest].max() < 1e-6  # the rounded bias u |C| |s_g|: 4e-7 rad/s
    b_double = affine_float_error_bound(cal.gyro, raw_g, acc, "double")
    assert b_double.max() < 1e-13


@pytest.mark.parametrize("precision", ["float", "double"])
def test_integer_entry_points_are_the_float_ones(xsens, xsens_libs, synthetic, tmp_path, precision):
    """NAME_apply_gyro_u16/i16 and NAME_apply_imu_u16/i16: exactly the real-valued entry points on
    the converted counts, and within the bound of Python on the same integers."""
    cal, _, raw_a, raw_g = xsens
    cases = [("u16", ctypes.c_uint16, cal, xsens_libs[precision], raw_a[::97].astype(np.uint16),
              raw_g[::97].astype(np.uint16))]
    rng = np.random.default_rng(17)  # the signed part: full int16 range, g-sensitivity on
    syn = synthetic["gsens"]
    cases.append(("i16", ctypes.c_int16, syn, _build(syn, tmp_path, "syn", precision),
                  rng.integers(-32768, 32768, (2000, 3)).astype(np.int16),
                  rng.integers(-32768, 32768, (2000, 3)).astype(np.int16)))
    for itype, ctype, c, lib, ia, ig in cases:
        ra, rg = ia.astype(float), ig.astype(float)
        acc_f, omega_f = lib.imu_batch(ra, rg)
        acc_ref, omega_ref = c.apply_imu(ra, rg)
        imu, gyro = lib.fn(f"apply_imu_{itype}"), lib.fn(f"apply_gyro_{itype}")
        acc, omega, omega2 = (np.zeros(3, lib.dtype) for _ in range(3))
        for k in range(ia.shape[0]):
            a, g = (ctype * 3)(*map(int, ia[k])), (ctype * 3)(*map(int, ig[k]))
            imu(ctypes.addressof(a), ctypes.addressof(g), acc.ctypes.data, omega.ctypes.data)
            assert np.array_equal(acc, acc_f[k]) and np.array_equal(omega, omega_f[k]), (itype, k)
            gyro(ctypes.addressof(g), acc.ctypes.data, omega2.ctypes.data)
            assert np.array_equal(omega2, omega), (itype, k)
        assert np.all(np.abs(omega_f - omega_ref) <= imu_bound(c, ra, rg, acc_ref, precision)), itype


def test_outputs_may_alias_inputs(xsens_libs, xsens):
    cal, _, raw_a, raw_g = xsens
    lib = xsens_libs["float"]
    ra, rg = lib.arr(raw_a[1000:1050]), lib.arr(raw_g[1000:1050])
    acc_ref, omega_ref = lib.imu_batch(ra, rg)
    for k in range(ra.shape[0]):
        a, g = ra[k].copy(), rg[k].copy()  # acc written over raw_g, omega over raw_a
        lib.fn("apply_imu")(a.ctypes.data, g.ctypes.data, g.ctypes.data, a.ctypes.data)
        assert np.array_equal(g, acc_ref[k]) and np.array_equal(a, omega_ref[k])
        g = rg[k].copy()  # omega written over raw_g, in place
        lib.fn("apply_gyro")(g.ctypes.data, acc_ref[k].ctypes.data, g.ctypes.data)
        assert np.array_equal(g, omega_ref[k])


def test_without_g_sensitivity_acc_is_not_read(synthetic, tmp_path):
    cal = synthetic["plain"]
    gen = generate_c(cal, prefix="pl")
    assert "#define PL_GYRO_USES_ACC 0" in gen.header and "B = 0: pl_apply_gyro does not read acc" in gen.header
    lib = _build(cal, tmp_path, "pl", "double")
    rng = np.random.default_rng(5)
    rg = rng.integers(-32768, 32768, (5000, 3)).astype(float)
    omega = lib.gyro_batch(rg, None)  # acc may be NULL
    ref = cal.gyro.apply(rg)
    bound = affine_float_error_bound(cal.gyro, rg, np.zeros_like(rg), "double") + python_gyro_bound(
        cal, rg, np.zeros_like(rg), np.zeros_like(rg))
    assert np.all(np.abs(omega - ref) <= bound)
    assert "#define IMUCAL_GYRO_USES_ACC 1" in generate_c(synthetic["gsens"]).header


def test_calibration_without_gyro_generates_no_gyro_functions(counts_run, tmp_path):
    cal = counts_run.calibration
    assert cal.gyro is None
    gen = generate_c(cal, prefix="acc_only")
    assert gen.apply_gyro_ops is None
    assert "#define ACC_ONLY_HAS_GYRO 0" in gen.header
    for text in (gen.header, gen.source):
        assert "apply_gyro" not in text and "apply_imu" not in text and "rad/s" not in text
    lib = _build(cal, tmp_path, "acc_only", "float")
    for name in ("apply_gyro", "apply_imu", "apply_gyro_i16", "apply_imu_i16"):
        with pytest.raises(AttributeError):
            lib.fn(name)


def test_header_documents_units_frame_values_and_bound(xsens):
    cal, path, _, _ = xsens
    h = generate_c(cal, prefix="imucal", source=path).header
    flat = " ".join(h.replace("\n *", " ").split())
    assert "omega = A (raw_g - s) + B [ax, ay, az]" in flat
    assert "omega in [rad/s], in the same frame f as acc" in flat
    assert f"s [{cal.gyro.raw_unit}] = " + ", ".join(format(x, ".10g") for x in cal.gyro.forward().s) in flat
    for n, p in cal.gyro.params.items():  # every parameter with its standard error and unit
        assert f"{n} = {p.value:.10g} +/- {cal.gyro.std[n]:.2g} [{p.unit}]" in flat, n
    d = cal.gyro.fit["rms_direction_error_deg"]
    assert f"rms_direction_error_deg before {d['before']:.3g}, after {d['after']:.3g}" in flat
    assert "float arithmetic: |error| per axis <= gamma |A| |raw_g - s| + u |A| |s| + gamma' |B| |inputs|" in flat
    for sig in ("void imucal_apply_gyro(const float raw_g[3], const float acc[3], float omega[3]);",
                "void imucal_apply_imu(const float raw_a[3], const float raw_g[3], float acc[3], float omega[3]);",
                "void imucal_apply_gyro_i16(const int16_t raw_g[3], const float acc[3], float omega[3]);",
                "void imucal_apply_imu_i16(const int16_t raw_a[3], const int16_t raw_g[3], float acc[3], "
                "float omega[3]);",
                "#define IMUCAL_HAS_GYRO 1", "#define IMUCAL_GYRO_USES_ACC 1"):
        assert sig in h
    d = generate_c(cal, precision="double").header
    assert "void imucal_apply_gyro(const double raw_g[3], const double acc[3], double omega[3]);" in d
    assert "float" not in d


def test_effects_with_covariates_give_apply_imu_cov(synthetic, tmp_path):
    from imucal.model.effects import make_effect

    base = synthetic["gsens"]
    eff = make_effect("bias_temperature", (0, 1, 2))
    extra = eff.parameters(base.params)
    params = base.params.extended(extra).with_values({q.name: 2.0 * (-1) ** i for i, q in enumerate(extra)})
    cal = dataclasses.replace(base, params=params, std={n: 0.0 for n in params},
                              effects=(("bias_temperature", (0, 1, 2)),))
    p = tmp_path / "eff.yaml"
    cal.save(p)
    cal = load_calibration(p)
    gen = generate_c(cal, prefix="ec", precision="double")
    assert "void ec_apply_imu_cov(" in gen.header and "void ec_apply_imu(" not in gen.header
    write_c(cal, tmp_path, prefix="ec", precision="double")
    dll = compile_shared(tmp_path, "ec")
    fn = dll.ec_apply_imu_cov
    fn.argtypes, fn.restype = [P, P, P, P, P], None
    rng = np.random.default_rng(9)
    ra = rng.integers(-32768, 32768, (300, 3)).astype(float)
    rg = rng.integers(-32768, 32768, (300, 3)).astype(float)
    temp = rng.uniform(-10, 50, 300)
    acc_ref, omega_ref = cal.apply_imu(ra, rg, {"temp": temp})
    acc, omega = np.zeros(3), np.zeros(3)
    got = []
    for k in range(300):
        fn(ra[k].ctypes.data, rg[k].ctypes.data, temp[k:k + 1].ctypes.data, acc.ctypes.data, omega.ctypes.data)
        assert np.allclose(acc, acc_ref[k], rtol=1e-12, atol=1e-12)
        got.append(omega.copy())
    acc_err = 1e-12 * (1 + np.abs(acc_ref))  # the effect model's C against Python's (asserted above)
    bound = affine_float_error_bound(cal.gyro, rg, acc_ref, "double", input_error=acc_err) + python_gyro_bound(
        cal, rg, acc_ref, np.zeros_like(acc_ref))
    assert np.all(np.abs(np.array(got) - omega_ref) <= bound)


# --- text from the file never reaches the C as code -------------------------------------------
PWN = '2024 */ __attribute__((constructor)) static void pwn(void){system("id");} /*'


def test_gyro_text_fields_are_refused_or_sanitised(synthetic, tmp_path):
    cal = synthetic["gsens"]
    for unit in (PWN, "rad/s//x", "deg/s\n"):
        bad = dataclasses.replace(cal, attached=(dataclasses.replace(cal.gyro, raw_unit=unit),))
        with pytest.raises(ImucalError, match=r"gyroscope.units.input: .* is not a unit \(letters, digits"):
            generate_c(bad)
    fit = {"rms_direction_error_deg": {"after": PWN, "before": "1e999 */"}, "chi2": PWN}
    gen = generate_c(dataclasses.replace(cal, attached=(dataclasses.replace(cal.gyro, fit=fit),)), prefix="tx")
    for text in gen.files.values():
        for marker in ("system(", "__attribute__", "pwn", "//"):
            assert marker not in text
    assert "rms_direction_error_deg" not in gen.header and "chi2" not in gen.header  # text, not numbers: left out
    for name, text in gen.files.items():
        (tmp_path / name).write_text(text)
    compile_shared(tmp_path, "tx")


def test_gyro_unit_payload_in_file_is_refused_in_one_line(synthetic, tmp_path, capsys):
    import yaml

    src = tmp_path / "good.yaml"
    synthetic["gsens"].save(src)
    d = yaml.safe_load(src.read_text())
    d["gyroscope"]["units"]["input"] = PWN
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml.safe_dump(d))
    assert main(["codegen", str(bad), "--out", str(tmp_path / "gen")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "bad.yaml: gyroscope.units.input: " in err and "is not a unit" in err
    assert not (tmp_path / "gen").exists()
    with pytest.raises(ImucalError):
        load_calibration(bad)


# --- the example program ----------------------------------------------------------------------
@pytest.fixture(scope="module")
def example(xsens, tmp_path_factory):
    """examples/codegen/example.c against the Xsens files, under ASan and UBSan."""
    cal, path, _, _ = xsens
    d = tmp_path_factory.mktemp("gyro_example")
    write_c(cal, d, precision="float", source=path)
    exe = d / "imucal_example_asan"
    subprocess.run([GCC, *STRICT, *EMBEDDED, *SANITIZE, f"-I{d}", "-o", str(exe), str(EXAMPLE / "example.c"),
                    str(d / "imucal.c"), "-lm"], check=True, capture_output=True, text=True)
    return exe


def _csv(header: str, rows: np.ndarray) -> str:
    return header + "\n" + "\n".join(",".join(f"{x:.9g}" for x in r) for r in rows) + "\n"


def test_example_reads_gx_gy_gz_and_matches_the_library_and_python(xsens, xsens_libs, example):
    cal, _, raw_a, raw_g = xsens
    t = np.loadtxt(real_file("xsens-mti-imutk", "xsens_acc.mat"))[:, :1]
    res = subprocess.run([str(example)], input=_csv("t,ax,ay,az,gx,gy,gz", np.hstack([t, raw_a, raw_g])),
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    lines = res.stdout.splitlines()
    assert lines[0] == "t,ax,ay,az,gx,gy,gz" and len(lines) == raw_a.shape[0] + 1
    out = np.loadtxt(lines[1:], delimiter=",")
    acc, omega = xsens_libs["float"].imu_batch(raw_a, raw_g)
    assert np.array_equal(out[:, 1:4].astype(np.float32), acc)  # 9 digits: float round-trips
    assert np.array_equal(out[:, 4:].astype(np.float32), omega)
    acc_ref, omega_ref = cal.apply_imu(raw_a, raw_g)
    assert np.all(np.abs(out[:, 4:] - omega_ref) <= imu_bound(cal, raw_a, raw_g, acc_ref, "float"))
    # other names and order (imucal's loader names): gyro_z, wy ...; run-time accelerometer parameters
    rows = np.hstack([raw_g[:500, 2:3], raw_a[:500], raw_g[:500, 1:2], raw_g[:500, :1]])
    params = [repr(float(v)) for v in cal.values[:9]]
    res = subprocess.run([str(example), *params], input=_csv("gyro_z,x,y,z,wy,gx", rows), capture_output=True,
                         text=True, timeout=60)
    assert res.returncode == 0, res.stderr
    lines = res.stdout.splitlines()
    assert lines[0] == "ax,ay,az,gx,gy,gz"
    out = np.loadtxt(lines[1:], delimiter=",")
    acc_c = out[:, :3]  # from NAME_prepare + NAME_apply_coeffs (float parameters, float trig)
    ref = cal.gyro.apply(raw_g[:500], acc_c)  # the gyro on the acc the program used
    e_in = np.abs(acc_c) * 2.0**-24  # acc printed with 9 digits: within half a float ULP
    bound = (affine_float_error_bound(cal.gyro, raw_g[:500], acc_c, "float", input_error=e_in)
             + python_gyro_bound(cal, raw_g[:500], acc_c, np.zeros_like(acc_c)))
    assert np.all(np.abs(out[:, 3:] - ref) <= bound)


def test_example_gyro_columns_errors_and_notes(example, counts_run, tmp_path):
    res = subprocess.run([str(example)], input="t,ax,ay,az,gx,gy\n0,1,2,3,4,5\n", capture_output=True, text=True,
                         timeout=30)
    assert res.returncode == 1 and "line 1: header names some but not all of gx, gy, gz" in res.stderr
    # an accelerometer-only calibration: the gyro columns are ignored, with a note
    write_c(counts_run.calibration, tmp_path, precision="double")
    exe = tmp_path / "acc_only"
    subprocess.run([GCC, *STRICT, *EMBEDDED, f"-I{tmp_path}", "-o", str(exe), str(EXAMPLE / "example.c"),
                    str(tmp_path / "imucal.c"), "-lm"], check=True, capture_output=True, text=True)
    res = subprocess.run([str(exe)], input="t,ax,ay,az,gx,gy,gz\n0,100,-200,16000,1,2,3\n", capture_output=True,
                         text=True, timeout=30)
    assert res.returncode == 0
    assert "note: the calibration has no gyroscope part; gx, gy, gz ignored" in res.stderr
    lines = res.stdout.splitlines()
    assert lines[0] == "t,ax,ay,az" and len(lines[1].split(",")) == 4
    np.testing.assert_allclose([float(x) for x in lines[1].split(",")[1:]],
                               counts_run.calibration.apply(np.array([100.0, -200.0, 16000.0])), rtol=1e-13)


def test_makefile_builds_the_gyro_example(xsens, tmp_path):
    make = shutil.which("make")
    if make is None:
        pytest.skip("make not found")
    cal, _, raw_a, raw_g = xsens
    gen, out = tmp_path / "gen", tmp_path / "build"
    write_c(cal, gen, prefix="imu_b", precision="double")
    res = subprocess.run([make, "-C", str(EXAMPLE), f"GEN={gen}", f"OUT={out}", "PREFIX=imu_b"],
                         capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    res = subprocess.run([str(out / "imu_b_example")], input=_csv("ax,ay,az,gx,gy,gz", np.hstack([raw_a, raw_g])[:300]),
                         capture_output=True, text=True, timeout=30)
    assert res.returncode == 0, res.stderr
    got = np.loadtxt(res.stdout.splitlines()[1:], delimiter=",")
    acc_ref, omega_ref = cal.apply_imu(raw_a[:300], raw_g[:300])
    assert np.all(np.abs(got[:, 3:] - omega_ref) <= imu_bound(cal, raw_a[:300], raw_g[:300], acc_ref, "double"))


def test_cli_codegen_of_a_calibration_with_gyro(xsens, tmp_path, capsys):
    _, path, _, _ = xsens
    assert main(["codegen", str(path), "--out", str(tmp_path / "fw"), "--prefix", "imu", "--precision", "double"]) == 0
    assert "wrote" in capsys.readouterr().out
    h = (tmp_path / "fw" / "imu.h").read_text()
    assert "void imu_apply_imu_u16(const uint16_t raw_a[3], const uint16_t raw_g[3], double acc[3], " in h
    assert "#define IMU_HAS_GYRO 1" in h
