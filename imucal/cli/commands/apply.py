"""`imucal apply CALIBRATION --data IN --out OUT.csv`: calibrated acceleration for every sample."""
from __future__ import annotations

import argparse

from imucal.cli.commands import options


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("apply", help="apply a calibration to a recording",
                       description="Write calibrated acceleration [m/s^2] in the Theorem's orthonormal "
                                   "frame for every sample: the input's time column exactly as it was "
                                   "(name, unit, origin), then ax, ay, az; with a calibrated gyroscope "
                                   "and gyro data, also gx, gy, gz [rad/s] in the same frame.")
    p.add_argument("calibration", help="calibration.yaml written by `imucal calibrate`")
    p.add_argument("--config", help="YAML run file: reuse its data section (columns, units, path)")
    options.add_data_options(p, gyro=True)
    p.add_argument("--out", required=True, help="output CSV")
    p.set_defaults(run=run)


def _time_column(rec) -> tuple:
    """(values, printf format): the input's stamps as read (unit and origin kept, integers kept
    integers), or seconds from the first sample when the file had no time column."""
    import numpy as np

    if rec.t_source is None:
        return rec.t, "%.9g"
    ts = rec.t_source
    exact_int = bool(np.all(ts == np.round(ts))) and float(np.max(np.abs(ts))) < 2.0**53
    return ts, ("%d" if exact_int else "%.17g")


def run(args: argparse.Namespace) -> int:
    import io

    import numpy as np

    from imucal.calibration.fileformat import load_calibration
    from imucal.data.load import load_recording
    from imucal.files.output import check_outputs, write_text_atomic
    from imucal.gyro.run import gyro_on_accel_samples
    from imucal.model.channels import covariate_values

    cfg = options.run_config(args, args.config)
    gyro_file = args.gyro_data or options.data_path(cfg, gyro=True)
    inputs = [args.calibration, args.config, options.data_path(cfg), gyro_file]
    check_outputs(inputs, [args.out])
    cal = load_calibration(args.calibration)
    rec = load_recording(cfg.data, cfg.base_dir)
    covs = covariate_values(cal.covariates, temp=rec.temp, time=rec.t, source=rec.source, what="the calibration")
    a = cal.apply(rec.raw, covs)
    cols, body = ["ax", "ay", "az"], [a]
    raw_g = None if cal.gyro is None else gyro_on_accel_samples(rec, None if gyro_file is None else str(gyro_file))
    if raw_g is not None:
        cols, body = cols + ["gx", "gy", "gz"], body + [cal.gyro.apply(raw_g, a)]
    ts, tfmt = _time_column(rec)
    buf = io.StringIO()
    buf.write(",".join(["t", *cols]) + "\n")  # imucal's layout (examples/codegen reads it)
    np.savetxt(buf, np.column_stack([ts, *body]), delimiter=",", fmt=[tfmt] + ["%.9g"] * len(cols))
    check_outputs(inputs, [args.out])  # nothing changed meanwhile
    write_text_atomic(args.out, buf.getvalue())
    how = (f"the input's {rec.time_column} column as read ({rec.time_unit})" if rec.t_source is not None
           else "s from the first sample")
    what = "[m/s^2] and angular rate [rad/s]" if raw_g is not None else "[m/s^2]"
    note = ("; the calibration has a gyroscope but the data have none (gx, gy, gz or --gyro-data): "
            "acceleration only" if cal.gyro is not None and raw_g is None else "")
    print(f"wrote {rec.n} calibrated samples {what} to {args.out}; t is {how}{note}")
    return 0
