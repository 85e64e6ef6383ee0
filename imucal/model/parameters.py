"""Named model parameters: value, bounds, fixed/free, unit, scale (in the manner of lmfit)."""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Iterable, Iterator, Mapping

from imucal.constants import DEFAULT_ANGLE_TOL, RIGHT_ANGLE
from imucal.errors import ImucalError

#: The paper's nine parameters, in the order used everywhere (Eq. theModel and Eq. angles).
BASE_NAMES = ("s1", "s2", "s3", "b1", "b2", "b3", "phi", "psi", "theta")
ANGLE_NAMES = ("phi", "psi", "theta")


#: Predicted standard error, in units of the parameter's scale, above which the poses leave a shift or a
#: scale undetermined: 1 % of g of bias, 1 % of the sensitivity (an angle's is its tolerance: the half-width
#: of its bound box, since the bounds alone pin it that well). imucal.solve.observability reads them.
UNDETERMINED_SHIFT, UNDETERMINED_SCALE = 0.01, 0.01

#: Slack of a bound check, relative to the bound or the parameter's scale (Parameter.admits).
BOUND_SLACK = 1e-6


@dataclass(frozen=True)
class Parameter:
    """One named parameter.

    ``scale`` is the typical magnitude the solver divides by, so IPOPT works on
    numbers near one (CasADi's sysid example).
    """

    name: str
    value: float
    lower: float = -math.inf
    upper: float = math.inf
    unit: str = ""
    fixed: bool = False
    scale: float = 1.0
    description: str = ""
    #: predicted standard error, in units of ``scale``, above which the evidence leaves it undetermined
    #: (imucal.solve.observability); None: the evidence's own rule
    undetermined: float | None = None

    def __post_init__(self) -> None:
        if not self.scale > 0 or not math.isfinite(self.scale):
            raise ImucalError(f"scale must be positive and finite, got {self.scale}",
                              field=f"parameters.{self.name}.scale", fix="give the parameter's typical size, above 0")
        if self.lower > self.upper:
            raise ImucalError(f"lower bound {self.lower} exceeds upper bound {self.upper}",
                              field=f"parameters.{self.name}", fix="give a lower bound at or below the upper one")

    @property
    def free(self) -> bool:
        return not self.fixed

    def admits(self, value: float, lower: float | None = None, upper: float | None = None) -> bool:
        """``value`` within [lower, upper] (default: this parameter's bounds), up to BOUND_SLACK of
        the larger of the finite bounds and the scale: IPOPT may end a hair outside a bound
        (bound_relax_factor 1e-8). False for NaN."""
        lo = self.lower if lower is None else lower
        hi = self.upper if upper is None else upper
        slack = BOUND_SLACK * max([abs(b) for b in (lo, hi) if math.isfinite(b)] + [self.scale])
        return lo - slack <= value <= hi + slack

    def at_bound(self, rel_tol: float = 1e-6) -> str | None:
        """'lower' or 'upper' when the value sits on a finite bound, else None."""
        tol = rel_tol * max(self.scale, abs(self.value), 1e-12)
        if math.isfinite(self.lower) and self.value - self.lower <= tol:
            return "lower"
        if math.isfinite(self.upper) and self.upper - self.value <= tol:
            return "upper"
        return None


