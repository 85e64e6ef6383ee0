"""The library without files: calibrate from arrays or a DataFrame, as a notebook user would.

>>> res = imucal.calibrate(acc, gyro, t=t, gravity=9.81744)     # doctest: +SKIP
>>> res.calibration.apply(acc[0])                                 # one (3,) sample  # doctest: +SKIP
>>> print(res.report())                                           # the CLI's report.txt  # doctest: +SKIP
>>> res.to_file("calibration.yaml")                               # doctest: +SKIP

The result is the run the command line builds (imucal.pipeline.CalibrationRun) with a few methods,
so the report, the files and the JSON summary are one call away, and the library and the command
line give one answer (tests/test_api.py). What the user must know about a fit is issued through
:mod:`warnings` as :class:`imucal.errors.ImucalWarning` (a notebook shows it; ``warnings.filterwarnings``
silences it); the steps of a run are logged at INFO on the ``imucal`` logger.
"""
from __future__ import annotations

import dataclasses
import hashlib
import logging
import os
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Union

import numpy as np

from imucal.config.run import RunConfig, config_from_dict
from imucal.constants import GYRO_UNIT_CHOICES
from imucal.data.recording import MAX_ABS_VALUE, Recording
from imucal.data.spec import DataSpec
from imucal.data.timebase import rate_time_base, stamped_times
from imucal.errors import ImucalError, ImucalWarning, check_choice
from imucal.pipeline import CalibrationRun, calibrate_imu

log = logging.getLogger("imucal")

#: What the arrays may be: a numpy array, a list of rows, or a pandas DataFrame / array-like.
ArrayLike = Union[np.ndarray, Sequence[Sequence[float]], Any]
#: DataFrame columns of each sensor, in axis order (as a CSV header names them).
FRAME_COLUMNS = {"acc": ("ax", "ay", "az"), "gyro": ("gx", "gy", "gz"), "mag": ("mx", "my", "mz")}


@dataclass(frozen=True)
class CalibrationResult(CalibrationRun):
    """A finished calibration: ``.calibration`` (the frozen, applicable calibration), ``.gyro``
    (the gyroscope's fit, or None), ``.intervals``, ``.result`` (the accelerometer's fit), and the
    methods below. It is a :class:`imucal.pipeline.CalibrationRun`, so every function that takes a
    run (``imucal.summary``, ``imucal.fit_report``) takes it."""

    @classmethod
    def of(cls, run: CalibrationRun) -> CalibrationResult:
        """The result of a pipeline run."""
        return cls(**{f.name: getattr(run, f.name) for f in dataclasses.fields(CalibrationRun)})

    @property
    def warnings(self) -> tuple[str, ...]:
        """What the user must know about the fit, one sentence each (also issued as ImucalWarning)."""
        return tuple(self.calibration.fit.get("warnings", ()))

    @property
    def success(self) -> bool:
        """Every fit converged (exit status 0 of ``imucal calibrate``)."""
        return (self.result.success and (self.gyro is None or self.gyro.success)
                and (self.mag is None or self.mag.fit.success))

    def report(self) -> str:
        """The text report, as ``imucal calibrate`` writes it into report.txt.

        Returns:
            Values with standard errors, correlations, the fit statistics and each sensor's section.
        """
        from imucal.report.text import fit_report

        return fit_report(self)

    def summary(self) -> dict[str, Any]:
        """The machine-readable summary, as ``imucal calibrate --json`` writes it.

        Returns:
            A JSON-ready mapping: parameters, standard errors, statistics, warnings, ``gyro``.
        """
        from imucal.report.text import summary

        return summary(self)

    def to_file(self, path: str | os.PathLike[str]) -> Path:
        """Write the calibration file of every sensor atomically.

        Args:
            path: where to write it (calibration.yaml; ``imucal.load_calibration`` reads it back).

        Returns:
            The path written.
        """
        self.calibration.save(path)
        return Path(path)

    def write(self, out: str | os.PathLike[str], figures: bool = True) -> list[Path]:
        """Write what ``imucal calibrate --out DIR`` writes, all files or none.

        Args:
            out: the folder (calibration.yaml, report.txt, report.html and the figures go into it).
            figures: also draw the PNG figures (report.html then shows them).

        Returns:
            The paths written.
        """
        from imucal.files.output import OutputSet, check_outputs
        from imucal.report.run_files import RunFiles, output_paths, stage_files

        folder = Path(out)
        paths = output_paths(folder, figures)
        check_outputs([], paths)
        with OutputSet() as o:
            stage_files(o, folder, RunFiles(run=self, text=self.report(), summary=self.summary()), figures)
        return [p for p in paths if p.exists()]


