"""`imucal noise --data STILL_LOG [--calibration CAL] [--json OUT]`: Allan-deviation noise terms."""
from __future__ import annotations

import argparse

from imucal.cli.commands import options


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("noise", help="white-noise density, bias instability and random walk (Allan deviation)",
                       description="Overlapping Allan deviation per axis of a still log (or of the longest still "
                                   "interval of a calibration log): white-noise density, bias instability and "
                                   "random walk with their uncertainty, and Kalibr's imu.yaml fields when a "
                                   "calibration converts the readings to m/s^2.")
    options.add_data_options(p, data_required=True)
    p.add_argument("--config", help="YAML run file: reuse its data section")
    p.add_argument("--calibration", help="calibration.yaml: evaluate calibrated acceleration [m/s^2]")
    p.add_argument("--json", help="write the estimates as JSON")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from imucal.calibration.frozen import load_calibration
    from imucal.data.load import load_recording
    from imucal.analysis.noise import allan_deviation, estimate
    from imucal.files.output import check_outputs, write_json_atomic
    from imucal.data.static import detect_static

    cfg = options.run_config(args, args.config)
    check_outputs([args.config, options.data_path(cfg), args.calibration], [args.json])
    rec = load_recording(cfg.data, cfg.base_dir)
    y, unit, what = rec.raw, rec.unit, "the whole log"
    iv = detect_static(rec.t, rec.raw)
    if iv.n and int(iv.n_samples.max()) < 0.9 * rec.n:  # a calibration log: its longest still interval
        k = int(np.argmax(iv.n_samples))
        y = rec.raw[iv.start[k]:iv.end[k]]
        what = f"the longest still interval, {iv.t_start[k]:.1f}..{iv.t_end[k]:.1f} s"
    if args.calibration:
        cal = load_calibration(args.calibration)
        y, unit = cal.apply(y), "m/s^2"
    curve = allan_deviation(y, rec.sample_rate, source=rec.source)
    est = [estimate(curve, j) for j in range(3)]
    print(f"Allan deviation of {what} ({y.shape[0]} samples, {rec.sample_rate:.4g} Hz), unit {unit}")
    print(f"{'axis':<5} {'white density':>16} {'bias instability':>18} {'random walk':>16}")
    def cell(v: float, rel: float) -> str:
        return f"{v:10.4g} +-{100 * rel:3.0f}%" if np.isfinite(v) else f"{'n/a':>16}"

    for a, e in zip("xyz", est):
        print(f"{a:<5} {cell(e.white_density, e.white_rel_err)} {cell(e.bias_instability, e.bias_instability_rel_err)}"
              f"  {cell(e.random_walk, e.random_walk_rel_err)}")
    if not all(np.isfinite(e.random_walk) for e in est):
        print("random walk n/a: no +1/2 slope in the curve (the still log is too short; record longer)")
    print(f"units: white density {unit}/sqrt(Hz), bias instability {unit}, random walk {unit}/s/sqrt(Hz)")
    out = {"unit": unit, "source": rec.source, "segment": what, "rate_hz": rec.sample_rate,
           "axes": {a: {k: (v if np.isfinite(v) else None) for k, v in e.__dict__.items()}
                    for a, e in zip("xyz", est)},
           "allan": {"tau_s": curve.tau.tolist(), "adev": curve.adev.tolist()}}
    if unit == "m/s^2":  # Kalibr's imu.yaml: the worst axis, as Kalibr takes one number per sensor
        rw = [e.random_walk for e in est if np.isfinite(e.random_walk)]
        out["kalibr"] = {"accelerometer_noise_density": max(e.white_density for e in est),
                         "accelerometer_random_walk": max(rw) if len(rw) == 3 else None,
                         "update_rate": rec.sample_rate}
        print("kalibr imu.yaml: " + ", ".join(f"{k}: {'n/a' if v is None else f'{v:.4g}'}"
                                              for k, v in out["kalibr"].items()))
    if args.json:
        write_json_atomic(args.json, out)
        print(f"wrote {args.json}")
    return 0
