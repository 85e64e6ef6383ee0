"""One schema mechanism for every file imucal reads: a frozen dataclass is the schema.

``fill(cls, raw, path)`` fills ``cls`` from a parsed YAML (or JSON) mapping by its type annotations
(str, int, float, bool, ``X | None``, ``Literal[...]``, ``tuple[X, ...]``, ``tuple[X, Y, Z]``,
``Mapping[str, X]``, nested dataclasses, unions of scalars and lists). It refuses unknown keys
(naming the allowed ones), missing required keys, wrong types, bools where numbers are expected
and non-finite numbers, in one line ``FILE: FIELD: what (fix: ...)`` with the field's path
(``fit.effects[2].axes``). Per-field bounds, messages and fixes are field metadata (``rule``);
checks across fields stay in the dataclass's ``__post_init__`` (raising ImucalError with a field).
A dataclass may define ``schema_input(cls, raw)`` (a classmethod) to accept a shorthand, e.g. an
effect given by its name alone. Why not pydantic 2: its import costs start-up time (measured by
scripts/bench_schema.py, docs/schema.md) and its messages would need translating into this form.
"""
from __future__ import annotations

import collections.abc
import dataclasses
import functools
import math
import re
import types
import typing
from dataclasses import dataclass
from typing import Any, Literal, Mapping, Union

from imucal.errors import ImucalError, key_text, short

#: The metadata key of a field's rule.
KEY = "imucal.schema"


@dataclass(frozen=True)
class Rule:
    """What a field accepts beyond its type. Bounds apply to numbers and to each number in a list."""

    gt: float | None = None
    ge: float | None = None
    lt: float | None = None
    le: float | None = None
    allow_inf: bool = False  #: +-inf accepted (bounds in files)
    allow_nan: bool = False  #: NaN accepted (an undetermined standard error)
    max_len: int | None = None  #: longest list or text
    min_len: int = 0
    unit: str = ""  #: named in messages ("a positive number of seconds")
    fix: str | None = None
    msg: str | None = None  #: replaces the message; ``{value}`` is the value given
    internal: bool = False  #: not read from the file (e.g. the file's own name)


def rule(**kw: Any) -> dict[str, Rule]:
    """Field metadata: ``field(default=0.5, metadata=rule(gt=0, unit="seconds"))``."""
    return {KEY: Rule(**kw)}


NO_RULE = Rule()


def fill(cls: type, raw: Any, path: str | None = None, where: str = "") -> Any:
    """An instance of the dataclass ``cls`` from ``raw``; ``where`` prefixes field paths."""
    return _dataclass(cls, raw, _Ctx(path), where)


def keys(cls: type) -> dict[str, Any]:
    """The keys a file may give for ``cls``, each with its type (internal fields left out)."""
    return {f.name: tp for f, tp, _ in _fields(cls)}


@dataclass(frozen=True)
class _Ctx:
    path: str | None

    def error(self, message: str, where: str, fix: str) -> ImucalError:
        return ImucalError(message, file=self.path, field=where or "top level", fix=fix)


@functools.lru_cache(maxsize=None)
def _fields(cls: type) -> tuple[tuple[dataclasses.Field, Any, Rule], ...]:
    hints = typing.get_type_hints(cls)
    return tuple((f, hints[f.name], f.metadata.get(KEY, NO_RULE)) for f in dataclasses.fields(cls)
                 if f.init and not f.metadata.get(KEY, NO_RULE).internal)


def _join(where: str, key: str) -> str:
    return f"{where}.{key}" if where else key


def _dataclass(cls: type, raw: Any, ctx: _Ctx, where: str) -> Any:
    hook = getattr(cls, "schema_input", None)
    if hook is not None:
        raw = _located(ctx, where, lambda: hook(raw))
    raw = {} if raw is None else raw
    if not isinstance(raw, Mapping):
        raise ctx.error(f"{'top level' if not where else 'section'} must be a mapping, got {type(raw).__name__}",
                        where, "write the file as a mapping of keys to values (YAML key: value lines, a JSON {...}), "
                        "not a list or a single value"
                        if not where else f"write {where} as a mapping of keys to values (YAML: key: value lines "
                        "indented under it)")
    spec = _fields(cls)
    allowed = [f.name for f, _, _ in spec]
    unknown = [k for k in raw if k not in allowed]
    if unknown:
        raise ctx.error(f"unknown key {short(unknown[0])}", _join(where, key_text(unknown[0])),
                        f"allowed {'top-level keys' if not where else 'keys here'}: {', '.join(allowed)}")
    kw = {}
    for f, tp, r in spec:
        here = _join(where, f.name)
        if f.name not in raw or (raw[f.name] is None and dataclasses.is_dataclass(tp)):
            if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
                what = "section" if dataclasses.is_dataclass(tp) else "key"
                raise ctx.error(f"missing {what} {f.name!r}", here, r.fix or f"add {here}")
            continue
        kw[f.name] = _value(tp, raw[f.name], ctx, here, r)
    return _located(ctx, where, lambda: cls(**kw))


