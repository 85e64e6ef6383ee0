"""A measured noise model for the fit's weights: `imucal noise --json` output or a Kalibr imu.yaml.

An interval mean's noise is otherwise its own scatter over sqrt(n) (imucal.data.static), which a
short interval estimates poorly (its variance has n - 1 degrees of freedom, and correlated noise
needs the batch-means factor). From a long still log's Allan deviation (imucal.analysis.noise):

    sigma_mean^2 = N^2 fs / n  +  (FLICKER_FACTOR B)^2          per axis [raw^2]

N the white-noise density [unit/sqrt(Hz)] (N sqrt(fs) is the per-sample white noise, divided by
sqrt(n) for a mean of n samples), B the bias instability: the Allan deviation's flat floor
sigma_min = FLICKER_FACTOR B, added only when the curve shows one (its minimum lies at half its
longest tau or earlier, so it turns up over an octave; a curve falling to its end has none).
A rows-of-samples fit uses the per-sample white noise N sqrt(fs). Densities in m/s^2 are
converted to the raw unit by the scale b_i [raw per m/s^2] of each axis (the ellipsoid guess;
the angles are near 90 deg, so raw axis i sees a_i b_i). The random walk is drift over the
whole log, not noise of one mean: not used here (fit a drift effect for it).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from imucal.analysis.noise import FLICKER_FACTOR
from imucal.errors import ImucalError, short
from imucal.export.kalibr import KALIBR_FIELDS
from imucal.export.peers import _json, _keys, number
from imucal.files.yamlio import read_yaml

CALIBRATED = "m/s^2"
#: Fields of `imucal noise --json` (imucal.cli.commands.noise) and of each of its axes.
NOISE_JSON_FIELDS = ("unit", "source", "segment", "rate_hz", "axes", "allan", "kalibr")
AXIS_FIELDS = ("white_density", "white_rel_err", "random_walk", "random_walk_rel_err", "bias_instability",
               "bias_instability_rel_err", "tau_min")
FIX = "pass the JSON `imucal noise --json` writes, or a Kalibr imu.yaml"


@dataclass(frozen=True)
class NoiseModel:
    """Per-axis white-noise density and bias-instability floor, in ``unit``."""

    white_density: np.ndarray  #: (3,) [unit/sqrt(Hz)]
    floor: np.ndarray  #: (3,) Allan deviation floor FLICKER_FACTOR B [unit]; 0 where none was seen
    unit: str
    source: str

    def in_raw(self, raw_unit: str, scale: np.ndarray) -> "NoiseModel":
        """The model in the recording's raw unit: as is when the units agree, else (m/s^2) times
        each axis's scale b_i [raw per m/s^2]."""
        if self.unit == raw_unit:
            return self
        if self.unit != CALIBRATED:
            raise ImucalError(f"unit {short(self.unit)} is neither the recording's raw unit {raw_unit!r} nor "
                              f"{CALIBRATED}", file=self.source, field="unit",
                              fix="run `imucal noise` on the sensor's raw log (or with --calibration for m/s^2)")
        b = np.abs(np.asarray(scale, float))
        return NoiseModel(self.white_density * b, self.floor * b, raw_unit, self.source)

    def mean_variance(self, n: np.ndarray, rate: float) -> np.ndarray:
        """(k, 3) variance of the mean of ``n`` samples at ``rate`` Hz [unit^2] (module docstring)."""
        n = np.asarray(n, float)[:, None]
        return self.white_density**2 * rate / n + self.floor**2

    def sample_variance(self, count: int, rate: float) -> np.ndarray:
        """(count, 3) white-noise variance of single samples at ``rate`` Hz [unit^2]."""
        return np.tile(self.white_density**2 * rate, (count, 1))


def _positive(v: Any, path: str, where: str) -> float:
    x = number(v, path, where)
    if not x > 0:
        raise ImucalError(f"{short(v)} must be positive", file=path, field=where, fix=FIX)
    return x


def _optional(v: Any, path: str, where: str) -> float | None:
    return None if v is None else _positive(v, path, where)


def _from_noise_json(d: Any, path: str) -> NoiseModel:
    d = _keys(d, ("unit", "axes"), NOISE_JSON_FIELDS, path, "imucal noise's JSON")
    if not isinstance(d["unit"], str) or not d["unit"]:
        raise ImucalError(f"{short(d['unit'])} is not a unit name", file=path, field="unit", fix=FIX)
    axes = _keys(d["axes"], ("x", "y", "z"), ("x", "y", "z"), path, "the axes section", "axes")
    taus = (d.get("allan") or {}).get("tau_s") if isinstance(d.get("allan"), Mapping) else None
    tau_end = max(number(t, path, "allan.tau_s") for t in taus) if isinstance(taus, list) and taus else math.inf
    white, floor = np.zeros(3), np.zeros(3)
    for j, a in enumerate("xyz"):
        ax = _keys(axes[a], ("white_density",), AXIS_FIELDS, path, "an axis's noise terms", f"axes.{a}")
        white[j] = _positive(ax["white_density"], path, f"axes.{a}.white_density")
        for k in AXIS_FIELDS[1:]:
            if ax.get(k) is not None and k != "tau_min":
                _positive(ax[k], path, f"axes.{a}.{k}")
        b, tmin = ax.get("bias_instability"), _optional(ax.get("tau_min"), path, f"axes.{a}.tau_min")
        if b is not None and tmin is not None and tmin <= tau_end / 2:  # turns up over an octave or more
            floor[j] = FLICKER_FACTOR * _positive(b, path, f"axes.{a}.bias_instability")
    return NoiseModel(white, floor, d["unit"], path)


def _from_kalibr(d: Any, path: str) -> NoiseModel:
    if isinstance(d, dict) and len(d) == 1 and isinstance(next(iter(d)), str) and next(iter(d)).startswith("imu"):
        d = next(iter(d.values()))  # Kalibr's result files nest the IMU under imu0
    d = _keys(d, ("accelerometer_noise_density",), KALIBR_FIELDS, path, "a Kalibr imu.yaml")
    nd = _positive(d["accelerometer_noise_density"], path, "accelerometer_noise_density")
    return NoiseModel(np.full(3, nd), np.zeros(3), CALIBRATED, path)


def load_noise_model(path: str | Path) -> NoiseModel:
    """The noise model in ``path``: `imucal noise --json` output (.json) or a Kalibr imu.yaml."""
    p = str(path)
    if p.lower().endswith(".json"):
        return _from_noise_json(_json(p, "noise"), p)
    if p.lower().endswith((".yaml", ".yml")):
        return _from_kalibr(read_yaml(p, "noise", FIX), p)
    raise ImucalError("is neither .json (imucal noise --json) nor .yaml (Kalibr imu.yaml)", file=p,
                      field="noise", fix=FIX)
