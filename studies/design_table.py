#!/usr/bin/env python
"""Optimal pose design against the common schemes (issue 6); writes studies/results/design.md.

For N = 9 .. 26 and the D, A and E criteria: the planned design (`imucal plan-poses --n N`),
the common cube schemes with N poses, the best N-subset of the 26 cube directions, and random
pose sets; predicted standard errors; and, when the Monte-Carlo cache of
studies/mc_uncertainty.py is present, the simulation check of planned-D-12 against the edges.

    python studies/design_table.py [--mc-cache /tmp/imucal_mc_uncertainty.pkl]
"""
from __future__ import annotations

import argparse
import math
import pickle
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
NS = (9, 12, 18, 24, 26)
NOISE = 0.002  # m/s^2 per interval mean (imucal.analysis.design.DEFAULT_NOISE)


def criterion_table(criterion: str, free, ns, n_random: int) -> tuple[list[str], dict]:
    from imucal.analysis.design import compare, optimal_design

    better = "smaller" if criterion == "A" else "larger"
    L = [f"| N | planned | common scheme(s) | best cube subset | random, median of {n_random} | random, best | "
         "planning time [s] |", "|---|---|---|---|---|---|---|"]
    planned = {}
    for n in ns:
        t0 = time.perf_counter()
        p = optimal_design(n, criterion, NOISE, free=free)
        dt = time.perf_counter() - t0
        c = compare(p, n_random=n_random)
        planned[n] = (p, c)
        schemes = [o for o in c.others if o.label != "best cube subset"]
        sub = [o for o in c.others if o.label == "best cube subset"]

        def cell(o) -> str:
            txt = f"{o.value:.4f}"
            if criterion == "D":
                txt += f" (eff {o.d_efficiency(p):.3f})"
            return txt

        L.append(f"| {n} | {p.value:.4f} | " + ("; ".join(f"{o.label}: {cell(o)}" for o in schemes) or "—")
                 + f" | {cell(sub[0]) if sub else '—'} | {c.random_median:.4f} | {c.random_best:.4f} | {dt:.2f} |")
    L.append("")
    L.append(f"({criterion}: {better} is better.)")
    return L, planned


def std_table(designs) -> list[str]:
    from imucal.model.parameters import BASE_NAMES

    L = ["| design | " + " | ".join(BASE_NAMES) + " |", "|---|" + "---|" * 9,
         "| unit | " + " | ".join(["mm/s^2"] * 3 + ["ppm"] * 3 + ["mrad"] * 3) + " |"]
    fac = [1e3] * 3 + [1e6] * 3 + [1e3] * 3
    for d in designs:
        L.append(f"| {d.label} ({d.n}) | " + " | ".join(f"{d.std[n] * f:.3g}" for n, f in zip(BASE_NAMES, fac)) + " |")
    return L


