"""The gyro fit's choices reach GyroOptions from the YAML gyro: section and the calibrate options,
and the default segments are chosen by the data (imucal.gyro.lead_in)."""
from __future__ import annotations

import dataclasses
import types

import numpy as np
import pytest

from imucal import pipeline
from imucal.cli.commands import options
from imucal.cli.main import build_parser
from imucal.config.run import GyroSettings, config_from_dict
from imucal.errors import ImucalError
from imucal.gyro import GyroOptions, fit_gyro
from imucal.gyro import run as gyro_run
from imucal.gyro.lead_in import LEAD_IN_S, lead_in_for
from imucal.gyro.result import arrays, motions
from imucal.gyro.simulate import GyroTruth, hand_held

TRUTH = GyroTruth(bias=np.array([0.01, -0.02, 0.005]), scale=np.array([1.01, 0.99, 1.005]),
                  mis=np.array([0.01, -0.02, 0.015, 0.03, -0.025, 0.02]),
                  gsens=np.array([[0.0, 2e-4, -1e-4], [3e-4, 0.0, 1e-4], [-2e-4, 1e-4, 0.0]]), noise=2e-3)


def _options_used(monkeypatch, cfg) -> GyroOptions:
    """The GyroOptions calibrate_imu hands to the gyro fit (the accelerometer fit stubbed out)."""
    seen = []
    run = types.SimpleNamespace(recording=types.SimpleNamespace(gyro=np.zeros((3, 3))))  # a recording with a gyro
    monkeypatch.setattr(pipeline, "calibrate_accelerometer", lambda config, recording=None: run)
    monkeypatch.setattr(gyro_run, "calibrate_gyro", lambda run, gyro_file, opts: seen.append(opts))
    pipeline.calibrate_imu(cfg)
    return seen[0]


def test_the_yaml_gyro_section_reaches_the_fit(monkeypatch):
    cfg = config_from_dict({"data": {"path": "x.csv"}, "gyro": {"gsens": "on", "lead_in_s": 0.25, "free_bias": True}})
    assert _options_used(monkeypatch, cfg) == GyroOptions(gsens="on", lead_in_s=0.25, free_bias=True)
    assert _options_used(monkeypatch, config_from_dict({"data": {"path": "x.csv"}})) == GyroOptions()


def test_the_calibrate_options_reach_the_fit(monkeypatch):
    args = build_parser().parse_args(["calibrate", "--data", "x.csv", "--gyro-gsens", "off", "--gyro-lead-in", "0.5",
                                      "--gyro-free-bias", "--gyro-unit", "deg/s"])
    cfg = options.run_config(args, None)
    assert cfg.data.gyro_unit == "deg/s"
    assert _options_used(monkeypatch, cfg) == GyroOptions(gsens="off", lead_in_s=0.5, free_bias=True)
    args = build_parser().parse_args(["calibrate", "--data", "x.csv", "--gyro-lead-in", "auto"])
    assert options.run_config(args, None).gyro == GyroSettings()


@pytest.mark.parametrize("section, field", [({"gsen": "on"}, "gyro.gsen"), ({"gsens": "yes"}, "gyro.gsens"),
                                            ({"lead_in_s": -1}, "gyro.lead_in_s"),
                                            ({"lead_in_s": "half"}, "gyro.lead_in_s"),
                                            ({"free_bias": "yes"}, "gyro.free_bias")])
def test_bad_gyro_settings_are_refused_with_the_key(section, field):
    with pytest.raises(ImucalError) as exc:
        config_from_dict({"data": {"path": "x.csv"}, "gyro": section}, "run.yaml")
    assert str(exc.value).startswith(f"run.yaml: {field}:")


def test_a_bad_lead_in_option_names_the_option(run_cli):
    code, _, err = run_cli(["calibrate", "--data", "x.csv", "--gyro-lead-in", "11"])
    assert code == 2 and "--gyro-lead-in: lead_in_s 11.0 is not auto or between 0 and 10 s" in err


def _late(d, k: int):
    """The static intervals reaching k samples into the motions (a detector's window counting them as still)."""
    return dataclasses.replace(d, start=np.r_[d.start[0], d.start[1:] - k], end=np.r_[d.end[:-1] + k, d.end[-1]])


def test_the_default_rule_picks_the_lead_in_with_g_sensitivity_when_the_edges_turn():
    d = hand_held(TRUTH, seed=1, unit="rad/s", n_poses=16, durations=None)
    late = _late(d, 6)
    assert lead_in_for(d, "auto", "auto") == 0.0  # exact still poses: nothing to recover
    assert lead_in_for(late, "off", "auto") == 0.0  # the g-sensitivity found is left out
    assert lead_in_for(late, "auto", "auto") == LEAD_IN_S
    r = fit_gyro(late)
    assert motions(r).gsens_selected.all() and motions(r).lead_in_s == LEAD_IN_S
    a = arrays(r)
    assert np.all(np.abs(a.scale - TRUTH.scale) <= 3 * a.scale_std)  # the turns missed at the edges recovered
    fixed = arrays(fit_gyro(late, GyroOptions(lead_in_s=0.0)))
    assert np.max(np.abs(fixed.scale - TRUTH.scale) / fixed.scale_std) > 3  # without: the scales come out short
