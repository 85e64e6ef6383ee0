"""The effect library: physical effects the paper's 9-parameter model leaves out.

Each effect is a small named unit (a subclass of :class:`imucal.model.sensor.Effect`) that adds
per-axis parameters and terms to the CasADi model, so a fit with effects is still one IPOPT
NLP. The paper's model, Eq. (theModel), is raw_i = s_i + b_i m_i; the effects make the shift
s_i or the scale b_i depend on a covariate, or make the reading nonlinear in m_i:

  bias_temperature    s_i -> s_i + k_i (T - T_ref)             k_i [raw/degC]
  scale_temperature   b_i -> b_i (1 + c_i (T - T_ref))         c_i [1/degC]
  bias_drift          s_i -> s_i + d_i t                       d_i [raw/s], t from the recording start
  scale_drift         b_i -> b_i (1 + e_i t)                   e_i [1/s]
  scale_nonlinearity  raw_i = s_i + b_i (m_i + q_i m_i^2)      q_i [1/(m/s^2)]

T_ref is a *fixed* parameter stored with the calibration (set to the mean interval temperature
of the fitted data, so that s_i and b_i are the values at the data's typical temperature and
the coefficients are well conditioned); the apply map needs nothing else. Time is seconds since
the recording's first sample, so s_i, b_i are the values at the start of the recording.

The same term code serves the symbolic model (CasADi SX) and the simulator (numpy arrays):
``shift_scale`` uses arithmetic only. The nonlinearity is written forward in ``distort`` (what
the sensor does) and inverted exactly in ``correct`` (what the calibration does).
"""
from __future__ import annotations

import math
from typing import Mapping, Sequence

import numpy as np

from imucal.errors import ImucalError, short
from imucal.model.sensor import Effect
from imucal.model.parameters import Parameter, Parameters

AXIS_NAMES = ("x", "y", "z")
#: Reference temperature [degC] used when no data set it (the simulator's default T_ref).
REFERENCE_TEMPERATURE = 25.0
#: Interval temperatures spanning less than this [degC] are "constant": no temperature effect.
MIN_TEMPERATURE_SPREAD = 0.5
#: Degrees of freedom an effect fit must keep (rows - free parameters), so its chi-square means something.
MIN_DOF = 3


class AxisEffect(Effect):
    """An effect with one coefficient per listed axis (0 = x, 1 = y, 2 = z)."""

    #: unit of the coefficient; "{raw}" is replaced by the raw unit of the shifts
    unit: str = ""
    #: A generous magnitude of the coefficient (the large end of what MEMS parts show), used as the
    #: parameter's scale: IPOPT's steps are bounded by it, and the observability check calls the
    #: coefficient undetermined when the poses predict a standard error above it.
    typical: float = 1.0
    #: physical meaning, for the description and the docs
    meaning: str = ""
    #: bounds on the coefficient (keep the scale positive, the inverse defined)
    bound: float = math.inf
    #: the effect needs a reference temperature parameter
    uses_tref: bool = False

    def __init__(self, axes: Sequence[int] = (0, 1, 2)) -> None:
        super().__init__(axes)
        if not self.axes or any(a not in (0, 1, 2) for a in self.axes):
            raise ImucalError(f"axes {list(axes)} must be a non-empty subset of 0, 1, 2 (x, y, z)",
                              field=f"effects.{self.name}.axes")

    def coefficient(self, axis: int) -> str:
        return f"{self.name}_{AXIS_NAMES[axis]}"

    @property
    def coefficient_names(self) -> tuple[str, ...]:
        return tuple(self.coefficient(a) for a in self.axes)

    @property
    def tref_name(self) -> str:
        return f"{self.name}_tref"

    def _scale(self, base: Parameters, axis: int) -> float:
        return self.typical

    def _unit(self, base: Parameters) -> str:
        return self.unit.replace("{raw}", base["s1"].unit or "raw")

    def parameters(self, base: Parameters) -> list[Parameter]:
        out = [Parameter(self.coefficient(a), 0.0, lower=-self.bound, upper=self.bound,
                         unit=self._unit(base), scale=self._scale(base, a),
                         description=f"{self.meaning}, axis {AXIS_NAMES[a]}")
               for a in self.axes]
        if self.uses_tref:
            out.append(Parameter(self.tref_name, REFERENCE_TEMPERATURE, unit="degC", fixed=True,
                                 scale=REFERENCE_TEMPERATURE,
                                 description=f"reference temperature of {self.name} (fixed)"))
        return out

    def distort(self, m: list, p: Mapping) -> list:
        """Forward (sensor) form of a measured-value effect; identity for shift/scale effects."""
        return m

    def coefficient_for_size(self, size: float, b: float, temp_span: float, duration: float,
                             gravity: float) -> float:
        """The coefficient whose largest change of a reading at 1 g is ``size`` [m/s^2].

        ``b`` is the axis scale [raw/(m/s^2)], ``temp_span`` the temperature range [degC] and
        ``duration`` the recording's length [s]. Used by the simulator and the detection study.
        """
        raise NotImplementedError


