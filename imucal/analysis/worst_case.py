"""Worst-case error of ignoring the axes' non-orthogonality (paper, Section 4), certified.

Notation: m_i = e_i . a are the measured values (Lemma 1), a_orth = |m| (Proposition 1),
a_nonorth = sqrt(m^T G^-1 m) (Proposition 2), G the Gram matrix of the unit axes (Eq. eq:12).

Certificate (docs/worst_case.md). For m != 0 the Rayleigh quotient of G^-1 gives
    lambda_min(G) <= (a_orth / a_nonorth)^2 = m^T m / m^T G^-1 m <= lambda_max(G),
with equality along the eigenvectors, so over an angle box B
    max |a_nonorth - a_orth| / a_nonorth = max(1 - sqrt(lmin), sqrt(lmax) - 1)
with lmin = min_B lambda_min(G), lmax = max_B lambda_max(G). lambda_min(G) = min_|v|=1 v^T G v is
a minimum of functions linear in the cosines, hence concave in them (lambda_max convex); cos is
monotone on (0, pi), so B maps onto a box of cosines with the same vertices and both extremes sit
at one of B's 8 vertices. Problem 1 (a_nonorth = g) is g times this number; Problem 2 is the
number itself, for every range (it depends on the direction of m only).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any, Sequence

import numpy as np

from imucal.constants import DEFAULT_ANGLE_TOL, RIGHT_ANGLE, STANDARD_GRAVITY
from imucal.errors import ImucalError
from imucal.model.sensor import gram_np, tbar
from imucal.config.limits import MAX_STARTS, check_count, check_seed
import casadi as ca
from imucal.model.sensor import frame_inverse_transpose

#: Smallest eigenvalue of G accepted anywhere in an angle box: below it the frame is (nearly)
#: degenerate (axes close to coplanar; E^-T amplifies by 1/sqrt(lambda_min) >= 10).
MIN_GRAM_EIGENVALUE = 1e-2
DEFAULT_STARTS = 16
DEFAULT_SEED = 0
#: Allowed |NLP - certificate| on the scaled problems (fractions of g or of |a|); IPOPT tol 1e-10.
CERTIFICATE_TOL = 1e-7
#: Problem 2 excludes |m| < RHO * range (0/0 at m = 0); the relative error depends on the
#: direction of m only, so the maximum is unchanged.
RHO = 0.1
ANGLE_NAMES = ("phi", "psi", "theta")
_OPTS = {"ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes", "ipopt.tol": 1e-10,
         "ipopt.max_iter": 500}
_CONVERGED = ("Solve_Succeeded", "Solved_To_Acceptable_Level")


class CertificateError(RuntimeError):
    """An NLP answer that disagrees with its certificate: an error, never a warning."""



def max_tolerance() -> float:
    """Largest tol with lambda_min(G) >= MIN_GRAM_EIGENVALUE on pi/2 (1 +- tol): 1 - 2 sin(tol pi/2)."""
    return math.asin((1 - MIN_GRAM_EIGENVALUE) / 2) / RIGHT_ANGLE


@dataclass(frozen=True)
class AngleBox:
    """Bounds on (phi, psi, theta) [rad]; refused if outside (0, pi) or if G degenerates in it."""

    lower: tuple[float, float, float]
    upper: tuple[float, float, float]
    label: str = ""

    def __post_init__(self) -> None:
        for name, lo, hi in zip(ANGLE_NAMES, self.lower, self.upper):
            if not (math.isfinite(lo) and math.isfinite(hi)):
                raise ImucalError(f"angle {name} bound is not finite", field=f"angles.{name}",
                                  fix="give finite bounds in (0, pi) rad")
            if not 0 < lo <= hi < math.pi:
                raise ImucalError(f"angle {name} range [{lo:.6g}, {hi:.6g}] rad is outside (0, pi)",
                                  field=f"angles.{name}", fix="give angles near pi/2 = 1.5708 rad")
        b = gram_bounds(self)
        if b.lambda_min < MIN_GRAM_EIGENVALUE:
            at = ", ".join(f"{n}={v:.4f}" for n, v in zip(ANGLE_NAMES, b.at_min))
            raise ImucalError(f"degenerate frame: at {at} rad the Gram matrix's smallest eigenvalue is "
                              f"{b.lambda_min:.3g} (< {MIN_GRAM_EIGENVALUE}: axes nearly coplanar)",
                              field="angles", fix="narrow the angle range towards pi/2")

    @classmethod
    def from_tolerance(cls, tol: float = DEFAULT_ANGLE_TOL) -> "AngleBox":
        """The paper's box pi/2 (1 +- tol) for all three angles."""
        tmax = max_tolerance()
        if not (math.isfinite(tol) and tol > 0):
            raise ImucalError(f"tolerance {tol} must be positive", field="tolerance",
                              fix="use a small fraction such as 0.02 (= 90 deg +- 2 %)")
        if tol >= 1:
            raise ImucalError(f"tolerance {tol} puts the angles pi/2 (1 +- tol) outside (0, pi)",
                              field="tolerance", fix=f"use a tolerance below {tmax:.4f}")
        if not tol <= tmax:
            worst = RIGHT_ANGLE * (1 + tol)
            lam = 1 - 2 * math.sin(tol * RIGHT_ANGLE)
            raise ImucalError(f"tolerance {tol} allows a degenerate frame: at phi=psi=theta={worst:.4f} "
                              f"rad the Gram matrix's smallest eigenvalue is {lam:.3g}",
                              field="tolerance", fix=f"use a tolerance below {tmax:.4f}")
        lo, hi = RIGHT_ANGLE * (1 - tol), RIGHT_ANGLE * (1 + tol)
        return cls((lo,) * 3, (hi,) * 3, f"pi/2 (1 +- {tol:g})")

    @classmethod
    def around(cls, angles: Sequence[float], std: Sequence[float] = (0.0, 0.0, 0.0), k: float = 0.0,
               label: str = "") -> "AngleBox":
        """angles +- k standard errors (k = 0: the angles fixed)."""
        if not (math.isfinite(k) and k >= 0):
            raise ImucalError(f"widening {k} must be a non-negative number of standard errors",
                              field="widen", fix="give 0 or more standard errors, e.g. 2")
        half = [k * s if k > 0 else 0.0 for s in std]
        if any(not math.isfinite(h) for h in half):
            raise ImucalError("an angle's standard error is not finite, cannot widen by it",
                              field="widen", fix="use --widen 0 or a calibration with standard errors")
        return cls(tuple(a - h for a, h in zip(angles, half)),  # type: ignore[arg-type]
                   tuple(a + h for a, h in zip(angles, half)), label)  # type: ignore[arg-type]

    @property
    def mid(self) -> np.ndarray:
        return (np.array(self.lower) + np.array(self.upper)) / 2

    @property
    def half(self) -> np.ndarray:
        return (np.array(self.upper) - np.array(self.lower)) / 2

    def vertices(self) -> np.ndarray:
        """The 8 corners, (8, 3)."""
        idx = np.array([[(k >> i) & 1 for i in range(3)] for k in range(8)])
        return np.where(idx, np.array(self.upper), np.array(self.lower))

    def to_dict(self) -> dict[str, Any]:
        return {"label": self.label, "unit": "rad",
                **{n: [lo, hi] for n, lo, hi in zip(ANGLE_NAMES, self.lower, self.upper)}}


