"""`imucal codegen --layout arduino` (imucal.export.arduino): the library folder's manifests parse,
its example sketch builds with the host g++ against a minimal Arduino shim written here and
prints what Python's apply computes, and text from the calibration file cannot break any file.
"""
from __future__ import annotations

import dataclasses
import json
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
import yaml

from imucal.analysis.simulate import mems_counts_sensor
from imucal.calibration.frozen import load_calibration
from imucal.export.arduino import arduino_files, sketch
from imucal.export.codegen import float_error_bound, generate_c, affine_float_error_bound
from test_codegen import STRICT, EffectCalibration, TempBias, _truth_calibration
from test_codegen_gyro import _gyro

GXX = shutil.which("g++")
GCC = shutil.which("gcc")
pytestmark = pytest.mark.skipif(GXX is None or GCC is None, reason="gcc/g++ not found: cannot build the sketch")

FILES = ["README.md", "examples/apply/apply.ino", "library.json", "library.properties", "src/{p}.c", "src/{p}.h"]
#: Arduino library specification 1.5: required fields of library.properties.
REQUIRED = {"name", "version", "author", "maintainer", "sentence", "paragraph", "category", "url", "architectures"}
SEMVER = re.compile(r"(0|[1-9]\d*)\.(0|[1-9]\d*)\.(0|[1-9]\d*)\Z")
#: Serial.print(x, 6) rounds to 6 decimals.
PRINT_ROUNDING = 0.5e-6

#: The smallest Arduino core this test needs: Serial's print/println, delay.
SHIM = """\
#include <stdint.h>
#include <stdio.h>
struct SerialShim {
  void begin(unsigned long) {}
  void print(const char *s) { fputs(s, stdout); }
  void print(char c) { putchar(c); }
  void print(double x, int digits = 2) { printf("%.*f", digits, x); }
  void println() { putchar('\\n'); }
};
static SerialShim Serial;
static void delay(unsigned long) {}
"""
MAIN = '#include "arduino_shim.h"\n#include "apply.ino"\nint main() { setup(); loop(); return 0; }\n'


@pytest.fixture(scope="module")
def accel_cal(tmp_path_factory):
    """A 16-bit counts accelerometer (the simulator's MEMS sensor, its true values), via its file."""
    cal = _truth_calibration(mems_counts_sensor(np.random.default_rng(2024)))
    path = tmp_path_factory.mktemp("ard") / "accel.yaml"
    cal.save(path)
    return load_calibration(path), path


@pytest.fixture(scope="module")
def imu_cal(accel_cal, tmp_path_factory):
    """The same accelerometer with a gyroscope part (bias, scales, misalignment, g-sensitivity)."""
    path = tmp_path_factory.mktemp("ard") / "imu.yaml"
    dataclasses.replace(accel_cal[0], attached=(_gyro(True),)).save(path)
    return load_calibration(path), path


def _properties(text: str) -> dict[str, str]:
    lines = text.splitlines()
    assert all(re.fullmatch(r"[a-z_]+=[^\n\r]*", line) for line in lines), lines
    props = dict(line.split("=", 1) for line in lines)
    assert len(props) == len(lines)  # no key twice
    return props


def _build_and_run(lib: Path, prefix: str, work: Path, defines: list[str] = ()) -> str:
    """Compile NAME.c as C and apply.ino as C++ against the shim, run, return stdout."""
    (work / "arduino_shim.h").write_text(SHIM)
    (work / "main.cpp").write_text(MAIN)
    obj = work / f"{prefix}.o"
    subprocess.run([GCC, *STRICT, "-c", str(lib / "src" / f"{prefix}.c"), "-o", str(obj)],
                   check=True, capture_output=True, text=True)
    exe = work / "apply"
    cmd = [GXX, "-std=c++11", "-Wall", "-Wextra", "-Werror", "-pedantic", "-Wshadow", "-Wconversion",
           "-I", str(lib / "src"), "-I", str(lib / "examples" / "apply"), "-I", str(work), *defines,
           str(work / "main.cpp"), str(obj), "-o", str(exe)]
    build = subprocess.run(cmd, capture_output=True, text=True)
    assert build.returncode == 0, build.stderr
    return subprocess.run([str(exe)], check=True, capture_output=True, text=True, timeout=60).stdout


def _vector(out: str, label: str) -> np.ndarray:
    rows = [line.split() for line in out.splitlines() if line.split()[:1] == [label]]
    assert len(rows) == 1, out
    return np.array([float(x) for x in rows[0][1:]])


