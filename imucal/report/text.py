"""Text report in the manner of lmfit's fit_report."""
from __future__ import annotations

import math

import numpy as np

from imucal.calibration.frozen import Calibration
from imucal.data.recording import TimeBase, TimeSource
from imucal.data.timebase import GAP_STEPS, SHORT_STEP
from imucal.errors import key_text, printable
from imucal.model.sensor import build_model
from imucal.pipeline import CalibrationRun, fit_data
from imucal.solve.fit import FitResult, jacobian_rows
from imucal.solve.stochastic import BiasDrift

#: Correlations above this are listed.
CORREL_MIN = 0.3


def t_quantile_975(dof: int) -> float:
    """Student-t 97.5 % quantile (Cornish-Fisher expansion about the normal; < 1 % off for dof >= 3)."""
    z = 1.959963984540054
    if dof <= 0:
        return float("nan")
    v = float(dof)
    return (z + (z**3 + z) / (4 * v) + (5 * z**5 + 16 * z**3 + 3 * z) / (96 * v**2)
            + (3 * z**7 + 19 * z**5 + 17 * z**3 - 15 * z) / (384 * v**3))


def interval_residuals(run: CalibrationRun) -> tuple[np.ndarray, np.ndarray]:
    """|a| - g at each interval mean and its noise sigma [m/s^2] (sigma NaN when the fit was on samples)."""
    res = run.result
    if res.mode == "means":
        return res.residuals, res.sigma
    model = build_model(run.calibration.effect_objects())
    d = fit_data(model, run.intervals, run.recording, "means", None)
    r = jacobian_rows(d, res.params, model, res.gravity, residuals=True)
    return r, np.full_like(r, np.nan)


def _fmt(v: float) -> str:
    return "nan" if not math.isfinite(v) else f"{v:.10g}"


def fit_report(run: CalibrationRun, correl_min: float = CORREL_MIN) -> str:
    """A run as text, in the manner of lmfit's fit_report (report.txt).

    Args:
        run: the run (imucal.pipeline.CalibrationRun, or imucal.calibrate's result).
        correl_min: correlations above this are listed.

    Returns:
        Values, standard errors (absolute and %), initial values, bounds hit, correlations, status,
        the intervals and every further sensor's section.
    """
    L = [*_calibration_lines(run), *_statistics_lines(run), *_variable_lines(run.result),
         *_correlation_lines(run.result, correl_min), *_apply_lines(run.calibration), *_interval_lines(run),
         *_gyro_lines(run), *_mag_lines(run)]
    return "\n".join(L) + "\n"


def _calibration_lines(run: CalibrationRun) -> list[str]:
    """What was calibrated: model, data, gravity."""
    res, cal, rec = run.result, run.calibration, run.recording
    L: list[str] = []
    L.append("[[Calibration]]")
    L.append(f"    model              = {res.model_name}")
    L.append(f"    data               = {printable(rec.source)} ({rec.n} samples, {rec.duration:.1f} s, "
             f"{rec.sample_rate:.4g} Hz, unit {cal.raw_unit})")
    L.append(f"    sha256             = {rec.sha256}")
    if columns_words(cal.data.get("columns", {})):
        L.append(f"    columns            = {columns_words(cal.data['columns'])}")
    if rec.time_note:
        L.append(f"    time               = {rec.time_note}")
    if time_base_words(rec.time_base):
        L.append(f"    time base          = {time_base_words(rec.time_base)}")
    L.append(f"    gravity            = {cal.gravity:.6f} m/s^2 ({run.gravity_source})")
    return L


def _duration(seconds: float) -> str:
    for unit, f in (("h", 3600.0), ("min", 60.0), ("s", 1.0)):
        if seconds >= f:
            return f"{seconds / f:.3g} {unit}"
    return f"{seconds * 1e3:.3g} ms"


