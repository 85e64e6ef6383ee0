"""The calibration's figures (PNG): the recording, |a| - g before and after, the residual per interval
and the intervals' directions on the sphere.

Plotting is kept apart from the maths; matplotlib is imported only when a figure is made, through
imucal.report.canvas (fixed margins, no pyplot).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from imucal.errors import printable
from imucal.pipeline import CalibrationRun
from imucal.report.canvas import Margins, new_figure, plain_ticks, save_png
from imucal.report.text import interval_residuals


def _plt():
    """pyplot on the Agg backend, for the figures drawn outside this module (fleet, discover, poses)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


#: The residual and before/after figures' size [in]; the recording's width.
WIDE, WIDE_H = 9.0, 4.2


def plain(text: str) -> str:
    """User text shown literally in a figure: dollar signs would start matplotlib's mathtext, a name that is
    not UTF-8 (a lone surrogate, b'log\xff.csv') is shown escaped, as every text output writes it
    (imucal.files.output.TEXT_ERRORS), and so is a character no font draws (a control character such as
    the \\r in a file name: matplotlib warned 'Glyph 13 missing from font(s)' on stderr)."""
    return printable(text).replace("$", r"\$")


def no_intervals_figure(path: str | Path) -> None:
    """The place of a per-interval figure for a log without a still interval (an accelerometer taken from
    fit.base on a hand-turned log: imucal.pipeline.taken_whole)."""
    fig, axes = new_figure(WIDE, WIDE_H)
    ax = axes[0, 0]
    ax.text(0.5, 0.5, "no still interval in this log: |a| - g not checked", ha="center", va="center")
    ax.set_axis_off()
    save_png(fig, path)


def residual_figure(run: CalibrationRun, path: str | Path) -> None:
    res, iv = run.result, run.intervals
    if iv.n == 0:
        return no_intervals_figure(path)
    r, s = interval_residuals(run)
    fig, axes = new_figure(WIDE, WIDE_H)
    ax = axes[0, 0]
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
    save_png(fig, path)


