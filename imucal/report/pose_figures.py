"""A drawing of the board per planned pose (PNG): the board as a box with its X, Y, Z axes, the
table below it and gravity pointing down, each titled with its plain-language instruction."""
from __future__ import annotations

import math
import textwrap
from itertools import product
from pathlib import Path
from typing import IO, Sequence

import numpy as np

from imucal.analysis.pose_instructions import PoseInstruction, board_rotation

#: Board half-sizes along its X, Y, Z axes (a flat board, so faces are told apart at a glance).
HALF = np.array([1.0, 0.65, 0.14])
AXIS_COLOURS = ("tab:red", "tab:green", "tab:blue")
#: Colour of each face, by (axis, sign): the +Z face (the top of the board) stands out.
FACE_COLOURS = {(0, 1): "#f4c7c3", (0, -1): "#e6a8a3", (1, 1): "#cfe8cc", (1, -1): "#aed3a9",
                (2, 1): "#bcd4f0", (2, -1): "#8fa9c8"}
COLUMNS = 6


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _box_faces(R: np.ndarray) -> list[tuple[np.ndarray, str]]:
    """The six faces of the board in world coordinates, with their colours."""
    out = []
    for ax in range(3):
        for sign in (1, -1):
            o = [i for i in range(3) if i != ax]
            corners = []
            for a, b in ((1, 1), (1, -1), (-1, -1), (-1, 1)):
                p = np.zeros(3)
                p[ax] = sign * HALF[ax]
                p[o[0]] = a * HALF[o[0]]
                p[o[1]] = b * HALF[o[1]]
                corners.append(R @ p)
            out.append((np.array(corners), FACE_COLOURS[(ax, sign)]))
    return out


def draw_pose(ax, inst: PoseInstruction, number: int) -> None:
    """One pose on a 3-D Axes: the board, its axes, the table and gravity."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    R = board_rotation(inst.up)
    corners = np.array(list(product((-1, 1), repeat=3))) * HALF
    low = float((corners @ R.T)[:, 2].min())  # the table touches the lowest corner
    table = np.array([[-1.3, -1.3, low], [1.3, -1.3, low], [1.3, 1.3, low], [-1.3, 1.3, low]])
    ax.add_collection3d(Poly3DCollection([table], facecolor="0.88", edgecolor="0.7", alpha=0.6))
    for corners, colour in _box_faces(R):
        ax.add_collection3d(Poly3DCollection([corners], facecolor=colour, edgecolor="k", linewidths=0.5,
                                             alpha=0.9))
    for i in range(3):
        v = R @ (np.eye(3)[i] * (HALF[i] + 0.55))
        ax.quiver(0, 0, 0, *v, color=AXIS_COLOURS[i], linewidth=1.6, arrow_length_ratio=0.2)
        ax.text(*(v * 1.15), f"+{'XYZ'[i]}", color=AXIS_COLOURS[i], fontsize=8, fontweight="bold")
    ax.quiver(1.1, 1.1, low + 2.1, 0, 0, -0.9, color="k", linewidth=1.4, arrow_length_ratio=0.25)
    ax.text(1.15, 1.1, low + 1.5, "g", fontsize=9)
    ax.set_xlim(-1.2, 1.2)
    ax.set_ylim(-1.2, 1.2)
    ax.set_zlim(low, low + 2.4)
    ax.set_box_aspect((1, 1, 1))
    ax.view_init(elev=22, azim=-58)
    ax.set_axis_off()
    ax.set_title(f"Pose {number}\n" + textwrap.fill(inst.text, 40), fontsize=7.5, pad=-4)


def poses_figure(insts: Sequence[PoseInstruction], path: str | Path | IO[bytes], title: str = "") -> None:
    """A grid of drawings, one per pose, numbered from 1 as in the plan."""
    plt = _plt()
    n = len(insts)
    cols = min(COLUMNS, max(n, 1))
    rows = max(1, math.ceil(n / cols))
    fig = plt.figure(figsize=(2.7 * cols, 3.4 * rows + 0.7), dpi=90)
    for k, inst in enumerate(insts):
        ax = fig.add_subplot(rows, cols, k + 1, projection="3d")
        draw_pose(ax, inst, k + 1)
    fig.suptitle((title + "\n" if title else "") + "Board axes +X red, +Y green, +Z blue; the grey plane is the "
                 "table, g points down; tilts are right-handed about the named board axis", fontsize=9)
    top = 1 - 0.7 / (3.4 * rows + 0.7)
    fig.subplots_adjust(left=0.0, right=1.0, bottom=0.0, top=top - 0.045, wspace=0.0, hspace=0.25)
    fig.savefig(path, format="png")
    plt.close(fig)
