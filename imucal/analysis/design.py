"""Pose design: Fisher information of a pose set, Cramér-Rao bound, and optimal poses.

The paper leaves open "the error with which the calibration parameters are estimated" and "the
optimal positions in which to collect the data". Both follow from the residual of the means fit,
r_k = |a_k| - g (end of Section 2: g = a_nonorth), at the true parameters:

  raw_k  = s + b * m_k,  m_k = g E^T u_k         Eq. (theModel), Lemma 1; u_k unit gravity direction
  abar_k = G^-1 m_k = g E^-1 u_k                  Lemma 2 (Tbar = G^-1, G = E^T E)
  dr/ds_i     = -(E^-1 u)_i / b_i                 d|a| = abar . dm / |a|,  dm_i = -ds_i / b_i
  dr/db_i     = -g (E^-1 u)_i (E^T u)_i / b_i     dm_i = -m_i db_i / b_i
  dr/dphi     = g sin(phi)   (E^-1 u)_1 (E^-1 u)_2    d|a|^2 = -abar^T dG abar, Eq. (eq:12)
  dr/dpsi     = g sin(psi)   (E^-1 u)_1 (E^-1 u)_3
  dr/dtheta   = g sin(theta) (E^-1 u)_2 (E^-1 u)_3

With independent noise sigma_k on each residual, the Fisher information is
F = J^T diag(1/sigma^2) J and any unbiased estimator has covariance >= F^-1 (Cramér-Rao).

Design criteria are evaluated in acceleration-equivalent units, so that A and E do not depend on
the raw unit: shifts as s_i/b_i [m/s^2], scales as g b_i / b_i0 [m/s^2], angles as g * angle
[m/s^2]; every sensitivity is then O(1) (for an ideal sensor: -u_i, -u_i^2, u_i u_j).
D (max log det F) is invariant to that choice; A (min trace F^-1) is the summed variance of the
nine error terms; E (max smallest eigenvalue) bounds the worst-determined combination. Criterion
values are reported for unit noise (F's noise factor 1/sigma^2 taken out).

Optimiser: coordinate exchange (Meyer & Nachtsheim 1995) over a dense Fibonacci grid on the
sphere plus the 26 cube directions, with closed-form rank-one updates (matrix determinant lemma
for D, Sherman-Morrison for A), several seeded starts, then a continuous pattern search per pose
on the sphere. Why not an IPOPT NLP over spherical angles: log det of a 9x9 symbolic matrix is
costly to differentiate, the problem has many equivalent local optima (the cube's 48 symmetries),
E is not differentiable where eigenvalues coincide (at the symmetric schemes, where its optima
lie), and the exchange step needs no derivatives and is exact for the rank-one structure. Exchange
finds the basin; the pattern search removes the grid's discretisation (~8 deg spacing).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Mapping, Sequence

import numpy as np

from imucal.constants import RIGHT_ANGLE, STANDARD_GRAVITY
from imucal.errors import ImucalError, short
from imucal.config.limits import (MAX_DESIGN_GRID, MAX_DESIGN_POSES, MAX_RANDOM_SETS, MAX_SIM_POSES, MAX_STARTS, check_count,
                     check_seed)
from imucal.solve.observability import distinct_directions
from imucal.model.parameters import ANGLE_NAMES, BASE_NAMES
from imucal.analysis.simulate import frame_matrix
from imucal.analysis.simulate import cube_directions
from imucal.analysis.simulate import random_directions

#: Design criteria: D (max log det F), A (min trace F^-1), E (max smallest eigenvalue of F).
CRITERIA = ("D", "A", "E")
#: Default noise of |a| - g per interval mean [m/s^2]: an MPU-6050 (~0.04 m/s^2 per sample)
#: held still for 4 s at 100 Hz (400 samples) gives ~0.002 m/s^2.
DEFAULT_NOISE = 0.002
#: Noise of |a| - g per interval mean that a design is scored at [m/s^2]: from 1e-9 (a nano-g, below any
#: accelerometer's mean of a hold) to 100 (ten g: no still pose); outside it F = J^T J / noise^2
#: overflows or underflows double precision and the scores mean nothing.
NOISE_RANGE = (1e-9, 100.0)
#: Parameters of the 6-parameter model (angles fixed at 90 deg).
SIX_NAMES = BASE_NAMES[:6]
#: Tilt of the wedge for the "wedge-24" scheme [deg]; 30.36 deg toward the face diagonals puts the
#: 24 directions on the vertices of a rhombicuboctahedron.
WEDGE_TILT_DEG = math.degrees(math.acos((1 + math.sqrt(2)) / math.sqrt(2 + (1 + math.sqrt(2)) ** 2)))


# --- the sensor at which information is evaluated ---------------------------------------------
@dataclass(frozen=True)
class DesignSensor:
    """The nine parameters at which the information is evaluated (default: an ideal SI sensor)."""

    s: tuple[float, float, float] = (0.0, 0.0, 0.0)  #: shifts [raw]
    b: tuple[float, float, float] = (1.0, 1.0, 1.0)  #: scales [raw per m/s^2]
    angles: tuple[float, float, float] = (RIGHT_ANGLE,) * 3  #: phi, psi, theta [rad]

    @classmethod
    def from_values(cls, values: Mapping[str, float]) -> "DesignSensor":
        return cls(s=tuple(float(values[f"s{i}"]) for i in (1, 2, 3)),  # type: ignore[arg-type]
                   b=tuple(float(values[f"b{i}"]) for i in (1, 2, 3)),
                   angles=tuple(float(values[a]) for a in ANGLE_NAMES))

    def values(self) -> dict[str, float]:
        v = {f"s{i+1}": float(self.s[i]) for i in range(3)}
        v.update({f"b{i+1}": float(self.b[i]) for i in range(3)})
        v.update(dict(zip(ANGLE_NAMES, map(float, self.angles))))
        return v

    def column_scale(self, gravity: float) -> np.ndarray:
        """Factors c with J_norm = J * c: parameters in acceleration-equivalent units [m/s^2]."""
        b = np.asarray(self.b, float)
        return np.concatenate([b, b / gravity, np.full(3, 1.0 / gravity)])


def _frame(angles: Sequence[float]) -> np.ndarray:

    return frame_matrix(np.asarray(angles, float))


def unit_rows(directions: np.ndarray) -> np.ndarray:
    d = np.atleast_2d(np.asarray(directions, float))
    if d.ndim != 2 or d.shape[1] != 3:
        raise ImucalError(f"directions must be an (n, 3) array, got shape {short(d.shape)}", field="poses",
                          fix="give one [x, y, z] direction per pose")
    if d.shape[0] > MAX_SIM_POSES:
        raise ImucalError(f"{d.shape[0]} poses, above the limit of {MAX_SIM_POSES}", field="poses",
                          fix="a calibration needs tens of poses")
    top = np.max(np.abs(d), axis=1, keepdims=True) if d.size else np.ones((0, 1))
    if not np.all(np.isfinite(d)) or np.any(top == 0):
        raise ImucalError("every pose must be a finite non-zero vector", field="poses",
                          fix="give each pose as the direction of gravity in the sensor frame, e.g. [0, 0, 1]")
    d = d / top  # scaled first: the norm of [1e308, 1e308, 0] overflows
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def sensitivity(directions: np.ndarray, sensor: DesignSensor = DesignSensor(),
                gravity: float = STANDARD_GRAVITY) -> np.ndarray:
    """dr/dp (n x 9, parameter order s1 s2 s3 b1 b2 b3 phi psi theta) at the truth, closed form."""
    u = unit_rows(directions)
    E = _frame(sensor.angles)
    b = np.asarray(sensor.b, float)
    w = np.linalg.solve(E, u.T).T  # E^-1 u: affine coordinates of the unit gravity (Lemma 2)
    m = gravity * u @ E  # m_i = g e_i . u (Lemma 1)
    sa = np.sin(np.asarray(sensor.angles, float))
    J = np.empty((u.shape[0], 9))
    J[:, 0:3] = -w / b  # shifts
    J[:, 3:6] = -w * m / b  # scales
    J[:, 6] = gravity * sa[0] * w[:, 0] * w[:, 1]  # phi: angle(x, y)
    J[:, 7] = gravity * sa[1] * w[:, 0] * w[:, 2]  # psi: angle(x, z)
    J[:, 8] = gravity * sa[2] * w[:, 1] * w[:, 2]  # theta: angle(y, z)
    return J


def residual_sigma(directions: np.ndarray, raw_std: Sequence[float] | np.ndarray,
                   sensor: DesignSensor = DesignSensor(), gravity: float = STANDARD_GRAVITY) -> np.ndarray:
    """Noise of |a| - g per pose from the raw noise of the interval mean: dr/draw = -dr/ds."""
    J = sensitivity(directions, sensor, gravity)
    rs = np.broadcast_to(np.asarray(raw_std, float), (J.shape[0], 3))
    return np.sqrt(np.sum((J[:, :3] * rs) ** 2, axis=1))


def _select(free: Sequence[str]) -> list[int]:
    bad = [n for n in free if n not in BASE_NAMES]
    if bad:
        raise ImucalError(f"unknown parameter(s) {bad}", field="free", fix=f"choose from {', '.join(BASE_NAMES)}")
    return [BASE_NAMES.index(n) for n in free]


def fisher(directions: np.ndarray, sigma: float | np.ndarray, sensor: DesignSensor = DesignSensor(),
           gravity: float = STANDARD_GRAVITY, free: Sequence[str] = BASE_NAMES) -> np.ndarray:
    """Fisher information F = J^T diag(1/sigma^2) J over ``free`` (natural units)."""
    J = sensitivity(directions, sensor, gravity)[:, _select(free)]
    sig = np.broadcast_to(np.asarray(sigma, float), (J.shape[0],))
    Jw = J / sig[:, None]
    return Jw.T @ Jw


def crlb(F: np.ndarray, free: Sequence[str] = BASE_NAMES) -> np.ndarray:
    """Cramér-Rao bound F^-1; refuses a singular F naming the undetermined parameters."""
    c = np.sqrt(np.clip(np.diag(F), 1e-300, None))
    Fn = F / np.outer(c, c)
    w, V = np.linalg.eigh(Fn)
    null = w <= 1e-10 * max(w[-1], 1e-300)
    if null.any():
        und = [free[j] for j in np.flatnonzero(np.abs(V[:, null]).max(axis=1) > 0.3)]
        raise ImucalError(f"the poses leave {', '.join(und) or 'some parameters'} undetermined "
                          "(Fisher information is singular)", field="poses",
                          fix="add orientations with gravity between the axes, e.g. the 12 cube edges")
    return np.linalg.inv(Fn) / np.outer(c, c)


def criterion_value(F_norm: np.ndarray, criterion: str) -> float:
    """D: log det F; A: trace F^-1; E: smallest eigenvalue (F in acceleration-equivalent units)."""
    w = np.linalg.eigvalsh(F_norm)
    if criterion == "D":
        return float(np.sum(np.log(w))) if w[0] > 0 else -math.inf
    if criterion == "A":
        return float(np.sum(1.0 / w)) if w[0] > 0 else math.inf
    if criterion == "E":
        return float(w[0])
    raise ImucalError(f"unknown criterion {short(criterion)}", field="criterion", fix="use D, A or E")


# --- standard schemes -------------------------------------------------------------------------
def wedge_directions(tilt_deg: float = WEDGE_TILT_DEG) -> np.ndarray:
    """6 faces x 4 turns about the vertical with the cube on a wedge tilted toward its face diagonals.

    Flat (tilt 0) this is the common "24-position" scheme, whose gravity directions are only the 6
    face normals; on the wedge the 24 directions are distinct.
    """

    t = math.radians(tilt_deg)
    out = []
    for n in cube_directions("faces"):
        a = np.flatnonzero(n == 0)  # the two in-face axes
        for sx, sy in ((1, 1), (-1, 1), (-1, -1), (1, -1)):  # 4 turns of 90 deg
            d = np.zeros(3)
            d[a[0]], d[a[1]] = sx, sy
            out.append(math.cos(t) * n + math.sin(t) * d / math.sqrt(2))
    return np.array(out)


def scheme_directions(name: str) -> np.ndarray:
    """Named pose schemes: faces (6), edges (12), corners (8), faces+edges (18), cube-24 (6 faces x 4
    turns, flat: 6 distinct directions), wedge-24 (the same on a 30 deg wedge: 24 distinct), cube-26."""

    if name == "cube-24":
        return np.repeat(cube_directions("faces"), 4, axis=0)
    if name == "wedge-24":
        return wedge_directions()
    if name == "cube-26":
        return cube_directions("faces+edges+corners")
    parts = name.split("+")
    if parts and all(p in ("faces", "edges", "corners") for p in parts):
        return cube_directions(name)
    raise ImucalError(f"unknown scheme {short(name)}", field="scheme",
                      fix="use faces, edges, corners, faces+edges, cube-24, wedge-24 or cube-26")


#: Common schemes and their pose counts.
SCHEMES = {"faces": 6, "corners": 8, "edges": 12, "faces+edges": 18, "cube-24": 24, "wedge-24": 24,
           "cube-26": 26}


# --- a scored design --------------------------------------------------------------------------
@dataclass(frozen=True)
class Design:
    """A pose set scored for the model's free parameters."""

    directions: np.ndarray  #: (n, 3) unit gravity directions in the sensor frame
    criterion: str
    value: float  #: criterion in acceleration-equivalent units (see module docstring)
    log_det_fisher: float  #: log det F in natural units at ``noise``
    std: dict[str, float]  #: predicted standard error per free parameter (natural units)
    free: tuple[str, ...]
    noise: float  #: noise of |a| - g per pose [m/s^2]
    n_distinct: int
    label: str = ""
    meta: dict = field(default_factory=dict)

    @property
    def n(self) -> int:
        return int(self.directions.shape[0])

    @property
    def det_fisher(self) -> float:
        return math.exp(self.log_det_fisher) if self.log_det_fisher < 700 else math.inf

    def d_efficiency(self, other: "Design") -> float:
        """(det F_self / det F_other)^(1/p): >1 means this design is better per parameter."""
        return math.exp((self.log_det_fisher - other.log_det_fisher) / len(self.free))

    def to_json(self) -> dict:
        return {"format": "imucal-pose-plan", "format_version": 1, "criterion": self.criterion,
                "n": self.n, "n_distinct": self.n_distinct, "noise_m_s2": self.noise,
                "free": list(self.free), "criterion_value": self.value,
                "log_det_fisher": self.log_det_fisher,
                "predicted_std": self.std, "label": self.label,
                "poses": [[float(x) for x in d] for d in self.directions]}


