"""The magnetometer's model, built once, symbolically, in CasADi.

The paper's model read for a field instead of gravity (shared/seed, Sections 2-3):

  raw_i = s_i + b_i m_i                 Eq. (theModel): s the hard iron [raw], b the scales [raw per field unit]
  h_mag = E^-T diag(1/b) (raw - s)      Theorem: the field in the magnetometer's orthonormal frame f
                                        (f1 along its x axis, f2 in its x-y plane), E of Eq. (eq:125).
                                        E^-T diag(1/b) with the angles is the symmetric soft iron: every
                                        ellipsoid (raw - s)^T H (raw - s) = F^2 is one (Proposition 2).
  h     = R(r) P h_mag                  the field in the accelerometer's frame: P a signed permutation of
                                        the axes (how the chip is mounted, found by imucal.mag.frame), R(r)
                                        a rotation by the Euler angles r = (rx, ry, rz), exact:
                                        R = Rz(rz) Ry(ry) Rx(rx). R P E^-T diag(1/b) is the full soft iron.

Evidence, one residual function with the kind of each row in its first input (``NORM``, ``DIP``, ``SIZE``):

  NORM   |h| - F                        the field's magnitude is constant (the accelerometer's |a| - g)
  DIP    asin(a . h / (|a| |h|)) - dip  the angle between field and gravity is constant at still poses,
                                        a the calibrated accelerometer (a row's other inputs)
  SIZE   (ln b1 + ln b2 + ln b3) / 3 - target
                                        F fitted: the scales' overall size held at exp(target) (one row)
  SKEW   (M_ij - M_ji) / (tr M / 3), M = P^T R P E^-T diag(1/b) the soft iron in the magnetometer's own
                                        axes: three rows make it symmetric (the symmetric soft iron: the
                                        magnetometer's axes, permuted, are the accelerometer's); without
                                        them M is any 3x3 of positive determinant (the full soft iron)

Nothing else in the package writes these formulas: numpy evaluators are generated from them
(imucal.solve.vectorize), and so is the noise of every row (``noise``).
"""
from __future__ import annotations

import math
import re
from dataclasses import replace
from functools import lru_cache
import casadi as ca
import numpy as np

from imucal.constants import RIGHT_ANGLE
from imucal.errors import ImucalError
from imucal.model.channels import MAGNETIC_FIELD
from imucal.model.geometry import frame, frame_inverse_transpose
from imucal.model.parameters import BASE_NAMES, Parameter, Parameters, base_parameters
from imucal.model.sensor import MAGNETOMETER, SensorModel
from imucal.solve.vectorize import Vectorized

#: Rotation to the accelerometer's frame [rad] (Euler angles, R = Rz Ry Rx), the field's magnitude and dip.
ROTATION_NAMES = ("rx", "ry", "rz")
NAMES = BASE_NAMES + ROTATION_NAMES + ("F", "dip")
#: Row kinds: the first covariate of every row. SKEW rows hold one skew element each: (j, i) of SKEW_PAIRS.
NORM, DIP, SIZE, SKEW_YZ, SKEW_XZ, SKEW_XY = 0, 1, 2, 3, 4, 5
SKEW_KINDS = (SKEW_YZ, SKEW_XZ, SKEW_XY)
SKEW_PAIRS = ((1, 2), (0, 2), (0, 1))
#: Covariates of a row: its kind and the calibrated accelerometer (zeros for NORM and SIZE rows).
COVARIATES = ("evidence", "ax", "ay", "az")
#: Soft iron is larger than an accelerometer's non-orthogonality: the angles within 90 deg +- 25 %
#: (22.5 deg; det G stays above 0.6, so the frame is valid everywhere in the box).
MAG_ANGLE_TOL = 0.25
#: The residual rotation after the axis permutation: any rotation is within 62.8 deg of one of the 24
#: signed permutations; the Euler angles are bounded away from the gimbal lock at ry = +-90 deg.
ROTATION_BOUND = math.radians(80.0)
#: Undetermined above this standard error (imucal.solve.observability thresholds its parameters by
#: their scale): a rotation or dip known worse than 3 deg, a field magnitude worse than 1 %.
ANGLE_SCALE = math.radians(3.0)
#: The SIZE and SKEW rows' standard error (on the mean log-scale; relative to the mean diagonal): constraints,
#: held to a millionth.
CONSTRAINT_SIGMA = 1e-6
#: The identity: the magnetometer's axes along the accelerometer's.
IDENTITY = (1, 0, 0, 0, 1, 0, 0, 0, 1)


def rotation(rx, ry, rz):
    """R = Rz(rz) Ry(ry) Rx(rx): the exact rotation by Euler angles [rad] (no small-angle approximation)."""
    cx, sx, cy, sy, cz, sz = ca.cos(rx), ca.sin(rx), ca.cos(ry), ca.sin(ry), ca.cos(rz), ca.sin(rz)
    return ca.vertcat(ca.horzcat(cz * cy, cz * sy * sx - sz * cx, cz * sy * cx + sz * sx),
                      ca.horzcat(sz * cy, sz * sy * sx + cz * cx, sz * sy * cx - cz * sx),
                      ca.horzcat(-sy, cy * sx, cy * cx))


