"""report.html (imucal.report.html): one self-contained page, verdict first, every number with its
unit, figures inline, user text escaped; written by calibrate and discover beside their outputs."""
from __future__ import annotations

import base64
import html
import io
import math
import re
import shutil
from dataclasses import replace

import matplotlib.image as mpimg
import numpy as np
import pytest

from imucal.analysis.simulate import PosePlan, cube_directions, mems_counts_sensor, simulate
from imucal.cli.main import main
from imucal.config.run import config_from_dict
from imucal.pipeline import calibrate_accelerometer
from imucal.report.html import calibration_html
from imucal.report.verdict import chi2_consistent, verdict
from imucal.solve.stats import chi2_sf

#: A file name an attacker could choose: markup, an entity, a quote and matplotlib's mathtext marker.
EVIL = 'evil<script>alert(1)<img src=x onerror=alert(2)>&"$x_$.csv'


def _images(page: str) -> list[bytes]:
    return [base64.b64decode(m) for m in re.findall(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"', page)]


@pytest.fixture(scope="module")
def cli_page(counts_recording, tmp_path_factory):
    """calibrate through the CLI, on a copy of the counts recording named EVIL, with an evil unit."""
    root = tmp_path_factory.mktemp("html")
    data = root / EVIL
    shutil.copyfile(counts_recording.path, data)
    out = root / "out"
    code = main(["calibrate", "--data", str(data), "--out", str(out), "--unit", "LSB", "--quiet"])  # markup in a
    # unit is refused where it enters (tests/test_trust_export.py): the file could not be read back
    return code, out, (out / "report.html").read_text(encoding="utf-8")


def test_calibrate_writes_report_html_with_the_fitted_numbers(cli_page, counts_run):
    code, out, page = cli_page
    assert code == 0
    assert page.startswith("<!DOCTYPE html>")
    # The verdict comes first, then parameters, residuals, figures.
    order = [page.index(f'id="{s}"') for s in ("verdict", "parameters", "residuals", "figures")]
    assert order == sorted(order)
    res = counts_run.result  # the same recording: the same fit
    for n, p in res.params.items():
        assert f"<td>{n}</td><td class=\"num\">{p.value:.10g}</td>" in page
        assert f"{res.std[n]:.4g}" in page
    assert f"{counts_run.calibration.fit['rms_residual'] * 1e3:.4g} mm/s²" in page
    assert "[mm/s²]" in page and "m/s²" in page and "[deg]" in page


def test_report_html_needs_no_network_and_runs_no_script(cli_page):
    _, out, page = cli_page
    assert "Content-Security-Policy" in page and "default-src 'none'" in page
    assert not re.search(r"<script", page, re.I)
    assert not re.search(r"""(src|href)=["']?(https?:|//|file:)""", page, re.I)
    imgs = _images(page)
    names = ["recording.png", "before_after.png", "residuals.png", "directions.png"]  # in the page's order
    assert imgs == [(out / n).read_bytes() for n in names]  # the same bytes as the files
    for png in imgs:  # they decode as pictures
        assert mpimg.imread(io.BytesIO(png), format="png").shape[0] > 100


def test_file_names_and_config_strings_are_escaped(cli_page):
    _, _, page = cli_page
    assert "<script" not in page and "<img src=x" not in page and "<b>LSB" not in page
    assert html.escape(EVIL, quote=True) in page  # shown, as text
    assert "LSB/(m/s^2)" in page  # the unit of the scales


def test_verdict_pass_on_a_clean_fit_and_check_when_warned(counts_run):
    v = verdict(counts_run)
    res = counts_run.result
    p = chi2_sf(res.chi2_noise, res.dof)  # against the noise alone
    assert v.checks[0].ok is True
    expected_ok = not (res.redchi_noise > 2 and p < 1e-3)
    assert v.checks[1].ok is expected_ok and f"p = {p:.3g}" in v.checks[1].detail
    assert v.level == ("pass" if expected_ok and not v.warnings else "check")
    assert v.headline.startswith("PASS" if v.level == "pass" else "CHECK")
    page = calibration_html(counts_run)
    for sv in v.sensors:
        assert page.index(html.escape(sv.headline)) < page.index('id="parameters"')
    assert "Figures were not made" in page


def test_chi2_consistency_rule():
    assert chi2_consistent(20.0, 20)[0] is True
    ok, p = chi2_consistent(200.0, 20)
    assert ok is False and p < 1e-3
    assert chi2_consistent(1.0, 0)[0] is None and math.isnan(chi2_consistent(1.0, 0)[1])


def test_poor_fit_is_flagged_in_the_verdict(tmp_path):
    """A scale that changes with time (drift the base model lacks) gives a poor fit: the verdict
    says CHECK, the residual check fails and the page carries the discover hint."""
    rng = np.random.default_rng(11)
    sensor = mems_counts_sensor(rng)
    plan = PosePlan(cube_directions(), hold=3.0, transition=1.5, rate=100.0)
    sim = simulate(sensor, plan, seed=3)
    t = sim.t
    raw = sim.raw * (1 + 5e-4 * (t / t[-1]))[:, None]  # 0.05 % scale drift over the log
    path = tmp_path / "drift.csv"
    path.write_text(replace(sim, raw=raw, sensor=replace(sensor, quantum=0.0)).to_csv_text())
    run = calibrate_accelerometer(config_from_dict({"data": {"path": str(path)}}))
    v = verdict(run)
    assert v.level == "check" and v.checks[1].ok is False
    page = calibration_html(run)
    assert "class=\"verdict check\"" in page and "imucal discover" in page
    # issue 29: the headline states the number its failed check states (was: the weighted fit's 1)
    red = f"reduced chi-square {run.result.redchi_noise:.3g} against the noise"
    assert red in v.sensors[0].headline and red in v.checks[1].detail
    assert f"reduced chi-square {run.result.redchi:.3g} against" not in v.sensors[0].headline


def test_discover_writes_report_html(tmp_path, run_cli, counts_recording):
    data = tmp_path / EVIL
    shutil.copyfile(counts_recording.path, data)
    r = run_cli(["discover", "--data", data, "--plot", tmp_path / "plots", "--quiet"])
    assert r.code == 0, r.err
    page = (tmp_path / "plots" / "report.html").read_text(encoding="utf-8")
    assert "<script" not in page and html.escape(EVIL, quote=True) in page
    assert len(_images(page)) == 5  # residuals, candidates, gap, Allan view, temperature sweep
    assert page.index('id="verdict"') < page.index('id="effects"') < page.index('id="parameters"')
    r2 = run_cli(["discover", "--data", data, "--out", tmp_path / "o", "--quiet"])
    assert r2.code == 0 and (tmp_path / "o" / "report.html").exists()


def test_report_html_is_never_an_input(tmp_path, run_cli, counts_recording):
    out = tmp_path / "o"
    out.mkdir()
    data = out / "report.html"
    shutil.copyfile(counts_recording.path, data)
    r = run_cli(["calibrate", "--data", data, "--out", out, "--no-figures"])
    assert r.code == 2 and "would overwrite the input" in r.err and "report.html" in r.err


def test_extra_sections_are_escaped(counts_run):
    page = calibration_html(counts_run, extra={"Gyro <i>": "bias 1 < 2 & </pre><script>"})
    assert "<h2>Gyro &lt;i&gt;</h2>" in page and "<pre>bias 1 &lt; 2 &amp; &lt;/pre&gt;&lt;script&gt;</pre>" in page
    assert page.index("Gyro &lt;i&gt;") < page.index('id="figures"')


# --- issue 29: a page an engineer reads at a glance, for every sensor of the calibration -----------------
@pytest.fixture(scope="module")
def imu_page(tmp_path_factory):
    """The shipped Xsens run: accelerometer and gyroscope (imu_tk's two files)."""
    from pathlib import Path

    out = tmp_path_factory.mktemp("imu") / "out"
    cfg = Path(__file__).resolve().parents[1] / "configs" / "xsens-mti-imutk.yaml"
    assert main(["calibrate", str(cfg), "--out", str(out), "--quiet"]) == 0
    return out, (out / "report.html").read_text(encoding="utf-8")


def test_every_sensor_has_its_verdict_and_its_section_in_one_form(imu_page, counts_run):
    from imucal.report.figures import recording_figure
    from imucal.report.html import render_png

    out, page = imu_page
    import yaml

    sensors = yaml.safe_load((out / "calibration.yaml").read_text())["sensors"]
    assert sensors == ["accelerometer", "gyroscope"]
    for s in sensors:
        assert f'id="verdict-{s}"' in page and page.index(f'id="verdict-{s}"') < page.index('id="recording"')
    assert page.index('id="recording"') < page.index('id="parameters"') < page.index('id="gyroscope"')
    assert "<pre>" not in page  # the gyroscope is a section, not a text dump
    for unit in ("mg", "raw/g", "mrad", "deg/s", "raw/deg/s", "(deg/s)/g"):
        assert f"<td>{html.escape(unit)}</td>" in page, unit
    assert "before: |a| − g [mm/s²]" in page and "after: |a| − g [mm/s²]" in page
    # the recording's time series has the gyroscope's panel too (its second file, imu_tk's layout)
    one_panel = mpimg.imread(io.BytesIO(render_png(recording_figure, counts_run)), format="png").shape[0]
    assert mpimg.imread(out / "recording.png").shape[0] > 1.4 * one_panel


def test_the_datasheet_units_are_the_fitted_values_converted():
    """mg, ppm and mrad from an SI sensor's parameters, each by its formula."""
    from imucal.calibration.frozen import Calibration
    from imucal.constants import STANDARD_GRAVITY
    from imucal.model.parameters import base_parameters
    from imucal.report.datasheet import datasheet

    p = base_parameters([0.1, -0.2, 0.3], [1.001, 0.999, 1.0002], [math.pi / 2 + 1e-3, math.pi / 2, math.pi / 2 - 2e-3],
                        raw_unit="m/s^2")
    std = {n: 1e-4 for n in p.names}
    rows = {r.quantity: r for r in datasheet(Calibration(params=p, std=std, gravity=9.81, raw_unit="m/s^2"))
            ["accelerometer"]}
    assert rows["bias x"].value == pytest.approx(0.1 / 1.001 / STANDARD_GRAVITY * 1e3) and rows["bias x"].unit == "mg"
    assert rows["scale error y"].value == pytest.approx((0.999 - 1) * 1e6) and rows["scale error y"].unit == "ppm"
    assert rows["scale error y"].std == pytest.approx(1e-4 * 1e6)
    assert rows["misalignment x-y (from 90°)"].value == pytest.approx(1.0) and rows["misalignment y-z (from 90°)"
                                                                                   ].value == pytest.approx(-2.0)


from hypothesis import given, settings, strategies as st  # noqa: E402


@settings(max_examples=200, deadline=None)
@given(st.text(alphabet=st.characters(codec="utf-8"), max_size=60)
       | st.sampled_from(['<script>alert(1)</script>', '"><img src=x onerror=alert(1)>', "' onmouseover='x",
                          "</td></tr></table><b>", "&amp;&lt;", "]]>--><!--", "\u2028\x00"]))
def test_the_html_escape_is_text_for_any_string(text):
    """page.esc, the one HTML escaping function: its output holds no markup character and reads back
    as the same text, inside an element and inside a quoted attribute, its control characters (ESC, a bidi
    override, NUL) shown as escapes (imucal.errors.printable)."""
    from imucal.errors import printable
    from imucal.report.page import esc

    out = esc(text)
    assert not set(out) & set("<>\"'") and html.unescape(out) == printable(text, keep="\n\t")
    assert "&" not in out.replace("&amp;", "").replace("&lt;", "").replace("&gt;", "").replace("&quot;", "").replace(
        "&#x27;", "")
