"""Temperature calibration on a real thermal sweep (issue 27): how far the calibration imucal writes
keeps each still pose's reading constant over temperature, in sample, interpolating and extrapolating.

The recording is ../shared/data/real/thermal-cats-skdivemove (a CATS tag, 1 Hz, 74.5 h: z, x, x, y
along -g, each a cold soak and a warm-up over about 5..25 degC; AGPL-3.0, read from there, never copied).
The run file holds what three one-axis-down poses cannot determine (the scales and angles at nominal,
fit.fix); the calibration is the product's (imucal.thermal.run.thermal_calibration: the orders chosen
by the data on each split's fit part). Judged on the four long poses (over LONG_POSE_H hours): the RMS
in mg of 10-minute means of each calibrated axis about its pose's mean (over the judged part), and the
same for the gyroscope in mrad/s, calibrated by the same calibration (its gyroscope section's bias(T) terms,
imucal.gyro.thermal, through Calibration.apply_all: what `imucal apply` writes).

Splits (the fit part chooses the orders and fits the terms; the judged part is not seen):
  in sample       fit everything, judge everything
  interpolating   fit the even one-hour blocks from the start, judge the odd ones (and the reverse)
  extrapolating   fit each long pose's colder half (below its median temperature), judge its warmer
                  half; and the same split at the middle of its temperature range

Writes studies/results/thermal.md and studies/results/thermal/residuals.png (10-minute means about their
poses against temperature, uncorrected and corrected, per axis); --json writes the numbers. The method and
the user's workflow: docs/thermal.md.

    python -m studies run thermal [--data FILE.nc] [--md PAGE.md] [--png FIGURE.png] [--json FILE]
"""
from __future__ import annotations

import argparse
import json
import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from imucal.calibration.frozen import Calibration
from imucal.config.run import config_from_dict
from imucal.constants import STANDARD_GRAVITY
from imucal.report.thermal import residual_temperature_figure
from imucal.thermal.evidence import thermal_rows
from imucal.thermal.run import Sweep, sweep_of, thermal_calibration
from imucal.thermal.select import ALPHA

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "real" / "thermal-cats-skdivemove" / "cats_temperature_calib.nc"
MG = STANDARD_GRAVITY / 1000.0
#: A pose judged: a still interval of at least this many hours.
LONG_POSE_H = 10.0
#: The judged means [s], and the least share of a block that must be judged for it to count.
BLOCK_S, BLOCK_MIN = 600.0, 0.5
#: The issue's targets: [mg] interpolating, extrapolating; gyroscope [mrad/s] in sample, extrapolating.
TARGETS = {"interpolating": 0.8, "extrapolating": 1.9, "gyro_in_sample": 0.45, "gyro_extrapolating": 0.6}
#: The run file of the study: what three one-axis-down poses cannot determine, held at nominal.
RUN = {"fit": {"fix": {"b1": 1.0, "b2": 1.0, "b3": 1.0, "phi": np.pi / 2, "psi": np.pi / 2, "theta": np.pi / 2}}}


@dataclass(frozen=True)
class Split:
    name: str
    fit: str
    judge: str


#: Other lengths of the alternating blocks (not the issue's split): how much the interpolating result owes to
#: where the blocks fall. [h]
OTHER_BLOCKS_H = (0.5, 2.0, 3.0)
#: A looser family-wise level for the orders, judged beside the product's (imucal.thermal.select.ALPHA).
LOOSE_ALPHA = 0.05
#: Hours at the start of the first long pose (the cool-down's settling at constant temperature) left out
#: of a second judgement of the even blocks.
SETTLE_H = 3.0

SPLITS = (Split("in sample", "all", "all"),
          Split("interpolating (fit even hours, judge odd)", "even", "odd"),
          Split("interpolating (fit odd hours, judge even)", "odd", "even"),
          Split("extrapolating (fit colder half, judge warmer)", "cold_median", "warm_median"),
          Split("extrapolating (fit below mid-range, judge above)", "cold_mid", "warm_mid"))