def _frame_columns(frame: Any, t: Any, temp: Any, gyro: Any, mag: Any) -> tuple[Any, Any, Any, Any, Any]:
    """A DataFrame's sensors by column name (ax.., gx.., mx.., t, temp); arrays pass through."""
    names = [str(c) for c in frame.columns]
    missing = [c for c in FRAME_COLUMNS["acc"] if c not in names]
    if missing:
        raise ImucalError(f"the DataFrame lacks column(s) {', '.join(missing)}", field="acc",
                          fix="name the accelerometer columns ax, ay, az (gx, gy, gz; mx, my, mz; t; temp)")

    def cols(kind: str) -> np.ndarray | None:
        have = [c for c in FRAME_COLUMNS[kind] if c in names]
        if not have:
            return None
        if len(have) != 3:
            raise ImucalError(f"the DataFrame has {', '.join(have)} but not all of "
                              f"{', '.join(FRAME_COLUMNS[kind])}", field=kind, fix="give all three axes or none")
        return frame[list(FRAME_COLUMNS[kind])].to_numpy(float)

    t = frame["t"].to_numpy(float) if t is None and "t" in names else t
    temp = frame["temp"].to_numpy(float) if temp is None and "temp" in names else temp
    gyro = cols("gyro") if gyro is None else gyro
    mag = cols("mag") if mag is None else mag
    return frame[list(FRAME_COLUMNS["acc"])].to_numpy(float), t, temp, gyro, mag


def _numbers(values: Any, name: str) -> np.ndarray:
    """``values`` as floats: text, complex numbers or flags refused in one line (numpy raised ValueError, or
    warned ComplexWarning and dropped the imaginary part)."""
    try:
        arr = np.asarray(values)
        if arr.dtype.kind in "iuf":
            return arr.astype(float)
        if arr.dtype.kind == "O":
            return arr.astype(float)  # None is NaN, refused as such; text raises
    except (TypeError, ValueError):
        pass
    raise ImucalError(f"{name} holds values that are not real numbers", field=name,
                      fix="give an array of floats (or integers)")


def _readings(values: Any, name: str, n: int | None = None) -> np.ndarray:
    """An (N, 3) finite array of one sensor's readings (N >= 3, or ``n`` rows), within the readers' +-MAX_ABS_VALUE."""
    raw = _numbers(values, name)
    if raw.ndim != 2 or raw.shape[1] != 3 or raw.shape[0] < 3:
        raise ImucalError(f"{name} must be an (N, 3) array with N >= 3, got shape {raw.shape}", field=name,
                          fix="give one row of three readings (x, y, z) per sample, at least 3 rows")
    if n is not None and raw.shape[0] != n:
        raise ImucalError(f"{name} has {raw.shape[0]} rows, acc has {n}", field=name,
                          fix="give one row per accelerometer sample (on its time base)")
    if not np.isfinite(raw).all():
        raise ImucalError(f"{name} holds NaN or Inf", field=name, fix="drop or repair those samples")
    if not (np.abs(raw) <= MAX_ABS_VALUE).all():
        raise ImucalError(f"{name} holds a value beyond +-{MAX_ABS_VALUE:g} (corrupt)", field=name,
                          fix="drop or repair those samples")
    return raw


