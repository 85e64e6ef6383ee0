"""The C of every sensor beside the accelerometer, generated the same way for each (issue 26).

A calibrated sensor (imucal.calibration.sensor.SensorCalibration) gets, from its description's
CasADi map with its values baked in (``codegen.sensor_function``, through the one emitter
``codegen.kernel``), with S its C symbol and y its output's (the gyroscope: gyro, omega):

  NAME_apply_S(raw_s, [acc], [cov], y)     the map; acc the calibrated acceleration of the same
                                           sample when it reads it, cov the covariates when it reads them
  NAME_apply_S_batch, NAME_apply_S_i16, NAME_apply_S_u16
  NAME_HAS_S, NAME_S_USES_ACC              what the firmware can test

and NAME_apply_imu (with _batch, _i16, _u16; _cov when a sensor reads covariates) runs every
sensor of one sample in order. Its error bound in the header is ``affine_float_error_bound``'s.
"""
from __future__ import annotations

import math
import textwrap
from typing import Any, Mapping

import numpy as np

from imucal.calibration.sensor import SensorCalibration
from imucal.constants import SI_ACCEL_UNIT
from imucal.model.channels import ACCELERATION, COVARIATES

#: imucal.export.codegen's _Context (the run's settings) and Kernel (a CasADi function as C statements): named
#: here, not imported, so codegen imports this module and not the other way round (tests/test_imports.py)
Context = Any
Kernel = Any

UNIT_ROUNDOFF = {"float": 2.0**-24, "double": 2.0**-53}


def names(s: SensorCalibration) -> dict[str, str]:
    """Its C names: the function's suffix, the raw argument, the output, the macro stem, the raw locals."""
    sym = s.model.symbol
    return {"fn": f"apply_{sym}", "raw": f"raw_{sym[0]}", "out": s.model.output_symbol, "macro": sym.upper(),
            "local": sym[0]}


def sources(s: SensorCalibration) -> list[tuple[str, list[str]]]:
    """The arrays its map's inputs come from, in order: ("acc", locals) for the accelerometer's calibrated
    columns, ("cov", locals) for covariates."""
    out: list[tuple[str, list[str]]] = []
    for key in s.model.inputs:
        src = "acc" if key in ACCELERATION.columns else "cov" if key in COVARIATES else None
        if src is None:
            raise ValueError(f"codegen: no C source for the {s.kind}'s input {key!r}")
        local = f"f{ACCELERATION.columns.index(key)}" if src == "acc" else f"c{len(out)}"
        if out and out[-1][0] == src:
            out[-1][1].append(local)
        else:
            out.append((src, [local]))
    return out


def kernel_io(s: SensorCalibration, cov_index: Mapping[str, int]) -> tuple[list[list[str]], list[list[str]]]:
    """The emitter's input and output expressions: raw locals, each input's local, the output elements."""
    n = names(s)
    locs = []
    for key in s.model.inputs:
        locs.append(f"f{ACCELERATION.columns.index(key)}" if key in ACCELERATION.columns else f"c{cov_index[key]}")
    return [[f"{n['local']}{i}" for i in range(3)], locs], [[f"{n['out']}[{i}]" for i in range(3)]]


def affine_float_error_bound(s: SensorCalibration, raw: np.ndarray, inputs: np.ndarray | None = None,
                             precision: str = "float", input_error: np.ndarray | None = None) -> np.ndarray:
    """A priori bound (N, 3) on |NAME_apply_S(raw, inputs) - exact| per axis, for a map the emitter writes as
    y = A (raw - s) + B inputs (SensorCalibration.affine and forward).

    y_i is a sum of at most 3 + k products: each A term carries the rounding of A_ij, of the subtraction,
    of the product and at most 2 + k of the sum (gamma_{k+5}), each B term one fewer (gamma_{k+4}), and the
    rounded s an absolute u |s_j| (Higham, Ch. 3):
        |err_i| <= gamma_{k+5} |A| |raw - s| + u (1 + gamma_{k+5}) |A| |s| + gamma_{k+4} |B| |in|.
    ``input_error`` bounds the error of the inputs passed in (NAME_apply_imu feeds its own float acc): it
    adds (1 + gamma_{k+4}) |B| input_error. The gyroscope (k = 3): gamma_8 and gamma_7."""
    u = UNIT_ROUNDOFF[precision]
    a, f = s.affine(), s.forward()
    k = a.B.shape[1]
    ga, gb = (k + 5) * u / (1 - (k + 5) * u), (k + 4) * u / (1 - (k + 4) * u)
    raw = np.atleast_2d(np.asarray(raw, float))
    inp = np.zeros((raw.shape[0], k)) if inputs is None else np.abs(np.atleast_2d(np.asarray(inputs, float)))
    e = np.zeros_like(inp) if input_error is None else np.abs(np.atleast_2d(input_error))
    A, B = np.abs(a.A), np.abs(a.B)
    return (ga * np.abs(raw - f.s) @ A.T + u * (1 + ga) * (A @ np.abs(f.s)) + gb * (inp + e) @ B.T + e @ B.T)


