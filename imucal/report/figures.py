"""Figures (matplotlib, PNG): residual per interval and interval directions on the sphere.

Plotting is kept apart from the maths; matplotlib is imported only when a figure is made.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from imucal.pipeline import CalibrationRun
from imucal.report.text import interval_residuals


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plain(text: str) -> str:
    """User text shown literally in a figure: dollar signs would start matplotlib's mathtext."""
    return text.replace("$", r"\$")


def residual_figure(run: CalibrationRun, path: str | Path) -> None:
    plt = _plt()
    res, iv = run.result, run.intervals
    r, s = interval_residuals(run)
    fig, ax = plt.subplots(figsize=(9, 4.2), dpi=110)
    k = np.arange(iv.n)
    ax.errorbar(k, r * 1e3, yerr=None if np.isnan(s).all() else 2 * s * 1e3, fmt="o", ms=4, capsize=2,
                label="|a| - g at interval mean (bars: 2 sigma)")
    rms = np.sqrt(np.mean(r**2)) * 1e3
    ax.axhline(0, color="k", lw=0.8)
    ax.axhspan(-rms, rms, color="tab:orange", alpha=0.15, label=f"RMS = {rms:.3g} mm/s^2")
    ax.set_xlabel("static interval, as numbered in the report [#]")
    ax.set_ylabel("residual |a| - g  [mm/s^2]")
    ax.set_title(f"Residual per interval ({plain(res.model_name)}, reduced chi-square {res.redchi:.3g})")
    ax.legend(loc="best", fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, format="png")
    plt.close(fig)


def _polar_angle_map(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Azimuthal equidistant projection about +z: distance from the centre = angle from +z [deg]."""
    ang = np.degrees(np.arccos(np.clip(v[:, 2], -1, 1)))
    h = np.hypot(v[:, 0], v[:, 1])
    safe = np.where(h > 0, h, 1.0)
    return ang * v[:, 0] / safe, ang * v[:, 1] / safe


def directions_figure(run: CalibrationRun, path: str | Path) -> None:
    """Gravity directions of the intervals, one disk per hemisphere: the distance from a disk's
    centre is the angle from the +z (left) or -z (right) sensor axis, in degrees. Every interval is
    numbered as in the report's tables; intervals in the same pose share a colour and a label."""
    plt = _plt()
    d = run.directions
    labels = run.observability.labels
    fig, axes = plt.subplots(1, 2, figsize=(10, 5.6), dpi=110)
    circ = np.linspace(0, 2 * np.pi, 200)
    for ax, sign in ((axes[0], 1), (axes[1], -1)):
        sel = (d[:, 2] >= 0) if sign > 0 else (d[:, 2] < 0)
        v = d[sel] * np.array([1, 1, sign])
        x, y = _polar_angle_map(v)
        for ang in (30, 60, 90):
            ax.plot(ang * np.cos(circ), ang * np.sin(circ), color="k" if ang == 90 else "0.8", lw=0.8)
            ax.annotate(f"{ang}°", (ang * np.cos(np.radians(-60)), ang * np.sin(np.radians(-60))), fontsize=7,
                        color="0.45", ha="left", va="top")
        ax.axhline(0, color="0.85", lw=0.6)
        ax.axvline(0, color="0.85", lw=0.6)
        ax.scatter(x, y, c=labels[sel], cmap="tab20", s=44, edgecolor="k", vmin=0, vmax=max(labels.max(), 1),
                   zorder=3)
        idx = np.flatnonzero(sel)
        for lab in np.unique(labels[sel]):  # one label per pose: the interval numbers in it
            m = labels[sel] == lab
            ax.annotate(",".join(str(i) for i in idx[m]), (float(np.mean(x[m])), float(np.mean(y[m]))),
                        fontsize=7, xytext=(4, 4), textcoords="offset points", zorder=4)
        ax.set_aspect("equal")
        ax.set_xlim(-100, 100)
        ax.set_ylim(-100, 100)
        z = "+z" if sign > 0 else "−z"
        ax.set_title(f"{z} axis up (reading has {'a_z ≥ 0' if sign > 0 else 'a_z < 0'}): "
                     f"{int(sel.sum())} intervals\ncentre: {z} vertical; rings: its tilt [deg]", fontsize=9)
        ax.set_xlabel(f"tilt from {z} toward +x [deg]")
        ax.set_ylabel(f"tilt from {z} toward +y [deg]")
    fig.suptitle(f"Direction of the accelerometer reading a/|a| (up, opposite gravity) per static interval, "
                 f"sensor frame "
                 f"({run.intervals.n} intervals, {run.observability.n_distinct} distinct poses)\n"
                 "azimuthal equidistant projection of each hemisphere; numbers = interval # in the report, "
                 "colour = pose", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, format="png")
    plt.close(fig)


FIGURES = {"residuals.png": residual_figure, "directions.png": directions_figure}
