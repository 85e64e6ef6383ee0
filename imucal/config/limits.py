"""Bounds on every size and count a user can ask for, checked before anything is allocated.

A request beyond these is refused in one line (README, "Bad input"), instead of exhausting the
machine's memory or running for days. Each bound is far above what the task needs.
"""
from __future__ import annotations

from imucal.errors import ImucalError, short

#: Multi-starts of a worst-case NLP (16 by default; each is one IPOPT solve).
MAX_STARTS = 10_000
#: Points of an error map (1e6 by default; 48 bytes each).
MAX_MAP_SAMPLES = 20_000_000
#: Samples of one simulated recording (about 56 bytes each with temperature).
MAX_SIM_SAMPLES = 50_000_000
#: Poses of one simulated plan or scored pose plan (listed or random): a calibration uses tens.
MAX_SIM_POSES = 10_000
#: Poses plan-poses optimises (the exchange costs grow with N times the grid).
MAX_DESIGN_POSES = 1000
#: Candidate directions of the design grid, and random sets a design is compared with.
MAX_DESIGN_GRID = 100_000
MAX_RANDOM_SETS = 10_000
#: Units of one fleet manifest (imucal batch); a production day is thousands.
MAX_FLEET_UNITS = 1_000_000
#: Largest seed numpy's generators take.
MAX_SEED = 2**63 - 1


def check_count(value: object, name: str, low: int, high: int, fix: str | None = None) -> int:
    """An integer in [low, high], or a one-line refusal naming the option."""
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise ImucalError(f"{name} {short(value)} must be an integer from {low} to {high}", field=name,
                          fix=fix or f"give {name} within [{low}, {high}]")
    return value


def check_seed(seed: object, name: str = "seed") -> int:
    """A seed numpy accepts: a non-negative integer below 2^63."""
    return check_count(seed, name, 0, MAX_SEED, fix="give a non-negative integer seed")
