"""The effect grammar: physical effects the paper's 9-parameter model leaves out.

Each effect is a small named unit (a subclass of :class:`imucal.model.sensor.Effect`) that adds
per-axis parameters and terms to the CasADi model, so a fit with effects is still one IPOPT
NLP. The paper's model, Eq. (theModel), is raw_i = s_i + b_i m_i. A *term* is a target times a
basis f of a covariate, named ``<target>_<basis>``:

  target  bias    s_i -> s_i + c_i f          c_i [raw / unit of f]
          scale   b_i -> b_i (1 + c_i f)      c_i [1 / unit of f]
  basis   temperature   p1(T) = T - T_ref                         degC
          temperature2  p2(T), orthogonal quadratic in T          degC^2
          temperature3  p3(T), orthogonal cubic in T              degC^3
          drift         t (seconds since the recording's start)   s
          drift2        p2(t), orthogonal quadratic in t          s^2
          warmup        1 - exp(-t / tau), tau fitted (> 0)       1
          step          H(t - t_s): 0 before t_s, 1 from it       1   (bias only; t_s given, not fitted)
          hysteresis    clip(dT/dt / r0, -1, 1): +1 warming,      1   (bias only; r0 fixed from the data)
                        -1 cooling, 0 at a steady temperature
  target  angle   phi -> phi + c f (psi, theta alike)     c [rad / unit of f]   (temperature only:
                  the angles between the axes, misalignment, linear in temperature)

and three terms in the specific force itself, u_i = m_i + ..., raw_i = s_i + b_i u_i:

  scale_nonlinearity        u_i = m_i + q_i m_i^2       q_i [1/(m/s^2)]
  scale_nonlinearity3       u_i = m_i + q_i m_i^3       q_i [1/(m/s^2)^2]
  cross_axis_nonlinearity   u_i = m_i + q_i m_j m_k     q_i [1/(m/s^2)], j, k the other two axes
  scale_asymmetry           u_i = m_i + a_i |m_i|       a_i [1]: scale b_i (1 + a_i) for m_i > 0, b_i (1 - a_i) below

Orders are not confounded: the polynomial bases are the monic orthogonal polynomials of the
recording's interval covariate values (three-term recurrence, p1 = x - a1,
p_{n+1} = (x - a_{n+1}) p_n - b_{n+1} p_{n-1}); their constants a1 (``_tref`` [degC] or ``_t0``
[s]), a2, b2, a3, b3 are *fixed* parameters stored with the calibration, set from the fitted data,
so the apply map needs nothing else. A quadratic term then leaves the linear coefficient what a
linear fit gives, and a cubic leaves both. (``bias_drift``/``scale_drift`` keep t from the
recording's start, and ``*_temperature`` keep T - T_ref with T_ref the mean interval
temperature, as before the grammar: files with those effects load and apply unchanged.)

The same term code serves the symbolic model (CasADi SX) and the simulator (numpy arrays):
``shift_scale`` uses arithmetic (and exp for the warm-up) only. Specific-force terms are written
forward in ``distort`` (what the sensor does) and inverted in ``correct`` (what the calibration
does): exactly for the quadratic and the asymmetry, by Newton steps for the cubic, by fixed-point steps
for the cross-axis term, each converged to rounding within the coefficient bounds (tested).

A bias step's time t_s is not a parameter the fit can move (the data hold no gradient in it between
two still intervals): discovery profiles it over the gaps between the intervals and a run file gives it
(``fit.initial.bias_step_t``), like a reference, but stored as the calibration's fixed parameter.
"""
from __future__ import annotations

import math
from dataclasses import replace
from typing import Mapping, Sequence

import casadi as ca
import numpy as np

from imucal.errors import ImucalError, short
from imucal.model.channels import temperature_rate
from imucal.model.geometry import frame_np
from imucal.model.sensor import Effect
from imucal.model.parameters import Parameter, Parameters

