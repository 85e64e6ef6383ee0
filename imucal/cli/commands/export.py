"""`imucal export CAL --format FMT --out FILE`: the calibration in a peer tool's format."""
from __future__ import annotations

import argparse

EXPORT_FORMATS = ("imutk", "madlab", "matrix")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("export", help="write a calibration in another tool's format (imu_tk, mad-lab, matrix)",
                       description="imutk: imu_tk's .calib; madlab: mad-lab-fau/imucal's Ferraris JSON; "
                                   "matrix: JSON (or CSV by the file ending) of a = matrix raw + offset. "
                                   "Exact for the paper's model; calibrations with effects are refused.")
    p.add_argument("calibration", help="calibration.yaml written by `imucal calibrate`")
    p.add_argument("--format", required=True, choices=EXPORT_FORMATS, help="target format")
    p.add_argument("--out", required=True, help="output file")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from imucal.calibration.frozen import load_calibration
    from imucal.export.formats import FORMATS, export_text
    from imucal.files.output import check_outputs, write_text_atomic

    check_outputs([args.calibration], [args.out])
    cal = load_calibration(args.calibration)
    text = export_text(cal, args.format, str(args.out))
    write_text_atomic(args.out, text)
    print(f"wrote {args.out}: {FORMATS[args.format][1]}")
    return 0
