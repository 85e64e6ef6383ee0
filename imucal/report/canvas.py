"""Where a calibration figure is made and written: matplotlib's Figure on the Agg canvas.

matplotlib is imported only when a figure is made (docs/architecture.md), and never pyplot: a
figure drawn for a file needs no figure manager or backend switch. Three choices keep a figure
at what matplotlib must spend (measured on the Xsens report's four figures, bench_speed's parts):
- the layout is fixed margins in inches, sized for the figure's text (no tight_layout: it
  measures every text once more before the draw, about a quarter of a figure's time; tests check
  that no text leaves the figure);
- PNG at zlib level 1 (matplotlib's default, 6, spends some 0.1 s more on four figures for files
  about 7 % smaller);
- tick labels in plain text where matplotlib would typeset mathtext (imucal.report.canvas.plain_ticks).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

#: Resolution of every calibration figure [dots per inch]: about 1000 px across a 9-10 in figure.
DPI = 110
#: zlib level of the PNG files (0-9): 1 compresses four times faster than 6 for ~7 % larger files.
PNG_COMPRESS_LEVEL = 1


@dataclass(frozen=True)
class Margins:
    """Space around the axes grid [in], and between axes [fraction of an axes' width / height]."""

    left: float = 0.85  # y tick labels of up to 6 characters and the y label
    right: float = 0.2
    bottom: float = 0.6  # x tick labels and the x label
    top: float = 0.4  # one line of title
    wspace: float = 0.2
    hspace: float = 0.2


def new_figure(width: float, height: float, margins: Margins = Margins(), nrows: int = 1, ncols: int = 1,
               dpi: int = DPI, **subplots: Any) -> tuple["Figure", np.ndarray]:
    """A width x height [in] figure and its nrows x ncols axes (always a 2-D array), placed by margins."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), dpi=dpi)
    fig.subplots_adjust(left=margins.left / width, right=1 - margins.right / width,
                        bottom=margins.bottom / height, top=1 - margins.top / height,
                        wspace=margins.wspace, hspace=margins.hspace)
    return fig, fig.subplots(nrows, ncols, squeeze=False, **subplots)


def plain_ticks(ax: "Axes") -> None:
    """The y axis's major tick labels as plain numbers (1000, -10, 0.5): a log or symlog axis would
    typeset 10^3 with mathtext, whose parser costs more than the rest of the figure's text."""
    from matplotlib.ticker import FuncFormatter

    ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _pos: f"{v:g}"))


def save_png(fig: "Figure", path: str | Path | IO[bytes]) -> None:
    """Draw the figure and write it as PNG to a path or a binary file."""
    fig.savefig(path, format="png", pil_kwargs={"compress_level": PNG_COMPRESS_LEVEL})
