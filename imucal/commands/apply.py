"""`imucal apply CALIBRATION --data IN --out OUT.csv`: calibrated acceleration for every sample."""
from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("apply", help="apply a calibration to a recording",
                       description="Write calibrated acceleration [m/s^2] in the Theorem's orthonormal "
                                   "frame for every sample: columns t, ax, ay, az.")
    p.add_argument("calibration", help="calibration.yaml written by `imucal calibrate`")
    p.add_argument("--data", required=True, help="recording (same formats as calibrate)")
    p.add_argument("--out", required=True, help="output CSV")
    p.add_argument("--sample-rate", type=float, help="sample rate [Hz] when the file has no time column")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    import io

    import numpy as np

    from ..calibration import load_calibration
    from ..data import DataSpec, load_recording
    from ..output import check_destination, write_text_atomic

    check_destination(args.out)
    cal = load_calibration(args.calibration)
    rec = load_recording(DataSpec(path=args.data, sample_rate=args.sample_rate))
    covs = {}
    if "temp" in cal.covariates:
        if rec.temp is None:
            from ..errors import ImucalError

            raise ImucalError("the calibration has a temperature effect but the data have no temp column",
                              file=rec.source, field="temp", fix="add a temp column in deg C")
        covs["temp"] = rec.temp
    if "time" in cal.covariates:
        covs["time"] = rec.t
    a = cal.apply(rec.raw, covs)
    buf = io.StringIO()
    buf.write("t,ax,ay,az\n")
    np.savetxt(buf, np.column_stack([rec.t, a]), delimiter=",", fmt="%.9g")
    write_text_atomic(args.out, buf.getvalue())
    print(f"wrote {rec.n} calibrated samples [m/s^2] to {args.out}")
    return 0
