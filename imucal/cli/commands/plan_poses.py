"""`imucal plan-poses --n N`: orientations that maximise the information on the 9 parameters.

Also scores a given plan (`--evaluate PLAN.json`) or a named scheme (`--scheme edges`), and
refuses plans whose gravity directions cannot determine the parameters.
"""
from __future__ import annotations

import argparse
import math


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("plan-poses", help="plan the static orientations of a calibration (optimal design)",
                       description="Plan N still orientations that maximise the Fisher information on the "
                                   "model's parameters (D: det, A: summed variance, E: worst direction), "
                                   "with the predicted standard error of each parameter, compared with the "
                                   "common cube schemes and random poses.")
    p.add_argument("--n", type=int, help="number of orientations to plan (>= 9; >= 6 with --fix-angles)")
    p.add_argument("--criterion", choices=("D", "A", "E"), default="D",
                   help="D: max det F (default); A: min summed variance; E: max smallest eigenvalue")
    p.add_argument("--noise", type=float, default=None,
                   help="noise of |a| - g per interval mean [m/s^2] (default 0.002: MEMS, 4 s holds)")
    p.add_argument("--fix-angles", action="store_true", help="plan for the 6-parameter model (angles at 90 deg)")
    p.add_argument("--seed", type=int, default=0, help="seed of the multi-start (default 0)")
    p.add_argument("--evaluate", metavar="PLAN.json", help="score this plan (JSON with 'poses') instead of planning")
    p.add_argument("--scheme", help="score a named scheme: faces, edges, corners, faces+edges, cube-24, "
                                    "wedge-24, cube-26")
    p.add_argument("--no-compare", action="store_true", help="skip the comparison with common schemes")
    p.add_argument("--json", metavar="OUT", help="write the plan (poses, instructions, predicted std, comparison) "
                                                 "as JSON")
    p.add_argument("--plot", metavar="PNG", help="draw the board in every pose (with its instruction) into this PNG")
    p.add_argument("--revisit", action="store_true",
                   help="for `imucal discover`: hold every pose twice, the second pass in reverse order "
                        "(the hold order is printed and written to the JSON as hold_order)")
    p.set_defaults(run=run)


def hold_order(n: int, revisit: bool) -> list[int]:
    """Pose numbers (1-based) in the order to hold them: each once, or with ``revisit`` the plan and
    then the plan reversed. A term in time or temperature is seen only by poses that come back at
    another time or temperature (docs/discover.md, "Plan the holds for discovery")."""
    once = list(range(1, n + 1))
    return once + once[::-1] if revisit else once


def _units(name: str) -> tuple[float, str]:
    """Display factor and unit for the ideal SI sensor the design is evaluated at."""
    if name.startswith("s"):
        return 1.0, "m/s^2"
    if name.startswith("b"):
        return 1e6, "ppm"
    return 1e3, "mrad"


#: What each named scheme is, in words (imucal.analysis.design.SCHEMES).
SCHEME_WORDS = {"faces": "the 6 cube faces", "corners": "the 8 cube corners", "edges": "the 12 cube edges",
                "faces+edges": "the 6 cube faces and 12 edges", "cube-24": "the 24 cube positions",
                "wedge-24": "the 24 positions on a wedge", "cube-26": "the 26 cube directions"}


def efficiency_line(design, eff: float, best) -> str:
    """``design``'s efficiency against the best plan of as many poses (imucal.analysis.design.against_optimum)."""
    name = SCHEME_WORDS.get(design.label, design.label or "this plan")
    cmd = (f"imucal plan-poses --n {design.n}" + (" --fix-angles" if len(design.free) == 6 else "")
           + (f" --criterion {design.criterion}" if design.criterion != "D" else ""))
    if best is design:
        return (f"[[Efficiency]] {name}: as good as the best {design.n}-pose plan found "
                f"(criterion {design.criterion}: {cmd} finds none better)")
    return (f"[[Efficiency]] {name}: {100 * eff:.1f} % efficient against the best {design.n}-pose plan found "
            f"(criterion {design.criterion}, {cmd}): {1 / eff:.3g} times the recordings to match it")


