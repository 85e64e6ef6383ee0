"""The library without files: calibrate from arrays, as a notebook user would.

>>> run = imucal.calibrate(acc, t=t, gravity=9.81744)          # doctest: +SKIP
>>> run.calibration.apply(acc[0])                                # one (3,) sample  # doctest: +SKIP
>>> imucal.summary(run)                                          # the CLI's --json  # doctest: +SKIP

The run is the same object the command line builds (imucal.pipeline.CalibrationRun), so the
report, the files and the JSON summary are one call away.
"""
from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from imucal.config.run import GravitySpec, RunConfig, config_from_dict
from imucal.data.recording import Recording
from imucal.data.spec import DataSpec
from imucal.data.timebase import rate_time_base, stamped_times
from imucal.errors import ImucalError
from imucal.pipeline import CalibrationRun, calibrate as _calibrate_config
import dataclasses


def _columns(acc: Any, t: Any, temp: Any) -> tuple[np.ndarray, Any, Any]:
    """Accept a pandas DataFrame with columns ax, ay, az (t, temp optional) or plain arrays."""
    cols = getattr(acc, "columns", None)
    if cols is not None:
        names = [str(c) for c in cols]
        missing = [c for c in ("ax", "ay", "az") if c not in names]
        if missing:
            raise ImucalError(f"the DataFrame lacks column(s) {missing}", field="acc",
                              fix="name the accelerometer columns ax, ay, az")
        t = acc["t"].to_numpy(float) if t is None and "t" in names else t
        temp = acc["temp"].to_numpy(float) if temp is None and "temp" in names else temp
        acc = acc[["ax", "ay", "az"]].to_numpy(float)
    return np.asarray(acc, float), t, temp


def recording_from_arrays(acc: Any, t: Sequence[float] | None = None, temp: Sequence[float] | None = None,
                          fs: float | None = None, unit: str = "raw", time_unit: str = "auto",
                          name: str = "<arrays>") -> Recording:
    """A Recording from an (N, 3) array (or DataFrame) of raw readings, with time or a rate."""
    raw, t, temp = _columns(acc, t, temp)
    if raw.ndim != 2 or raw.shape[1] != 3 or raw.shape[0] < 3:
        raise ImucalError(f"acc must be an (N, 3) array with N >= 3, got shape {raw.shape}", field="acc")
    if not np.isfinite(raw).all():
        raise ImucalError("acc holds NaN or Inf", field="acc", fix="drop or repair those samples")
    DataSpec(path=name, sample_rate=fs, unit=unit, time_unit=time_unit)  # the same checks as a file
    n = raw.shape[0]
    if t is None:
        if fs is None:
            raise ImucalError("no time stamps and no sample rate", field="t", fix="pass t=... or fs=... [Hz]")
        stamps = None
        tu, note, tb = rate_time_base(fs)
        tt = np.arange(n) / float(fs)
    else:
        stamps = np.asarray(t, float)
        if stamps.shape != (n,) or not np.isfinite(stamps).all() or not (np.diff(stamps) > 0).all():
            raise ImucalError("t must be N finite, strictly increasing time stamps", field="t")
        # the readers' time base: unit, jitter, gaps, and fs (when given too) checked against t
        tt, tu, note, tb = stamped_times(stamps, time_unit, fs, "t", Path(name))
    tc = None if temp is None else np.asarray(temp, float)
    if tc is not None and tc.shape != (n,):
        raise ImucalError(f"temp must have {n} values, got shape {tc.shape}", field="temp")
    sha = hashlib.sha256(np.ascontiguousarray(raw).tobytes()).hexdigest()
    return Recording(t=tt, raw=raw, temp=tc, unit=unit, source=name, sha256=sha, t_source=stamps,
                     time_unit=tu, time_note=note, time_base=tb)


def calibrate(acc: Any, t: Sequence[float] | None = None, temp: Sequence[float] | None = None, *,
              fs: float | None = None, gravity: float | None = None, latitude: float | None = None,
              height: float = 0.0, unit: str = "raw", time_unit: str = "auto", fix_angles: bool = False,
              mode: str = "means", weights: str = "auto", noise: str | None = None,
              config: RunConfig | None = None) -> CalibrationRun:
    """Calibrate from arrays: ``acc`` (N, 3) raw readings (or a DataFrame with ax, ay, az[, t, temp]).

    ``noise``: a noise file (`imucal noise --json` output or a Kalibr imu.yaml) for the interval
    means' noise (imucal.analysis.noise_model), as ``--noise`` and ``fit.noise``.

    Also takes a RunConfig as the only argument (the YAML's typed form), as the CLI does.
    """
    if isinstance(acc, RunConfig):
        return _calibrate_config(acc)
    rec = recording_from_arrays(acc, t, temp, fs, unit, time_unit)
    base = config or config_from_dict({"data": {"path": rec.source}}, None)
    grav = base.gravity if gravity is None and latitude is None else GravitySpec(
        value=gravity, latitude=latitude, height=height)
    fit = base.fit
    if fix_angles or mode != "means" or weights != "auto" or noise is not None:
        fit = dataclasses.replace(fit, mode=mode, weights=weights, noise=noise if noise is not None else fit.noise,
                                  fix=tuple(sorted(set(fit.fix) | ({"phi", "psi", "theta"} if fix_angles else set()))))

    cfg = dataclasses.replace(base, data=DataSpec(path=rec.source, unit=unit), gravity=grav, fit=fit)
    return _calibrate_config(cfg, recording=rec)
