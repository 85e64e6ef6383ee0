"""Numpy evaluators generated from CasADi SX functions: one row's maths, run over N rows at once.

A model's residual is written once, symbolically, for one observation (imucal.model). Mapping
it with ``Function.map`` runs CasADi's virtual machine row by row, about 15 times slower at 10^6
rows than array arithmetic. Instead, the SX algorithm (the straight-line instruction list CasADi
stores for an SX Function) is translated once into Python source in which every instruction is
one numpy operation. Inputs that are the same for every row (parameters) stay scalars, inputs
that vary (raw readings, covariates) are (N,) arrays, and numpy's broadcasting does the rest, so
the per-row work is a few dozen vector operations whatever the model.

The generated source contains only register names, numpy calls and the function's numeric
constants (``repr`` of floats): nothing user-supplied reaches it.
"""
from __future__ import annotations

import math
from functools import lru_cache
from typing import Callable, Sequence

import casadi as ca
import numpy as np

_UNARY = {
    ca.OP_ASSIGN: "{0}", ca.OP_NEG: "-{0}", ca.OP_SQ: "{0}*{0}", ca.OP_TWICE: "2.0*{0}",
    ca.OP_INV: "1.0/{0}", ca.OP_SQRT: "_np.sqrt({0})", ca.OP_SIN: "_np.sin({0})",
    ca.OP_COS: "_np.cos({0})", ca.OP_TAN: "_np.tan({0})", ca.OP_EXP: "_np.exp({0})",
    ca.OP_LOG: "_np.log({0})", ca.OP_FABS: "_np.abs({0})", ca.OP_SIGN: "_np.sign({0})",
    ca.OP_ASIN: "_np.arcsin({0})", ca.OP_ACOS: "_np.arccos({0})", ca.OP_ATAN: "_np.arctan({0})",
    ca.OP_SINH: "_np.sinh({0})", ca.OP_COSH: "_np.cosh({0})", ca.OP_TANH: "_np.tanh({0})",
    ca.OP_EXPM1: "_np.expm1({0})", ca.OP_LOG1P: "_np.log1p({0})", ca.OP_FLOOR: "_np.floor({0})",
    ca.OP_CEIL: "_np.ceil({0})", ca.OP_NOT: "1.0*({0}==0)",
}
_BINARY = {
    ca.OP_ADD: "{0}+{1}", ca.OP_SUB: "{0}-{1}", ca.OP_MUL: "{0}*{1}", ca.OP_DIV: "{0}/{1}",
    ca.OP_POW: "_np.power({0},{1})", ca.OP_CONSTPOW: "_np.power({0},{1})",
    ca.OP_ATAN2: "_np.arctan2({0},{1})", ca.OP_FMIN: "_np.minimum({0},{1})",
    ca.OP_FMAX: "_np.maximum({0},{1})", ca.OP_HYPOT: "_np.hypot({0},{1})",
    ca.OP_COPYSIGN: "_np.copysign({0},{1})", ca.OP_FMOD: "_np.fmod({0},{1})",
    ca.OP_LT: "1.0*({0}<{1})", ca.OP_LE: "1.0*({0}<={1})", ca.OP_EQ: "1.0*({0}=={1})",
    ca.OP_NE: "1.0*({0}!={1})", ca.OP_AND: "1.0*(({0}!=0)&({1}!=0))",
    ca.OP_OR: "1.0*(({0}!=0)|({1}!=0))", ca.OP_IF_ELSE_ZERO: "_np.where({0}!=0,{1},0.0)",
}


def _source(f: ca.Function) -> str:
    """Python source of ``f``'s SX algorithm, one numpy operation per instruction."""
    lines = [f"def _generated({', '.join(f'i{k}' for k in range(f.n_in()))}):"]
    outs = [f"o{k}" for k in range(f.n_out())]
    for k in range(f.n_out()):
        lines.append(f"    o{k} = [0.0] * {f.nnz_out(k)}")
    for k in range(f.n_instructions()):
        op, ins, out = f.instruction_id(k), f.instruction_input(k), f.instruction_output(k)
        if op == ca.OP_INPUT:
            lines.append(f"    w{out[0]} = i{ins[0]}[{ins[1]}]")
        elif op == ca.OP_OUTPUT:
            lines.append(f"    o{out[0]}[{out[1]}] = w{ins[0]}")
        elif op == ca.OP_CONST:
            lines.append(f"    w{out[0]} = {_constant(float(f.instruction_constant(k)))}")
        elif op in _UNARY:
            lines.append(f"    w{out[0]} = " + _UNARY[op].format(f"w{ins[0]}"))
        elif op in _BINARY:
            lines.append(f"    w{out[0]} = " + _BINARY[op].format(f"w{ins[0]}", f"w{ins[1]}"))
        else:
            raise NotImplementedError(f"CasADi operation {op} of {f.name()} has no numpy form")
    lines.append(f"    return {', '.join(outs)}{',' if len(outs) == 1 else ''}")
    return "\n".join(lines)