class BiasTemperature(AxisEffect):
    """Bias linear in temperature: s_i(T) = s_i + k_i (T - T_ref)."""

    name = "bias_temperature"
    covariates = ("temp",)
    unit = "{raw}/degC"
    typical = 1e-3  # x one g in raw units: 1 mg/degC
    meaning = "change of the shift s_i per degC"
    uses_tref = True

    def _scale(self, base: Parameters, axis: int) -> float:
        return base[f"s{axis + 1}"].scale * self.typical

    def shift_scale(self, s, b, cov, p):
        s = list(s)
        for a in self.axes:
            s[a] = s[a] + p[self.coefficient(a)] * (cov["temp"] - p[self.tref_name])  # s_i + k_i (T - T_ref)
        return s, b

    def coefficient_for_size(self, size, b, temp_span, duration, gravity):
        return size * b / temp_span


class ScaleTemperature(AxisEffect):
    """Scale linear in temperature: b_i(T) = b_i (1 + c_i (T - T_ref))."""

    name = "scale_temperature"
    covariates = ("temp",)
    unit = "1/degC"
    typical = 1e-3  # 0.1 %/degC
    bound = 0.01  # 1 %/degC: far beyond any MEMS part, keeps b_i(T) > 0
    meaning = "relative change of the scale b_i per degC"
    uses_tref = True

    def shift_scale(self, s, b, cov, p):
        b = list(b)
        for a in self.axes:
            b[a] = b[a] * (1 + p[self.coefficient(a)] * (cov["temp"] - p[self.tref_name]))  # b_i (1 + c_i dT)
        return s, b

    def coefficient_for_size(self, size, b, temp_span, duration, gravity):
        return size / (gravity * temp_span)


class BiasDrift(AxisEffect):
    """Bias linear in time: s_i(t) = s_i + d_i t, t in seconds since the recording's start."""

    name = "bias_drift"
    covariates = ("time",)
    unit = "{raw}/s"
    typical = 1e-4  # x one g in raw units: 0.1 mg/s
    meaning = "change of the shift s_i per second"

    def _scale(self, base: Parameters, axis: int) -> float:
        return base[f"s{axis + 1}"].scale * self.typical

    def shift_scale(self, s, b, cov, p):
        s = list(s)
        for a in self.axes:
            s[a] = s[a] + p[self.coefficient(a)] * cov["time"]  # s_i + d_i t
        return s, b

    def coefficient_for_size(self, size, b, temp_span, duration, gravity):
        return size * b / duration


