"""Detection study for `imucal discover` over the effect grammar: how often it names the hidden term, by size and noise.

Each case is a seeded simulated recording (imucal.analysis.simulate.draw_effect_case: random sensor in raw
counts or m/s^2, 18-26 poses of 3 s at 100 Hz, warm-up plus a non-monotonic temperature swing)
with one effect on a random axis subset, or none. Discover runs without being told anything.

The effect size is the largest change of a reading at 1 g over the recording [mg]; the
signal-to-noise ratio (SNR) divides it by the noise of one interval mean. For every noise level
and effect the script finds the smallest SNR (and size in mg) at which the right effect on the
right axes is named in at least 90 % of the cases, and counts false positives on clean data.

    python scripts/discover_study.py                 # the full study over the grammar (15 terms)
    python scripts/discover_study.py --classic       # the five effects before the grammar only
    python scripts/discover_study.py --quick         # a smoke run
For the cross-axis term only the sum of its coefficients over the axes reaches |a| (see
imucal.model.effects), so "correct" there means the term on one axis.
Writes docs/discover_study.md (and prints it).
"""
from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from imucal.constants import STANDARD_GRAVITY  # noqa: E402
from imucal.model.effects import CLASSIC, EFFECTS  # noqa: E402
from imucal.report.progress import progress  # noqa: E402

#: "reliably": the right effect and axes in at least this share of the cases.
RELIABLE = 0.9


def run_case(args: tuple) -> dict:
    """Simulate one case, run discover, classify the outcome."""
    seed, effect, snr, noise_mg, pool = args
    from imucal.config.run import config_from_dict
    from imucal.analysis.discover import discover
    from imucal.analysis.simulate import draw_effect_case

    if effect == "pair":
        return run_pair(seed, snr, noise_mg, pool)
    case = draw_effect_case(seed, effect=effect, snr=snr, noise_mg=noise_mg)
    sim = case.config.run()
    with tempfile.TemporaryDirectory() as d:
        path = os.path.join(d, "case.csv")
        with open(path, "w") as f:
            f.write(sim.to_csv_text())
        t0 = time.perf_counter()
        res = discover(config_from_dict({"data": {"path": path, "unit": case.config.sensor.unit}}))
        dt = time.perf_counter() - t0
    got = [(e.name, tuple(e.axes)) for e in res.effects]
    if case.effect is None:
        outcome = "clean-ok" if not got else "false-positive"
    elif got == [(case.effect, case.axes)] or (not EFFECTS[case.effect].axes_observable
                                               and [n for n, _ in got] == [case.effect]):
        outcome = "correct"
    elif not got:
        outcome = "missed"
    elif (case.effect, case.axes) in got:
        outcome = "correct+extra"
    elif any(n == case.effect for n, _ in got):
        outcome = "wrong-axes"
    else:
        outcome = "wrong-effect"
    return {"seed": seed, "effect": effect, "snr": snr, "noise_mg": noise_mg, "outcome": outcome,
            "found": [f"{n}[{''.join('xyz'[a] for a in ax)}]" for n, ax in got], "truth": case.label,
            "ambiguous": any(e.ambiguous_with for e in res.effects), "size_mg": case.size / STANDARD_GRAVITY * 1e3,
            "sigma_mean_mg": case.sigma_mean / STANDARD_GRAVITY * 1e3, "redchi_after": res.final.result.redchi,
            "gap_after": res.rms_after / res.rms_noise, "gap_before": res.rms_before / res.rms_noise,
            "counts": case.config.sensor.unit == "raw", "seconds": dt}