def _sample(cal, k: tuple[float, float, float]) -> np.ndarray:
    """An int16 reading: the shift plus k times the scale (k = acceleration in g per axis)."""
    raw = np.round(cal.values[0:3] + cal.values[3:6] * np.array(k) * cal.gravity)
    assert np.all(np.abs(raw) < 32767)
    return raw


# --- the layout ------------------------------------------------------------------------------
def test_layout_files_and_manifests(accel_cal, tmp_path, run_cli):
    cal, path = accel_cal
    code, out, err = run_cli(["codegen", path, "--out", tmp_path / "libs", "--layout", "arduino",
                              "--prefix", "imu_board"])
    assert code == 0, err
    lib = tmp_path / "libs" / "imu_board"
    assert sorted(str(p.relative_to(lib)) for p in lib.rglob("*") if p.is_file()) == \
        sorted(f.format(p="imu_board") for f in FILES)
    props = _properties((lib / "library.properties").read_text())
    assert REQUIRED <= set(props)
    assert props["name"] == "imu_board" and props["category"] == "Sensors" and props["architectures"] == "*"
    assert SEMVER.match(props["version"]) and props["version"] == "2024.1.1"  # created 2024-01-01
    assert props["includes"] == "imu_board.h" and props["author"] == "imucal"
    manifest = json.loads((lib / "library.json").read_text())
    assert manifest["name"] == "imu_board" and manifest["version"] == props["version"]
    assert manifest["frameworks"] == ["arduino"] and manifest["platforms"] == "*"
    assert isinstance(manifest["keywords"], list) and manifest["description"]
    # src/ holds generate_c's files unchanged.
    gen = generate_c(cal, "imu_board", "float", path)
    assert (lib / "src" / "imu_board.h").read_text() == gen.header
    assert (lib / "src" / "imu_board.c").read_text() == gen.source
    readme = (lib / "README.md").read_text()
    assert "m/s^2" in readme and "orthonormal frame f" in readme and "#include <imu_board.h>" in readme


def test_default_layout_is_flat(accel_cal, tmp_path, run_cli):
    code, _, err = run_cli(["codegen", accel_cal[1], "--out", tmp_path])
    assert code == 0, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["imucal.c", "imucal.h"]


def test_unknown_layout_refused_in_one_line(accel_cal, tmp_path, run_cli, unchanged):
    with unchanged():
        code, out, err = run_cli(["codegen", accel_cal[1], "--out", tmp_path / "o", "--layout", "zephyr"])
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and "--layout: 'zephyr' is not a layout (fix: use one of flat, arduino)" in err


def test_long_prefix_refused(accel_cal, tmp_path, run_cli, unchanged):
    with unchanged():
        code, _, err = run_cli(["codegen", accel_cal[1], "--out", tmp_path / "o", "--layout", "arduino",
                                "--prefix", "x" * 64])
    assert code == 2 and err.count("\n") == 1 and "too long for an Arduino library name" in err


def test_nothing_left_when_one_file_cannot_be_written(accel_cal, tmp_path, run_cli):
    lib = tmp_path / "imucal"
    (lib / "examples" / "apply" / "apply.ino").mkdir(parents=True)  # a folder where a file goes
    code, _, err = run_cli(["codegen", accel_cal[1], "--out", tmp_path, "--layout", "arduino"])
    assert code == 2 and "apply.ino" in err and err.count("\n") == 1
    assert sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*")) == \
        ["imucal", "imucal/examples", "imucal/examples/apply", "imucal/examples/apply/apply.ino"]


# --- the sketch, built on the host -------------------------------------------------------------
def test_sketch_prints_python_apply(accel_cal, tmp_path, run_cli):
    cal, path = accel_cal
    assert run_cli(["codegen", path, "--out", tmp_path, "--layout", "arduino"]).code == 0
    raw = _sample(cal, (0.31, -0.52, 0.77))
    defines = ["-DIMUCAL_EXAMPLE_RAW={%d,%d,%d}" % tuple(raw)]
    out = _build_and_run(tmp_path / "imucal", "imucal", tmp_path, defines)
    acc = _vector(out, "acc")
    expected = cal.apply(raw)
    assert np.all(np.abs(acc - expected) <= float_error_bound(cal, raw[None])[0] + PRINT_ROUNDING), (acc, expected)
    assert np.linalg.norm(expected) > 5  # a sample well away from zero
    assert "omega" not in out


