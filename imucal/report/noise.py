"""`imucal noise` in words and as a figure: each sensor's noise terms per axis, and the Allan
deviation of every axis on log-log scales with the terms it gives (imucal.analysis.still_noise)."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from imucal.analysis.noise import FLICKER_FACTOR, NoiseEstimate
from imucal.analysis.still_noise import SensorNoise, StillNoise


def _cell(v: float, rel: float) -> str:
    return f"{v:10.4g} +-{100 * rel:3.0f}%" if math.isfinite(v) else f"{'n/a':>16}"


def _sensor_lines(s: SensorNoise) -> list[str]:
    L = [f"[{s.sensor}] unit {s.unit}",
         f"{'axis':<5} {'white density':>16} {'bias instability':>18} {'random walk':>16}"]
    for a, e in zip("xyz", s.axes):
        L.append(f"{a:<5} {_cell(e.white_density, e.white_rel_err)} "
                 f"{_cell(e.bias_instability, e.bias_instability_rel_err)}  {_cell(e.random_walk, e.random_walk_rel_err)}")
    if not s.random_walk_found:
        L.append("random walk n/a: no +1/2 slope in the curve (the still log is too short; record longer)")
    L.append(f"units: white density {s.unit}/sqrt(Hz), bias instability {s.unit}, random walk {s.unit}/s/sqrt(Hz)")
    return L


def noise_text(n: StillNoise) -> str:
    """The tables `imucal noise` prints: one per sensor, then Kalibr's fields when in SI units."""
    L = [f"Allan deviation of {n.segment} ({n.n_samples} samples, {n.rate:.4g} Hz)"]
    for s in n.sensors:
        L += _sensor_lines(s)
    if (k := n.kalibr()) is not None:
        L.append("kalibr imu.yaml: " + ", ".join(f"{key}: {'n/a' if v is None else f'{v:.4g}'}"
                                                 for key, v in k.items()))
    return "\n".join(L)


def _model_lines(ax, tau: np.ndarray, e: NoiseEstimate, color: str) -> None:
    """The terms as the lines they are on the Allan plot: N / sqrt(tau), the floor 0.664 B, K sqrt(tau / 3)."""
    if math.isfinite(e.white_density):
        ax.loglog(tau, e.white_density / np.sqrt(tau), ls=":", color=color, lw=0.9)
    ax.axhline(e.bias_instability * FLICKER_FACTOR, ls="--", color=color, lw=0.6, alpha=0.6)
    if math.isfinite(e.random_walk):
        ax.loglog(tau, e.random_walk * np.sqrt(tau / 3.0), ls="-.", color=color, lw=0.9)


def _plt():  # matplotlib only when a figure is drawn (docs/architecture.md)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def allan_figure(n: StillNoise, path: str | Path) -> None:
    """Allan deviation of each axis of each sensor (one panel per sensor), with the fitted terms."""
    from imucal.report.figures import plain  # figure text's one escaping function

    plt = _plt()
    fig, axes = plt.subplots(1, len(n.sensors), figsize=(5.2 * len(n.sensors), 4.4), dpi=110, squeeze=False)
    for ax, s in zip(axes[0], n.sensors):
        for j, (a, color) in enumerate(zip("xyz", ("tab:blue", "tab:orange", "tab:green"))):
            ax.loglog(s.curve.tau, s.curve.adev[:, j], "o-", ms=2.5, lw=1.2, color=color, label=f"axis {a}")
            _model_lines(ax, s.curve.tau, s.axes[j], color)
        ax.set_ylim(s.curve.adev.min() / 3, s.curve.adev.max() * 1.5)  # the curves; a term's line may leave it
        ax.set_xlabel("averaging time tau [s]")
        ax.set_ylabel(f"Allan deviation [{plain(s.unit)}]")
        ax.set_title(f"{s.sensor}: white (dotted), floor (dashed), walk (dash-dot)", fontsize=9)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8, loc="best")
    fig.suptitle(plain(f"Allan deviation of {n.segment} ({n.rate:.4g} Hz)"), fontsize=10)
    fig.tight_layout()
    fig.savefig(path, format="png")
    plt.close(fig)
