"""imucal: MEMS accelerometer calibration with exact non-orthogonal axes.

Implements Nakov & Ivanov, "A Calibration Algorithm for Microelectromechanical Systems
Accelerometers in Inertial Navigation Sensors" (shared/seed). Heavy modules are imported
lazily so that ``imucal --help`` and small commands start fast.
"""
from __future__ import annotations

__version__ = "0.1.0"

_LAZY = {
    "Calibration": "imucal.calibration",
    "load_calibration": "imucal.calibration",
    "FitResult": "imucal.fit",
    "fit": "imucal.fit",
    "calibrate": "imucal.api",
    "recording_from_arrays": "imucal.api",
    "summary": "imucal.report",
    "fit_report": "imucal.report",
    "Recording": "imucal.data",
    "load_recording": "imucal.data",
    "detect_static": "imucal.static",
    "Intervals": "imucal.static",
    "Parameters": "imucal.parameters",
    "ImucalError": "imucal.errors",
    "normal_gravity": "imucal.gravity",
}


def __getattr__(name: str):
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'imucal' has no attribute {name!r}")


__all__ = ["__version__", *_LAZY]
