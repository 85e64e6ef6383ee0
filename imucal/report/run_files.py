"""The files of one calibration run, shared by `imucal calibrate` and `imucal batch`.

``calibrate_files(config, gyro_file)`` fits the accelerometer and the gyroscope, when the
recording has one (imucal.pipeline.calibrate_imu: one calibration holding both), and builds the
report text, the HTML page and the JSON summary; ``stage_files`` puts calibration.yaml,
report.txt, report.html, the figures and the summary into an OutputSet, which publishes them
together or not at all.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from imucal.config.run import RunConfig
from imucal.data.load import other_sensors, use_stream
from imucal.errors import ImucalError
from imucal.files.output import OutputSet
from imucal.pipeline import CalibrationRun, calibrate_imu
from imucal.report.figures import FIGURES
from imucal.report.html import calibration_html, render_png
from imucal.report.text import fit_report, summary

if TYPE_CHECKING:
    from imucal.solve.fit import FitResult

CALIBRATION_FILE, REPORT_FILE, HTML_FILE = "calibration.yaml", "report.txt", "report.html"


@dataclass(frozen=True)
class RunFiles:
    """A finished run and the text and summary written for it."""

    run: CalibrationRun
    text: str  #: report.txt
    summary: dict  #: the JSON summary (--json)

    @property
    def gyro(self) -> FitResult | None:
        """The gyroscope fit; None when the recording has no gyroscope."""
        return self.run.gyro

    @property
    def success(self) -> bool:
        """Every fit converged (exit status 0 of `imucal calibrate`)."""
        return (self.run.result.success and (self.gyro is None or self.gyro.success)
                and (self.run.mag is None or self.run.mag.fit.success))


def output_paths(out: Path, figures: bool) -> list[Path]:
    """Every file ``stage_files`` may write into ``out``."""
    return [out / CALIBRATION_FILE, out / REPORT_FILE, out / HTML_FILE, *([out / n for n in FIGURES] if figures else [])]


def calibrate_files(config: RunConfig, gyro_file: str | Path | None = None) -> RunFiles:
    """Fit ``config``'s recording (and its gyroscope) and build the report and summary."""
    if use_stream(config.data, config.base_dir):
        others = ("gyroscope",) if gyro_file is not None else other_sensors(config.data, config.base_dir)
        if others:
            raise ImucalError(f"has {' and '.join(others)} data, which reading in chunks does not keep",
                              file=config.data.path, field="--stream",
                              fix="give --stream never (data.stream: never) to read it whole")
    run = calibrate_imu(config, gyro_file=None if gyro_file is None else str(gyro_file))
    return RunFiles(run=run, text=fit_report(run), summary=summary(run))


def stage_files(o: OutputSet, out: Path, files: RunFiles, figures: bool, json_path: str | Path | None = None) -> None:
    """Stage the run's files in ``out`` (and the summary at ``json_path``) into ``o``."""
    pngs = {name: render_png(fn, files.run) for name, fn in FIGURES.items()} if figures else {}
    o.call(out / CALIBRATION_FILE, files.run.calibration.save)
    o.text(out / REPORT_FILE, files.text)
    o.text(out / HTML_FILE, calibration_html(files.run, pngs))  # every sensor's section, in one form
    for name, png in pngs.items():
        o.bytes(out / name, png)
    if json_path is not None:
        o.json(json_path, files.summary)
