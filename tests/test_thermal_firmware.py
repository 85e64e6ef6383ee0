"""What the firmware needs, from a temperature sweep's calibration (issue 27): the generated C and the
ArduPilot INS_TCAL1_* / PX4 TC_A0_* parameters, each evaluated the way the firmware's own code does it
(float32, its reference temperature, its clamping to [TMIN, TMAX]) against ``imucal apply``.

The formulas are written here from the autopilots' sources, not taken from imucal's export code:
  ArduPilot  libraries/AP_InertialSensor/AP_InertialSensor_tempcal.cpp TCal::correct_sensor:
             T = constrain(T, TMIN, TMAX); Tc = constrain(INS_ACC1_CALTEMP, TMIN, TMAX);
             v -= P(T - 35); v += P(Tc - 35); P(x) = (c1 + (c2 + c3 x) x) x * 1e-6, in float;
             then AP_InertialSensor_Backend::_rotate_and_correct_accel: v -= INS_ACCOFFS; v *= INS_ACCSCAL.
  PX4        src/modules/temperature_compensation/TemperatureCompensation.cpp calc_thermal_offsets_3D:
             dT = (T > TMAX ? TMAX : T < TMIN ? TMIN : T) - TREF; o = X0 + X1 dT + X2 dT^2 + X3 dT^3, in
             float; then Accelerometer.hpp Correct(): (v - o - CAL_ACC0_*OFF) .* CAL_ACC0_*SCALE.
"""
from __future__ import annotations

import ctypes
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from test_thermal import MG, run_config, sweep
from imucal.analysis.discover import discover
from imucal.calibration.frozen import load_calibration

GCC = shutil.which("gcc")
F = np.float32
#: Bias-only truth (what both autopilots hold exactly): linear on x, y, z and quadratic on y.
BIAS_ONLY = {"bias1": (0.6 * MG, -2.2 * MG, 2.5 * MG), "bias2": (0.0, 0.05 * MG, 0.0), "scale1": (0.0, 0.0, 0.0)}


