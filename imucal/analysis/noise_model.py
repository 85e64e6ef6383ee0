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
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from imucal.analysis.noise import FLICKER_FACTOR
from imucal.errors import ImucalError, short
from imucal.files.inputs import read_json
from imucal.files.schema import fill, rule
from imucal.files.yamlio import read_yaml

CALIBRATED = "m/s^2"
FIX = "pass the JSON `imucal noise --json` writes, or a Kalibr imu.yaml"
#: The noise a model gives the interval means may differ from the means' own noise (their scatter,
#: imucal.data.static) by at most this factor either way (median over intervals and axes). A noise
#: file in another unit misses by the units' ratio (9.81 for g, 1000 for mg, thousands for counts);
#: the same sensor measured on another day, or held by hand, stays well within it.
NOISE_UNIT_FACTOR = 5.0


@dataclass(frozen=True)
class NoiseModel:
    """Per-axis white-noise density and bias-instability floor, in ``unit``."""

    white_density: np.ndarray  #: (3,) [unit/sqrt(Hz)]
    floor: np.ndarray  #: (3,) Allan deviation floor FLICKER_FACTOR B [unit]; 0 where none was seen
    unit: str
    source: str
    measured_in: str = ""  #: the noise file's own unit, when the model was converted from it (in_raw)

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
        return NoiseModel(self.white_density * b, self.floor * b, raw_unit, self.source, self.unit)

    def check_scale(self, n: np.ndarray, mean_std: np.ndarray, rate: float, data: str | None,
                    data_unit: str) -> None:
        """Refuse a model whose noise of the interval means (``n`` samples each at ``rate`` Hz) is
        not the data's own (``mean_std``, (k, 3), in the raw unit) within NOISE_UNIT_FACTOR: it
        was measured in another unit than the recording's."""
        own = np.asarray(mean_std, float)
        ok = own > 0
        if not ok.any():
            return
        ratio = float(np.median(np.sqrt(self.mean_variance(n, rate))[ok] / own[ok]))
        if 1 / NOISE_UNIT_FACTOR <= ratio <= NOISE_UNIT_FACTOR:
            return
        density = own * np.sqrt(np.asarray(n, float)[:, None] / rate)  # the white density the data imply
        mine = self.measured_in or self.unit
        labels = f"both labelled {mine}" if mine == data_unit else f"noise file: {mine}, data.unit: {data_unit}"
        raise ImucalError(
            f"its noise of an interval mean is {ratio:.3g} times the noise the recording {data or ''} shows at "
            f"rest (median over {int(np.count_nonzero(ok.any(axis=1)))} still intervals; white density "
            f"{np.median(self.white_density):.3g} {self.unit}/sqrt(Hz) from the noise file, "
            f"{np.median(density[ok]):.3g} {data_unit}/sqrt(Hz) in the data): the noise file is in another unit "
            f"than the recording ({labels})",
            file=self.source, field="unit",
            fix="measure the noise on a still log in the recording's unit (imucal noise --data STILL_LOG), "
                "or set data.unit to the unit its readings are in")

    def mean_variance(self, n: np.ndarray, rate: float) -> np.ndarray:
        """(k, 3) variance of the mean of ``n`` samples at ``rate`` Hz [unit^2] (module docstring)."""
        n = np.asarray(n, float)[:, None]
        return self.white_density**2 * rate / n + self.floor**2

    def sample_variance(self, count: int, rate: float) -> np.ndarray:
        """(count, 3) white-noise variance of single samples at ``rate`` Hz [unit^2]."""
        return np.tile(self.white_density**2 * rate, (count, 1))


_POSITIVE = rule(gt=0, fix=FIX)


