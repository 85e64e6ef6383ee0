"""`imucal calibrate CONFIG.yaml | --data FILE`: fit, then write calibration.yaml, report.txt, figures."""
from __future__ import annotations

import argparse

from imucal.cli.commands import options


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("calibrate", help="fit the 9-parameter model to a static multi-pose recording",
                       description="Fit shifts, scales and axis angles (Nakov & Ivanov) to a recording. "
                                   "Writes DIR/calibration.yaml, DIR/report.txt and figures.")
    p.add_argument("config", nargs="?", help="YAML run file (see configs/)")
    options.add_data_options(p, stream=True)
    options.add_gravity_options(p)
    options.add_model_options(p)
    p.add_argument("--gyro-data", metavar="FILE",
                   help="gyroscope recording on the accelerometer's time base (imu_tk: t x y z); "
                        "gyro columns gx, gy, gz in --data are used without it")
    p.add_argument("--out", help="output directory (default: config output.dir, else ./out)")
    p.add_argument("--json", help="also write a machine-readable summary to this file")
    p.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    p.add_argument("--quiet", action="store_true", help="print only where the files went")
    p.set_defaults(run=run)


def _config(args: argparse.Namespace):
    from imucal.errors import ImucalError

    if args.config and args.data:
        raise ImucalError("give either CONFIG or --data, not both", field="arguments",
                          fix="put data.path in the YAML, or drop the YAML for a quick run")
    if not args.config and not args.data:
        raise ImucalError("nothing to calibrate", field="arguments",
                          fix="give a YAML run file or --data RECORDING")
    return options.run_config(args, args.config)


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from imucal.files.output import OutputSet, check_outputs
    from imucal.pipeline import calibrate
    import yaml

    from imucal.data.stream import has_gyro, use_stream
    from imucal.errors import ImucalError
    from imucal.gyro.run import calibrate_gyro
    from imucal.report.text import fit_report, summary

    cfg = _config(args)
    out = Path(args.out or cfg.output.dir)
    if args.out is None and cfg.source:
        out = cfg.base_dir / cfg.output.dir if not Path(cfg.output.dir).is_absolute() else out
    import os

    from imucal.report.figures import FIGURES

    out = Path(os.path.normpath(out))
    figures = cfg.output.figures and not args.no_figures
    gyro_file = args.gyro_data or options.data_path(cfg, gyro=True)
    inputs = [args.config, options.data_path(cfg), gyro_file]
    outputs = [out / "calibration.yaml", out / "report.txt", out / "gyro.yaml", args.json,
               *([out / n for n in FIGURES] if figures else [])]
    check_outputs(inputs, outputs)  # fail before the work, not after it
    if use_stream(cfg.data, cfg.base_dir) and has_gyro(cfg.data, cfg.base_dir):
        raise ImucalError("has gyroscope data, which reading in chunks does not keep", file=str(options.data_path(cfg)),
                          field="--stream", fix="give --stream never (data.stream: never) to read it whole")
    result = calibrate(cfg)
    text = fit_report(result)
    gyro = calibrate_gyro(result, None if gyro_file is None else str(gyro_file))  # None when the recording has no gyroscope
    js = summary(result)
    if gyro is not None:
        text += "[[Gyroscope]]  (provisional: apply and codegen do not use it yet)\n" + gyro.report() + "\n"
        js["gyro"] = gyro.to_dict()
    with OutputSet(inputs) as o:
        o.call(out / "calibration.yaml", result.calibration.save)
        o.text(out / "report.txt", text)
        if figures:
            for name, fn in FIGURES.items():
                o.call(out / name, lambda p, fn=fn: fn(result, p))
        if gyro is not None:
            o.text(out / "gyro.yaml", yaml.safe_dump({"format": "imucal-gyro-calibration", "format_version": 0,
                                                      **gyro.to_dict()}, sort_keys=False))
        if args.json:
            o.json(args.json, js)
    import sys

    for w in result.calibration.fit.get("warnings", []):
        sys.stderr.write(f"imucal: warning: {w}\n")
    if not args.quiet:
        print(text.split("[[Static intervals]]")[0].rstrip())
    if gyro is not None and not args.quiet:
        print(gyro.report())
    print(f"wrote {out / 'calibration.yaml'}, {out / 'report.txt'}" + (f", {out / 'gyro.yaml'}" if gyro else "")
          + (", figures" if figures else "") + (f", {args.json}" if args.json else ""))
    ok = result.result.success and (gyro is None or gyro.success)
    return 0 if ok else 1  # EXIT_NOT_CONVERGED: the files say which fit