def simulation_check(cache: Path) -> list[str]:
    """Empirical std of planned-D-12 vs edges from the Monte-Carlo recordings."""
    if not cache.exists():
        return [f"(Monte-Carlo cache {cache} not found: run studies/mc_uncertainty.py first.)"]
    with open(cache, "rb") as f:
        saved = pickle.load(f)
    from imucal.model.parameters import BASE_NAMES

    from imucal.analysis.design import evaluate, optimal_design, scheme_directions

    pred_eff = optimal_design(12, "D").d_efficiency(evaluate(scheme_directions("edges"), "D"))
    dets: list[str] = []
    by = {(s["scheme"], s["sensor"], s["series"], s["orthogonal"], s.get("noise_factor", 1.0)): saved["results"][i]
          for i, s in enumerate(saved["settings"])}
    L = ["Empirical standard deviation of the estimates over the Monte-Carlo recordings (`studies/mc_uncertainty.py`, "
         "same sensor and noise for both designs), as the ratio edges / planned-D-12, beside the predicted ratio "
         "(square roots of the CRLB diagonals). > 1: the planned poses estimate that parameter better.", "",
         "| sensor | recordings | | " + " | ".join(BASE_NAMES) + " | geometric mean |", "|---|---|---|" + "---|" * 10]
    for sensor in ("si", "counts"):
        e, p = by.get(("edges", sensor, False, False, 1.0)), by.get(("planned-D-12", sensor, False, False, 1.0))
        if not e or not p:
            continue
        se = np.std([r["err"] for r in e if "err" in r], axis=0, ddof=1)
        sp = np.std([r["err"] for r in p if "err" in r], axis=0, ddof=1)
        pe = np.mean([r["crlb"] for r in e if "crlb" in r], axis=0)
        pp = np.mean([r["crlb"] for r in p if "crlb" in r], axis=0)
        emp, pred = se / sp, pe / pp
        L.append(f"| {sensor} | {len(e)} + {len(p)} | empirical | " + " | ".join(f"{x:.3f}" for x in emp)
                 + f" | {math.exp(np.mean(np.log(emp))):.3f} |")
        L.append(f"| {sensor} | | predicted | " + " | ".join(f"{x:.3f}" for x in pred)
                 + f" | {math.exp(np.mean(np.log(pred))):.3f} |")
        # the D criterion measured: determinants of the empirical covariances
        ce = np.cov(np.array([r["err"] for r in e if "err" in r]).T)
        cp = np.cov(np.array([r["err"] for r in p if "err" in r]).T)
        eff = math.exp((np.linalg.slogdet(ce)[1] - np.linalg.slogdet(cp)[1]) / 9)
        sd = math.sqrt(2) * math.sqrt(2 * 9 / len(e)) / 9
        dets.append(f"{sensor}: measured (det C_edges / det C_planned)^(1/9) = {eff:.3f} (+- {1.96 * sd * eff:.3f})")
    L += ["", "D-efficiency of planned-D-12 over the edges, predicted (det F_planned / det F_edges)^(1/9) = "
          f"{pred_eff:.3f}; " + "; ".join(dets) + "."]
    return L


