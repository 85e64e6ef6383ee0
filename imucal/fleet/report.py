"""The fleet report: one row per unit (parameters, standard errors, RMS, status), pass/fail
against the manifest's tolerances, the yield, robust outliers, and a histogram per parameter.

An outlier is a unit whose parameter sits far from the fleet's distribution even when its own
fit is fine: robust z = 0.6745 (x - median) / MAD above OUTLIER_Z on any parameter, over the
units that converged (the median and MAD are not pulled by the outliers themselves).
"""
from __future__ import annotations

import contextlib
import csv
import io
import math
import threading
from dataclasses import dataclass
from typing import Mapping
from pathlib import Path

import numpy as np

from imucal.fleet.manifest import Tolerances
from imucal.files.output import OutputSet
from imucal.fleet.parquet import parquet_writer
from imucal.fleet.run import ERROR, INTERNAL, NOT_CONVERGED, OK
from imucal.model.parameters import ANGLE_NAMES, BASE_NAMES
from imucal.report.page import esc, figures_html, num, page_html, table_html

#: Robust z-score above which a parameter marks its unit as an outlier.
OUTLIER_Z = 5.0
#: 0.6745 = the normal distribution's 75 % quantile: MAD / 0.6745 estimates sigma.
MAD_SIGMA = 0.6745
#: Fewest converged units for outlier flags (a median of fewer says little).
MIN_UNITS_FOR_OUTLIERS = 5
REPORT_CSV, REPORT_PARQUET, REPORT_TEXT = "fleet.csv", "fleet.parquet", "fleet.txt"
#: the fleet's page (imucal.report.html), beside each unit's own report.html in its folder
REPORT_HTML = "report.html"

#: Derived columns checked against tolerances: the zero-g reading [m/s^2] and angle offset [deg].
BIAS_COLS = ("bias_x", "bias_y", "bias_z")
ANGLE_DEV_COLS = tuple(f"{a}_from_90_deg" for a in ANGLE_NAMES)
COLUMNS = ("unit", "status", "verdict", "outlier", "reasons", "error", *BASE_NAMES,
           *(f"std_{n}" for n in BASE_NAMES), *BIAS_COLS, *ANGLE_DEV_COLS, "rms_residual", "rms_residual_samples",
           "redchi", "n_intervals", "raw_unit", "seconds", "cpu_seconds", "skipped", "input_sha256", "settings_hash")


@dataclass(frozen=True)
class FleetTable:
    rows: list[dict]
    tolerances: Tolerances

    @property
    def n(self) -> int:
        return len(self.rows)

    def count(self, key: str, value: object) -> int:
        return sum(r[key] == value for r in self.rows)

    @property
    def yield_fraction(self) -> float:
        """Units that pass, over all units (errors count as failures)."""
        return self.count("verdict", "pass") / self.n if self.n else float("nan")


def _row(rec: dict) -> dict:
    row = {c: None for c in COLUMNS}
    row.update(unit=rec["unit"], status=rec["status"], error=rec.get("error") or "",
               seconds=rec.get("seconds"), cpu_seconds=rec.get("cpu_seconds"), skipped=bool(rec.get("skipped")),
               input_sha256=" ".join(f"{k}:{v}" for k, v in (rec.get("input_sha256") or {}).items()),
               settings_hash=rec.get("settings_hash"))
    s = rec.get("summary")
    if not s:
        return row
    p, sd = s["params"], s["std"]
    values = {**{f"s{i+1}": p["s"][i] for i in range(3)}, **{f"b{i+1}": p["b"][i] for i in range(3)},
              **{a: p[a] for a in ANGLE_NAMES}}
    stds = {**{f"s{i+1}": sd["s"][i] for i in range(3)}, **{f"b{i+1}": sd["b"][i] for i in range(3)},
            **{a: sd[a] for a in ANGLE_NAMES}}
    row.update(values)
    row.update({f"std_{n}": stds[n] for n in BASE_NAMES})
    # raw = s + b m (the paper's model): a zero-g reading of s_i, i.e. s_i / b_i in m/s^2
    row.update({c: values[f"s{i+1}"] / values[f"b{i+1}"] for i, c in enumerate(BIAS_COLS)})
    row.update({c: math.degrees(values[a]) - 90.0 for c, a in zip(ANGLE_DEV_COLS, ANGLE_NAMES)})
    row.update(rms_residual=s["rms_residual"], rms_residual_samples=s["rms_residual_samples"],
               redchi=s["redchi"], n_intervals=s["n_intervals"], raw_unit=s["raw_unit"])
    for e in s.get("effects", []):
        row.update(e["coefficients"])
    row.update(_mag_columns(s.get("mag")))
    return row


