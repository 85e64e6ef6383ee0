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
    d = _chromium(page, tmp_path, "--dump-dom")
    assert _console_errors(d.stderr) == []
    dom = d.stdout
    assert dom.count("<img") == 4  # the recording, |a| - g before and after, residuals, directions
    for n, p in run.result.params.items():  # fitted values and their standard errors, as rendered
        assert f"{p.value:.10g}" in dom and f"{run.result.std[n]:.4g}" in dom, n
    assert f"{run.calibration.fit['rms_residual'] * 1e3:.4g} mm/s²" in dom
    assert ("PASS" in dom) or ("CHECK" in dom)


#: A desktop window: the page is laid out within this width, nothing wider than it (issue 29).
DESKTOP = (1280, 1600)
#: Measures the laid-out page in the browser (run on a copy of the page: the page itself runs no script):
#: the document's width, and every element wider than the window outside a scrolling table.
LAYOUT_PROBE = """<script>
addEventListener('load', () => {
  const w = innerWidth, out = [];
  for (const e of document.body.querySelectorAll('*')) {
    if (e.closest('.scroll') && !e.classList.contains('scroll')) continue;
    const r = e.getBoundingClientRect();
    if (r.right > w + 0.5 || r.left < -0.5) out.push(e.tagName + '#' + (e.id || '') + ' ' + Math.round(r.right));
  }
  const p = document.createElement('pre'); p.id = 'layout';
  p.textContent = JSON.stringify({width: w, scroll: document.documentElement.scrollWidth, wide: out});
  document.body.appendChild(p);
});
</script>"""


@pytest.fixture(scope="module")
def imu_page(tmp_path_factory) -> Path:
    """report.html of the shipped Xsens recording: accelerometer and gyroscope, with a poor accelerometer fit."""
    out = tmp_path_factory.mktemp("imu") / "out"
    cfg = Path(__file__).resolve().parents[1] / "configs" / "xsens-mti-imutk.yaml"
    assert main(["calibrate", str(cfg), "--out", str(out), "--quiet"]) == 0
    return out / "report.html"


def _layout(page: Path, tmp: Path) -> dict:
    import json

    probe = tmp / "probe.html"
    text = page.read_text(encoding="utf-8").replace("default-src 'none'", "default-src 'none'; script-src 'unsafe-inline'")
    probe.write_text(text.replace("</body>", LAYOUT_PROBE + "</body>"), encoding="utf-8")
    d = _chromium(probe, tmp, "--dump-dom", f"--window-size={DESKTOP[0]},{DESKTOP[1]}")
    start = d.stdout.index('<pre id="layout">') + len('<pre id="layout">')
    return json.loads(d.stdout[start:d.stdout.index("</pre>", start)].replace("&quot;", '"'))


def test_the_imu_page_loads_cleanly_within_a_desktop_window(imu_page, tmp_path):
    """Every sensor's verdict and section laid out within 1280 px, nothing overflowing (a wide table scrolls
    inside its box); the screenshot at desktop width is the one the docs show (KEEP_SCREENSHOT)."""
    shot = tmp_path / "desktop.png"
    r = _chromium(imu_page, tmp_path, f"--screenshot={shot}", f"--window-size={DESKTOP[0]},{DESKTOP[1]}")
    assert shot.exists() and _console_errors(r.stderr) == [], r.stderr[-2000:]
    assert _screenshot_std(shot) > BLANK_STD and mpimg.imread(shot).shape[1] == DESKTOP[0]
    layout = _layout(imu_page, tmp_path)
    assert layout["width"] == DESKTOP[0] and layout["scroll"] <= DESKTOP[0] and layout["wide"] == [], layout
    dom = _chromium(imu_page, tmp_path, "--dump-dom").stdout
    assert 'id="verdict-accelerometer"' in dom and 'id="verdict-gyroscope"' in dom and 'id="gyroscope"' in dom
    if os.environ.get(KEEP_SCREENSHOT):
        shutil.copyfile(shot, Path(os.environ[KEEP_SCREENSHOT]) / "report-desktop.png")


def test_the_layout_check_catches_an_overflow(imu_page, tmp_path):
    """The same measure finds an element wider than the window."""
    wide = tmp_path / "wide.html"
    wide.write_text(imu_page.read_text(encoding="utf-8").replace(
        "</body>", '<div id="toowide" style="width:2000px">x</div></body>'), encoding="utf-8")
    layout = _layout(wide, tmp_path)
    assert layout["scroll"] > DESKTOP[0] and any(w.startswith("DIV#toowide") for w in layout["wide"])


def test_the_screenshot_goes_to_the_docs_when_asked(imu_page, tmp_path, monkeypatch):
    """`python scripts/update_docs.py screenshots` sets the variable: the docs show this test's screenshot."""
    keep = tmp_path / "images"
    keep.mkdir()
    monkeypatch.setenv(KEEP_SCREENSHOT, str(keep))
    test_the_imu_page_loads_cleanly_within_a_desktop_window(imu_page, tmp_path)
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
