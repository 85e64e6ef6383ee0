"""``imucal worst-case``: the paper's two extremal problems (Section 4), certified."""
from __future__ import annotations

import argparse
import sys


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "worst-case", help="largest error of ignoring non-orthogonality (IPOPT, certified)",
        description="Problem 1: max |a_nonorth - a_orth| at a_nonorth = g; Problem 2: max relative "
                    "error over |m_i| <= range; and the exact-vs-linearised model difference. "
                    "Each NLP answer is checked against a closed-form certificate.")
    src = p.add_mutually_exclusive_group()
    src.add_argument("--tolerance", type=float, default=None,
                     help="angles in pi/2 (1 +- tol) (default 0.02, the paper's 2 %%)")
    src.add_argument("--calibration", metavar="FILE",
                     help="fix the angles at this calibration's estimates instead")
    p.add_argument("--widen", type=float, default=0.0, metavar="K",
                   help="with --calibration: angles +- K standard errors (default 0: fixed)")
    p.add_argument("--gravity", type=float, default=None, metavar="G",
                   help="g [m/s^2] (default: standard gravity, or the calibration's)")
    p.add_argument("--range-g", type=float, default=16.0, metavar="R",
                   help="sensor full scale in g: box |m_i| <= R g (default 16)")
    p.add_argument("--starts", type=int, default=16, help="multi-start count (default 16)")
    p.add_argument("--seed", type=int, default=0, help="multi-start seed (default 0)")
    p.add_argument("--json", metavar="OUT", help="write the results as JSON")
    p.set_defaults(run=run)


def _line(label: str, e, unit_fmt) -> list[str]:
    c = e.certificate
    return [f"{label}: {unit_fmt(e.value)}  (certificate {unit_fmt(c.bound)}, {c.kind}; "
            f"difference {c.gap:.2e})",
            "    at m = (" + ", ".join(f"{x:.6g}" for x in e.acceleration) + ") m/s^2, angles = ("
            + ", ".join(f"{x:.6g}" for x in e.angles) + f") rad; {len(e.maximisers)} distinct "
            f"maximiser(s), {e.converged}/{e.starts} starts converged"]


def report(wc) -> str:
    g = wc.gram
    lines = [f"angle box: {wc.box.label}: " + ", ".join(
        f"{n} [{lo:.6g}, {hi:.6g}]" for n, lo, hi in zip(("phi", "psi", "theta"), wc.box.lower, wc.box.upper))
        + " rad",
        f"eigenvalues of G over the box: min {g.lambda_min:.7g}, max {g.lambda_max:.7g} (at vertices)",
        f"g = {wc.gravity:.7g} m/s^2, range {wc.range_g:g} g = {wc.range_g * wc.gravity:.6g} m/s^2, "
        f"multi-start seed {wc.abs_error.seed}"]
    lines += _line("problem 1, max |a_nonorth - a_orth| at a_nonorth = g", wc.abs_error,
                   lambda v: f"{v:.7f} m/s^2")
    lines += _line("problem 2, max |a_nonorth - a_orth| / a_nonorth", wc.rel_error,
                   lambda v: f"{100 * v:.4f} %")
    lines += _line("exact vs linearised model, max |a - a_lin|", wc.linearisation,
                   lambda v: f"{v:.6f} m/s^2")
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    from imucal.config.run import check_gravity
    from imucal.constants import DEFAULT_ANGLE_TOL, STANDARD_GRAVITY
    from imucal.errors import ImucalError
    from imucal.files.output import check_outputs, write_json_atomic
    from imucal.analysis.worst_case import AngleBox, CertificateError, analyse

    check_outputs([args.calibration], [args.json])
    if args.gravity is not None:  # as calibrate's: 1e26 or 1e-308 m/s^2 was analysed
        check_gravity(args.gravity, "--gravity")
    gravity = args.gravity
    source: dict = {}
    if args.calibration:
        from imucal.calibration.frozen import load_calibration

        cal = load_calibration(args.calibration)
        names = ("phi", "psi", "theta")
        box = AngleBox.around([cal.params[n].value for n in names],
                              [cal.std.get(n, float("nan")) for n in names], args.widen,
                              label=f"calibration {args.calibration} +- {args.widen:g} std")
        gravity = cal.gravity if gravity is None else gravity
        source = {"calibration": str(args.calibration), "widen_std": args.widen}
    else:
        if args.widen:
            raise ImucalError("--widen needs --calibration", field="--widen",
                              fix="pass --calibration FILE or drop --widen")
        tol = DEFAULT_ANGLE_TOL if args.tolerance is None else args.tolerance
        box = AngleBox.from_tolerance(tol)
        source = {"tolerance": tol}
    gravity = STANDARD_GRAVITY if gravity is None else gravity
    try:
        wc = analyse(box, gravity, args.range_g, args.starts, args.seed, source)
    except CertificateError as exc:
        sys.stderr.write(f"imucal: error: certificate failed: {exc}\n")
        return 1
    print(report(wc))
    if args.json:
        write_json_atomic(args.json, wc.to_dict())
    return 0
