"""Reading YAML files with one-line errors (file, field, fix); safe loading only.

Every YAML file imucal reads (run configs, simulations, calibrations) goes through here: a
regular file within the size limit (imucal.files.inputs), ``yaml.SafeLoader`` semantics, and three
refusals that plain ``safe_load`` lacks: duplicate keys (the second value would silently win),
alias bombs (a few lines that expand to billions of nodes), and integers no float can hold.
Numbers are read as YAML 1.1 and 1.2 agree on them: YAML 1.1's base-60 numbers (``9:48`` is 588)
and leading-zero octal integers (``010`` is 8) stay text, so a field that needs a number refuses
them in one line instead of taking a value nobody wrote (an explicit ``!!int 9:48`` is refused).
"""
from __future__ import annotations

import os
import re
from pathlib import Path
from typing import Any

import yaml

from imucal.errors import ImucalError, short
from imucal.files.inputs import read_input_text

#: Most aliases (*name) a file may use: configs and calibrations need none.
MAX_ALIASES = 10
#: Most nodes (scalars, lists, mappings) a file may hold.
MAX_NODES = 200_000
#: Deepest nesting accepted.
MAX_DEPTH = 50


#: libyaml's emitter when PyYAML was built with it (same text as the Python emitter, 4-6x faster on a
#: calibration file), else the Python one.
_DUMPER = getattr(yaml, "CSafeDumper", yaml.SafeDumper)


def dump_yaml(data: Any, **options: Any) -> str:
    """``yaml.safe_dump(data, **options)`` as text, by the fastest safe emitter available. Text
    that is not valid Unicode (a file name's undecodable bytes, read as surrogates) goes to the
    Python emitter, which escapes it (libyaml cannot encode it); both write the same text otherwise."""
    try:
        return yaml.dump(data, Dumper=_DUMPER, **options)
    except UnicodeEncodeError:
        return yaml.dump(data, Dumper=yaml.SafeDumper, **options)


_INT_TAG, _FLOAT_TAG = "tag:yaml.org,2002:int", "tag:yaml.org,2002:float"
#: SafeLoader's implicit int and float (yaml/resolver.py) without YAML 1.1's base-60 forms
#: (``1:30``) and leading-zero octal (``010``): those stay text (module docstring).
_INT = re.compile(r"""^(?:[-+]?0b[0-1_]+
                    |[-+]?(?:0|[1-9][0-9_]*)
                    |[-+]?0x[0-9a-fA-F_]+)$""", re.X)
