"""imucal: MEMS accelerometer calibration with exact non-orthogonal axes.

Implements Nakov & Ivanov, "A Calibration Algorithm for Microelectromechanical Systems
Accelerometers in Inertial Navigation Sensors" (shared/seed). Heavy modules are imported
lazily so that ``imucal --help`` and small commands start fast.
"""
from __future__ import annotations

__version__ = "0.1.0"

_LAZY = {
    "Calibration": "imucal.calibration.frozen",
    "load_calibration": "imucal.calibration.frozen",
    "FitResult": "imucal.solve.fit",
    "fit": "imucal.solve.fit",
    "calibrate": "imucal.api",
    "recording_from_arrays": "imucal.api",
    "summary": "imucal.report.text",
    "fit_report": "imucal.report.text",
    "Recording": "imucal.data.recording",
    "load_recording": "imucal.data.load",
    "detect_static": "imucal.data.static",
    "Intervals": "imucal.data.static",
    "Parameters": "imucal.model.parameters",
    "ImucalError": "imucal.errors",
    "normal_gravity": "imucal.model.gravity",
}


def __getattr__(name: str):
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'imucal' has no attribute {name!r}")


__all__ = ["__version__", *_LAZY]
