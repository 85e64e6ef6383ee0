"""Navigation drift: what a constant acceleration error does to dead-reckoned position.

Double integration of a constant error e from a correct start gives p(t) = e t^2 / 2 (paper,
Introduction: "catastrophic error ... within a few seconds of integrating").

The error of each treatment is the magnitude error at rest, | |a_hat| - g |: the only error a
still sensor reveals without an external attitude reference. The vector error is at least this
large (| |a_hat| - |a| | <= |a_hat - a|), so the drifts of raw and angles-ignored are lower bounds.
Treatments of one calibration (s, b, angles fitted; docs/worst_case.md):
  raw             a_hat = (raw - s_bar) / b_bar with one offset s_bar = mean(s_i) and one scale
                  b_bar = (b1 b2 b3)^(1/3) for all axes: nominal values, as exact on average as a
                  datasheet could be (this also absorbs an ADC's mid-scale zero, e.g. 32768), but
                  no per-axis shift or scale and no angles.
  angles ignored  a_hat = (raw - s) / b (fitted s, b; angles forced to pi/2, Proposition 1).
  calibrated      the full model (Theorem); its error is the fit's RMS residual on its own data,
                  or the residual on a given recording.
Without a recording, raw and angles-ignored are evaluated on 2000 gravity directions spread
evenly over the sphere (|a| = g, raw = s + b * (E^T a), the model read forwards).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from imucal.errors import ImucalError
from imucal.model.channels import covariate_values
import casadi as ca
from imucal.model.sensor import frame
from imucal.data.static import detect_static

#: The issue's table times [s].
TABLE_TIMES = (1.0, 5.0, 10.0, 60.0)
DIRECTIONS = 2000


def position_error(error: float, t: np.ndarray | float) -> np.ndarray:
    """p(t) = e t^2 / 2 [m] for a constant acceleration error e [m/s^2]."""
    return 0.5 * error * np.asarray(t, float) ** 2


@dataclass(frozen=True)
class DriftCase:
    """One constant acceleration error and where it comes from."""

    name: str
    error: float  #: the error integrated [m/s^2]
    statistic: str  #: how ``error`` was obtained
    error_max: float | None = None  #: largest single error, when ``error`` is an RMS [m/s^2]

    def to_dict(self, times: Sequence[float]) -> dict[str, Any]:
        return {"name": self.name, "error": self.error, "error_unit": "m/s^2",
                "statistic": self.statistic, "error_max": self.error_max,
                "position_error": [float(p) for p in position_error(self.error, times)],
                "position_unit": "m"}


@dataclass(frozen=True)
class DriftReport:
    cases: tuple[DriftCase, ...]
    times: tuple[float, ...]
    gravity: float
    source: dict[str, Any] = field(default_factory=dict)

    def table(self) -> str:
        """Fixed-width text table: one row per case, position error [m] at each time."""
        head = ["case", "error [m/s^2]"] + [f"p({t:g} s) [m]" for t in self.times]
        rows = [[c.name, f"{c.error:.4g}"] + [f"{p:.4g}" for p in position_error(c.error, self.times)]
                for c in self.cases]
        w = [max(len(r[i]) for r in [head] + rows) for i in range(len(head))]
        fmt = lambda r: "  ".join(x.ljust(w[0]) if i == 0 else x.rjust(w[i]) for i, x in enumerate(r))
        return "\n".join([fmt(head), "  ".join("-" * x for x in w)] + [fmt(r) for r in rows])

    def to_dict(self) -> dict[str, Any]:
        return {"format": "imucal-drift", "format_version": 1, "model": "p(t) = e t^2 / 2",
                "gravity": self.gravity, "gravity_unit": "m/s^2", "times": list(self.times),
                "time_unit": "s", "source": dict(self.source),
                "cases": [c.to_dict(self.times) for c in self.cases]}


def table_times(duration: float) -> tuple[float, ...]:
    """The table's times [s]: the standard ones up to ``duration``, and ``duration`` itself."""
    if not (math.isfinite(duration) and 0 < duration <= 1e7):
        raise ImucalError(f"duration {duration:g} s must be positive (at most 1e7 s)", field="duration",
                          fix="give the dead-reckoning time in seconds, e.g. 60")
    return tuple(sorted({t for t in TABLE_TIMES if t <= duration} | {float(duration)}))


