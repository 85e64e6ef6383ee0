"""`imucal apply CALIBRATION --data IN --out OUT.csv`: calibrated acceleration for every sample."""
from __future__ import annotations

import argparse

from imucal.cli.commands import options


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("apply", help="apply a calibration to a recording",
                       description="Write calibrated acceleration [m/s^2] in the Theorem's orthonormal "
                                   "frame for every sample: the input's time column exactly as it was "
                                   "(name, unit, origin), then ax, ay, az.")
    p.add_argument("calibration", help="calibration.yaml written by `imucal calibrate`")
    p.add_argument("--config", help="YAML run file: reuse its data section (columns, units, path)")
    options.add_data_options(p)
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

    from imucal.calibration.frozen import load_calibration
    from imucal.data.load import load_recording
    from imucal.errors import ImucalError
    from imucal.files.output import check_outputs, write_text_atomic

    cfg = options.run_config(args, args.config)
    inputs = [args.calibration, args.config, options.data_path(cfg)]
    check_outputs(inputs, [args.out])
    cal = load_calibration(args.calibration)
    rec = load_recording(cfg.data, cfg.base_dir)
    covs = {}
    if "temp" in cal.covariates:
        if rec.temp is None:
            raise ImucalError("the calibration has a temperature effect but the data have no temp column",
                              file=rec.source, field="temp", fix="add a temp column in deg C")
        covs["temp"] = rec.temp
    if "time" in cal.covariates:
        covs["time"] = rec.t
    a = cal.apply(rec.raw, covs)
    ts, tfmt = _time_column(rec)
    buf = io.StringIO()
    buf.write("t,ax,ay,az\n")  # imucal's layout (examples/codegen reads it)
    body = np.column_stack([ts, a])
    np.savetxt(buf, body, delimiter=",", fmt=[tfmt, "%.9g", "%.9g", "%.9g"])
    check_outputs(inputs, [args.out])  # nothing changed meanwhile
    write_text_atomic(args.out, buf.getvalue())
    how = (f"the input's {rec.time_column} column as read ({rec.time_unit})" if rec.t_source is not None
           else "s from the first sample")
    print(f"wrote {rec.n} calibrated samples [m/s^2] to {args.out}; t is {how}")
    return 0
