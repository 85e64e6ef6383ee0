"""One calibration file section per sensor (format version 3), generated from its Parameters (issue 26).

Every sensor beside the accelerometer (the gyroscope; any kind imucal.model.registry knows) is written and
read by these two functions, whatever its kind:

    <kind>:
      kind: <kind>
      model: <its description's name>
      units: {input: <raw unit>, output: <its output unit>}
      inputs: [<the other inputs its map reads: ax, ay, az ...>]
      parameters: {<name>: {value, std, unit, lower, upper, fixed, solver_scale}, ...}
      apply: {matrix, offset, input_matrix, equation}   # derived from the parameters, for people
      fit: {...}                                         # its fit statistics

The parameters are the source of truth; the apply map is derived (SensorModel.affine) and checked
against them on load, so a hand edit of a derived value is refused. The accelerometer's top-level
``parameters:`` are written by the same ``parameter_entries``.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

from imucal.calibration.fields import NAME_PATTERN, check_raw_unit, check_unit
from imucal.calibration.sensor import SensorCalibration
from imucal.errors import ImucalError, short
from imucal.files.schema import fill, rule
from imucal.model.parameters import Parameter, Parameters
from imucal.model.registry import describe, parameter_units

REGEN = "regenerate the file with `imucal calibrate`"
#: Relative disagreement between a stored apply map and the parameters' that counts as an edit.
DERIVED_RTOL = 1e-9
#: Smallest |det A| relative to the product of A's row norms: a map that loses a direction is refused.
MIN_RELATIVE_DET = 1e-9


def parameter_entries(params: Parameters, std: Mapping[str, float]) -> dict[str, dict[str, Any]]:
    """The ``parameters:`` mapping of a file: every parameter with its standard error, unit, bounds,
    fixed flag and the solver's scale."""
    return {n: {"value": float(p.value), "std": _f(std.get(n, float("nan"))), "unit": p.unit,
                "lower": _f(p.lower), "upper": _f(p.upper), "fixed": bool(p.fixed),
                "solver_scale": float(p.scale)}  # IPOPT's scaling magnitude, not a sensor's scale
            for n, p in params.items()}


def equation(s: SensorCalibration) -> str:
    """The section's apply equation in words of its columns (a map that reads covariates: at their reference,
    the parameters' terms moving it with them)."""
    r = s.at_reference()
    out, inputs = "[" + ", ".join(r.model.output.columns) + "]", "[" + ", ".join(r.model.inputs) + "]"
    tail = f" + input_matrix @ {inputs}  ({', '.join(r.model.inputs)}: the map's inputs)" if r.model.inputs else ""
    ref = s.reference_inputs()
    if ref:
        tail += ("; at " + ", ".join(f"{k} = {v:.6g}" for k, v in ref.items())
                 + f": the parameters' terms move it with {', '.join(ref)}")
    return f"{out} = matrix @ raw + offset{tail}"


def to_section(s: SensorCalibration) -> dict[str, Any]:
    """The file section of one sensor; its apply map at its covariates' reference (``at_reference``)."""
    a = s.at_reference().affine()
    return {"kind": s.kind, "model": s.model.name,
            "units": {"input": s.raw_unit, "output": s.model.output.unit},
            "inputs": list(s.model.inputs),
            "parameters": parameter_entries(s.params, s.std),
            "apply": {"matrix": a.A.tolist(), "offset": a.c.tolist(), "input_matrix": a.B.tolist(),
                      "equation": equation(s)},
            "fit": plain(dict(s.fit))}


_NUMBER = rule(msg="{value} is not a number", fix=REGEN)
_BOUND = rule(msg="{value} is not a number", allow_inf=True, fix=REGEN)
#: A standard error: not negative (null when undetermined, .inf when unbounded).
_STD = rule(ge=0, allow_inf=True, msg="{value} is not a standard error (a number >= 0, or null)", fix=REGEN)