class ScaleDrift(AxisEffect):
    """Scale linear in time: b_i(t) = b_i (1 + e_i t)."""

    name = "scale_drift"
    covariates = ("time",)
    unit = "1/s"
    typical = 1e-5  # 10 ppm/s
    bound = 1e-3  # 0.1 %/s
    meaning = "relative change of the scale b_i per second"

    def shift_scale(self, s, b, cov, p):
        b = list(b)
        for a in self.axes:
            b[a] = b[a] * (1 + p[self.coefficient(a)] * cov["time"])  # b_i (1 + e_i t)
        return s, b

    def coefficient_for_size(self, size, b, temp_span, duration, gravity):
        return size / (gravity * duration)


class ScaleNonlinearity(AxisEffect):
    """Quadratic term in each axis's own reading: raw_i = s_i + b_i (m_i + q_i m_i^2).

    The calibration inverts it exactly: with u = (raw_i - s_i)/b_i (Eq. theModel),
    m_i = 2 u / (1 + sqrt(1 + 4 q_i u)), the root of q m^2 + m - u = 0 that tends to u as q -> 0.
    """

    name = "scale_nonlinearity"
    unit = "1/(m/s^2)"
    typical = 1e-3  # 1 % of the reading at 1 g
    bound = 0.01  # keeps 1 + 4 q u > 0 up to |u| = 2.5 g
    meaning = "quadratic coefficient of the axis's own reading"

    def correct(self, m, raw, cov, p):
        m = list(m)
        for a in self.axes:
            q = p[self.coefficient(a)]
            m[a] = 2 * m[a] / (1 + (1 + 4 * q * m[a]) ** 0.5)  # exact inverse of u = m + q m^2
        return m

    def distort(self, m, p):
        m = list(m)
        for a in self.axes:
            m[a] = m[a] + p[self.coefficient(a)] * m[a] ** 2  # u = m + q m^2
        return m

    def coefficient_for_size(self, size, b, temp_span, duration, gravity):
        return size / gravity**2


#: Effect name -> class. Order = the order candidates are listed in reports.
EFFECTS: dict[str, type[AxisEffect]] = {
    cls.name: cls for cls in (BiasTemperature, ScaleTemperature, BiasDrift, ScaleDrift, ScaleNonlinearity)
}


def make_effect(name: str, axes: Sequence[int] = (0, 1, 2)) -> AxisEffect:
    """The effect ``name`` on ``axes`` (0 = x, 1 = y, 2 = z)."""
    if name not in EFFECTS:
        raise ImucalError(f"unknown effect {short(name)}", field="effects",
                          fix=f"choose from {', '.join(EFFECTS)}")
    return EFFECTS[name](axes)


# --- data checks and reference values ---------------------------------------------------------
def temperature_spread(temp: np.ndarray | None) -> float:
    """Range of the interval mean temperatures [degC]; 0 without a temperature column."""
    if temp is None or len(temp) == 0:
        return 0.0
    return float(np.max(temp) - np.min(temp))


def check_effects(effects: Sequence[Effect], covariates: Mapping[str, np.ndarray | None], n_rows: int,
                  n_free: int, source: str | None = None) -> None:
    """Refuse effects the data cannot determine, with a one-line ImucalError.

    ``covariates`` holds the per-row (interval-mean) covariates; ``n_free`` the free parameters
    of the whole model (base + effects).
    """
    for e in effects:
        if "temp" in e.covariates:
            temp = covariates.get("temp")
            if temp is None:
                raise ImucalError(f"effect {e.name} needs temperature but the data have no temp column",
                                  file=source, field="data.columns.temp",
                                  fix="add a temperature column (deg C) or drop the temperature effect")
            spread = temperature_spread(np.asarray(temp, float))
            if spread < MIN_TEMPERATURE_SPREAD:
                raise ImucalError(f"effect {e.name} needs a temperature change but the temperature is constant "
                                  f"(interval means span {spread:.3g} degC < {MIN_TEMPERATURE_SPREAD} degC)",
                                  file=source, field="fit.effects",
                                  fix="record while the sensor warms up or cools down, or drop the temperature effect")
    if effects and n_rows - n_free < MIN_DOF:
        raise ImucalError(f"{n_rows} static intervals are too few for {n_free} free parameters with effects "
                          f"(need at least {n_free + MIN_DOF})", file=source, field="intervals",
                          fix="record more static orientations or drop effects")


