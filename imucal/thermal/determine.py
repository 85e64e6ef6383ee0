"""What the poses of a temperature sweep determine, and what to record for what they do not.

An axis's reading in a still pose is s_i(T) + b_i(T) m_i, m_i its share of gravity (Eq. theModel
with the temperature terms of imucal.model.effects). Over a temperature change, a pose in which
the axis reads about 0 g shows its bias(T) alone; a pose in which it reads about g shows
bias(T) + g scale(T). Three one-axis-down poses (z, x, y along gravity) therefore give each axis
both: bias(T) from the two poses that hold it horizontal, scale(T) from the one that holds it
along gravity, each over that pose's temperature range. What no pose varies, the data cannot
tell: the words here name the pose and the range to record (``advice``), from the poses the
rows hold (``PoseSupport``). Whether a coefficient is determined is decided by its standard
error (imucal.thermal.select), not here.

Absolute bias and scale at the reference temperature are a separate matter: |a| = g (the base
fit) tells s_i from b_i only when axis i meets gravity in both directions (``one_sided``).
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from imucal.model.effects import AXIS_NAMES
from imucal.thermal.evidence import ThermalRows

#: A temperature coefficient's name: target, axis (imucal.model.effects: <target>_temperature[2|3]_<axis>).
_COEFFICIENT = re.compile(r"(bias|scale)_temperature[23]?_([xyz])\Z")
#: An axis reads "about g" in a pose when its share of gravity is above this, "about 0 g" below
#: LEVEL_ZERO (a pose tilted between the two shows both, mixed).
LEVEL_G, LEVEL_ZERO = 0.8, 0.3


@dataclass(frozen=True)
class PoseSupport:
    """Per sweeping pose: its axis shares of gravity and its temperature range."""

    poses: np.ndarray  #: pose indices
    share: np.ndarray  #: (P, 3) each axis's signed share of gravity in the pose (m_i / |m|)
    tmin: np.ndarray  #: (P,) [degC]
    tmax: np.ndarray  #: (P,)

    @classmethod
    def of(cls, rows: ThermalRows, vectors: np.ndarray, poses: np.ndarray) -> "PoseSupport":
        """From a fit's pose vectors (``vectors`` in the order of ``poses``), keeping the sweeping poses."""
        keep = np.isin(poses, rows.sweeping())
        v = vectors[keep]
        share = v / np.maximum(np.linalg.norm(v, axis=1, keepdims=True), 1e-300)
        spans = np.array([rows.span(int(p)) for p in poses[keep]]).reshape(-1, 2)
        return cls(poses[keep], share, spans[:, 0], spans[:, 1])

    def range_where(self, axis: int, along: bool) -> tuple[float, float] | None:
        """[degC] the temperature range over which axis ``axis`` is held about g (``along``) or about 0 g."""
        s = np.abs(self.share[:, axis])
        m = s >= LEVEL_G if along else s <= LEVEL_ZERO
        if not m.any():
            return None
        return float(self.tmin[m].min()), float(self.tmax[m].max())

    def describe(self) -> list[str]:
        """One line per pose: which axis is along gravity, over which range."""
        out = []
        for k, p in enumerate(self.poses):
            j = int(np.argmax(np.abs(self.share[k])))
            sign = "+" if self.share[k, j] > 0 else "-"
            out.append(f"pose {int(p)}: {AXIS_NAMES[j]} along {sign}g ({abs(self.share[k, j]):.3f}), "
                       f"{self.tmin[k]:.1f}..{self.tmax[k]:.1f} degC")
        return out


def advice(target: str, axis: int, support: PoseSupport) -> str:
    """What to record so that ``target`` (bias or scale) of ``axis`` over temperature is determined."""
    a = AXIS_NAMES[axis]
    along, level = support.range_where(axis, True), support.range_where(axis, False)
    where_g = f"{along[0]:.1f}..{along[1]:.1f} degC" if along else "no temperature range"
    where_0 = f"{level[0]:.1f}..{level[1]:.1f} degC" if level else "no temperature range"
    if target == "scale":
        return (f"axis {a} is held along gravity over {where_g} (and horizontal over {where_0}): hold the sensor "
                f"still with {a} along gravity (up or down) while the temperature sweeps the range to calibrate")
    return (f"axis {a} is held horizontal over {where_0}: hold the sensor still with {a} horizontal (another axis "
            "along gravity) while the temperature sweeps the range to calibrate")


def one_sided(directions: np.ndarray) -> list[int]:
    """Axes that meet gravity in one direction only among ``directions`` (unit, calibrated frame): their
    shift and scale at the reference temperature are not told apart by |a| = g."""
    out = []
    for i in range(3):
        d = directions[:, i]
        if not (d.max() > LEVEL_G and d.min() < -LEVEL_G):
            out.append(i)
    return out


def interval_advice(names: Sequence[str], directions: np.ndarray, temps: np.ndarray | None) -> str | None:
    """What to record for undetermined temperature coefficients of a fit on still intervals (|a| = g):
    the axis held along gravity (scale) or across it (bias) over a temperature change, with the
    range the intervals give now; None when no name is a temperature coefficient."""
    out = []
    for n in names:
        m = _COEFFICIENT.match(n)
        if m is None:
            continue
        target, axis = m.group(1), AXIS_NAMES.index(m.group(2))
        share = np.abs(directions[:, axis])
        sel = share >= LEVEL_G if target == "scale" else share <= LEVEL_ZERO
        have = (f"the intervals with it so span {np.min(temps[sel]):.1f}..{np.max(temps[sel]):.1f} degC"
                if temps is not None and sel.any() else "no interval holds it so")
        how = "along gravity (up or down)" if target == "scale" else "horizontal (another axis along gravity)"
        out.append(f"{n}: hold the sensor still with {AXIS_NAMES[axis]} {how} while the temperature changes over "
                   f"the range to calibrate ({have})")
    return "; ".join(out) or None
