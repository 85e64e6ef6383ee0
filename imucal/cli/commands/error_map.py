"""``imucal error-map``: the paper's Fig. 3 (histogram) and Fig. 4 (3-D domains) for given angles."""
from __future__ import annotations

import argparse


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "error-map", help="relative error over a box of accelerations: histogram and 3-D domains",
        description="Sample [-range, range]^3 uniformly (seeded), evaluate |a_nonorth - a_orth| / "
                    "a_nonorth for the given angles, and draw the paper's Fig. 3 and Fig. 4.")
    p.add_argument("--angles", type=float, nargs=3, required=True, metavar=("PHI", "PSI", "THETA"),
                   help="axis angles [rad], e.g. the paper's 1.53938 1.60221 1.60221")
    p.add_argument("--range", type=float, default=20.0, help="box half-width [m/s^2] (default 20)")
    p.add_argument("--out", required=True, metavar="DIR", help="output directory")
    p.add_argument("--samples", type=int, default=1_000_000, help="samples (default 1e6)")
    p.add_argument("--seed", type=int, default=0, help="sampling seed (default 0)")
    p.add_argument("--levels", type=float, nargs="+", default=[1.4, 1.6], metavar="PCT",
                   help="domain levels [%%] (default 1.4 1.6)")
    p.add_argument("--grid", type=int, default=16, help="voxels per axis in the domain plot (default 16)")
    p.add_argument("--bins", type=int, default=200, help="histogram bins (default 200)")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from imucal.analysis.error_map import compute_error_map, plot_domains, plot_histogram
    from imucal.errors import ImucalError
    from imucal.files.output import OutputSet

    if not 2 <= args.grid <= 40:
        raise ImucalError(f"grid {args.grid} must be between 2 and 40", field="--grid",
                          fix="give --grid a whole number from 2 to 40 (voxels per axis)")
    if not 5 <= args.bins <= 2000:
        raise ImucalError(f"bins {args.bins} must be between 5 and 2000", field="--bins",
                          fix="give --bins a whole number from 5 to 2000")
    emap = compute_error_map(args.angles, args.range, args.samples, args.seed,
                             [lv / 100 for lv in args.levels])
    out = Path(args.out)
    files = {"histogram": out / "relative_error_histogram.png",
             "domains": out / "relative_error_domains.png", "summary": out / "error_map.json"}
    summary = emap.to_dict(args.bins)
    summary["files"] = {k: v.name for k, v in files.items()}
    with OutputSet() as o:
        o.call(files["histogram"], lambda p: plot_histogram(emap, str(p), args.bins))
        o.call(files["domains"], lambda p: plot_domains(emap, str(p), args.grid))
        o.json(files["summary"], summary)
    print(f"relative error over [-{args.range:g}, {args.range:g}]^3 m/s^2, {summary['samples']} samples "
          f"(seed {args.seed}): max {100 * summary['sample_max']:.4f} % (bound "
          f"{100 * summary['bound']:.4f} %), jump at {100 * summary['jump_at']:.4f} %")
    for k, v in summary["domains"].items():
        print(f"  share with error {k[:2]} {100 * float(k[2:]):g} %: {100 * v:.1f} %")
    for v in files.values():
        print(f"wrote {v}")
    return 0