def run_pair(seed: int, snr: float, noise_mg: float, pool: tuple[str, ...]) -> dict:
    """Two different effects, one axis each, same SNR: are both named, and nothing else?"""
    from imucal.config.run import config_from_dict
    from imucal.analysis.discover import discover
    from imucal.analysis.simulate import draw_pair_case, pair_config

    c1, c2 = draw_pair_case(seed, snr=snr, noise_mg=noise_mg, candidates=pool)
    with tempfile.TemporaryDirectory() as d:
        path = os.path.join(d, "case.csv")
        with open(path, "w") as f:
            f.write(pair_config(c1, c2).run().to_csv_text())
        t0 = time.perf_counter()
        res = discover(config_from_dict({"data": {"path": path, "unit": c1.config.sensor.unit}}))
        dt = time.perf_counter() - t0
    def label(name: str, axes) -> str:  # the cross-axis term's axis is a convention
        return name if not EFFECTS[name].axes_observable else f"{name}[{''.join('xyz'[a] for a in axes)}]"

    found = sorted(label(e.name, e.axes) for e in res.effects)
    truth = sorted([label(c1.effect, c1.axes), label(c2.effect, c2.axes)])
    outcome = "pair-correct" if found == truth else ("pair-one" if set(found) & set(truth) else "pair-none")
    return {"seed": seed, "effect": "pair", "snr": snr, "noise_mg": noise_mg, "outcome": outcome,
            "found": found, "truth": " + ".join(truth), "ambiguous": any(e.ambiguous_with for e in res.effects),
            "size_mg": c1.size / STANDARD_GRAVITY * 1e3, "sigma_mean_mg": c1.sigma_mean / STANDARD_GRAVITY * 1e3,
            "redchi_after": res.final.result.redchi, "seconds": dt, "counts": c1.config.sensor.unit == "raw",
            "gap_after": res.rms_after / res.rms_noise, "gap_before": res.rms_before / res.rms_noise,
            "lookahead": any(s.jointly_with for s in res.steps)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--noise", type=float, nargs="+", default=[0.1, 0.3, 1.0], help="noise per sample [mg]")
    ap.add_argument("--snr", type=float, nargs="+", default=[10, 15, 20, 30, 40, 60],
                    help="effect sizes / sigma_mean")
    ap.add_argument("--cases", type=int, default=20, help="cases per (effect, noise, snr) cell")
    ap.add_argument("--clean", type=int, default=40, help="clean cases per noise level")
    ap.add_argument("--pairs", type=int, default=30, help="two-effect cases per pair SNR and noise level")
    ap.add_argument("--pair-snr", type=float, nargs="+", default=[20, 40], help="SNR of each effect of a pair")
    ap.add_argument("--jobs", type=int, default=max(1, (os.cpu_count() or 1)), help="worker processes")
    ap.add_argument("--seed", type=int, default=50000, help="first seed")
    ap.add_argument("--quick", action="store_true", help="a smoke run: 2 cases per cell, 2 SNRs, 1 noise")
    ap.add_argument("--classic", action="store_true", help="only the five effects before the grammar")
    ap.add_argument("--effects", nargs="+", choices=list(EFFECTS), help="terms to hide (default: the grammar)")
    ap.add_argument("--out", default=str(ROOT / "docs" / "discover_study.md"))
    a = ap.parse_args(argv)
    if a.quick:
        a.noise, a.snr, a.cases, a.clean, a.pairs = [0.3], [10, 40], 2, 4, 2
    a.terms = tuple(a.effects or (CLASSIC if a.classic else EFFECTS))
    jobs = []
    seed = a.seed
    for noise in a.noise:
        for _ in range(a.clean):
            jobs.append((seed, None, 0.0, noise, a.terms))
            seed += 1
        for eff in a.terms:
            for snr in a.snr:
                for _ in range(a.cases):
                    jobs.append((seed, eff, snr, noise, a.terms))
                    seed += 1
        for snr in a.pair_snr:
            for _ in range(a.pairs):
                jobs.append((seed, "pair", snr, noise, a.terms))
                seed += 1
    t0 = time.perf_counter()
    rows = []
    with mp.get_context("fork").Pool(a.jobs) as pool, progress("cases", total=len(jobs), unit="case") as step:
        for row in pool.imap_unordered(run_case, jobs, chunksize=2):
            rows.append(row)
            step()
    rows.sort(key=lambda r: r["seed"])
    wall = time.perf_counter() - t0
    text = report(rows, a, wall)
    from imucal.files.output import write_text_atomic

    write_text_atomic(a.out, text)
    print(text)
    return 0


def report(rows: list[dict], a: argparse.Namespace, wall: float) -> str:
    L = ["# Discover: detection rate, smallest detectable effect, false positives", "",
         f"Measured by `python scripts/discover_study.py` ({len(rows)} seeded cases, {wall / 60:.1f} min "
         f"wall time on {a.jobs} processes, first seed {a.seed}; terms: {', '.join(a.terms)}; noise "
         f"{', '.join(f'{n:g}' for n in a.noise)} mg; SNR {', '.join(f'{s:g}' for s in a.snr)}; {a.cases} cases per cell, "
         f"{a.clean} clean cases and {a.pairs} pairs per SNR {', '.join(f'{s:g}' for s in a.pair_snr)} per noise level). "
         "Each case: a random sensor (raw counts with "
         "quantisation, or factory-scaled m/s^2), 18-26 poses of 3 s at 100 Hz, warm-up plus non-monotonic "
         "temperature swing, one effect on a random axis subset with a random sign, or none. "
         "Discover is told nothing.", "",
         "*Size* = largest change of a reading at 1 g over the recording [mg]. *sigma_mean* = noise of one "
         "interval mean = noise per sample / sqrt(samples per interval) [mg]. *SNR* = size / sigma_mean. "
         "*Correct* = exactly the hidden effect on exactly its axes, nothing else.", ""]
    clean = [r for r in rows if r["effect"] is None]
    L += ["## False positives on clean data", "", "| noise per sample [mg] | clean cases | effects named |",
          "|---|---|---|"]
    for noise in a.noise:
        cs = [r for r in clean if r["noise_mg"] == noise]
        fp = sum(r["outcome"] == "false-positive" for r in cs)
        L.append(f"| {noise:g} | {len(cs)} | {fp} |")
    L.append("")
    L += ["## Correct effect and axes, by SNR", "",
          "| effect | noise [mg] | " + " | ".join(f"SNR {s:g}" for s in a.snr) + " |",
          "|---|---|" + "---|" * len(a.snr)]
    cells: dict = defaultdict(list)
    for r in rows:
        if r["effect"] not in (None, "pair"):
            cells[(r["effect"], r["noise_mg"], r["snr"])].append(r)
    for eff in a.terms:
        for noise in a.noise:
            vals = []
            for s in a.snr:
                cs = cells[(eff, noise, s)]
                vals.append(f"{sum(r['outcome'] == 'correct' for r in cs)}/{len(cs)}")
            L.append(f"| {eff} | {noise:g} | " + " | ".join(vals) + " |")
    L.append("")
    L += [f"## Smallest reliably found effect ({RELIABLE:.0%} correct at this SNR and at every larger one tried)",
          "", "| effect | noise per sample [mg] | sigma_mean [mg] | smallest SNR | smallest size [mg] |",
          "|---|---|---|---|---|"]
    for eff in a.terms:
        for noise in a.noise:
            ok = [s for s in a.snr if cells[(eff, noise, s)]
                  and np.mean([r["outcome"] == "correct" for r in cells[(eff, noise, s)]]) >= RELIABLE]
            smallest = next((s for s in a.snr if all(t in ok for t in a.snr if t >= s)), None)
            sig = np.mean([r["sigma_mean_mg"] for r in rows if r["noise_mg"] == noise])
            if smallest is None:
                L.append(f"| {eff} | {noise:g} | {sig:.3g} | > {max(a.snr):g} | - |")
            else:
                L.append(f"| {eff} | {noise:g} | {sig:.3g} | {smallest:g} | {smallest * sig:.3g} |")
    L.append("")
    pairs = [r for r in rows if r["effect"] == "pair"]
    if pairs:
        L += ["## Two effects at once", "",
              "Two different effects, each on one random axis, both of the given SNR, in one recording. "
              "*Both* = exactly the two, nothing else; *lookahead* = a round in which no single effect was "
              "significant on its own and the pair test added one.", "",
              "| SNR of each | noise [mg] | cases | both named | one of them | none | lookahead used |",
              "|---|---|---|---|---|---|---|"]
        for snr in a.pair_snr:
            for noise in a.noise:
                cs = [r for r in pairs if r["snr"] == snr and r["noise_mg"] == noise]
                if cs:
                    L.append(f"| {snr:g} | {noise:g} | {len(cs)} | {sum(r['outcome'] == 'pair-correct' for r in cs)} | "
                             f"{sum(r['outcome'] == 'pair-one' for r in cs)} | "
                             f"{sum(r['outcome'] == 'pair-none' for r in cs)} | {sum(r['lookahead'] for r in cs)} |")
        L.append("")
    L += ["## By sensor kind and the gap closed", "",
          "Correct share per sensor kind (raw counts with quantisation / factory-scaled m/s^2), single terms at "
          "SNR >= 10; *gap* = RMS of |a| - g on interval means over the RMS the noise alone gives (median), "
          "before and after discovery, over the correctly named cases.", "",
          "| sensor | cases | correct | gap before | gap after |", "|---|---|---|---|---|"]
    single = [r for r in rows if r["effect"] not in (None, "pair") and r["snr"] >= 10]
    for kind, flag in (("counts", True), ("SI (m/s^2)", False)):
        cs = [r for r in single if r["counts"] == flag]
        ok = [r for r in cs if r["outcome"] == "correct"]
        if cs:
            L.append(f"| {kind} | {len(cs)} | {len(ok)} ({len(ok) / len(cs):.0%}) | "
                     f"{np.median([r['gap_before'] for r in ok]) if ok else float('nan'):.3g} | "
                     f"{np.median([r['gap_after'] for r in ok]) if ok else float('nan'):.3g} |")
    L.append("")
    outcomes = defaultdict(int)
    for r in rows:
        outcomes[r["outcome"]] += 1
    L += ["## All outcomes", "", "| outcome | cases |", "|---|---|"]
    L += [f"| {k} | {v} |" for k, v in sorted(outcomes.items())]
    amb = sum(r["ambiguous"] for r in rows)
    L += ["", f"{amb} cases reported an ambiguity (a competitor within the ambiguity margin).", ""]
    we = [r for r in rows if r["outcome"] == "wrong-effect"]
    if we:
        L += [f"Wrong effect named in {len(we)} of {sum(r['effect'] not in (None, 'pair') for r in rows)} "
              f"single-effect cases, at SNR <= {max(r['snr'] for r in we):g}; the ambiguity was flagged in "
              f"{sum(r['ambiguous'] for r in we)} of them.", ""]
    wrong = [r for r in rows if r["outcome"] not in ("correct", "clean-ok", "missed", "pair-correct")]
    if wrong:
        L += ["## Misidentified cases", "", "| seed | truth | SNR | noise [mg] | found | ambiguity flagged |",
              "|---|---|---|---|---|---|"]
        for r in wrong:
            L.append(f"| {r['seed']} | {r['truth']} | {r['snr']:g} | {r['noise_mg']:g} | {', '.join(r['found'])} | "
                     f"{'yes' if r['ambiguous'] else 'no'} |")
        L.append("")
    secs = [r["seconds"] for r in rows]
    L += [f"Discover took {np.median(secs):.2f} s per case (median), {np.max(secs):.1f} s at most.", ""]
    return "\n".join(L)


if __name__ == "__main__":
    raise SystemExit(main())
