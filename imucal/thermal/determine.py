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

from dataclasses import dataclass

import numpy as np

from imucal.model.effects import AXIS_NAMES
from imucal.thermal.evidence import ThermalRows

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