def _polar_angle_map(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Azimuthal equidistant projection about +z: distance from the centre = angle from +z [deg]."""
    ang = np.degrees(np.arccos(np.clip(v[:, 2], -1, 1)))
    h = np.hypot(v[:, 0], v[:, 1])
    safe = np.where(h > 0, h, 1.0)
    return ang * v[:, 0] / safe, ang * v[:, 1] / safe


#: Two lines of figure title and two of each disk's title above the disks; the right disk's tick labels
#: and y label between them.
DIRECTIONS_MARGINS = Margins(top=1.05, wspace=0.3)


def directions_figure(run: CalibrationRun, path: str | Path) -> None:
    """Gravity directions of the intervals, one disk per hemisphere: the distance from a disk's
    centre is the angle from the +z (left) or -z (right) sensor axis, in degrees. Every interval is
    numbered as in the report's tables; intervals in the same pose share a colour and a label."""
    if run.intervals.n == 0:
        return no_intervals_figure(path)
    d = run.directions
    labels = run.observability.labels
    fig, axes = new_figure(10, 5.6, DIRECTIONS_MARGINS, 1, 2)
    circ = np.linspace(0, 2 * np.pi, 200)
    for ax, sign in ((axes[0, 0], 1), (axes[0, 1], -1)):
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
    save_png(fig, path)


#: Points drawn per channel of the recording's time series (evenly spaced samples): a screen's width.
SERIES_POINTS = 4000
#: Shading of the recording's spans: still intervals, intervals dropped (an axis clipped), and still
#: intervals the gyroscope showed turning (imucal.gyro.still).
STILL, DROPPED, TURNING = ("tab:green", 0.14), ("tab:red", 0.30), ("tab:orange", 0.35)


def _shade(ax, spans, style, label: str, hatch: str | None = None) -> None:
    for k, (a, b) in enumerate(spans):
        ax.axvspan(a, b, color=style[0], alpha=style[1], lw=0, hatch=hatch, label=label if k == 0 else None)


def _gyro_turning(run: CalibrationRun) -> list[tuple[float, float]]:
    if run.gyro is None:
        return []
    from imucal.gyro.result import motions  # only a run with a gyroscope

    st = motions(run.gyro).still
    return [] if st is None else [(r.t_start, r.t_end) for r in st.rejected]


def _gyro_samples(run: CalibrationRun) -> np.ndarray | None:
    """The gyroscope's raw readings on the accelerometer's samples: the recording's columns, or the second
    file the run names (data.gyro_path, imu_tk's layout); None without a gyroscope."""
    rec, data = run.recording, run.config.data
    if rec.raw is None or run.calibration.gyro is None:
        return None
    if rec.gyro is not None or data.gyro_path is None:
        return rec.gyro
    from imucal.gyro.run import gyro_on_accel_samples  # only a run with a gyroscope

    p = Path(data.gyro_path)
    return gyro_on_accel_samples(rec, str(p if p.is_absolute() or run.config.base_dir is None
                                          else run.config.base_dir / p))


#: The panels share the time axis: little space between them.
RECORDING_MARGINS = Margins(hspace=0.1)


def recording_figure(run: CalibrationRun, path: str | Path) -> None:
    """The recording against time: calibrated acceleration (and angular rate, when the run calibrated a
    gyroscope), the still intervals shaded, the dropped and the gyro's turning ones marked."""
    from imucal.model.channels import covariate_values

    rec, cal, iv = run.recording, run.calibration, run.intervals
    gyro = _gyro_samples(run)
    fig, axes = new_figure(10, 5.6 if gyro is not None else 3.4, RECORDING_MARGINS, 2 if gyro is not None else 1,
                           sharex=True)
    panels = [(axes[0, 0], "acceleration [m/s^2]")] + ([(axes[1, 0], "angular rate [deg/s]")] if gyro is not None else [])
    if rec.raw is not None:  # (a file read in chunks keeps no samples: the spans alone)
        k = np.unique(np.linspace(0, rec.n - 1, min(rec.n, SERIES_POINTS)).astype(int))
        covs = covariate_values(cal.covariates, temp=None if rec.temp is None else rec.temp[k], time=rec.t[k])
        acc = cal.apply(rec.raw[k], covs)
        series = [acc] + ([np.degrees(cal.gyro.apply(gyro[k], acc))] if gyro is not None else [])
        for (ax, _), y in zip(panels, series):
            for j, (a, c) in enumerate(zip("xyz", ("tab:blue", "tab:orange", "tab:green"))):
                ax.plot(rec.t[k], y[:, j], lw=0.7, color=c, label=a)
    dropped = [(d["t_start"], d["t_end"]) for d in cal.data.get("dropped_intervals", [])]
    for ax, label in panels:
        _shade(ax, zip(iv.t_start, iv.t_end), STILL, f"still ({iv.n})")
        _shade(ax, dropped, DROPPED, f"dropped: an axis clipped ({len(dropped)})", "//")
        _shade(ax, _gyro_turning(run), TURNING, "turning for the gyro", "xx")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
        ax.legend(loc="upper right", fontsize=7, ncol=6)
    axes[-1, 0].set_xlabel("time [s]")
    fig.suptitle(plain(f"{Path(rec.source).name}: {rec.n} samples, {iv.n} still intervals"), fontsize=10)
    save_png(fig, path)


def before_after(run: CalibrationRun) -> tuple[np.ndarray, np.ndarray]:
    """|a| - g [m/s^2] at each interval mean before calibration and after. Before: the readings with one
    offset and one scale common to the three axes (the means of the fitted ones: an ADC's mid-scale code
    and its nominal sensitivity), so what the per-axis offsets, scales and angles correct."""
    p = run.calibration.params
    s = float(np.mean([p[f"s{i}"].value for i in (1, 2, 3)]))
    b = float(np.mean([p[f"b{i}"].value for i in (1, 2, 3)]))
    before = np.linalg.norm((run.intervals.mean - s) / b, axis=1) - run.calibration.gravity
    return before, interval_residuals(run)[0]


#: The legend sits below the x label.
BEFORE_AFTER_MARGINS = Margins(bottom=0.95)


def before_after_figure(run: CalibrationRun, path: str | Path) -> None:
    """|a| - g per pose before and after the calibration, on a scale linear near zero and logarithmic
    beyond (the two differ by orders of magnitude)."""
    if run.intervals.n == 0:
        return no_intervals_figure(path)
    before, after = before_after(run)
    k = np.arange(before.size)
    fig, axes = new_figure(WIDE, WIDE_H, BEFORE_AFTER_MARGINS)
    ax = axes[0, 0]
    ax.plot(k, before * 1e3, "s", ms=5, color="0.55", label="before: one offset and one scale for all axes")
    ax.plot(k, after * 1e3, "o", ms=5, color="tab:blue", label="after the calibration")
    rms = float(np.sqrt(np.mean(after**2))) * 1e3
    ax.set_yscale("symlog", linthresh=max(rms, 1e-6))
    plain_ticks(ax)
    ax.axhline(0, color="k", lw=0.8)
    ax.set_xlabel("static interval, as numbered in the report [#]")
    ax.set_ylabel("|a| - g  [mm/s^2]")
    ax.set_title(f"|a| - g per pose: RMS {np.sqrt(np.mean(before**2)) * 1e3:.4g} mm/s^2 before, {rms:.3g} after")
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=2, fontsize=8, frameon=False)
    ax.grid(alpha=0.3, which="both")
    save_png(fig, path)


FIGURES = {"recording.png": recording_figure, "before_after.png": before_after_figure,
           "residuals.png": residual_figure, "directions.png": directions_figure}