def main(argv: list[str] | None = None) -> int:
    from imucal.analysis.design import BASE_NAMES, DEFAULT_NOISE, SIX_NAMES, evaluate, scheme_directions

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default=str(ROOT / "studies" / "results" / "design.md"))
    ap.add_argument("--mc-cache", default=str(Path(tempfile.gettempdir()) / "imucal_mc_uncertainty.pkl"))
    ap.add_argument("--random", type=int, default=200, help="random pose sets per N")
    args = ap.parse_args(argv)
    assert NOISE == DEFAULT_NOISE
    L = ["# Optimal pose design", "",
         "Generated by `python studies/design_table.py`. Do not edit by hand; the method is described in "
         "`imucal/analysis/design.py` and summarised here.", "",
         "## What is optimised", "",
         "The means fit minimises sum_k ((|a_k| - g)/sigma_k)^2 (end of Section 2 of the paper: g = a_nonorth). "
         "At the true parameters its Jacobian has a closed form in the gravity direction u_k of each pose "
         "(`imucal.analysis.design.sensitivity`, checked against CasADi's derivative of the model in the tests):", "",
         "    dr/ds_i = -(E^-1 u)_i / b_i,  dr/db_i = -g (E^-1 u)_i (E^T u)_i / b_i,",
         "    dr/dphi = g sin(phi) (E^-1 u)_1 (E^-1 u)_2  (psi: 1,3; theta: 2,3),", "",
         "with E the frame of Eq. (eq:125). The Fisher information is F = J^T diag(1/sigma^2) J and F^-1 is the "
         "Cramér-Rao bound on the covariance of any unbiased estimate: the predicted standard errors below. "
         "Designs are compared at an ideal sensor (s = 0, b = 1, 90 deg), with sigma = "
         f"{NOISE} m/s^2 per interval mean (a MEMS part held 4 s at 100 Hz). Criteria use parameters in "
         "acceleration-equivalent units (s/b, g b, g angle, all in m/s^2), so every sensitivity is O(1):", "",
         "* **D**: log det F (unit noise). Invariant to the units; D-efficiency of a design relative to the "
         "planned one = (det F / det F_planned)^(1/9); an efficiency of 0.97 means the design needs 1/0.97 = 1.03 "
         "times as many recordings to match the planned poses' determinant.",
         "* **A**: trace F^-1 (unit noise): summed variance of the nine error terms.",
         "* **E**: smallest eigenvalue of F (unit noise): the worst-determined combination.", "",
         "Optimiser: coordinate exchange (Meyer & Nachtsheim) over a Fibonacci grid of 600 directions plus the 26 "
         "cube directions, six seeded random starts, the common schemes and the best cube subset as further "
         "starts, then a pattern search per pose on the sphere to leave the grid. Rank-one updates are exact "
         "(determinant lemma for D, Sherman-Morrison for A). An IPOPT NLP over spherical angles was not used: "
         "log det of a 9x9 symbolic matrix is expensive to differentiate, the problem has many equivalent optima "
         "(the cube's 48 symmetries), and E is not differentiable where eigenvalues coincide (at the symmetric "
         "schemes, which is where its optima lie).", ""]
    for crit in ("D", "A", "E"):
        print(f"criterion {crit} ...", file=sys.stderr)
        tab, planned = criterion_table(crit, BASE_NAMES, NS, args.random)
        L += [f"## Criterion {crit}, 9 parameters", ""] + tab + [""]
        if crit == "D":
            d_planned = planned
    L += ["## The 6-parameter model (angles fixed at 90 deg), criterion D", ""]
    tab, _ = criterion_table("D", SIX_NAMES, (6, 12, 24), args.random)
    L += tab + ["", "The 6 faces are D-optimal for 6 parameters; the flat 24-position scheme (6 faces x 4 turns) "
                "is the 6 faces repeated 4 times.", ""]
    L += ["## The 24-position scheme", "",
          "The common \"24 positions\" (a cube on each of its 6 faces, turned 4 times about the vertical) put gravity "
          "along only the 6 face normals: turning about the vertical does not move gravity in the sensor frame. "
          "The 9 parameters are not determined (the angles enter |a| only through products of two gravity "
          "components, which vanish on every face). imucal says so:", "",
          "    $ imucal plan-poses --scheme cube-24"]
    try:
        evaluate(scheme_directions("cube-24"), label="cube-24")
    except Exception as exc:  # ImucalError: the message the CLI prints
        L.append(f"    imucal: error: {exc}")
    p12, c12 = d_planned[12]
    p24, c24 = d_planned[24]
    wedge = next(o for o in c24.others if o.label == "wedge-24")
    L += ["", "and so does `imucal calibrate` (observability check) on such a recording. On a wedge (the same "
          "24 positions with the cube tilted 30.4 deg toward its face diagonals, `wedge-24`) the 24 directions are "
          f"distinct and the scheme has D-efficiency {wedge.d_efficiency(p24):.4f} relative to the planned 24 poses.",
          "", f"## Predicted standard errors (noise {NOISE} m/s^2 per mean, ideal sensor)", ""]
    designs = [p12] + [o for o in c12.others if o.label == "edges"] + [p24] + \
              [o for o in c24.others if o.label == "wedge-24"] + [o for o in d_planned[18][1].others
                                                                 if o.label == "faces+edges"]
    L += std_table(designs) + [""]
    L += ["For `imucal discover`, `--revisit` adds the hold order that holds every pose twice, the second pass "
          "in reverse (`[[Hold order]]` and `hold_order` in the JSON): effects in time and temperature are seen "
          "only by poses that come back at another time or temperature (docs/discover.md, \"Plan the holds for "
          "discovery\").", ""]
    L += ["## Planned 12 poses (D)", "", "    $ imucal plan-poses --n 12 --json plan.json", "",
          "| # | g_x | g_y | g_z |", "|---|---|---|---|"]
    for k, u in enumerate(p12.directions):
        L.append(f"| {k + 1} | {u[0]:+.4f} | {u[1]:+.4f} | {u[2]:+.4f} |")
    L += ["", "## Check by simulation", ""] + simulation_check(Path(args.mc_cache)) + [""]
    from imucal.files.output import write_text_atomic

    write_text_atomic(args.out, "\n".join(L) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