#: The model's name; its constants follow in brackets: the mounting P and the calibrated field's unit.
LABEL = "magnetometer-ellipsoid"
#: The label's bracket: axes as signed axis letters per row of P (+x+y+z is the identity), the field's unit.
LABEL_PATTERN = re.compile(r"^" + re.escape(LABEL) + r"\[axes=((?:[+-][xyz]){3}),field=([A-Za-z0-9_/^.()*-]{1,32})\]$")


def axes_code(axes: tuple[int, ...]) -> str:
    """P as signed axis letters, one per row (the magnetometer axis i reads frame axis j): +y+x-z."""
    P = np.array(axes, int).reshape(3, 3)
    return "".join(("+" if P[i, j] > 0 else "-") + "xyz"[j] for i in range(3) for j in range(3) if P[i, j])


def label_of(axes: tuple[int, ...], field_unit: str) -> str:
    """The description's name: LABEL[axes=+x+y+z,field=uT] (the constants a file's section records)."""
    return f"{LABEL}[axes={axes_code(axes)},field={field_unit}]"


def mag_model() -> SensorModel:
    """The magnetometer's default description (imucal.model.registry): the identity mounting, the field in the
    sensor's raw unit."""
    return build_mag_model()


def described(label: str) -> SensorModel | None:
    """The description a file's model name names (imucal.model.registry's hook), None when it names none."""
    m = LABEL_PATTERN.match(label)
    if m is None:
        return None
    code, unit = m.groups()
    axes = [0] * 9
    for i in range(3):
        sign, j = code[2 * i], "xyz".index(code[2 * i + 1])
        axes[3 * i + j] = 1 if sign == "+" else -1
    try:
        return build_mag_model(tuple(axes), unit)
    except ImucalError:  # not a proper permutation (an axis twice, a left-handed frame)
        return None


def permutation(model: SensorModel) -> np.ndarray:
    """The mounting P of a magnetometer description (a constant of its map)."""
    return np.asarray(model.functions["permutation"].call([])[0], float).reshape(3, 3)


def vectorized(model: SensorModel, name: str) -> Vectorized:
    """The numpy evaluator of one of the description's functions, generated once (imucal.solve.vectorize)."""
    return _vectorized(model.functions[name])


@lru_cache(maxsize=64)
def _vectorized(fn: ca.Function) -> Vectorized:
    return Vectorized(fn)


def _build(axes: tuple[int, ...]) -> dict[str, ca.Function]:
    raw, cov, p, g = ca.SX.sym("raw", 3), ca.SX.sym("cov", len(COVARIATES)), ca.SX.sym("p", len(NAMES)), ca.SX.sym("g")
    pd = {n: p[i] for i, n in enumerate(NAMES)}
    s = ca.vertcat(pd["s1"], pd["s2"], pd["s3"])
    b = [pd["b1"], pd["b2"], pd["b3"]]
    P = ca.DM(np.array(axes, float).reshape(3, 3))
    R = rotation(pd["rx"], pd["ry"], pd["rz"])
    L = frame_inverse_transpose(pd["phi"], pd["psi"], pd["theta"])  # Theorem: E^-T
    m = ca.vertcat(*[(raw[i] - s[i]) / b[i] for i in range(3)])  # Eq. (theModel)
    h = ca.mtimes([R, P, L, m])
    norm = ca.norm_2(h)
    kind, a = cov[0], cov[1:4]
    is_norm, is_dip, is_size = kind == NORM, kind == DIP, kind == SIZE
    a_safe = a + (1 - is_dip) * ca.DM([0, 0, 1])  # NORM and SIZE rows carry no accelerometer: no 0/0
    dip = ca.asin(ca.dot(a_safe, h) / (ca.norm_2(a_safe) * norm))
    size = (ca.log(b[0]) + ca.log(b[1]) + ca.log(b[2])) / 3
    M = ca.mtimes([P.T, R, P, L, ca.diag(ca.vertcat(*[1 / bi for bi in b]))])  # soft iron in the magnetometer's axes
    tr3 = ca.trace(M) / 3
    skew = sum(((kind == k) * (M[i, j] - M[j, i]) / tr3 for k, (i, j) in zip(SKEW_KINDS, SKEW_PAIRS)), ca.SX(0))
    is_constraint = is_size + sum((kind == k for k in SKEW_KINDS), ca.SX(0))
    r = is_norm * (norm - pd["F"]) + is_dip * (dip - pd["dip"]) + is_size * size + skew - g
    var_raw, var_acc = ca.SX.sym("var_raw", 3), ca.SX.sym("var_acc", 3)
    # first-order noise of r from the readings' variance (the gradient's squares); the SIZE row's is fixed
    sigma = ca.sqrt(ca.dot(ca.jacobian(r, raw).T ** 2, var_raw) + ca.dot(ca.jacobian(r, a).T ** 2, var_acc)
                    + is_constraint * CONSTRAINT_SIGMA ** 2)
    # forward map h -> raw: raw = s + diag(b) E^T P^T R^T h (the inverse of apply)
    hin = ca.SX.sym("h", 3)
    mf = ca.mtimes([frame(pd["phi"], pd["psi"], pd["theta"]).T, P.T, R.T, hin])
    raw_f = s + ca.vertcat(*[b[i] * mf[i] for i in range(3)])
    araw = ca.SX.sym("a", 3)
    dip_of = ca.asin(ca.dot(araw, h) / (ca.norm_2(araw) * norm))
    return {
        "apply": ca.Function("apply", [raw, ca.SX.sym("inputs", 0), p], [h], ["raw", "inputs", "p"], ["calibrated"]),
        "field": ca.Function("mag_field", [raw, p], [h], ["raw", "p"], ["h"]),
        "permutation": ca.Function("permutation", [], [P]),
        "forward": ca.Function("mag_forward", [hin, p], [raw_f], ["h", "p"], ["raw"]),
        "residual": ca.Function("mag_residual", [raw, cov, p, g], [r], ["raw", "cov", "p", "g"], ["r"]),
        "noise": ca.Function("mag_noise", [raw, cov, p, g, var_raw, var_acc], [sigma],
                             ["raw", "cov", "p", "g", "var_raw", "var_acc"], ["sigma"]),
        "norm": ca.Function("mag_norm", [raw, p], [norm], ["raw", "p"], ["norm"]),
        "dip": ca.Function("mag_dip", [raw, araw, p], [dip_of], ["raw", "a", "p"], ["dip"]),
    }