_FLOAT = re.compile(r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+][0-9]+)?
                    |\.[0-9_]+(?:[eE][-+][0-9]+)?
                    |[-+]?\.(?:inf|Inf|INF)
                    |\.(?:nan|NaN|NAN))$""", re.X)


#: A UTF-16 surrogate pair, and a surrogate that is neither half of one nor an undecodable byte (\udc80-\udcff,
#: Python's surrogateescape).
_PAIR = re.compile("[\ud800-\udbff][\udc00-\udfff]")
_LONE = re.compile("[\ud800-\udc7f\udd00-\udfff]")


class _Loader(yaml.SafeLoader):
    """SafeLoader that counts aliases and nodes and refuses duplicate keys."""

    def __init__(self, stream: str) -> None:
        super().__init__(stream)
        self._aliases = 0
        self._nodes = 0

    def compose_node(self, parent, index):  # type: ignore[override]
        if self.check_event(yaml.AliasEvent):
            self._aliases += 1
            if self._aliases > MAX_ALIASES:
                raise _Refused(f"more than {MAX_ALIASES} aliases (an alias bomb?)")
        self._nodes += 1
        if self._nodes > MAX_NODES:
            raise _Refused(f"more than {MAX_NODES} nodes")
        return super().compose_node(parent, index)

    def construct_mapping(self, node, deep=False):  # type: ignore[override]
        seen: set = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=True)
            try:
                dup = key in seen
                seen.add(key)
            except TypeError:  # unhashable keys: SafeLoader refuses them itself
                dup = False
            if dup:
                raise _Refused(f"duplicate key {short(key)} at line {key_node.start_mark.line + 1}")
        return super().construct_mapping(node, deep=deep)

    def construct_yaml_str(self, node):  # type: ignore[no-untyped-def]
        """Text; a double-quoted UTF-16 surrogate pair (JSON's "\\ud83d\\ude00") is the one character it
        encodes, \\udc80-\\udcff a file name's undecodable byte (as dump_yaml writes it), any other surrogate is
        no character: refused (it reached os.stat as an internal error)."""
        value = _PAIR.sub(lambda m: m.group().encode("utf-16", "surrogatepass").decode("utf-16"),
                          super().construct_yaml_str(node))
        if _LONE.search(value):
            raise _Refused(f"text at line {node.start_mark.line + 1} holds a lone UTF-16 surrogate",
                           "write the character itself, or its \\U00XXXXXX escape")
        return value

    def construct_number(self, node):  # type: ignore[no-untyped-def]
        """An explicitly tagged !!int or !!float: refused in base 60 (``!!int 9:48``) or leading-zero octal."""
        value = self.construct_scalar(node)
        octal = node.tag == _INT_TAG and re.fullmatch(r"[-+]?0[0-7_]+", value) is not None
        if ":" in value or octal:
            raise _Refused(f"{short(value)} at line {node.start_mark.line + 1} is a YAML 1.1 "
                           f"{'octal' if octal else 'base-60'} number", "write the number in decimal")
        return (self.construct_yaml_int if node.tag == _INT_TAG else self.construct_yaml_float)(node)


_Loader.yaml_implicit_resolvers = {
    ch: [(tag, rx) for tag, rx in rs if tag not in (_INT_TAG, _FLOAT_TAG)]
    for ch, rs in yaml.SafeLoader.yaml_implicit_resolvers.items()}
_Loader.add_implicit_resolver(_INT_TAG, _INT, list("-+0123456789"))
_Loader.add_implicit_resolver(_FLOAT_TAG, _FLOAT, list("-+0123456789."))
_Loader.add_constructor("tag:yaml.org,2002:str", _Loader.construct_yaml_str)
_Loader.add_constructor(_INT_TAG, _Loader.construct_number)
_Loader.add_constructor(_FLOAT_TAG, _Loader.construct_number)


def parse_scalar(text: str) -> Any:
    """One YAML value given as text (a cell of a CSV manifest), read as ``read_yaml`` reads files
    (so ``9:48`` stays text). Raises yaml.YAMLError when it is not YAML."""
    loader = _Loader(text)
    try:
        return loader.get_single_data()
    except _Refused as exc:
        raise yaml.YAMLError(str(exc)) from None
    finally:
        loader.dispose()


class _TooLarge(Exception):
    """An integer no float can hold (float() raises OverflowError): names its field."""


class _Refused(Exception):
    def __init__(self, message: str, fix: str = "write each key once, without anchors and aliases") -> None:
        super().__init__(message)
        self.fix = fix


def _check_values(obj: Any, depth: int = 0, where: str = "", seen: set | None = None, paths: bool = False) -> None:
    """Nesting depth and numbers: an integer beyond 64 bits is corrupt, not a value; with ``paths`` (a file whose
    text names files), text with a NUL character too. Objects shared through aliases are visited once."""
    seen = set() if seen is None else seen
    if depth > MAX_DEPTH:
        raise _Refused(f"nested deeper than {MAX_DEPTH} levels", "flatten the file")
    if isinstance(obj, (dict, list)):
        if id(obj) in seen:
            return
        seen.add(id(obj))
    if isinstance(obj, dict):
        for k, v in obj.items():
            _check_values(k, depth + 1, where, seen, paths)
            _check_values(v, depth + 1, f"{where}.{k}" if where else str(k), seen, paths)
    elif isinstance(obj, list):
        for v in obj:
            _check_values(v, depth + 1, where, seen, paths)
    elif paths and isinstance(obj, str) and "\x00" in obj:  # no path holds one (os.stat raised ValueError)
        raise _Refused(f"the text of {short(where, 80) if where else 'the top level'} holds a NUL character",
                       "remove it: no file name or label holds one")
    elif isinstance(obj, int) and not isinstance(obj, bool) and abs(obj) >= 2**1023:
        try:
            float(obj)
        except OverflowError:  # rounds beyond the largest float
            raise _TooLarge(where[:80] or "top level") from None


def check_structure(obj: Any, path: str | None = None, field: str = "config", paths: bool = False) -> None:
    """Refuse integers no float holds and nesting deeper than MAX_DEPTH, in one line; with ``paths`` (a run file,
    a manifest, a simulation: files whose text names files to open), text holding a NUL character too.

    read_yaml applies it to every file; config_from_dict and simulation_from_dict apply it to
    mappings a notebook user builds, so both paths refuse the same values.
    """
    try:
        _check_values(obj, paths=paths)
    except _TooLarge as exc:
        raise ImucalError("integer is too large for a float", file=path, field=str(exc),
                          fix="give a number within the field's range") from None
    except _Refused as exc:
        raise ImucalError(f"is refused: {exc}", file=path, field=field, fix=exc.fix) from None


def read_yaml(path: str | os.PathLike, field: str, fix: str) -> Any:
    """Parse the YAML file at ``path``; any failure is an ImucalError naming it and ``field``."""
    p = Path(path)
    text = read_input_text(p, field=field, fix=fix)
    try:
        loader = _Loader(text)
        try:
            obj = loader.get_single_data()
        finally:
            loader.dispose()
    except _TooLarge as exc:
        raise ImucalError("integer is too large for a float", file=str(p), field=str(exc),
                          fix="give a number within the field's range") from None
    except _Refused as exc:
        raise ImucalError(f"is refused: {exc}", file=str(p), field=field, fix=exc.fix) from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark else ""
        raise ImucalError(f"is not valid YAML{where}", file=str(p), field=field,
                          fix="check indentation and quoting") from None
    except (ValueError, TypeError, RecursionError, OverflowError) as exc:  # e.g. "!!timestamp 2001-02-30"
        raise ImucalError(f"is not valid YAML ({type(exc).__name__}: {short(str(exc), 80)})", file=str(p),
                          field=field, fix="check indentation and quoting") from None
    check_structure(obj, str(p), field)
    return obj
