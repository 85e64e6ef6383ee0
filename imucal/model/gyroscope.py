"""The gyroscope as a sensor description (issue 26): named parameters and its map, once, in CasADi.

Forward (what the sensor reports):  raw = s_g + B_g (M_g omega + G_s a)
Inverse (``apply``):                omega = C (raw - s_g) - D a,   C = M_g^-1 B_g^-1,  D = C H

s_g the bias [raw]; B_g = diag(scale) [raw per rad/s]; M_g maps the rate in the accelerometer's
orthonormal output frame to the gyro's sensitive axes, unit diagonal and six free off-diagonal
entries (the diagonal is carried by B_g: a general 3x3 M_g with a free diagonal would duplicate the
scale, so only 9 = 3 + 6 entries of B_g M_g are identifiable); the g-sensitivity is held in raw units,
H = B_g G_s [raw per m/s^2] (what the still poses measure: imucal.gyro.gsens), so G_s = B_g^-1 H
[(rad/s) per (m/s^2)]; a the calibrated specific force [m/s^2] in the accelerometer's frame (its
inputs ax, ay, az). The bias is subtracted first (c = -C s_g cancels for offset-binary counts).

Its evidence is the motion segments between still poses (imu_tk's residual R_k^T u0 - u1 after
integrating ``apply``'s rate with the RK4 step of imucal.gyro.model: imucal.gyro.attitude).
"""
from __future__ import annotations

from functools import lru_cache
from typing import Iterable

import casadi as ca
import numpy as np

from imucal.constants import SI_RATE_UNIT
from imucal.model.channels import ACCELERATION, ANGULAR_RATE, TIME
from imucal.model.parameters import Parameter, Parameters
from imucal.model.sensor import GYROSCOPE, SensorModel

AXES = "xyz"
#: M_g's free entries: m_ij is row i (gyro axis), column j (frame axis)
MIS_NAMES = ("m_xy", "m_xz", "m_yx", "m_yz", "m_zx", "m_zy")
MIS_INDEX = ((0, 1), (0, 2), (1, 0), (1, 2), (2, 0), (2, 1))
BIAS_NAMES = tuple(f"bias_{a}" for a in AXES)
SCALE_NAMES = tuple(f"scale_{a}" for a in AXES)
#: H = B_g G_s row-major: gsens_ij is gyro axis i's reading per m/s^2 along frame axis j
GSENS_NAMES = tuple(f"gsens_{i}{j}" for i in AXES for j in AXES)
NAMES = BIAS_NAMES + SCALE_NAMES + MIS_NAMES + GSENS_NAMES
#: the calibrated acceleration's columns, the inputs of the map (the accelerometer's output)
INPUTS = ACCELERATION.columns
#: the model's name in files and reports
LABEL = "gyro-bias-scale-misalignment-gsens"
#: A scale is undetermined when its predicted relative standard error exceeds 1 / (45 deg in rad): the
#: motions must turn gravity about the axis by an effective 45 deg (imucal.gyro.fit: MIN_ANGLE_DEG)
MIN_ANGLE_DEG = 45.0
#: The bias correction's solver unit, relative to the scale: 1 mrad/s of raw reading (imu_tk's
#: enableGyroBiasOptimization moves the bias by a small fraction of a rad/s)
BIAS_STEP = 1e-3


def misalignment_matrix(m: "ca.SX | ca.MX | np.ndarray") -> "ca.SX | ca.MX | np.ndarray":
    """M_g from its six off-diagonal entries (unit diagonal)."""
    if isinstance(m, np.ndarray):
        M = np.eye(3)
        for k, (i, j) in enumerate(MIS_INDEX):
            M[i, j] = m[k]
        return M
    M = type(m).eye(3)
    for k, (i, j) in enumerate(MIS_INDEX):
        M[i, j] = m[k]
    return M


def misalignment_entries(M: np.ndarray) -> np.ndarray:
    """The six off-diagonal entries of a unit-diagonal M_g (inverse of ``misalignment_matrix``)."""
    return np.array([M[i, j] for i, j in MIS_INDEX])


