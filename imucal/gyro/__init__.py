"""Gyroscope calibration from a multi-position recording (issue 11).

Model (``model``), motion segments between static intervals (``segments``), the g-sensitivity
selection on the static intervals (``gsens``), the rotation fit (``fit``), its typed result
(``result``) and a simulator with known truth (``simulate``).
"""
from imucal.gyro.fit import GyroOptions, fit_gyro
from imucal.gyro.result import GyroResult
from imucal.gyro.segments import GyroData, gyro_data_from_run

__all__ = ["GyroData", "GyroOptions", "GyroResult", "fit_gyro", "gyro_data_from_run"]