AXIS_NAMES = ("x", "y", "z")
#: Reference temperature [degC] used when no data set it (the simulator's default T_ref).
REFERENCE_TEMPERATURE = 25.0
#: Interval temperatures spanning less than this [degC] are "constant": no temperature effect.
MIN_TEMPERATURE_SPREAD = 0.5
#: Degrees of freedom an effect fit must keep (rows - free parameters), so its chi-square means something.
MIN_DOF = 3
#: Newton steps inverting u = m + q m^3, and fixed-point steps inverting the cross-axis term:
#: enough for rounding-level agreement within the coefficient bounds up to |m| = 2.5 g (tested).
CUBIC_NEWTON_STEPS = 6
CROSS_FIXED_POINT_STEPS = 32
#: Warm-up time constant: bounds [s] in a file or simulation; in a fit, bounds, start and scale
#: as fractions of the last interval time (beyond it 1 - exp(-t/tau) is a straight line, the drift).
WARMUP_TAU_BOUNDS = (1.0, 1.0e5)
WARMUP_TAU_FIT = (0.02, 1.0)
WARMUP_TAU_START = 0.2
#: A hysteresis's deadband r0 [degC/s]: a tenth of the rows' typical (median) rate of change, and at least
#: STEADY_RATE (0.5 degC/h, imucal.thermal's): below r0 the temperature counts as steady. (A share of the
#: fastest rate hid the cooling of a swing behind a fast warm-up's rate.)
HYSTERESIS_DEADBAND = 0.1
STEADY_RATE = 0.5 / 3600.0
#: The angles' names, the "axes" of an angle term (phi between x and y, psi x and z, theta y and z).
ANGLE_AXES = ("phi", "psi", "theta")


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
    #: the coefficient multiplies a raw-unit quantity (its scale is one g of raw output)
    raw_coefficient: bool = False
    #: static poses tell the axes apart (False: only the sum of the coefficients reaches |a|)
    axes_observable: bool = True
    #: the nested simpler term this one tends to (warm-up with tau beyond the recording -> drift)
    simpler: str | None = None
    #: the names of its "axes" 0, 1, 2 (the sensor axes; an angle term's are the angles)
    axis_names: tuple[str, str, str] = AXIS_NAMES

    def __init__(self, axes: Sequence[int] = (0, 1, 2)) -> None:
        super().__init__(axes)
        if not self.axes or any(a not in (0, 1, 2) for a in self.axes):
            raise ImucalError(f"axes {list(axes)} must be a non-empty subset of 0, 1, 2 (x, y, z)",
                              field=f"effects.{self.name}.axes", fix="e.g. axes (0, 2) for x and z")

    def coefficient(self, axis: int) -> str:
        return f"{self.name}_{self.axis_names[axis]}"

    @classmethod
    def axis_label(cls, axes: Sequence[int]) -> str:
        """The axes as written in a label: ``xy`` (sensor axes), ``phi,theta`` (angles)."""
        sep = "" if all(len(n) == 1 for n in cls.axis_names) else ","
        return sep.join(cls.axis_names[a] for a in axes)

    @property
    def coefficient_names(self) -> tuple[str, ...]:
        return tuple(self.coefficient(a) for a in self.axes)

    # -- parameters besides the per-axis coefficients ------------------------------------------
    @property
    def uses_tref(self) -> bool:
        return f"{self.name}_tref" in self.reference_names

    @property
    def tref_name(self) -> str:
        return f"{self.name}_tref"

    @property
    def reference_names(self) -> tuple[str, ...]:
        """Fixed parameters set from the data (reference temperature/time, basis constants)."""
        return tuple(p.name for p in self._extra(None) if p.fixed)

    @property
    def shape_names(self) -> tuple[str, ...]:
        """Free parameters shared by the axes (the warm-up's tau)."""
        return tuple(p.name for p in self._extra(None) if not p.fixed)

    @property
    def given_names(self) -> tuple[str, ...]:
        """Fixed parameters that no data set: a run file gives them (``fit.initial``), discovery profiles
        them (a bias step's time)."""
        return ()

    def profile_grid(self, covariates: Mapping[str, np.ndarray | None]) -> list[dict[str, float]]:
        """The values of ``given_names`` discovery tries for these rows (none: nothing to profile)."""
        return []

    def jumps(self, values: Mapping[str, float]) -> tuple[float, ...]:
        """Times [s] at which the effect jumps, given ``values`` of its parameters: a still interval
        that holds one holds two readings, and is cut there (imucal.pipeline)."""
        return ()

    def _extra(self, base: Parameters | None) -> list[Parameter]:
        return []

    def data_values(self, covariates: Mapping[str, np.ndarray | None]) -> dict[str, float]:
        """Reference constants (and shape starting values) from the interval covariates."""
        return {}

    def data_bounds(self, covariates: Mapping[str, np.ndarray | None]) -> dict[str, tuple[float, float, float]]:
        """(lower, upper, scale) of shape parameters for these data."""
        return {}

    def default_values(self) -> dict[str, float]:
        """Reference values when no data set them (the simulator's defaults)."""
        return {p.name: p.value for p in self._extra(None)}

    def _scale(self, base: Parameters | None, axis: int) -> float:
        if self.raw_coefficient and base is not None:
            return base[f"s{axis + 1}"].scale * self.typical
        return self.typical

    def _unit(self, base: Parameters | None) -> str:
        raw = (base["s1"].unit or "raw") if base is not None else "raw"
        return self.unit.replace("{raw}", raw)

    def start(self, base: Parameters, axis: int) -> float:
        """Starting value of a coefficient (0: no effect)."""
        return 0.0

    def parameters(self, base: Parameters) -> list[Parameter]:
        out = [Parameter(self.coefficient(a), self.start(base, a), lower=-self.bound, upper=self.bound,
                         unit=self._unit(base), scale=self._scale(base, a),
                         description=f"{self.meaning}, axis {AXIS_NAMES[a]}")
               for a in self.axes]
        return out + self._extra(base)

    def distort(self, m: list, p: Mapping) -> list:
        """Forward (sensor) form of a measured-value effect; identity for shift/scale effects."""
        return m

    def coefficient_for_size(self, size: float, b: float, span: float, gravity: float) -> float:
        """The coefficient whose largest change of a reading at 1 g over the recording is ``size`` [m/s^2].

        ``b`` is the axis scale [raw/(m/s^2)], ``span`` the range of the basis over the
        recording (unused by the specific-force terms). Used by the simulator and the studies.
        """
        raise NotImplementedError