def time_base_words(tb: TimeBase | None) -> str:
    """A recording's time base (imucal.data.timebase) in words; empty for stamps taken as read
    without a gap or a checked rate, and for a given rate."""
    if tb is None:
        return ""
    out = []
    if tb.source is TimeSource.CLOCK:
        out.append(f"the time stamps are jitter ({100 * tb.short_fraction:.3g} % of their steps are shorter than "
                   f"{SHORT_STEP:g} of the sample step, median step {_duration(tb.median_step)}): the samples are "
                   f"re-timed on a clock fitted to the stamps, {tb.rate:.4g} Hz")
    if tb.n_gaps:
        where = f" at line {tb.longest_gap_line}" if tb.longest_gap_line else ""
        out.append(f"{tb.n_gaps} gap(s) in the time stamps (samples missing: steps over {GAP_STEPS:g} sample steps "
                   f"that the later stamps do not make up) kept as gaps, the longest "
                   f"{_duration(tb.longest_gap)}{where}")
    if tb.rate_given is not None:
        out.append(f"the sample rate given, {tb.rate_given:g} Hz, agrees with the time column ({tb.rate:.4g} Hz)")
    return "; ".join(out)


def _taken_lines(run: CalibrationRun) -> list[str]:
    """An accelerometer taken from fit.base or the run file (imucal.pipeline.taken_whole): where from, no fit;
    this log's still intervals as a check, when it has some; warnings."""
    from imucal.report.verdict import taken_words

    cal, iv = run.calibration, run.intervals
    name, what = taken_words(cal.fit["taken"])
    L = ["[[Taken, not fitted]]",
         f"    accelerometer      = taken from {name}: {what}, not fitted to this log"]
    if iv.n:
        L.append(f"    check on           = {iv.n} still intervals of this log ({run.observability.n_distinct} "
                 "distinct orientations)")
        L.append(f"    chi-square         = {cal.fit['chi2']:.6g} on {iv.n} intervals (reduced {cal.fit['redchi']:.4g}; "
                 "1 = |a| - g at the noise of the means and the taken standard errors)")
        L.append(f"    RMS |a|-g, means   = {cal.fit['rms_residual']:.6g} m/s^2")
        L.append(f"    RMS |a|-g, samples = {cal.fit['rms_residual_samples']:.6g} m/s^2")
    else:
        L.append("    check on           = none: this log has no still interval")
    for wtext in cal.fit.get("warnings", []):
        L.append(f"    WARNING            = {printable(wtext)}")
    return L


def _statistics_lines(run: CalibrationRun) -> list[str]:
    """Solver, chi-square, the stochastic excess, RMS, conditioning, warnings."""
    res, cal, iv = run.result, run.calibration, run.intervals
    if "taken" in cal.fit:
        return _taken_lines(run)
    L: list[str] = []
    L.append("[[Fit Statistics]]")
    L.append(f"    solver             = IPOPT: {res.status_words}")
    L.append(f"    # iterations       = {res.iterations}")
    L.append("    fit on             = interval means" if res.mode == "means" else
             f"    fit on             = {res.residuals.size} samples")
    if res.mode == "means" and cal.fit.get("weights") == "auto":
        L.append("    weights            = every interval alike (auto); each mean's noise sets the standard errors, "
                 "not the values")
    L.append(f"    # intervals        = {iv.n} ({run.observability.n_distinct} distinct orientations)")
    L.append(f"    # free parameters  = {len(res.free_names)}")
    L.append(f"    chi-square         = {res.chi2:.6g}")
    L.append(f"    reduced chi-square = {res.redchi:.6g}  (1 = residuals match the noise of the means"
             + (", with the excess below)" if res.excess > 0 or res.random_walk > 0 else ")"))
    if res.excess > 0 or res.random_walk > 0:
        L.append(f"    noise alone        = reduced chi-square {res.redchi_noise:.6g}: the intervals scatter more "
                 "than their own noise")
    if res.excess > 0:
        L.append(f"    bias_instability   = {math.sqrt(res.excess):.4g} m/s^2 rms per visit of a pose (random "
                 f"offset between intervals, {'REML' if res.random_walk > 0 else 'Paule-Mandel'}), added to every "
                 "interval's sigma: the standard errors include it")
    if res.random_walk > 0:
        L.append(f"    bias_random_walk   = {math.sqrt(res.random_walk):.4g} +/- {res.stochastic.q_std:.2g} m/s^2/sqrt(s) "
                 "(REML): the bias moved during the recording; the standard errors include the walk (its full "
                 "covariance between the intervals, about its mean)")
    if res.bias_drift is not None:
        L += _drift_lines(res.bias_drift, cal.raw_unit)
    if res.scatter_term is not None:
        L += _scatter_lines(res, iv)
    L.append(f"    degrees of freedom = {res.dof}  (95 % intervals: value +/- {t_quantile_975(res.dof):.3g} x std, "
             "Student-t, since std is scaled by the reduced chi-square)")
    L.append(f"    RMS |a|-g, means   = {cal.fit['rms_residual']:.6g} m/s^2")
    L.append(f"    RMS |a|-g, samples = {cal.fit['rms_residual_samples']:.6g} m/s^2")
    if cal.fit.get("noise", "scatter") == "scatter":
        L.append(f"    noise inflation    = {iv.noise_inflation:.3g}  (batch-means / white-noise variance)")
    else:
        L.append(f"    noise of the means = from {cal.fit['noise']} (white-noise density x sqrt(fs/n), "
                 "bias-instability floor), not each interval's scatter")
    L.append(f"    Jacobian condition = {run.observability.condition:.4g}")
    if run.observability.poorly_determined:
        L.append("    WARNING            = poorly determined by these poses: "
                 + ", ".join(f"{n} (predicted std {run.observability.predicted_z[n]:.2g} x scale)"
                             for n in run.observability.poorly_determined))
    for wtext in cal.fit.get("warnings", []):
        L.append(f"    WARNING            = {printable(wtext)}")
    return L


