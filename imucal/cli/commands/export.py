"""`imucal export CAL --format FMT --out FILE`: the calibration in a peer tool's format."""
from __future__ import annotations

import argparse
from pathlib import Path

from imucal.cli.commands import options

EXPORT_FORMATS = ("imutk", "madlab", "matrix", "kalibr", "ardupilot", "px4")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("export", help="write a calibration in another tool's format "
                                      "(imu_tk, mad-lab, matrix, Kalibr, ArduPilot, PX4)",
                       description="imutk: imu_tk's .calib; madlab: mad-lab-fau/imucal's Ferraris JSON; "
                                   "matrix: JSON (or CSV by the file ending) of a = matrix raw + offset; "
                                   "kalibr: Kalibr's imu.yaml (scale-misalignment intrinsics; noise fields from "
                                   "--data's still segment, else null); ardupilot, px4: offset and diagonal scale "
                                   "(the misalignment they cannot hold is measured and stated). A gyroscope part "
                                   "is written wherever the format holds one (imutk: a second .calib, --gyro-out); "
                                   "what a format cannot hold of it is measured and stated. Effects are not "
                                   "exported: the map at their reference point is written, and the output says so.")
    p.add_argument("calibration", help="calibration.yaml written by `imucal calibrate`")
    p.add_argument("--format", required=True, choices=EXPORT_FORMATS, help="target format")
    p.add_argument("--out", required=True, help="output file")
    p.add_argument("--gyro-out", help="imutk: the gyroscope's .calib (default: OUT with _gyro before its ending)")
    p.add_argument("--rostopic", default="/imu0", help="kalibr: the IMU's ROS topic (default /imu0)")
    p.add_argument("--config", help="YAML run file: reuse its data section (kalibr noise)")
    options.add_data_options(p, gyro=True)
    p.set_defaults(run=run)


def gyro_out_name(out: str) -> str:
    """imu_tk's second file beside OUT: x.calib -> x_gyro.calib."""
    p = Path(out)
    return str(p.with_name(f"{p.stem}_gyro{p.suffix}"))


def run(args: argparse.Namespace) -> int:
    from imucal.calibration.frozen import load_calibration
    from imucal.errors import ImucalError
    from imucal.export.formats import ExportOptions
    from imucal.export.registry import FORMATS, export
    from imucal.files.output import OutputSet, check_outputs

    noise_data = bool(args.data or args.config or args.gyro_data)
    if noise_data and args.format != "kalibr":
        raise ImucalError("--data, --gyro-data and --config feed Kalibr's noise fields only", field="--data",
                          fix="drop --data, or use --format kalibr")
    if args.gyro_out and args.format != "imutk":
        raise ImucalError("only imu_tk keeps the gyroscope in a second file", field="--gyro-out",
                          fix="drop --gyro-out, or use --format imutk")
    cfg = options.run_config(args, args.config) if (args.data or args.config) else None
    if args.gyro_data and cfg is None:
        raise ImucalError("needs the accelerometer's recording", field="--gyro-data", fix="add --data LOG")
    gyro_file = args.gyro_data or (options.data_path(cfg, gyro=True) if cfg else None)
    inputs = [args.calibration, args.config, options.data_path(cfg) if cfg else None, gyro_file]
    cal = load_calibration(args.calibration)
    gyro_out = None
    if args.format == "imutk" and cal.gyro is not None:
        gyro_out = args.gyro_out or gyro_out_name(args.out)
    outs = [args.out] + ([gyro_out] if gyro_out else [])
    check_outputs(inputs, outs)
    noise = None
    if cfg is not None:
        from imucal.data.load import load_recording
        from imucal.export.kalibr import still_noise
        from imucal.gyro.run import gyro_on_accel_samples

        rec = load_recording(cfg.data, cfg.base_dir)
        graw = gyro_on_accel_samples(rec, None if gyro_file is None else str(gyro_file))
        noise = still_noise(cal, rec.t, rec.raw, rec.sample_rate, graw)
    try:
        out = export(cal, args.format, ExportOptions(filename=str(args.out), noise=noise, rostopic=args.rostopic))
    except ImucalError as exc:  # about the calibration's contents unless it names another file
        if exc.file is not None:
            raise
        raise ImucalError(exc.message, file=str(args.calibration), field=exc.field, fix=exc.fix) from None
    with OutputSet(inputs) as files:  # both of imu_tk's files appear, or neither
        files.text(args.out, out.text)
        if gyro_out:
            files.text(gyro_out, out.gyro_text)
    print(f"wrote {args.out}: {FORMATS[args.format][1]}")
    if gyro_out:
        print(f"wrote {gyro_out}: imu_tk .calib of the gyroscope (omega = T K (raw - b))")
    for note in out.notes:
        print(f"note: {note}")
    return 0