# --- bases: functions of one covariate ---------------------------------------------------------
class Basis:
    """f(covariate) with its fixed constants; ``value`` works on CasADi SX and numpy alike."""

    name = ""
    covariate = ""
    unit = ""  #: unit of f
    typical = {"bias": 1.0, "scale": 1.0}  #: generous coefficient magnitudes (bias: in g of raw)
    bound = {"bias": math.inf, "scale": math.inf}

    def extra(self, prefix: str, base: Parameters | None) -> list[Parameter]:
        return []

    def value(self, x, p: Mapping, prefix: str):
        raise NotImplementedError

    def data_values(self, x: np.ndarray, prefix: str) -> dict[str, float]:
        return {}

    def data_bounds(self, x: np.ndarray | None, prefix: str) -> dict[str, tuple[float, float, float]]:
        return {}

    def given(self, prefix: str) -> tuple[str, ...]:
        """Fixed constants a run file gives (``AxisEffect.given_names``)."""
        return ()

    def grid(self, x: np.ndarray | None, prefix: str) -> list[dict[str, float]]:
        """Values of the given constants to profile over these rows (``AxisEffect.profile_grid``)."""
        return []

    def jumps(self, prefix: str, values: Mapping[str, float]) -> tuple[float, ...]:
        """Times at which f jumps (``AxisEffect.jumps``)."""
        return ()


def recurrence(x: np.ndarray, order: int, a1: float | None = None) -> tuple[list[float], list[float]]:
    """Constants (a_1..a_n, b_2..b_n) of the monic orthogonal polynomials over the points x.

    p_0 = 1, p_1 = x - a_1, p_{k+1} = (x - a_{k+1}) p_k - b_{k+1} p_{k-1} with
    a_{k+1} = <x p_k, p_k> / <p_k, p_k>, b_{k+1} = <p_k, p_k> / <p_{k-1}, p_{k-1}> (Forsythe).
    """
    x = np.asarray(x, float)
    a = [float(np.mean(x)) if a1 is None else float(a1)]
    b: list[float] = []
    prev, cur = np.ones_like(x), x - a[0]
    for _ in range(order - 1):
        nn = float(cur @ cur)
        a.append(float((x * cur) @ cur / nn) if nn > 0 else a[0])
        b.append(nn / float(prev @ prev) if nn > 0 else 0.0)
        prev, cur = cur, (x - a[-1]) * cur - b[-1] * prev
    return a, b


class Polynomial(Basis):
    """p_n of the orthogonal recurrence; order 1 is x - a1 (or x itself, without a reference)."""

    def __init__(self, name: str, covariate: str, order: int, unit: str, ref: str | None,
                 ref_default: float, typical: dict, bound: dict) -> None:
        self.name, self.covariate, self.order, self.unit = name, covariate, order, unit
        self.ref, self.ref_default, self.typical, self.bound = ref, ref_default, typical, bound
        self.cov_unit = unit.split("^")[0]

    def _names(self, prefix: str) -> list[tuple[str, str]]:
        out = [(f"{prefix}_{self.ref}", self.cov_unit)] if self.ref else []
        for k in range(2, self.order + 1):
            out += [(f"{prefix}_a{k}", self.cov_unit), (f"{prefix}_b{k}", f"{self.cov_unit}^2")]
        return out

    def extra(self, prefix, base):
        what = {"tref": "reference temperature", "t0": "reference time"}
        out = []
        for n, unit in self._names(prefix):
            key = n[len(prefix) + 1:]
            value = self.ref_default if key in ("tref", "t0") or key.startswith("a") else 0.0
            descr = (f"{what[key]} of {prefix} (fixed)" if key in what else
                     f"orthogonal-polynomial constant {key} of {prefix} (fixed)")
            out.append(Parameter(n, value, unit=unit, fixed=True, scale=max(abs(value), 1.0), description=descr))
        return out

    def value(self, x, p, prefix):
        if not self.ref:  # t from the recording's start (bias_drift, scale_drift)
            return x
        prev, cur = 1.0, x - p[f"{prefix}_{self.ref}"]
        for k in range(2, self.order + 1):  # p_k = (x - a_k) p_{k-1} - b_k p_{k-2}
            prev, cur = cur, (x - p[f"{prefix}_a{k}"]) * cur - p[f"{prefix}_b{k}"] * prev
        return cur

    def data_values(self, x, prefix):
        if not self.ref or x is None or len(x) == 0:
            return {}
        a1 = float(np.round(np.mean(x), 3)) if self.ref == "tref" else None  # T_ref as before the grammar
        a, b = recurrence(x, self.order, a1)
        out = {f"{prefix}_{self.ref}": a[0]}
        for k in range(2, self.order + 1):
            out[f"{prefix}_a{k}"] = a[k - 1]
            out[f"{prefix}_b{k}"] = b[k - 2]
        return out