@dataclass(frozen=True)
class GramBounds:
    """Extreme eigenvalues of G over an angle box, and the vertices where they occur."""

    lambda_min: float
    lambda_max: float
    at_min: tuple[float, float, float]
    at_max: tuple[float, float, float]

    @property
    def relative(self) -> float:
        """The certified max of |a_nonorth - a_orth| / a_nonorth over the box."""
        return max(1 - math.sqrt(self.lambda_min), math.sqrt(self.lambda_max) - 1)


def gram_bounds(box: AngleBox) -> GramBounds:
    """Eigenvalue extremes over the box, at its vertices (concavity of lambda_min, see top)."""
    V = box.vertices()
    ev = np.linalg.eigvalsh(gram_np(V))
    i, j = int(np.argmin(ev[:, 0])), int(np.argmax(ev[:, -1]))
    return GramBounds(float(ev[i, 0]), float(ev[j, -1]), tuple(V[i]), tuple(V[j]))  # type: ignore


@dataclass(frozen=True)
class Certificate:
    """``exact``: the NLP must equal ``bound``; ``lower``: the NLP must reach ``bound`` (a sample)."""

    kind: str
    bound: float
    nlp: float
    tolerance: float
    formula: str

    @property
    def gap(self) -> float:
        return self.bound - self.nlp

    def to_dict(self) -> dict[str, Any]:
        return {"kind": self.kind, "value": self.bound, "nlp": self.nlp, "difference": self.gap,
                "tolerance": self.tolerance, "formula": self.formula}


