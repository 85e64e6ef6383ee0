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
    p.add_argument("--out", required=True, help="output CSV")
    p.add_argument("--seed", type=int, help="override the config's seed")
    p.add_argument("--truth", help="also write the true parameters (JSON)")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    import dataclasses

    from imucal.config.limits import check_seed
    from imucal.files.output import OutputSet, check_outputs
    from imucal.analysis.simulate import load_simulation_config

    check_outputs([args.config], [args.out, args.truth])
    cfg = load_simulation_config(args.config)
    if args.seed is not None:
        check_seed(args.seed, "--seed")
        cfg = dataclasses.replace(cfg, seed=args.seed)
    sim = cfg.run()
    with OutputSet([args.config]) as o:
        o.text(args.out, sim.to_csv_text())
        if args.truth:
            o.json(args.truth, {
                "format": "imucal-simulation-truth", "format_version": 1, "seed": cfg.seed,
                "gravity": cfg.gravity, "unit": cfg.sensor.unit, "parameters": cfg.sensor.values(),
                "effects": {n: dict(c) for n, c in cfg.sensor.effects.items()},
                "noise": list(cfg.sensor.noise), "quantum": cfg.sensor.quantum,
                "poses": len(cfg.plan.directions), "hold_bounds": sim.hold_bounds.tolist()})
    temp = f", temp {sim.temp.min():.1f}..{sim.temp.max():.1f} degC" if sim.temp is not None else ", no temp column"
    print(f"wrote {sim.t.size} samples ({sim.t[-1]:.1f} s, {len(cfg.plan.directions)} poses, unit {cfg.sensor.unit}"
          f"{temp}) to {args.out}" + (f" and the truth to {args.truth}" if args.truth else ""))
    return 0