class Warmup(Basis):
    """1 - exp(-t / tau): the settling of a part after power-on; tau [s] fitted, shared by the axes."""

    name, covariate, unit = "warmup", "time", ""
    typical = {"bias": 2e-3, "scale": 1e-3}
    bound = {"bias": math.inf, "scale": 0.1}

    def extra(self, prefix, base):
        lo, hi = WARMUP_TAU_BOUNDS
        return [Parameter(f"{prefix}_tau", 60.0, lower=lo, upper=hi, unit="s", scale=60.0,
                          description=f"time constant of {prefix}")]

    def value(self, x, p, prefix):
        e = -x / p[f"{prefix}_tau"]
        return 1 - (ca.exp(e) if isinstance(e, (ca.SX, ca.MX, ca.DM)) else np.exp(e))

    def data_values(self, x, prefix):
        return {f"{prefix}_tau": WARMUP_TAU_START * _t_end(x)} if x is not None and len(x) else {}

    def data_bounds(self, x: np.ndarray | None, prefix: str) -> dict[str, tuple[float, float, float]]:
        """tau within the recording (lower, upper, scale) [s]; the scale, the recording's length, is
        also what the observability check calls undetermined."""
        if x is None or not len(x):
            return {}
        t = _t_end(x)
        return {f"{prefix}_tau": (WARMUP_TAU_FIT[0] * t, WARMUP_TAU_FIT[1] * t, t)}


#: Still intervals a bias step needs on each side of it, so that each side holds a shift of its own.
STEP_MIN_SIDE = 3


class Step(Basis):
    """H(t - t_s): a bias that jumps at t_s [s] (the sensor knocked); t_s given (``_t``), not fitted."""

    name, covariate, unit = "step", "time", ""
    typical = {"bias": 2e-3}
    bound = {"bias": math.inf}

    def extra(self, prefix, base):
        return [Parameter(f"{prefix}_t", math.nan, unit="s", fixed=True, scale=60.0,
                          description=f"time of the step of {prefix} [s from the recording's start] (given)")]

    def value(self, x, p, prefix):
        return 1.0 * (x >= p[f"{prefix}_t"])  # H(t - t_s)

    def given(self, prefix):
        return (f"{prefix}_t",)

    def jumps(self, prefix, values):
        t = values.get(f"{prefix}_t", math.nan)
        return (float(t),) if math.isfinite(t) else ()

    def grid(self, x, prefix):
        """The midpoints between consecutive row times with ``STEP_MIN_SIDE`` rows on each side."""
        if x is None or len(x) < 2 * STEP_MIN_SIDE:
            return []
        ts = np.unique(np.asarray(x, float))
        mids = 0.5 * (ts[STEP_MIN_SIDE - 1:len(ts) - STEP_MIN_SIDE] + ts[STEP_MIN_SIDE:len(ts) - STEP_MIN_SIDE + 1])
        return [{f"{prefix}_t": float(m)} for m in mids]


class Hysteresis(Basis):
    """clip(dT/dt / r0, -1, 1): +1 while the temperature rises, -1 while it falls, 0 while it is steady
    (|dT/dt| < r0): a bias that differs between warming and cooling. r0 (``_r0``) is fixed from the data."""

    name, covariate, unit = "hysteresis", "temp_rate", ""
    typical = {"bias": 1e-3}
    bound = {"bias": math.inf}

    def extra(self, prefix, base):
        return [Parameter(f"{prefix}_r0", STEADY_RATE, unit="degC/s", fixed=True, scale=STEADY_RATE,
                          description=f"deadband of {prefix}: a temperature changing slower is steady (fixed)")]

    def value(self, x, p, prefix):
        v = x / p[f"{prefix}_r0"]
        if isinstance(v, (ca.SX, ca.MX, ca.DM)):
            return ca.fmin(ca.fmax(v, -1.0), 1.0)
        return np.clip(v, -1.0, 1.0)

    def data_values(self, x, prefix):
        if x is None or not len(x):
            return {}
        return {f"{prefix}_r0": max(STEADY_RATE, HYSTERESIS_DEADBAND * float(np.median(np.abs(x))))}


def _t_end(x: np.ndarray) -> float:
    lo, hi = WARMUP_TAU_BOUNDS
    return float(np.clip(np.max(x), lo / WARMUP_TAU_FIT[0], hi))


