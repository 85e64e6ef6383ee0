"""The magnetometer's results in words (issue 26): its warnings, lines of the text report. The values are
typed in imucal.mag.result.MagCalibration; this module only renders them."""
from __future__ import annotations

import math

from imucal.mag.model import MAG_ANGLE_TOL
from imucal.mag.result import MagCalibration
from imucal.mag.units import convert, stated_unit_mismatch


def mag_warnings(cal: MagCalibration) -> list[str]:
    """What the user must know about the magnetometer fit, one sentence each (as the accelerometer's)."""
    out = []
    if not cal.fit.success:
        out.append(f"magnetometer: the solver stopped with {cal.fit.status}: check the fit before using it")
    if cal.soft_iron_at_bound:
        out.append(f"magnetometer: the soft iron's angle(s) {', '.join(cal.soft_iron_at_bound)} reached their bound "
                   f"(90 deg +- {90 * MAG_ANGLE_TOL:g} deg): the field is distorted more than a board's soft iron "
                   "(a magnet or a steel part close to the sensor?); move the sensor away from it and record again")
    steps = cal.steps
    if steps is not None and steps.step_after is not None:
        out.append(f"magnetometer: the field's magnitude steps by {100 * steps.step:+.2g} % after pose "
                   f"{steps.step_after + 1} (a disturbed environment: iron moved, a motor or a magnet near): "
                   f"record again away from it")
    if cal.excluded:
        out.append(f"magnetometer: {len(cal.excluded)} pose(s) whose field stood out were left out of the fit "
                   f"(samples {', '.join(f'{o.start}-{o.end}' for o in cal.excluded)})")
    if cal.left_handed:
        out.append("magnetometer: the fitted dip has the opposite sign of the field model's: one of its axes is "
                   "probably inverted (a left-handed frame); check the axis signs")
    b = math.prod(cal.params[f"b{i}"].value for i in (1, 2, 3)) ** (1 / 3)
    looks = stated_unit_mismatch(cal.raw_unit, cal.field_unit, b)
    if looks is not None:
        hint = f"they look like {looks}: give mag.unit {looks}" if looks else "counts? give mag.unit raw"
        out.append(f"magnetometer: its scales are {b:.3g} {cal.raw_unit} per {cal.field_unit}, where readings in "
                   f"{cal.raw_unit} have about {convert(1.0, cal.field_unit, cal.raw_unit):.3g}: the readings are not "
                   f"in {cal.raw_unit} ({hint}, or check mag.field)")
    if not cal.field_given:
        out.append(f"magnetometer: the field's magnitude was fitted (its overall scale held): the calibrated "
                   f"field is in the sensor's unit {cal.field_unit}; give mag.field (--mag-field) for a field unit")
    return out


def no_magnetometer_warning(source: str, unread: str = "") -> str:
    """The magnetometer's settings given (mag:, --mag-*) for a recording without one, or a magnetometer the file
    holds but was not asked to read (``unread``: a netCDF field variable, "NAME (UNITS)")."""
    if unread:
        name = unread.rsplit(" (", 1)[0]
        return (f"magnetometer: {source} holds {unread}, not read: no magnetometer calibrated (map it to calibrate "
                f"it: --columns mx={name}, or data.columns: {{mx: {name}}})")
    return (f"magnetometer: mag settings given, but {source} has no mx, my, mz: no magnetometer calibrated "
            "(map its columns: data.columns, --columns mx=...,my=...,mz=...)")


def mag_lines(cal: MagCalibration) -> list[str]:
    """The magnetometer's lines of the text report."""
    r, p = cal.report, cal.params
    out = [f"model: {cal.fit.model.name}",
           f"hard iron: {', '.join(f'{v:.4g}' for v in (p['s1'].value, p['s2'].value, p['s3'].value))} "
           f"{cal.raw_unit}",
           f"field: {p['F'].value:.5g} {cal.field_unit} ({'given' if cal.field_given else 'fitted'})",
           f"field-norm residual: {r.norm_pct.before:.3g} % before, {r.norm_pct.after:.3g} % after "
           f"(noise floor {r.norm_pct.floor:.2g} %)"]
    if r.dip_deg is not None:
        out.append(f"dip scatter: {r.dip_deg.before:.3g} deg before, {r.dip_deg.after:.3g} deg after "
                   f"(alignment {math.degrees(cal.misalignment):.3g} deg, soft iron "
                   f"{'full 3x3' if cal.full_soft_iron else 'symmetric'})")
    if cal.lag is not None:
        how = f"estimated, correlation {cal.lag.correlation:.2f}" if cal.lag.estimated else "given"
        out.append(f"lag: mx, my, mz lag the accelerometer by {cal.lag.samples:.3g} samples ({how}; taken out of the "
                   "fit); `imucal apply` moves them earlier by the nearest whole number of samples at the data's "
                   "rate, the generated C and the exports do not: pair mag[k] with acc[k - lag] in firmware")
    out.append(f"solver: {cal.fit.status}")
    return out