def _drift_lines(d: BiasDrift, unit: str) -> list[str]:
    """How far a walking bias moved (its smoothed estimate) and the epoch of the offsets."""
    moved, sd, ptp = d.moved, d.moved_std, d.peak_to_peak
    L = [f"    bias moved         = per sensor axis, last minus first interval (t = {d.t[0]:.1f} to {d.t[-1]:.1f} s, "
         "smoothed) +/- std; largest minus smallest over the intervals:"]
    for i in range(3):
        L.append(f"        {'xyz'[i]}: {d.in_raw(moved)[i]:+.4g} +/- {d.in_raw(sd)[i]:.2g} {unit} "
                 f"({d.in_mg(moved)[i]:+.3g} +/- {d.in_mg(sd)[i]:.2g} mg); peak to peak {d.in_raw(ptp)[i]:.4g} {unit} "
                 f"({d.in_mg(ptp)[i]:.3g} mg)")
    L.append(f"    offsets s1..s3     = the bias averaged over the {d.t.size} still intervals (each once, "
             f"t = {d.t[0]:.1f} to {d.t[-1]:.1f} s): the constant that fits them; at another time it differs by "
             "the walk")
    return L


def _scatter_lines(res: FitResult, iv) -> list[str]:
    """Samples mode: the correction for the samples' own scatter and how much it moved the values."""
    spread = float(np.max(np.sqrt(np.sum(iv.std**2, axis=1)))) if iv.n else float("nan")
    z = res.scatter_z
    moved = f"; without it {z[0]} would move by {z[1]:.3g} standard errors" if z is not None else ""
    return [f"    scatter correction = |a| of a sample exceeds |a| of its interval's mean by up to "
            f"{float(np.max(res.scatter_term)):.3g} m/s^2 (scatter up to {spread:.3g} raw rms): corrected to "
            f"second order{moved}"]


def _variable_lines(res: FitResult) -> list[str]:
    """Each parameter with its standard error, initial value and bound."""
    L: list[str] = []
    L.append("[[Variables]]")
    w = max(len(n) for n in res.params)
    for n, p in res.params.items():
        sd = res.std.get(n, float("nan"))
        init = res.initial[n].value
        if p.fixed:
            L.append(f"    {n:<{w}}: {_fmt(p.value)} (fixed) {p.unit}")
            continue
        pct = abs(sd / p.value) * 100 if p.value else float("nan")
        flag = f"  (at {res.at_bound[n]} bound)" if n in res.at_bound else ""
        err = f"+/- {sd:.4g} ({pct:.3g}%)" if math.isfinite(sd) else "+/- n/a (not estimable: 0 dof)"
        L.append(f"    {n:<{w}}: {_fmt(p.value)} {err} {p.unit} (init = {_fmt(init)}){flag}")
    if any(n in res.params and n in ("phi", "psi", "theta") for n in res.free_names):
        L.append("    angles in degrees: " + ", ".join(
            f"{n} = {math.degrees(res.params[n].value):.4f}" for n in ("phi", "psi", "theta")))
    return L