BASES: dict[str, Basis] = {b.name: b for b in (
    Polynomial("temperature", "temp", 1, "degC", "tref", REFERENCE_TEMPERATURE,
               {"bias": 1e-3, "scale": 1e-3, "angle": 1e-4}, {"bias": math.inf, "scale": 0.01, "angle": 0.01}),
    Polynomial("temperature2", "temp", 2, "degC^2", "tref", REFERENCE_TEMPERATURE,
               {"bias": 1e-4, "scale": 1e-4}, {"bias": math.inf, "scale": 1e-3}),
    Polynomial("temperature3", "temp", 3, "degC^3", "tref", REFERENCE_TEMPERATURE,
               {"bias": 1e-5, "scale": 1e-5}, {"bias": math.inf, "scale": 1e-4}),
    Polynomial("drift", "time", 1, "s", None, 0.0, {"bias": 1e-4, "scale": 1e-5}, {"bias": math.inf, "scale": 1e-3}),
    Polynomial("drift2", "time", 2, "s^2", "t0", 0.0, {"bias": 1e-6, "scale": 1e-7},
               {"bias": math.inf, "scale": 1e-5}),
    Warmup(),
    Step(),
    Hysteresis(),
)}

_MEANING = {"bias": "change of the shift s_i per unit of", "scale": "relative change of the scale b_i per unit of",
            "angle": "change of the angle between two axes [rad] per unit of"}


class Term(AxisEffect):
    """target x basis: bias s_i + c_i f, or scale b_i (1 + c_i f) (see the module's table)."""

    target = "bias"
    basis: Basis = BASES["temperature"]

    def _extra(self, base):
        return self.basis.extra(self.name, base)

    def _rows(self, covariates: Mapping[str, np.ndarray | None]) -> np.ndarray | None:
        """The basis's covariate over the rows (temp_rate derived from temp and time)."""
        key = self.basis.covariate
        if covariates.get(key) is not None:
            return np.asarray(covariates[key], float)
        if key == "temp_rate" and covariates.get("temp") is not None and covariates.get("time") is not None:
            return temperature_rate(covariates["time"], covariates["temp"])
        return None

    def data_values(self, covariates):
        return self.basis.data_values(self._rows(covariates), self.name)

    def data_bounds(self, covariates):
        return self.basis.data_bounds(self._rows(covariates), self.name)

    @property
    def given_names(self):
        return self.basis.given(self.name)

    def profile_grid(self, covariates):
        return self.basis.grid(self._rows(covariates), self.name)

    def jumps(self, values):
        return self.basis.jumps(self.name, values)

    def start(self, base, axis):
        # A warm-up amplitude starts at its scale: at 0 its tau would not enter the model, and the
        # observability check (and IPOPT's first step) would see no tau at all.
        return self._scale(base, axis) if isinstance(self.basis, Warmup) else 0.0

    def shift_scale(self, s, b, cov, p):
        if self.target == "angle":
            return s, b
        f = self.basis.value(cov[self.basis.covariate], p, self.name)
        s, b = list(s), list(b)
        for a in self.axes:
            c = p[self.coefficient(a)]
            if self.target == "bias":
                s[a] = s[a] + c * f  # s_i + c_i f
            else:
                b[a] = b[a] * (1 + c * f)  # b_i (1 + c_i f)
        return s, b

    def base_parameter(self, axis: int) -> str:
        """The paper's parameter the term modulates on ``axis``: s_i, b_i, or the angle."""
        return {"bias": f"s{axis + 1}", "scale": f"b{axis + 1}", "angle": ANGLE_AXES[axis]}[self.target]

    def angles(self, ang, cov, p):
        if self.target != "angle":
            return ang
        f = self.basis.value(cov[self.basis.covariate], p, self.name)
        ang = list(ang)
        for a in self.axes:
            ang[a] = ang[a] + p[self.coefficient(a)] * f  # phi + c f: the Gram matrix of Eq. (eq:12) at T
        return ang

    def coefficient_for_size(self, size, b, span, gravity):
        # an angle moved by c span turns a reading at 1 g by about g c span, as a scale c span does
        return size * b / span if self.target == "bias" else size / (gravity * span)


_TARGET_UNIT = {"bias": "{raw}", "scale": "1", "angle": "rad"}


def _term(target: str, basis: Basis) -> type[Term]:
    unit = basis.unit and ("/" + basis.unit)
    return type("".join(w.capitalize() for w in f"{target}_{basis.name}".split("_")), (Term,), {
        "name": f"{target}_{basis.name}", "target": target, "basis": basis,
        "axis_names": ANGLE_AXES if target == "angle" else AXIS_NAMES,
        "unit": _TARGET_UNIT[target] + unit,
        "covariates": (basis.covariate,), "typical": basis.typical[target], "bound": basis.bound[target], "raw_coefficient": target == "bias",
        "meaning": f"{_MEANING[target]} {basis.name}",
        "simpler": f"{target}_drift" if isinstance(basis, Warmup) else None,
        "__doc__": f"{target} x {basis.name}: see imucal.model.effects.", "__module__": __name__})


