#!/usr/bin/env python
"""Right by default on real recordings (issue 25): for every real recording in ../shared/data/real, and
any recording or run file you name, the default calibration's RMS of |a| - g on its still poses beside
the uniformly weighted fit's on the same poses, their ratio (target <= 1.02), and whether the bias moved
during the recording (a bias random walk: how far, per axis, in mg). For every recording with a gyroscope,
the static intervals its default fit found not still for the gyro, and the RMS gravity-direction error of
the default gyro fit beside the fit without those intervals (target: no worse) and the fit that takes every
interval as still (before issue 25), all on the same motions (imucal.gyro.check).

    python studies/trust_real.py                     # every real recording -> studies/results/trust_real.md
    python studies/trust_real.py my_run.yaml          # ... and a run file of yours
    python studies/trust_real.py --data log.csv --unit m/s^2 [--sample-rate 100] [--gravity 9.81]

Each recording runs as its run file says (configs/ where one exists), else with the defaults and the
data section below; "default" is that run with fit.weights auto, "uniform" the same run with
fit.weights uniform. A recording imucal refuses is listed with the refusal (it exits 2 on it).
"""
from __future__ import annotations

import argparse
import json
import math
import re
import sys
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
REAL = (ROOT / ".." / "shared" / "data" / "real").resolve()
#: The target: the default calibration fits its still poses no worse than this times the uniform fit.
TARGET_RATIO = 1.02
#: mikoff's logs: acceleration [m/s^2] in columns 0-2, angular rate [rad/s] in columns 3-5, 100 Hz
MIKOFF = {"columns": {"ax": 0, "ay": 1, "az": 2, "gx": 3, "gy": 4, "gz": 5}, "sample_rate": 100, "unit": "m/s^2",
          "gyro_unit": "rad/s"}
#: magnetometer-ckexplorer's acc_log.csv states no rate: it is 160 blocks of 100 samples, one block per
#: orientation, with no samples while the board moved. 25 Hz makes a block a 4 s hold for the default
#: static detector (0.5 s window, 1.5 s minimum); the values do not depend on the rate (no term in time),
#: only a random walk's density would (per sqrt(s) of this assumed clock).
CKEXPLORER_RATE = 25.0


@dataclass(frozen=True)
class Source:
    """One recording: a run file (configs/), or a data section (paths relative to REAL) and gravity."""

    name: str
    config: Path | None = None
    data: dict = field(default_factory=dict)
    gravity: float | None = None  #: [m/s^2]; None: the run file's, else standard gravity
    fit: dict = field(default_factory=dict)
    note: str = ""
    #: data fields added to a run file's (a gyroscope file the run file does not name: path relative to REAL)
    extra: dict = field(default_factory=dict)

    def run_config(self):
        from imucal.config.run import config_from_dict, load_config

        if self.config is not None:
            cfg = load_config(self.config)
            if not self.extra:
                return cfg
            extra = {k: str(REAL / v) if k == "gyro_path" else v for k, v in self.extra.items()}
            return replace(cfg, data=replace(cfg.data, **extra))
        data = {**self.data, "path": str(REAL / self.data["path"]) if not Path(self.data["path"]).is_absolute()
                else self.data["path"]}
        d = {"data": data, "fit": dict(self.fit)}
        if self.gravity is not None:
            d["gravity"] = {"value": self.gravity}
        return config_from_dict(d)


ROS = "ros-imu-getovermassif"
SOURCES = [
    Source("xsens-mti-imutk", ROOT / "configs" / "xsens-mti-imutk.yaml"),
    Source("imucal-ferraris (6-param)", ROOT / "configs" / "imucal-ferraris-6param.yaml",
           note="6 axis-aligned poses: angles held at 90 deg, samples mode (its run file)"),
    Source("mpu6050-tomisuarez", ROOT / "configs" / "mpu6050-tomisuarez.yaml", note="phi held (its run file)"),
    Source("ros-imu data1", data={"path": f"{ROS}/data1/acc_data.txt", "unit": "m/s^2"}, gravity=9.81744),
    *[Source(f"ros-imu data{k}", ROOT / "configs" / f"ros-imu-data{k}.yaml",
             extra={"gyro_path": f"{ROS}/data{k}/gyro_data.txt", "gyro_unit": "rad/s"}) for k in (2, 3, 4)],
    *[Source(f"mpu9150-mikoff imu{k}", data={"path": f"mpu9150-mikoff/imu{k}.log", **MIKOFF}) for k in (0, 1, 2)],
    Source("magnetometer-ckexplorer acc_log", data={"path": "magnetometer-ckexplorer/acc_log.csv",
                                                      "sample_rate": CKEXPLORER_RATE, "unit": "g"},
           note=f"readings in g, rate not stated: taken as {CKEXPLORER_RATE:g} Hz (see the script)"),
]