def efficiency(design: Design, best: Design) -> float:
    """How near ``design`` comes to ``best`` on their criterion (1: as good; 0.97: it needs 1/0.97 times
    the recordings to match): D (det F / det F_best)^(1/p), A trace F_best^-1 / trace F^-1, E
    lambda_min(F) / lambda_min(F_best)."""
    if design.criterion != best.criterion or design.free != best.free:
        raise ImucalError("designs scored on different criteria or parameters cannot be compared",
                          field="criterion", fix="score both with the same --criterion and model")
    if design.criterion == "D":
        return design.d_efficiency(best)
    return best.value / design.value if design.criterion == "A" else design.value / best.value


def against_optimum(design: Design, sensor: DesignSensor = DesignSensor(), gravity: float = STANDARD_GRAVITY,
                    seed: int = 0, progress: Callable[[], None] | None = None) -> tuple[float, Design]:
    """``design``'s efficiency against the best design of as many poses that ``optimal_design`` finds
    (the same criterion, noise and parameters), and that design (``design`` itself when no better one
    is found: efficiency 1)."""
    best = optimal_design(design.n, design.criterion, design.noise, sensor, gravity, design.free, seed=seed,
                          progress=progress)
    eff = efficiency(design, best)
    return (1.0, design) if eff >= 1.0 else (eff, best)