BiasTemperature, ScaleTemperature = _term("bias", BASES["temperature"]), _term("scale", BASES["temperature"])
BiasDrift, ScaleDrift = _term("bias", BASES["drift"]), _term("scale", BASES["drift"])


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

    def coefficient_for_size(self, size, b, span, gravity):
        return size / gravity**2


class ScaleNonlinearity3(AxisEffect):
    """Cubic (odd-order) term in each axis's own reading: raw_i = s_i + b_i (m_i + q_i m_i^3).

    Inverted by Newton's method from m = u: m <- m - (m + q m^3 - u) / (1 + 3 q m^2); the
    bound keeps 1 + 3 q m^2 > 0.4 up to |m| = 2.5 g, where the steps converge quadratically.
    """

    name = "scale_nonlinearity3"
    unit = "1/(m/s^2)^2"
    typical = 1e-4  # 1 % of the reading at 1 g
    bound = 3e-4  # 3 % at 1 g
    meaning = "cubic coefficient of the axis's own reading"

    def correct(self, m, raw, cov, p):
        m = list(m)
        for a in self.axes:
            q, u = p[self.coefficient(a)], m[a]
            x = u
            for _ in range(CUBIC_NEWTON_STEPS):
                x = x - (x + q * x * x * x - u) / (1 + 3 * q * x * x)
            m[a] = x
        return m

    def distort(self, m, p):
        m = list(m)
        for a in self.axes:
            m[a] = m[a] + p[self.coefficient(a)] * m[a] * m[a] * m[a]  # u = m + q m^3
        return m

    def coefficient_for_size(self, size, b, span, gravity):
        return size / gravity**3


class CrossAxisNonlinearity(AxisEffect):
    """Axis i responds to the product of the other two: raw_i = s_i + b_i (m_i + q_i m_j m_k).

    Inverted by fixed-point steps m_i <- u_i - q_i m_j m_k from m = u (a contraction with factor
    below 0.3 inside the bound up to |m| = 2.5 g: CROSS_FIXED_POINT_STEPS reach rounding).

    Observability: to first order |u|^2 = |m|^2 + 2 (q_x + q_y + q_z) m_x m_y m_z, so a
    calibration from |a| alone determines the sum of the coefficients, not which axis carries it
    (the axis is a convention; discovery fits one axis and says so). To second order |u|^2 gains
    q_i^2 (m_j m_k)^2 per axis, which tells the axes apart once the coefficients are large (two that
    nearly cancel in the sum, say): discovery then tries two and three axes and reports the sum, the
    observable combination, beside them.
    """

    name = "cross_axis_nonlinearity"
    axes_observable = False
    unit = "1/(m/s^2)"
    typical = 1e-3  # 0.5 % of g at 1 g split between two axes
    bound = 6e-3  # 3 % of g at 1 g; the fixed-point steps contract by < 0.3 up to |m| = 2.5 g
    meaning = "coefficient of the product of the other two axes' readings"

    @staticmethod
    def _others(a: int) -> tuple[int, int]:
        return tuple(k for k in range(3) if k != a)  # type: ignore[return-value]

    def correct(self, m, raw, cov, p):
        u = list(m)
        x = list(m)
        for _ in range(CROSS_FIXED_POINT_STEPS):
            nxt = list(x)
            for a in self.axes:
                j, k = self._others(a)
                nxt[a] = u[a] - p[self.coefficient(a)] * x[j] * x[k]
            x = nxt
        return x

    def distort(self, m, p):
        out = list(m)
        for a in self.axes:
            j, k = self._others(a)
            out[a] = m[a] + p[self.coefficient(a)] * m[j] * m[k]  # u_i = m_i + q_i m_j m_k
        return out

    def coefficient_for_size(self, size, b, span, gravity):
        return size / (gravity**2 / 2)  # |m_j m_k| <= g^2 / 2 at 1 g


class ScaleAsymmetry(AxisEffect):
    """A different scale for positive and negative inputs: raw_i = s_i + b_i (m_i + a_i |m_i|), i.e. the
    scale b_i (1 + a_i) for m_i > 0 and b_i (1 - a_i) for m_i < 0 (very common in MEMS).

    The calibration inverts it exactly: with u = (raw_i - s_i)/b_i (Eq. theModel), sign(u) = sign(m)
    for |a| < 1, so m = u / (1 + a sign(u)) = (u - a |u|) / (1 - a^2).
    """

    name = "scale_asymmetry"
    unit = "1"
    typical = 2e-3  # 0.2 % between the two halves of the range
    bound = 0.05  # keeps both half-scales within 5 % of b_i
    meaning = "half the relative difference of the scale for positive and negative readings"

    def correct(self, m, raw, cov, p):
        m = list(m)
        for a in self.axes:
            q = p[self.coefficient(a)]
            m[a] = (m[a] - q * abs(m[a])) / (1 - q * q)  # exact inverse of u = m + q |m|
        return m

    def distort(self, m, p):
        m = list(m)
        for a in self.axes:
            m[a] = m[a] + p[self.coefficient(a)] * abs(m[a])  # u = m + q |m|
        return m

    def coefficient_for_size(self, size, b, span, gravity):
        return size / gravity  # a reading at 1 g moves by a g