@dataclass
class Row:
    """One recording's outcome."""

    source: Source
    default: object | None = None  #: CalibrationRun, weights auto
    uniform: object | None = None  #: CalibrationRun, weights uniform
    refused: str | None = None
    rms_default: float = math.nan  #: RMS of |a| - g over the default run's interval means [m/s^2]
    rms_uniform: float = math.nan  #: the uniform calibration's on the same interval means [m/s^2]
    gyro: object | None = None  #: imucal.gyro.check.StillCheck; None without a gyroscope
    gyro_refused: str | None = None  #: the gyroscope fit's refusal, if any
    seconds: float = 0.0

    @property
    def ratio(self) -> float:
        return self.rms_default / self.rms_uniform if self.rms_uniform > 0 else math.nan

    @property
    def assessable(self) -> bool:
        """Whether the interval means are more than the free parameters: with no more, every calibration
        fits them exactly (RMS ~ 0 either way) and the ratio says nothing."""
        return not self.refused and self.default.intervals.n > len(self.default.result.free_names)

    @property
    def met(self) -> bool | None:
        return bool(self.ratio <= TARGET_RATIO) if self.assessable else None


def _rms_on(run, cal) -> float:
    """RMS of |a| - g of ``cal`` applied to ``run``'s interval means [m/s^2]."""
    from imucal.model.channels import covariate_values

    iv = run.intervals
    covs = covariate_values(cal.covariates, temp=iv.temp, time=iv.t_mid) if cal.effects else None
    r = np.linalg.norm(cal.apply(iv.mean, covs), axis=1) - cal.gravity
    return float(np.sqrt(np.mean(r**2)))


def evaluate(src: Source) -> Row:
    """Calibrate once with the default weights and once uniform (one reading of the file), score both
    on the default run's still intervals."""
    from imucal.data.load import load_recording
    from imucal.errors import ImucalError
    from imucal.pipeline import calibrate_accelerometer

    row, t0 = Row(src), time.perf_counter()
    try:
        cfg = src.run_config()
        rec = load_recording(cfg.data, cfg.base_dir)
        row.default = calibrate_accelerometer(cfg, rec)
        row.uniform = calibrate_accelerometer(replace(cfg, fit=replace(cfg.fit, weights="uniform")), rec)
    except ImucalError as exc:
        row.refused = str(exc)
    else:
        row.rms_default = _rms_on(row.default, row.default.calibration)
        row.rms_uniform = _rms_on(row.default, row.uniform.calibration)
        _gyro(row)
    row.seconds = time.perf_counter() - t0
    return row


def _gyro(row: Row) -> None:
    """The gyroscope's three fits (imucal.gyro.check) on the default run, when the recording has one."""
    from imucal.errors import ImucalError
    from imucal.gyro.check import run_still_check

    try:
        row.gyro = run_still_check(row.default)
    except ImucalError as exc:
        row.gyro_refused = str(exc)


# --- the table: each column a header and a cell; the gyroscope's columns go in GYRO_COLUMNS -----------
@dataclass(frozen=True)
class Column:
    header: str
    cell: Callable[[Row], str]


def _moved(row: Row) -> str:
    res = row.default.result
    d = res.bias_drift
    if d is None:
        kind = (f"no walk; per-visit scatter {res.bias_instability / 9.80665 * 1e3:.3g} mg rms" if res.excess > 0
                else "no")
        return kind
    mg = d.in_mg(d.peak_to_peak)
    return "yes: peak to peak " + ", ".join(f"{'xyz'[i]} {mg[i]:.3g}" for i in range(3)) + " mg"


def _fmt(v: float, spec: str) -> str:
    return format(v, spec) if math.isfinite(v) else "—"


def _rms(v: float) -> str:
    """[m/s^2] to the micro-g digit; a mean fitted exactly (no more means than parameters) shows its size."""
    return _fmt(v, ".6f" if not 0 < v < 1e-5 else ".2g")