def recording_from_arrays(acc: ArrayLike, t: Sequence[float] | np.ndarray | None = None,
                          temp: Sequence[float] | np.ndarray | None = None, fs: float | None = None,
                          unit: str = "raw", time_unit: str = "auto", name: str = "<arrays>", *,
                          gyro: ArrayLike | None = None, gyro_unit: str = "raw", mag: ArrayLike | None = None
                          ) -> Recording:
    """A recording built from arrays, checked as a file's would be.

    Args:
        acc: (N, 3) raw accelerometer readings, or a DataFrame with columns ax, ay, az (gx..gz, t, temp).
        t: N strictly increasing time stamps (unit inferred, or ``time_unit``); None: give ``fs``.
        temp: N temperatures [deg C], or None.
        fs: the sample rate [Hz]; beside ``t`` it is checked against the stamps.
        unit: the accelerometer's raw unit (a label: raw, m/s^2, ...).
        time_unit: the unit of ``t`` (auto, s, ms, us, ns, min).
        name: the recording's name in messages and reports.
        gyro: (N, 3) gyroscope readings on the same samples, or None.
        gyro_unit: the gyroscope's raw unit: raw (counts), deg/s or rad/s.
        mag: (N, 3) magnetometer readings on the same samples, or None.

    Returns:
        The Recording the pipeline reads.
    """
    if getattr(acc, "columns", None) is not None:
        acc, t, temp, gyro, mag = _frame_columns(acc, t, temp, gyro, mag)
    raw = _readings(acc, "acc")
    n = raw.shape[0]
    rates = None if gyro is None else _readings(gyro, "gyro", n)
    field = None if mag is None else _readings(mag, "mag", n)
    check_choice(gyro_unit, GYRO_UNIT_CHOICES, "gyro_unit", "gyro unit")
    DataSpec(path=name, sample_rate=fs, unit=unit, time_unit=time_unit)  # the same checks as a file
    if t is None:
        if fs is None:
            raise ImucalError("no time stamps and no sample rate", field="t", fix="pass t=... or fs=... [Hz]")
        stamps = None
        tu, note, tb = rate_time_base(fs)
        tt = np.arange(n) / float(fs)
    else:
        stamps = _numbers(t, "t")
        if stamps.shape != (n,) or not np.isfinite(stamps).all() or not (np.diff(stamps) > 0).all():
            raise ImucalError("t must be N finite, strictly increasing time stamps", field="t",
                              fix="give one finite time stamp per row of acc, increasing, or drop t and give fs")
        # the readers' time base: unit, jitter, gaps, and fs (when given too) checked against t
        tt, tu, note, tb = stamped_times(stamps, time_unit, fs, "t", Path(name))
    tc = None if temp is None else _numbers(temp, "temp")
    if tc is not None and tc.shape != (n,):
        raise ImucalError(f"temp must have {n} values, got shape {tc.shape}", field="temp",
                          fix="give one temperature per row of acc")
    sha = hashlib.sha256(np.ascontiguousarray(raw).tobytes()).hexdigest()
    return Recording(t=tt, raw=raw, temp=tc, unit=unit, source=name, sha256=sha, t_source=stamps,
                     time_unit=tu, time_note=note, time_base=tb, gyro=rates, mag=field,
                     gyro_unit="raw" if gyro_unit in ("auto", "counts") else gyro_unit)


def _fit_section(base: RunConfig, fix: Sequence[str] | Mapping[str, float], fix_angles: bool, mode: str | None,
                 weights: str | None, noise: str | os.PathLike[str] | None) -> dict[str, Any]:
    """The run file's ``fit:`` mapping: ``base``'s with the keywords given (checked as the YAML is)."""
    held = {str(n): v for n, v in fix.items()} if isinstance(fix, Mapping) else {}
    names = [*base.fit.fix, *(held or [str(n) for n in fix]), *(("phi", "psi", "theta") if fix_angles else ())]
    fit: dict[str, Any] = {"mode": mode or base.fit.mode, "weights": weights or base.fit.weights,
                           "angle_tolerance": base.fit.angle_tolerance, "fix": list(dict.fromkeys(names)),
                           "initial": {**base.fit.initial, **held},  # held AT a value: it starts there
                           "effects": [{"name": e.name, "axes": list(e.axes)} for e in base.fit.effects]}
    noise = base.fit.noise if noise is None else os.fspath(noise)
    return fit if noise is None else {**fit, "noise": noise}