@dataclass(frozen=True)
class AxisNoise:
    """One axis of `imucal noise --json` (imucal.analysis.noise.NoiseEstimate's fields)."""

    white_density: float = field(metadata=_POSITIVE)
    white_rel_err: float | None = field(default=None, metadata=_POSITIVE)
    random_walk: float | None = field(default=None, metadata=_POSITIVE)
    random_walk_rel_err: float | None = field(default=None, metadata=_POSITIVE)
    bias_instability: float | None = field(default=None, metadata=_POSITIVE)
    bias_instability_rel_err: float | None = field(default=None, metadata=_POSITIVE)
    tau_min: float | None = field(default=None, metadata=_POSITIVE)


@dataclass(frozen=True)
class NoiseAxes:
    x: AxisNoise
    y: AxisNoise
    z: AxisNoise


@dataclass(frozen=True)
class AllanSection:
    tau_s: tuple[float, ...] = field(default=(), metadata=_POSITIVE)
    adev: Any = None  #: (taus, 3) Allan deviation; not read


@dataclass(frozen=True)
class NoiseJson:
    """What `imucal noise --json` writes (imucal.cli.commands.noise)."""

    unit: str = field(metadata=rule(min_len=1, msg="{value} is not a unit name", fix=FIX))
    axes: NoiseAxes
    source: str | None = None
    segment: str | None = None
    rate_hz: float | None = None
    allan: AllanSection | None = None
    kalibr: Mapping[str, float | None] | None = None
    gyro: Any = None  #: the gyroscope's noise (same fields); not read: the fit's noise is the accelerometer's


@dataclass(frozen=True)
class KalibrNoiseFile:
    """The noise part of a Kalibr imu.yaml; its intrinsics may be present and are not read here."""

    accelerometer_noise_density: float = field(metadata=_POSITIVE)
    accelerometer_random_walk: float | None = field(default=None, metadata=_POSITIVE)
    gyroscope_noise_density: float | None = field(default=None, metadata=_POSITIVE)
    gyroscope_random_walk: float | None = field(default=None, metadata=_POSITIVE)
    update_rate: float | None = field(default=None, metadata=_POSITIVE)
    rostopic: str | None = None
    model: Any = None
    accelerometers: Any = None
    gyroscopes: Any = None
    T_i_b: Any = None
    time_offset: Any = None
    imucal_accelerometer_offset: Any = None
    imucal_gyroscope_offset: Any = None


def _from_noise_json(d: Any, path: str) -> NoiseModel:
    f = fill(NoiseJson, d, path)
    tau_end = max(f.allan.tau_s) if f.allan is not None and f.allan.tau_s else math.inf
    white, floor = np.zeros(3), np.zeros(3)
    for j, ax in enumerate((f.axes.x, f.axes.y, f.axes.z)):
        white[j] = ax.white_density
        b, tmin = ax.bias_instability, ax.tau_min
        if b is not None and tmin is not None and tmin <= tau_end / 2:  # turns up over an octave or more
            floor[j] = FLICKER_FACTOR * b
    return NoiseModel(white, floor, f.unit, path)


def _from_kalibr(d: Any, path: str) -> NoiseModel:
    if isinstance(d, dict) and len(d) == 1 and isinstance(next(iter(d)), str) and next(iter(d)).startswith("imu"):
        d = next(iter(d.values()))  # Kalibr's result files nest the IMU under imu0
    nd = fill(KalibrNoiseFile, d, path).accelerometer_noise_density
    return NoiseModel(np.full(3, nd), np.zeros(3), CALIBRATED, path)


def load_noise_model(path: str | Path) -> NoiseModel:
    """The noise model in ``path``: `imucal noise --json` output (.json) or a Kalibr imu.yaml."""
    p = str(path)
    if p.lower().endswith(".json"):
        return _from_noise_json(read_json(p, "noise"), p)
    if p.lower().endswith((".yaml", ".yml")):
        return _from_kalibr(read_yaml(p, "noise", FIX), p)
    raise ImucalError("is neither .json (imucal noise --json) nor .yaml (Kalibr imu.yaml)", file=p,
                      field="noise", fix=FIX)