ACC_COLUMNS: tuple[Column, ...] = (
    Column("recording", lambda r: r.source.name),
    Column("intervals", lambda r: f"{r.default.intervals.n}"),
    Column("fit", lambda r: f"{len(r.default.result.free_names)} parameters, {r.default.result.mode}"),
    Column("RMS default [m/s^2]", lambda r: _rms(r.rms_default)),
    Column("RMS uniform [m/s^2]", lambda r: _rms(r.rms_uniform)),
    Column("ratio", lambda r: _fmt(r.ratio, ".4f") if r.assessable else "—"),
    Column(f"<= {TARGET_RATIO:g}", lambda r: "n/a: no more means than parameters" if r.met is None
           else "yes" if r.met else "NO"),
    Column("bias moved", _moved),
)


def _gyro_cell(cell: Callable[[object], str], first: bool = False) -> Callable[[Row], str]:
    """A gyroscope cell: "—" without a gyroscope; where its fit was refused, the first column says so."""
    return lambda r: cell(r.gyro) if r.gyro is not None else "refused (notes)" if r.gyro_refused and first else "—"


def _not_still(c) -> str:
    """How many intervals the gyro found turning, and their mean rates [deg/s] beyond the bias."""
    if not c.rejected:
        return f"0 of {c.n_intervals}"
    rates = ", ".join(f"{math.hypot(*r.rate_deg_s):.2g}" for r in sorted(c.rejected, key=lambda r: r.interval))
    return f"{len(c.rejected)} of {c.n_intervals}: {rates} deg/s"


#: The gyroscope's columns (imucal.gyro.check.StillCheck): its direction error beside the fit without
#: the rejected intervals and the fit that takes every static interval as still, on the same motions.
GYRO_COLUMNS: tuple[Column, ...] = (
    Column("gyro: not still", _gyro_cell(_not_still, first=True)),
    Column("gyro motions", _gyro_cell(lambda c: f"{c.n_segments}")),
    Column("gyro default [deg]", _gyro_cell(lambda c: f"{c.default_deg:.4f}")),
    Column("without rejected [deg]", _gyro_cell(lambda c: f"{c.removed_deg:.4f}")),
    Column("all still (old) [deg]", _gyro_cell(lambda c: f"{c.all_still_deg:.4f}")),
    Column("default no worse", _gyro_cell(lambda c: "yes" if c.no_worse else "NO")),
)


def markdown(rows: list[Row]) -> str:
    cols = ACC_COLUMNS + GYRO_COLUMNS
    L = ["# Right by default on real recordings", "",
         "Generated by `python studies/trust_real.py` from the recordings in `../shared/data/real` (see the README "
         "there for their origin and licences). Do not edit by hand.", "",
         "Each recording runs as its run file says (`configs/`), else with the default settings. \"Default\" is "
         "that run (`fit.weights: auto`), \"uniform\" the same run with `fit.weights: uniform`; both are scored on "
         "the default run's still intervals: RMS of |a| - g over the interval means. Target: default <= "
         f"{TARGET_RATIO:g} x uniform. \"Bias moved\": the bias random walk the default fit names, largest minus "
         "smallest of its smoothed estimate over the intervals, per sensor axis.", "",
         "Gyroscope (where the recording has one; `imucal.gyro.check`): \"not still\" are the static intervals "
         "the default gyro fit found turning (mean rate beyond the still poses' bias, deg/s), which it takes as no "
         "still pose. Three fits, all scored on the same motions (those between the intervals kept, RMS "
         "gravity-direction error): the default; the fit with the rejected intervals removed from the recording; "
         "and the fit that takes every static interval as still (the behaviour before issue 25). Target: default "
         "no worse than without the rejected intervals.", "",
         "| " + " | ".join(c.header for c in cols) + " |", "|" + "---|" * len(cols)]
    for r in rows:
        if r.refused:
            L.append(f"| {r.source.name} | refused |" + " — |" * (len(cols) - 2))
        else:
            L.append("| " + " | ".join(c.cell(r) for c in cols) + " |")
    notes = [f"* {r.source.name}: {r.source.note}." for r in rows if r.source.note]
    notes += [f"* {r.source.name}: refused (exit 2): `{_shown(r.refused)}`" for r in rows if r.refused]
    notes += [f"* {r.source.name}: gyroscope refused (exit 2): `{_shown(r.gyro_refused)}`"
              for r in rows if r.gyro_refused]
    L += ["", "<!-- begin:summary -->", _summary(rows), "<!-- end:summary -->", ""]
    return "\n".join(L + (["Notes:", "", *notes, ""] if notes else []))


