"""`imucal noise --data STILL_LOG | --config RUN.yaml [--calibration CAL] [--json OUT] [--plot PNG]`:
Allan-deviation noise terms of the accelerometer and, when the recording has one, the gyroscope."""
from __future__ import annotations

import argparse

from imucal.cli.commands import options


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("noise", help="white-noise density, bias instability and random walk (Allan deviation)",
                       description="Overlapping Allan deviation per axis of a still log (or of the longest still "
                                   "interval of a calibration log), for the accelerometer and the gyroscope (gx, gy, "
                                   "gz columns or a bag's angular_velocity): white-noise density, bias instability "
                                   "and random walk with their uncertainty, and Kalibr's imu.yaml fields when the "
                                   "readings are in SI units (or a calibration converts them).")
    options.add_data_options(p, gyro=True)
    p.add_argument("--config", help="YAML run file: reuse its data section (data.path is the still log unless --data "
                                    "names another)")
    p.add_argument("--calibration", help="calibration.yaml: evaluate calibrated acceleration [m/s^2] (and angular "
                                         "rate [rad/s] when it holds a gyroscope)")
    p.add_argument("--json", help="write the estimates as JSON ('-': to stdout)")
    p.add_argument("--plot", metavar="PNG", help="draw the Allan deviation of every axis with its terms")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    import dataclasses

    from imucal.analysis.still_noise import measure_noise
    from imucal.calibration.frozen import load_calibration
    from imucal.data.load import load_recording
    from imucal.files.output import OutputSet, check_outputs
    from imucal.report.noise import allan_figure, noise_text

    cfg = options.run_config(args, args.config)
    gyro_file = args.gyro_data or options.data_path(cfg, gyro=True)
    inputs = [args.config, options.data_path(cfg), gyro_file, args.calibration]
    check_outputs(inputs, [args.json, args.plot])
    rec = load_recording(cfg.data, cfg.base_dir)
    if gyro_file is not None:  # imu_tk's second file, on the accelerometer's samples
        from imucal.gyro.run import gyro_on_accel_samples

        rec = dataclasses.replace(rec, gyro=gyro_on_accel_samples(rec, str(gyro_file)))
    noise = measure_noise(rec, load_calibration(args.calibration) if args.calibration else None)
    print(noise_text(noise))
    with OutputSet(inputs) as o:
        if args.json:
            o.json(args.json, noise.to_json())
        if args.plot:
            o.call(args.plot, lambda p: allan_figure(noise, p))
    for f in (args.json, args.plot):
        if f and f != "-":
            print(f"wrote {f}")
    return 0