@lru_cache(maxsize=64)
def build_mag_model(axes: tuple[int, ...] = IDENTITY, field_unit: str = "raw") -> SensorModel:
    """The magnetometer's description for the axis permutation ``axes`` and the calibrated field's unit
    (built once per pair): kind magnetometer, its map ``apply``(raw, [], p) -> h, its evidence's rows
    reading ``COVARIATES`` (the row's kind and the calibrated acceleration)."""
    axes = tuple(int(v) for v in axes)
    P = np.array(axes, float).reshape(3, 3) if len(axes) == 9 else np.zeros((3, 3))
    if len(axes) != 9 or not np.allclose(P @ P.T, np.eye(3)) or not np.isclose(np.linalg.det(P), 1.0):
        raise ImucalError(f"axes {axes} are not a proper signed permutation", field="mag.axes",
                          fix="each row one +-1, a right-handed frame")
    return SensorModel(effects=(), names=NAMES, inputs=(), functions=_build(axes), kind=MAGNETOMETER,
                       label=label_of(axes, field_unit), channel=MAGNETIC_FIELD,
                       output=MAGNETIC_FIELD.with_unit(field_unit), symbol="mag", output_symbol="mag",
                       evidence_inputs=COVARIATES)


def mag_parameters(s0, b0, angles0=(RIGHT_ANGLE,) * 3, field_magnitude: float = 1.0,
                   rotation0=(0.0, 0.0, 0.0), dip0: float = 0.0, raw_unit: str = "raw", field_unit: str = "raw",
                   angle_tol: float = MAG_ANGLE_TOL) -> Parameters:
    """The model's parameters, named with units, bounds and scales (the solver's and the coverage check's).

    The nine of the accelerometer (imucal.model.parameters.base_parameters) with a field for gravity:
    a shift's scale is one field's worth of raw output, so 1 % of it is the coverage check's limit.
    """
    base = base_parameters(s0, b0, angles0, angle_tol=angle_tol, raw_unit=raw_unit, gravity=field_magnitude)
    unit_b = f"{raw_unit}/{field_unit}"
    params = [replace(base[n], unit=unit_b) if n.startswith("b") else
              replace(base[n], description=f"hard iron (offset) of axis {n[1]}") if n.startswith("s") else base[n]
              for n in base.names]
    for name, v in zip(ROTATION_NAMES, rotation0):
        params.append(Parameter(name, float(v), -ROTATION_BOUND, ROTATION_BOUND, "rad", scale=ANGLE_SCALE,
                                undetermined=1.0,
                                description=f"rotation to the accelerometer's frame about {name[1]}"))
    params.append(Parameter("F", float(field_magnitude), 0.0, math.inf, field_unit, undetermined=1.0,
                            scale=0.01 * abs(float(field_magnitude)) or 1.0, description="field magnitude"))
    params.append(Parameter("dip", float(dip0), -RIGHT_ANGLE, RIGHT_ANGLE, "rad", scale=ANGLE_SCALE,
                            undetermined=1.0,
                            description="angle between field and gravity's plane: asin(a . h / |a||h|)"))
    return Parameters(params)


def parameter_units(model: SensorModel, raw_unit: str) -> dict[str, str]:
    """Each parameter's unit for a magnetometer read in ``raw_unit`` whose field is in the model's output unit
    (imucal.model.registry.parameter_units's hook): the units ``mag_parameters`` writes."""
    params = mag_parameters((0.0,) * 3, (1.0,) * 3, raw_unit=raw_unit, field_unit=model.output.unit)
    return {n: p.unit for n, p in params.items()}