@dataclass(frozen=True)
class ParameterEntry:
    """One entry of ``parameters:``; ``scale`` is ``solver_scale``'s name in files before the rename."""

    value: float = field(metadata=_NUMBER)
    std: float | None = field(default=None, metadata=_STD)  #: null: not determined
    unit: str = field(default="", metadata=rule(msg="{value} is not text", fix=REGEN))
    lower: float | None = field(default=None, metadata=_BOUND)
    upper: float | None = field(default=None, metadata=_BOUND)
    fixed: bool = field(default=False, metadata=rule(msg="{value} is not true or false"))
    solver_scale: float | None = field(default=None, metadata=_NUMBER)
    scale: float | None = field(default=None, metadata=_NUMBER)


@dataclass(frozen=True)
class SectionUnits:
    input: str = field(metadata=rule(msg="{value} is not text", fix=REGEN))
    output: str = field(metadata=rule(msg="{value} is not text", fix=REGEN))


@dataclass(frozen=True)
class SensorSection:
    """A sensor's section as ``to_section`` writes it."""

    kind: str = field(metadata=rule(msg="{value} is not text", fix=REGEN))
    model: str = field(metadata=rule(msg="{value} is not text", fix=REGEN))
    units: SectionUnits
    parameters: Mapping[str, ParameterEntry] = field(metadata=rule(fix=REGEN))
    inputs: tuple[str, ...] = field(default=(), metadata=rule(fix=REGEN))
    apply: Any = None  #: derived from the parameters; checked against them
    fit: Mapping[str, Any] = field(default_factory=dict, metadata=rule(fix=REGEN))


def read_parameters(entries: Mapping[str, ParameterEntry], names: tuple[str, ...], path: str, where: str = "parameters"
                    ) -> tuple[Parameters, dict[str, float]]:
    """Parameters (in the order ``names``) and their standard errors from a file's entries."""
    plist: list[Parameter] = []
    std: dict[str, float] = {}
    for n in names:
        if n not in entries:
            raise ImucalError(f"missing key {n!r}", file=path, field=f"{where}.{n}", fix=REGEN)
        e, at = entries[n], f"{where}.{n}."
        if e.solver_scale is not None and e.scale is not None:
            raise ImucalError("has both solver_scale and its old name scale", file=path, field=at + "scale",
                              fix="keep only solver_scale")
        key = "scale" if e.scale is not None else "solver_scale"
        try:
            plist.append(Parameter(n, float(e.value), lower=-math.inf if e.lower is None else float(e.lower),
                                   upper=math.inf if e.upper is None else float(e.upper), unit=e.unit,
                                   fixed=e.fixed, scale=float(getattr(e, key) or 1.0)))
        except ImucalError as exc:
            field_ = at + key if exc.field and exc.field.endswith(".scale") else exc.field
            raise ImucalError(exc.message, file=path, field=field_, fix=exc.fix) from None
        std[n] = math.nan if e.std is None else float(e.std)
    return Parameters(plist), std


def from_section(kind: str, raw: Any, path: str) -> SensorCalibration:
    """The sensor of a version-3 section, checked: its model, parameter names, units, bounds and derived map."""
    sec = fill(SensorSection, raw, path, kind)
    if sec.kind != kind:
        raise ImucalError(f"kind {short(sec.kind)} is not {kind!r}", file=path, field=f"{kind}.kind", fix=REGEN)
    model = describe(kind, sec.model, kind, path)
    extra = [n for n in sec.parameters if n not in model.names]
    if extra:
        raise ImucalError(f"parameter(s) {short(extra)} are not the {kind} model's", file=path,
                          field=f"{kind}.parameters", fix=REGEN)
    params, std = read_parameters(sec.parameters, model.names, path, f"{kind}.parameters")
    if tuple(sec.inputs) != model.inputs:
        raise ImucalError(f"inputs {short(list(sec.inputs))} are not the model's {list(model.inputs)}", file=path,
                          field=f"{kind}.inputs", fix=REGEN)
    if sec.units.output != model.output.unit:
        raise ImucalError(f"output unit {short(sec.units.output)} is not {model.output.unit!r}", file=path,
                          field=f"{kind}.units.output", fix=REGEN)
    check_raw_unit(sec.units.input, f"{kind}.units.input", path, "write e.g. rad/s, deg/s or counts")
    check_parameter_units(params, parameter_units(kind, model, sec.units.input), sec.units.input, path,
                          f"{kind}.parameters")
    s = SensorCalibration(model, params, std, sec.units.input, dict(sec.fit))
    check_sensor(s, path)
    _check_derived(s, sec.apply, path)
    return s