def _summary(rows: list[Row]) -> str:
    """How many recordings meet each target."""
    ok = [r for r in rows if r.assessable]
    gy = [r.gyro for r in rows if r.gyro is not None]
    n_gyro_refused = sum(bool(r.gyro_refused) for r in rows)
    return (f"{sum(bool(r.met) for r in ok)} of {len(ok)} recordings with more interval means than parameters "
            f"meet the target; {sum(1 for r in rows if r.refused)} refused. Gyroscope: the default no worse than "
            f"without the rejected intervals on {sum(c.no_worse for c in gy)} of {len(gy)} recordings"
            + (f"; {n_gyro_refused} refused." if n_gyro_refused else "."))


def _shown(message: str) -> str:
    """A refusal with the real recordings' folder as the README names it, however the path was spelled."""
    return re.sub(r"\S*/shared/data/real", "../shared/data/real", message.replace(str(REAL), "../shared/data/real"))


def to_json(rows: list[Row]) -> list[dict]:
    out = []
    for r in rows:
        d = {"name": r.source.name, "refused": r.refused, "seconds": r.seconds}
        if not r.refused:
            res = r.default.result
            d |= {"intervals": r.default.intervals.n, "free_parameters": len(res.free_names),
                  "rms_default": r.rms_default, "rms_uniform": r.rms_uniform, "ratio": r.ratio,
                  "assessable": r.assessable, "met": r.met, "random_walk": math.sqrt(res.random_walk),
                  "bias_drift": None if res.bias_drift is None else res.bias_drift.to_json(
                      r.default.calibration.raw_unit), "gyro": _gyro_json(r)}
        out.append(d)
    return out


def _gyro_json(r: Row) -> dict | None:
    c = r.gyro
    if c is None:
        return {"refused": r.gyro_refused} if r.gyro_refused else None
    return {"intervals": c.n_intervals, "segments": c.n_segments, "default_deg": c.default_deg,
            "removed_deg": c.removed_deg, "all_still_deg": c.all_still_deg, "no_worse": c.no_worse,
            "not_still": [{"interval": n.interval, "t_start": n.t_start, "t_end": n.t_end,
                           "rate_deg_s": list(n.rate_deg_s or ()), "test": n.test.value} for n in c.rejected]}


def _user_sources(args: argparse.Namespace) -> list[Source]:
    out = [Source(Path(p).name, Path(p).resolve()) for p in args.configs]
    for p in args.data or []:
        data = {"path": str(Path(p).resolve()), **({"unit": args.unit} if args.unit else {}),
                **({"sample_rate": args.sample_rate} if args.sample_rate else {})}
        out.append(Source(Path(p).name, data=data, gravity=args.gravity))
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("configs", nargs="*", help="run files (YAML) of more recordings")
    ap.add_argument("--data", action="append", help="a recording of yours (repeatable), read with the options below")
    ap.add_argument("--unit", help="its raw unit (label), e.g. raw or m/s^2")
    ap.add_argument("--sample-rate", type=float, help="its rate [Hz] when it has no time column")
    ap.add_argument("--gravity", type=float, help="local gravity [m/s^2] (default: standard gravity)")
    ap.add_argument("--only-yours", action="store_true", help="skip the shared real recordings")
    ap.add_argument("--out", default=str(ROOT / "studies" / "results" / "trust_real.md"), help="the table (Markdown)")
    ap.add_argument("--json", help="also the rows as JSON")
    args = ap.parse_args(argv)
    sources = [] if args.only_yours else SOURCES
    if sources and not REAL.exists():
        print(f"real recordings not found at {REAL}", file=sys.stderr)
        return 2
    t0 = time.perf_counter()
    rows = [evaluate(s) for s in [*sources, *_user_sources(args)]]
    from imucal.files.output import write_text_atomic

    text = markdown(rows)
    write_text_atomic(args.out, text)
    if args.json:
        write_text_atomic(args.json, json.dumps(to_json(rows), indent=1) + "\n")
    print(text)
    print(f"wrote {args.out} ({time.perf_counter() - t0:.1f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