@pytest.fixture(scope="module")
def cal_path(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("fw")
    d = discover(run_config(sweep(root / "sweep.csv", truth=BIAS_ONLY, seed=11)))
    assert d.thermal.effects == {"bias_temperature": (0, 1, 2), "bias_temperature2": (1,)}
    path = root / "calibration.yaml"
    d.calibration_run.calibration.save(path)
    return path


def _samples() -> tuple[np.ndarray, np.ndarray]:
    """Readings near each pose, at temperatures inside and outside the calibrated range (-20..60 degC)."""
    rng = np.random.default_rng(27)
    raw = np.vstack([rng.normal(c, 0.3, (300, 3)) for c in ([0, 0, -9.8], [-9.8, 0, 0], [0, -9.8, 0])])
    return raw, rng.uniform(-20.0, 60.0, raw.shape[0])


def _apply(cli, cal: Path, raw: np.ndarray, temp: np.ndarray, tmp: Path) -> np.ndarray:
    """``imucal apply`` on a CSV with a temp column."""
    src = tmp / "in.csv"
    np.savetxt(src, np.column_stack([np.arange(raw.shape[0]) * 0.01, raw, temp]), delimiter=",",
               header="t,ax,ay,az,temp", comments="", fmt="%.9g")
    r = cli(["apply", cal, "--data", src, "--out", tmp / "out.csv"])
    assert r.code == 0, r.err
    return np.loadtxt(tmp / "out.csv", delimiter=",", skiprows=1)[:, 1:4]


def _export(cli, cal: Path, fmt: str, tmp: Path) -> dict[str, float]:
    out = tmp / f"{fmt}.param"
    r = cli(["export", cal, "--format", fmt, "--out", out])
    assert r.code == 0, r.err
    rows = [ln for ln in out.read_text().splitlines() if ln.strip() and not ln.startswith("#")]
    if fmt == "ardupilot":
        return {a: float(b) for a, b in (ln.split(",")[:2] for ln in rows)}
    return {p[2]: float(p[3]) for p in (ln.split("\t") for ln in rows)}


def ardupilot(p: dict[str, float], raw: np.ndarray, temp: np.ndarray, sensor: str = "ACC") -> np.ndarray:
    """AP_InertialSensor_TCal's correction of ``sensor`` (ACC, GYR) as its float32 code does it, then the
    offsets (and the accelerometer's scales)."""
    lo, hi = F(p["INS_TCAL1_TMIN"]), F(p["INS_TCAL1_TMAX"])
    c = [np.array([p[f"INS_TCAL1_{sensor}{k}_{a}"] for a in "XYZ"], F) for k in (1, 2, 3)]

    def P(x):  # polynomial_eval
        x = F(x)
        return (c[0] + (c[1] + c[2] * x) * x) * x * F(1.0e-6)

    cal_t = np.clip(F(p[f"INS_{sensor}1_CALTEMP"]), lo, hi)
    off = np.array([p[f"INS_{sensor}OFFS_{a}" if sensor == "ACC" else f"INS_GYROFFS_{a}"] for a in "XYZ"], F)
    scale = np.array([p[f"INS_ACCSCAL_{a}"] for a in "XYZ"], F) if sensor == "ACC" else np.ones(3, F)
    out = np.empty(raw.shape, F)
    for k, (v, T) in enumerate(zip(raw.astype(F), temp.astype(F))):
        v = v - P(np.clip(T, lo, hi) - F(35.0)) + P(cal_t - F(35.0))  # correct_sensor
        out[k] = (v - off) * scale
    return out.astype(float)


def px4(p: dict[str, float], raw: np.ndarray, temp: np.ndarray, sensor: str = "A") -> np.ndarray:
    """PX4's TemperatureCompensation of ``sensor`` (A, G) as its float32 code does it, then the offsets (and the
    accelerometer's scales)."""
    tmin, tmax, tref = F(p[f"TC_{sensor}0_TMIN"]), F(p[f"TC_{sensor}0_TMAX"]), F(p[f"TC_{sensor}0_TREF"])
    x = [np.array([p[f"TC_{sensor}0_X{k}_{i}"] for i in range(3)], F) for k in range(4)]
    cal = "CAL_ACC0" if sensor == "A" else "CAL_GYRO0"
    off = np.array([p[f"{cal}_{a}OFF"] for a in "XYZ"], F)
    scale = np.array([p[f"{cal}_{a}SCALE"] for a in "XYZ"], F) if sensor == "A" else np.ones(3, F)
    out = np.empty(raw.shape, F)
    for k, (v, T) in enumerate(zip(raw.astype(F), temp.astype(F))):
        dT = (tmax - tref) if T > tmax else ((tmin - tref) if T < tmin else (T - tref))
        dT2 = dT * dT
        o = x[0] + x[1] * dT + x[2] * dT2 + x[3] * dT2 * dT  # calc_thermal_offsets_3D
        out[k] = (v - o - off) * scale
    return out.astype(float)


@pytest.mark.parametrize("fmt", ["ardupilot", "px4"])
def test_the_autopilots_formula_gives_what_apply_gives(cal_path, run_cli, tmp_path, fmt):
    """Inside the calibrated range the firmware's own polynomial equals apply to float precision; outside it
    the firmware holds the end value, which is apply at the clamped temperature."""
    raw, temp = _samples()
    params = _export(run_cli, cal_path, fmt, tmp_path)
    assert "holds no temperature scale term" not in (tmp_path / f"{fmt}.param").read_text()  # none to drop
    lo, hi = (params["INS_TCAL1_TMIN"], params["INS_TCAL1_TMAX"]) if fmt == "ardupilot" else \
        (params["TC_A0_TMIN"], params["TC_A0_TMAX"])
    cal = load_calibration(cal_path)
    assert (lo, hi) == pytest.approx(tuple(cal.fit["temperature_range"]), abs=0.01)
    firmware = (ardupilot if fmt == "ardupilot" else px4)(params, raw, temp)
    ref = _apply(run_cli, cal_path, raw, np.clip(temp, lo, hi), tmp_path)
    assert np.abs(firmware - ref).max() < 2e-3 * MG  # float32 and the parameter file's digits
    inside = (temp > lo) & (temp < hi)
    moved = np.abs(_apply(run_cli, cal_path, raw, temp, tmp_path) - ref).max(axis=1)
    assert inside.any() and (~inside).any() and np.all(moved[inside] == 0) and moved[~inside].max() > 0.5 * MG


def test_the_generated_c_gives_what_apply_gives(cal_path, run_cli, tmp_path):
    """imucal codegen from the sweep's calibration: compiled, fed the temperature, equal to apply in float."""
    if GCC is None:
        pytest.skip("gcc not found")
    raw, temp = _samples()
    r = run_cli(["codegen", cal_path, "--out", tmp_path / "c", "--precision", "float", "--prefix", "th"])
    assert r.code == 0, r.err
    lib = tmp_path / "c" / "libth.so"
    subprocess.run([GCC, "-std=c99", "-O2", "-fPIC", "-shared", "-o", str(lib), str(tmp_path / "c" / "th.c"), "-lm"],
                   check=True, capture_output=True, text=True)
    dll = ctypes.CDLL(str(lib))
    fn = dll.th_apply_cov_batch
    fn.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t]
    r32, t32 = np.ascontiguousarray(raw, F), np.ascontiguousarray(temp[:, None], F)
    acc = np.zeros_like(r32)
    fn(r32.ctypes.data, t32.ctypes.data, acc.ctypes.data, raw.shape[0])
    ref = _apply(run_cli, cal_path, r32.astype(float), t32[:, 0].astype(float), tmp_path)
    assert np.abs(acc - ref).max() < 1e-3 * MG  # float32 arithmetic on |a| ~ 10 m/s^2
