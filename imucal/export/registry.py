"""Every calibration format both ways: name -> writer (`imucal export`) and name -> reader
(`imucal compare`). The formats live in their own modules (formats.py: imu_tk, mad-lab, matrix;
kalibr.py; autopilot.py; peers.py: the readers' shared checks); this module only names them, so
no format module imports another's dispatch (no import cycle).
"""
from __future__ import annotations

import re
from pathlib import Path
from typing import Any, Callable

from imucal.calibration.frozen import load_calibration
from imucal.calibration.frozen import Calibration
from imucal.errors import ImucalError, short
from imucal.export.autopilot import read_ardupilot_params, read_px4_params, to_ardupilot, to_px4
from imucal.export.formats import ExportOptions, Exported, to_imutk, to_madlab, to_matrix
from imucal.export.kalibr import read_kalibr_yaml, to_kalibr
from imucal.export.peers import read_imutk_calib, read_madlab_calibration, read_matrix, read_tomisuarez_params
from imucal.files.inputs import read_input_text

#: Format name -> (writer, what it is).
FORMATS: dict[str, tuple[Callable[[Calibration, ExportOptions], Exported], str]] = {
    "imutk": (to_imutk, "imu_tk .calib text (a = T K (raw - b)); the gyroscope in a second .calib"),
    "madlab": (to_madlab, "mad-lab-fau/imucal Ferraris JSON 2.0 (a = R_a^-1 K_a^-1 (raw - b_a), "
                          "gyr = R_g^-1 K_g^-1 (raw_g - K_ga a - b_g))"),
    "matrix": (to_matrix, "JSON matrix and offset (a = matrix raw + offset; omega = matrix raw_g + offset - "
                          "acc_matrix a); CSV when the file ends in .csv"),
    "kalibr": (to_kalibr, "Kalibr imu.yaml, scale-misalignment intrinsics (raw = M a + bias; "
                        "raw_g = M C_gyro_i omega + A C_gyro_i a + bias)"),
    "ardupilot": (to_ardupilot, "ArduPilot parameters INS_ACCOFFS/INS_ACCSCAL (a = (raw - offset) * scale), "
                              "INS_GYROFFS (omega = reading - offset)"),
    "px4": (to_px4, "PX4 parameters CAL_ACC0_*OFF/*SCALE (a = (raw - offset) * scale), CAL_GYRO0_*OFF "
                  "(omega = reading - offset)"),
}




def export(cal: Calibration, fmt: str, opts: ExportOptions = ExportOptions()) -> Exported:
    """The calibration in format ``fmt``, with what the format could not hold."""
    if fmt not in FORMATS:
        raise ImucalError(f"unknown format {fmt!r}", field="--format", fix=f"use one of {', '.join(FORMATS)}")
    return FORMATS[fmt][0](cal, opts)


def export_text(cal: Calibration, fmt: str, filename: str = "") -> str:
    """The calibration's text in format ``fmt`` (see :func:`export` for the notes)."""
    return export(cal, fmt, ExportOptions(filename=filename)).text


#: Format name -> reader. The same names as the export formats, plus imucal's own file.
READERS: dict[str, Callable[[str | Path], Any]] = {
    "imucal": load_calibration, "imutk": read_imutk_calib, "madlab": read_madlab_calibration,
    "matrix": read_matrix, "kalibr": read_kalibr_yaml, "ardupilot": read_ardupilot_params, "px4": read_px4_params,
    "tomisuarez": read_tomisuarez_params,
}

_IMUCAL_TAG = re.compile(r"^format:\s*imucal-calibration\s*$", re.M)


def guess_format(path: str | Path) -> str:
    """The format of a calibration file from its name (and, for .yaml/.json, a look at its text)."""
    p = str(path).lower()
    for end, fmt in ((".calib", "imutk"), (".param", "ardupilot"), (".parm", "ardupilot"),
                     (".params", "px4"), (".csv", "matrix")):
        if p.endswith(end):
            return fmt
    if p.endswith((".yaml", ".yml")):
        return "imucal" if _IMUCAL_TAG.search(read_input_text(path, field="calibration")) else "kalibr"
    if p.endswith(".json"):
        return "madlab" if '"cal_type"' in read_input_text(path, field="calibration") else "matrix"
    raise ImucalError("cannot tell the calibration format from the file name", file=str(path), field="--format",
                      fix=f"give --format, one of {', '.join(READERS)}")


def read_peer(path: str | Path, fmt: str | None = None) -> Any:
    """Any calibration file: imucal's own (a Calibration) or a peer's (an AffineCalibration)."""
    fmt = fmt or guess_format(path)
    if fmt not in READERS:
        raise ImucalError(f"unknown format {short(fmt)}", field="--format", fix=f"use one of {', '.join(READERS)}")
    return READERS[fmt](path)
