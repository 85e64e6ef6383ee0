"""What real magnetometer logs do, said rather than hidden.

  coverage     a log that turns the sensor through too few directions leaves parameters undetermined:
               refused, naming the directions to add (the observability check of the field-norm fit,
               imucal.solve.observability, on the accelerometer's thresholds)
  field steps  a field whose magnitude steps between poses (a steel desk, a laptop, a car): the poses'
               mean |h| - F in time order, a CUSUM test against the scatter of successive poses (which a
               step does not inflate), and single poses far off the rest; both named with the poses
"""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from imucal.errors import ImucalError
from imucal.mag.evidence import MAD_TO_STD, MagRows, Poses
from imucal.model.sensor import SensorModel
from imucal.model.parameters import Parameters
from imucal.solve import least_squares as lsq
from imucal.solve import observability

#: Rows (evenly spaced samples) the coverage check looks at: its cost is linear in them.
COVERAGE_ROWS = 2000
#: [raw] An axis whose readings span less holds no field the fit can resolve (its absolute tolerances and the
#: observability thresholds lose it below about 1e-15; a log in tesla spans some 1e-4).
MIN_SPAN = 1e-12
#: A direction is covered when a recorded field direction lies within this angle of it [deg].
COVERED_DEG = 30.0
#: CUSUM test of a step in the field: significance.
STEP_LEVEL = 1e-3
#: A step or a single pose is reported only above this fraction of the field (0.5 %: below the
#: residual of a good hard/soft-iron fit, a step changes nothing a user could act on).
MIN_STEP_FRACTION = 0.005
#: A single pose is off the rest above this many robust standard deviations of the poses about their level.
OUTLIER_Z = 5.0


def _direction_words(d: np.ndarray) -> str:
    return "".join(f"{'+' if v > 0 else '-'}{'xyz'[i]}" for i, v in enumerate(d) if v != 0)


#: The 26 directions of a cube's faces, edges and corners, in the sensor's axes.
CANDIDATES = tuple(np.array(v, float) for v in itertools.product((-1, 0, 1), repeat=3) if any(v))


def require_span(mag: np.ndarray, source: str | None = None) -> None:
    """Refuse readings that hardly change on an axis (a constant column, or values near the smallest floats):
    below MIN_SPAN the fit's absolute tolerances cannot resolve a field turning with the sensor."""
    span = np.ptp(mag, axis=0) if len(mag) else np.zeros(3)
    if not (span >= MIN_SPAN).all():
        i = int(np.argmin(span))
        raise ImucalError(f"m{'xyz'[i]} spans only {span[i]:.3g} over the log: not a field turning with the sensor",
                          file=source, field="mx, my, mz",
                          fix="check that mx, my, mz hold the magnetometer, and turn the sensor through many "
                              "orientations")


def missing_directions(directions: np.ndarray) -> list[str]:
    """The cube directions no recorded field direction comes within COVERED_DEG of: the faces (the axes both
    ways) when any is missing, else the edges, else the corners (what to add first)."""
    norm = np.linalg.norm(directions, axis=1, keepdims=True)
    seen = np.isfinite(norm[:, 0]) & (norm[:, 0] > 0)  # a reading at the centre has no direction
    u = directions[seen] / norm[seen]
    cos_min = math.cos(math.radians(COVERED_DEG))
    for order in (1, 2, 3):  # faces, edges, corners
        out = [_direction_words(c) for c in CANDIDATES
               if np.count_nonzero(c) == order and np.max(u @ (c / np.linalg.norm(c)), initial=-1.0) < cos_min]
        if out:
            return out
    return []


def require_coverage(model: SensorModel, rows: MagRows, params: Parameters, source: str | None = None
                     ) -> observability.Observability:
    """Refuse a log whose field directions leave the hard and soft iron undetermined (NORM rows only).

    ``params``: the initial guess with only the nine ellipsoid parameters free."""
    norm = np.flatnonzero(rows.kind == 0)
    pick = norm[np.linspace(0, len(norm) - 1, min(len(norm), COVERAGE_ROWS)).astype(int)]
    sub = rows.subset(pick)
    free = params.free_names
    fns = lsq.row_functions(model, free)
    pfix = np.array(params.values(), float)
    pfree = np.array([params[n].value for n in free])
    _, J, Jraw = lsq.jacobians(fns, lsq.Rows(sub.raw, sub.cov), pfree, pfix, sub.target)
    J = J * np.array([params[n].scale for n in free])
    sigma = np.sqrt(np.sum(Jraw**2 * sub.var_raw, axis=1))
    sigma = np.maximum(sigma, max(float(np.median(sigma)) * 1e-3, 1e-300))
    weighted = J / sigma[:, None] * math.sqrt(len(norm) / len(pick))  # the fit sees every sample
    s0 = np.array([params[f"s{i}"].value for i in (1, 2, 3)])
    directions = sub.raw - s0
    directions /= np.maximum(np.linalg.norm(directions, axis=1, keepdims=True), np.finfo(float).tiny)
    angle_tol = params["phi"].upper / (math.pi / 2) - 1.0
    obs = observability.analyse(directions, J, free, weighted, observability.thresholds(params, free, angle_tol))
    if obs.undetermined or obs.n_distinct < len(free):
        raise coverage_error(directions, f"({obs.n_distinct} distinct) leave "
                             f"{', '.join(obs.undetermined) or 'the hard and soft iron'}", source)
    return obs


