"""The files of one calibration run, shared by `imucal calibrate` and `imucal batch`.

``calibrate_files(config, gyro_file)`` fits the accelerometer (and the gyroscope, when the
recording has one) and builds the report text and the JSON summary; ``stage_files`` puts
calibration.yaml, report.txt, gyro.yaml, the figures and the summary into an OutputSet, which
publishes them together or not at all.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import yaml

from imucal.config.run import RunConfig
from imucal.files.output import OutputSet
from imucal.gyro.result import GyroResult
from imucal.gyro.run import calibrate_gyro
from imucal.pipeline import CalibrationRun, calibrate
from imucal.report.figures import FIGURES
from imucal.report.text import fit_report, summary

CALIBRATION_FILE, REPORT_FILE, GYRO_FILE = "calibration.yaml", "report.txt", "gyro.yaml"


@dataclass(frozen=True)
class RunFiles:
    """A finished run and the text and summary written for it."""

    run: CalibrationRun
    gyro: GyroResult | None  #: None when the recording has no gyroscope
    text: str  #: report.txt
    summary: dict  #: the JSON summary (--json)

    @property
    def success(self) -> bool:
        """Both fits converged (exit status 0 of `imucal calibrate`)."""
        return self.run.result.success and (self.gyro is None or self.gyro.success)


def output_paths(out: Path, figures: bool) -> list[Path]:
    """Every file ``stage_files`` may write into ``out`` (gyro.yaml only when there is a gyroscope)."""
    return [out / CALIBRATION_FILE, out / REPORT_FILE, out / GYRO_FILE, *([out / n for n in FIGURES] if figures else [])]


def calibrate_files(config: RunConfig, gyro_file: str | Path | None = None) -> RunFiles:
    """Fit ``config``'s recording (and its gyroscope) and build the report and summary."""
    run = calibrate(config)
    text = fit_report(run)
    gyro = calibrate_gyro(run, None if gyro_file is None else str(gyro_file))
    js = summary(run)
    if gyro is not None:
        text += "[[Gyroscope]]  (provisional: apply and codegen do not use it yet)\n" + gyro.report() + "\n"
        js["gyro"] = gyro.to_dict()
    return RunFiles(run=run, gyro=gyro, text=text, summary=js)


def stage_files(o: OutputSet, out: Path, files: RunFiles, figures: bool, json_path: str | Path | None = None) -> None:
    """Stage the run's files in ``out`` (and the summary at ``json_path``) into ``o``."""
    o.call(out / CALIBRATION_FILE, files.run.calibration.save)
    o.text(out / REPORT_FILE, files.text)
    if figures:
        for name, fn in FIGURES.items():
            o.call(out / name, lambda p, fn=fn: fn(files.run, p))
    if files.gyro is not None:
        o.text(out / GYRO_FILE, yaml.safe_dump({"format": "imucal-gyro-calibration", "format_version": 0,
                                                **files.gyro.to_dict()}, sort_keys=False))
    if json_path is not None:
        o.json(json_path, files.summary)
