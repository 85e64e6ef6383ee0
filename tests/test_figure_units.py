"""Every figure imucal draws is read at a glance: every visible axis has a label, and every axis
with a numeric scale carries its unit in square brackets ([m/s^2], [deg], [s], [1] for a pure
number, [#] for an index). The figure functions are found in the source (every function that
calls savefig), so a new figure cannot escape this test."""
from __future__ import annotations

import ast
import io
import functools
import re
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pytest
from matplotlib.figure import Figure

from imucal.analysis import drift, error_map
from imucal.analysis.discover import discover
from imucal.analysis.pose_instructions import instructions
from imucal.analysis.simulate import cube_directions, draw_effect_case
from imucal.config.run import config_from_dict
from imucal.report import discover_figures, figures, pose_figures
from imucal.report.figures import directions_figure

ROOT = Path(__file__).resolve().parents[1]
UNIT = re.compile(r"\[[^\[\]]+\]")
#: A tick label that is a number (also 10^{2} in mathtext, with a unicode minus).
NUMBER = re.compile(r"[-\u2212+0-9.,eE^{}\s$×]*")


def categorical(axis) -> bool:
    """Whether the axis is labelled with names (its tick labels are not numbers). Read after savefig,
    which draws the ticks."""
    texts = [t.get_text().replace("\\mathdefault", "") for t in axis.get_ticklabels()]
    return any(t and not NUMBER.fullmatch(t) for t in texts)


def figure_functions() -> set[str]:
    """module.function of every function in imucal that calls .savefig(...) or imucal.report.canvas's
    save_png(...) (the one that writes a figure: itself not a figure)."""
    found = set()
    for path in (ROOT / "imucal").rglob("*.py"):
        mod = ".".join(path.relative_to(ROOT).with_suffix("").parts)
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.FunctionDef) and any(
                    isinstance(c, ast.Call) and (isinstance(c.func, ast.Attribute) and c.func.attr == "savefig"
                                                 or isinstance(c.func, ast.Name) and c.func.id == "save_png")
                    for c in ast.walk(node)):
                found.add(f"{mod}.{node.name}")
    return found - {"imucal.report.canvas.save_png"}


@pytest.fixture
def drawn(monkeypatch):
    """Calls fn(*args) and returns the matplotlib Figures it saved."""
    saved: list[Figure] = []
    orig = Figure.savefig

    def record(self, *a, **k):
        saved.append(self)
        return orig(self, *a, **k)

    monkeypatch.setattr(Figure, "savefig", record)

    def draw(fn, *args, **kw) -> list[Figure]:
        start = len(saved)
        fn(*args[:1], io.BytesIO(), *args[1:], **kw)
        return saved[start:]

    return draw


def axis_problems(fig: Figure) -> list[str]:
    """Every visible axis without a label, or with a numeric scale but no [unit]."""
    bad = []
    title = fig._suptitle.get_text() if fig._suptitle else ""
    for ax in fig.axes:
        if not ax.get_visible() or not ax.axison:
            continue
        axes = [("x", ax.xaxis), ("y", ax.yaxis)] + ([("z", ax.zaxis)] if hasattr(ax, "zaxis") else [])
        labels = [(n, a.get_label_text().strip(), categorical(a)) for n, a in axes]
        if hasattr(ax, "_colorbar"):  # a colour bar: its one long axis is labelled
            if not any(UNIT.search(t) for _, t, _ in labels):
                bad.append(f"{title[:40]!r}: colour bar without a unit")
            continue
        for name, text, named in labels:
            where = f"{title[:40]!r} / {ax.get_title()[:40]!r} {name}-axis {text!r}"
            if not text:
                bad.append(where + ": no label")
            elif not named and not UNIT.search(text):
                bad.append(where + ": no [unit]")
    return bad


# --- the objects the figures are drawn from ----------------------------------------------------
@pytest.fixture(scope="module")
def discoveries(tmp_path_factory):
    """One discovery that adds an effect (temperature column), one clean without temperature."""
    tmp = tmp_path_factory.mktemp("figs")
    out = []
    for name, case in (("effect", draw_effect_case(7001, effect="bias_temperature", snr=80.0)),
                       ("clean", draw_effect_case(8001, effect=None, with_temperature=False))):
        p = tmp / f"{name}.csv"
        p.write_text(case.config.run().to_csv_text())
        out.append(discover(config_from_dict({"data": {"path": str(p), "unit": case.config.sensor.unit}})))
    assert out[0].effects and not out[1].effects  # both branches of the figures are drawn
    return out


