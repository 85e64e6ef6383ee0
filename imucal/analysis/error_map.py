"""The relative error of ignoring non-orthogonality over a box of accelerations (paper, Figs. 3, 4).

err(m) = |a_nonorth - a_orth| / a_nonorth = |1 - sqrt(m^T m / m^T G^-1 m)| (Propositions 1, 2)
depends on the direction of m only. Writing w_i = (v_i . m / |m|)^2 in the eigenbasis (lambda_i,
v_i) of G: (a_orth / a_nonorth)^2 = 1 / sum_i w_i / lambda_i. The histogram's features sit at the
critical values |1 - sqrt(lambda_i)| (see docs/worst_case.md).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from imucal.errors import ImucalError, short
from imucal.config.limits import MAX_MAP_SAMPLES, check_count, check_seed
from imucal.analysis.worst_case import ANGLE_NAMES, AngleBox, gram_np

#: The paper's Fig. 3/4 setting: angles of the authors' sensor, box [-20, 20]^3 m/s^2.
PAPER_ANGLES = (1.53938, 1.60221, 1.60221)
PAPER_RANGE = 20.0
PAPER_LEVELS = (0.014, 0.016)
DEFAULT_SAMPLES = 1_000_000


def relative_error(m: np.ndarray, angles: Sequence[float]) -> np.ndarray:
    """|a_nonorth - a_orth| / a_nonorth for each row of m (N, 3) [-]."""
    m = np.asarray(m, float)
    q = np.einsum("ki,ik->k", m, np.linalg.solve(gram_np(angles), m.T))  # m^T G^-1 m, Prop. 2
    return np.abs(1 - np.sqrt(np.einsum("ki,ki->k", m, m) / q))


@dataclass(frozen=True)
class ErrorMap:
    """A seeded uniform sample of the box and its relative errors, summarised."""

    angles: tuple[float, float, float]
    range: float  #: half-width of the box [m/s^2]
    seed: int
    points: np.ndarray = field(repr=False)  #: (N, 3) [m/s^2]
    errors: np.ndarray = field(repr=False)  #: (N,) fraction
    eigenvalues: np.ndarray  #: of G, ascending
    eigenvectors: np.ndarray  #: columns
    levels: tuple[float, ...]  #: thresholds of the domains (fractions)

    @property
    def critical_levels(self) -> list[float]:
        """|1 - sqrt(lambda_i)| per eigenvalue: where the density of err has its features."""
        return [abs(1 - math.sqrt(lam)) for lam in self.eigenvalues]

    @property
    def plateau(self) -> float:
        """The jump: the largest error reached from the side a_orth < a_nonorth (lambda < 1)."""
        below = [1 - math.sqrt(lam) for lam in self.eigenvalues if lam < 1]
        return max(below) if below else 0.0

    def cones(self) -> dict[str, float] | None:
        """With a double eigenvalue err depends on the angle to the simple eigenvector v only:
        the half-angles [deg] around v where err = 0 and where err = each level (both branches)."""
        lam = self.eigenvalues
        if np.isclose(lam[0], lam[1], rtol=1e-4):
            ls, ld = lam[2], (lam[0] + lam[1]) / 2
        elif np.isclose(lam[1], lam[2], rtol=1e-4):
            ls, ld = lam[0], (lam[1] + lam[2]) / 2
        else:
            return None

        def half_angle(R: float) -> float | None:  # (a_orth / a_nonorth)^2 = R at w = (v.u)^2
            w = (1 / R - 1 / ld) / (1 / ls - 1 / ld)
            return math.degrees(math.acos(math.sqrt(w))) if 0 <= w <= 1 else None

        out = {"zero": half_angle(1.0)}
        for lv in self.levels:
            out[f"{lv:g} (a_orth > a_nonorth)"] = half_angle((1 + lv) ** 2)
            out[f"{lv:g} (a_orth < a_nonorth)"] = half_angle((1 - lv) ** 2)
        return out

    @property
    def cone_axis(self) -> np.ndarray:
        """Eigenvector of the eigenvalue farthest from 1 (the simple one here), sign: sum >= 0."""
        v = self.eigenvectors[:, int(np.argmax(np.abs(1 - np.sqrt(self.eigenvalues))))]
        return v if v.sum() >= 0 else -v

    def histogram(self, bins: int = 200) -> tuple[np.ndarray, np.ndarray]:
        hi = float(self.errors.max()) * 1.02
        return np.histogram(self.errors, bins=bins, range=(0.0, hi))

    def to_dict(self, bins: int = 200) -> dict[str, Any]:
        counts, edges = self.histogram(bins)
        e = self.errors
        return {
            "format": "imucal-error-map", "format_version": 1,
            "angles": dict(zip(ANGLE_NAMES, self.angles)), "angles_unit": "rad",
            "box": [-self.range, self.range], "box_unit": "m/s^2",
            "samples": int(e.size), "seed": self.seed, "error_unit": "fraction",
            "gram_eigenvalues": self.eigenvalues.tolist(),
            "gram_eigenvectors": self.eigenvectors.T.tolist(),
            "critical_levels": self.critical_levels, "jump_at": self.plateau,
            "cone_half_angles_deg": self.cones(), "cone_axis": self.cone_axis.tolist(),
            "bound": max(self.critical_levels),
            "sample_max": float(e.max()), "sample_mean": float(e.mean()),
            "quantiles": {str(q): float(np.quantile(e, q)) for q in (0.05, 0.25, 0.5, 0.75, 0.95)},
            "domains": {f"{op}{lv:g}": float(np.mean(e <= lv if op == "<=" else e >= lv))
                        for lv in self.levels for op in ("<=", ">=")},
            "histogram": {"edges": edges.tolist(), "counts": counts.tolist()},
        }


def compute_error_map(angles: Sequence[float] = PAPER_ANGLES, range_ms2: float = PAPER_RANGE,
                      samples: int = DEFAULT_SAMPLES, seed: int = 0,
                      levels: Sequence[float] = PAPER_LEVELS) -> ErrorMap:
    """Sample [-range, range]^3 uniformly (seeded) and evaluate the relative error."""
    if len(angles) != 3:
        raise ImucalError(f"need 3 angles (phi psi theta), got {len(angles)}", field="angles",
                          fix="give the three axis angles phi psi theta in radians")
    AngleBox.around(angles)  # refuses angles outside (0, pi) and degenerate frames
    if not (math.isfinite(range_ms2) and range_ms2 > 0):
        raise ImucalError(f"range {range_ms2:g} must be positive", field="range",
                          fix="give the half-width of the box in m/s^2, e.g. 20")
    check_count(samples, "samples", 1000, MAX_MAP_SAMPLES)
    check_seed(seed)
    if not all(0 < lv < 1 for lv in levels):
        raise ImucalError(f"levels {short(list(levels), 60)} must be fractions in (0, 1)", field="levels",
                          fix="e.g. 0.014 0.016 for 1.4 % and 1.6 %")
    pts = np.random.default_rng(seed).uniform(-range_ms2, range_ms2, (samples, 3))
    lam, vec = np.linalg.eigh(gram_np(angles))
    return ErrorMap(tuple(float(a) for a in angles), float(range_ms2), seed, pts,  # type: ignore[arg-type]
                    relative_error(pts, angles), lam, vec, tuple(float(v) for v in levels))


def _angles_text(emap: ErrorMap) -> str:
    return ", ".join(f"{s}={a:.5f}" for s, a in zip(("φ", "ψ", "θ"), emap.angles)) + " rad"


def plot_histogram(emap: ErrorMap, path: str, bins: int = 200) -> None:
    """Fig. 3: distribution of the relative error, with the eigenvalue levels marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    counts, edges = emap.histogram(bins)
    share = 100 * counts / counts.sum()
    fig, ax = plt.subplots(figsize=(8, 4.8), dpi=120)
    ax.bar(100 * edges[:-1], share, width=100 * np.diff(edges), align="edge", color="#4878a8",
           edgecolor="none", label=f"{emap.errors.size:,} uniform samples")
    lam = emap.eigenvalues
    for k, lv in enumerate(emap.critical_levels):
        mult = int(np.sum(np.isclose(lam, lam[k], rtol=1e-4)))
        if k and np.isclose(lam[k], lam[k - 1], rtol=1e-4):
            continue
        side = "1 - √λ" if lam[k] < 1 else "√λ - 1"
        ax.axvline(100 * lv, color="#c44e52" if mult > 1 else "#555555", ls="--", lw=1.2,
                   label=f"{side} = {100 * lv:.3f} %  (λ = {lam[k]:.4f}{', double' if mult > 1 else ''})")
    for lv in emap.levels:
        ax.axvline(100 * lv, color="#55a868", ls=":", lw=1.2)
    ax.set_xlabel("relative error |a_nonorth - a_orth| / a_nonorth  [%]")
    ax.set_ylabel(f"share of samples per bin [%]  (bin {100 * (edges[1] - edges[0]):.3f} %)")
    ax.set_title(f"Relative error over [-{emap.range:g}, {emap.range:g}]³ m/s²\n{_angles_text(emap)}",
                 fontsize=10)
    ax.set_xlim(0, 100 * edges[-1])
    ax.legend(fontsize=8, loc="upper right", title="eigenvalues of G (dotted: domain levels)",
              title_fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, format="png")
    plt.close(fig)


