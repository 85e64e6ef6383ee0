"""Observability: refuse fits the evidence cannot determine, and say what to add.

One check for every sensor (``determination``): each free parameter's predicted standard error from the
evidence's information, against its threshold (Parameter.undetermined, in units of its scale): alone
(every other parameter known), together (all estimated at once), and the information's null and weak
directions. What to refuse and how to say it is the evidence's (the accelerometer's poses below:
``analyse`` and ``require_observable``; the gyroscope's motions: imucal.gyro.evidence).

The accelerometer's poses add two checks before it: the number of distinct gravity directions
(repeated poses add no rank), and the rank of the residual Jacobian with one row per distinct
direction. Parameters that load on the Jacobian's (near) null space are named as undetermined.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Mapping, Sequence

import numpy as np

from imucal.errors import ImucalError
from imucal.solve.covariance import unscaled_covariance
from imucal.model.parameters import ANGLE_NAMES, UNDETERMINED_SCALE, UNDETERMINED_SHIFT, Parameters

#: Two interval directions closer than this are the same pose [deg].
DISTINCT_ANGLE_DEG = 10.0
#: Relative singular value below which a direction of parameter space is undetermined.
RANK_TOL = 1e-6
#: Predicted standard error above which the poses leave a parameter undetermined, in units of
#: the parameter's scale (b_i for a scale, one g of raw output for a shift, pi/2 for an angle):
#: 1 % of the sensitivity, 1 % of g of bias; for an angle, the half-width of its bound box
#: (the angle tolerance), since the bounds alone already pin it that well.
UNDETERMINED_Z = {"s": UNDETERMINED_SHIFT, "b": UNDETERMINED_SCALE}
#: A coefficient larger than its generous magnitude is determined when it is at least this many
#: (noise-only) standard errors from zero: the detection level, chi-square(1) at p = 1e-3.
LARGE_EFFECT_Z = 3.29
#: Reported as poorly determined above this fraction of the threshold.
POOR_FRACTION = 0.1


def thresholds(params: Parameters, free_names: tuple[str, ...], angle_tol: float,
               sizes: Mapping[str, float] | None = None) -> np.ndarray:
    """Per-parameter undetermined thresholds in scaled units: each parameter's own (Parameter.undetermined:
    UNDETERMINED_Z of a shift or a scale, the angle tolerance of an angle, as base_parameters sets them;
    by name for parameters read from a file).

    An effect parameter's is 1 (its generous magnitude), or its own size over LARGE_EFFECT_Z when a
    start puts it larger (``sizes``: |value| / scale, e.g. a term discover found): a coefficient ten
    times the usual size and ten standard errors from zero is determined, though its error is not
    small against the usual size."""
    sizes = sizes or {}
    out = []
    for n in free_names:
        own = params[n].undetermined
        if own is not None:
            out.append(own)
        elif n in ANGLE_NAMES:
            out.append(angle_tol)
        elif n[:1] in UNDETERMINED_Z and n[1:] in ("1", "2", "3"):
            out.append(UNDETERMINED_Z[n[:1]])
        else:
            out.append(max(1.0, abs(float(sizes.get(n, 0.0))) / LARGE_EFFECT_Z))
    return np.array(out)


#: A direction of the information is null below this fraction of its largest eigenvalue.
NULL_RTOL = 1e-9


@dataclass(frozen=True)
class Determination:
    """What the evidence determines of the free parameters: predicted standard errors (noise only, or the
    evidence's own whitening) in units of each parameter's threshold (> 1: undetermined)."""

    names: tuple[str, ...]
    alone: np.ndarray  #: each with every other parameter known: 1 / sqrt(I_kk)
    together: np.ndarray  #: all estimated together: sqrt((I^+)_kk), undetermined directions dropped
    eigenvalues: np.ndarray  #: of the information I, ascending
    eigenvectors: np.ndarray  #: its unit eigenvectors (columns), in threshold units

    @property
    def null(self) -> np.ndarray:
        """Which eigen-directions the evidence leaves without information (bool per eigenvalue)."""
        lam = self.eigenvalues
        return lam <= NULL_RTOL * max(lam[-1] if lam.size else 0.0, 1e-300)

    @property
    def weak(self) -> tuple[str, ...]:
        """The parameters loading (> 0.5) on the directions whose predicted standard error exceeds the threshold."""
        bad = 1.0 / np.sqrt(np.maximum(self.eigenvalues, 1e-300)) > 1.0
        if not bad.any():
            return ()
        load = np.sqrt((self.eigenvectors[:, bad] ** 2).sum(axis=1))
        return tuple(n for n, v in zip(self.names, load) if v > 0.5)


def determination(J: np.ndarray, names: tuple[str, ...], limits: np.ndarray) -> Determination:
    """The one observability check's numbers: J (rows, free) in the parameters' units, its rows whitened by
    the evidence; ``limits`` each parameter's threshold in the same units (scale x undetermined)."""
    Jt = np.asarray(J, float) * np.asarray(limits, float)
    info = Jt.T @ Jt
    with np.errstate(divide="ignore"):
        alone = 1.0 / np.sqrt(np.clip(np.diag(info), 0, None))
    lam, V = np.linalg.eigh(info)
    with np.errstate(invalid="ignore"):
        together = np.sqrt(np.clip(np.diag(unscaled_covariance(Jt)), 0, None))
    return Determination(tuple(names), alone, together, lam, V)


@dataclass(frozen=True)
class Observability:
    n_distinct: int
    labels: np.ndarray  #: cluster index of each interval
    singular_values: np.ndarray  #: of the column-scaled Jacobian, largest first
    undetermined: tuple[str, ...]
    predicted_z: dict = None  #: predicted std / scale per free parameter (noise only)
    poorly_determined: tuple[str, ...] = ()

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


def analyse(directions: np.ndarray, jac_rows: np.ndarray, free_names: tuple[str, ...],
            weighted_rows: np.ndarray | None = None, limits: np.ndarray | None = None,
            varying: Sequence[str] = ()) -> Observability:
    """Distinct poses, Jacobian rank and predicted standard errors.

    ``jac_rows`` is (n_intervals, n_free) with columns times each parameter's scale;
    ``weighted_rows`` the same divided by each row's noise (Fisher information J^T J);
    ``varying``: parameters of effects in time or temperature, whose columns differ between visits
    of one pose.
    """
    n_distinct, labels = distinct_directions(directions)
    # One row per distinct direction: repeats of a pose add no information about the static model
    # (two holds within DISTINCT_ANGLE_DEG count as one pose).
    J = np.vstack([jac_rows[labels == k].mean(axis=0) for k in range(n_distinct)])
    vary = set(varying)
    cols = [j for j, n in enumerate(free_names) if n in vary]
    if cols:  # ... but they do about an effect in time or temperature: a revisit at another time or
        # temperature is what determines it (a drift on a plan that visits every pose twice, forward
        # then in reverse, has cluster means of its column near zero)
        dev = np.zeros_like(jac_rows)
        dev[:, cols] = jac_rows[:, cols] - J[labels][:, cols]
        J = np.vstack([J, dev])
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
    z: dict[str, float] = {}
    poor: list[str] = []
    if weighted_rows is not None and n_distinct >= nf:
        # Noise-only Fisher information at the initial guess, in units of each parameter's
        # threshold. Its eigenvectors whose predicted standard error exceeds 1 are directions
        # the poses do not determine; the parameters that load on them are named. (Exact
        # degeneracies show up at noise level in the singular values, so a rank test alone
        # misses them.)
        lim = np.ones(nf) if limits is None else np.asarray(limits, float)
        det = determination(weighted_rows, free_names, lim)
        und += [n for n in det.weak if n not in und]
        zt = det.together
        z = {n: float(v * l) for n, v, l in zip(free_names, zt, lim)}  # std / scale
        poor = [n for n, v in zip(free_names, zt) if v > POOR_FRACTION and n not in und]
    return Observability(n_distinct, labels, svf, tuple(sorted(und, key=free_names.index)), z, tuple(poor))


def require_observable(obs: Observability, free_names: tuple[str, ...], source: str | None,
                       advice: Callable[[Sequence[str]], str | None] | None = None) -> None:
    """Raise a one-line ImucalError naming undetermined parameters and the poses to add; ``advice``
    names what to record for undetermined parameters of effects (a pose over a temperature range,
    imucal.thermal.determine.interval_advice), or None to keep the words about orientations."""
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
        plural = "s" if obs.n_distinct != 1 else ""
        raise ImucalError(f"only {obs.n_distinct} distinct orientation{plural} for {nf} free parameters: {what}",
                          file=source, field="intervals", fix=fix)
    if obs.undetermined:
        detail = f"Jacobian condition {obs.condition:.3g}"
        fix = "add orientations that tilt gravity towards the missing axes (cube faces, edges and corners)"
        if not angles_free:
            fix += "; fixing the angles does not help here"
        else:
            fix += ", or fix those parameters"
        said = advice(obs.undetermined) if advice is not None else None
        if said:
            fix = said
        raise ImucalError(f"the orientations leave {', '.join(obs.undetermined)} undetermined ({detail})",
                          file=source, field="intervals", fix=fix)