def _block(text: str) -> list[str]:
    """A C block comment of ``text`` wrapped to 100 columns (the text is the generator's, values through
    comment_text)."""
    lines = textwrap.wrap(text + " */", 97, initial_indent="/* ", subsequent_indent=" * ")
    return lines


def _fmt(x: object, spec: str = ".6g") -> str:
    if isinstance(x, bool) or not isinstance(x, (int, float, np.floating, np.integer)):
        return "n/a"
    v = float(x)
    return format(v, spec) if math.isfinite(v) else "n/a"


def _matrix_text(M: np.ndarray, spec: str = ".9g") -> str:
    return "; ".join(", ".join(_fmt(x, spec) for x in row) for row in np.asarray(M))


def _fit_text(fit: Mapping) -> str:
    """Its fit statistics that are numbers (or a mapping of numbers), as the file holds them."""
    out = []
    for key, v in fit.items():
        if isinstance(v, Mapping) and v and all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                                 for x in v.values()):
            out.append(f"{key} " + ", ".join(f"{k} {_fmt(x, '.3g')}" for k, x in v.items()))
        elif isinstance(v, (int, float)) and not isinstance(v, bool):
            out.append(f"{key} {_fmt(v, '.6g')}")
    return "; ".join(out)


def doc(c: Context, s: SensorCalibration, k: Kernel) -> list[str]:
    """Header comment lines: its model, values with standard errors, units, frame, error bound and cost."""
    t = c.text
    n, p, real = names(s), c.prefix, c.real
    r = s.at_reference()  # a map with bias(T) terms: A, s and the bound at T_ref
    a, f = r.affine(), r.forward()
    unit = t(s.raw_unit)
    u = UNIT_ROUNDOFF[real]
    k_in = a.B.shape[1]
    at_rest = np.full((1, k_in), c.cal.gravity / math.sqrt(3)) if k_in else None
    rest = affine_float_error_bound(r, f.s, at_rest, real).max()
    per_out = (k_in + 5) * u * (np.abs(a.A) @ np.abs(f.P)).sum(axis=1).max()  # |raw - s| = |P y| at inputs 0
    ins = ", ".join(r.model.inputs)
    ref = s.reference_inputs()
    terms = ", ".join(e.name for e in s.model.effects)

    def wrap(text: str) -> list[str]:
        return textwrap.wrap(text, 94, initial_indent=" *   ", subsequent_indent=" *     ")

    values = "; ".join(f"{t(nm)} = {_fmt(prm.value, '.10g')} +/- {_fmt(s.std.get(nm), '.2g')} [{t(prm.unit)}]"
                       for nm, prm in s.params.items())
    head = (f"{s.kind.capitalize()} ({t(s.model.name)}): {n['out']} = A ({n['raw']} - s)"
            + (f" + B [{ins}]" if k_in else "") + ", this calibration's values baked in;")
    return [
        " *",
        *textwrap.wrap(head, 94, initial_indent=" * ", subsequent_indent=" *   "),
        *wrap(f"parameters (the calibration file's, with standard errors): {values}."),
        *(wrap(f"Terms in {', '.join(ref)} ({t(terms)}): the map below is at " + ", ".join(
            f"{k} = {_fmt(v, '.6g')}" for k, v in ref.items()) + f"; {p}_{n['fn']} reads {', '.join(ref)} from cov "
            f"and adds the terms (the parameters above). The error bound is at the reference.") if ref else []),
        *wrap(f"s [{unit}] = " + ", ".join(_fmt(x, ".10g") for x in f.s)),
        *wrap(f"A [{s.model.output.unit} per {unit}] = " + _matrix_text(a.A)),
        *(wrap(f"B = {_matrix_text(a.B)}" if r.reads_inputs() else
               f"B = 0: {p}_{n['fn']} does not read {', '.join(_unread(s, k))}") if k_in else []),
        f" * Units: {n['raw']} in [{unit}] (the recording's unit); {n['out']} in [{s.model.output.unit}], in the",
        " * same frame f as acc (the accelerometer's orthonormal frame above).",
        *_lag_lines(s, n["raw"]),
        " *",
        " * Expected error",
        *wrap(f"fit: {t(_fit_text(s.fit), 300)}"),
        f" *   {real} arithmetic: |error| per axis <= gamma |A| |{n['raw']} - s| + u |A| |s|"
        + (" + gamma' |B| |inputs|," if k_in else ","),
        f" *   i.e. <= {rest:.2g} {s.model.output.unit} at rest" + (f" with |a| = g" if k_in else "")
        + f", plus {per_out:.2g} max_j |{n['out']}_j| otherwise.",
        " *",
        f" * Cost of {p}_{n['fn']}: {k.ops}; no branch, no heap, no",
        " * mutable static state.",
    ]


