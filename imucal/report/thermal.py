"""A temperature sweep's calibration in words and in a figure (imucal.thermal holds the values)."""
from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from imucal.constants import STANDARD_GRAVITY
from imucal.model.effects import AXIS_NAMES
from imucal.thermal.evidence import TEMPERATURE_STEP

if TYPE_CHECKING:
    from imucal.thermal.lag import LagTest
    from imucal.thermal.run import ThermalCalibration

#: [m/s^2] one milli-g (standard gravity / 1000): the unit the words give residuals in.
MG = STANDARD_GRAVITY / 1000.0


def lag_lines(lag: LagTest) -> list[str]:
    tau = (f"first-order lag of the temperature sensor: tau = {lag.tau:.3g} +/- {lag.tau_std:.2g} s "
           f"(Wald {lag.tau_lr:.3g}, p adjusted {lag.tau_p:.2g}): ")
    tau += "named: the die leads the sensor" if lag.lag_named else "not shown by these data (none claimed)"
    h = ", ".join(f"{AXIS_NAMES[i]} {lag.hysteresis[i] / MG:+.2f} +/- {lag.hysteresis_std[i] / MG:.2f}"
                  for i in range(3))
    hy = (f"hysteresis (warming minus cooling, half): {h} mg over {lag.n_warming} warming and {lag.n_cooling} "
          f"cooling rows (Wald {lag.hysteresis_lr:.3g}, p adjusted {lag.hysteresis_p:.2g}): ")
    hy += "named" if lag.hysteresis_named else "not shown by these data (none claimed)"
    return [tau, hy]


def determined_lines(tc: ThermalCalibration) -> list[str]:
    """What the poses determine and what they do not, with what to record."""
    from imucal.thermal.determine import advice

    out = [f"poses over temperature: {'; '.join(tc.support.describe())}"]
    for t in tc.selection.undetermined:
        out.append(f"{t.label} is not determined by these poses (standard error {t.std:.3g} against its "
                   f"magnitude {t.typical:.3g}): {advice(t.name.split('_')[0], t.axis, tc.support)}")
    if tc.one_sided:
        axes = ", ".join(AXIS_NAMES[i] for i in tc.one_sided)
        held = f" (held by the run file: {', '.join(tc.held)})" if tc.held else ""
        out.append(f"axes {axes} meet gravity in one direction only: the absolute bias and scale at the reference "
                   f"temperature are not determined by this recording{held}, only their change with "
                   "temperature; calibrate them from a multi-pose log (or hold each axis up and down)")
    return out


def gap_lines(tc: ThermalCalibration, alpha: float) -> list[str]:
    """Discover's [[Gap]] for a sweep: the rows about their poses without and with the terms."""
    b, f = tc.selection.none, tc.selection.fit
    return ["[[Gap]]            before          after           (temperature rows about their poses)",
            f"    RMS        = {b.rms:<15.6g} {f.rms:<15.6g} m/s^2 (noise of a row: {f.sigma:.3g})",
            f"    chi2 / dof = {b.chi2:.4g} / {b.dof:<6d}  {f.chi2:.4g} / {f.dof}",
            f"    chi2/dof   = {b.redchi:<15.4g} {f.redchi:<15.4g} (1 = residual at noise level)",
            f"    p (chi2)   = {tc.p_noise(False):<15.3g} {tc.p_noise(True):<15.3g} "
            f"(below {alpha:g}: disagrees with the noise)"]


def gyro_lines(tc: ThermalCalibration) -> list[str]:
    """The gyroscope's bias(T) from the same rows (the calibration's gyroscope section), and its drift beside it."""
    g, section = tc.gyro, tc.final.calibration.gyro
    if g is None or section is None:
        return [tc.gyro_note] if tc.gyro_note else []
    held = section.fit.get("held", "scale, misalignment and g-sensitivity held")
    rms = lambda x: np.sqrt(np.mean(x ** 2, axis=0)) * 1e3  # noqa: E731  [mrad/s]
    out = [f"gyroscope bias(T) (in the calibration's gyroscope section; {held}): "
           "orders x, y, z = "
           + ", ".join(map(str, g.orders)) + "; rows about their poses "
           + ", ".join(f"{b:.3g} -> {a:.3g}" for b, a in zip(rms(g.before), rms(g.after))) + " mrad/s"]
    out += [f"    {n} = {g.params[n].value:.4g} +/- {g.std[n]:.2g} {g.params[n].unit}" for n in g.params.free_names]
    out.append("gyroscope drift in time fitted beside it: " + ", ".join(
        f"{a} {d * 1e3:+.2f} +/- {s * 1e3:.2f} mrad/s per day" for a, d, s in zip(AXIS_NAMES, g.drift, g.drift_std))
               + "; correlation with the linear temperature term " + ", ".join(
        "n/a" if not np.isfinite(c) else f"{c:+.2f}" for c in g.drift_correlation)
               + ": a sweep warms over hours, so a drift and a temperature term are confounded")
    return out