def coverage_error(directions: np.ndarray, what: str, source: str | None) -> ImucalError:
    """The one message for a log whose field directions do not determine the calibration: what they leave
    undetermined and the directions to add (``missing_directions``)."""
    add = missing_directions(directions)
    where = (f"turn the sensor so that the field also lies along {', '.join(add)} of its axes"
             if add else "turn the sensor through more orientations, the field along every axis both ways")
    return ImucalError(f"the field's directions {what} undetermined", file=source, field="mx, my, mz", fix=where)


@dataclass(frozen=True)
class PoseOffset:
    """One pose whose field differs from the rest."""

    pose: int
    start: int  #: first sample
    end: int  #: one past the last
    offset: float  #: its mean |h| - F over the field [fraction]


@dataclass(frozen=True)
class FieldSteps:
    """The poses' field magnitudes tested for steps (a disturbed environment)."""

    statistic: float  #: the CUSUM maximum in robust standard deviations times sqrt(poses)
    p: float  #: its p-value (Kolmogorov's distribution of a Brownian bridge's maximum)
    step_after: int | None  #: the last pose before the step, when one is found
    step: float  #: the mean after minus the mean before, over the field [fraction]
    outliers: tuple[PoseOffset, ...]  #: single poses far off the rest
    after: tuple[PoseOffset, ...]  #: the poses after the step

    @property
    def disturbed(self) -> bool:
        return self.step_after is not None or bool(self.outliers)


def _kolmogorov_sf(x: float) -> float:
    """P(sup |Brownian bridge| > x) = 2 sum_j (-1)^(j-1) exp(-2 j^2 x^2)."""
    if x <= 0.2:
        return 1.0
    return float(min(1.0, 2 * sum((-1) ** (j - 1) * math.exp(-2 * j * j * x * x) for j in range(1, 101))))


def _outliers(r: np.ndarray, level: np.ndarray, among: np.ndarray) -> np.ndarray:
    """Poses off their level by more than OUTLIER_Z robust standard deviations of the poses ``among`` (and
    by more than MIN_STEP_FRACTION): their spread, not successive differences (the windows of a moving log
    are alike, so differences would understate it)."""
    d = r - level
    spread = max(MAD_TO_STD * float(np.median(np.abs(d[among] - np.median(d[among])))), 1e-12)
    return (np.abs(d) / spread > OUTLIER_Z) & (np.abs(d) > MIN_STEP_FRACTION)


def field_steps(offsets: np.ndarray, poses: Poses) -> FieldSteps:
    """Test the poses' mean |h| - F (over F, in time order) for a step and for single poses off the rest.

    Single poses are found about the median first and left out of the step test (one pose far off would
    otherwise read as a step beside it); with a step, they are found again about each side's level."""
    r = np.asarray(offsets, float)
    n = len(r)
    if n < 4:
        return FieldSteps(0.0, 1.0, None, 0.0, (), ())
    everyone = np.ones(n, bool)
    rest = np.flatnonzero(~_outliers(r, np.full(n, np.median(r)), everyone))
    q = r[rest]
    s = MAD_TO_STD * float(np.median(np.abs(np.diff(q) - np.median(np.diff(q))))) / math.sqrt(2)
    s = max(s, 1e-12)  # successive differences: a step does not inflate them
    cs = np.cumsum(q - q.mean())
    k = int(np.argmax(np.abs(cs[:-1])))
    stat = float(np.abs(cs[k]) / (s * math.sqrt(len(q))))
    p = _kolmogorov_sf(stat)
    step = float(q[k + 1:].mean() - q[:k + 1].mean())
    found = p < STEP_LEVEL and abs(step) > MIN_STEP_FRACTION
    last = int(rest[k])  # the last pose before the step

    def offset(j: int) -> PoseOffset:
        return PoseOffset(j, int(poses.start[j]), int(poses.end[j]), float(r[j]))

    level = (np.where(np.arange(n) > last, q[k + 1:].mean(), q[:k + 1].mean()) if found
             else np.full(n, np.median(r)))
    out = _outliers(r, level, np.isin(np.arange(n), rest))
    after = tuple(offset(j) for j in range(last + 1, n) if not out[j]) if found else ()
    return FieldSteps(stat, p, last if found else None, step if found else 0.0,
                      tuple(offset(j) for j in np.flatnonzero(out)), after)
