"""The calibration's figures are drawn at what matplotlib must spend (imucal.report.canvas): no
pyplot, no tight_layout pass, no mathtext; and with fixed margins no text leaves the figure."""
from __future__ import annotations

import io
import subprocess
import sys

import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from imucal.report import figures
from imucal.report.canvas import Margins, new_figure


@pytest.fixture
def saved(monkeypatch):
    """The Figures save_png drew, in order."""
    out: list[Figure] = []
    orig = Figure.savefig

    def record(self, *a, **k):
        out.append(self)
        return orig(self, *a, **k)

    monkeypatch.setattr(Figure, "savefig", record)
    return out


def outside(fig: Figure) -> list[str]:
    """The sides of the figure that its drawn content (texts, ticks, legends: what tight_layout and
    bbox_inches="tight" measure) crosses, by more than a pixel."""
    canvas = FigureCanvasAgg(fig)  # (a Figure made without pyplot has no Agg canvas of its own)
    canvas.draw()
    box = fig.get_tightbbox(canvas.get_renderer())  # [in]
    w, h = fig.get_size_inches()
    px = 1 / fig.dpi
    sides = {"left": box.x0 < -px, "bottom": box.y0 < -px, "right": box.x1 > w + px, "top": box.y1 > h + px}
    return [k for k, v in sides.items() if v]


def test_calibration_figures_keep_every_text_inside(counts_run, saved):
    for name, fn in figures.FIGURES.items():
        fn(counts_run, io.BytesIO())
        assert outside(saved[-1]) == [], name
    assert len(saved) == len(figures.FIGURES)


def test_the_check_sees_a_label_cut_off():
    fig, axes = new_figure(4, 3, Margins(left=0.05))
    axes[0, 0].set_ylabel("acceleration [m/s^2]")
    fig.savefig(io.BytesIO(), format="png")
    assert outside(fig) == ["left"]


def test_no_layout_pass_and_no_mathtext(counts_run, monkeypatch):
    import matplotlib.mathtext

    def refuse(*a, **k):
        raise AssertionError("a figure paid for a layout pass or a mathtext parse")

    monkeypatch.setattr(Figure, "tight_layout", refuse)
    monkeypatch.setattr(matplotlib.mathtext.MathTextParser, "parse", refuse)
    for fn in figures.FIGURES.values():
        fn(counts_run, io.BytesIO())


def test_figures_are_drawn_without_pyplot(counts_recording, tmp_path):
    code = ("import io, sys\n"
            "from imucal.config.run import config_from_dict\n"
            "from imucal.pipeline import calibrate_accelerometer\n"
            "from imucal.report.figures import FIGURES\n"
            f"run = calibrate_accelerometer(config_from_dict({{'data': {{'path': {str(counts_recording.path)!r}}}}}))\n"
            "for fn in FIGURES.values():\n"
            "    fn(run, io.BytesIO())\n"
            "print('matplotlib.pyplot' in sys.modules, 'matplotlib.figure' in sys.modules)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path, check=True)
    assert out.stdout.split() == ["False", "True"]


def test_fleet_histograms_keep_every_text_inside(saved):
    from imucal.fleet import report as fleet_report

    # values whose axes carry an offset or a power of ten beside their ticks (1e6 + ..., 1e-5 ...)
    scales = [1e6, -3e6, 16384.0, 1e-5, 0.1, 1.0, 1.5707, 1.5708, 1.5709, 2e-5]
    rows = [{"status": fleet_report.OK, "verdict": "pass" if k else "fail", "outlier": "", "raw_unit": "counts",
             **{n: v * (1.0 + 1e-5 * k) for n, v in zip(fleet_report.HISTOGRAMS, scales)}} for k in range(12)]
    table = fleet_report.FleetTable(rows, None)
    for name in fleet_report.HISTOGRAMS:
        fleet_report.histogram(table, name, io.BytesIO())
        assert outside(saved[-1]) == [], name
