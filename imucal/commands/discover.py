"""`imucal discover --data FILE [--config CONFIG.yaml]`: find the effect the 9-parameter model lacks."""
from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("discover", help="find where the model disagrees with the data, name the effect, add it",
                       description="Fit the paper's 9-parameter model, test the residual of the interval means "
                                   "against their noise (chi-square), and while it disagrees add the candidate "
                                   "effect (temperature, drift, nonlinearity) that is significant by a "
                                   "likelihood-ratio test. Prints the report; --json, --plot and --out write files.")
    p.add_argument("--data", help="recording (CSV columns t, ax, ay, az, temp; raw counts or m/s^2)")
    p.add_argument("--config", help="YAML run file (data, static, gravity, fit sections); --data overrides its path")
    p.add_argument("--json", help="write the machine-readable summary here")
    p.add_argument("--plot", metavar="DIR", help="write the figures into DIR")
    p.add_argument("--out", metavar="DIR", help="write the final calibration.yaml and report.txt into DIR")
    p.add_argument("--gravity", type=float, help="local gravity [m/s^2] (default: config, else 9.80665)")
    p.add_argument("--unit", help="unit of the raw readings (label only, e.g. raw or m/s^2)")
    p.add_argument("--sample-rate", type=float, help="sample rate [Hz] when the file has no time column")
    p.add_argument("--candidates", nargs="+", metavar="EFFECT",
                   help="effects to try (default: all of bias_temperature, scale_temperature, bias_drift, "
                        "scale_drift, scale_nonlinearity)")
    p.add_argument("--alpha", type=float, default=1e-3,
                   help="significance level of the noise test and of adding an effect (default 1e-3)")
    p.add_argument("--max-effects", type=int, default=3, help="add at most this many effects (default 3)")
    p.add_argument("--quiet", action="store_true", help="print only the verdict and where the files went")
    p.set_defaults(run=run)


def _config(args: argparse.Namespace):
    import dataclasses

    from ..config import GravitySpec, config_from_dict, load_config
    from ..errors import ImucalError

    if not args.config and not args.data:
        raise ImucalError("nothing to analyse", field="arguments", fix="give --data RECORDING (and optionally --config)")
    if args.config:
        cfg = load_config(args.config)
        if args.data:
            cfg = dataclasses.replace(cfg, data=dataclasses.replace(cfg.data, path=args.data), source=None)
    else:
        cfg = config_from_dict({"data": {"path": args.data}}, None)
    data = cfg.data
    if args.sample_rate is not None or args.unit is not None:
        data = dataclasses.replace(data, **{k: v for k, v in (("sample_rate", args.sample_rate),
                                                            ("unit", args.unit)) if v is not None})
    grav = cfg.gravity if args.gravity is None else GravitySpec(value=args.gravity)
    return dataclasses.replace(cfg, data=data, gravity=grav)


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from ..discover import DiscoverSettings, discover
    from ..effects import EFFECTS
    from ..output import OutputSet

    cfg = _config(args)
    settings = DiscoverSettings(candidates=tuple(args.candidates or EFFECTS), alpha_noise=args.alpha,
                                alpha_effect=args.alpha, max_effects=args.max_effects)
    result = discover(cfg, settings)
    text = result.report()
    written = []
    with OutputSet() as o:
        if args.json:
            o.json(args.json, result.to_json())
            written.append(args.json)
        if args.plot:
            from ..discover_plots import FIGURES

            for name, fn in FIGURES.items():
                o.call(Path(args.plot) / name, lambda p, fn=fn: fn(result, p))
            written.append(f"{args.plot}/ ({len(FIGURES)} figures)")
        if args.out:
            from ..report import fit_report

            out = Path(args.out)
            o.call(out / "calibration.yaml", result.final.calibration.save)
            o.text(out / "report.txt", fit_report(result.final) + "\n" + text)
            written.append(f"{out / 'calibration.yaml'}, {out / 'report.txt'}")
    print(f"verdict: {result.verdict}" if args.quiet else text.rstrip())
    if written:
        print("wrote " + ", ".join(written))
    return 0
