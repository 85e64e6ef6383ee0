"""Figures (matplotlib, PNG): residual per interval and interval directions on the sphere.

Plotting is kept apart from the maths; matplotlib is imported only when a figure is made.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from imucal.pipeline import CalibrationRun


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def residual_figure(run: CalibrationRun, path: str | Path) -> None:
    plt = _plt()
    res, iv = run.result, run.intervals
    from imucal.solve.fit import jacobian_rows
    from imucal.pipeline import fit_data
    from imucal.model.sensor import build_model

    if res.mode == "means":
        r, s = res.residuals, res.sigma
    else:
        model = build_model(run.calibration.effect_objects())
        d = fit_data(model, iv, run.recording, "means", None)
        r = jacobian_rows(d, res.params, model, res.gravity, residuals=True)
        s = np.full_like(r, np.nan)
    fig, ax = plt.subplots(figsize=(9, 4.2), dpi=110)
    k = np.arange(iv.n)
    ax.errorbar(k, r * 1e3, yerr=None if np.isnan(s).all() else 2 * s * 1e3, fmt="o", ms=4, capsize=2,
                label="|a| - g at interval mean (bars: 2 sigma)")
    rms = np.sqrt(np.mean(r**2)) * 1e3
    ax.axhline(0, color="k", lw=0.8)
    ax.axhspan(-rms, rms, color="tab:orange", alpha=0.15, label=f"RMS = {rms:.3g} mm/s^2")
    ax.set_xlabel("static interval #")
    ax.set_ylabel("residual |a| - g  [mm/s^2]")
    ax.set_title(f"Residual per interval ({res.model_name}, reduced chi-square {res.redchi:.3g})")
    ax.legend(loc="best", fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, format="png")
    plt.close(fig)


def directions_figure(run: CalibrationRun, path: str | Path) -> None:
    """Gravity directions of the intervals: upper and lower hemispheres, equal-area projection."""
    plt = _plt()
    d = run.directions
    labels = run.observability.labels
    fig, axes = plt.subplots(1, 2, figsize=(9, 4.6), dpi=110)
    for ax, sign, name in ((axes[0], 1, "z >= 0 (upper)"), (axes[1], -1, "z < 0 (lower)")):
        sel = (d[:, 2] >= 0) if sign > 0 else (d[:, 2] < 0)
        v = d[sel] * np.array([1, 1, sign])
        # Lambert azimuthal equal-area projection about +z.
        k = np.sqrt(2 / (1 + np.clip(v[:, 2], -1 + 1e-12, 1)))
        x, y = k * v[:, 0], k * v[:, 1]
        circ = np.linspace(0, 2 * np.pi, 200)
        ax.plot(np.sqrt(2) * np.cos(circ), np.sqrt(2) * np.sin(circ), "k", lw=0.8)
        for ang in (30, 60):
            r = 2 * np.sin(np.radians(ang) / 2)
            ax.plot(r * np.cos(circ), r * np.sin(circ), color="0.8", lw=0.6)
        ax.scatter(x, y, c=labels[sel], cmap="tab20", s=40, edgecolor="k", vmin=0,
                        vmax=max(labels.max(), 1))
        for i, (xx, yy) in zip(np.flatnonzero(sel), zip(x, y)):
            ax.annotate(str(i), (xx, yy), fontsize=6, xytext=(3, 3), textcoords="offset points")
        ax.set_aspect("equal")
        ax.set_xlim(-1.5, 1.5)
        ax.set_ylim(-1.5, 1.5)
        ax.set_title(f"hemisphere {name}")
        ax.set_xlabel("x")
        ax.set_ylabel("y")
    fig.suptitle(f"Gravity direction per static interval ({run.intervals.n} intervals, "
                 f"{run.observability.n_distinct} distinct; colour = pose cluster)")
    fig.tight_layout()
    fig.savefig(path, format="png")
    plt.close(fig)


FIGURES = {"residuals.png": residual_figure, "directions.png": directions_figure}