def _require_distinct(u: np.ndarray, free: Sequence[str], label: str) -> int:
    k, _ = distinct_directions(u)
    if k < len(free):
        six = len(free) == 9
        raise ImucalError(
            f"only {k} distinct gravity directions for {len(free)} parameters"
            + (": phi, psi, theta cannot be determined" if six else ""),
            field=f"poses{' (' + label + ')' if label else ''}",
            fix=("repeating a pose or turning about the vertical adds no information; use >= 9 distinct "
                 "directions (e.g. the 12 cube edges, or the 24 positions on a 30 deg wedge)"
                 + (", or score the 6-parameter model (--fix-angles)" if six else "")))
    return k


def evaluate(directions: np.ndarray, criterion: str = "D", noise: float = DEFAULT_NOISE,
             sensor: DesignSensor = DesignSensor(), gravity: float = STANDARD_GRAVITY,
             free: Sequence[str] = BASE_NAMES, label: str = "", check_distinct: bool = True) -> Design:
    """Score a pose set: criterion, det F and predicted standard errors at noise ``noise``."""
    if criterion not in CRITERIA:
        raise ImucalError(f"unknown criterion {short(criterion)}", field="criterion", fix="use D, A or E")
    if isinstance(noise, bool) or not isinstance(noise, (int, float)) or not (math.isfinite(noise) and noise > 0):
        raise ImucalError(f"noise {short(noise)} must be a positive number of m/s^2", field="noise",
                          fix=f"give the noise of a pose's mean in m/s^2, e.g. {DEFAULT_NOISE:g}")
    if not NOISE_RANGE[0] <= noise <= NOISE_RANGE[1]:
        raise ImucalError(f"noise {noise:g} m/s^2 per interval mean is outside {NOISE_RANGE[0]:g} to "
                          f"{NOISE_RANGE[1]:g} m/s^2", field="noise",
                          fix="give the noise of |a| - g of one pose's mean, e.g. 0.002 for a MEMS held 4 s")
    u = unit_rows(directions)
    free = tuple(free)
    k = _require_distinct(u, free, label) if check_distinct else distinct_directions(u)[0]
    idx = _select(free)
    F = fisher(u, noise, sensor, gravity, free)
    C = crlb(F, free)
    c = sensor.column_scale(gravity)[idx]
    Fn = F * np.outer(c, c) * noise**2  # unit noise, acceleration-equivalent units
    sign, logdet = np.linalg.slogdet(F)
    return Design(directions=u, criterion=criterion, value=criterion_value(Fn, criterion),
                  log_det_fisher=float(logdet) if sign > 0 else -math.inf,
                  std={n: float(math.sqrt(C[i, i])) for i, n in enumerate(free)}, free=free,
                  noise=float(noise), n_distinct=k, label=label)


