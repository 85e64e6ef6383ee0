"""Whether to integrate the motion segments from inside the still poses (``GyroOptions.lead_in_s="auto"``).

A static detector's window (0.5 s) can count a motion's first and last moments as still; the
segments between the detected intervals then miss that rotation. Integrating from ``LEAD_IN_S``
inside each pose recovers it, at the price of integrating the static model's residual bias for
2 ``LEAD_IN_S`` more per segment. That residual varies from pose to pose when the static means
depend on gravity and the fit leaves the g-sensitivity out (Xsens MTi: 2.2 mrad/s rms without,
0.66 with it), and the lead-in then costs more than it recovers (studies/results/gyro_lead_in.md). The rule:

1. the poses' edges turn: per pose, the rate integrated over its first and last ``LEAD_IN_S``
   (the pose's inner mean removed) has a mean square at least ``EDGE_RATIO`` times that of
   windows of the same length inside the pose (a still edge gives about 1);
2. the static model holds the g-sensitivity its test finds (imucal.gyro.gsens): gsens "auto" or
   "on", or "off" when the test keeps it on no axis.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from imucal.gyro.gsens import ALPHA, StaticFit, fit_static
from imucal.gyro.segments import GyroData
from imucal.solve.stats import median

#: [s] how far inside the poses the segments start and end when the rule says so
LEAD_IN_S = 0.5
#: edges' mean square integrated rate over inner windows' at and above which the edges turn
EDGE_RATIO = 4.0


@dataclass(frozen=True)
class EdgeMotion:
    """Integrated rate [raw unit x s] over the poses' edges against windows inside the poses."""

    edge_ms: float  #: mean square over edges and axes, each over its still-noise factor
    inner_ms: float  #: mean square over inner windows and axes, each over its still-noise factor
    n_edges: int
    n_windows: int

    @property
    def ratio(self) -> float:
        return self.edge_ms / self.inner_ms if self.inner_ms > 0 else float("inf")

    @property
    def turns(self) -> bool:
        return self.n_windows > 0 and self.ratio >= EDGE_RATIO


def edge_motion(data: GyroData, st: StaticFit, lead_in: float = LEAD_IN_S) -> EdgeMotion:
    """Edge and inner-window rotation of every pose at least 4 ``lead_in`` long (bias and G_s removed).

    Each squared sum is divided by its variance factor under still white noise, with the inner
    mean over N samples removed: n (1 + n/N) for an edge of n samples, n (1 - n/N) for an inner
    window (so a still pose gives a ratio near 1 however long it is).
    """
    dt = median(np.diff(data.t))
    n = max(int(round(lead_in / dt)), 1)
    rate = data.gyro - st.bias - data.acc @ st.H.T
    edges, inner = [], []
    for a, b in zip(data.start, data.end):
        if b - a < 4 * n:
            continue
        f = n / (b - a - 2 * n)
        m = rate[a + n:b - n].mean(0)
        edges += [np.square((rate[i:i + n] - m).sum(0) * dt) / (1 + f) for i in (a, b - n)]
        inner += [np.square((rate[k:k + n] - m).sum(0) * dt) / (1 - f) for k in range(a + n, b - 2 * n + 1, n)]
    ms = [float(np.mean(v)) if v else 0.0 for v in (edges, inner)]
    return EdgeMotion(ms[0], ms[1], len(edges), len(inner))


def lead_in_for(data: GyroData, gsens: str, lead_in: float | str, st: StaticFit | None = None) -> float:
    """The lead-in [s] a fit uses: ``lead_in`` when given in seconds, else the rule above."""
    if lead_in != "auto":
        return float(lead_in)
    if st is None:
        gm, _, am, _ = data.static_means()
        st = fit_static(gm, am, gsens)
    modelled = gsens != "off" or not np.any(st.p_value < ALPHA)
    return LEAD_IN_S if modelled and edge_motion(data, st).turns else 0.0