def thermal_lines(tc: ThermalCalibration) -> list[str]:
    """The [[Temperature]] section of the discover report."""
    from imucal.thermal.run import axis_rms

    sel = tc.selection
    L = ["[[Temperature]]  pose constancy: a still pose's calibrated reading does not change with temperature",
         f"    rows       = {tc.rows.n} (at most {TEMPERATURE_STEP:g} degC each) in {tc.rows.poses.size} poses, "
         f"{tc.temperature_range[0]:.2f}..{tc.temperature_range[1]:.2f} degC",
         "    RMS about the poses, per axis (x, y, z): before "
         + ", ".join(f"{v / MG:.3g}" for v in axis_rms(tc, False))
         + " mg; after " + ", ".join(f"{v / MG:.3g}" for v in axis_rms(tc)) + " mg"]
    for r in sel.rounds:
        tried = [t for t in r.trials if t.dof > 0]
        skipped = [t.label for t in r.trials if not t.determined]
        what = (f"added {r.chosen.label} (LR {r.chosen.lr:.4g}, p adjusted {r.chosen.p_adjusted:.3g})" if r.chosen
                else ("no candidate significant" + (f" (best {tried[0].label}: LR {tried[0].lr:.3g}, p adjusted "
                                                    f"{tried[0].p_adjusted:.3g})" if tried else "")))
        L.append(f"    round {r.index}: {what}" + (f"; not determined: {', '.join(skipped)}" if skipped else ""))
    for n in sel.fit.free_names:
        p = sel.fit.params[n]
        L.append(f"    {n:<26s} = {p.value:.6g} +/- {sel.fit.std[n]:.3g} {p.unit}")
    L.extend(f"    - {s}" for s in [*lag_lines(tc.lag), *determined_lines(tc)])
    L.extend(("    - " if not s.startswith("    ") else "      ") + s.strip() for s in gyro_lines(tc))
    return L


def thermal_json(tc: ThermalCalibration) -> dict[str, Any]:
    from imucal.thermal.run import axis_rms

    lag = tc.lag

    def num(x: float) -> float | None:
        return float(x) if math.isfinite(x) else None

    return {"rows": tc.rows.n, "poses": int(tc.rows.poses.size), "temperature_range": list(tc.temperature_range),
            "effects": {n: [AXIS_NAMES[a] for a in ax] for n, ax in tc.effects.items()},
            "coefficients": {n: tc.selection.fit.params[n].value for n in tc.selection.fit.free_names},
            "std": {n: num(v) for n, v in tc.selection.fit.std.items()},
            "rms_before": tc.rms_before, "rms_after": tc.rms_after, "rms_unit": "m/s^2",
            "rms_axis_before": axis_rms(tc, False).tolist(), "rms_axis_after": axis_rms(tc).tolist(),
            "undetermined": [t.label for t in tc.selection.undetermined],
            "lag": {"tau_s": num(lag.tau), "tau_std_s": num(lag.tau_std), "p": lag.tau_p, "named": lag.lag_named},
            "hysteresis": {"half_warming_minus_cooling": lag.hysteresis.tolist(),
                           "std": [num(v) for v in lag.hysteresis_std], "p": lag.hysteresis_p,
                           "named": lag.hysteresis_named},
            "one_sided_axes": [AXIS_NAMES[i] for i in tc.one_sided],
            "gyro_note": tc.gyro_note or None,
            "gyro": None if tc.gyro is None else {
                "orders": list(tc.gyro.orders), "unit": "rad/s",
                "coefficients": {n: tc.gyro.params[n].value for n in tc.gyro.params.free_names},
                "std": {n: num(v) for n, v in tc.gyro.std.items()},
                "drift_per_day": tc.gyro.drift.tolist(), "drift_std_per_day": tc.gyro.drift_std.tolist()}}


def residual_temperature_figure(temp: np.ndarray, before: np.ndarray, after: np.ndarray, pose: np.ndarray,
                                path: str | Path | Any, title: str) -> None:
    """Residual about each pose [mg] against temperature, per axis: without the temperature terms and
    with them. ``before``/``after``: (n, 3) [m/s^2]; ``pose``: (n,) pose of each point (its colour)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(3, 2, figsize=(10, 9), dpi=100)
    colours = plt.get_cmap("tab10")
    poses = np.unique(pose)
    for i in range(3):
        top = max(float(np.max(np.abs(before[:, i]))), float(np.max(np.abs(after[:, i]))), 1e-12) / MG * 1.1
        for j, (vals, what) in enumerate(((before, "uncorrected"), (after, "corrected"))):
            ax = axes[i, j]
            for c, p in enumerate(poses):
                m = pose == p
                ax.plot(temp[m], vals[m, i] / MG, ".", ms=3, color=colours(c % 10), label=f"pose {int(p)}")
            rms = float(np.sqrt(np.mean(vals[:, i] ** 2))) / MG
            ax.set_title(f"axis {AXIS_NAMES[i]}, {what}: RMS {rms:.3g} mg", fontsize=9)
            ax.set_ylim(-top, top)  # one scale per axis: before and after compare at a glance
            ax.grid(True, alpha=0.3)
            ax.set_xlabel("temperature [degC]", fontsize=8)
            ax.set_ylabel("about the pose [mg]", fontsize=8)
    axes[0, 1].legend(fontsize=7, loc="best", markerscale=2)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, format="png")
    plt.close(fig)


def thermal_figure(tc: ThermalCalibration, path: str | Path | Any) -> None:
    """The rows' residual about their poses against temperature, before and after the terms found."""
    residual_temperature_figure(tc.rows.temp, tc.selection.none.residuals, tc.selection.fit.residuals, tc.rows.pose,
                                path, f"still poses over temperature: rows at most {TEMPERATURE_STEP:g} degC wide, "
                                      "residual about each pose's own reading")