def _apply() -> ca.Function:
    raw, a, p = ca.SX.sym("raw", 3), ca.SX.sym("inputs", 3), ca.SX.sym("p", len(NAMES))
    s, scale, mis = p[0:3], p[3:6], p[6:12]
    H = ca.reshape(p[12:21], 3, 3).T  # row-major
    C = ca.mtimes(ca.inv(misalignment_matrix(mis)), ca.diag(1.0 / scale))  # M_g^-1 B_g^-1
    omega = ca.mtimes(C, raw - s) - ca.mtimes(ca.mtimes(C, H), a)  # C (raw - s_g) - D a, D = M_g^-1 G_s
    return ca.Function("apply", [raw, a, p], [omega], ["raw", "inputs", "p"], ["calibrated"])


@lru_cache(maxsize=1)
def gyro_model() -> SensorModel:
    """The gyroscope's description (built once)."""
    return SensorModel(effects=(), names=NAMES, inputs=INPUTS, functions={"apply": _apply()}, kind=GYROSCOPE,
                       label=LABEL, channel=ANGULAR_RATE, output=ANGULAR_RATE.with_unit(SI_RATE_UNIT),
                       evidence_reads=(TIME,), symbol="gyro", output_symbol="omega")


def gyro_parameters(unit: str, bias: Iterable[float], scale: Iterable[float], mis: Iterable[float] = (0.0,) * 6,
                    gsens: Iterable[float] = (0.0,) * 9, *, free_bias: bool = False, nominal: float | None = None,
                    gsens_free: Iterable[bool] = (False,) * 3, min_angle_deg: float = MIN_ANGLE_DEG) -> Parameters:
    """The gyroscope's 21 named parameters, as the rotation fit frees them.

    Scale and misalignment free; the bias and the g-sensitivity H (row-major, ``gsens``) held at the still
    poses' values (imucal.gyro.gsens), the bias freed with ``free_bias``. The solver's units: ``nominal``
    [unit per rad/s] (default: the mean scale) for a scale, 1 for an entry of M_g, BIAS_STEP ``nominal`` for
    a bias. A scale is undetermined beyond 1/rad(``min_angle_deg``) of ``nominal``; an entry of M_g beyond 1.
    ``gsens_free``: per gyro axis, whether its row of H is a fitted value (the file's fixed flag reads it).
    """
    bias, scale, mis, H = (np.asarray(list(v), float) for v in (bias, scale, mis, gsens))
    k = float(nominal if nominal is not None else np.mean(scale))
    raw_rate, raw_acc = f"{unit}/(rad/s)", f"{unit}/(m/s^2)"
    rows = list(gsens_free)
    out = [Parameter(n, float(v), unit=unit, fixed=not free_bias, scale=BIAS_STEP * k,
                     description=f"bias of gyro axis {a}") for n, v, a in zip(BIAS_NAMES, bias, AXES)]
    out += [Parameter(n, float(v), lower=0.0, unit=raw_rate, scale=k, undetermined=1.0 / np.radians(min_angle_deg),
                      description=f"scale (sensitivity) of gyro axis {a}") for n, v, a in zip(SCALE_NAMES, scale, AXES)]
    out += [Parameter(n, float(v), unit="1", scale=1.0, undetermined=1.0,
                      description=f"misalignment: gyro axis {AXES[i]}'s response to a rate about frame axis {AXES[j]}")
            for n, v, (i, j) in zip(MIS_NAMES, mis, MIS_INDEX)]
    out += [Parameter(n, float(v), unit=raw_acc, fixed=True, scale=BIAS_STEP * k,
                      description=f"g-sensitivity (B_g G_s) of gyro axis {n[-2]} to specific force along frame axis "
                                  f"{n[-1]}" + ("" if rows[AXES.index(n[-2])] else ", not selected: zero"))
            for n, v in zip(GSENS_NAMES, H.ravel())]
    return Parameters(out)


def values(params: Parameters) -> dict[str, np.ndarray]:
    """The parameters as the model's arrays: bias (3,), scale (3,), misalignment M_g (3, 3), H (3, 3)."""
    v = params.value_dict()
    return {"bias": np.array([v[n] for n in BIAS_NAMES]), "scale": np.array([v[n] for n in SCALE_NAMES]),
            "misalignment": misalignment_matrix(np.array([v[n] for n in MIS_NAMES])),
            "H": np.array([v[n] for n in GSENS_NAMES]).reshape(3, 3)}