def _lag_lines(s: SensorCalibration, raw: str) -> list[str]:
    """A sensor whose readings lag the accelerometer's (a magnetometer's fit ``lag_s``/``lag_samples``): the
    function does not shift them, the caller must (``imucal apply`` does)."""
    sec, samples = s.fit.get("lag_s"), s.fit.get("lag_samples")
    if not any(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v != 0
               for v in (sec, samples)):
        return []
    return textwrap.wrap(f"Time: {raw} lags the accelerometer's readings by {_fmt(sec, '.4g')} s ({_fmt(samples, '.3g')} "
                         f"samples at the recording's rate); this function does not shift it: pass {raw} read that "
                         f"much later ({raw}[k + lag] with the accelerometer's sample k), as `imucal apply` does.", 94,
                         initial_indent=" * ", subsequent_indent=" *   ")


def _unread(s: SensorCalibration, k: Kernel) -> list[str]:
    """The input arrays (acc, cov) its emitted function never reads (exact zeros dropped)."""
    return [src for src, _ in sources(s) if not any(r.startswith({"acc": "f", "cov": "c"}[src]) for r in k.reads)]


def _args(c: Context, s: SensorCalibration, real: str, const: bool = True) -> str:
    """The input arguments of its apply after raw: one array per source."""
    q = "const " if const else ""
    out = []
    for src, _ in sources(s):
        out.append(f"{q}{real} acc[3]" if src == "acc" else f"{q}{real} cov[{c.P}_N_COV]")
    return "".join(", " + a for a in out)


def declarations(c: Context, s: SensorCalibration, k: Kernel) -> list[str]:
    n, p, P, real = names(s), c.prefix, c.P, c.real
    unit = c.text(s.raw_unit)
    uses_acc = any(r.startswith("f") for r in k.reads)
    srcs = [src for src, _ in sources(s)]
    out = []
    if "acc" in srcs:
        out += [*_block(f"1: {p}_{n['fn']} reads acc (its map depends on the calibrated acceleration); 0: acc is "
                        "not read and may be NULL."), f"#define {P}_{n['macro']}_USES_ACC {int(uses_acc)}", ""]
    what = s.model.channel.role.replace("_", " ")
    text = f"{n['out']} = calibrated {what} [{s.model.output.unit}, frame f] from {n['raw']} [{unit}]"
    if "acc" in srcs:
        text += (f" and acc, the calibrated acceleration [{SI_ACCEL_UNIT}, frame f] of the same sample ({p}_apply's "
                 f"output). The argument is there whether or not this calibration uses it ({P}_{n['macro']}_USES_ACC), "
                 "so firmware need not change when a new calibration selects it.")
    else:
        text += "."
    out += [*_block(text + f" {n['out']} may alias its inputs."),
            f"void {p}_{n['fn']}(const {real} {n['raw']}[3]{_args(c, s, real)}, {real} {n['out']}[3]);", "",
            f"/* {p}_{n['fn']} over n samples stored as x y z x y z ... */",
            f"void {p}_{n['fn']}_batch(const {real} *{n['raw']}{_batch_args(s, real)}, {real} *{n['out']}, size_t n);",
            "", f"/* {p}_{n['fn']} on integer counts: int16_t (two's complement) or uint16_t (offset binary). */",
            *(f"void {p}_{n['fn']}_{sfx}(const {it} {n['raw']}[3]{_args(c, s, real)}, {real} {n['out']}[3]);"
              for it, sfx in (("int16_t", "i16"), ("uint16_t", "u16"))), ""]
    return out