OTHER_SPLITS = tuple(Split(f"alternate {h:g} h blocks (fit {a}, judge {b})", f"{a}:{h:g}", f"{b}:{h:g}")
                     for h in OTHER_BLOCKS_H for a, b in (("even", "odd"), ("odd", "even")))


def part(sweep: Sweep, long: list[int], kind: str) -> np.ndarray:
    """A sample mask over the long poses: all, even/odd hours from the start ("even:H": blocks of H hours),
    or a pose's colder/warmer part."""
    rec, iv = sweep.recording, sweep.intervals
    kind, _, hours = kind.partition(":")
    m = np.zeros(rec.n, bool)
    for k in long:
        a, b = iv.start[k], iv.end[k]
        T, block = rec.temp[a:b], np.floor(rec.t[a:b] / (3600.0 * float(hours or 1.0)))
        cut = np.median(T) if kind.endswith("median") else (T.min() + T.max()) / 2
        m[a:b] = {"all": np.ones(b - a, bool), "even": block % 2 == 0, "odd": block % 2 == 1,
                  "cold_median": T < cut, "warm_median": T >= cut, "cold_mid": T < cut, "warm_mid": T >= cut}[kind]
    return m


def block_means(sweep: Sweep, long: list[int], judge: np.ndarray, values: np.ndarray) -> list[np.ndarray]:
    """Per long pose, the 10-minute means of ``values`` (n, 3) over its judged samples."""
    rec, iv, out = sweep.recording, sweep.intervals, []
    for k in long:
        a, b = iv.start[k], iv.end[k]
        blk, ok = np.floor(rec.t[a:b] / BLOCK_S).astype(int), judge[a:b]
        full = np.bincount(blk - blk[0], minlength=1)
        good = np.bincount(blk[ok] - blk[0], minlength=full.size)
        keep = np.flatnonzero(good >= BLOCK_MIN * BLOCK_S * rec.sample_rate)
        v, j = values[a:b][ok], blk[ok] - blk[0]
        out.append(np.array([v[j == u].mean(axis=0) for u in keep]).reshape(-1, 3))
    return out


def rms_about_poses(means: list[np.ndarray]) -> float:
    return float(np.sqrt(np.mean(np.concatenate([m - m.mean(axis=0) for m in means if m.size]) ** 2)))


def calibrated(cal: Calibration, sweep: Sweep) -> np.ndarray:
    rec = sweep.recording
    return cal.apply(rec.raw, {"temp": rec.temp, "time": rec.t}) if cal.effects else cal.apply(rec.raw)


def run_split(sweep: Sweep, long: list[int], s: Split, alpha: float = ALPHA) -> dict:
    rec = sweep.recording
    fit = None if s.fit == "all" else part(sweep, long, s.fit)
    rows = thermal_rows(rec, sweep.intervals, keep=fit)
    tc = thermal_calibration(Sweep(sweep.config, rec, sweep.intervals, rows), alpha=alpha)
    judge = part(sweep, long, s.judge)
    cal = tc.final.calibration
    acc = rms_about_poses(block_means(sweep, long, judge, calibrated(cal, sweep)))
    gt = tc.gyro
    assert gt is not None and cal.gyro is not None, "the sweep's calibration holds its gyroscope"
    # the gyroscope as the calibration file carries it: its bias(T) terms in the one apply map (issue 27)
    omega = cal.apply_all({"accelerometer": rec.raw, "gyroscope": rec.gyro}, {"temp": rec.temp, "time": rec.t})
    gyro = rms_about_poses(block_means(sweep, long, judge, omega["gyroscope"]))
    return {"split": s.name, "rows": rows.n, "mg": acc / MG,
            "terms": {n: "".join("xyz"[a] for a in ax) for n, ax in tc.effects.items()},
            "gyro_mrad_s": gyro * 1e3, "gyro_orders": list(gt.orders), "tc": tc, "gt": gt}