def certify(kind: str, nlp: float, bound: float, tol: float, formula: str, what: str) -> Certificate:
    """Build a certificate; raise CertificateError when the NLP disagrees beyond ``tol``."""
    cert = Certificate(kind, float(bound), float(nlp), float(tol), formula)
    bad = abs(cert.gap) > tol if kind == "exact" else cert.gap > tol
    if bad:
        raise CertificateError(f"{what}: NLP value {nlp:.10g} disagrees with the certificate "
                               f"{bound:.10g} ({kind}) by {cert.gap:.3g} > {tol:.3g}")
    return cert


@dataclass(frozen=True)
class Extremum:
    """One multi-start NLP answer: the maximum, its maximiser and how it was found."""

    problem: str
    value: float
    unit: str
    acceleration: tuple[float, float, float]  #: maximiser m [m/s^2]; m >= 0 on a box symmetric about pi/2
    angles: tuple[float, float, float]  #: maximiser (phi, psi, theta) [rad]
    starts: int
    converged: int
    seed: int
    maximisers: tuple[tuple[float, ...], ...]  #: distinct (m1, m2, m3, phi, psi, theta) at the max
    certificate: Certificate

    def to_dict(self) -> dict[str, Any]:
        return {"problem": self.problem, "value": self.value, "unit": self.unit,
                "acceleration": list(self.acceleration), "acceleration_unit": "m/s^2",
                "acceleration_is": "measured values m_i = e_i . a (Lemma 1)",
                "angles": list(self.angles), "angles_unit": "rad",
                "bound": self.certificate.to_dict(),
                "multistart": {"starts": self.starts, "converged": self.converged, "seed": self.seed},
                "maximisers": [list(m) for m in self.maximisers]}


def _linearised_frame(ang):
    """E^-T (Theorem) and its first-order Taylor expansion in delta = angles - pi/2.

    The expansion is what sin(delta) ~ delta, cos(delta) ~ 1 gives after dropping products of
    deltas: [[1, 0, 0], [d_phi, 1, 0], [d_psi, d_theta, 1]], the linear models' misalignment matrix.
    """


    a = ca.SX.sym("a", 3)
    L = frame_inverse_transpose(a[0], a[1], a[2])
    a0 = ca.SX(ca.DM([RIGHT_ANGLE] * 3))
    J0 = ca.substitute(ca.jacobian(ca.vec(L), a), a, a0)
    L_lin = ca.substitute(L, a, a0) + ca.reshape(ca.mtimes(J0, ang - a0), 3, 3)
    return ca.substitute(L, a, ang), L_lin


