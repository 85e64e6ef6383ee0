"""`imucal simulate CONFIG.yaml --out FILE.csv`: a seeded simulated recording with known truth."""
from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("simulate", help="simulate a multi-pose recording (sensor, poses, noise, temperature, effects)",
                       description="Simulate a static multi-pose recording from a YAML description (see "
                                   "configs/simulate_example.yaml): the paper's sensor model plus effects, "
                                   "pose plan with moving transitions, white noise, quantisation, temperature. "
                                   "Writes CSV columns t, ax, ay, az (and temp).")
    p.add_argument("config", help="simulation YAML")
    p.add_argument("--out", required=True, help="output CSV (with --fleet: output folder)")
    p.add_argument("--seed", type=int, help="override the config's seed")
    p.add_argument("--truth", help="also write the true parameters (JSON)")
    f = p.add_argument_group("fleet", "N units around the config's sensor: OUT/recordings/<unit>.csv, OUT/truth.csv and "
                                      "OUT/manifest.yaml for `imucal batch` (docs/fleet.md)")
    f.add_argument("--fleet", type=int, metavar="N", help="simulate N units instead of one recording")
    f.add_argument("--defective", type=int, default=0, metavar="K",
                   help="K units with a bias or angle far outside the tolerances")
    f.add_argument("--corrupt", type=int, default=0, metavar="M", help="M units with a damaged file")
    f.add_argument("--spread", metavar="SPEC",
                   help="unit-to-unit standard deviations and defect sizes, e.g. bias=0.05,scale=0.002,angle=0.05 "
                        "(m/s^2, relative, deg; also defect_bias, defect_angle)")
    p.set_defaults(run=run)


def _fleet(args: argparse.Namespace, cfg) -> int:
    from pathlib import Path

    from imucal.errors import ImucalError
    from imucal.fleet.population import MANIFEST_FILE, TRUTH_FILE, Population, draw_fleet, parse_spread, write_fleet
    from imucal.report.progress import progress

    if args.truth:
        raise ImucalError("--truth is for one recording; a fleet writes OUT/truth.csv", field="--truth",
                          fix="drop --truth")
    units = draw_fleet(cfg, args.fleet, args.defective, args.corrupt,
                       parse_spread(args.spread) if args.spread else Population())
    with progress("simulate --fleet", total=len(units), unit="unit", leave=True) as step:  # on a terminal only
        manifest = write_fleet(units, Path(args.out), [args.config], progress=step)
    print(f"wrote {len(units)} units ({args.defective} defective, {args.corrupt} corrupt) to {args.out}: "
          f"recordings/<unit>.csv, {TRUTH_FILE}, {MANIFEST_FILE}; run: imucal batch {manifest} --out RESULTS")
    return 0


def run(args: argparse.Namespace) -> int:
    import dataclasses

    from imucal.config.limits import check_seed
    from imucal.files.output import OutputSet, check_outputs
    from imucal.analysis.simulate import load_simulation_config

    if args.fleet is None and (args.defective or args.corrupt or args.spread):
        from imucal.errors import ImucalError

        raise ImucalError("--defective, --corrupt and --spread need --fleet N", field="--fleet",
                          fix="add --fleet N (units), or drop them")
    if args.fleet is None:
        check_outputs([args.config], [args.out, args.truth])
    cfg = load_simulation_config(args.config)
    if args.seed is not None:
        check_seed(args.seed, "--seed")
        cfg = dataclasses.replace(cfg, seed=args.seed)
    if args.fleet is not None:
        return _fleet(args, cfg)
    sim = cfg.run()
    with OutputSet([args.config]) as o:
        o.text(args.out, sim.to_csv_text())
        if args.truth:
            o.json(args.truth, {
                "format": "imucal-simulation-truth", "format_version": 1, "seed": cfg.seed,
                "gravity": cfg.gravity, "unit": cfg.sensor.unit, "parameters": cfg.sensor.values(),
                "effects": {n: dict(c) for n, c in cfg.sensor.effects.items()},
                "noise": list(cfg.sensor.noise), "quantum": cfg.sensor.quantum,
                "random_walk": list(cfg.sensor.random_walk), "visit_offset": list(cfg.sensor.visit_offset),
                "poses": len(cfg.plan.directions), "hold_bounds": sim.hold_bounds.tolist()})
    temp = f", temp {sim.temp.min():.1f}..{sim.temp.max():.1f} degC" if sim.temp is not None else ", no temp column"
    print(f"wrote {sim.t.size} samples ({sim.t[-1]:.1f} s, {len(cfg.plan.directions)} poses, unit {cfg.sensor.unit}"
          f"{temp}) to {args.out}" + (f" and the truth to {args.truth}" if args.truth else ""))
    return 0