def _correlation_lines(res: FitResult, correl_min: float) -> list[str]:
    """Correlations above ``correl_min``, largest first."""
    L: list[str] = []
    L.append(f"[[Correlations]] (unreported correlations are < {correl_min:.3f})")
    pairs = []
    fn = res.free_names
    for i in range(len(fn)):
        for j in range(i + 1, len(fn)):
            c = res.correlation[i, j]
            if math.isfinite(c) and abs(c) > correl_min:
                pairs.append((abs(c), fn[i], fn[j], c))
    for _, a, b, c in sorted(pairs, reverse=True):
        L.append(f"    C({a}, {b}) = {c:+.4f}")
    return L


def _apply_lines(cal: Calibration) -> list[str]:
    """The apply map as applied."""
    L: list[str] = []
    A, c = cal.linear_map()
    L.append("[[Apply map]]  a = A raw + c  (Theorem; A lower triangular, output in m/s^2)" if not cal.effects
             else f"[[Apply map]]  {cal.equation}; A, c:")
    for i in range(3):
        L.append("    " + " ".join(f"{v:+.9e}" for v in A[i]) + f"   | {c[i]:+.9e}")
    return L


def _interval_lines(run: CalibrationRun) -> list[str]:
    """The static intervals, dropped ones, and the residual of each."""
    res, cal, iv = run.result, run.calibration, run.intervals
    L: list[str] = []
    L.append(f"[[Static intervals]]  times in s, means and std in {cal.raw_unit}, directions unit vectors")
    L.append(iv.table(run.directions))
    for d in cal.data.get("dropped_intervals", []):
        L.append(f"    dropped {d['t_start']:.2f}..{d['t_end']:.2f} s: {d['reason']}")
    L.append("[[Residuals per interval]]  |a| - g [m/s^2], sigma from the interval's own scatter")
    r = res.residuals if res.mode == "means" else None
    if r is not None:
        for k in range(iv.n):
            L.append(f"    {k:3d} {r[k]:+.6f} +/- {res.sigma[k]:.6f}  ({r[k] / res.sigma[k]:+.2f} sigma)")
    return L


def _gyro_json(res) -> dict:
    from imucal.gyro.result import to_dict  # measured start-up: only a run with a gyroscope

    return to_dict(res)


def _gyro_lines(run: CalibrationRun) -> list[str]:
    """The gyroscope's report and apply map, when there is one."""
    cal = run.calibration
    L: list[str] = []
    if run.gyro is not None:
        L.append("[[Gyroscope]]")
        from imucal.report.gyro import gyro_report  # measured start-up: only a run with a gyroscope

        L.append(gyro_report(run.gyro))
        a = cal.gyro.at_reference().affine()
        C, c, D = a.A, a.c, -a.B
        L.append("[[Gyro apply map]]  omega = C raw + c - D a  (rad/s, the accelerometer's frame; "
                 "a: calibrated acceleration)")
        for i in range(3):
            L.append("    " + " ".join(f"{v:+.9e}" for v in C[i]) + f"   | {c[i]:+.9e}   | "
                     + " ".join(f"{v:+.6e}" for v in D[i]))
    return L


def _mag_lines(run: CalibrationRun) -> list[str]:
    """The magnetometer's report and apply map, when there is one."""
    if run.mag is None:
        return []
    from imucal.report.mag import mag_lines  # measured start-up: only a run with a magnetometer

    m = run.calibration.sensor("magnetometer")
    assert m is not None
    a = m.affine()
    L = ["[[Magnetometer]]", *("    " + line for line in mag_lines(run.mag)),
         f"[[Magnetometer apply map]]  h = A raw + c  ({m.model.output.unit}, the accelerometer's frame)"]
    L += ["    " + " ".join(f"{v:+.9e}" for v in a.A[i]) + f"   | {a.c[i]:+.9e}" for i in range(3)]
    return L


