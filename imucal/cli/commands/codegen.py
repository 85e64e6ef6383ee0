"""`imucal codegen CALIBRATION --out DIR`: C code (NAME.h, NAME.c) for firmware, or with
`--layout arduino` an Arduino / PlatformIO library folder DIR/NAME around them."""
from __future__ import annotations

import argparse


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("codegen", help="generate C code that applies a calibration on a microcontroller",
                       description="Write DIR/NAME.h and DIR/NAME.c: NAME_apply (this calibration baked "
                                   "in), NAME_prepare and NAME_apply_coeffs (parameters at run time) and "
                                   "batch forms; 6 multiplies and 6 additions per sample. With a gyroscope part, also "
                                   "NAME_apply_gyro and NAME_apply_imu (rad/s, the accelerometer's frame). "
                                   "With --layout arduino: the library folder DIR/NAME (library.properties, "
                                   "library.json, src/, examples/apply/apply.ino). See docs/codegen.md.")
    p.add_argument("calibration", help="calibration.yaml written by `imucal calibrate`")
    p.add_argument("--out", required=True, help="output directory for NAME.h and NAME.c")
    p.add_argument("--precision", choices=("float", "double"), default="float",
                   help="C type of inputs, outputs and constants (default: float)")
    p.add_argument("--prefix", default="imucal",
                   help="NAME: file names and prefix of every C symbol; a C identifier (default: imucal)")
    p.add_argument("--layout", default="flat",
                   help="flat: DIR/NAME.h and DIR/NAME.c (default); arduino: an Arduino / PlatformIO "
                        "library DIR/NAME with an example sketch")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from imucal.calibration.frozen import load_calibration
    from imucal.export.arduino import arduino_paths, check_layout, write_arduino
    from imucal.export.codegen import check_prefix, write_c

    from pathlib import Path

    from imucal.files.output import check_outputs

    check_prefix(args.prefix)  # before reading anything: a bad prefix or layout is refused outright
    arduino = check_layout(args.layout) == "arduino"
    out = Path(args.out)
    if out.is_dir() or not out.exists():  # a file here is refused by write_c, naming --out
        check_outputs([args.calibration], arduino_paths(out, args.prefix) if arduino else
                      [out / f"{args.prefix}.h", out / f"{args.prefix}.c"])
    cal = load_calibration(args.calibration)
    write = write_arduino if arduino else write_c
    paths = write(cal, args.out, prefix=args.prefix, precision=args.precision, source=args.calibration)
    print(f"wrote {', '.join(str(p) for p in paths)} ({args.precision})")
    return 0
