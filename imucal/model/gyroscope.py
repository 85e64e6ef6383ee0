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

Temperature (issue 27): the grammar's terms (imucal.model.effects, a target x a basis: ``bias_temperature``,
``_temperature2``, ``_temperature3``, the drift and scale terms alike) make the bias and the scale functions of
a covariate, s_g -> s_g + c_i p_k(T), b_g -> b_g (1 + c_i p_k(T)), exactly as they do the accelerometer's
shifts and scales; the covariate (``temp``) is then one more input of the map, after ax, ay, az, and the
terms' coefficients and fixed references (T_ref, the orthogonal polynomials' constants) follow the 21 names.
Without terms the description is the one above, unchanged.
"""
from __future__ import annotations

import re
from functools import lru_cache
from typing import Iterable, Mapping, Sequence

import casadi as ca
import numpy as np

from imucal.constants import SI_RATE_UNIT
from imucal.errors import ImucalError, short
from imucal.model.channels import ACCELERATION, ANGULAR_RATE, TIME
from imucal.model.parameters import Parameter, Parameters
from imucal.model.sensor import GYROSCOPE, Effect, SensorModel

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


def _apply(effects: tuple[Effect, ...] = ()) -> ca.Function:
    names, covs = _names(effects), _covariates(effects)
    raw, a, p = ca.SX.sym("raw", 3), ca.SX.sym("inputs", len(INPUTS) + len(covs)), ca.SX.sym("p", len(names))
    acc = a[0:3]
    s, scale, mis = p[0:3], p[3:6], p[6:12]
    if effects:  # the grammar's terms on the bias and the scale (imucal.model.effects.Term.shift_scale)
        pd = {n: p[i] for i, n in enumerate(names)}
        cd = {c: a[len(INPUTS) + i] for i, c in enumerate(covs)}
        sl, bl = [s[i] for i in range(3)], [scale[i] for i in range(3)]
        for e in effects:
            sl, bl = e.shift_scale(sl, bl, cd, pd)
        s, scale = ca.vertcat(*sl), ca.vertcat(*bl)
    H = ca.reshape(p[12:21], 3, 3).T  # row-major
    C = ca.mtimes(ca.inv(misalignment_matrix(mis)), ca.diag(1.0 / scale))  # M_g^-1 B_g^-1
    omega = ca.mtimes(C, raw - s) - ca.mtimes(ca.mtimes(C, H), acc)  # C (raw - s_g) - D a, D = M_g^-1 G_s
    return ca.Function("apply", [raw, a, p], [omega], ["raw", "inputs", "p"], ["calibrated"])


def _covariates(effects: Sequence[Effect]) -> tuple[str, ...]:
    return tuple(sorted({c for e in effects for c in e.covariates}))


def _names(effects: Sequence[Effect]) -> tuple[str, ...]:
    return NAMES + tuple(p.name for e in effects for p in e.parameters(None))  # type: ignore[arg-type]


def _checked(effects: Iterable[Effect]) -> tuple[Effect, ...]:
    """The terms the gyroscope takes: the grammar's shift and scale terms (no specific-force term)."""
    from imucal.model.effects import EFFECTS, Term
    out = tuple(effects)
    for e in out:
        if not isinstance(e, Term):
            raise ImucalError(f"the gyroscope takes no {short(e.name)} term", field="gyroscope.model",
                              fix=f"use the bias and scale terms: {', '.join(n for n, c in EFFECTS.items() if issubclass(c, Term))}")
    return out


def label(effects: Sequence[Effect] = ()) -> str:
    """The description's name: LABEL, then each term as the accelerometer's model names it."""
    return LABEL + "".join(f"+{e.name}[{''.join(AXES[i] for i in e.axes)}]" for e in effects)


@lru_cache(maxsize=16)
def _cached(key: tuple, effects: tuple[Effect, ...]) -> SensorModel:
    covs = _covariates(effects)
    return SensorModel(effects=effects, names=_names(effects), inputs=INPUTS + covs,
                       functions={"apply": _apply(effects)}, kind=GYROSCOPE, label=label(effects),
                       channel=ANGULAR_RATE, output=ANGULAR_RATE.with_unit(SI_RATE_UNIT), evidence_reads=(TIME,),
                       symbol="gyro", output_symbol="omega")


def gyro_model(effects: Iterable[Effect] = ()) -> SensorModel:
    """The gyroscope's description, with the grammar's temperature (or drift) terms ``effects`` (built once
    per set)."""
    effs = _checked(effects)
    return _cached(tuple(e.key for e in effs), effs)


_TERM = re.compile(r"\+([a-z0-9_]+)\[([xyz]+)\]")


def described(name: str) -> SensorModel | None:
    """The description a file's model name names (``label``), or None when it is not a gyroscope's
    (imucal.model.registry.describe's hook)."""
    from imucal.model.effects import EFFECTS, make_effect
    if not name.startswith(LABEL):
        return None
    rest, effects = name[len(LABEL):], []
    for m in _TERM.finditer(rest):
        if m.group(1) not in EFFECTS:
            return None
        effects.append(make_effect(m.group(1), sorted(AXES.index(c) for c in m.group(2))))
    if "".join(m.group(0) for m in _TERM.finditer(rest)) != rest:
        return None
    model = gyro_model(effects)
    return model if model.name == name else None


def term_parameters(effects: Sequence[Effect], unit: str, values: Mapping[str, float], nominal: float = 1.0
                    ) -> list[Parameter]:
    """The terms' parameters for a gyroscope read in ``unit``: each coefficient (a bias term's in ``unit`` per
    unit of its basis, its solver unit the grammar's generous magnitude times ``nominal`` [unit per rad/s]; a
    scale term's relative) and the fixed references, valued from ``values`` (the sweep's fit)."""
    out = []
    for e in effects:
        for prm in e.parameters(None):  # type: ignore[arg-type]
            v = float(values.get(prm.name, prm.value))
            if prm.fixed:
                out.append(Parameter(prm.name, v, unit=prm.unit, fixed=True, scale=max(abs(v), 1.0),
                                     description=prm.description))
                continue
            bias = getattr(e, "target", "") == "bias"
            out.append(Parameter(prm.name, v, lower=prm.lower, upper=prm.upper,
                                 unit=e.unit.replace("{raw}", unit), scale=e.typical * (nominal if bias else 1.0),
                                 description=f"gyroscope {prm.description}"))
    return out


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


def parameter_units(model: SensorModel, raw_unit: str) -> dict[str, str]:
    """Each parameter's unit for a gyroscope read in ``raw_unit`` (imucal.model.registry.parameter_units's hook):
    the units ``gyro_parameters`` and ``term_parameters`` write."""
    params = gyro_parameters(raw_unit, (0.0,) * 3, (1.0,) * 3).extended(term_parameters(model.effects, raw_unit, {}))
    return {n: p.unit for n, p in params.items()}


def values(params: Parameters) -> dict[str, np.ndarray]:
    """The parameters as the model's arrays: bias (3,), scale (3,), misalignment M_g (3, 3), H (3, 3)."""
    v = params.value_dict()
    return {"bias": np.array([v[n] for n in BIAS_NAMES]), "scale": np.array([v[n] for n in SCALE_NAMES]),
            "misalignment": misalignment_matrix(np.array([v[n] for n in MIS_NAMES])),
            "H": np.array([v[n] for n in GSENS_NAMES]).reshape(3, 3)}