def _batch_args(s: SensorCalibration, real: str) -> str:
    return "".join(f", const {real} *{src}" for src, _ in sources(s))


def source(c: Context, s: SensorCalibration, k: Kernel) -> list[str]:
    n, p, real = names(s), c.prefix, c.real
    loc = n["local"]
    reads = [f"{loc}{i} = {n['raw']}[{i}]" for i in range(3) if f"{loc}{i}" in k.reads]
    reads += [f"f{i} = acc[{i}]" for i in range(3) if f"f{i}" in k.reads]
    reads += [f"{v} = cov[{v[1:]}]" for v in sorted(r for r in k.reads if r.startswith("c"))]
    srcs = [src for src, _ in sources(s)]
    unread = _unread(s, k)
    call = {"acc": "acc + 3 * i", "cov": f"cov + {c.P}_N_COV * i"}
    out = [f"/* {n['out']} = A ({n['raw']} - s) + B inputs with this calibration's values ({k.ops}). */",
           f"void {p}_{n['fn']}(const {real} {n['raw']}[3]{_args(c, s, real)}, {real} {n['out']}[3])", "{",
           *([f"  const {real} {', '.join(reads)}; /* inputs first: {n['out']} may alias them */"] if reads else []),
           *[f"  (void){src}; /* B = 0: not read */" for src in unread],
           *([] if any(r.startswith(loc) for r in reads) else [f"  (void){n['raw']};"]),
           k.body(), "}", "",
           f"void {p}_{n['fn']}_batch(const {real} *{n['raw']}{_batch_args(s, real)}, {real} *{n['out']}, "
           "size_t n)", "{", "  size_t i;",
           f"  for (i = 0; i < n; ++i) {p}_{n['fn']}({n['raw']} + 3 * i"
           + "".join(f", {src if src in unread else call[src]}" for src in srcs)
           + f", {n['out']} + 3 * i);" + (f" /* {', '.join(unread)} unread */" if unread else ""), "}", ""]
    for itype, sfx in (("int16_t", "i16"), ("uint16_t", "u16")):
        out += [f"void {p}_{n['fn']}_{sfx}(const {itype} {n['raw']}[3]{_args(c, s, real)}, {real} {n['out']}[3])",
                "{", _converted(real, loc, n["raw"]),
                f"  {p}_{n['fn']}({loc}" + "".join(f", {src}" for src in srcs) + f", {n['out']});", "}", ""]
    return out


def _converted(real: str, name: str, raw: str) -> str:
    """A local float copy of a raw integer (or aliased) array."""
    return f"  const {real} {name}[3] = {{({real}){raw}[0], ({real}){raw}[1], ({real}){raw}[2]}};"


def _lists(real: str, sensors: tuple[SensorCalibration, ...], itype: str | None = None) -> dict[str, str]:
    """The argument lists of NAME_apply_imu after the accelerometer's: raw arrays, outputs, batch pointers."""
    nm = [names(s) for s in sensors]
    return {"raws": "".join(f", const {itype or real} {x['raw']}[3]" for x in nm),
            "outs": "".join(f", {real} {x['out']}[3]" for x in nm),
            "raw_ptrs": "".join(f", const {real} *{x['raw']}" for x in nm),
            "out_ptrs": "".join(f", {real} *{x['out']}" for x in nm),
            "raw_at": "".join(f", {x['raw']} + 3 * i" for x in nm),
            "out_at": "".join(f", {x['out']} + 3 * i" for x in nm)}