#: Effect name -> class. Order = the order candidates are listed in reports (today's five first).
EFFECTS: dict[str, type[AxisEffect]] = {cls.name: cls for cls in (
    BiasTemperature, ScaleTemperature, BiasDrift, ScaleDrift, ScaleNonlinearity,
    *(_term(t, BASES[b]) for b in ("temperature2", "temperature3", "drift2", "warmup") for t in ("bias", "scale")),
    ScaleNonlinearity3, CrossAxisNonlinearity, ScaleAsymmetry, _term("bias", BASES["step"]),
    _term("bias", BASES["hysteresis"]), _term("angle", BASES["temperature"]))}
#: The five effects of the library before the grammar.
CLASSIC = ("bias_temperature", "scale_temperature", "bias_drift", "scale_drift", "scale_nonlinearity")


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
        if any(c in ("temp", "temp_rate") for c in e.covariates):
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
        if "temp_rate" in e.covariates:
            _check_both_ways(e, covariates, source)
    if effects and n_rows - n_free < MIN_DOF:
        raise ImucalError(f"{n_rows} static intervals are too few for {n_free} free parameters with effects "
                          f"(need at least {n_free + MIN_DOF})", file=source, field="intervals",
                          fix="record more static orientations or drop effects")


#: Rows a hysteresis needs warming, and as many cooling, so that its two offsets are told from the shift.
MIN_ROWS_EACH_WAY = 2


def _check_both_ways(e: Effect, covariates: Mapping[str, np.ndarray | None], source: str | None) -> None:
    """A hysteresis needs rows where the temperature rises and rows where it falls (faster than r0)."""
    h = e.basis.value(e._rows(covariates), e.data_values(covariates), e.name)
    up, down = int(np.sum(h >= 1.0)), int(np.sum(h <= -1.0))
    if min(up, down) < MIN_ROWS_EACH_WAY:
        raise ImucalError(f"effect {e.name} needs the temperature to rise and to fall, but {up} intervals warm and "
                          f"{down} cool (at least {MIN_ROWS_EACH_WAY} each)", file=source, field="fit.effects",
                          fix="record while the sensor warms up and cools down, or drop the hysteresis")


def given_names(effects: Sequence[Effect]) -> tuple[str, ...]:
    """The fixed parameters of ``effects`` that a run file gives (``AxisEffect.given_names``)."""
    return tuple(n for e in effects if isinstance(e, AxisEffect) for n in e.given_names)


def check_given(effects: Sequence[Effect], params: Parameters, source: str | None = None) -> None:
    """Refuse an effect whose given parameter (a bias step's time) the run file did not give."""
    for n in given_names(effects):
        if not math.isfinite(params[n].value):
            raise ImucalError(f"{n} is not given: the effect needs the time of its step", file=source,
                              field=f"fit.initial.{n}", fix=f"give fit.initial.{n} in {params[n].unit} from the "
                              "recording's start (imucal discover finds it)")


def reference_values(effects: Sequence[Effect], covariates: Mapping[str, np.ndarray | None]
                     ) -> dict[str, float]:
    """Parameters set from the data: fixed references (T_ref = mean interval temperature [degC],
    the orthogonal-polynomial constants) and the warm-up's starting tau."""
    out: dict[str, float] = {}
    for e in effects:
        if isinstance(e, AxisEffect):
            out.update(e.data_values(covariates))
    return out


def fit_to_data(effects: Sequence[Effect], params: Parameters, covariates: Mapping[str, np.ndarray | None]
                ) -> Parameters:
    """Reference values, shape starts and shape bounds (the warm-up's tau) from the data."""
    bounds: dict[str, tuple[float, float, float]] = {}
    for e in effects:
        if isinstance(e, AxisEffect):
            bounds.update(e.data_bounds(covariates))
    if bounds:
        params = Parameters(replace(p, lower=bounds[n][0], upper=bounds[n][1], scale=bounds[n][2])
                            if n in bounds else p for n, p in params.items())
    values = reference_values(effects, covariates)
    return params.with_values({n: float(np.clip(v, params[n].lower, params[n].upper)) for n, v in values.items()})