def _mag_columns(mag: dict | None) -> dict:
    """A unit's magnetometer (its summary's ``mag``, imucal.report.text): the hard iron [raw], the field-norm
    residual after [% of the field], the dip scatter after [deg] and the rotation beyond the mounting [deg]."""
    if not mag:
        return {}
    f = mag["fit"]
    out = {f"mag_s{i}": mag["params"][f"s{i}"] for i in (1, 2, 3)}
    out["mag_norm_residual_pct"] = f["norm_residual_pct"]["after"]
    out["mag_dip_scatter_deg"] = f.get("dip_scatter_deg", {}).get("after")
    out["mag_misalignment_deg"] = f["misalignment_deg"]
    return out


def _tolerance_misses(row: dict, tol: Tolerances) -> list[str]:
    out = []
    if tol.bias_abs_max is not None:
        out += [f"|{c}| {abs(row[c]):.3g} > {tol.bias_abs_max:g} m/s^2" for c in BIAS_COLS
                if not abs(row[c]) <= tol.bias_abs_max]
    if tol.angle_deg_from_90_max is not None:
        out += [f"|{c}| {abs(row[c]):.3g} > {tol.angle_deg_from_90_max:g} deg" for c in ANGLE_DEV_COLS
                if not abs(row[c]) <= tol.angle_deg_from_90_max]
    if tol.rms_max is not None and not row["rms_residual"] <= tol.rms_max:
        out.append(f"rms {row['rms_residual']:.3g} > {tol.rms_max:g} m/s^2")
    for i in (1, 2, 3):
        b = row[f"b{i}"]
        if tol.scale_min is not None and not b >= tol.scale_min:
            out.append(f"b{i} {b:.6g} < {tol.scale_min:g}")
        if tol.scale_max is not None and not b <= tol.scale_max:
            out.append(f"b{i} {b:.6g} > {tol.scale_max:g}")
    return out


def robust_z(x: np.ndarray) -> np.ndarray:
    """0.6745 (x - median) / MAD; zeros where the MAD is 0 (a held or constant parameter)."""
    med = np.median(x)
    mad = np.median(np.abs(x - med))
    return np.zeros_like(x) if mad == 0 else MAD_SIGMA * (x - med) / mad


def fleet_table(records: list[dict], tolerances: Tolerances) -> FleetTable:
    """Rows with verdicts and outlier flags, in the records' order."""
    rows = [_row(r) for r in records]
    good = [r for r in rows if r["status"] == OK]
    flags: dict[str, list[str]] = {r["unit"]: [] for r in rows}
    if len(good) >= MIN_UNITS_FOR_OUTLIERS:
        for n in BASE_NAMES:
            z = robust_z(np.array([r[n] for r in good], float))
            for r, zi in zip(good, z):
                if abs(zi) > OUTLIER_Z:
                    flags[r["unit"]].append(f"{n} z={zi:+.1f}")
    for r in rows:
        if r["status"] != OK:
            r["verdict"] = "fail"
            r["reasons"] = r["status"]
        else:
            misses = _tolerance_misses(r, tolerances)
            r["verdict"] = "fail" if misses else "pass"
            r["reasons"] = "; ".join(misses)
        r["outlier"] = "; ".join(flags[r["unit"]])
    return FleetTable(rows=rows, tolerances=tolerances)


def _columns(table: FleetTable) -> list[str]:
    extra = [k for r in table.rows for k in r if k not in COLUMNS]
    return [*COLUMNS, *dict.fromkeys(extra)]