def _located(ctx: _Ctx, where: str, make: Any) -> Any:
    """``make()``; an ImucalError it raises (from ``__post_init__``) names the file."""
    try:
        return make()
    except ImucalError as exc:
        if exc.file is not None:
            raise
        raise ImucalError(exc.message, file=ctx.path, field=exc.field or where or None, fix=exc.fix) from None


def _name(where: str) -> str:
    """The field's own name in a message: ``M`` for ``accelerometers.M[0][1]``."""
    return where.rsplit(".", 1)[-1].split("[", 1)[0]


#: A number in exponent form YAML 1.1 reads as text (1e-3, 1.5e3, 1E+5: no "." before the exponent, or no sign in it).
_EXPONENT_TEXT = re.compile(r"(?P<m>[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+))[eE](?P<e>[-+]?[0-9]+)")


def _fail(ctx: _Ctx, raw: Any, where: str, r: Rule, expect: str) -> ImucalError:
    name = _name(where)
    msg = r.msg.format(value=short(raw)) if r.msg else f"{name} {short(raw)} must be {expect}"
    m = _EXPONENT_TEXT.fullmatch(raw.strip()) if isinstance(raw, str) and "number" in expect else None
    if m is not None:  # window: 1e-3 is the text '1e-3' to YAML 1.1: say so, and how to write the number
        mant, exp = m["m"] + (".0" if "." not in m["m"] else "0" if m["m"].endswith(".") else ""), m["e"]
        return ctx.error(f"{msg} (YAML reads {short(raw)} as text, not a number)", where,
                         f"write {mant}e{exp if exp[0] in '+-' else '+' + exp}: a decimal point and a signed exponent")
    return ctx.error(msg, where, r.fix or f"give {where or 'it'} as {expect}")


def _value(tp: Any, raw: Any, ctx: _Ctx, where: str, r: Rule) -> Any:
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if tp is Any or tp is object:
        return raw
    if origin in (Union, types.UnionType):
        return _union(args, raw, ctx, where, r)
    if tp is type(None):
        if raw is not None:
            raise _fail(ctx, raw, where, r, "null")
        return None
    if origin is Literal:
        if not any(type(raw) is type(a) and raw == a for a in args):
            raise _fail(ctx, raw, where, r, f"one of {', '.join(map(str, args))}")
        return raw
    if dataclasses.is_dataclass(tp):
        return _dataclass(tp, raw, ctx, where)
    if tp in (bool, int, float, str):
        return _scalar(tp, raw, ctx, where, r)
    if origin in (tuple, list) or tp in (tuple, list):
        return _sequence(tp, origin or tp, args, raw, ctx, where, r)
    if origin in (dict, collections.abc.Mapping) or tp in (dict, Mapping, collections.abc.Mapping):
        return _mapping(args, raw, ctx, where, r)
    raise TypeError(f"imucal.files.schema: unsupported annotation {tp!r} at {where}")


def _kind(tp: Any) -> str:
    """What a YAML value of type ``tp`` looks like: text, number, flag, list, mapping or null."""
    origin = typing.get_origin(tp)
    if tp is str or (origin is Literal and all(isinstance(a, str) for a in typing.get_args(tp))):
        return "text"
    if tp in (int, float) or origin is Literal:
        return "number"
    if tp is bool:
        return "flag"
    if origin in (tuple, list) or tp in (tuple, list):
        return "list"
    if tp is type(None):
        return "null"
    return "mapping"


def _raw_kind(raw: Any) -> str:
    if isinstance(raw, bool):
        return "flag"
    if isinstance(raw, (int, float)):
        return "number"
    return {str: "text", list: "list", tuple: "list", type(None): "null"}.get(type(raw), "mapping")


def _union(args: tuple, raw: Any, ctx: _Ctx, where: str, r: Rule) -> Any:
    """``X | None`` and unions of different kinds (a number or a list of three): the alternative
    of the value's kind is checked, so its message is the specific one."""
    if raw is None and type(None) in args:
        return None
    for alt in args:
        if alt is not type(None) and _kind(alt) == _raw_kind(raw):
            return _value(alt, raw, ctx, where, r)
    kinds = [_describe(a, r) for a in args if a is not type(None)]
    return_none = " (or null)" if type(None) in args else ""
    raise _fail(ctx, raw, where, r, " or ".join(kinds) + return_none)