def judged(sweep: Sweep, long: list[int], r: dict, kind: str, skip_h: float = 0.0) -> float:
    """[mg] split ``r``'s calibration judged on the blocks ``kind``, less the first ``skip_h`` hours of
    the first long pose."""
    rec, iv, m = sweep.recording, sweep.intervals, part(sweep, long, kind)
    a, b = iv.start[long[0]], iv.end[long[0]]
    m[a:b] &= rec.t[a:b] >= iv.t_start[long[0]] + skip_h * 3600.0
    return rms_about_poses(block_means(sweep, long, m, calibrated(r["tc"].final.calibration, sweep))) / MG


def why_lines(sweep: Sweep, long: list[int], res: list[dict], loose: list[dict]) -> list[str]:
    """Why the two interpolating directions differ, measured (issue 27's open question)."""
    even_fit, odd_fit = res[1], res[2]

    def terms(r: dict) -> str:
        return ", ".join(f"{n}[{a}]" for n, a in r["terms"].items())
    return [f"Why the two directions differ: fitted on the even hours the data chose {terms(even_fit)}; fitted "
            f"on the odd hours, {terms(odd_fit)}. The odd-hour calibration scores {odd_fit['mg']:.2f} mg on the "
            f"even blocks, {judged(sweep, long, odd_fit, 'even', SETTLE_H):.2f} mg without the first "
            f"{SETTLE_H:g} h of pose {long[0]} (the fast cool-down, after which x and z keep settling at constant "
            "temperature: the figure, near 5 degC; no temperature term describes it); the in-sample "
            f"calibration scores {judged(sweep, long, res[0], 'even'):.2f} mg on them, the even-hour one "
            f"{judged(sweep, long, even_fit, 'even'):.2f} mg on its own blocks. A looser level for the orders "
            f"(family-wise alpha {LOOSE_ALPHA:g} instead of {ALPHA:g}) gives {loose[0]['mg']:.2f} mg on the odd-hour "
            f"split ({terms(loose[0])}) but {loose[1]['mg']:.2f} mg extrapolating to the warmer halves "
            f"({terms(loose[1])}): the product's level is kept."]


def figure(sweep: Sweep, long: list[int], r: dict, path: Path) -> None:
    rec, judge = sweep.recording, part(sweep, long, "all")
    before = block_means(sweep, long, judge, rec.raw)
    after = block_means(sweep, long, judge, calibrated(r["tc"].final.calibration, sweep))
    temp = block_means(sweep, long, judge, np.repeat(rec.temp[:, None], 3, axis=1))
    pose = np.concatenate([np.full(m.shape[0], k) for k, m in zip(long, before)])
    residual_temperature_figure(np.concatenate([t[:, 0] for t in temp]),
                                np.concatenate([m - m.mean(axis=0) for m in before]),
                                np.concatenate([m - m.mean(axis=0) for m in after]), pose, path,
                                f"thermal-cats-skdivemove: 10-minute means about each pose, uncorrected and with "
                                f"{', '.join(f'{n}[{a}]' for n, a in r['terms'].items())}")


def _headline(unc: dict, res: list[dict]) -> str:
    """The table in one sentence (the README quotes it): the range over each kind of split."""
    def span(kind: str, key: str) -> str:
        v = sorted(r[key] for r in res if r["split"].startswith(kind))
        return f"{v[0]:.2f}" if len(v) == 1 else f"{v[0]:.2f}-{v[-1]:.2f}"
    return (f"Accelerometer: {unc['mg']:.2f} mg uncorrected, {span('in sample', 'mg')} in sample, "
            f"{span('interpolating', 'mg')} interpolating, {span('extrapolating', 'mg')} extrapolating. "
            f"Gyroscope bias(T): {unc['gyro_mrad_s']:.2f} mrad/s uncorrected, {span('in sample', 'gyro_mrad_s')} "
            f"in sample, {span('interpolating', 'gyro_mrad_s')} interpolating, "
            f"{span('extrapolating', 'gyro_mrad_s')} extrapolating.")


