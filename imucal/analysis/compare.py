"""Two calibrations on the same still intervals: |a| - g per interval, RMS and max.

Both maps are applied to every sample of each still interval of one recording and the interval's
mean acceleration is compared with local gravity. |a| is frame-free, so calibrations whose
output frames differ by a rotation (every peer's) compare directly.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from imucal.data.recording import Recording
from imucal.data.static import Intervals
from imucal.errors import ImucalError
from imucal.model.channels import covariate_values


@dataclass(frozen=True)
class Comparison:
    names: tuple[str, str]
    gravity: float  #: [m/s^2]
    t_start: np.ndarray  #: [s]
    t_end: np.ndarray  #: [s]
    errors: np.ndarray  #: (n, 2): |mean a| - g per interval, one column per calibration [m/s^2]

    @property
    def rms(self) -> np.ndarray:
        return np.sqrt(np.mean(self.errors**2, axis=0))

    @property
    def max(self) -> np.ndarray:
        return np.max(np.abs(self.errors), axis=0)

    def table(self) -> str:
        w = max(22, *(len(n) + 2 for n in self.names))
        head = f"{'interval':>8}  {'t [s]':>15}  " + "  ".join(f"{n:>{w}}" for n in self.names)
        rows = [head, f"{'':>8}  {'':>15}  " + "  ".join(f"{'|a| - g [m/s^2]':>{w}}" for _ in self.names)]
        for i, (a, b, e) in enumerate(zip(self.t_start, self.t_end, self.errors), 1):
            rows.append(f"{i:>8}  {f'{a:.1f}..{b:.1f}':>15}  " + "  ".join(f"{x:>+{w}.5f}" for x in e))
        rows.append(f"{'RMS':>8}  {'':>15}  " + "  ".join(f"{x:>{w}.5f}" for x in self.rms))
        rows.append(f"{'max':>8}  {'':>15}  " + "  ".join(f"{x:>{w}.5f}" for x in self.max))
        return "\n".join(rows)

    def to_dict(self) -> dict[str, Any]:
        return {"gravity": self.gravity, "unit": "m/s^2", "names": list(self.names),
                "rms": dict(zip(self.names, map(float, self.rms))),
                "max": dict(zip(self.names, map(float, self.max))),
                "intervals": [{"t_start": float(a), "t_end": float(b), "errors": dict(zip(self.names, map(float, e)))}
                              for a, b, e in zip(self.t_start, self.t_end, self.errors)]}


def calibrated(cal: Any, rec: Recording, idx: np.ndarray) -> np.ndarray:
    """Acceleration [m/s^2] of samples ``idx`` by ``cal`` (a Calibration with its covariates, or
    any peer map with ``apply(raw)``)."""
    covs = getattr(cal, "covariates", ())
    if not covs:
        return cal.apply(rec.raw[idx])
    given = covariate_values(covs, temp=None if rec.temp is None else rec.temp[idx], time=rec.t[idx],
                             source=rec.source, what="the calibration")
    return cal.apply(rec.raw[idx], given)


def compare(first: Any, second: Any, rec: Recording, iv: Intervals, gravity: float,
            names: tuple[str, str] = ("first", "second")) -> Comparison:
    """|mean a| - g on every still interval of ``rec`` for both calibrations."""
    if iv.n == 0:
        raise ImucalError("no still intervals found", file=rec.source, field="data",
                          fix="give the calibration recording (several still poses)")
    err = np.empty((iv.n, 2))
    for i in range(iv.n):
        idx = np.arange(iv.start[i], iv.end[i])
        for j, cal in enumerate((first, second)):
            err[i, j] = np.linalg.norm(calibrated(cal, rec, idx).mean(axis=0)) - gravity
    return Comparison(names=names, gravity=float(gravity), t_start=np.asarray(iv.t_start, float),
                      t_end=np.asarray(iv.t_end, float), errors=err)
