"""`imucal batch MANIFEST --out DIR`: calibrate a fleet of units, resumably, and report on it."""
from __future__ import annotations

import argparse
import os


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("batch", help="calibrate a fleet of units listed in a manifest (processes or a Dask cluster)",
                       description="Calibrate every unit of a manifest (YAML or CSV, or a folder of recordings) "
                                   "as `imucal calibrate` would, each into DIR/<unit id>/, then write the fleet "
                                   "report DIR/fleet.csv (and fleet.parquet with pyarrow), DIR/fleet.txt and "
                                   "histograms DIR/fleet_*.png. A rerun skips units already done with the same "
                                   "inputs and settings. See docs/fleet.md.")
    p.add_argument("manifest", help="fleet manifest (YAML or CSV) or a folder of recordings (*.csv)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder: DIR/<unit id>/ and DIR/fleet.*")
    p.add_argument("--config", metavar="RUN.yaml",
                   help="shared settings: an `imucal calibrate` run file (its data.path is not used)")
    p.add_argument("--workers", type=int, metavar="N", help="worker processes (default: one per CPU)")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="run on a dask.distributed cluster, e.g. tcp://host:8786 (the fleet extra: dask[distributed]); "
                        "every worker must see the recordings and DIR at the same paths")
    p.add_argument("--no-figures", action="store_true",
                   help="skip the fleet histograms (unit figures follow the settings' output.figures)")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    import sys
    from pathlib import Path

    from imucal.config.limits import check_count
    from imucal.errors import EXIT_INTERRUPTED, ImucalError, interruption_line
    from imucal.files.inputs import same_file
    from imucal.files.output import check_outputs

    if args.workers is not None:
        check_count(args.workers, "--workers", 1, 4096)
        if args.scheduler is not None:
            raise ImucalError("--workers and --scheduler both given", field="--workers",
                              fix="the cluster sets the workers: drop --workers")
    out = Path(args.out)
    inputs = [args.manifest, args.config]
    if os.path.isdir(args.manifest) and same_file(args.manifest, out):  # False, not OSError, for bad names
        raise ImucalError("is the folder of recordings", file=args.out, field="--out",
                          fix="write the results to another folder (its fleet.csv would become a unit)")
    if args.scheduler is None:  # before the imports below: the workers' server loads meanwhile (docs/fleet.md)
        from imucal.fleet.workers import start_workers_early

        start_workers_early()
    from imucal.fleet.manifest import load_manifest
    from imucal.fleet.report import (REPORT_CSV, REPORT_HTML, REPORT_PARQUET, REPORT_TEXT, fleet_table, load_writers,
                                     summary_text, write_report)
    from imucal.fleet.run import executor, progress_bar, run_units

    check_outputs(inputs, [out / REPORT_CSV, out / REPORT_TEXT, out / REPORT_PARQUET, out / REPORT_HTML])

    manifest = load_manifest(args.manifest, args.config)
    n = len(manifest.units)
    writers = load_writers(figures=not args.no_figures)  # beside the units (fixed cost: docs/fleet.md)
    try:  # leaving the pool's block stops its workers, on an interrupt too (imucal.fleet.run)
        with executor(args.workers, args.scheduler) as pool, progress_bar(n) as step:
            records = run_units(manifest, out, pool, step)
        table = fleet_table(records, manifest.tolerances)
        writers.join()
        written = write_report(table, out, [p for p in inputs if p is not None], figures=not args.no_figures)
    except KeyboardInterrupt as exc:  # Ctrl-C, SIGTERM, SIGHUP, ...: one line, EXIT_INTERRUPTED
        sys.stderr.write(interruption_line(exc, f"batch stopped: finished units are kept in {out}; "
                                                "rerun the same command to resume") + "\n")
        return EXIT_INTERRUPTED
    finally:
        writers.join()  # (a thread that only loads modules: it ends on its own)
    print(summary_text(table), end="")
    print(f"wrote {n} unit folders and " + ", ".join(str(p) for p in written[:3])
          + (f" and {len(written) - 3} histograms" if len(written) > 3 else ""))
    return 0