# --- the optimiser ----------------------------------------------------------------------------
def fibonacci_sphere(n: int) -> np.ndarray:
    """n nearly uniform unit vectors (golden-angle spiral)."""
    i = np.arange(n) + 0.5
    z = 1 - 2 * i / n
    r = np.sqrt(1 - z * z)
    phi = math.pi * (3 - math.sqrt(5)) * i
    return np.column_stack([r * np.cos(phi), r * np.sin(phi), z])


class _Scorer:
    """Criterion of F_rest + j j^T for many candidate rows j at once (rank-one updates).

    Values are signed so that larger is better. A rank-deficient matrix scores by its rank first
    (1e12 per missing rank), so that exchange can start from a singular pose set.
    """

    def __init__(self, criterion: str, p: int) -> None:
        self.criterion, self.p = criterion, p

    def score(self, F: np.ndarray) -> float:
        return float(self.batch(F, np.zeros((1, self.p)))[0])

    def batch(self, F_rest: np.ndarray, rows: np.ndarray) -> np.ndarray:
        crit = self.criterion
        if crit in ("D", "A"):
            w = np.linalg.eigvalsh(F_rest)
            if w[0] > 1e-9 * max(w[-1], 1e-300):
                Fi = np.linalg.inv(F_rest)
                y = rows @ Fi
                q = np.einsum("ij,ij->i", y, rows)
                if crit == "D":  # matrix determinant lemma: det(F + r r^T) = det F (1 + r^T F^-1 r)
                    return np.sum(np.log(w)) + np.log1p(q)
                # Sherman-Morrison: tr (F + r r^T)^-1 = tr F^-1 - |F^-1 r|^2 / (1 + r^T F^-1 r)
                return -(np.sum(1 / w) - np.einsum("ij,ij->i", y, y) / (1 + q))
        Fc = F_rest[None] + rows[:, :, None] * rows[:, None, :]
        w = np.linalg.eigvalsh(Fc)
        if crit == "E":
            return w[:, 0]
        tol = 1e-10 * max(float(np.max(w[:, -1])), 1e-300)
        big = w > tol
        missing = self.p - np.sum(big, axis=1)
        wv = np.where(big, w, 1.0)
        if crit == "D":
            return np.sum(np.log(wv), axis=1) - 1e12 * missing
        return np.where(missing == 0, -np.sum(1 / wv, axis=1), -1e12 * missing - 1e9)