@lru_cache(maxsize=None)
def _problem(kind: str):
    """Build one NLP once: variables x (scaled m) and u (angles = mid + half * u, u in [-1, 1])."""

    x, u, p = ca.SX.sym("x", 3), ca.SX.sym("u", 3), ca.SX.sym("p", 7)
    ang = p[:3] + p[3:6] * u  # p = [mid(3), half(3), objective scale]
    q = ca.dot(x, ca.mtimes(tbar(ang[0], ang[1], ang[2]), x))  # Prop. 2: (a_nonorth / scale)^2
    r2 = ca.dot(x, x)  # Prop. 1: (a_orth / scale)^2
    if kind == "abs":  # Problem 1, x = m / g: max (a_nonorth - a_orth)^2 s.t. a_nonorth = g
        obj, g = (1 - ca.sqrt(r2)) ** 2, q
    elif kind == "rel":  # Problem 2, x = m / range: max ((a_nonorth - a_orth) / a_nonorth)^2
        obj, g = (1 - ca.sqrt(r2 / q)) ** 2, r2
    elif kind == "lin":  # exact vs linearised apply map, x = m / range
        L, L_lin = _linearised_frame(ang)
        d = ca.mtimes(L - L_lin, x)
        obj, g = ca.dot(d, d), ca.SX(0, 1)
    else:  # pragma: no cover
        raise ValueError(kind)
    w = ca.vertcat(x, u)
    solver = ca.nlpsol(f"worst_{kind}", "ipopt", {"x": w, "p": p, "f": -p[6] * obj, "g": g}, _OPTS)
    value = ca.Function(f"value_{kind}", [w, p], [ca.sqrt(obj), q])
    return solver, value


def _multistart(kind: str, box: AngleBox, x0s: np.ndarray, u0s: np.ndarray, xb: float,
                lbg: float, ubg: float) -> list[tuple[float, np.ndarray]]:
    solver, value = _problem(kind)
    p = np.concatenate([box.mid, box.half, [1.0]])
    # Objective scale: 1 / (largest value at the starts)^2, so IPOPT sees numbers near one
    # even for tiny tolerances (independent of the certificate).
    v0 = max(float(value(np.concatenate([x0, u0]), p)[0]) for x0, u0 in zip(x0s, u0s))
    p[6] = 1.0 / v0**2 if v0 > 0 else 1.0
    ub = np.concatenate([np.full(3, xb), np.where(box.half > 0, 1.0, 0.0)])
    out = []
    for x0, u0 in zip(x0s, u0s):
        kw: dict[str, Any] = {"x0": np.concatenate([x0, u0]), "p": p, "lbx": -ub, "ubx": ub}
        if kind != "lin":
            kw.update(lbg=lbg, ubg=ubg)
        sol = solver(**kw)
        if solver.stats()["return_status"] in _CONVERGED:
            w = np.clip(np.asarray(sol["x"]).ravel(), -ub, ub)  # IPOPT may relax bounds by 1e-8
            if kind == "abs":  # a_nonorth = g exactly: q is homogeneous of degree 2 in x
                w[:3] /= math.sqrt(float(value(w, p)[1]))
            out.append((float(value(w, p)[0]), w))  # value at a feasible point: a true lower bound
    return out


def _extremum(problem: str, box: AngleBox, scale: float, unit: str, starts: int, seed: int,
              runs: list, value_scale: float, cert: tuple[str, float, float, str]) -> Extremum:
    """Best of the starts, its distinct equivalents, the certificate check and the report."""
    if not runs:
        raise CertificateError(f"{problem}: none of {starts} starts converged (seed {seed})")
    best = max(v for v, _ in runs)
    tol = CERTIFICATE_TOL
    near = [w for v, w in runs if v >= best - tol]
    uniq: dict[tuple, np.ndarray] = {}
    for w in near:  # key: scaled variables to 1e-4
        uniq.setdefault(tuple(np.round(w, 4) + 0.0), w)
    maxs = tuple(tuple(float(v) for v in np.concatenate([uniq[k][:3] * scale,
                                                         box.mid + box.half * uniq[k][3:]]))
                 for k in sorted(uniq, reverse=True))
    kind_c, bound, ctol, formula = cert
    c = certify(kind_c, best * value_scale, bound, ctol, formula, problem)
    m, ang = _canonical(np.array(maxs[0][:3]), np.array(maxs[0][3:]), box)
    return Extremum(problem, best * value_scale, unit, m, ang, starts, len(runs), seed, maxs, c)


#: Angles that involve each axis: x in (phi, psi), y in (phi, theta), z in (psi, theta).
_AXIS_ANGLES = ((0, 1), (0, 2), (1, 2))


