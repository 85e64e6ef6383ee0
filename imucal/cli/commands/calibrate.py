"""`imucal calibrate CONFIG.yaml | --data FILE`: fit, then write calibration.yaml, report.txt, report.html,
figures."""
from __future__ import annotations

import argparse

from imucal.cli.commands import options
from imucal.errors import printable


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("calibrate", help="fit the 9-parameter model to a static multi-pose recording",
                       description="Fit shifts, scales and axis angles (Nakov & Ivanov) to a recording. "
                                   "Writes DIR/calibration.yaml, DIR/report.txt, DIR/report.html and figures.")
    p.add_argument("config", nargs="?", metavar="CONFIG|RECORDING",
                   help="YAML run file (.yaml, .yml; see configs/), or a recording, read as --data")
    options.add_data_options(p, gyro=True, stream=True)
    options.add_gravity_options(p)
    options.add_model_options(p, noise=True)
    options.add_gyro_options(p)
    options.add_mag_options(p)
    p.add_argument("--out", help="output directory (default: config output.dir, else ./out)")
    p.add_argument("--json", help="also write a machine-readable summary to this file")
    p.add_argument("--no-figures", action="store_true", help="skip the PNG figures (report.html then has none)")
    p.add_argument("--quiet", action="store_true", help="print only where the files went")
    p.set_defaults(run=run)


def _config(args: argparse.Namespace):
    from imucal.errors import ImucalError

    if args.config and not options.is_run_file(args.config):  # `imucal calibrate bench.csv`
        if args.data:
            raise ImucalError(f"{args.config} is a recording and --data names another", field="arguments",
                              fix="give the recording once, as --data or alone")
        args.config, args.data = None, args.config
    if args.config and args.data:
        raise ImucalError("give either CONFIG or --data, not both", field="arguments",
                          fix="put data.path in the YAML, or drop the YAML for a quick run")
    if not args.config and not args.data:
        raise ImucalError("nothing to calibrate", field="arguments",
                          fix="give a YAML run file or --data RECORDING")
    return options.run_config(args, args.config)


def run(args: argparse.Namespace) -> int:
    import os
    import sys
    from pathlib import Path

    from imucal.files.output import OutputSet, check_outputs
    from imucal.report.run_files import calibrate_files, output_paths, stage_files

    cfg = _config(args)
    out = Path(args.out or cfg.output.dir)
    if args.out is None and cfg.source:
        out = cfg.base_dir / cfg.output.dir if not Path(cfg.output.dir).is_absolute() else out
    out = Path(os.path.normpath(out))
    figures = cfg.output.figures and not args.no_figures
    gyro_file = args.gyro_data or options.data_path(cfg, gyro=True)
    if args.gyro_data:  # the run records where its gyroscope came from (the report's time series reads it)
        import dataclasses

        cfg = dataclasses.replace(cfg, data=dataclasses.replace(cfg.data, gyro_path=os.path.abspath(args.gyro_data)))
    inputs = [args.config, options.data_path(cfg), gyro_file, options.noise_path(cfg)]
    check_outputs(inputs, [*output_paths(out, figures), args.json])  # fail before the work, not after it
    files = calibrate_files(cfg, gyro_file)
    with OutputSet(inputs) as o:
        stage_files(o, out, files, figures, args.json)
    result, gyro, text = files.run, files.gyro, files.text
    for w in result.calibration.fit.get("warnings", []):
        sys.stderr.write(f"imucal: warning: {printable(w)}\n")
    if not args.quiet:
        print(text.split("[[Static intervals]]")[0].rstrip())
    if gyro is not None and not args.quiet:
        from imucal.report.gyro import gyro_report

        print(gyro_report(gyro))
    if result.mag is not None and not args.quiet:
        from imucal.report.mag import mag_lines

        print("\n".join(["magnetometer calibration", *("  " + line for line in mag_lines(result.mag))]))
    kinds = result.calibration.sensors
    held = f" ({', '.join(kinds[:-1])} and {kinds[-1]})" if len(kinds) > 1 else ""
    print(f"wrote {out / 'calibration.yaml'}" + held
          + f", {out / 'report.txt'}, {out / 'report.html'}"
          + (", figures" if figures else "") + (f", {args.json}" if args.json else ""))
    return 0 if files.success else 1  # EXIT_NOT_CONVERGED: the files say which fit