def check_parameter_units(params: Parameters, want: Mapping[str, str], raw_unit: str, path: str, where: str) -> None:
    """Every parameter's unit label must be the one the model gives it for readings in ``raw_unit`` (``want``):
    a file edited to state a bias in another unit would be applied as if the number were in the model's. An empty
    label (files before the grammar wrote none for the base) states nothing and is read in the model's unit."""
    for n, p in params.items():
        if n in want and p.unit and p.unit != want[n] and not (_dimensionless(p.unit) and _dimensionless(want[n])):
            raise ImucalError(f"{n} is labelled {short(p.unit)}, but the model with input unit {short(raw_unit)} "
                              f"has it in {want[n]!r} (the number is not converted)", file=path,
                              field=f"{where}.{n}.unit",
                              fix=f"write unit: {want[n]} with the value in {want[n]}, or {REGEN}")


def _dimensionless(unit: str) -> bool:
    """1, or a unit per itself (m/s^2/(m/s^2), uT/uT): one unit written several ways."""
    u = unit.replace(" ", "")
    return u == "1" or re.fullmatch(r"(.+)/\(\1\)|(.+)/\2", u) is not None


def check_sensor(s: SensorCalibration, path: str) -> None:
    """Names and units that reach C and reports, every value within its bounds, a map that keeps every direction."""
    for n, p in s.params.items():
        if not NAME_PATTERN.match(n):
            raise ImucalError(f"{short(n)} is not a parameter name", file=path, field=f"{s.kind}.parameters", fix=REGEN)
        check_unit(p.unit, f"{s.kind}.parameters.{n}.unit", path, REGEN)
        if not p.admits(p.value):
            raise ImucalError(f"{n} = {p.value:.6g} {p.unit} is outside the file's bounds "
                              f"[{p.lower:.6g}, {p.upper:.6g}]", file=path, field=f"{s.kind}.parameters.{n}.value",
                              fix=REGEN)
    if s.at_reference().model.affine is not None:
        with np.errstate(all="ignore"):  # a hostile scale (1e-300) overflows here: the test below names it
            A = s.at_reference().affine().A
            scale = np.prod(np.linalg.norm(A, axis=1))
            singular = not (np.all(np.isfinite(A)) and abs(np.linalg.det(A)) > MIN_RELATIVE_DET * scale)
        if singular:
            raise ImucalError(f"the {s.kind} parameters give a singular map (a direction lost)", file=path,
                              field=f"{s.kind}.parameters", fix=REGEN)


def _check_derived(s: SensorCalibration, apply: Any, path: str) -> None:
    """The stored apply map must be the parameters' (a hand edit of a derived value is refused)."""
    if apply is None:
        return
    a = s.at_reference().affine()
    fix = "edit the parameters, not the derived apply map, or restore the file"
    for key, want in (("matrix", a.A), ("offset", a.c), ("input_matrix", a.B)):
        try:
            got = np.array(apply.get(key), dtype=float) if isinstance(apply, Mapping) else None
        except (TypeError, ValueError, OverflowError):
            got = None
        if got is not None and want.size == 0 and got.size == 0:
            continue
        if got is None or got.shape != want.shape or not np.allclose(
                got, want, rtol=DERIVED_RTOL, atol=DERIVED_RTOL * np.abs(want).max(initial=1e-300)):
            raise ImucalError("does not match the parameters (edited by hand?)", file=path,
                              field=f"{s.kind}.apply.{key}", fix=fix)


def _f(x: float) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else (None if math.isnan(x) else x)


def plain(x: Any) -> Any:
    """Numbers and containers as YAML's safe dumper writes them."""
    if isinstance(x, Mapping):
        return {str(k): plain(v) for k, v in x.items()}
    if isinstance(x, np.ndarray):
        return [plain(v) for v in x.tolist()]
    if isinstance(x, (list, tuple)):
        return [plain(v) for v in x]
    if isinstance(x, (np.floating, float)):
        return float(x)
    if isinstance(x, (np.integer, int)) and not isinstance(x, bool):
        return int(x)
    if isinstance(x, np.bool_):
        return bool(x)
    return x