def _canonical(m: np.ndarray, ang: np.ndarray, box: AngleBox) -> tuple[tuple, tuple]:
    """On a box symmetric about pi/2, flipping axis i (m_i -> -m_i, its two angles -> pi - angle)
    maps G to D G D and the box onto itself: every problem here is invariant. Report m >= 0."""
    if not np.allclose(box.mid, RIGHT_ANGLE, rtol=0, atol=1e-12):
        return tuple(float(v) for v in m), tuple(float(v) for v in ang)
    m, ang = m.copy(), ang.copy()
    for i in range(3):
        if m[i] < 0:
            m[i] = -m[i]
            for k in _AXIS_ANGLES[i]:
                ang[k] = math.pi - ang[k]
    return tuple(float(v) for v in m), tuple(float(v) for v in ang)


def _check_run(gravity: float, starts: int) -> None:
    if not (math.isfinite(gravity) and gravity > 0):
        raise ImucalError(f"gravity {gravity} must be positive", field="gravity", fix="e.g. 9.80665 m/s^2")
    check_count(starts, "starts", 1, MAX_STARTS)


def _angle_starts(rng: np.random.Generator, box: AngleBox, n: int) -> np.ndarray:
    return rng.uniform(-1, 1, (n, 3)) * (box.half > 0)


def max_abs_error(box: AngleBox, gravity: float = STANDARD_GRAVITY, starts: int = DEFAULT_STARTS,
                  seed: int = DEFAULT_SEED) -> Extremum:
    """Problem 1: max |a_nonorth - a_orth| subject to a_nonorth = g [m/s^2], certified."""
    _check_run(gravity, starts)
    rng = np.random.default_rng(seed)
    u0s = _angle_starts(rng, box, starts)
    d = rng.normal(size=(starts, 3))
    G = gram_np(box.mid + box.half * u0s)
    x0s = d / np.sqrt(np.einsum("ki,ki->k", d, np.linalg.solve(G, d[..., None])[..., 0]))[:, None]
    runs = _multistart("abs", box, x0s, u0s, 2.0, 1.0, 1.0)
    b = gram_bounds(box)
    cert = ("exact", gravity * b.relative, CERTIFICATE_TOL * gravity,
            "g * max(1 - sqrt(lambda_min(G)), sqrt(lambda_max(G)) - 1) over the angle box")
    return _extremum("problem 1: max |a_nonorth - a_orth| at a_nonorth = g", box, gravity,
                     "m/s^2", starts, seed, runs, gravity, cert)


def max_rel_error(box: AngleBox, range_ms2: float, starts: int = DEFAULT_STARTS,
                  seed: int = DEFAULT_SEED) -> Extremum:
    """Problem 2: max |(a_nonorth - a_orth) / a_nonorth| over |m_i| <= range [fraction], certified."""
    _check_range(range_ms2)
    _check_run(1.0, starts)
    rng = np.random.default_rng(seed)
    u0s = _angle_starts(rng, box, starts)
    x0s = rng.uniform(-1, 1, (starts, 3))
    small = np.linalg.norm(x0s, axis=1) < 2 * RHO
    x0s[small] = 0.5  # keep every start clear of the excluded ball
    runs = _multistart("rel", box, x0s, u0s, 1.0, RHO**2, math.inf)
    b = gram_bounds(box)
    cert = ("exact", b.relative, CERTIFICATE_TOL,
            "max(1 - sqrt(lambda_min(G)), sqrt(lambda_max(G)) - 1) over the angle box")
    return _extremum("problem 2: max |(a_nonorth - a_orth) / a_nonorth| over the box", box,
                     range_ms2, "fraction", starts, seed, runs, 1.0, cert)