def to_csv(table: FleetTable) -> str:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=_columns(table), lineterminator="\n")
    w.writeheader()
    for r in table.rows:
        w.writerow({k: ("" if v is None else repr(v) if isinstance(v, float) else v) for k, v in r.items()})
    return buf.getvalue()


def load_writers(figures: bool) -> threading.Thread:
    """Load the report's writers in a thread, while the units run: pyarrow's JSON reader and Parquet
    writer (fleet.parquet, imucal.fleet.parquet: no pandas), matplotlib for the histograms. Their
    loading is most of a batch's fixed cost; it runs beside the units; join the thread before the
    report is written."""
    def load() -> None:
        with contextlib.suppress(ImportError):
            import pyarrow.json  # noqa: F401
            import pyarrow.parquet  # noqa: F401
        if figures:
            import matplotlib.figure  # noqa: F401 - what imucal.report.canvas draws with
            import matplotlib.backends.backend_agg  # noqa: F401

    thread = threading.Thread(target=load, name="imucal-report-writers")
    thread.start()
    return thread


def histogram(table: FleetTable, name: str, path: Path) -> None:
    """Histogram of one column over the converged units, outliers and failures marked."""
    from imucal.report.canvas import Margins, new_figure, save_png

    ok = [r for r in table.rows if r["status"] == OK and r[name] is not None]
    x = np.array([r[name] for r in ok], float)
    bad = np.array([r[name] for r in ok if r["verdict"] == "fail" or r["outlier"]], float)
    fig, axes = new_figure(6, 3.6, Margins(top=0.15), dpi=HISTOGRAM_DPI)
    ax = axes[0, 0]
    ax.hist(x, bins=min(40, max(5, int(np.sqrt(max(x.size, 1))) * 2)), color="#4477aa", alpha=0.85,
            label=f"{x.size} converged units")
    if bad.size:
        ax.plot(bad, np.zeros_like(bad), "v", color="#cc3311", ms=9, label=f"{bad.size} failing or outlier")
    raw = next((str(r["raw_unit"]) for r in ok if r.get("raw_unit")), "raw")
    unit = {"phi": "rad", "psi": "rad", "theta": "rad", "rms_residual": "m/s^2"}.get(
        name, raw if name.startswith("s") else f"{raw}/(m/s^2)")
    ax.set_xlabel(f"{name} [{unit}]")
    ax.set_ylabel("units calibrated [#]")
    ax.legend(fontsize=8)
    save_png(fig, path)


#: Resolution of the fleet's histograms [dots per inch]: 600 x 360 px, ten of them on the page.
HISTOGRAM_DPI = 100
#: Columns with a histogram: the nine parameters and the fit's RMS.
HISTOGRAMS = (*BASE_NAMES, "rms_residual")


def summary_text(table: FleetTable) -> str:
    """The printed summary: counts, yield, tolerances, failures and outliers (one line each)."""
    n, t = table.n, table.tolerances.given()
    lines = [f"fleet: {n} units: {table.count('status', OK)} calibrated, "
             f"{table.count('status', NOT_CONVERGED)} not converged, {table.count('status', ERROR)} refused, "
             f"{table.count('status', INTERNAL)} internal errors ({sum(r['skipped'] for r in table.rows)} "
             "skipped: already done)",
             f"yield: {table.count('verdict', 'pass')}/{n} = {100 * table.yield_fraction:.1f} % pass"
             + (" (" + ", ".join(f"{k} {v:g}" for k, v in t.items()) + ")" if t else " (no tolerances given)"),
             f"outliers (robust z > {OUTLIER_Z:g}): {sum(bool(r['outlier']) for r in table.rows)}"]
    for r in table.rows:
        if r["verdict"] == "fail" or r["outlier"]:
            why = r["error"] if r["status"] != OK and r["error"] else r["reasons"]
            lines.append(f"  {r['unit']}: {r['verdict']}" + (f": {why}" if why else "")
                         + (f" | outlier: {r['outlier']}" if r["outlier"] else ""))
    return "\n".join(lines) + "\n"


