"""imucal: MEMS IMU calibration with exact non-orthogonal axes (Nakov & Ivanov, shared/seed).

The library in a few names (``from imucal import *`` gives exactly these):

- ``calibrate(acc, gyro=None, mag=None, *, t=..., fs=..., gravity=..., ...)``: calibrate from arrays
  or a pandas DataFrame (columns ax ay az, gx gy gz, t, temp), or from a ``RunConfig``; returns a
  ``CalibrationResult`` with ``.calibration``, ``.report()``, ``.to_file()``, ``.write()``.
- ``Calibration`` (``load_calibration(path)``): a frozen calibration that applies itself
  (``.apply(raw)``, ``.apply_imu(acc, gyro)``), saves itself and states its equation.
- ``load_config(path)`` / ``RunConfig``: the YAML run file as typed settings (what ``imucal calibrate
  CONFIG`` reads); ``load_recording``, ``Recording``, ``recording_from_arrays``: a recording.
- ``detect_static`` / ``Intervals``: the still intervals; ``fit`` / ``FitResult`` / ``Parameters``:
  the one least-squares fit; ``fit_report`` and ``summary``: a run as text and as the JSON summary.
- ``normal_gravity(latitude, height)``: WGS84 normal gravity [m/s^2].
- ``ImucalError``: bad input, one line naming file, field and fix; ``ImucalWarning``: what a user
  must know about a result (issued through :mod:`warnings`; the ``imucal`` logger logs the steps).

Names load on first use (PEP 562), so ``import imucal`` and ``imucal --version`` stay fast.
"""
from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

__version__ = "0.1.0"

#: Public name -> "module:attribute" (an attribute path may be dotted: a classmethod).
_LAZY = {
    "calibrate": "imucal.api:calibrate",
    "CalibrationResult": "imucal.api:CalibrationResult",
    "recording_from_arrays": "imucal.api:recording_from_arrays",
    "Calibration": "imucal.calibration.frozen:Calibration",
    "load_calibration": "imucal.calibration.frozen:load_calibration",
    "RunConfig": "imucal.config.run:RunConfig",
    "load_config": "imucal.config.run:load_config",
    "Recording": "imucal.data.recording:Recording",
    "load_recording": "imucal.data.load:load_recording",
    "detect_static": "imucal.data.static:detect_static",
    "Intervals": "imucal.data.static:Intervals",
    "FitResult": "imucal.solve.fit:FitResult",
    "fit": "imucal.solve.fit:fit",
    "Parameters": "imucal.model.parameters:Parameters",
    "fit_report": "imucal.report.text:fit_report",
    "summary": "imucal.report.text:summary",
    "normal_gravity": "imucal.model.gravity:normal_gravity",
    "ImucalError": "imucal.errors:ImucalError",
    "ImucalWarning": "imucal.errors:ImucalWarning",
}

__all__ = ["__version__", *_LAZY]

if TYPE_CHECKING:  # what the names are, for type checkers and editors (nothing is imported at run time)
    from imucal.api import CalibrationResult, calibrate, recording_from_arrays
    from imucal.calibration.frozen import Calibration, load_calibration
    from imucal.config.run import RunConfig, load_config
    from imucal.data.load import load_recording
    from imucal.data.recording import Recording
    from imucal.data.static import Intervals, detect_static
    from imucal.errors import ImucalError, ImucalWarning
    from imucal.model.gravity import normal_gravity
    from imucal.model.parameters import Parameters
    from imucal.report.text import fit_report, summary
    from imucal.solve.fit import FitResult, fit


def __getattr__(name: str) -> Any:
    """Load a public name on first use (PEP 562) and keep it, so the next access is plain."""
    if name not in _LAZY:
        raise AttributeError(f"module 'imucal' has no attribute {name!r}")
    module, _, path = _LAZY[name].partition(":")
    value: Any = importlib.import_module(module)
    for part in path.split("."):
        value = getattr(value, part)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    """The public names (loaded or not) and the subpackages already imported."""
    subpackages = {n for n, v in globals().items() if getattr(v, "__name__", "") == f"{__name__}.{n}"}
    return sorted({*__all__, *subpackages})
