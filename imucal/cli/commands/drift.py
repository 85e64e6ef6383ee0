"""``imucal drift``: position error of dead reckoning with an acceleration error, e t^2 / 2."""
from __future__ import annotations

import argparse
import sys


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "drift", help="position drift from the worst-case, a given, or a calibration's errors",
        description="Double-integrate a constant acceleration error: p(t) = e t^2 / 2. Always "
                    "reports the certified worst case (problem 1); --error adds a given error; "
                    "--calibration adds raw / angles ignored / fully calibrated.")
    src = p.add_mutually_exclusive_group()
    src.add_argument("--calibration", metavar="FILE", help="calibration YAML")
    src.add_argument("--error", type=float, metavar="E", help="a constant acceleration error [m/s^2]")
    p.add_argument("--recording", metavar="FILE",
                   help="with --calibration: evaluate the treatments on this recording's static intervals")
    p.add_argument("--duration", type=float, default=60.0, metavar="S",
                   help="dead-reckoning time [s] (default 60)")
    p.add_argument("--tolerance", type=float, default=None,
                   help="worst case: angles in pi/2 (1 +- tol) (default 0.02)")
    p.add_argument("--gravity", type=float, default=None, metavar="G",
                   help="g [m/s^2] (default: standard gravity, or the calibration's)")
    p.add_argument("--json", metavar="OUT", help="write the table as JSON")
    p.add_argument("--plot", metavar="PNG", help="draw position error against time")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    import math

    from imucal.config.run import check_gravity
    from imucal.constants import DEFAULT_ANGLE_TOL, STANDARD_GRAVITY
    from imucal.analysis.drift import DriftCase, DriftReport, calibration_cases, plot_drift, table_times
    from imucal.errors import ImucalError
    from imucal.files.output import OutputSet, check_outputs
    from imucal.analysis.worst_case import AngleBox, CertificateError, max_abs_error

    times = table_times(args.duration)
    check_outputs([args.calibration, args.recording], [args.json, args.plot])
    if args.recording and not args.calibration:
        raise ImucalError("--recording needs --calibration", field="recording",
                          fix="pass the calibration to evaluate on the recording")
    if args.error is not None and not (math.isfinite(args.error) and args.error >= 0):
        raise ImucalError(f"error {args.error:g} m/s^2 must be a non-negative number", field="error",
                          fix="give the magnitude of the acceleration error")
    cal = None
    if args.calibration:
        from imucal.calibration.frozen import load_calibration

        cal = load_calibration(args.calibration)
    if args.gravity is not None:  # as calibrate's: 1e26 or 1e-308 m/s^2 was integrated
        check_gravity(args.gravity, "--gravity")
    gravity = args.gravity if args.gravity is not None else (cal.gravity if cal else STANDARD_GRAVITY)
    tol = DEFAULT_ANGLE_TOL if args.tolerance is None else args.tolerance
    box = AngleBox.from_tolerance(tol)
    try:
        worst = max_abs_error(box, gravity)
    except CertificateError as exc:
        sys.stderr.write(f"imucal: error: certificate failed: {exc}\n")
        return 1
    cases = [DriftCase("worst case", worst.value,
                       f"certified max of problem 1, angles in pi/2 (1 +- {tol:g})")]
    source: dict = {"tolerance": tol}
    if args.error is not None:
        cases.append(DriftCase("given", args.error, "--error"))
    if cal is not None:
        rec = None
        if args.recording:
            from imucal.data.load import load_recording

            rec = load_recording(args.recording)
            source["recording"] = args.recording
        cases += calibration_cases(cal, gravity, rec)
        source["calibration"] = args.calibration
    rep = DriftReport(tuple(cases), times, gravity, source)
    print(rep.table())
    for c in cases:
        print(f"  {c.name}: {c.statistic}" + (f" (max {c.error_max:.4g} m/s^2)" if c.error_max else ""))
    with OutputSet([args.calibration, args.recording]) as o:
        if args.json:
            o.json(args.json, rep.to_dict())
        if args.plot:
            o.call(args.plot, lambda p: plot_drift(rep, str(p), args.duration))
    return 0
