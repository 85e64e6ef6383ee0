"""One self-contained HTML page per run, read at a glance: the verdict of every sensor first (typed in
imucal.report.verdict), the recording as a time series with its still intervals, then each sensor the
calibration holds in the same form (datasheet units beside the fitted values, the checks' evidence, its
apply map), the statistics and the figures. Every text goes through page.esc, the one HTML escaping
function; the page runs no script and loads nothing (page.CSP). Built from the same run object as the
text report (imucal.report.text).
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Mapping

import numpy as np

from imucal.pipeline import CalibrationRun
from imucal.report.datasheet import DatasheetRow, datasheet
from imucal.report.figures import before_after
from imucal.report.page import (CSP, STYLE, esc, figures_html, num, page_html, render_png,  # noqa: F401
                                table_html)
from imucal.report.text import columns_words, interval_residuals, t_quantile_975, time_base_words
from imucal.report.verdict import Check, SensorVerdict, Verdict, chi2_consistent, taken_words, verdict  # noqa: F401

if TYPE_CHECKING:  # discovery pages only: `imucal calibrate` does not import the discovery modules
    from imucal.analysis.discover import Discovery
    from imucal.calibration.sensor import SensorCalibration


def _checks_html(checks: tuple[Check, ...]) -> str:
    rows = []
    for c in checks:
        mark, cls = ("yes", "ok") if c.ok else (("no", "bad") if c.ok is False else ("n/a", "na"))
        rows.append(f'<tr><td>{esc(c.what)}</td><td class="{cls}">{mark}</td><td>{esc(c.detail)}</td></tr>')
    return f'<div class="scroll"><table><tbody>{"".join(rows)}</tbody></table></div>'


def _sensor_verdict_html(s: SensorVerdict) -> str:
    warn = ("<ul class=\"warn\">" + "".join(f"<li>{esc(w)}</li>" for w in s.warnings) + "</ul>") if s.warnings else ""
    return (f'<div class="verdict {s.level}" id="verdict-{s.sensor}"><h2>{esc(s.headline)}</h2>'
            f"{_checks_html(s.checks)}{warn}</div>")


def _verdict_html(v: Verdict) -> str:
    """The page's level first, then each sensor's verdict with the checks it is made of."""
    return (f'<section class="verdict {v.level}" id="verdict"><h2>{esc(v.headline.split(";")[0])}</h2>'
            f'<div class="sensors">{"".join(_sensor_verdict_html(s) for s in v.sensors)}</div></section>')


def _datasheet_html(rows: list[DatasheetRow]) -> str:
    return table_html(["quantity", "value", "standard error", "unit", "fitted", "value", "standard error", "unit"],
                      [[esc(r.quantity), num(r.value, ".5g"), num(r.std, ".2g"), esc(r.unit), esc(r.parameter),
                        num(r.fitted, ".8g"), num(r.fitted_std, ".2g"), esc(r.fitted_unit)] for r in rows],
                      [False, True, True, False, False, True, True, False])


DATASHEET_NOTE = ("<p class=\"meta\">In a datasheet's units; a bias is the offset s/b as an acceleration (or rate), "
                  "which for a sensor reading unsigned counts holds its mid-scale code. Standard errors to first "
                  "order.</p>")


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
    if iv.n == 0:  # an accelerometer taken from fit.base, on a log that never stops (imucal.pipeline)
        return "<p>No still interval in this log: |a| − g was not checked.</p>"
    r, s = interval_residuals(run)
    before, _ = before_after(run)
    rows, cls = [], []
    for k in range(iv.n):
        z = r[k] / s[k] if math.isfinite(s[k]) and s[k] > 0 else math.nan
        rows.append([str(k), num(iv.t_start[k], ".2f"), num(iv.t_end[k], ".2f"),
                     " ".join(num(v, "+.3f") for v in run.directions[k]),
                     num(before[k] * 1e3, "+.5g"), num(r[k] * 1e3, "+.4f"), num(s[k] * 1e3, ".4f"), num(z, "+.2f")])
        cls.append("out" if math.isfinite(z) and abs(z) > 3 else "")
    rms = float(np.sqrt(np.mean(r**2)))
    return (f"<p>|a| − g at each interval mean; σ from the interval's own scatter. RMS {rms * 1e3:.4g} mm/s²; "
            "rows beyond 3σ are shaded.</p>"
            + table_html(["#", "start [s]", "end [s]", "direction (unit vector)", "before: |a| − g [mm/s²]",
                          "after: |a| − g [mm/s²]", "σ [mm/s²]", "residual / σ"], rows,
                         [True, True, True, False, True, True, True, True], cls))


def _taken_rows(run: CalibrationRun) -> list[tuple[str, str]]:
    """An accelerometer taken from fit.base or the run file (imucal.pipeline.taken_whole): no fit; this log's
    still intervals, if any, a check."""
    cal, iv, rec = run.calibration, run.intervals, run.recording
    name, what = taken_words(cal.fit["taken"])
    check = (f"{iv.n} intervals ({run.observability.n_distinct} distinct orientations), reduced chi-square "
             f"{num(cal.fit['redchi'], '.4g')}, RMS |a| − g {cal.fit['rms_residual'] * 1e3:.4g} mm/s²" if iv.n
             else "none: this log has no still interval")
    return [("model", esc(run.result.model_name)),
            ("accelerometer", f"taken from {esc(name)}: {esc(what)}, not fitted to this log"),
            ("check on this log's still intervals", check),
            ("gravity", f"{cal.gravity:.6f} m/s² ({'the base' if 'base' in cal.fit['taken'] else 'the run'}'s)"),
            ("data", f"{esc(Path(rec.source).name)}: {rec.n} samples, {rec.duration:.1f} s, "
                     f"{rec.sample_rate:.4g} Hz, raw unit {esc(cal.raw_unit)}"),
            ("SHA-256", f"<code>{esc(rec.sha256)}</code>")]


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
            ("SHA-256", f"<code>{esc(rec.sha256)}</code>")] if "taken" not in cal.fit else _taken_rows(run)
    if columns_words(cal.data.get("columns", {})):
        rows.append(("columns read", esc(columns_words(cal.data["columns"]))))
    if rec.time_note:
        rows.append(("time", esc(rec.time_note)))
    if time_base_words(rec.time_base):
        rows.append(("time base", esc(time_base_words(rec.time_base))))
    for d in cal.data.get("dropped_intervals", []):
        rows.append(("dropped interval", f"{d['t_start']:.2f} – {d['t_end']:.2f} s: {esc(d['reason'])}"))
    return table_html(["", ""], [[a, b] for a, b in rows])


CAPTIONS = {
    "recording.png": "the recording against time, calibrated: still intervals shaded green, intervals dropped "
                     "(an axis clipped) red, intervals the gyroscope showed turning orange",
    "before_after.png": "|a| − g of each interval mean before (one offset and one scale for all axes) and after "
                        "the calibration",
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


def _accelerometer_html(run: CalibrationRun, figures: Mapping[str, bytes]) -> str:
    parts = [_datasheet_html(datasheet(run.calibration)["accelerometer"]), DATASHEET_NOTE,
             f"<h3>{'Parameters taken from ' + esc(taken_words(run.calibration.fit['taken'])[0]) if 'taken' in run.calibration.fit else 'Fitted parameters'}</h3>",
             _parameters_html(run), "<h3>|a| − g per pose, before and after</h3>"]
    if "before_after.png" in figures:
        parts.append(figures_html({"before_after.png": figures["before_after.png"]}, CAPTIONS))
    parts += [f'<div id="residuals">{_residuals_html(run)}</div>', '<h3 id="apply">Apply map</h3>', _apply_html(run)]
    return "\n".join(parts)


def _gyroscope_held_html(g: SensorCalibration) -> str:
    """A gyroscope the run did not fit to rotations: its parameters as the calibration holds them."""
    rows = [[esc(n), num(p.value, ".10g"), num(g.std.get(n, math.nan), ".4g") + (" (held)" if p.fixed else ""),
             esc(p.unit)] for n, p in g.params.items()]
    what = g.fit.get("evidence", "") if isinstance(g.fit, Mapping) else ""
    return "\n".join(["<h3>Parameters</h3>", f"<p class=\"meta\">{esc(what)}</p>" if what else "",
                      table_html(["parameter", "value", "standard error", "unit"], rows, [False, True, True, False])])


def _gyroscope_html(run: CalibrationRun) -> str:
    from imucal.gyro.result import arrays, motions  # only a run with a gyroscope
    from imucal.report.gyro import gap_lines, still_lines

    res, g = run.gyro, run.calibration.gyro
    assert g is not None
    if res is None:  # a gyroscope from other evidence than rotations (a temperature sweep's bias(T))
        return _gyroscope_held_html(g)
    rows = [[esc(n), num(p.value, ".10g"), "fixed" if p.fixed else num(res.std.get(n, math.nan), ".4g"), esc(p.unit)]
            for n, p in res.params.items()]
    m = motions(res)
    aff = g.at_reference().affine()  # omega = A raw + c + B a (the description's apply), D = -B
    C, c, D = aff.A, aff.c, -aff.B
    apply_rows = [[f"ω<sub>{'xyz'[i]}</sub>"] + [num(v, "+.9e") for v in C[i]] + [num(c[i], "+.9e")]
                  + [num(v, "+.3e") for v in D[i]] for i in range(3)]
    still = "".join(f"<li>{esc(line.strip())}</li>" for line in [*still_lines(m.still), *gap_lines(m.gapped)]
                    ) if m.still is not None else ""
    return "\n".join([
        _datasheet_html(datasheet(run.calibration)["gyroscope"]), DATASHEET_NOTE, "<h3>Fitted parameters</h3>",
        table_html(["parameter", "value", "standard error", "unit"], rows, [False, True, True, False]),
        f"<p class=\"meta\">Raw unit {esc(m.unit)}; scales {esc(m.unit)} per rad/s; "
        f"{arrays(res).bias.size} axes; IPOPT {esc(res.status_words)}, {res.iterations} iterations.</p>",
        "<h3>Still poses and motions</h3>", f"<ul>{still}</ul>" if still else "",
        "<h3>Apply map</h3>",
        f"<p>ω = C raw + c − D a, with ω in rad/s, raw in {esc(m.unit)}, a the calibrated acceleration [m/s²].</p>",
        table_html(["", "C[:, x]", "C[:, y]", "C[:, z]", "c [rad/s]", "D[:, x]", "D[:, y]", "D[:, z]"], apply_rows,
                   [False] + [True] * 7)])


def _magnetometer_html(run: CalibrationRun) -> str:
    cal, m = run.mag, run.calibration.sensor("magnetometer")
    assert cal is not None and m is not None
    rows = [[esc(n), num(p.value, ".10g"), "fixed" if p.fixed else num(m.std.get(n, math.nan), ".4g"), esc(p.unit)]
            for n, p in m.params.items()]
    r = cal.report
    fig = [["field-norm residual [% of the field, rms]", num(r.norm_pct.before, ".3g"), "",
            num(r.norm_pct.after, ".3g"), num(r.norm_pct.floor, ".2g")]]
    if r.dip_deg is not None:
        fig.append(["dip-angle scatter [deg, std over poses]", num(r.dip_deg.before, ".3g"),
                    num(r.dip_deg.unaligned, ".3g"), num(r.dip_deg.after, ".3g"), num(r.dip_deg.floor, ".2g")])
    aff = m.affine()
    apply_rows = [[f"h<sub>{'xyz'[i]}</sub>"] + [num(v, "+.9e") for v in aff.A[i]] + [num(aff.c[i], "+.9e")]
                  for i in range(3)]
    per_pose = [[str(k + 1), f"{q.start}–{q.end}", num(q.norm_before_pct, "+.3g"), num(q.norm_after_pct, "+.3g"),
                 *(num(v, "+.3g") if v is not None else "" for v in (q.dip_before_deg, q.dip_unaligned_deg,
                                                                      q.dip_after_deg))]
                for k, q in enumerate(r.poses)]
    out = m.model.output.unit
    return "\n".join([
        _datasheet_html(datasheet(run.calibration)["magnetometer"]), DATASHEET_NOTE,
        "<h3>Before and after</h3>",
        table_html(["figure", "before", "hard and soft iron only", "after (aligned)", "noise floor"], fig,
                   [False, True, True, True, True]),
        f"<p class=\"meta\">Model {esc(m.model.name)}; soft iron {'full 3x3' if cal.full_soft_iron else 'symmetric'};"
        f" alignment beyond the mounting {math.degrees(cal.misalignment):.3g}°;"
        f" field {'given' if cal.field_given else 'fitted'}"
        f"; {len(r.poses)} poses; IPOPT {esc(cal.fit.status)}, {cal.fit.iterations} iterations.</p>",
        "<h3>Fitted parameters</h3>",
        table_html(["parameter", "value", "standard error", "unit"], rows, [False, True, True, False]),
        "<h3>Per pose</h3>",
        "<p>|h| − F in % of the field (before: |raw| against its mean), and the dip minus its mean or fitted "
        "value [deg], as read, with the hard and soft iron only, and aligned.</p>",
        table_html(["pose", "samples", "norm before", "norm after", "dip before", "dip hard/soft only",
                    "dip after"], per_pose, [False, False] + [True] * 5),
        "<h3>Apply map</h3>",
        f"<p>h = A raw + c, with h in {esc(out)} in the accelerometer's frame, raw in {esc(m.raw_unit)}.</p>",
        table_html(["", "A[:, x]", "A[:, y]", "A[:, z]", f"c [{esc(out)}]"], apply_rows, [False] + [True] * 4)])


def _recording_html(figures: Mapping[str, bytes]) -> str:
    if "recording.png" not in figures:
        return "<p class=\"meta\">Figures were not made for this run.</p>"
    return figures_html({"recording.png": figures["recording.png"]}, CAPTIONS)


#: Each sensor kind's section (a calibration's sensors in its order); a new sensor adds one line.
SENSOR_SECTIONS = {"accelerometer": ("Accelerometer", _accelerometer_html),
                   "gyroscope": ("Gyroscope", lambda run, figures: _gyroscope_html(run)),
                   "magnetometer": ("Magnetometer", lambda run, figures: _magnetometer_html(run))}


def _calibration_sections(run: CalibrationRun, figures: Mapping[str, bytes] | None = None
                          ) -> list[tuple[str, str, str]]:
    figures = figures or {}
    out = [("recording", "The recording", _recording_html(figures))]
    for sensor in run.calibration.sensors:
        title, section = SENSOR_SECTIONS[sensor]
        out.append((sensor if sensor != "accelerometer" else "parameters", esc(title), section(run, figures)))
    out.append(("statistics", "Fit statistics and data", _statistics_html(run)))
    return out


def calibration_html(run: CalibrationRun, figures: Mapping[str, bytes] | None = None,
                     extra: Mapping[str, str] | None = None) -> str:
    """The page of ``imucal calibrate``: the verdict of every sensor, the recording, each sensor's section,
    the statistics and the remaining figures.

    ``figures`` maps file names to PNG bytes; ``extra`` maps headings to more plain text, shown
    preformatted and escaped."""
    figures = dict(figures or {})
    title = f"imucal calibration: {Path(run.recording.source).name}"
    sections = [("verdict", "", _verdict_html(verdict(run))), *_calibration_sections(run, figures)]
    for k, (head, text) in enumerate((extra or {}).items()):
        sections.append((f"extra{k}", esc(head), f"<pre>{esc(text)}</pre>"))
    rest = {n: png for n, png in figures.items() if n not in ("recording.png", "before_after.png")}
    sections.append(("figures", "Figures", figures_html(rest, CAPTIONS)))
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
                *_calibration_sections(d.final, figures),
                ("discovery", "Discovery report (text)", f"<pre>{esc(discovery_report(d))}</pre>"),
                ("figures", "Figures", figures_html(figures or {}, CAPTIONS))]
    return page_html(title, sections)