class _RowMap:
    """Normalised sensitivity rows for many directions, with the sensor's matrices precomputed."""

    def __init__(self, sensor: DesignSensor, gravity: float, idx: list[int], c: np.ndarray) -> None:
        E = _frame(sensor.angles)
        self.EinvT = np.linalg.inv(E).T
        self.gE = gravity * E
        self.b = np.asarray(sensor.b, float)
        self.gs = gravity * np.sin(np.asarray(sensor.angles, float))
        self.idx, self.c = idx, c

    def __call__(self, u: np.ndarray) -> np.ndarray:
        w = u @ self.EinvT  # E^-1 u
        m = u @ self.gE
        J = np.concatenate([-w / self.b, -w * m / self.b,
                            self.gs * (w[:, [0, 0, 1]] * w[:, [1, 2, 2]])], axis=1)  # as sensitivity()
        return J[:, self.idx] * self.c


def _exchange(cand: np.ndarray, rows_c: np.ndarray, start: np.ndarray, scorer: _Scorer,
              distinct: bool, max_sweeps: int = 50) -> tuple[np.ndarray, float]:
    """Coordinate exchange over candidate indices; returns the indices and the signed score."""
    idx = start.copy()
    F = rows_c[idx].T @ rows_c[idx]
    best = scorer.score(F)
    for _ in range(max_sweeps):
        improved = False
        for k in range(idx.size):
            r = rows_c[idx[k]]
            F_rest = F - np.outer(r, r)
            v = scorer.batch(F_rest, rows_c)
            if distinct:
                others = np.delete(idx, k)
                v[others] = -np.inf
            j = int(np.argmax(v))
            if j != idx[k] and v[j] > best + 1e-10 * max(1.0, abs(best)):
                idx[k] = j
                F = F_rest + np.outer(rows_c[j], rows_c[j])
                best = scorer.score(F)
                improved = True
        if not improved:
            break
    return idx, scorer.score(rows_c[idx].T @ rows_c[idx])