def test_every_figure_function_is_checked(counts_run, discoveries, drawn):
    checked: dict[str, list[Figure]] = {}

    def check(fn, *args, **kw):
        checked.setdefault(f"{fn.__module__}.{fn.__name__}", []).extend(drawn(fn, *args, **kw))

    for fn in figures.FIGURES.values():
        check(fn, counts_run)
    check(figures.no_intervals_figure)  # a log without a still interval (an accelerometer taken from fit.base)
    for d in discoveries:
        for fn in discover_figures.FIGURES.values():
            check(fn, d)
    emap = error_map.compute_error_map(samples=20_000, seed=0)
    check(error_map.plot_histogram, emap, bins=20)
    check(error_map.plot_domains, emap, grid=4)
    rep = drift.DriftReport((drift.DriftCase("calibrated", 0.004, "RMS"), drift.DriftCase("raw", 0.2, "RMS")),
                            drift.table_times(60.0), 9.81)
    check(drift.plot_drift, rep, 60.0)
    dirs = np.vstack([cube_directions("faces+edges+corners")[:4], [[0.3, 0.5, 0.8]]])
    check(pose_figures.poses_figure, instructions(dirs / np.linalg.norm(dirs, axis=1, keepdims=True)))

    from imucal.fleet import report as fleet_report

    rows = [{"status": fleet_report.OK, "verdict": "pass" if k else "fail", "outlier": "", "raw_unit": "counts",
             **{n: 1.0 + 0.01 * k for n in fleet_report.HISTOGRAMS}} for k in range(12)]
    table = fleet_report.FleetTable(rows, None)
    def histogram(table, path, name):  # draw() passes the path second
        fleet_report.histogram(table, name, path)

    functools.update_wrapper(histogram, fleet_report.histogram)
    for name in ("s1", "b2", "theta", "rms_residual"):
        check(histogram, table, name)

    from imucal.report import thermal as thermal_report

    def residual_temperature(arrays, path):  # draw() passes the path second
        thermal_report.residual_temperature_figure(*arrays, path, "a temperature sweep")

    functools.update_wrapper(residual_temperature, thermal_report.residual_temperature_figure)
    r = np.random.default_rng(0).normal(0, 1e-3, (30, 3))
    check(residual_temperature, (np.linspace(5, 25, 30), r, r / 10, np.repeat([0, 1, 2], 10)))

    from imucal.analysis.still_noise import measure_noise
    from imucal.data.recording import Recording
    from imucal.report.noise import allan_figure

    rng = np.random.default_rng(3)
    n = 3000
    still = Recording(t=np.arange(n) / 100.0, raw=rng.normal(0, 1, (n, 3)), temp=None, unit="m/s^2", source="s",
                      sha256="", gyro=rng.normal(0, 1e-3, (n, 3)), gyro_unit="rad/s")
    check(allan_figure, measure_noise(still))

    assert set(checked) == figure_functions(), "a figure function is not checked here"
    problems = [p for figs in checked.values() for f in figs for p in axis_problems(f)]
    assert problems == []
    assert all(checked.values())  # each call saved a figure


def test_the_check_catches_an_axis_without_a_unit():
    fig, (a, b) = plt.subplots(1, 2)
    a.set_xlabel("time [s]")
    a.set_ylabel("acceleration")  # no unit
    b.set_xticks([0, 1])
    b.set_xticklabels(["base", "final"])
    b.set_xlabel("model")  # categorical: a label, no unit needed
    fig.savefig(io.BytesIO(), format="png")
    problems = axis_problems(fig)
    plt.close(fig)
    assert len(problems) == 2 and "'acceleration': no [unit]" in problems[0] and "'': no label" in problems[1]


def test_directions_figure_is_titled_labelled_and_numbered(counts_run, drawn):
    (fig,) = drawn(directions_figure, counts_run)
    assert "projection" in fig._suptitle.get_text()
    texts = [t.get_text() for ax in fig.axes for t in ax.texts]
    numbers = sorted(int(n) for t in texts if re.fullmatch(r"[\d,]+", t) for n in t.split(","))
    assert numbers == list(range(counts_run.intervals.n))  # every interval numbered once
    for ax in fig.axes:
        assert "[deg]" in ax.get_xlabel() and "[deg]" in ax.get_ylabel()