def imu_declarations(c: Context, sensors: tuple[SensorCalibration, ...]) -> list[str]:
    """NAME_apply_imu: every sensor of one sample, the accelerometer first."""
    p, P, real = c.prefix, c.P, c.real
    L = _lists(real, sensors)
    what = ", ".join(f"{names(s)['out']} ({p}_{names(s)['fn']})" for s in sensors)
    if c.covariates:
        acc = (f"raw_a and the covariates ({p}_apply_cov)" if c.acc_covariates else f"raw_a ({p}_apply)")
        return [*_block(f"Every sensor of one sample: acc from {acc}, then {what}, each reading the covariates "
                        "it needs from cov. The outputs may alias the inputs."),
                f"void {p}_apply_imu_cov(const {real} raw_a[3]{L['raws']}, const {real} cov[{P}_N_COV],",
                f"                       {real} acc[3]{L['outs']});", ""]
    out = [*_block(f"Every sensor of one sample: acc from raw_a ({p}_apply), then {what}. The outputs may alias "
                   "the inputs."), f"void {p}_apply_imu(const {real} raw_a[3]{L['raws']}, {real} acc[3]{L['outs']});",
           "", f"/* {p}_apply_imu over n samples, each array stored as x y z x y z ... */",
           f"void {p}_apply_imu_batch(const {real} *raw_a{L['raw_ptrs']}, {real} *acc{L['out_ptrs']}, size_t n);", "",
           f"/* {p}_apply_imu on integer counts of every sensor (exact conversion). */"]
    for itype, sfx in (("int16_t", "i16"), ("uint16_t", "u16")):
        out.append(f"void {p}_apply_imu_{sfx}(const {itype} raw_a[3]{_lists(real, sensors, itype)['raws']}, "
                   f"{real} acc[3]{L['outs']});")
    return out + [""]


def imu_source(c: Context, sensors: tuple[SensorCalibration, ...]) -> list[str]:
    p, P, real = c.prefix, c.P, c.real
    nm = [names(s) for s in sensors]
    L = _lists(real, sensors)
    copies = [f"  const {real} {x['local']}[3] = {{{x['raw']}[0], {x['raw']}[1], {x['raw']}[2]}}; "
              "/* acc may alias it */" for x in nm]

    def calls(first: str) -> list[str]:
        return [first] + [f"  {p}_{x['fn']}({x['local']}{''.join(', ' + src for src, _ in sources(s))}, {x['out']});"
                          for s, x in zip(sensors, nm)]

    if c.covariates:
        return [f"void {p}_apply_imu_cov(const {real} raw_a[3]{L['raws']}, const {real} cov[{P}_N_COV],",
                f"                       {real} acc[3]{L['outs']})", "{", *copies,
                *calls(f"  {p}_apply_cov(raw_a, cov, acc);" if c.acc_covariates else f"  {p}_apply(raw_a, acc);"),
                "}", ""]
    out = [f"void {p}_apply_imu(const {real} raw_a[3]{L['raws']}, {real} acc[3]{L['outs']})", "{", *copies,
           *calls(f"  {p}_apply(raw_a, acc);"), "}", "",
           f"void {p}_apply_imu_batch(const {real} *raw_a{L['raw_ptrs']}, {real} *acc{L['out_ptrs']}, size_t n)", "{",
           "  size_t i;",
           f"  for (i = 0; i < n; ++i) {p}_apply_imu(raw_a + 3 * i{L['raw_at']}, acc + 3 * i{L['out_at']});",
           "}", ""]
    for itype, sfx in (("int16_t", "i16"), ("uint16_t", "u16")):
        conv = [_converted(real, "a", "raw_a")] + [_converted(real, x["local"], x["raw"]) for x in nm]
        out += [f"void {p}_apply_imu_{sfx}(const {itype} raw_a[3]{_lists(real, sensors, itype)['raws']}, "
                f"{real} acc[3]{L['outs']})", "{", *conv, *calls(f"  {p}_apply(a, acc);"), "}", ""]
    return out