def format_design(design, comparison=None) -> str:

    from imucal.analysis.design import efficiency
    from imucal.analysis.pose_instructions import instructions

    L = []
    d = design
    what = {"D": "log det F, larger is better", "A": "trace F^-1, smaller is better",
            "E": "smallest eigenvalue of F, larger is better"}[d.criterion]
    L.append(f"[[Pose plan]] {d.label or 'plan'}: {d.n} orientations ({d.n_distinct} distinct), "
             f"{len(d.free)} parameters, criterion {d.criterion}")
    L.append("    up direction in the sensor frame (the reading a/|a|, unit vector), and how to set the board down")
    for k, (u, inst) in enumerate(zip(d.directions, instructions(d.directions))):
        L.append(f"    {k + 1:3d}  {u[0]:+.4f} {u[1]:+.4f} {u[2]:+.4f}   {inst.text}")
    L.append(f"[[Predicted standard errors]] noise {d.noise:g} m/s^2 per interval mean, ideal sensor "
             "(s in m/s^2, b relative)")
    for n, v in d.std.items():
        f, unit = _units(n)
        L.append(f"    {n:<6} +/- {v * f:.4g} {unit}")
    L.append(f"    criterion {d.criterion} ({what}; F for unit noise, parameters in m/s^2-equivalents) = {d.value:.6g}")
    if comparison is not None:
        L.append(f"[[Comparison at N = {d.n}]]  criterion {d.criterion}"
                 + ("; D-efficiency = (det F / det F_planned)^(1/p)" if d.criterion == "D" else ""))
        rows = [(d.label, d)] + [(o.label, o) for o in comparison.others if o.label != d.label]
        for label, o in rows:
            eff = f"   D-eff {o.d_efficiency(d):.4f}" if d.criterion == "D" else ""
            L.append(f"    {label:<18} {o.value:12.6g}   max std ratio {max(o.std[k] / d.std[k] for k in d.std):.3f}{eff}")
        L.append(f"    {'random (median)':<18} {comparison.random_median:12.6g}   ({comparison.n_random} sets)")
        L.append(f"    {'random (best)':<18} {comparison.random_best:12.6g}")
        if not math.isfinite(comparison.random_median):
            L.append("    (some random sets leave parameters undetermined)")
        named = [o for o in comparison.others if o.label in SCHEME_WORDS and o.label != d.label]
        if named and d.label not in SCHEME_WORDS:
            L.append("[[Efficiency]] against this plan: " + "; ".join(
                f"{SCHEME_WORDS[o.label]} {100 * efficiency(o, d):.1f} %" for o in named))
    return "\n".join(L)


def run(args: argparse.Namespace) -> int:
    from imucal.report.progress import progress
    from imucal.analysis.design import (BASE_NAMES, DEFAULT_NOISE, SIX_NAMES, against_optimum, compare, evaluate,
                                        optimal_design, scheme_directions)
    from imucal.errors import ImucalError
    from imucal.analysis.plan_file import read_plan
    from imucal.analysis.pose_instructions import instructions
    from imucal.files.output import OutputSet, check_outputs

    from imucal.config.limits import check_seed

    check_seed(args.seed, "--seed")
    check_outputs([args.evaluate], [args.json, args.plot])
    free = SIX_NAMES if args.fix_angles else BASE_NAMES
    noise = DEFAULT_NOISE if args.noise is None else args.noise
    given = [x for x in (args.n is not None, bool(args.evaluate), bool(args.scheme)) if x]
    if len(given) != 1:
        raise ImucalError("give exactly one of --n, --evaluate, --scheme", field="arguments",
                          fix="e.g. imucal plan-poses --n 12")
    if args.evaluate or args.scheme:
        dirs = read_plan(args.evaluate) if args.evaluate else scheme_directions(args.scheme)
        label = args.evaluate or args.scheme
        design = evaluate(dirs, args.criterion, noise, free=free, label=label)
    else:
        with progress("plan-poses: exchange starts and polish", unit="step") as step:  # on a terminal only
            design = optimal_design(args.n, args.criterion, noise, free=free, seed=args.seed, progress=step)
    comp = None if args.no_compare else compare(design, seed=args.seed)
    print(format_design(design, comp))
    eff = None
    if args.evaluate or args.scheme:  # how near the optimum it comes (the 12 cube edges: 97 %)
        with progress("plan-poses: the best plan of as many poses", unit="step") as step:
            eff, best = against_optimum(design, seed=args.seed, progress=step)
        print(efficiency_line(design, eff, best))
    order = hold_order(design.n, args.revisit)
    if args.revisit:
        print(f"[[Hold order]] every pose twice, the second pass in reverse ({len(order)} holds; for discover): "
              + " ".join(map(str, order)))
    insts = instructions(design.directions)
    with OutputSet([args.evaluate]) as o:
        if args.json:
            obj = design.to_json()
            obj["instructions"] = [inst.numbered(k + 1) for k, inst in enumerate(insts)]
            obj["hold_order"] = order
            if eff is not None:
                obj["efficiency_vs_best_found"] = eff
            if comp is not None:
                obj["comparison"] = [{"label": other.label, "criterion_value": other.value,
                                      "log_det_fisher": other.log_det_fisher, "predicted_std": other.std}
                                     for other in comp.others]
                obj["random"] = {"n_sets": comp.n_random, "median": comp.random_median, "best": comp.random_best}
            o.json(args.json, obj)
        if args.plot:
            from imucal.report.figures import plain
            from imucal.report.pose_figures import poses_figure

            o.call(args.plot, lambda p: poses_figure(insts, p, f"Pose plan: {plain(design.label or 'plan')}, "
                                                                f"{design.n} orientations"))
    for f in (args.json, args.plot):
        if f:
            print(f"wrote {f}")
    return 0