def sphere_directions(n: int = DIRECTIONS) -> np.ndarray:
    """n unit vectors spread evenly over the sphere (Fibonacci lattice), (n, 3)."""
    k = np.arange(n) + 0.5
    z = 1 - 2 * k / n
    phi = math.pi * (3 - math.sqrt(5)) * k
    r = np.sqrt(1 - z**2)
    return np.column_stack([r * np.cos(phi), r * np.sin(phi), z])


def _stats(err: np.ndarray) -> tuple[float, float]:
    return float(np.sqrt(np.mean(err**2))), float(np.max(err))


def calibration_cases(cal: Any, gravity: float, recording: Any = None) -> list[DriftCase]:
    """Raw, angles ignored and calibrated errors of one calibration (definitions at the top)."""


    v = {n: float(cal.params[n].value) for n in ("s1", "s2", "s3", "b1", "b2", "b3", "phi", "psi", "theta")}
    s = np.array([v["s1"], v["s2"], v["s3"]])
    b = np.array([v["b1"], v["b2"], v["b3"]])
    s_bar, b_bar = float(np.mean(s)), float(np.prod(b) ** (1 / 3))
    if recording is None:
        E = np.asarray(frame(ca.DM(v["phi"]), ca.DM(v["psi"]), ca.DM(v["theta"])))  # Eq. (eq:125)
        raw = s + b * (gravity * sphere_directions() @ E)  # m_i = e_i . a (Lemma 1), Eq. (theModel)
        where = f"over {DIRECTIONS} gravity directions"
        calibrated = DriftCase("calibrated", abs(cal.rms_residual),
                               "RMS residual of the fit on its own data")
    else:

        iv = detect_static(recording.t, recording.raw, temp=recording.temp, source=recording.source)
        if iv.n == 0:
            raise ImucalError("no static intervals found", file=recording.source, field="recording",
                              fix="record the sensor still in several orientations")
        raw = iv.mean
        where = f"over {iv.n} static intervals of {recording.source}"
        a = cal.apply(raw, covariate_values(cal.covariates, temp=iv.temp, time=iv.t_mid, source=recording.source,
                                            what="the calibration", temp_rate=iv.temp_rate))
        rms, mx = _stats(np.abs(np.linalg.norm(a, axis=1) - gravity))
        calibrated = DriftCase("calibrated", rms, f"RMS of | |a| - g | {where}", mx)
    rms_r, max_r = _stats(np.abs(np.linalg.norm((raw - s_bar) / b_bar, axis=1) - gravity))
    rms_a, max_a = _stats(np.abs(np.linalg.norm((raw - s) / b, axis=1) - gravity))
    if not math.isfinite(calibrated.error):
        raise ImucalError("the calibration records no RMS residual", field="fit.rms_residual",
                          fix="pass --recording to evaluate it on data")
    return [DriftCase("raw", rms_r, f"RMS of | |(raw - s_bar) / b_bar| - g | {where}", max_r),
            DriftCase("angles ignored", rms_a, f"RMS of | |(raw - s) / b| - g | {where}", max_a),
            calibrated]


def plot_drift(report: DriftReport, path: str, duration: float) -> None:
    """Position error against time, log-log, one line per case, table times marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = np.geomspace(min(report.times[0], duration) / 10, duration, 200)
    fig, ax = plt.subplots(figsize=(7.5, 5), dpi=120)
    for c in report.cases:
        if c.error <= 0:
            continue
        line, = ax.loglog(t, position_error(c.error, t), lw=1.8, label=f"{c.name}: e = {c.error:.3g} m/s²")
        tt = np.array([x for x in report.times if x <= duration])
        ax.loglog(tt, position_error(c.error, tt), "o", color=line.get_color(), ms=4)
        if tt.size:
            pe = float(position_error(c.error, tt[-1]))
            txt = f"{pe:.3g}" if pe < 1000 else f"{pe:,.0f}"
            ax.annotate(f"{txt} m at {tt[-1]:g} s", (tt[-1], pe), xytext=(-6, 6),
                        textcoords="offset points", ha="right", fontsize=8, color=line.get_color())
    ax.set_xlabel("dead-reckoning time t [s]")
    ax.set_ylabel("position error e t² / 2 [m]")
    ax.set_title("Position drift from a constant acceleration error", fontsize=11)
    ax.grid(which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, format="png")
    plt.close(fig)
