"""Gyroscope calibration from a multi-position recording (issue 11).

Model (``model``), motion segments between static intervals (``segments``), the g-sensitivity
selection on the static intervals (``gsens``), the rotation fit (``fit``), its typed result
(``result``: the motions' summary the one result carries) and a simulator with known truth (``simulate``).

The names below load their module on first use (PEP 562), so importing ``imucal.gyro.model``
(the calibration file does) does not import the fit: `imucal calibrate` without a gyroscope
starts without it (tests/test_startup.py).
"""
from __future__ import annotations

import importlib
from typing import Any

_EXPORTS = {"GyroData": "segments", "GyroOptions": "fit", "MotionSummary": "result", "fit_gyro": "fit",
            "gyro_data_from_run": "segments"}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:
        return getattr(importlib.import_module(f"imucal.gyro.{_EXPORTS[name]}"), name)
    raise AttributeError(f"module 'imucal.gyro' has no attribute {name!r}")