def markdown(res: list[dict], unc: dict, sweep: Sweep, seconds: float, png: str, why: list[str],
             other: list[dict]) -> str:
    tc, gt = res[0]["tc"], res[0]["gt"]
    rows = tc.rows
    across = float(np.polyfit(rows.t / 86400.0, rows.gyro[:, 0], 1)[0])  # [rad/s per day]
    lo, hi = tc.temperature_range
    L = ["# Temperature calibration on a real thermal sweep",
         "",
         "Generated by `studies/thermal_study.py` (`python -m studies run thermal`, issue 27); do not edit by "
         "hand. The method and the workflow: [Temperature calibration](../thermal.md).",
         "",
         f"Recording: thermal-cats-skdivemove (CATS tag, {sweep.recording.sample_rate:g} Hz, "
         f"{sweep.recording.duration / 3600:.1f} h; z, x, x, y along -g, each a cold soak and a warm-up; "
         f"{lo:.1f}..{hi:.1f} degC in the rows). Run file: the scales and angles held at nominal (`fit.fix`), "
         "what three one-axis-down poses cannot determine. Judged: the RMS of 10-minute means of each calibrated "
         f"axis about its pose's mean, over the {len(res[0]['tc'].support.poses)} poses that sweep and the four "
         f"long ones judged; the orders are chosen by the data on each split's fit part. The gyroscope is "
         "calibrated by the same calibration's gyroscope section (its bias(T) terms in the one apply map, what "
         f"`imucal apply` writes). {seconds:.0f} s.",
         "",
         "<!-- begin:table -->",
         "| split | rows | terms chosen | accelerometer [mg] | gyroscope bias(T) [mrad/s] | gyro orders x, y, z |",
         "|---|---|---|---|---|---|",
         f"| uncorrected | | | {unc['mg']:.2f} | {unc['gyro_mrad_s']:.2f} | |"]
    for r in res:
        terms = ", ".join(f"{n}[{a}]" for n, a in r["terms"].items()) or "none"
        L.append(f"| {r['split']} | {r['rows']} | {terms} | {r['mg']:.2f} | {r['gyro_mrad_s']:.2f} | "
                 f"{', '.join(map(str, r['gyro_orders']))} |")
    lag = tc.lag
    L += ["<!-- end:table -->", "", "<!-- begin:headline -->", _headline(unc, res), "<!-- end:headline -->", "",
          f"Targets (issue 27): interpolating <= {TARGETS['interpolating']} mg and extrapolating <= "
          f"{TARGETS['extrapolating']} mg (the first two splits of each), gyroscope <= {TARGETS['gyro_in_sample']} "
          f"mrad/s in sample and <= {TARGETS['gyro_extrapolating']} extrapolating. An independent least-squares "
          "reference reached uncorrected 9.8 mg; linear in T 0.90 in sample, 0.92 interpolating, 1.89 "
          "extrapolating; a quadratic or cubic 0.67-0.75 in sample but 7-12 mg extrapolating.",
          "",
          *why,
          "",
          "Other lengths of the alternating blocks (not the issue's split; the orders chosen by the data on "
          "each fit part), for how much an interpolating result owes to where the blocks fall:",
          "",
          "| split | terms chosen | accelerometer [mg] | gyroscope bias(T) [mrad/s] |",
          "|---|---|---|---|",
          *[f"| {r['split']} | {', '.join(f'{n}[{a}]' for n, a in r['terms'].items()) or 'none'} | "
            f"{r['mg']:.2f} | {r['gyro_mrad_s']:.2f} |" for r in other],
          "",
          "## What the file determines, and what it cannot tell",
          "",
          *[f"- {line}" for line in _determined(tc)],
          f"- Lag of the temperature sensor: tau = {lag.tau:.3g} +/- {lag.tau_std:.2g} s (p adjusted "
          f"{lag.tau_p:.2g}); hysteresis (half warming minus cooling) x, y, z = "
          + ", ".join(f"{h / MG:+.2f} +/- {s / MG:.2f}" for h, s in zip(lag.hysteresis, lag.hysteresis_std))
          + f" mg (p adjusted {lag.hysteresis_p:.2g}): "
          + ("named" if lag.lag_named or lag.hysteresis_named else "neither is shown by these data; none is claimed")
          + ".",
          "- Gyroscope: bias(T) orders x, y, z = " + ", ".join(map(str, gt.orders)) + "; a linear drift in time "
          "fitted beside them: " + ", ".join(f"{a} {d * 1e3:+.2f} +/- {s * 1e3:.2f} mrad/s per day" for a, d, s in
                                           zip("xyz", gt.drift, gt.drift_std))
          + " (correlation with the linear temperature term " + ", ".join(
              "n/a" if not np.isfinite(c) else f"{c:+.2f}" for c in gt.drift_correlation)
          + "): time and temperature move together in each warm-up, so a drift and a temperature term are "
            f"confounded. Across the recording (the rows against time, pose constants not fitted) the x axis "
            f"moves by {across * 1e3:+.2f} mrad/s per day, a drift the poses' own constants absorb and no "
            "temperature term explains.",
          "",
          f"![10-minute means about each pose against temperature]({png})",
          ""]
    return "\n".join(L)