def plot_domains(emap: ErrorMap, path: str, grid: int = 16) -> None:
    """Fig. 4: the domains err <= / >= each level, as voxels coloured by the error."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib import cm, colors

    n = grid + grid % 2  # even: no cell centred on m = 0
    R = emap.range
    e = np.linspace(-R, R, n + 1)
    c = (e[:-1] + e[1:]) / 2
    X, Y, Z = np.meshgrid(c, c, c, indexing="ij")
    err = relative_error(np.column_stack([X.ravel(), Y.ravel(), Z.ravel()]), emap.angles).reshape(X.shape)
    norm = colors.Normalize(0, 100 * max(emap.critical_levels))
    cmap = plt.get_cmap("viridis")
    face = cmap(norm(100 * err))
    Xe, Ye, Ze = np.meshgrid(e, e, e, indexing="ij")
    k_ax = int(np.argmax(np.abs(1 - np.sqrt(emap.eigenvalues))))
    v = emap.cone_axis
    elev, azim = _side_view(v)
    fig = plt.figure(figsize=(11, 9.6), dpi=110)
    fig.subplots_adjust(left=0.0, right=0.86, top=0.9, bottom=0.02, wspace=0.02, hspace=0.08)
    panels = [(lv, op) for lv in emap.levels for op in ("<=", ">=")]
    for k, (lv, op) in enumerate(panels):
        ax = fig.add_subplot(2, 2, k + 1, projection="3d")
        mask = err <= lv if op == "<=" else err >= lv
        ax.voxels(Xe, Ye, Ze, mask, facecolors=face, edgecolor=(0, 0, 0, 0.15), linewidth=0.2)
        ax.set_title(f"({'abcd'[k]}) relative error {'≤' if op == '<=' else '≥'} {100 * lv:g} %"
                     f"  ({100 * mask.mean():.0f} % of the box)", fontsize=10)
        for setl, lab in ((ax.set_xlabel, "m_x"), (ax.set_ylabel, "m_y"), (ax.set_zlabel, "m_z")):
            setl(f"{lab} [m/s²]", fontsize=8, labelpad=2)
        ax.tick_params(labelsize=7, pad=0)
        ax.set_xlim(-R, R)
        ax.set_ylim(-R, R)
        ax.set_zlim(-R, R)
        ax.view_init(elev=elev, azim=azim)
    vtxt = "(" + ", ".join(f"{x:.3f}" for x in v) + ")"
    fig.suptitle(f"Domains of the relative error in [-{R:g}, {R:g}]³ m/s², {_angles_text(emap)}\n"
                 f"cones around the eigenvector {vtxt} of G (λ = {emap.eigenvalues[k_ax]:.4f}), "
                 f"viewed from the side", fontsize=11)
    cax = fig.add_axes((0.89, 0.25, 0.02, 0.5))
    fig.colorbar(cm.ScalarMappable(norm=norm, cmap=cmap), cax=cax, label="relative error [%]")
    fig.savefig(path, format="png")
    plt.close(fig)


def _side_view(v: np.ndarray, elev: float = 18.0) -> tuple[float, float]:
    """(elev, azim) [deg] of a camera perpendicular to v, so cones around v show their profile."""
    t = math.tan(math.radians(elev)) * v[2]
    r = math.hypot(v[0], v[1])
    if r < abs(t) + 1e-9:
        return elev, -60.0
    base = math.atan2(v[1], v[0])  # solve r cos(az - base) = -t; keep the root nearest -60 deg
    roots = [math.degrees(base + sgn * math.acos(-t / r)) for sgn in (1, -1)]
    return elev, min(roots, key=lambda az: abs((az + 60 + 180) % 360 - 180))
