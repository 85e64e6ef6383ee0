"""`imucal export CAL --format FMT --out FILE`: the calibration in a peer tool's format."""
from __future__ import annotations

import argparse

from imucal.cli.commands import options

EXPORT_FORMATS = ("imutk", "madlab", "matrix", "kalibr", "ardupilot", "px4")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("export", help="write a calibration in another tool's format "
                                      "(imu_tk, mad-lab, matrix, Kalibr, ArduPilot, PX4)",
                       description="imutk: imu_tk's .calib; madlab: mad-lab-fau/imucal's Ferraris JSON; "
                                   "matrix: JSON (or CSV by the file ending) of a = matrix raw + offset; "
                                   "kalibr: Kalibr's imu.yaml (scale-misalignment intrinsics; noise fields from "
                                   "--data's still segment, else null); ardupilot, px4: offset and diagonal scale "
                                   "(the misalignment they cannot hold is measured and stated). Effects are not "
                                   "exported: the map at their reference point is written, and the output says so.")
    p.add_argument("calibration", help="calibration.yaml written by `imucal calibrate`")
    p.add_argument("--format", required=True, choices=EXPORT_FORMATS, help="target format")
    p.add_argument("--out", required=True, help="output file")
    p.add_argument("--rostopic", default="/imu0", help="kalibr: the IMU's ROS topic (default /imu0)")
    p.add_argument("--config", help="YAML run file: reuse its data section (kalibr noise)")
    options.add_data_options(p)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from imucal.calibration.fileformat import load_calibration
    from imucal.errors import ImucalError
    from imucal.export.formats import FORMATS, ExportOptions, export
    from imucal.files.output import check_outputs, write_text_atomic

    noise_data = bool(args.data or args.config)
    if noise_data and args.format != "kalibr":
        raise ImucalError("--data and --config feed Kalibr's noise fields only", field="--data",
                          fix="drop --data, or use --format kalibr")
    cfg = options.run_config(args, args.config) if noise_data else None
    inputs = [args.calibration, args.config, options.data_path(cfg) if cfg else None]
    check_outputs(inputs, [args.out])
    cal = load_calibration(args.calibration)
    noise = None
    if cfg is not None:
        from imucal.data.load import load_recording
        from imucal.export.kalibr import still_noise

        rec = load_recording(cfg.data, cfg.base_dir)
        noise = still_noise(cal, rec.t, rec.raw, rec.sample_rate)
    out = export(cal, args.format, ExportOptions(filename=str(args.out), noise=noise, rostopic=args.rostopic))
    check_outputs(inputs, [args.out])
    write_text_atomic(args.out, out.text)
    print(f"wrote {args.out}: {FORMATS[args.format][1]}")
    for note in out.notes:
        print(f"note: {note}")
    return 0
