"""Observability: refuse fits the poses cannot determine, and say what to add.

Two checks before the fit: the number of distinct gravity directions (repeated poses add no
rank), and the rank of the residual Jacobian with one row per distinct direction. Parameters
that load on the Jacobian's (near) null space are named as undetermined.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import ImucalError
from .parameters import ANGLE_NAMES

#: Two interval directions closer than this are the same pose [deg].
DISTINCT_ANGLE_DEG = 10.0
#: Relative singular value below which a direction of parameter space is undetermined.
RANK_TOL = 1e-6


@dataclass(frozen=True)
class Observability:
    n_distinct: int
    labels: np.ndarray  #: cluster index of each interval
    singular_values: np.ndarray  #: of the column-scaled Jacobian, largest first
    undetermined: tuple[str, ...]

    @property
    def condition(self) -> float:
        sv = self.singular_values
        return float(sv[0] / sv[-1]) if sv.size and sv[-1] > 0 else float("inf")


def distinct_directions(directions: np.ndarray, min_angle_deg: float = DISTINCT_ANGLE_DEG
                        ) -> tuple[int, np.ndarray]:
    """Greedy clustering of unit vectors: returns the count and a label per row."""
    cos_min = np.cos(np.radians(min_angle_deg))
    centres: list[np.ndarray] = []
    labels = np.empty(len(directions), int)
    for i, d in enumerate(directions):
        for j, c in enumerate(centres):
            if d @ c >= cos_min:
                labels[i] = j
                break
        else:
            centres.append(d)
            labels[i] = len(centres) - 1
    return len(centres), labels


def analyse(directions: np.ndarray, jac_rows: np.ndarray, free_names: tuple[str, ...]
            ) -> Observability:
    """Distinct poses and Jacobian rank; ``jac_rows`` is (n_intervals, n_free), column-scaled."""
    n_distinct, labels = distinct_directions(directions)
    # One row per distinct direction: repeats of a pose add no information about the model.
    J = np.vstack([jac_rows[labels == k].mean(axis=0) for k in range(n_distinct)])
    # Columns are already multiplied by each parameter's typical scale (dimensionless), so a
    # column that the poses barely excite stays small and shows up in the null space.
    U, sv, Vt = np.linalg.svd(J, full_matrices=True)
    nf = len(free_names)
    svf = np.zeros(nf)
    svf[: sv.size] = sv
    null = svf < RANK_TOL * max(svf[0], 1e-300)
    null[n_distinct:] = True  # fewer distinct poses than parameters: rank <= n_distinct
    und: list[str] = []
    if null.any():
        V = Vt[null]
        load = np.sqrt((V**2).sum(axis=0))  # share of each parameter in the null space
        und = [free_names[j] for j in range(nf) if load[j] > 0.5]
    return Observability(n_distinct, labels, svf, tuple(sorted(und, key=free_names.index)))


def require_observable(obs: Observability, free_names: tuple[str, ...], source: str | None) -> None:
    """Raise a one-line ImucalError naming undetermined parameters and the poses to add."""
    nf = len(free_names)
    angles_free = [a for a in ANGLE_NAMES if a in free_names]
    if obs.n_distinct < nf:
        und = list(obs.undetermined)
        if not und and angles_free:
            und = angles_free
        what = f"{', '.join(und)} undetermined" if und else "parameters undetermined"
        fix = (f"hold the sensor still in at least {nf - obs.n_distinct} more orientations with gravity "
               "between the axes (e.g. the 12 cube edges or 8 corners)")
        if angles_free:
            fix += ", or fit the 6-parameter model with the angles fixed at 90 deg (--fix-angles, "
            fix += "or fit.fix: [phi, psi, theta] in the YAML)"
        raise ImucalError(f"only {obs.n_distinct} distinct orientations for {nf} free parameters: {what}",
                          file=source, field="intervals", fix=fix)
    if obs.undetermined:
        raise ImucalError(f"the orientations leave {', '.join(obs.undetermined)} undetermined "
                          f"(Jacobian condition {obs.condition:.3g})", file=source, field="intervals",
                          fix="add orientations that tilt gravity towards the missing axes, or fix those parameters")