def test_sketch_with_gyro_double(imu_cal, tmp_path, run_cli):
    cal, path = imu_cal
    assert run_cli(["codegen", path, "--out", tmp_path, "--layout", "arduino", "--precision", "double",
                    "--prefix", "board"]).code == 0
    raw = _sample(cal, (-0.6, 0.2, 0.75))
    raw_g = np.array([812.0, -1530.0, 97.0])
    defines = ["-DBOARD_EXAMPLE_RAW={%d,%d,%d}" % tuple(raw), "-DBOARD_EXAMPLE_RAW_G={%d,%d,%d}" % tuple(raw_g)]
    out = _build_and_run(tmp_path / "board", "board", tmp_path, defines)
    acc_py, omega_py = cal.apply_imu(raw, raw_g)
    acc_bound = float_error_bound(cal, raw[None], "double")[0]
    omega_bound = affine_float_error_bound(cal.gyro, raw_g, acc_py, "double", acc_bound)[0]
    assert np.all(np.abs(_vector(out, "acc") - acc_py) <= acc_bound + PRINT_ROUNDING)
    assert np.all(np.abs(_vector(out, "omega") - omega_py) <= omega_bound + PRINT_ROUNDING)
    assert np.linalg.norm(omega_py) > 0.5  # rad/s: the gyro path is exercised


def test_sketch_builds_for_a_map_with_covariates(accel_cal, tmp_path):
    """Effects with a covariate: no NAME_apply_i16, the sketch uses NAME_apply_cov (placeholder cov 0)."""
    base = accel_cal[0]
    params = base.params.extended(TempBias().parameters(base.params)).with_values(
        {"tb1": 3.5, "tb2": -2.0, "tb3": 0.7, "tk": 1.5e-4})
    cal = EffectCalibration(params=params, std={n: 0.0 for n in params}, gravity=base.gravity,
                            effects=(("tbias_test", (0, 1, 2)),), data=base.data, created=base.created)
    gen = generate_c(cal, "imucal")
    assert gen.apply_ops is None
    lib = tmp_path / "lib"
    for rel, text in arduino_files(gen, cal, None).items():
        (lib / rel).parent.mkdir(parents=True, exist_ok=True)
        (lib / rel).write_text(text)
    raw = _sample(cal, (0.1, 0.2, -0.9))
    out = _build_and_run(lib / "imucal", "imucal", tmp_path, ["-DIMUCAL_EXAMPLE_RAW={%d,%d,%d}" % tuple(raw)])
    expected = cal.apply(raw, {"temp": np.zeros(1)})
    assert np.allclose(_vector(out, "acc"), expected, rtol=0, atol=1e-4)


# --- text from the calibration file -----------------------------------------------------------
EVIL = 'x"\n*/ }, "name": "pwned", /* \\ ??/\r\nsentence=pwned'


def test_crafted_recording_name_breaks_nothing(accel_cal, tmp_path, run_cli):
    d = yaml.safe_load(accel_cal[1].read_text())
    d["data"]["file"] = EVIL
    path = tmp_path / "crafted.yaml"
    path.write_text(yaml.safe_dump(d))
    assert load_calibration(path).data["file"] == EVIL  # the loader keeps it as text
    code, _, err = run_cli(["codegen", path, "--out", tmp_path / "o", "--layout", "arduino"])
    assert code == 0, err
    lib = tmp_path / "o" / "imucal"
    texts = {p.name: p.read_text() for p in lib.rglob("*") if p.is_file()}
    for name, text in texts.items():
        assert "pwned" not in text and 'x"' not in text, name
    assert json.loads(texts["library.json"])["name"] == "imucal"
    assert _properties(texts["library.properties"])["name"] == "imucal"
    assert "name not shown" in texts["README.md"]
    assert texts["apply.ino"] == sketch(generate_c(load_calibration(path), "imucal"))  # no file text in it
    raw = _sample(accel_cal[0], (0.0, 0.0, 1.0))
    out = _build_and_run(lib, "imucal", tmp_path, ["-DIMUCAL_EXAMPLE_RAW={%d,%d,%d}" % tuple(raw)])
    assert np.allclose(_vector(out, "acc"), accel_cal[0].apply(raw), atol=1e-4)


@pytest.mark.parametrize("field, value", [(("software", "version"), '1.0"\n*/'),
                                          (("units", "input"), 'counts"\n}')])
def test_crafted_version_or_unit_refused(accel_cal, tmp_path, run_cli, unchanged, field, value):
    d = yaml.safe_load(accel_cal[1].read_text())
    d.setdefault(field[0], {})[field[1]] = value
    path = tmp_path / "crafted.yaml"
    path.write_text(yaml.safe_dump(d))
    with unchanged():
        code, out, err = run_cli(["codegen", path, "--out", tmp_path / "o", "--layout", "arduino"])
    assert code == 2 and out == "" and err.count("\n") == 1
    assert f"{field[0]}.{field[1]}" in err
