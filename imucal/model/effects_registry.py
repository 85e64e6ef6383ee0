"""Name -> effect lookup for configs and calibration files (effects live in imucal.model.effects)."""
from __future__ import annotations

from typing import Sequence

from imucal.errors import ImucalError, short
from imucal.model.effects import AXIS_NAMES, EFFECTS, make_effect


def effects_from_specs(specs: Sequence, source: str | None = None) -> list:
    """Build effect objects from config EffectSpecs (name, axes as 'x'/'y'/'z')."""
    if not specs:
        return []
    out = []
    for i, s in enumerate(specs):
        if s.name not in EFFECTS:
            raise ImucalError(f"unknown effect {short(s.name)}", file=source, field=f"fit.effects[{i}].name",
                              fix=f"choose from {', '.join(EFFECTS)}")
        names = EFFECTS[s.name].axis_names
        axes = names if tuple(s.axes) == AXIS_NAMES else tuple(s.axes)  # the default: all of its axes
        bad = [a for a in axes if a not in names]
        if bad or not axes:
            raise ImucalError(f"axes {short(list(s.axes))} must be a non-empty list of {', '.join(names)}",
                              file=source, field=f"fit.effects[{i}].axes",
                              fix=f"e.g. axes: [{names[0]}, {names[-1]}], or leave axes out for all of them")
        if any(e.name == s.name for e in out):
            raise ImucalError(f"effect {s.name} is listed twice", file=source, field=f"fit.effects[{i}]",
                              fix=f"list it once with all its axes, e.g. {{name: {s.name}, axes: [x, y]}}")
        out.append(make_effect(s.name, tuple(names.index(a) for a in axes)))
    return out