def _constant(v: float) -> str:
    if np.isnan(v):
        return "_np.nan"
    if np.isinf(v):
        return "_np.inf" if v > 0 else "-_np.inf"
    return repr(v)


#: Rows evaluated at a time: each register of the generated code is then a 32 KB array that stays in
#: the CPU's cache (17,860 rows of the gyroscope's 3,000-instruction tangent: 33 ms in one block,
#: 21 ms in blocks of 4096; the same numbers, every operation being elementwise).
ROW_BLOCK = 4096


class Vectorized:
    """``f`` evaluated over N rows at once with numpy.

    Call with one array per input, shaped (nnz,) for inputs shared by every row or (nnz, N) for
    inputs that vary by row. Returns, per output, a dense array (numel, N) in CasADi's
    column-major order (or (numel,) when no input varies by row). Inputs may also be (nnz, *shape)
    with shapes that broadcast (say parameters (nnz, k, 1) against rows (nnz, 1, N)): every output is
    then (numel, *broadcast shape), and an instruction on the parameters alone runs k times, not k N.
    """

    def __init__(self, f: ca.Function) -> None:
        if not f.is_a("SXFunction"):
            f = f.expand()
        self.function = f
        namespace: dict = {"_np": np}
        exec(compile(_source(f), f"<vectorized {f.name()}>", "exec"), namespace)  # noqa: S102
        self._run: Callable = namespace["_generated"]
        self._dense = [(f.sparsity_out(k).row(), f.sparsity_out(k).get_col(), f.size1_out(k))
                       for k in range(f.n_out())]
        # sizes read once: the evaluator runs hundreds of times per fit (each CasADi query is a call)
        self._nnz_in = [f.nnz_in(k) for k in range(f.n_in())]
        self._numel_out = [f.numel_out(k) for k in range(f.n_out())]

    def __call__(self, *args: np.ndarray | Sequence[float]) -> list[np.ndarray]:
        ins = [np.asarray(a, float) for a in args]
        ins = [a if a.ndim >= 2 else a.reshape(self._nnz_in[k]) for k, a in enumerate(ins)]
        varying = [a.shape[1:] for a in ins if a.ndim >= 2]
        if not varying:
            return self._evaluate(ins, ())
        shape = np.broadcast_shapes(*varying)
        n, step = shape[-1], max(ROW_BLOCK // math.prod(shape[:-1]), 64)  # blocks of the last axis
        if n <= step:
            return self._evaluate(ins, shape)
        outs = [np.empty((m,) + shape) for m in self._numel_out]
        for s in range(0, n, step):
            block = [a[..., s:s + step] if a.ndim >= 2 and a.shape[-1] > 1 else a for a in ins]
            for out, part in zip(outs, self._evaluate(block, shape[:-1] + (min(step, n - s),))):
                out[..., s:s + step] = part
        return outs

    def _evaluate(self, ins: list[np.ndarray], shape: tuple[int, ...]) -> list[np.ndarray]:
        """The generated code on one block of rows; outputs (numel, *shape)."""
        with np.errstate(all="ignore"):
            raw = self._run(*[list(a) for a in ins])
        res = []
        for k, nz in enumerate(raw):
            rows, cols, n1 = self._dense[k]
            out = np.zeros((self._numel_out[k],) + shape)
            for v, i, j in zip(nz, rows, cols):
                out[i + j * n1] = v
            res.append(out)
        return res


#: Rows per block of ``apply_values``: the generated code's registers stay in the CPU cache.
APPLY_BLOCK = 65536


@lru_cache(maxsize=64)
def _apply_evaluator(fn: ca.Function) -> Vectorized:
    return Vectorized(fn)


def apply_values(model, p: Sequence[float] | np.ndarray, raw: np.ndarray, inputs: np.ndarray | None = None
                 ) -> np.ndarray:
    """A sensor description's map (``SensorModel.apply``) over rows: raw (N, 3) and inputs (N, k) at the
    parameter values ``p`` -> calibrated (N, 3), numpy generated from the CasADi function, in blocks."""
    raw = np.atleast_2d(np.asarray(raw, float))
    n, k = raw.shape[0], len(model.inputs)
    inp = np.zeros((n, k)) if inputs is None else np.asarray(inputs, float).reshape(n, k)
    f = _apply_evaluator(model.functions["apply"])
    p = np.asarray(p, float)
    out = np.empty((n, 3))
    for s in range(0, n, APPLY_BLOCK):
        out[s:s + APPLY_BLOCK] = f(raw[s:s + APPLY_BLOCK].T, inp[s:s + APPLY_BLOCK].T, p)[0].T
    return out