def _tangent_basis(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    a = np.array([1.0, 0, 0]) if abs(u[0]) < 0.9 else np.array([0, 1.0, 0])
    t1 = a - (a @ u) * u
    t1 /= math.sqrt(t1 @ t1)
    t2 = np.array([u[1] * t1[2] - u[2] * t1[1], u[2] * t1[0] - u[0] * t1[2], u[0] * t1[1] - u[1] * t1[0]])
    return t1, t2


def _refine(U: np.ndarray, scorer: _Scorer, rowfn: _RowMap, step0: float = 0.05, step_min: float = 1e-6,
            max_rounds: int = 400) -> tuple[np.ndarray, float]:
    """Continuous pattern search on the sphere, one pose at a time with its own step size.

    Each round tries 8 moves of every pose at its step; success grows the step, failure halves
    it; stops when every step is below ``step_min`` [rad].
    """
    U = U.copy()
    R = rowfn(U)
    F = R.T @ R
    best = scorer.score(F)
    ang = np.linspace(0, 2 * math.pi, 8, endpoint=False)
    cs, sn = np.cos(ang)[:, None], np.sin(ang)[:, None]
    steps = np.full(U.shape[0], step0)
    for _ in range(max_rounds):
        if np.all(steps < step_min):
            break
        for k in np.flatnonzero(steps >= step_min):
            F_rest = F - np.outer(R[k], R[k])
            t1, t2 = _tangent_basis(U[k])
            cand = U[k] + steps[k] * (cs * t1 + sn * t2)
            cand /= np.linalg.norm(cand, axis=1, keepdims=True)
            rc = rowfn(cand)
            v = scorer.batch(F_rest, rc)
            j = int(np.argmax(v))
            if v[j] > best + 1e-14 * max(1.0, abs(best)):
                U[k], R[k] = cand[j], rc[j]
                F = F_rest + np.outer(R[k], R[k])
                best = scorer.score(F)
                steps[k] = min(steps[k] * 1.5, step0)
            else:
                steps[k] *= 0.5
    return U, best


def _setup(n: int, criterion: str, sensor: DesignSensor, gravity: float, free: tuple[str, ...]
           ) -> tuple[_Scorer, _RowMap]:
    if criterion not in CRITERIA:
        raise ImucalError(f"unknown criterion {short(criterion)}", field="criterion", fix="use D, A or E")
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < len(free):
        raise ImucalError(f"{n} poses cannot determine {len(free)} parameters", field="n",
                          fix=f"ask for at least {len(free)} poses (12 or more leave room to check the fit)")
    if n > MAX_DESIGN_POSES:
        raise ImucalError(f"{n} poses is more than a calibration needs", field="n",
                          fix=f"ask for at most {MAX_DESIGN_POSES}")
    idx_p = _select(free)
    return _Scorer(criterion, len(free)), _RowMap(sensor, gravity, idx_p, sensor.column_scale(gravity)[idx_p])


def _refined(U: np.ndarray, scorer: _Scorer, rowfn: _RowMap, step: Callable[[], None] | None):
    """_refine, then one progress step."""
    out = _refine(U, scorer, rowfn)
    if step is not None:
        step()
    return out


def _exchange_starts(cand: np.ndarray, n: int, scorer: _Scorer, rowfn: _RowMap, rng: np.random.Generator,
                     starts: int, distinct: bool, step: Callable[[], None] | None = None
                     ) -> list[tuple[float, np.ndarray]]:
    rows_c = rowfn(cand)
    found = []
    for _ in range(max(1, starts)):
        start = rng.choice(cand.shape[0], size=n, replace=n > cand.shape[0])
        idx, v = _exchange(cand, rows_c, start, scorer, distinct)
        found.append((v, cand[idx]))
        if step is not None:
            step()
    return sorted(found, key=lambda t: -t[0])


def best_cube_subset(n: int, criterion: str = "D", noise: float = DEFAULT_NOISE,
                     sensor: DesignSensor = DesignSensor(), gravity: float = STANDARD_GRAVITY,
                     free: Sequence[str] = BASE_NAMES, seed: int = 0, starts: int = 20) -> Design:
    """The best n distinct directions among the 26 of a cube (faces, edges, corners), by exchange."""

    free = tuple(free)
    scorer, rowfn = _setup(n, criterion, sensor, gravity, free)
    check_count(starts, "starts", 1, MAX_STARTS)
    if n > 26:
        raise ImucalError(f"a cube has 26 directions, not {n}", field="n",
                          fix="ask for at most 26 directions of the cube")
    v, U = _exchange_starts(cube_directions("faces+edges+corners"), n, scorer, rowfn,
                            np.random.default_rng(check_seed(seed)), starts, distinct=True)[0]
    return evaluate(U, criterion, noise, sensor, gravity, free, label="best cube subset", check_distinct=False)


def optimal_design(n: int, criterion: str = "D", noise: float = DEFAULT_NOISE,
                   sensor: DesignSensor = DesignSensor(), gravity: float = STANDARD_GRAVITY,
                   free: Sequence[str] = BASE_NAMES, seed: int = 0, starts: int = 6, grid: int = 600,
                   progress: Callable[[], None] | None = None) -> Design:
    """N poses maximising the information on the free parameters.

    Coordinate exchange from ``starts`` seeded random subsets of a Fibonacci grid (plus the 26 cube
    directions); the common schemes with N poses and the best N-subset of the cube directions join
    as starting designs; the best three are polished by a pattern search on the sphere. The result
    therefore never scores below those schemes. ``progress`` is called after each start and each
    polish (``starts`` + 3 calls; imucal.report.progress).
    """

    free = tuple(free)
    scorer, rowfn = _setup(n, criterion, sensor, gravity, free)
    check_count(starts, "starts", 1, MAX_STARTS)
    check_count(grid, "grid", 1, MAX_DESIGN_GRID)
    rng = np.random.default_rng(check_seed(seed))
    cand = np.vstack([cube_directions("faces+edges+corners"), fibonacci_sphere(grid)])
    found = _exchange_starts(cand, n, scorer, rowfn, rng, starts, distinct=False, step=progress)
    seeds = [scheme_directions(k) for k, m in SCHEMES.items() if m == n]
    if n <= 26:
        seeds.append(best_cube_subset(n, criterion, noise, sensor, gravity, free, seed=seed).directions)
    for U in seeds:
        R = rowfn(U)
        found.append((scorer.score(R.T @ R), U))
    found.sort(key=lambda t: -t[0])
    # polish the three best off the grid; refinement only improves a design
    best_u, _ = max((_refined(U, scorer, rowfn, progress) for _, U in found[:3]), key=lambda t: t[1])
    d = evaluate(best_u, criterion, noise, sensor, gravity, free, label=f"planned-{criterion}",
                 check_distinct=False)
    return Design(**{**d.__dict__, "meta": {"seed": seed, "starts": starts, "grid": grid}})


def random_design(n: int, rng: np.random.Generator, criterion: str = "D", noise: float = DEFAULT_NOISE,
                  sensor: DesignSensor = DesignSensor(), gravity: float = STANDARD_GRAVITY,
                  free: Sequence[str] = BASE_NAMES) -> Design:
    """A design of n uniformly random directions (not checked for distinctness)."""

    return evaluate(random_directions(n, rng), criterion, noise, sensor, gravity, free, label="random",
                    check_distinct=False)


@dataclass(frozen=True)
class Comparison:
    """Planned design beside common schemes, best cube subsets and random sets at the same N."""

    planned: Design
    others: list[Design]
    random_median: float  #: median criterion over random sets
    random_best: float  #: best criterion over random sets
    n_random: int


def compare(planned: Design, sensor: DesignSensor = DesignSensor(), gravity: float = STANDARD_GRAVITY,
            n_random: int = 200, seed: int = 0, cube_subset: bool = True) -> Comparison:
    """Score the common schemes with planned.n poses, the best subset of the 26 cube directions
    (exchange, several starts) and random sets, on the planned design's criterion and noise."""
    n, crit, free = planned.n, planned.criterion, planned.free
    check_count(n_random, "n_random", 0, MAX_RANDOM_SETS)
    check_seed(seed)
    others: list[Design] = []
    for name, k in SCHEMES.items():
        if k != n or name == planned.label:
            continue
        try:
            others.append(evaluate(scheme_directions(name), crit, planned.noise, sensor, gravity, free, label=name))
        except ImucalError:
            pass  # e.g. cube-24: only 6 distinct directions (reported by evaluate when asked)
    if cube_subset and n <= 26:
        others.append(best_cube_subset(n, crit, planned.noise, sensor, gravity, free, seed=seed))
    rng = np.random.default_rng(seed)
    vals = []
    for _ in range(n_random):
        try:
            vals.append(random_design(n, rng, crit, planned.noise, sensor, gravity, free).value)
        except ImucalError:
            vals.append(-math.inf if crit != "A" else math.inf)
    vals_a = np.array(vals)
    best = float(vals_a.min() if crit == "A" else vals_a.max())
    return Comparison(planned, others, float(np.median(vals_a)), best, n_random)
