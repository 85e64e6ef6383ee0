"""One self-contained HTML page per run: the verdict first, then parameters, residuals, figures.

The page needs nothing but itself: figures are inline base64 PNGs, the style is inline, there is
no script, and a Content-Security-Policy forbids loading anything from elsewhere. Every piece of
text that comes from the user (file names, units, config strings, effect labels) is escaped.
Built from the same run object as the text report (imucal.report.text).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Mapping

import numpy as np

from imucal.pipeline import CalibrationRun
from imucal.solve.misfit import POOR_FIT_P, POOR_FIT_REDCHI, excess_residuals
from imucal.report.text import interval_residuals, t_quantile_975, time_base_words
from imucal.solve.stats import chi2_sf
from imucal.report.page import esc, figures_html, num, page_html, render_png, table_html  # noqa: F401 (render_png: callers)

if TYPE_CHECKING:  # discovery pages only: `imucal calibrate` does not import the discovery modules
    from imucal.analysis.discover import Discovery

@dataclass(frozen=True)
class Check:
    """One line of the verdict: what was checked, whether it passed (None: cannot tell), details."""

    what: str
    ok: bool | None
    detail: str


@dataclass(frozen=True)
class Verdict:
    level: str  #: "pass", "check" (usable, but read the warnings) or "fail"
    headline: str
    checks: tuple[Check, ...]
    warnings: tuple[str, ...]


def chi2_consistent(chi2: float, dof: int) -> tuple[bool | None, float]:
    """Whether chi-square on ``dof`` is consistent with the noise (the rule of imucal.pipeline.fit_warnings:
    poor when reduced chi-square > POOR_FIT_REDCHI and p < POOR_FIT_P), and its p-value."""
    if dof <= 0 or not math.isfinite(chi2):
        return None, math.nan
    return excess_residuals(chi2, dof) is None, chi2_sf(chi2, dof)


def verdict(run: CalibrationRun) -> Verdict:
    """Pass/fail first: converged? residuals consistent with the noise? anything to warn about?"""
    res, cal, obs = run.result, run.calibration, run.observability
    consistent, p = chi2_consistent(res.chi2_noise, res.dof)  # against the noise alone
    dropped = cal.data.get("dropped_intervals", [])
    rms = cal.fit["rms_residual"] * 1e3
    checks = [
        Check("IPOPT converged", res.success, f"{res.status_words}; {res.iterations} iterations"),
        Check("residuals consistent with the noise", consistent,
              "cannot be tested: 0 degrees of freedom" if consistent is None else
              f"reduced chi-square {res.redchi_noise:.3g} (chi-square {res.chi2_noise:.4g} on {res.dof} dof, "
              f"p = {p:.3g}; poor when above {POOR_FIT_REDCHI:g} with p < {POOR_FIT_P:g})"
              + (f"; the standard errors include a between-interval excess of {res.excess ** 0.5:.3g} m/s^2 rms "
                 "(bias_instability)" if res.excess > 0 else "")),
        Check("every parameter determined by the poses", not obs.poorly_determined,
              f"{obs.n_distinct} distinct orientations; Jacobian condition {obs.condition:.3g}"
              + ("; poorly determined: " + ", ".join(obs.poorly_determined) if obs.poorly_determined else "")),
        Check("no parameter at a bound", not res.at_bound,
              "; ".join(f"{n} at its {b} bound" for n, b in res.at_bound.items()) or "all inside their bounds"),
        Check("no static interval dropped", not dropped,
              f"{len(dropped)} dropped because an axis was clipped" if dropped else
              f"{run.intervals.n} static intervals used"),
    ]
    warnings = tuple(cal.fit.get("warnings", []))
    if not res.success:
        level, word = "fail", "FAIL: the solver did not converge"
    elif any(c.ok is False for c in checks) or warnings:
        level, word = "check", "CHECK: usable, read the warnings"
    else:
        level, word = "pass", "PASS"
    headline = (f"{word} (RMS |a| - g {rms:.3g} mm/s² on {run.intervals.n} interval means, "
                f"reduced chi-square {num(res.redchi, '.3g')})")
    return Verdict(level, headline, tuple(checks), warnings)


def _verdict_html(v: Verdict) -> str:
    rows = []
    for c in v.checks:
        mark, cls = ("yes", "ok") if c.ok else (("no", "bad") if c.ok is False else ("n/a", "na"))
        rows.append(f'<tr><td>{esc(c.what)}</td><td class="{cls}">{mark}</td><td>{esc(c.detail)}</td></tr>')
    warn = ""
    if v.warnings:
        warn = "<p><b>Warnings</b></p><ul class=\"warn\">" + "".join(f"<li>{esc(w)}</li>" for w in v.warnings) + "</ul>"
    return (f'<section class="verdict {v.level}" id="verdict"><h2>{esc(v.headline)}</h2>'
            f"<table><tbody>{''.join(rows)}</tbody></table>{warn}</section>")


def _parameters_html(run: CalibrationRun) -> str:
    res = run.result
    t = t_quantile_975(res.dof)
    rows = []
    for n, p in res.params.items():
        sd = res.std.get(n, math.nan)
        if p.fixed:
            rows.append([esc(n), num(p.value, ".10g"), "fixed", "", esc(p.unit), num(res.initial[n].value, ".6g")])
            continue
        pct = abs(sd / p.value) * 100 if p.value and math.isfinite(sd) else math.nan
        flag = f" (at {res.at_bound[n]} bound)" if n in res.at_bound else ""
        rows.append([esc(n), num(p.value, ".10g"), num(sd, ".4g"), num(pct, ".3g"), esc(p.unit),
                     num(res.initial[n].value, ".6g") + esc(flag)])
    body = table_html(["parameter", "value", "standard error", "error [%]", "unit", "initial value"], rows,
                  [False, True, True, True, False, True])
    angles = [n for n in ("phi", "psi", "theta") if n in res.params]
    if angles:
        body += table_html(["angle", "value [deg]", "standard error [deg]", "from 90° [mrad]"],
                       [[esc(n), num(math.degrees(res.params[n].value), ".5f"),
                         num(math.degrees(res.std.get(n, math.nan)), ".3g"),
                         num((res.params[n].value - math.pi / 2) * 1e3, ".4g")] for n in angles],
                       [False, True, True, True])
    body += (f"<p class=\"meta\">95 % intervals: value ± {num(t, '.3g')} × standard error (Student-t, "
             f"{res.dof} dof; the errors are scaled by the reduced chi-square).</p>")
    return body


def _apply_html(run: CalibrationRun) -> str:
    A, c = run.calibration.linear_map()
    unit = esc(run.calibration.raw_unit)
    rows = [[f"a<sub>{'xyz'[i]}</sub>"] + [num(v, "+.9e") for v in A[i]] + [num(c[i], "+.9e")] for i in range(3)]
    return (f"<p>a = A raw + c, with a in m/s², raw in {unit}; A [(m/s²)/{unit}] is lower triangular "
            "(the Theorem).</p>"
            + table_html(["", "A[:, x]", "A[:, y]", "A[:, z]", "c [m/s²]"], rows, [False, True, True, True, True]))


def _residuals_html(run: CalibrationRun) -> str:
    iv = run.intervals
    r, s = interval_residuals(run)
    rows, cls = [], []
    for k in range(iv.n):
        z = r[k] / s[k] if math.isfinite(s[k]) and s[k] > 0 else math.nan
        rows.append([str(k), num(iv.t_start[k], ".2f"), num(iv.t_end[k], ".2f"),
                     " ".join(num(v, "+.3f") for v in run.directions[k]),
                     num(r[k] * 1e3, "+.4f"), num(s[k] * 1e3, ".4f"), num(z, "+.2f")])
        cls.append("out" if math.isfinite(z) and abs(z) > 3 else "")
    rms = float(np.sqrt(np.mean(r**2)))
    return (f"<p>|a| − g at each interval mean; σ from the interval's own scatter. RMS {rms * 1e3:.4g} mm/s²; "
            "rows beyond 3σ are shaded.</p>"
            + table_html(["#", "start [s]", "end [s]", "direction (unit vector)", "|a| − g [mm/s²]", "σ [mm/s²]",
                      "residual / σ"], rows, [True, True, True, False, True, True, True], cls))


def _statistics_html(run: CalibrationRun) -> str:
    res, cal, iv, rec = run.result, run.calibration, run.intervals, run.recording
    rows = [("model", esc(res.model_name)),
            ("fit on", "interval means" if res.mode == "means" else f"{res.residuals.size} samples"),
            ("static intervals", f"{iv.n} ({run.observability.n_distinct} distinct orientations)"),
            ("free parameters", str(len(res.free_names))),
            ("chi-square / dof", f"{num(res.chi2, '.6g')} / {res.dof}"),
            ("reduced chi-square", f"{num(res.redchi, '.4g')} (1 = residuals at the noise of the means)"),
            ("RMS |a| − g, interval means", f"{cal.fit['rms_residual'] * 1e3:.4g} mm/s²"),
            ("RMS |a| − g, samples", f"{cal.fit['rms_residual_samples'] * 1e3:.4g} mm/s²"),
            ("noise inflation", f"{iv.noise_inflation:.3g} (batch-means / white-noise variance)"),
            ("gravity", f"{cal.gravity:.6f} m/s² ({esc(run.gravity_source)})"),
            ("data", f"{esc(Path(rec.source).name)}: {rec.n} samples, {rec.duration:.1f} s, "
                     f"{rec.sample_rate:.4g} Hz, raw unit {esc(cal.raw_unit)}"),
            ("SHA-256", f"<code>{esc(rec.sha256)}</code>")]
    if rec.time_note:
        rows.append(("time", esc(rec.time_note)))
    if time_base_words(rec.time_base):
        rows.append(("time base", esc(time_base_words(rec.time_base))))
    for d in cal.data.get("dropped_intervals", []):
        rows.append(("dropped interval", f"{d['t_start']:.2f} – {d['t_end']:.2f} s: {esc(d['reason'])}"))
    return table_html(["", ""], [[a, b] for a, b in rows])


CAPTIONS = {
    "residuals.png": "residual |a| − g of each interval mean, with 2σ bars and the RMS band",
    "directions.png": "gravity direction of each interval on the sphere (equal-area projection), numbered "
                      "as in the residual table",
    "discover_residuals.png": "normalised residual against time, temperature and orientation, before and "
                              "after the effects found",
    "discover_candidates.png": "likelihood-ratio statistic of each candidate effect against the threshold",
    "discover_gap.png": "RMS and chi-square per dof before and after, against the noise",
    "discover_temperature.png": "a temperature sweep's still poses: each axis's reading about its pose against "
                                "temperature, before and after the temperature terms found",
}


def _calibration_sections(run: CalibrationRun) -> list[tuple[str, str, str]]:
    return [("parameters", "Parameters with standard errors", _parameters_html(run)),
            ("statistics", "Fit statistics and data", _statistics_html(run)),
            ("residuals", "Residuals per pose", _residuals_html(run)),
            ("apply", "Apply map", _apply_html(run))]


def calibration_html(run: CalibrationRun, figures: Mapping[str, bytes] | None = None,
                     extra: Mapping[str, str] | None = None) -> str:
    """The page of ``imucal calibrate``: verdict, parameters, statistics, residuals, figures.

    ``figures`` maps file names to PNG bytes; ``extra`` maps headings to more plain text (e.g. the
    gyroscope report), shown preformatted and escaped."""
    title = f"imucal calibration: {Path(run.recording.source).name}"
    sections = [("verdict", "", _verdict_html(verdict(run))), *_calibration_sections(run)]
    for k, (head, text) in enumerate((extra or {}).items()):
        sections.append((f"extra{k}", esc(head), f"<pre>{esc(text)}</pre>"))
    sections.append(("figures", "Figures", figures_html(figures or {}, CAPTIONS)))
    return page_html(title, sections)


def discovery_html(d: Discovery, figures: Mapping[str, bytes] | None = None) -> str:
    """The page of ``imucal discover``: its verdict, the gap, the effects, then the final calibration."""
    from imucal.report.discover_text import discovery_report, verdict_text  # (start-up: `calibrate` skips discovery)

    b, f = d.base.result, d.final.result
    v = verdict(d.final)
    level = "pass" if d.consistent_after and v.level == "pass" else ("fail" if v.level == "fail" else "check")
    head = (f'<section class="verdict {level}" id="verdict"><h2>{esc(verdict_text(d.verdict))}</h2>'
            + table_html(["", "base model", "final model"],
                     [["model", esc(b.model_name), esc(f.model_name)],
                      ["RMS |a| − g [mm/s²]", num(d.rms_before * 1e3, ".4g"), num(d.rms_after * 1e3, ".4g")],
                      ["chi-square / dof", f"{num(b.chi2, '.4g')} / {b.dof}", f"{num(f.chi2, '.4g')} / {f.dof}"],
                      ["p (chi-square)", num(d.p_before, ".3g"), num(d.p_after, ".3g")],
                      ["consistent with the noise", "yes" if d.consistent_before else "no",
                       "yes" if d.consistent_after else "no"]], [False, True, True])
            + f"<p class=\"meta\">Noise of the means alone: RMS {d.rms_noise * 1e3:.4g} mm/s²; significance "
              f"level {d.settings.alpha_noise:g}.</p></section>")
    rows = []
    for e in d.effects:
        for n, val in e.coefficients.items():
            rows.append([esc(e.label), esc(n), num(val, ".6g"), num(e.std.get(n, math.nan), ".3g"),
                         esc(e.units.get(n, "")), num(e.lr, ".4g"), num(e.p_value, ".3g")])
    effects = (table_html(["effect", "coefficient", "value", "standard error", "unit", "LR", "p (adjusted)"], rows,
                      [False, False, True, True, False, True, True]) if rows else "<p>None added.</p>")
    title = f"imucal discover: {Path(d.base.recording.source).name}"
    sections = [("verdict", "", head), ("fit", "", _verdict_html(v)), ("effects", "Effects found", effects),
                *_calibration_sections(d.final),
                ("discovery", "Discovery report (text)", f"<pre>{esc(discovery_report(d))}</pre>"),
                ("figures", "Figures", figures_html(figures or {}, CAPTIONS))]
    return page_html(title, sections)