def _describe(tp: Any, r: Rule) -> str:
    origin = typing.get_origin(tp)
    if tp in (int, float):
        return _number_text(tp, r)
    if tp is bool:
        return "true or false"
    if tp is str:
        return "text"
    if origin is Literal:
        return f"one of {', '.join(map(str, typing.get_args(tp)))}"
    if origin in (tuple, list):
        args = typing.get_args(tp)
        return f"a list of {len(args)} values" if args and args[-1] is not Ellipsis else "a list"
    return "a mapping"


def _number_text(tp: type, r: Rule) -> str:
    """What a number field accepts, in words: "a positive number of seconds", "an integer from 0 to 9"."""
    noun = "integer" if tp is int else "number"
    article = "an" if tp is int else "a"
    upper = (r.lt, r.le) != (None, None)
    if r.gt == 0 and not upper:
        text = f"a positive {noun}"
    elif r.ge == 0 and not upper:
        text = f"a non-negative {noun}"
    elif r.ge is not None and r.le is not None:
        text = f"{article} {noun} from {r.ge:g} to {r.le:g}"
    elif (r.gt, r.ge) != (None, None) or upper:
        lo = f"({r.gt:g}" if r.gt is not None else f"[{r.ge:g}" if r.ge is not None else "(-inf"
        hi = f"{r.lt:g})" if r.lt is not None else f"{r.le:g}]" if r.le is not None else "inf)"
        text = f"{article} {noun} in {lo}, {hi}"
    else:
        text = f"{article} {noun}" if r.allow_inf or tp is int else f"a finite {noun}"
    return f"{text} of {r.unit}" if r.unit else text


def _scalar(tp: type, raw: Any, ctx: _Ctx, where: str, r: Rule) -> Any:
    if tp is bool:
        if not isinstance(raw, bool):
            raise _fail(ctx, raw, where, r, "true or false")
        return raw
    if tp is str:
        if not isinstance(raw, str) or not r.min_len <= len(raw) <= (r.max_len or math.inf):
            raise _fail(ctx, raw, where, r, "text" if r.max_len is None else f"text of at most {r.max_len} characters")
        return raw
    ok = isinstance(raw, int) if tp is int else isinstance(raw, (int, float))
    if isinstance(raw, bool) or not ok:
        raise _fail(ctx, raw, where, r, _number_text(tp, r))
    name = _name(where)
    try:
        x = float(raw)
    except OverflowError:  # an integer beyond the float range
        raise ctx.error(f"{name} {short(raw)} is too large for a float", where,
                        r.fix or f"give {where} as {_number_text(tp, r)}") from None
    if (math.isnan(x) and not r.allow_nan) or (math.isinf(x) and not r.allow_inf):
        raise ctx.error(f"{name} is not finite ({short(raw)})", where,
                        r.fix or f"give {where} as {_number_text(tp, r)}")
    if not math.isnan(x) and not _within(x, r):
        raise _fail(ctx, raw, where, r, _number_text(tp, r))
    return raw  # an int stays an int (messages show the value as given)


def _within(x: float, r: Rule) -> bool:
    return ((r.gt is None or x > r.gt) and (r.ge is None or x >= r.ge)
            and (r.lt is None or x < r.lt) and (r.le is None or x <= r.le))


def _sequence(tp: Any, origin: Any, args: tuple, raw: Any, ctx: _Ctx, where: str, r: Rule) -> Any:
    if not isinstance(raw, (list, tuple)):
        raise _fail(ctx, raw, where, r, _describe(tp, r))
    if args and args[-1] is not Ellipsis:  # fixed length: tuple[float, float, float]
        if len(raw) != len(args):
            raise _fail(ctx, raw, where, r, _describe(tp, r))
        items = args
    else:
        if r.max_len is not None and len(raw) > r.max_len:
            raise ctx.error(f"{len(raw)} entries, above the limit of {r.max_len}", where,
                            r.fix or f"give {where} at most {r.max_len} entries")
        if len(raw) < r.min_len:
            raise ctx.error(f"{len(raw)} entries, at least {r.min_len} needed", where,
                            r.fix or f"give {where} at least {r.min_len} entries")
        items = (args[0] if args else Any,) * len(raw)
    inner = dataclasses.replace(r, max_len=None, min_len=0)
    out = [_value(t, v, ctx, f"{where}[{i}]", inner) for i, (t, v) in enumerate(zip(items, raw))]
    return out if origin is list else tuple(out)


def _mapping(args: tuple, raw: Any, ctx: _Ctx, where: str, r: Rule) -> dict:
    if not isinstance(raw, Mapping):
        raise _fail(ctx, raw, where, r, "a mapping")
    kt, vt = args if args else (Any, Any)
    out = {}
    for k, v in raw.items():
        key = _value(kt, k, ctx, where, dataclasses.replace(r, msg=None, gt=None, ge=None, lt=None, le=None))
        out[key] = _value(vt, v, ctx, _join(where, key_text(k)), r)
    return out