def calibrate(acc: ArrayLike | RunConfig, gyro: ArrayLike | None = None, mag: ArrayLike | None = None, *,
              t: Sequence[float] | np.ndarray | None = None, temp: Sequence[float] | np.ndarray | None = None,
              fs: float | None = None, gravity: float | None = None, latitude: float | None = None,
              height: float = 0.0, unit: str = "raw", gyro_unit: str = "raw", time_unit: str = "auto",
              fix: Sequence[str] | Mapping[str, float] = (), fix_angles: bool = False, mode: str | None = None,
              weights: str | None = None, noise: str | os.PathLike[str] | None = None,
              mag_field: float | None = None, mag_field_unit: str | None = None,
              config: RunConfig | None = None) -> CalibrationResult:
    """Calibrate an IMU from its readings, as ``imucal calibrate`` does from a file.

    Args:
        acc: (N, 3) raw accelerometer readings, or a pandas DataFrame with columns ax, ay, az
            (and gx, gy, gz; mx, my, mz; t; temp, each taken when the keyword is not given), or a
            RunConfig (the YAML's typed form: the file it names is calibrated, as the CLI does).
        gyro: (N, 3) gyroscope readings on the accelerometer's time base: the gyroscope is
            calibrated too, into the same calibration.
        mag: (N, 3) magnetometer readings on the accelerometer's time base: the magnetometer is calibrated
            too (hard and soft iron, the rotation to the accelerometer's frame), into the same calibration.
        t: N time stamps (unit inferred, or ``time_unit``); or give ``fs`` instead.
        temp: N temperatures [deg C], for temperature effects.
        fs: the sample rate [Hz] (without ``t``; beside it, checked against the stamps).
        gravity: local g [m/s^2] (default: standard gravity, or the ``config``'s).
        latitude: [deg] for WGS84 normal gravity instead of ``gravity``.
        height: [m] above the ellipsoid, with ``latitude``.
        unit: the accelerometer's raw unit (label: raw, m/s^2, ...).
        gyro_unit: the gyroscope's raw unit: raw (counts: the scale is searched), deg/s or rad/s.
        time_unit: the unit of ``t``: auto (inferred and reported), s, ms, us, ns or min.
        fix: parameters held at their initial value (``["phi"]``), or at a value (``{"s1": 0.0}``).
        fix_angles: hold the three axis angles at 90 deg (the 6-parameter model).
        mode: fit interval ``"means"`` (default) or ``"samples"``.
        weights: ``"auto"`` (default), ``"noise"`` or ``"uniform"`` (as imu_tk).
        noise: a noise file (``imucal noise --json`` output or a Kalibr imu.yaml) for the interval
            means' noise (imucal.analysis.noise_model), as ``--noise`` and ``fit.noise``.
        mag_field: the local field's magnitude (e.g. 48.2 with ``mag_field_unit="uT"``: the WMM/IGRF value for
            the place); None: the ``config``'s ``mag:`` section, else fitted (the output in the sensor's unit).
        mag_field_unit: the unit of ``mag_field`` (uT, nT, gauss, mG ...; None: the sensor's).
        config: a RunConfig whose settings (static detection, effects, gyro and mag options) are used.

    Returns:
        A :class:`CalibrationResult`. Fit warnings are issued as :class:`imucal.errors.ImucalWarning`.

    Raises:
        ImucalError: bad input or a refused fit, with the field and the fix in its one-line message.
    """
    if isinstance(acc, RunConfig):
        return _finish(calibrate_imu(acc))
    if getattr(acc, "columns", None) is not None:
        acc, t, temp, gyro, mag = _frame_columns(acc, t, temp, gyro, mag)
    rec = recording_from_arrays(acc, t, temp, fs, unit, time_unit, gyro=gyro, gyro_unit=gyro_unit, mag=mag)
    base = config or config_from_dict({"data": {"path": rec.source}}, None)
    given: dict[str, Any] = {"data": {"path": rec.source, "unit": unit},
                             "fit": _fit_section(base, fix, fix_angles, mode, weights, noise)}
    grav = {k: v for k, v in (("value", gravity), ("latitude", latitude), ("height", height or None)) if v is not None}
    if grav:  # both, or a height without a latitude, are refused as in the YAML
        given["gravity"] = grav
    cfg = config_from_dict(given, None)
    cfg = dataclasses.replace(base, data=cfg.data, fit=cfg.fit,
                              gravity=cfg.gravity if "gravity" in given else base.gravity)
    if mag_field is not None or mag_field_unit is not None:  # checked as the YAML's mag: section is
        field = {"field": mag_field, "field_unit": mag_field_unit}
        cfg = dataclasses.replace(cfg, mag=config_from_dict({"data": {"path": rec.source}, "mag": {
            **{k: v for k, v in dataclasses.asdict(base.mag).items() if v is not None},
            **{k: v for k, v in field.items() if v is not None}}}, None).mag)
    log.info("calibrating %d samples (%s%s%s)", rec.n, "accelerometer", " and gyroscope" if gyro is not None else "",
             " and magnetometer" if mag is not None else "")
    return _finish(calibrate_imu(cfg, rec))


def _finish(run: CalibrationRun) -> CalibrationResult:
    """The result, its warnings issued (warnings module) and its outcome logged."""
    res = CalibrationResult.of(run)
    log.info("%d still intervals; accelerometer fit: %s in %d iterations%s", res.intervals.n, res.result.status,
             res.result.iterations, "" if res.gyro is None else f"; gyroscope fit: {res.gyro.status}")
    for w in res.warnings:
        warnings.warn(w, ImucalWarning, stacklevel=3)
    return res
