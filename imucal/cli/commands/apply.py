"""`imucal apply CALIBRATION --data IN --out OUT.csv`: calibrated acceleration for every sample."""
from __future__ import annotations

import argparse

from imucal.cli.commands import options
from imucal.errors import key_text, printable


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("apply", help="apply a calibration to a recording",
                       description="Write calibrated acceleration [m/s^2] in the Theorem's orthonormal "
                                   "frame for every sample: the input's time column exactly as it was "
                                   "(name, unit, origin), then ax, ay, az; with a calibrated gyroscope "
                                   "and gyro data, also gx, gy, gz [rad/s] in the same frame; with a "
                                   "calibrated magnetometer and mx, my, mz data, also mx, my, mz (the "
                                   "field's unit).")
    p.add_argument("calibration", help="calibration.yaml written by `imucal calibrate`")
    p.add_argument("--config", help="YAML run file: reuse its data section (columns, units, path)")
    options.add_data_options(p, gyro=True)
    p.add_argument("--out", required=True, help="output CSV")
    p.add_argument("--no-gravity-check", action="store_true",
                   help="write the output even when |a| at rest after calibration misses the calibration's "
                        "gravity by more than 10 %% or |h| its field by a factor 2 (default: refused, as data in "
                        "another unit than the calibration's do; a warning instead with this flag)")
    p.set_defaults(run=run)


def _time_column(rec, spec, path) -> tuple:
    """(values, printf format, texts): the input's stamps as read (unit and origin kept, integers kept
    integers), or seconds from the first sample when the file had no time column; texts: the stamps as the
    file writes them when they are integers beyond 2**53, which a double does not hold (else None)."""
    import numpy as np

    from imucal.data.whole import stamp_texts

    if rec.t_source is None:
        return rec.t, "%.9g", None
    ts = rec.t_source
    integers = bool(np.all(ts == np.round(ts)))
    if integers and float(np.max(np.abs(ts))) >= 2.0**53:  # nanoseconds since 1970: the file's own digits
        return ts, "%.17g", stamp_texts(spec, path, rec.n)
    return ts, ("%d" if integers else "%.17g"), None


def _rest_words(chk) -> str:
    """One sentence on |a| at rest after calibration (imucal.analysis.rest.RestCheck)."""
    def unit(u: str) -> str:
        return "raw counts" if u in ("raw", "counts") else u

    text = (f"|a| at rest {chk.at_rest:.3g} m/s^2 after calibration, where the calibration's gravity is "
            f"{chk.gravity:.4g} m/s^2 (median of {chk.intervals} still intervals)")
    if chk.ok:
        return text
    looks = chk.data_looks_like
    seen = f"|reading| at rest {chk.raw_at_rest:.4g}"
    if looks is not None and unit(looks) != unit(chk.cal_unit):
        return f"{text}: the data look like {looks} ({seen}) while the calibration takes {unit(chk.cal_unit)}"
    return f"{text}: the data ({seen}) do not fit a calibration that takes {unit(chk.cal_unit)}"


def _span_words(span, n: int) -> str:
    return (f"{span.outside} of {n} samples are at temperatures well outside the {span.tmin:.4g}..{span.tmax:.4g} degC "
            f"the calibration's temperature terms were fitted over (the data span {span.low:.4g}..{span.high:.4g} degC): "
            "there they are extrapolated (the autopilots hold the end value)")


