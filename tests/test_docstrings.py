"""Issue 29: the public API's docstrings in one style (Google's, as mkdocstrings renders it): a one-line
summary ending in a full stop, then an ``Args:`` section naming every parameter and a ``Returns:`` section
for a function that returns something."""
from __future__ import annotations

import inspect

import pytest

import imucal


#: The methods of the public classes a user calls (the rest are the library's own).
METHODS = {"CalibrationResult": ("report", "summary", "to_file", "write"),
           "Calibration": ("apply", "apply_imu", "save", "load", "linear_map")}


def _public() -> list[tuple[str, object]]:
    out = []
    for name in imucal.__all__:
        obj = getattr(imucal, name)
        if name.startswith("__") or not callable(obj):
            continue
        if inspect.isclass(obj):
            out += [(f"{name}.{m}", getattr(obj, m)) for m in METHODS.get(name, ())]
        else:
            out.append((name, obj))
    return out


@pytest.mark.parametrize("name, fn", _public(), ids=[n for n, _ in _public()])
def test_public_functions_are_documented_in_one_style(name, fn):
    fn = getattr(fn, "__func__", fn)
    doc = inspect.getdoc(fn) or ""
    summary = doc.split("\n\n")[0]
    assert doc and summary.rstrip().endswith(".") and "\n" not in summary.strip(), (name, summary)
    params = [p for p in inspect.signature(fn).parameters if p not in ("self", "cls")]
    if params:
        assert "\nArgs:\n" in doc, name
        args = doc.split("\nArgs:\n")[1].split("\n\n")[0]
        missing = [p for p in params if f"    {p}:" not in args and f"    {p} (" not in args
                   and not any(f"{p}, " in ln or f", {p}:" in ln for ln in args.splitlines())]
        assert missing == [], (name, missing)
    returns = inspect.signature(fn).return_annotation
    if returns not in (None, "None", inspect.Signature.empty):
        assert "\nReturns:\n" in doc, name