def linearisation_samples(box: AngleBox, range_ms2: float, samples: int, seed: int) -> float:
    """Dense-sample lower bound of max |(E^-T - E^-T_lin) m| over the box [m/s^2].

    |D m| is convex in m, so its max over the m-box is at one of the 8 m-vertices: sampling only
    the angles (seeded, plus the angle box's vertices) loses nothing in m.
    """

    a = ca.SX.sym("a", 3)
    L, L_lin = _linearised_frame(a)
    D = ca.Function("D", [a], [L - L_lin]).map(samples + 8)
    rng = np.random.default_rng(seed)
    ang = np.vstack([box.vertices(), box.mid + box.half * rng.uniform(-1, 1, (samples, 3))])
    Ds = np.asarray(D(ang.T)).reshape(3, samples + 8, 3)  # [D_1 D_2 ...] -> [row, sample, col]
    V = np.array([[(k >> i) & 1 for i in range(3)] for k in range(8)]) * 2.0 - 1.0
    return float(range_ms2 * np.linalg.norm(np.einsum("rsc,vc->svr", Ds, V), axis=-1).max())


def max_linearisation_error(box: AngleBox, range_ms2: float, starts: int = DEFAULT_STARTS,
                            seed: int = DEFAULT_SEED, samples: int = 20000) -> Extremum:
    """max |E^-T m - E^-T_lin m| [m/s^2]: the exact apply map vs its small-angle linearisation."""
    _check_range(range_ms2)
    _check_run(1.0, starts)
    rng = np.random.default_rng(seed)
    u0s = _angle_starts(rng, box, starts)
    x0s = rng.uniform(-1, 1, (starts, 3))
    runs = _multistart("lin", box, x0s, u0s, 1.0, 0.0, 0.0)
    lb = linearisation_samples(box, range_ms2, samples, seed)
    cert = ("lower", lb, CERTIFICATE_TOL * range_ms2,
            f"max over {samples} seeded angle samples + box vertices x the 8 vertices of the m-box")
    return _extremum("exact vs linearised (sin x ~ x, cos x ~ 1) calibrated acceleration", box,
                     range_ms2, "m/s^2", starts, seed, runs, range_ms2, cert)


def _check_range(range_ms2: float) -> None:
    if not (math.isfinite(range_ms2) and range_ms2 > 0):
        raise ImucalError(f"range {range_ms2:g} must be positive", field="range",
                          fix="give the sensor's full scale, e.g. 16 (g) or 20 (m/s^2)")


@dataclass(frozen=True)
class WorstCase:
    """Problems 1 and 2 and the linearisation error on one angle box, each certified."""

    box: AngleBox
    gravity: float
    range_g: float
    gram: GramBounds
    abs_error: Extremum
    rel_error: Extremum
    linearisation: Extremum
    source: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {"format": "imucal-worst-case", "format_version": 1,
                "gravity": self.gravity, "gravity_unit": "m/s^2",
                "range_g": self.range_g, "range": self.range_g * self.gravity, "range_unit": "m/s^2",
                "angle_box": self.box.to_dict(), "source": dict(self.source),
                "gram_eigenvalues": {"min": self.gram.lambda_min, "at_min": list(self.gram.at_min),
                                     "max": self.gram.lambda_max, "at_max": list(self.gram.at_max)},
                "abs_error_max": self.abs_error.to_dict(), "rel_error_max": self.rel_error.to_dict(),
                "linearisation_error_max": self.linearisation.to_dict()}


def analyse(box: AngleBox, gravity: float = STANDARD_GRAVITY, range_g: float = 16.0,
            starts: int = DEFAULT_STARTS, seed: int = DEFAULT_SEED,
            source: dict[str, Any] | None = None) -> WorstCase:
    """Solve and certify everything ``imucal worst-case`` reports."""
    _check_run(gravity, starts)
    check_seed(seed)
    if not (math.isfinite(range_g) and range_g > 0):
        raise ImucalError(f"range {range_g:g} g must be positive", field="range-g",
                          fix="give the sensor's full scale in g, e.g. 4, 8 or 16")
    rng_ms2 = range_g * gravity
    return WorstCase(box, gravity, range_g, gram_bounds(box),
                     max_abs_error(box, gravity, starts, seed),
                     max_rel_error(box, rng_ms2, starts, seed),
                     max_linearisation_error(box, rng_ms2, starts, seed), dict(source or {}))
