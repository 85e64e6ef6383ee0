"""The paper's sensor model, built once, symbolically, in CasADi.

Notation (shared/seed, Sections 2-3):
  raw_i = s_i + b_i * m_i            Eq. (theModel): shift s_i [raw], scale b_i [raw/(m/s^2)]
  m_i   = e_i . a                    Lemma 1: projection of the true acceleration on unit axis e_i
  G     = Gram matrix of the e_i     Eq. (eq:12): 1 on the diagonal, cos phi, cos psi, cos theta off it
  abar  = G^-1 m                     Lemma 2 / Remark 1 (Tbar = G^-1): affine coordinates
  |a|^2 = m . abar = m^T G^-1 m      Lemma 3 (a_nonorth) and Proposition 2
  E     = Tbar^orth (upper triangular, columns e_i in the frame f)    Proposition 3, Eq. (eq:125)
  a_orth = E abar = E^-T m           Theorem; E^-T is lower triangular, so the whole apply map is
                                     a lower-triangular matrix A = E^-T diag(1/b) and an offset -A s.
Exact trigonometry throughout: no small-angle approximation.

Effects (see imucal.model.effects) extend the shifts, the scales or the measured value with terms in
covariates such as temperature or time; the base model has none.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property, lru_cache
from typing import Mapping, Sequence

import casadi as ca

from imucal.model.geometry import (frame, frame_inverse_transpose, frame_np, geometry_function,  # noqa: F401
                                   gram, gram_det, gram_det_np, gram_np, tbar)
from imucal.constants import SI_ACCEL_UNIT
from imucal.model.channels import ACCELERATION, COVARIATES, Channel, covariate_channels
from imucal.model.parameters import BASE_NAMES, Parameter, Parameters
from imucal.model.parameters import base_parameters


class Effect:
    """A named physical effect: extra parameters and terms in the sensor model.

    Subclasses override ``shift_scale`` (to make s, b depend on covariates), ``correct`` (to
    change the measured value m) and/or ``angles`` (to make the angles between the axes depend on them). ``key`` identifies the effect for caching.
    """

    name: str = "effect"
    covariates: tuple[str, ...] = ()

    def __init__(self, axes: Sequence[int] = (0, 1, 2)) -> None:
        self.axes = tuple(sorted(set(int(a) for a in axes)))

    @property
    def key(self) -> tuple:
        return (self.name, self.axes)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Effect) and self.key == other.key

    def __hash__(self) -> int:
        return hash(self.key)

    def __repr__(self) -> str:
        return f"{type(self).__name__}(axes={self.axes})"

    def parameters(self, base: Parameters) -> list[Parameter]:
        return []

    def shift_scale(self, s: list, b: list, cov: Mapping[str, ca.SX], p: Mapping[str, ca.SX]
                    ) -> tuple[list, list]:
        return s, b

    def correct(self, m: list, raw: ca.SX, cov: Mapping[str, ca.SX], p: Mapping[str, ca.SX]) -> list:
        return m

    def angles(self, ang: list, cov: Mapping[str, ca.SX], p: Mapping[str, ca.SX]) -> list:
        """The angles phi, psi, theta (Eq. eq:12) as the effect makes them depend on covariates."""
        return ang


#: The sensor kinds (``SensorModel.kind``; a calibration file's section names).
ACCELEROMETER, GYROSCOPE, MAGNETOMETER = "accelerometer", "gyroscope", "magnetometer"


@dataclass(frozen=True)
class SensorModel:
    """One sensor, described as data (issue 26): every sensor is an instance, and the fit, the
    covariance, the observability check, the file section, the numpy evaluator and the C are generated
    from it (docs/architecture.md, "A sensor is data").

      kind      "accelerometer", "gyroscope" (the calibration file's section, the report's heading)
      label     the model's name (nakov-ivanov-9+effects, imutk-gyro ...)
      channel   the raw channel it calibrates (imucal.model.channels: columns and unit)
      inputs    the other inputs its map reads, in order: covariate keys (temp, time: Effect.covariates)
                or another sensor's calibrated columns (ax, ay, az: the gyroscope's g-sensitivity)
      names     its parameters in the order of p (named Parameters with units, bounds, scales and
                undetermined thresholds are built by each sensor's own function)
      output    the calibrated channel: its columns (ax.., gx..) and unit (m/s^2, rad/s)
      symbol    its short name in generated C (acc, gyro) and its output's (acc, omega)
      functions CasADi functions built once:
        apply(raw[3], inputs[k], p[n]) -> calibrated[3]   the map from raw to calibrated
      and, generated from apply, ``affine``: p -> (A, c, B) with calibrated = A raw + c + B inputs, for a
      map that is affine in raw and inputs (None otherwise: an accelerometer with effects)
        and the residual of its evidence: the accelerometer's residual(raw, cov, p, g) = |a| - g per row
        (the gyroscope's evidence, its motion segments, integrates apply: imucal.gyro.attitude)

    The accelerometer's model (``build_model``) also has, per sample (``cov`` = ``inputs``):
      measured(raw[3], cov[k], p[np]) -> m[3]          Eq. (theModel) plus effects
      accel(raw, cov, p)              -> a_orth[3]     Theorem
      norm(raw, cov, p)               -> |a|           Proposition 2 (m^T G^-1 m)
      residual(raw, cov, p, g)        -> |a| - g       the calibration condition g = a_nonorth
    """

    effects: tuple[Effect, ...]
    names: tuple[str, ...]
    inputs: tuple[str, ...]
    functions: Mapping[str, ca.Function] = field(compare=False, repr=False)
    kind: str = ACCELEROMETER
    label: str = ""
    channel: Channel = ACCELERATION
    output: Channel = ACCELERATION.with_unit(SI_ACCEL_UNIT)
    #: channels its evidence reads beyond its raw channel and inputs (the gyroscope's: time)
    evidence_reads: tuple[Channel, ...] = ()
    #: its short name in generated C (NAME_apply_<symbol>, raw_<first letter>, NAME_HAS_<SYMBOL>) and the
    #: name of its calibrated output there
    symbol: str = "acc"
    output_symbol: str = "acc"
    #: the other inputs of its evidence's residual (the ``cov`` of imucal.solve.least_squares.row_functions)
    #: when they are not its map's covariates (the magnetometer's rows: their kind and the calibrated
    #: acceleration); None: ``covariates``
    evidence_inputs: tuple[str, ...] | None = None

    @property
    def name(self) -> str:
        if self.label:
            return self.label
        if not self.effects:
            return "nakov-ivanov-9"
        return "nakov-ivanov-9+" + "+".join(f"{e.name}[{''.join('xyz'[a] for a in e.axes)}]"
                                            for e in self.effects)

    @property
    def covariates(self) -> tuple[str, ...]:
        """The inputs that are covariates of the recording (temp, time), in the layout of ``cov``."""
        return tuple(k for k in self.inputs if k in COVARIATES)

    @property
    def evidence_covariates(self) -> tuple[str, ...]:
        """The layout of its evidence residual's ``cov`` input (``evidence_inputs``, else ``covariates``)."""
        return self.covariates if self.evidence_inputs is None else self.evidence_inputs

    @property
    def reads(self) -> tuple[Channel, ...]:
        """The channels the model reads: its raw channel, the channels behind its inputs (covariates, or
        the sensor whose calibrated output it takes), and what its evidence needs."""
        out = [self.channel, *covariate_channels(self.covariates)]
        out += [ACCELERATION for k in self.inputs if k in ACCELERATION.columns][:1]
        out += list(self.evidence_reads)
        return tuple(dict.fromkeys(out))

    @property
    def is_affine(self) -> bool:
        """The map is calibrated = A raw + c + B inputs (``affine``)."""
        return self.affine is not None

    @cached_property
    def affine(self) -> ca.Function | None:
        """p -> (A[3x3], c[3], B[3xk]) with calibrated = A raw + c + B inputs, derived from ``apply`` by
        CasADi (A, B its Jacobians, c its value at zero); None when apply is not affine in raw and inputs."""
        f = self.functions["apply"]
        raw, inp, p = (ca.SX.sym(n, f.sparsity_in(k)) for k, n in enumerate(("raw", "inputs", "p")))
        y = f(raw, inp, p)
        x = ca.vertcat(raw, inp)
        if not ca.is_linear(y, x):
            return None
        c = ca.substitute(y, x, ca.DM.zeros(x.shape))
        return ca.Function("affine", [p], [ca.jacobian(y, raw), c, ca.jacobian(y, inp)], ["p"], ["A", "c", "B"])

    def parameters(self, base: Parameters) -> Parameters:
        """Base parameters extended by each effect's parameters."""
        extra: list[Parameter] = []
        for e in self.effects:
            extra.extend(e.parameters(base))
        return base.extended(extra)

    def __getattr__(self, name: str) -> ca.Function:
        fns = object.__getattribute__(self, "functions")
        if name in fns:
            return fns[name]
        raise AttributeError(name)


def _build(effects: tuple[Effect, ...], names: tuple[str, ...]) -> dict:
    covs = tuple(sorted({c for e in effects for c in e.covariates}))
    raw = ca.SX.sym("raw", 3)
    cov = ca.SX.sym("cov", len(covs))
    p = ca.SX.sym("p", len(names))
    g = ca.SX.sym("g")
    pd = {n: p[i] for i, n in enumerate(names)}
    cd = {c: cov[i] for i, c in enumerate(covs)}
    s = [pd["s1"], pd["s2"], pd["s3"]]
    b = [pd["b1"], pd["b2"], pd["b3"]]
    for e in effects:
        s, b = e.shift_scale(s, b, cd, pd)
    m = [(raw[i] - s[i]) / b[i] for i in range(3)]  # Eq. (theModel)
    for e in reversed(effects):  # the sensor applies its specific-force terms in order: undo them in reverse
        m = e.correct(m, raw, cd, pd)
    m = ca.vertcat(*m)
    ang = [pd["phi"], pd["psi"], pd["theta"]]
    for e in effects:
        ang = e.angles(ang, cd, pd)
    phi, psi, theta = ang
    abar = ca.mtimes(tbar(phi, psi, theta), m)  # Lemma 2
    norm = ca.sqrt(ca.dot(m, abar))  # Proposition 2: |a|^2 = m^T G^-1 m
    L = frame_inverse_transpose(phi, psi, theta)
    a_orth = ca.mtimes(L, m)  # Theorem
    fns = {
        "covariates": covs,
        "measured": ca.Function("measured", [raw, cov, p], [m], ["raw", "cov", "p"], ["m"]),
        "accel": ca.Function("accel", [raw, cov, p], [a_orth], ["raw", "cov", "p"], ["a"]),
        "norm": ca.Function("norm", [raw, cov, p], [norm], ["raw", "cov", "p"], ["norm"]),
        "residual": ca.Function("residual", [raw, cov, p, g], [norm - g],
                                ["raw", "cov", "p", "g"], ["r"]),
    }
    if not effects:
        A = ca.SX(3, 3)  # structural zeros stay zeros
        for i in range(3):
            for j in range(i + 1):
                A[i, j] = L[i, j] / b[j]  # A = E^-T diag(1/b): lower triangular
        c = -ca.mtimes(A, ca.vertcat(*s))
        fns["linear_map"] = ca.Function("linear_map", [p], [A, c], ["p"], ["A", "c"])
        # Theorem: a = A (raw - s), the shift subtracted first (exact for raw near s, offset-binary counts)
        a_orth = ca.mtimes(A, raw - ca.vertcat(*s))
    fns["apply"] = ca.Function("apply", [raw, cov, p], [a_orth], ["raw", "inputs", "p"], ["calibrated"])
    return fns


@lru_cache(maxsize=64)
def _cached(effects_key: tuple, effects: tuple[Effect, ...]) -> SensorModel:

    names = BASE_NAMES + tuple(p.name for e in effects
                               for p in e.parameters(base_parameters([0, 0, 0], [1, 1, 1])))
    fns = _build(effects, names)
    return SensorModel(effects, names, fns.pop("covariates"), fns)


def build_model(effects: Sequence[Effect] = ()) -> SensorModel:
    """The sensor model with the given effects; symbolic functions are built once per effect set."""
    effects = tuple(effects)
    return _cached(tuple(e.key for e in effects), effects)