def run(args: argparse.Namespace) -> int:
    import io
    import sys

    import numpy as np

    from imucal.analysis.rest import rest_check, temperature_span
    from imucal.calibration.frozen import load_calibration
    from imucal.data.static import detect_static
    from imucal.errors import ImucalError
    from imucal.data.load import load_recording
    from imucal.files.output import check_outputs, write_text_atomic
    from imucal.gyro.run import gyro_on_accel_samples
    from imucal.model.channels import covariate_values
    from imucal.model.sensor import ACCELEROMETER, GYROSCOPE, MAGNETOMETER

    cfg = options.run_config(args, args.config)
    gyro_file = args.gyro_data or options.data_path(cfg, gyro=True)
    inputs = [args.calibration, args.config, options.data_path(cfg), gyro_file]
    check_outputs(inputs, [args.out])
    cal = load_calibration(args.calibration)
    rec = load_recording(cfg.data, cfg.base_dir)
    raw_g = None if cal.gyro is None else gyro_on_accel_samples(rec, None if gyro_file is None else str(gyro_file))
    raws = {ACCELEROMETER: rec.raw, GYROSCOPE: raw_g, MAGNETOMETER: rec.mag}
    lag = 0
    if cal.sensor(MAGNETOMETER) is not None and rec.mag is not None:
        from imucal.mag.run import aligned  # only a calibration with a magnetometer

        raws[MAGNETOMETER], lag = aligned(cal.sensor(MAGNETOMETER), rec.mag, rec.sample_rate, rec.mag_unit)
    # the covariates of every sensor the data hold (the gyroscope's bias(T) reads temp even when the
    # accelerometer's map does not)
    keys = tuple(dict.fromkeys([*cal.covariates, *(k for s in cal.attached if raws.get(s.kind) is not None
                                                   for k in s.covariates)]))
    covs = covariate_values(keys, temp=rec.temp, time=rec.t, source=rec.source, what="the calibration")
    a = cal.apply(rec.raw, covs)
    chk = None
    if rec.n >= 3:  # |a| at rest, where the data have still spans, must be the calibration's gravity
        chk = rest_check(a, rec.raw, detect_static(rec.t, rec.raw, cfg.static, source=rec.source),
                         cal.gravity, cal.raw_unit)
    if chk is not None and not chk.ok:
        if not args.no_gravity_check:
            raise ImucalError(_rest_words(chk), file=rec.source, field="data.unit",
                              fix=f"apply the calibration made for data in this unit, or give data in its unit "
                                  f"({cal.raw_unit}); --no-gravity-check writes the output anyway")
        sys.stderr.write(f"imucal: warning: {_rest_words(chk)}\n")
    span = temperature_span([cal.fit, *(s.fit for s in cal.attached if raws.get(s.kind) is not None)],
                            rec.temp if "temp" in keys else None)
    if span is not None and span.outside:
        sys.stderr.write(f"imucal: warning: {_span_words(span, rec.n)}\n")
    out = cal.apply_all(raws, covs, acc=a)  # every sensor, one frame
    if MAGNETOMETER in out:  # |h| must be the calibration's field, as |a| at rest its gravity
        from imucal.mag.run import field_error

        if (err := field_error(cal.sensor(MAGNETOMETER), out[MAGNETOMETER], rec.source)) is not None:
            if not args.no_gravity_check:
                raise err
            sys.stderr.write(f"imucal: warning: {printable(err.message)}\n")
    done = [s for s in cal.all_sensors if s.kind in out]
    cols, body = [c for s in done for c in s.model.output.columns], [out[s.kind] for s in done]
    ts, tfmt, texts = _time_column(rec, cfg.data, options.data_path(cfg))
    buf = io.StringIO()
    buf.write(",".join(["t", *cols]) + "\n")  # imucal's layout (examples/codegen reads it)
    if texts is None:
        np.savetxt(buf, np.column_stack([ts, *body]), delimiter=",", fmt=[tfmt] + ["%.9g"] * len(cols))
    else:
        rows = io.StringIO()
        np.savetxt(rows, np.column_stack(body), delimiter=",", fmt="%.9g")
        buf.writelines(f"{t},{row}\n" for t, row in zip(texts, rows.getvalue().splitlines()))
    check_outputs(inputs, [args.out])  # nothing changed meanwhile
    write_text_atomic(args.out, buf.getvalue())
    unwrapped = ", a wrapped counter unwrapped" if rec.time_base is not None and rec.time_base.wraps else ""
    how = (f"the input's {key_text(rec.time_column)} column as read ({rec.time_unit}{unwrapped})"
           if rec.t_source is not None else "s from the first sample")
    what = " and ".join((f"{s.model.output.role.replace('_', ' ')} " if k else "") + f"[{s.model.output.unit}]"
                        for k, s in enumerate(done))  # the acceleration first, as the samples
    lack = [s for s in cal.attached if s.kind not in out]
    note = "".join(f"; the calibration has a {s.kind} but the data have none ({', '.join(s.model.channel.columns)}"
                   f"{' or --gyro-data' if s.kind == GYROSCOPE else ''}): left out" for s in lack)
    if lag:
        note += (f"; mx, my, mz moved {lag} samples {'earlier' if lag > 0 else 'later'} (the magnetometer's lag "
                 f"behind the accelerometer): the {'last' if lag > 0 else 'first'} {abs(lag)} rows' mx, my, mz are nan")
    rest = "; no still span: |a| at rest not checked" if chk is None else f"; {_rest_words(chk)}"
    print(f"wrote {rec.n} calibrated samples {what} to {args.out}; t is {how}{note}{rest}")
    return 0