#: The fleet table's columns shown on the page, with units (COLUMNS).
FLEET_NUMBERS = (("bias_x", "m/s²"), ("bias_y", "m/s²"), ("bias_z", "m/s²"), ("phi_from_90_deg", "deg"),
                 ("psi_from_90_deg", "deg"), ("theta_from_90_deg", "deg"), ("rms_residual", "m/s²"))


def _fleet_verdict(table: FleetTable) -> str:
    n, passed = table.n, table.count("verdict", "pass")
    level = "pass" if n and passed == n else ("fail" if passed == 0 else "check")
    tol = table.tolerances.given()
    rows = [["units", str(n)], ["calibrated", str(table.count("status", OK))],
            ["refused (bad input)", str(table.count("status", ERROR))],
            ["not converged", str(table.count("status", NOT_CONVERGED))],
            ["internal errors", str(table.count("status", INTERNAL))],
            [f"outliers (robust z > {OUTLIER_Z:g} against the fleet)", str(sum(bool(r["outlier"]) for r in table.rows))],
            ["tolerances", esc(", ".join(f"{k} {v:g}" for k, v in tol.items()) or "none given")]]
    return (f'<section class="verdict {level}" id="verdict"><h2>yield {passed}/{n} = '
            f"{num(100 * table.yield_fraction, '.1f')} % pass</h2>"
            + table_html(["", ""], rows, [False, True]) + "</section>")


def _fleet_rows(rows: list[dict]) -> str:
    head = ["unit", "status", "verdict", "outlier", "why"] + [f"{esc(c)} [{u}]" for c, u in FLEET_NUMBERS]
    cells = [[esc(r["unit"]), esc(r["status"]), esc(r["verdict"]), esc(r["outlier"] or ""),
              esc(r["error"] if r["status"] != OK and r["error"] else r["reasons"] or "")]
             + [num(r.get(c), ".4g") if isinstance(r.get(c), (int, float)) else "n/a" for c, _ in FLEET_NUMBERS]
             for r in rows]
    return table_html(head, cells, [False] * 5 + [True] * len(FLEET_NUMBERS),
                  ["out" if r["verdict"] == "fail" or r["outlier"] else "" for r in rows])


def fleet_html(table: FleetTable, figures: Mapping[str, bytes] | None = None, title: str = "imucal fleet") -> str:
    """The page of ``imucal batch``: the yield first, then the units that fail or stand out, every
    unit, and the histograms of the parameters across the fleet."""
    flagged = [r for r in table.rows if r["verdict"] == "fail" or r["outlier"]]
    sections = [("verdict", "", _fleet_verdict(table)),
                ("flagged", "Units that fail a tolerance, were refused or stand out",
                 _fleet_rows(flagged) if flagged else "<p>None.</p>"),
                ("units", "Every unit", _fleet_rows(table.rows)),
                ("figures", "Parameters across the fleet", figures_html(figures or {}, {}))]
    return page_html(f"{title}: {table.n} units", sections)


def write_report(table: FleetTable, out: Path, inputs: list[str], figures: bool = True) -> list[Path]:
    """fleet.csv, fleet.parquet (with pyarrow), fleet.txt and fleet_<column>.png, published together."""
    written = [out / REPORT_CSV, out / REPORT_TEXT, out / REPORT_HTML]
    pngs = {}
    if figures and table.count("status", OK):  # the same PNGs go on the page and beside it
        for name in HISTOGRAMS:
            buf = io.BytesIO()
            histogram(table, name, buf)
            pngs[f"fleet_{name}.png"] = buf.getvalue()
    with OutputSet(inputs) as o:
        o.text(out / REPORT_CSV, to_csv(table))
        o.text(out / REPORT_TEXT, summary_text(table))
        o.text(out / REPORT_HTML, fleet_html(table, pngs))
        pq = parquet_writer(table.rows, _columns(table))
        if pq is not None:
            o.call(out / REPORT_PARQUET, pq)
            written.append(out / REPORT_PARQUET)
        for name, png in pngs.items():
            o.bytes(out / name, png)
            written.append(out / name)
    return written