def reference_values(effects: Sequence[Effect], covariates: Mapping[str, np.ndarray | None]
                     ) -> dict[str, float]:
    """Fixed reference parameters from the data: T_ref = mean interval temperature [degC]."""
    out: dict[str, float] = {}
    temp = covariates.get("temp")
    for e in effects:
        if getattr(e, "uses_tref", False) and temp is not None and len(temp):
            out[e.tref_name] = float(np.round(np.mean(temp), 3))
    return out


def prepare_parameters(effects: Sequence[Effect], params: Parameters,
                       covariates: Mapping[str, np.ndarray | None], n_rows: int,
                       source: str | None = None) -> Parameters:
    """Check that the data determine the effects, then set their reference parameters."""
    if not effects:
        return params
    check_effects(effects, covariates, n_rows, len(params.free_names), source)
    return params.with_values(reference_values(effects, covariates))


# --- the simulator's side ---------------------------------------------------------------------
def effects_from_coefficients(spec: Mapping[str, Mapping[str, float]]) -> list[AxisEffect]:
    """Effects of a simulated sensor: effect name -> {parameter name: value}; axes from the names."""
    out = []
    for name, coeffs in spec.items():
        if name not in EFFECTS:
            raise ImucalError(f"unknown effect {short(name)}", field="sensor.effects",
                              fix=f"choose from {', '.join(EFFECTS)}")
        proto = EFFECTS[name]((0, 1, 2))
        allowed = set(proto.coefficient_names) | ({proto.tref_name} if proto.uses_tref else set())
        coeffs = dict(coeffs or {})
        bad = sorted(set(coeffs) - allowed)
        if bad:
            raise ImucalError(f"unknown parameter {short(bad[0])} of effect {name}", field=f"sensor.effects.{name}",
                              fix=f"use {', '.join(sorted(allowed))}")
        axes = tuple(a for a in range(3) if proto.coefficient(a) in coeffs)
        if not axes:
            raise ImucalError(f"effect {name} has no coefficient", field=f"sensor.effects.{name}",
                              fix=f"give at least one of {', '.join(proto.coefficient_names)}")
        out.append(EFFECTS[name](axes))
    return out


def simulate_effects(sensor, m: np.ndarray, t: np.ndarray, temp: np.ndarray | None,
                     raw: np.ndarray) -> np.ndarray:
    """Noise-free raw readings of ``sensor`` (a SensorSpec) with its effects' forward terms.

    ``raw`` is the paper's s + b m (Eq. theModel) without effects; it is recomputed here as
    raw_i = s_i(T, t) + b_i(T, t) * u_i with u = distort(m) (the sensor's forward model).
    """
    effects = effects_from_coefficients(sensor.effects)
    p = {e.tref_name: REFERENCE_TEMPERATURE for e in effects if e.uses_tref}
    p.update(sensor.values())
    n = m.shape[0]
    cov: dict[str, np.ndarray] = {"time": np.asarray(t, float)}
    if any("temp" in e.covariates for e in effects):
        if temp is None:
            raise ImucalError("the sensor has a temperature effect but the simulation has no temperature profile",
                              field="temperature", fix="add a temperature: section or drop the effect")
        cov["temp"] = np.asarray(temp, float)
    s = [np.full(n, float(sensor.s[i])) for i in range(3)]
    b = [np.full(n, float(sensor.b[i])) for i in range(3)]
    for e in effects:
        s, b = e.shift_scale(s, b, cov, p)
    u = [m[:, i] for i in range(3)]
    for e in effects:
        u = e.distort(u, p)
    return np.column_stack([s[i] + b[i] * u[i] for i in range(3)])
