"""Reading YAML files with one-line errors (file, field, fix); safe loading only.

Every YAML file imucal reads (run configs, simulations, calibrations) goes through here: a
regular file within the size limit (imucal.files.inputs), ``yaml.SafeLoader`` semantics, and three
refusals that plain ``safe_load`` lacks: duplicate keys (the second value would silently win),
alias bombs (a few lines that expand to billions of nodes), and integers no float can hold.
"""
from __future__ import annotations

import os
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
    """``yaml.safe_dump(data, **options)`` as text, by the fastest safe emitter available."""
    return yaml.dump(data, Dumper=_DUMPER, **options)


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


class _TooLarge(Exception):
    """An integer no float can hold (float() raises OverflowError): names its field."""


class _Refused(Exception):
    def __init__(self, message: str, fix: str = "write each key once, without anchors and aliases") -> None:
        super().__init__(message)
        self.fix = fix


def _check_values(obj: Any, depth: int = 0, where: str = "", seen: set | None = None) -> None:
    """Nesting depth and numbers: an integer beyond 64 bits is corrupt, not a value. Objects
    shared through aliases are visited once."""
    seen = set() if seen is None else seen
    if depth > MAX_DEPTH:
        raise _Refused(f"nested deeper than {MAX_DEPTH} levels", "flatten the file")
    if isinstance(obj, (dict, list)):
        if id(obj) in seen:
            return
        seen.add(id(obj))
    if isinstance(obj, dict):
        for k, v in obj.items():
            _check_values(k, depth + 1, where, seen)
            _check_values(v, depth + 1, f"{where}.{k}" if where else str(k), seen)
    elif isinstance(obj, list):
        for v in obj:
            _check_values(v, depth + 1, where, seen)
    elif isinstance(obj, int) and not isinstance(obj, bool) and abs(obj) >= 2**1023:
        try:
            float(obj)
        except OverflowError:  # rounds beyond the largest float
            raise _TooLarge(where[:80] or "top level") from None


def check_structure(obj: Any, path: str | None = None, field: str = "config") -> None:
    """Refuse integers no float holds and nesting deeper than MAX_DEPTH, in one line.

    read_yaml applies it to every file; config_from_dict and simulation_from_dict apply it to
    mappings a notebook user builds, so both paths refuse the same values.
    """
    try:
        _check_values(obj)
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