def _determined(tc) -> list[str]:
    from imucal.report.thermal import determined_lines

    return determined_lines(tc)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default=str(DATA))
    ap.add_argument("--md", default=str(ROOT / "studies" / "results" / "thermal.md"))
    ap.add_argument("--png", default=str(ROOT / "studies" / "results" / "thermal" / "residuals.png"))
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    config = config_from_dict({"data": {"path": args.data}, **RUN})
    sweep = sweep_of(config)
    if sweep is None or sweep.rows is None:
        raise SystemExit(f"{args.data}: no still pose spans a temperature change")
    iv = sweep.intervals
    long = [k for k in range(iv.n) if iv.t_end[k] - iv.t_start[k] >= LONG_POSE_H * 3600]
    everything = part(sweep, long, "all")
    unc = {"mg": rms_about_poses(block_means(sweep, long, everything, sweep.recording.raw)) / MG,
           "gyro_mrad_s": rms_about_poses(block_means(sweep, long, everything, sweep.recording.gyro)) * 1e3}
    res = [run_split(sweep, long, s) for s in SPLITS]
    other = [run_split(sweep, long, s) for s in OTHER_SPLITS]
    why = why_lines(sweep, long, res, [run_split(sweep, long, s, LOOSE_ALPHA) for s in (SPLITS[2], SPLITS[3])])
    seconds = time.perf_counter() - t0
    print(f"uncorrected: {unc['mg']:.2f} mg, gyroscope {unc['gyro_mrad_s']:.2f} mrad/s")
    for r in res + other:
        print(f"{r['split']:<52s} {r['mg']:6.2f} mg  gyro {r['gyro_mrad_s']:5.2f} mrad/s  {r['terms']}")
    png, md = Path(args.png), Path(args.md)
    png.parent.mkdir(parents=True, exist_ok=True)
    figure(sweep, long, res[0], png)
    link = Path(os.path.relpath(png, md.parent)).as_posix()
    md.write_text(markdown(res, unc, sweep, seconds, link, why, other))
    if args.json:
        Path(args.json).write_text(json.dumps({
            "uncorrected": unc, "targets": TARGETS, "seconds": seconds,
            "splits": [{k: v for k, v in r.items() if k not in ("tc", "gt")} for r in res],
            "other_splits": [{k: v for k, v in r.items() if k not in ("tc", "gt")} for r in other]}, indent=1))
    print(f"wrote {args.md}, {png} ({seconds:.0f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