class Parameters(Mapping[str, Parameter]):
    """An ordered, immutable set of named parameters."""

    def __init__(self, params: Iterable[Parameter]) -> None:
        self._p: dict[str, Parameter] = {}
        for p in params:
            if p.name in self._p:
                raise ImucalError(f"duplicate parameter {p.name!r}", field="parameters")
            self._p[p.name] = p

    def __getitem__(self, name: str) -> Parameter:
        try:
            return self._p[name]
        except KeyError:
            raise ImucalError(f"unknown parameter {name!r}", field="parameters",
                              fix=f"use one of {', '.join(self._p)}") from None

    def __iter__(self) -> Iterator[str]:
        return iter(self._p)

    def __contains__(self, name: object) -> bool:
        return name in self._p

    def __len__(self) -> int:
        return len(self._p)

    def __repr__(self) -> str:
        return "Parameters(" + ", ".join(f"{n}={p.value:.6g}" for n, p in self._p.items()) + ")"

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(self._p)

    @property
    def free_names(self) -> tuple[str, ...]:
        return tuple(n for n, p in self._p.items() if p.free)

    def values(self) -> list[float]:  # type: ignore[override]
        return [p.value for p in self._p.values()]

    def value_dict(self) -> dict[str, float]:
        return {n: p.value for n, p in self._p.items()}

    def with_values(self, values: Mapping[str, float]) -> "Parameters":
        return Parameters(replace(p, value=float(values.get(n, p.value))) for n, p in self._p.items())

    def with_fixed(self, names: Iterable[str], fixed: bool = True,
                   values: Mapping[str, float] | None = None) -> "Parameters":
        names = set(names)
        unknown = names - set(self._p)
        if unknown:
            raise ImucalError(f"cannot fix unknown parameter(s) {sorted(unknown)}", field="fix",
                              fix=f"choose from {', '.join(self._p)}")
        values = values or {}
        return Parameters(
            replace(p, fixed=fixed if n in names else p.fixed, value=float(values.get(n, p.value)))
            for n, p in self._p.items())

    def extended(self, extra: Iterable[Parameter]) -> "Parameters":
        return Parameters([*self._p.values(), *extra])


def base_parameters(s0: Iterable[float], b0: Iterable[float],
                    angles0: Iterable[float] = (RIGHT_ANGLE,) * 3,
                    angle_tol: float = DEFAULT_ANGLE_TOL, raw_unit: str = "raw",
                    gravity: float = 9.80665) -> Parameters:
    """The paper's nine parameters with the issue's bounds.

    Shifts s_i [raw] free; scales b_i [raw per m/s^2] positive; angles in
    pi/2 * (1 +- tol) (the paper's "0.98 pi .. 1.02 pi" read as multiples of pi/2).
    """
    if not 0 < angle_tol < 1:
        raise ImucalError(f"angle tolerance {angle_tol} must lie in (0, 1)", field="angle_tolerance",
                          fix="use a small fraction such as 0.02 (= 90 deg +- 2 %)")
    s0, b0, angles0 = list(s0), list(b0), list(angles0)
    lo, hi = RIGHT_ANGLE * (1 - angle_tol), RIGHT_ANGLE * (1 + angle_tol)
    params: list[Parameter] = []
    for i in range(3):
        # Scale for a shift: one g worth of raw units, so x = s/scale is O(1..10).
        params.append(Parameter(f"s{i+1}", float(s0[i]), unit=raw_unit,
                                scale=max(abs(b0[i]) * gravity, 1e-12), undetermined=UNDETERMINED_SHIFT,
                                description=f"shift (zero-g output) of axis {i+1}"))
    for i in range(3):
        params.append(Parameter(f"b{i+1}", float(b0[i]), lower=0.0, unit=f"{raw_unit}/(m/s^2)",
                                scale=max(abs(b0[i]), 1e-12), undetermined=UNDETERMINED_SCALE,
                                description=f"scale (sensitivity) of axis {i+1}"))
    descr = {"phi": "angle between axes x and y", "psi": "angle between axes x and z",
             "theta": "angle between axes y and z"}
    for name, a0 in zip(ANGLE_NAMES, angles0):
        params.append(Parameter(name, float(min(max(a0, lo), hi)), lower=lo, upper=hi, unit="rad",
                                scale=RIGHT_ANGLE, undetermined=angle_tol, description=descr[name]))
    return Parameters(params)


def model_label(model_name: str, params: "Parameters") -> str:
    """The model's name as fitted: the paper's 9-parameter model becomes "nakov-ivanov-6" when
    all three angles are held at 90 deg, and names any other held parameter."""
    fixed = [n for n in BASE_NAMES if n in params and params[n].fixed]
    base, sep, rest = model_name.partition("+")
    if base == "nakov-ivanov-9" and set(ANGLE_NAMES) <= set(fixed):
        base = "nakov-ivanov-6"
        fixed = [n for n in fixed if n not in ANGLE_NAMES]
    label = base + sep + rest
    return label + (f" ({', '.join(fixed)} held fixed)" if fixed else "")
