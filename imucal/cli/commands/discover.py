"""`imucal discover --data FILE [--config CONFIG.yaml]`: find the effect the 9-parameter model lacks."""
from __future__ import annotations

import argparse

from imucal.cli.commands import options


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("discover", help="find where the model disagrees with the data, name the effect, add it",
                       description="Fit the paper's 9-parameter model, test the residual of the interval means "
                                   "against their noise (chi-square), and while it disagrees add the candidate "
                                   "effect (temperature, drift, nonlinearity) that is significant by a "
                                   "likelihood-ratio test. A recording that holds still poses over a temperature "
                                   "change (a sweep: one pose spanning 2 degC) takes its temperature terms from each "
                                   "pose's constancy instead (docs/thermal.md). Prints the report; --json, --plot and "
                                   "--out write files (report.html goes into --out DIR, else into --plot DIR).")
    p.add_argument("--config", help="YAML run file (data, static, gravity, fit sections); --data overrides its path")
    options.add_data_options(p)
    options.add_gravity_options(p)
    options.add_model_options(p, mode=False)  # discovery works on interval means
    p.add_argument("--json", help="write the machine-readable summary here")
    p.add_argument("--plot", metavar="DIR", help="write the figures into DIR")
    p.add_argument("--out", metavar="DIR", help="write the final calibration.yaml, report.txt and report.html "
                                                "(figures embedded) into DIR")
    p.add_argument("--candidates", nargs="+", metavar="EFFECT",
                   help="terms to try (default: the whole grammar: bias_/scale_ x temperature, temperature2, "
                        "temperature3, drift, drift2, warmup; scale_nonlinearity, scale_nonlinearity3, "
                        "cross_axis_nonlinearity)")
    p.add_argument("--alpha", type=float, default=1e-3,
                   help="significance level of the noise test and of adding an effect (default 1e-3)")
    p.add_argument("--max-effects", type=int, default=3, help="add at most this many effects (default 3)")
    p.add_argument("--quiet", action="store_true", help="print only the verdict and where the files went")
    p.set_defaults(run=run)


def _config(args: argparse.Namespace):
    from imucal.errors import ImucalError

    if not args.config and not args.data:
        raise ImucalError("nothing to analyse", field="arguments", fix="give --data RECORDING (and optionally --config)")
    return options.run_config(args, args.config)


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from imucal.analysis.discover import DiscoverSettings, discover
    from imucal.model.effects import EFFECTS
    from imucal.files.output import OutputSet, check_outputs
    from imucal.report.discover_figures import FIGURES
    from imucal.report.discover_text import discovery_json, discovery_report, verdict_text
    from imucal.report.html import discovery_html, render_png
    from imucal.report.progress import progress

    cfg = _config(args)
    inputs = [args.config, options.data_path(cfg)]
    plot_names = [Path(args.plot) / n for n in FIGURES] if args.plot else []
    outs = [Path(args.out) / "calibration.yaml", Path(args.out) / "report.txt"] if args.out else []
    page_dir = args.out or args.plot  # report.html beside the other outputs
    page_path = Path(page_dir) / "report.html" if page_dir else None
    check_outputs(inputs, [args.json, *plot_names, *outs, page_path])
    with options.named_options({"alpha_noise": "--alpha", "alpha_effect": "--alpha", "alpha_scan": "--alpha",
                                "settings": "--max-effects", "candidates": "--candidates"}):
        settings = DiscoverSettings(candidates=tuple(args.candidates or EFFECTS), alpha_noise=args.alpha,
                                    alpha_effect=args.alpha, alpha_scan=args.alpha / 10, max_effects=args.max_effects)
    with progress("discover", unit="fit") as step:  # a bar on a terminal only
        result = discover(cfg, settings, step)
    text = discovery_report(result)
    written = []
    pngs = {name: render_png(fn, result) for name, fn in FIGURES.items()} if page_dir else {}
    with OutputSet(inputs) as o:
        if args.json:
            o.json(args.json, discovery_json(result))
            written.append(args.json)
        if args.plot:
            for name, png in pngs.items():
                o.bytes(Path(args.plot) / name, png)
            written.append(f"{args.plot}/ ({len(FIGURES)} figures)")
        if args.out:
            from imucal.report.text import fit_report

            out = Path(args.out)
            o.call(out / "calibration.yaml", result.calibration_run.calibration.save)
            o.text(out / "report.txt", fit_report(result.calibration_run) + "\n" + text)
            written.append(f"{out / 'calibration.yaml'}, {out / 'report.txt'}")
        if page_path is not None:
            o.text(page_path, discovery_html(result, pngs))
            written.append(str(page_path))
    print(f"verdict: {verdict_text(result.verdict)}" if args.quiet else text.rstrip())
    if written:
        print("wrote " + ", ".join(written))
    return 0
