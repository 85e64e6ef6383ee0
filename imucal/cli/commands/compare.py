"""`imucal compare CAL OTHER --data FILE [--format FMT]`: two calibrations on the same still intervals."""
from __future__ import annotations

import argparse

from imucal.cli.commands import options
from imucal.errors import printable

IMPORT_FORMATS = ("imucal", "imutk", "madlab", "matrix", "kalibr", "ardupilot", "px4", "tomisuarez")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("compare", help="compare a calibration with another (any exported or peer format)",
                       description="Apply CAL and OTHER to every still interval of the recording and print "
                                   "|a| - g per interval, the RMS and the max, one table. OTHER's format comes "
                                   "from its name (.calib imutk, .param ardupilot, .params px4, .csv matrix, "
                                   ".json madlab or matrix, .yaml imucal or kalibr) unless --format is given. "
                                   "g is CAL's gravity.")
    p.add_argument("calibration", help="calibration.yaml written by `imucal calibrate`")
    p.add_argument("other", help="the other calibration file")
    p.add_argument("--format", choices=IMPORT_FORMATS, help="OTHER's format (default: from its name)")
    p.add_argument("--config", help="YAML run file: reuse its data and static sections")
    options.add_data_options(p)
    p.add_argument("--json", help="write the table as JSON")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from imucal.analysis.compare import compare
    from imucal.calibration.frozen import load_calibration
    from imucal.data.load import load_recording
    from imucal.data.static import detect_static
    from imucal.export.registry import guess_format, read_peer
    from imucal.files.output import check_outputs, write_json_atomic

    cfg = options.run_config(args, args.config)
    inputs = [args.calibration, args.other, args.config, options.data_path(cfg)]
    check_outputs(inputs, [args.json])
    cal = load_calibration(args.calibration)
    fmt = args.format or guess_format(args.other)
    other = read_peer(args.other, fmt)
    rec = load_recording(cfg.data, cfg.base_dir)
    declared = cfg.data.declared_rails
    iv = detect_static(rec.t, rec.raw, cfg.static, rec.temp, source=rec.source, rails=declared)
    names = (Path(args.calibration).name, f"{Path(args.other).name} ({fmt})")
    res = compare(cal, other, rec, iv, cal.gravity, names)
    print(f"{iv.n} still intervals of {printable(rec.source)}; g = {cal.gravity:.6g} m/s^2 (from {names[0]})")
    if getattr(other, "extra", {}).get("offset_held") is False:
        print(f"note: {names[1]} holds no bias (Kalibr estimates it online): its offset is taken as zero")
    print(res.table())
    if args.json:
        check_outputs(inputs, [args.json])
        write_json_atomic(args.json, res.to_dict())
        print(f"wrote {args.json}")
    return 0
