"""Figures of a discovery (PNG, matplotlib Agg imported only when a figure is made).

- residuals: where the base model disagrees with the noise, before and after the effects found:
  normalised residual (|a| - g) / sigma of each interval mean against time, temperature and the
  gravity component along each sensor axis (orientation and axis);
- candidates: the likelihood-ratio statistic of every candidate of each round against the
  significance threshold;
- gap: RMS and chi-square per degree of freedom before and after, against the noise level;
- allan: the overlapping Allan deviation of the longest still interval (when it is long enough) with
  the +1/2 slope line q sqrt(tau / 3) of the bias random walk discovery found.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from imucal.analysis.discover import Discovery
from imucal.report.discover_text import HEADLINE, verdict_text
from imucal.solve.stats import chi2_sf
from imucal.model.effects import AXIS_NAMES
from imucal.report.figures import plain
import textwrap


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


#: |residual / sigma| beyond this is drawn as "beyond the noise" (3 sigma).
BAND = 3.0


def _norm(run) -> np.ndarray:
    return run.result.residuals / run.result.sigma


def residuals_figure(d: Discovery, path: str | Path) -> None:
    """Normalised residual against time, temperature and the gravity component on x, y, z.

    The sixth panel plots the base residual against the part of it the effects explain (base
    minus final residual): when an effect is what was missing, the points lie on the diagonal.
    """
    plt = _plt()
    iv = d.base.intervals
    before, after = _norm(d.base), _norm(d.final)
    changed = d.final is not d.base
    dirs = d.base.directions
    fig, axes = plt.subplots(2, 3, figsize=(13, 7.6), dpi=100)
    panels = [(axes[0, 0], iv.t_mid, "time of the interval [s]"),
              (axes[0, 1], iv.temp, "mean temperature of the interval [degC]")]
    panels += [(axes[1, i], dirs[:, i], f"gravity component along axis {AXIS_NAMES[i]} [g]")
               for i in range(3)]
    lim = max(BAND * 1.5, float(np.nanmax(np.abs(np.concatenate([before, after])))) * 1.1)
    for ax, x, label in panels:
        if x is None:
            ax.axis("off")
            ax.text(0.5, 0.5, "no temperature column:\ntemperature effects not tested", ha="center",
                    va="center", transform=ax.transAxes, color="0.35")
            continue
        ax.axhspan(-BAND, BAND, color="0.9", zorder=0)
        ax.axhline(0, color="k", lw=0.7)
        ax.plot(x, before, "o", ms=5, mfc="none", color="tab:red", label=f"base model ({d.base.result.model_name})")
        if changed:
            ax.plot(x, after, ".", ms=7, color="tab:blue", label=f"with effects ({d.final.result.model_name})")
        ax.set_xlabel(label)
        ax.set_ylim(-lim, lim)
        ax.grid(alpha=0.3)
        ax.set_ylabel("residual (|a| - g) / σ  [σ]")
    # What the effects explain, interval by interval.
    ax = axes[0, 2]
    if changed:
        ax.axhspan(-BAND, BAND, color="0.9", zorder=0)
        explained = before - after
        lo, hi = float(min(explained.min(), before.min())), float(max(explained.max(), before.max()))
        ax.plot([lo, hi], [lo, hi], color="tab:blue", lw=1, label="base residual = explained part")
        ax.plot(explained, before, "o", ms=5, mfc="none", color="tab:red")
        ax.set_xlabel("part explained by " + ", ".join(e.label for e in d.effects) + "  [σ]")
        ax.legend(fontsize=7, loc="upper left")
        ax.set_ylabel("base residual (|a| - g) / σ  [σ]")
    else:  # nothing added: how the residuals compare with the noise they should have
        edges = np.linspace(-lim, lim, 25)
        ax.hist(before, bins=edges, color="tab:red", alpha=0.6, label="residual / sigma")
        z = np.linspace(-lim, lim, 200)
        width = edges[1] - edges[0]
        ax.plot(z, before.size * width * np.exp(-z**2 / 2) / np.sqrt(2 * np.pi), color="k", lw=1,
                label="noise alone: N(0, 1)")
        ax.set_xlabel("residual (|a| - g) / σ, no effect added  [σ]")
        ax.set_ylabel("static intervals per bin [count]")
        ax.legend(fontsize=7, loc="upper left")
    ax.grid(alpha=0.3)
    h, lab = axes[1, 0].get_legend_handles_labels()
    fig.legend(h + [plt.Rectangle((0, 0), 1, 1, color="0.9")], lab + [f"within +-{BAND:g} sigma of the noise"],
               loc="lower center", ncol=3, fontsize=9, frameon=False)
    if changed:
        gap = (f"chi2/dof {d.base.result.redchi:.3g} -> {d.final.result.redchi:.3g}, RMS {d.rms_before * 1e3:.3g} -> "
               f"{d.rms_after * 1e3:.3g} mm/s^2 (noise alone {d.rms_noise * 1e3:.3g}); effects added: "
               + ", ".join(e.label for e in d.effects))
    else:
        gap = (f"chi2/dof {d.base.result.redchi:.3g}, RMS {d.rms_before * 1e3:.3g} mm/s^2 (noise alone "
               f"{d.rms_noise * 1e3:.3g}); no effect added")
    fig.suptitle(f"{plain(Path(d.base.recording.source).name)}: {iv.n} static intervals; residual of each interval mean "
                 f"over its noise sigma\n{gap}", fontsize=11)
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    fig.savefig(path, format="png")
    plt.close(fig)


def _wrap(text: str, width: int) -> str:

    return "\n".join(textwrap.wrap(text, width))


def _critical_lr(k: int, p: float) -> float:
    """x with P(chi2(k) > x) = p, by bisection on chi2_sf."""
    lo, hi = 0.0, 1.0
    while chi2_sf(hi, k) > p:
        hi *= 2
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if chi2_sf(mid, k) > p else (lo, mid)
    return hi


def candidates_figure(d: Discovery, path: str | Path, top: int = 14) -> None:
    """Likelihood-ratio statistic of the candidates of each round, against the threshold."""
    plt = _plt()
    steps = d.steps
    if not steps:
        fig, ax = plt.subplots(figsize=(8, 2.6), dpi=100)
        ax.axis("off")
        ax.text(0.5, 0.5, _wrap("No candidates were tried: " + verdict_text(d.verdict), 80), ha="center", va="center",
                fontsize=10)
        fig.savefig(path, format="png")
        plt.close(fig)
        return
    fig, axes = plt.subplots(1, len(steps), figsize=(7.5 * len(steps), 0.36 * top + 1.8), dpi=100,
                             squeeze=False)
    for ax, s in zip(axes[0], steps):
        cs = sorted(s.candidates, key=lambda c: (not c.fitted, c.score if c.fitted else c.chi2_screen))[:top]
        cs = cs[::-1]
        M = len(s.candidates)
        vals = []
        for c in cs:
            if c.fitted:
                vals.append(c.lr)
            else:  # screened only: the Gauss-Newton estimate of the same statistic
                vals.append(max(0.0, (s.chi2_before - c.chi2_screen) / s.scale))
        colors = ["tab:green" if (s.chosen is not None and c.label == s.chosen.label) else
                  ("tab:orange" if c.significant else ("0.6" if c.fitted else "0.85")) for c in cs]
        y = np.arange(len(cs))
        ax.barh(y, np.maximum(vals, 1e-2), color=colors)
        ax.set_yticks(y)
        ax.set_yticklabels([c.label + ("" if c.fitted else " (screened)") for c in cs], fontsize=8)
        ax.set_xscale("log")
        crit = _critical_lr(1, d.settings.alpha_effect / M)
        ax.axvline(crit, color="k", ls="--", lw=1)
        ax.text(crit, -0.9, f"significance threshold (1 coefficient, p = {d.settings.alpha_effect:g} / {M}) ",
                fontsize=7, va="center", ha="right")
        ax.set_ylim(-1.4, len(cs) - 0.5)
        ax.set_xlim(min(0.5, min(vals) * 0.8 if min(vals) > 0 else 0.5), max(max(vals), crit) * 3)
        ax.set_xlabel("likelihood-ratio statistic: chi-square removed / misfit scale  [1]")
        ax.set_ylabel("candidate effect and its axes")
        chosen = s.chosen.label if s.chosen else "none significant"
        ax.set_title(f"Round {s.index}: {M} candidates; added: {chosen}\n(ranked by chi-square left + "
                     f"{d.settings.penalty:.3g} per coefficient; the best are fitted in full)", fontsize=9)
        ax.grid(axis="x", alpha=0.3)
    from matplotlib.patches import Patch

    fig.legend(handles=[Patch(color="tab:green", label="added"), Patch(color="tab:orange", label="significant"),
                        Patch(color="0.6", label="fitted, not significant"),
                        Patch(color="0.85", label="screened (linearised), not fitted")],
               loc="lower center", ncol=4, fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0.06, 1, 1))
    fig.savefig(path, format="png")
    plt.close(fig)


def gap_figure(d: Discovery, path: str | Path) -> None:
    """RMS and chi-square per dof before and after, with the noise level."""
    plt = _plt()
    b, f = d.base.result, d.final.result
    rms_all, red_all, noise, dof = [d.rms_before, d.rms_after], [b.redchi, f.redchi], d.rms_noise, f.dof
    what, noise_label = "RMS of |a| - g on interval means [mm/s^2]", "noise of the means alone"
    if d.thermal is not None:  # a sweep: its gap is the temperature rows' constancy about their poses
        none, fit = d.thermal.selection.none, d.thermal.selection.fit
        rms_all, red_all, noise, dof = [none.rms, fit.rms], [none.redchi, fit.redchi], fit.sigma, fit.dof
        what, noise_label = "RMS of the temperature rows about their poses [mm/s^2]", "noise of a row"
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(9, 3.8), dpi=100)
    if d.effects:
        labels, x = ["base model", "with " + ", ".join(e.label for e in d.effects)], [0, 1]
        rms, red, colors = rms_all, red_all, ["tab:red", "tab:blue"]
    else:
        labels, x = ["base model (nothing added)"], [0]
        rms, red, colors = rms_all[:1], red_all[:1], ["tab:red"]
    red = [v if np.isfinite(v) else 0.0 for v in red]  # no degrees of freedom: nothing to show
    a1.bar(x, np.array(rms) * 1e3, color=colors, width=0.5)
    a1.axhline(noise * 1e3, color="k", ls="--", lw=1, label=noise_label)
    a1.set_ylabel(what)
    a2.bar(x, red, color=colors, width=0.5)
    a2.axhline(1.0, color="k", ls="--", lw=1, label="1 = at noise level")
    crit = _critical_lr(max(dof, 1), d.settings.alpha_noise) / max(dof, 1)
    a2.axhline(crit, color="tab:gray", ls=":", lw=1.2, label=f"p = {d.settings.alpha_noise:g} limit ({dof} dof)")
    a2.set_ylabel("chi-square per degree of freedom  [1]")
    for ax, top in ((a1, max(max(rms), noise) * 1e3), (a2, max(max(red), crit))):
        ax.set_xticks(x)
        ax.set_xticklabels(labels, fontsize=8)
        ax.set_xlabel("model")
        ax.set_xlim(-0.6, len(x) - 0.4)
        if ax is a2 and top > 30:
            ax.set_yscale("log")
            ax.set_ylim(0.1, top * 8)
        else:
            ax.set_ylim(0, top * 1.35)
        ax.legend(fontsize=8, loc="upper right")
    fig.suptitle("The gap before and after adding the effects found" if d.effects
                 else "The gap: no effect added (" + HEADLINE[d.verdict.outcome] + ")", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, format="png")
    plt.close(fig)


def allan_figure(d: Discovery, path: str | Path) -> None:
    """Allan deviation per axis of the longest still interval, with the discovered random walk's line."""
    plt = _plt()
    a = d.allan
    if a is None:
        fig, ax = plt.subplots(figsize=(8, 2.2), dpi=100)
        ax.axis("off")
        ax.text(0.5, 0.5, _wrap("No Allan view: the recording has no still interval of at least "
                                "10000 samples (100 x 100 sample periods).", 80), ha="center", va="center", fontsize=10)
        fig.savefig(path, format="png")
        plt.close(fig)
        return
    fig, ax = plt.subplots(figsize=(7, 4.6), dpi=100)
    for i, c in enumerate(("tab:red", "tab:green", "tab:blue")):
        ax.loglog(a.tau, a.adev[:, i], color=c, lw=1.4, label=f"measured, axis {AXIS_NAMES[i]}")
    if a.q > 0:
        ax.loglog(a.tau, a.line(), "k--", lw=1.2, label=f"bias_random_walk found: q sqrt(tau/3), q = {a.q:.3g} m/s^2/sqrt(s)")
        lo, hi = max(a.q - a.q_std, 0.0), a.q + a.q_std
        ax.fill_between(a.tau, lo * np.sqrt(a.tau / 3), hi * np.sqrt(a.tau / 3), color="k", alpha=0.12,
                        label="+/- 1 std of q")
    ax.set_xlabel("averaging time tau [s]")
    ax.set_ylabel("Allan deviation [m/s^2]")
    ax.legend(fontsize=8, loc="best")
    ax.grid(True, which="both", alpha=0.3)
    fig.suptitle(f"Allan view: interval {a.interval}, {a.duration:.0f} s still at {a.rate:.0f} Hz", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, format="png")
    plt.close(fig)


def temperature_figure(d: Discovery, path: str | Path) -> None:
    """A temperature sweep's rows about their poses against temperature, before and after the terms
    found (imucal.report.thermal); a note when the recording is no sweep."""
    if d.thermal is not None:
        from imucal.report.thermal import thermal_figure

        thermal_figure(d.thermal, path)
        return
    plt = _plt()
    fig, ax = plt.subplots(figsize=(8, 2.2), dpi=100)
    ax.axis("off")
    ax.text(0.5, 0.5, _wrap("No temperature sweep: no still pose of this recording spans half a degree or more "
                            "(or it has no temperature column).", 80), ha="center", va="center", fontsize=10)
    fig.savefig(path, format="png")
    plt.close(fig)


#: File name -> figure function, for `imucal discover --plot DIR`.
FIGURES = {"discover_residuals.png": residuals_figure, "discover_candidates.png": candidates_figure,
           "discover_gap.png": gap_figure, "discover_allan.png": allan_figure,
           "discover_temperature.png": temperature_figure}
