"""report.html in a real browser: Debian's chromium, headless, loads the page written by
`imucal calibrate`, with no console error or blocked resource, a screenshot that is not blank and
the fitted numbers in the rendered DOM. Skips with the reason when no chromium is installed
(.ci/run installs it: apt-get install chromium)."""
from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import matplotlib.image as mpimg
import pytest

from imucal.cli.main import main
from imucal.config.run import config_from_dict
from imucal.pipeline import calibrate_accelerometer

CHROMIUM = next((shutil.which(n) for n in ("chromium", "chromium-browser", "google-chrome") if shutil.which(n)),
                None)
pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="no chromium found (Debian: apt-get install chromium)")

#: Pixel standard deviation (0..1 per channel) below which a screenshot counts as blank.
BLANK_STD = 0.02
WINDOW = "1200,1800"
#: Set by `python scripts/update_docs.py screenshots`: the folder that receives this test's screenshot,
#: which the documentation shows (docs/images/report-desktop.png).
KEEP_SCREENSHOT = "IMUCAL_DOCS_SCREENSHOTS"


def _chromium(page: Path, tmp: Path, *args: str) -> subprocess.CompletedProcess:
    cmd = [CHROMIUM, "--headless", "--disable-gpu", "--no-sandbox", "--no-first-run", "--disable-extensions",
           f"--user-data-dir={tmp / 'profile'}", "--enable-logging=stderr", "--v=0", f"--window-size={WINDOW}",
           *args, page.resolve().as_uri()]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=60, cwd=tmp)


def _console_errors(stderr: str) -> list[str]:
    """Console messages (script errors, blocked or failed loads) and failed resource loads."""
    return [line for line in stderr.splitlines()
            if ":CONSOLE" in line or "net::ERR_" in line or "Failed to load resource" in line]


def _screenshot_std(png: Path) -> float:
    img = mpimg.imread(png)[..., :3]
    return float(img.std())


@pytest.fixture(scope="module")
def calibrated(counts_recording, tmp_path_factory):
    out = tmp_path_factory.mktemp("browser") / "out"
    assert main(["calibrate", "--data", str(counts_recording.path), "--out", str(out), "--quiet"]) == 0
    run = calibrate_accelerometer(config_from_dict({"data": {"path": str(counts_recording.path)}}))
    return out / "report.html", run


def test_report_loads_cleanly_and_shows_its_numbers(calibrated, tmp_path):
    page, run = calibrated
    shot = tmp_path / "shot.png"
    r = _chromium(page, tmp_path, f"--screenshot={shot}")
    assert shot.exists(), r.stderr[-2000:]
    assert _console_errors(r.stderr) == []
    assert _screenshot_std(shot) > BLANK_STD
    if os.environ.get(KEEP_SCREENSHOT):
        shutil.copyfile(shot, Path(os.environ[KEEP_SCREENSHOT]) / "report-desktop.png")
    d = _chromium(page, tmp_path, "--dump-dom")
    assert _console_errors(d.stderr) == []
    dom = d.stdout
    assert dom.count("<img") == 2
    for n, p in run.result.params.items():  # fitted values and their standard errors, as rendered
        assert f"{p.value:.10g}" in dom and f"{run.result.std[n]:.4g}" in dom, n
    assert f"{run.calibration.fit['rms_residual'] * 1e3:.4g} mm/s²" in dom
    assert ("PASS" in dom) or ("CHECK" in dom)


def test_the_screenshot_goes_to_the_docs_when_asked(calibrated, tmp_path, monkeypatch):
    """`python scripts/update_docs.py screenshots` sets the variable: the docs show this test's screenshot."""
    keep = tmp_path / "images"
    keep.mkdir()
    monkeypatch.setenv(KEEP_SCREENSHOT, str(keep))
    test_report_loads_cleanly_and_shows_its_numbers(calibrated, tmp_path)
    assert _screenshot_std(keep / "report-desktop.png") > BLANK_STD


def test_the_checks_catch_a_broken_page(calibrated, tmp_path):
    """The same checks fail on a page that loads something from elsewhere, and on a blank page."""
    page, _ = calibrated
    bad = tmp_path / "bad.html"
    bad.write_text(page.read_text(encoding="utf-8").replace(
        "</body>", '<img src="http://example.invalid/x.png"><img src="missing.png"></body>'), encoding="utf-8")
    r = _chromium(bad, tmp_path, "--dump-dom")
    assert len(_console_errors(r.stderr)) >= 1
    blank = tmp_path / "blank.html"
    blank.write_text("<!DOCTYPE html><html><body></body></html>", encoding="utf-8")
    shot = tmp_path / "blank.png"
    _chromium(blank, tmp_path, f"--screenshot={shot}")
    assert _screenshot_std(shot) < BLANK_STD


def test_the_fleet_page_loads_cleanly_and_shows_the_yield(tmp_path_factory, tmp_path):
    """`imucal batch`'s report.html: the same checks, and the yield and every unit in the DOM."""
    root = Path(__file__).resolve().parents[1]
    d = tmp_path_factory.mktemp("fleetpage")
    assert main(["simulate", str(root / "configs" / "simulate_fleet.yaml"), "--fleet", "6", "--defective", "1",
                 "--out", str(d / "sim")]) == 0
    assert main(["batch", str(d / "sim" / "manifest.yaml"), "--out", str(d / "res"), "--workers", "1"]) == 0
    page = d / "res" / "report.html"
    shot = tmp_path / "fleet.png"
    r = _chromium(page, tmp_path, f"--screenshot={shot}")
    assert shot.exists(), r.stderr[-2000:]
    assert _console_errors(r.stderr) == [] and _screenshot_std(shot) > BLANK_STD
    dom = _chromium(page, tmp_path, "--dump-dom").stdout
    assert "% pass" in dom and dom.count("<img") == 10  # nine parameters and the RMS, inline
    units = [p.name for p in (d / "res").iterdir() if p.is_dir()]
    assert len(units) == 6 and all(f"<td>{u}</td>" in dom for u in units)
