"""The candidates of a round: every term of the grammar on every axis subset the data can carry."""
from __future__ import annotations

import itertools
import math
from typing import Sequence

from imucal.analysis.discover.problem import Effects
from imucal.analysis.discover.result import Candidate, FoundEffect
from imucal.errors import ImucalError
from imucal.model.effects import (EFFECTS, MIN_DOF, MIN_TEMPERATURE_SPREAD, check_effects, make_effect,
                                  temperature_spread)
from imucal.solve.fit import FitResult


def subsets() -> list[tuple[int, ...]]:
    """Every non-empty axis subset: x, y, z, xy, xz, yz, xyz."""
    return [c for r in (1, 2, 3) for c in itertools.combinations(range(3), r)]


def extra(name: str, effects: Effects) -> int:
    """Parameters besides its coefficients an effect adds when it enters the model: a warm-up's tau
    (fitted), a step's time (profiled over the gaps between intervals)."""
    e = make_effect(name, (0,))
    return 0 if name in effects else len(e.shape_names) + len(e.given_names)


def candidates(names: Sequence[str], effects: Effects, n_free: int, n_rows: int,
               n_distinct: int) -> list[tuple[str, tuple[int, ...], tuple[int, ...]]]:
    """(name, merged axes, new axes) of every candidate: each effect on each axis subset, merged
    with the same effect already in the model, that the intervals can still carry. (A cross-axis term's
    axes are told apart only by its second-order terms: on two or three axes it is counted only where
    the poses determine them, ``selection``.)"""
    out, seen = [], set()
    for n in names:
        have = set(effects.get(n, ()))
        for sub in subsets():
            new = tuple(sorted(set(sub) - have))
            merged = tuple(sorted(set(sub) | have))
            nf = n_free + len(new) + extra(n, effects)
            if not new or (n, merged) in seen or n_rows - nf < MIN_DOF or nf > n_distinct:
                continue
            seen.add((n, merged))
            out.append((n, merged, new))
    return out


def nested(a: Candidate, b: Candidate) -> bool:
    """The same term, one's axes inside the other's."""
    return a.name == b.name and (set(a.axes) <= set(b.axes) or set(b.axes) <= set(a.axes))


def in_temperature(name: str) -> bool:
    """The effect depends on the temperature (or its rate of change)."""
    return any(c in ("temp", "temp_rate") for c in EFFECTS[name].covariates)


def testable(names: list[str], iv, source: str, notes: list[str]) -> list[str]:
    """Drop the temperature effects when the data cannot carry them (and say why); a hysteresis also
    when the temperature does not both rise and fall."""
    names = _both_ways(names, iv, notes)
    temp_names = [n for n in names if in_temperature(n)]
    reason = None
    if temp_names and iv.temp is None:
        reason = "the data have no temp column"
    elif temp_names and temperature_spread(iv.temp) < MIN_TEMPERATURE_SPREAD:
        reason = (f"the temperature is constant (interval means span {temperature_spread(iv.temp):.3g} degC "
                  f"< {MIN_TEMPERATURE_SPREAD} degC)")
    if reason is None:
        return names
    if len(temp_names) == len(names):
        raise ImucalError(f"{', '.join(temp_names)} cannot be tested: {reason}", file=source, field="candidates",
                          fix="record with a changing temperature column, or test other effects")
    notes.append(f"temperature effects not tested: {reason}")
    return [n for n in names if n not in temp_names]


def _both_ways(names: list[str], iv, notes: list[str]) -> list[str]:
    """Without intervals that warm and intervals that cool, a hysteresis is a constant: not tested."""
    rate = [n for n in names if "temp_rate" in EFFECTS[n].covariates]
    if not rate or iv.temp is None or temperature_spread(iv.temp) < MIN_TEMPERATURE_SPREAD:
        return names
    try:
        check_effects([make_effect(n, (0,)) for n in rate], iv.covariates, iv.n, 0)
    except ImucalError as exc:
        notes.append(f"not tested: {exc.message}")
        return [n for n in names if n not in rate]
    return names


def found_effect(name: str, axes: tuple[int, ...], res: FitResult, lr: float, p: float,
                 ambiguous: tuple[str, ...], unresolved: tuple[int, ...] = ()) -> FoundEffect:
    """A term as found: its coefficients (and shape parameters) with standard errors, units, references."""
    e = make_effect(name, axes)
    coef = {n: float(res.params[n].value) for n in (*e.coefficient_names, *e.shape_names)}
    ref = {n: float(res.params[n].value) for n in e.reference_names}
    return FoundEffect(name=name, axes=tuple(axes), coefficients=coef,
                       std={n: float(res.std.get(n, math.nan)) for n in coef},
                       units={n: res.params[n].unit for n in (*coef, *ref)}, reference=ref, lr=lr, p_value=p,
                       ambiguous_with=ambiguous, unresolved_axes=unresolved)