def summary(run: CalibrationRun) -> dict:
    """The machine-readable summary of a run (``imucal calibrate --json``).

    Args:
        run: the run (imucal.pipeline.CalibrationRun, or imucal.calibrate's result).

    Returns:
        A JSON-ready mapping: parameters, standard errors, statistics, warnings and ``gyro``.
    """
    res, cal = run.result, run.calibration
    v, sd = res.params, res.std

    def nz(x: float):
        return None if not math.isfinite(x) else float(x)

    return {
        "status": "ok" if res.success else "failed",
        "solver_status": res.status,
        "model": res.model_name,
        "params": {"s": [v[f"s{i}"].value for i in (1, 2, 3)], "b": [v[f"b{i}"].value for i in (1, 2, 3)],
                   "phi": v["phi"].value, "psi": v["psi"].value, "theta": v["theta"].value},
        "std": {"s": [nz(sd[f"s{i}"]) for i in (1, 2, 3)], "b": [nz(sd[f"b{i}"]) for i in (1, 2, 3)],
                "phi": nz(sd["phi"]), "psi": nz(sd["psi"]), "theta": nz(sd["theta"])},
        "effects": [{"name": n, "axes": ["xyz"[a] for a in ax],
                     "coefficients": {k: v[k].value for k in v if k.startswith(n)}} for n, ax in cal.effects],
        **({"taken": dict(cal.fit["taken"])} if "taken" in cal.fit else {}),  # the accelerometer not fitted
        "rms_residual": nz(cal.fit.get("rms_residual", math.nan)),  # (none without a still interval: taken)
        "rms_residual_samples": nz(cal.fit.get("rms_residual_samples", math.nan)),
        "chi2": nz(res.chi2), "dof": res.dof, "redchi": nz(res.redchi), "redchi_noise": nz(res.redchi_noise),
        "bias_instability": res.bias_instability,
        "bias_random_walk": math.sqrt(res.random_walk),
        **({"bias_drift": res.bias_drift.to_json(cal.raw_unit)} if res.bias_drift is not None else {}),
        **({"scatter_correction": {"max_m_s2": float(np.max(res.scatter_term)), "shift": dict(res.scatter_shift),
                                   "largest_shift_in_std": None if res.scatter_z is None else list(res.scatter_z)}}
           if res.scatter_shift is not None else {}),
        "n_intervals": run.intervals.n,
        "n_distinct_orientations": run.observability.n_distinct,
        "gravity": cal.gravity,
        "raw_unit": cal.raw_unit,
        "matrix": cal.linear_map()[0].tolist(),
        "offset": cal.linear_map()[1].tolist(),
        "data": dict(cal.data),
        "warnings": list(cal.fit.get("warnings", [])),
        "sensors": list(cal.sensors),
        "equation": cal.equation,
        **({"gyro": _gyro_json(run.gyro)} if run.gyro is not None else {}),
        **({"mag": _mag_json(run)} if run.mag is not None else {}),
    }


def _mag_json(run: CalibrationRun) -> dict:
    """The magnetometer's parameters, standard errors and figures (its file section's numbers)."""
    m = run.calibration.sensor("magnetometer")
    assert m is not None
    return {"model": m.model.name, "params": m.params.value_dict(),
            "std": {n: (float(v) if math.isfinite(v) else None) for n, v in m.std.items()}, "fit": dict(m.fit)}


#: The roles of one sensor, shown together (ax, ay, az: AccX, AccY, AccZ).
_ROLE_GROUPS = (("t",), ("ax", "ay", "az"), ("gx", "gy", "gz"), ("mx", "my", "mz"), ("temp",))


def columns_words(columns: dict) -> str:
    """The columns a calibration read by an exporter's names, as one printable line: "t: TimeUS; ax, ay, az: AccX,
    AccY, AccZ; temp: T" (each name as a message shows a key: cut and escaped when not short and printable)."""
    parts = []
    for group in _ROLE_GROUPS:
        roles = [r for r in group if r in columns]
        if roles:
            parts.append(f"{', '.join(roles)}: {', '.join(key_text(columns[r]) for r in roles)}")
    return "; ".join(parts)
