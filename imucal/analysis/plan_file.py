"""A pose plan file: a JSON list of gravity directions [gx, gy, gz], or the object `plan-poses --json`
writes (``poses`` plus its results, which scoring does not read). Validated by imucal.files.schema."""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from imucal.config.limits import MAX_SIM_POSES
from imucal.errors import ImucalError, short
from imucal.files.inputs import read_input_text
from imucal.files.schema import fill, rule

FORMAT = "imucal-pose-plan"
#: Largest plan file read (a plan of 10000 poses is about 0.5 MB).
MAX_PLAN_BYTES = 4 << 20
_POSES_FIX = "list the gravity direction of each pose, e.g. \"poses\": [[0, 0, 1], ...]"


@dataclass(frozen=True, kw_only=True)
class PlanFile:
    """The keys of a plan file, checked in this order; only ``poses`` is read, the rest are
    plan-poses' results."""

    format: Literal["imucal-pose-plan"] = field(default=FORMAT, metadata=rule(
        msg="format {value} is not a pose plan", fix='write {"poses": [[gx, gy, gz], ...]}'))
    format_version: Literal[1] = field(default=1, metadata=rule(
        msg="unknown format_version {value}", fix="this imucal reads version 1"))
    poses: tuple[tuple[float, float, float], ...] = field(metadata=rule(
        min_len=1, max_len=MAX_SIM_POSES, msg="poses must be a non-empty list of [gx, gy, gz] numbers", fix=_POSES_FIX))
    instructions: Any = None
    hold_order: Any = None  #: the order to hold the poses in (plan-poses --revisit: each twice)
    criterion: Any = None
    n: Any = None
    n_distinct: Any = None
    noise_m_s2: Any = None
    free: Any = None
    criterion_value: Any = None
    log_det_fisher: Any = None
    predicted_std: Any = None
    label: Any = None
    comparison: Any = None
    random: Any = None
    efficiency_vs_best_found: Any = None  #: a scheme's or plan's efficiency against the best of as many poses

    @classmethod
    def schema_input(cls, raw: Any) -> Any:
        """A bare list is the poses alone."""
        return {"poses": raw} if isinstance(raw, list) else raw


def _unique(path: str):
    def pairs_hook(pairs: list) -> dict:
        keys = [k for k, _ in pairs]
        dup = next((k for i, k in enumerate(keys) if k in keys[:i]), None)
        if dup is not None:
            raise ImucalError(f"duplicate key {short(dup)}", file=path, field="evaluate", fix="write each key once")
        return dict(pairs)
    return pairs_hook


def read_plan(path: str) -> np.ndarray:
    """The gravity directions (n, 3) of a pose plan file. Duplicate and unknown keys are refused,
    as in the YAML files."""
    text = read_input_text(path, field="evaluate", fix="give a JSON plan with 'poses'", max_bytes=MAX_PLAN_BYTES)
    try:
        obj = json.loads(text, object_pairs_hook=_unique(path))
    except RecursionError:
        raise ImucalError("is nested too deeply", file=path, field="evaluate",
                          fix="give a JSON plan with 'poses'") from None
    except ValueError as exc:  # JSONDecodeError, or an integer with too many digits
        raise ImucalError(f"is not readable JSON: {short(str(exc), 80)}", file=path, field="evaluate",
                          fix="give a JSON plan with 'poses' (imucal plan-poses --json writes one)") from None
    return np.array(fill(PlanFile, obj, path).poses, float)