def prepare_parameters(effects: Sequence[Effect], params: Parameters,
                       covariates: Mapping[str, np.ndarray | None], n_rows: int,
                       source: str | None = None) -> Parameters:
    """Check that the data determine the effects, then set their reference and shape parameters."""
    if not effects:
        return params
    check_effects(effects, covariates, n_rows, len(params.free_names), source)
    return fit_to_data(effects, params, covariates)


# --- the simulator's side ---------------------------------------------------------------------
def effects_from_coefficients(spec: Mapping[str, Mapping[str, float]]) -> list[AxisEffect]:
    """Effects of a simulated sensor: effect name -> {parameter name: value}; axes from the names.

    Besides the coefficients an effect may give its references (``_tref``, ``_t0``, ``_a2`` ...;
    default: plain powers about 25 degC or the recording's start) and the warm-up's ``_tau``.
    """
    out = []
    for name, coeffs in spec.items():
        if name not in EFFECTS:
            raise ImucalError(f"unknown effect {short(name)}", field="sensor.effects",
                              fix=f"choose from {', '.join(EFFECTS)}")
        proto = EFFECTS[name]((0, 1, 2))
        allowed = set(proto.coefficient_names) | set(proto.reference_names) | set(proto.shape_names)
        coeffs = dict(coeffs or {})
        bad = sorted(set(coeffs) - allowed)
        if bad:
            raise ImucalError(f"unknown parameter {short(bad[0])} of effect {name}", field=f"sensor.effects.{name}",
                              fix=f"use {', '.join(sorted(allowed))}")
        axes = tuple(a for a in range(3) if proto.coefficient(a) in coeffs)
        if not axes:
            raise ImucalError(f"effect {name} has no coefficient", field=f"sensor.effects.{name}",
                              fix=f"give at least one of {', '.join(proto.coefficient_names)}")
        missing = [n for n in proto.given_names if n not in coeffs]
        if missing:
            raise ImucalError(f"effect {name} needs {missing[0]}", field=f"sensor.effects.{name}",
                              fix=f"give {missing[0]} (the time of the step [s from the start])")
        lo, hi = WARMUP_TAU_BOUNDS
        for n in proto.shape_names:
            if n in coeffs and not lo <= coeffs[n] <= hi:
                raise ImucalError(f"{short(coeffs[n])} s is outside [{lo:g}, {hi:g}] s",
                                  field=f"sensor.effects.{name}.{n}", fix=f"give {n} in seconds from {lo:g} to {hi:g}")
        out.append(EFFECTS[name](axes))
    return out


def _covariates(effects: Sequence[AxisEffect], t: np.ndarray, temp: np.ndarray | None) -> dict[str, np.ndarray]:
    """The simulated samples' covariates (temp_rate as the calibration derives it, imucal.model.channels)."""
    cov: dict[str, np.ndarray] = {"time": np.asarray(t, float)}
    if any(c in ("temp", "temp_rate") for e in effects for c in e.covariates):
        if temp is None:
            raise ImucalError("the sensor has a temperature effect but the simulation has no temperature profile",
                              field="temperature", fix="add a temperature: section or drop the effect")
        cov["temp"] = np.asarray(temp, float)
        cov["temp_rate"] = temperature_rate(cov["time"], cov["temp"])
    return cov


def simulate_effects(sensor, a: np.ndarray, t: np.ndarray, temp: np.ndarray | None) -> np.ndarray:
    """Noise-free raw readings of ``sensor`` (a SensorSpec) with its effects' forward terms, for the true
    specific force ``a`` (N x 3, frame f).

    raw_i = s_i(T, t) + b_i(T, t) * u_i with u = distort(m) and m_i = e_i(T) . a (Lemma 1, the axes at the
    angles the effects give each sample): the sensor's forward model; several specific-force terms
    compose in the model's order, and the model inverts them in reverse.
    """
    effects = effects_from_coefficients(sensor.effects)
    p: dict[str, float] = {}
    for e in effects:
        p.update(e.default_values())
    p.update(sensor.values())
    n = a.shape[0]
    cov = _covariates(effects, t, temp)
    ang = [np.full(n, float(p[k])) for k in ("phi", "psi", "theta")]
    for e in effects:
        ang = e.angles(ang, cov, p)
    E = frame_np(np.column_stack(ang))  # (N, 3, 3), columns e_i (Eq. eq:125)
    m = np.einsum("nj,nji->ni", np.asarray(a, float), E)
    s = [np.full(n, float(sensor.s[i])) for i in range(3)]
    b = [np.full(n, float(sensor.b[i])) for i in range(3)]
    for e in effects:
        s, b = e.shift_scale(s, b, cov, p)
    u = [m[:, i] for i in range(3)]
    for e in _model_order(effects):
        u = e.distort(u, p)
    return np.column_stack([s[i] + b[i] * u[i] for i in range(3)])


def _model_order(effects: Sequence[AxisEffect]) -> list[AxisEffect]:
    order = {n: i for i, n in enumerate(EFFECTS)}
    return sorted(effects, key=lambda e: order[e.name])
