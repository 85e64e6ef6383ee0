"""`imucal simulate` and `imucal discover` from the command line: files, reproducibility, messages."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from imucal.cli.main import main
from imucal.data.load import load_recording
from imucal.errors import ImucalError
from imucal.analysis.simulate import draw_effect_case, load_simulation_config, sensor_from_values, simulation_from_dict

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "configs" / "simulate_example.yaml"


def _cli(capsys, *argv):
    code = main([str(a) for a in argv])
    out = capsys.readouterr()
    return code, out.out, out.err


@pytest.fixture(scope="module")
def example_csv(tmp_path_factory):
    d = tmp_path_factory.mktemp("sim")
    out, truth = d / "sim.csv", d / "truth.json"
    assert main(["simulate", str(EXAMPLE), "--out", str(out), "--truth", str(truth)]) == 0
    return out, truth


def test_simulate_writes_a_recording_the_loader_reads(example_csv):
    out, truth = example_csv
    rec = load_recording(str(out))
    assert rec.temp is not None and rec.raw.shape[1] == 3
    assert np.all(rec.raw == np.round(rec.raw))  # raw counts, quantised
    assert np.ptp(rec.temp) > 5  # warm-up
    # non-monotonic: the temperature falls somewhere after rising
    smooth = np.convolve(rec.temp, np.ones(200) / 200, mode="valid")
    assert np.any(np.diff(smooth) > 0) and np.any(np.diff(smooth) < 0)
    t = json.loads(truth.read_text())
    assert t["effects"] == {"bias_temperature": {"bias_temperature_x": 2.4, "bias_temperature_tref": 25.0}}
    assert t["poses"] == 22 and t["unit"] == "raw"


def test_simulate_is_reproducible(tmp_path, capsys, example_csv):
    a, b, c = tmp_path / "a.csv", tmp_path / "b.csv", tmp_path / "c.csv"
    assert _cli(capsys, "simulate", EXAMPLE, "--out", a)[0] == 0
    assert _cli(capsys, "simulate", EXAMPLE, "--out", b)[0] == 0
    assert _cli(capsys, "simulate", EXAMPLE, "--out", c, "--seed", 8)[0] == 0
    assert a.read_bytes() == b.read_bytes() == example_csv[0].read_bytes()
    assert a.read_bytes() != c.read_bytes()


def test_discover_cli_finds_the_example_effect(example_csv, tmp_path, capsys):
    out, _ = example_csv
    js, plots, cal = tmp_path / "d.json", tmp_path / "plots", tmp_path / "cal"
    code, stdout, _ = _cli(capsys, "discover", "--data", out, "--json", js, "--plot", plots, "--out", cal)
    assert code == 0
    assert "bias_temperature[x]" in stdout and "explained" in stdout
    d = json.loads(js.read_text())
    assert [(e["name"], e["axes"]) for e in d["effects"]] == [("bias_temperature", ["x"])]
    e = d["effects"][0]
    assert abs(e["coefficients"]["bias_temperature_x"] - 2.4) < 5 * e["std"]["bias_temperature_x"]
    assert e["units"]["bias_temperature_x"] == "raw/degC"
    assert d["rms_after"] < d["rms_before"] and d["chi2_after"] < d["chi2_before"] and d["dof"] > 0
    for name in ("discover_residuals.png", "discover_candidates.png", "discover_gap.png"):
        assert (plots / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # the calibration file carries the effect; apply needs the temperature column
    c = yaml.safe_load((cal / "calibration.yaml").read_text())
    assert c["effects"] == [{"name": "bias_temperature", "axes": ["x"]}]
    applied = tmp_path / "applied.csv"
    assert _cli(capsys, "apply", cal / "calibration.yaml", "--data", out, "--out", applied)[0] == 0
    a = np.loadtxt(applied, delimiter=",", skiprows=1)
    assert a.shape[1] == 4
    notemp = tmp_path / "notemp.csv"
    notemp.write_text("\n".join(",".join(ln.split(",")[:4]) for ln in out.read_text().splitlines()) + "\n")
    code, _, err = _cli(capsys, "apply", cal / "calibration.yaml", "--data", notemp, "--out", tmp_path / "x.csv")
    assert code == 2 and "temperature effect but the data have no temp column" in err


def test_discover_cli_clean_data_finds_nothing(tmp_path, capsys):
    case = draw_effect_case(8100, effect=None, counts=False)
    p = tmp_path / "clean.csv"
    p.write_text(case.config.run().to_csv_text())
    js = tmp_path / "d.json"
    code, stdout, _ = _cli(capsys, "discover", "--data", p, "--unit", "m/s^2", "--json", js, "--quiet")
    assert code == 0 and stdout.startswith("verdict: consistent with noise")
    d = json.loads(js.read_text())
    assert d["effects"] == [] and d["rms_after"] == d["rms_before"]


def test_discover_cli_errors_are_one_line(tmp_path, capsys):
    code, _, err = _cli(capsys, "discover")
    assert code == 2 and "nothing to analyse" in err and err.count("\n") == 1
    code, _, err = _cli(capsys, "discover", "--data", tmp_path / "missing.csv")
    assert code == 2 and "missing.csv: data.path: file not found" in err
    code, _, err = _cli(capsys, "discover", "--data", EXAMPLE, "--candidates", "wobble")
    assert code == 2 and "unknown effect 'wobble'" in err


def test_discover_cli_leaves_no_half_written_output(tmp_path, capsys):
    code, _, _ = _cli(capsys, "discover", "--data", tmp_path / "missing.csv", "--json", tmp_path / "d.json",
                      "--plot", tmp_path / "plots")
    assert code == 2 and not (tmp_path / "d.json").exists() and not (tmp_path / "plots").exists()


# --- the simulation config ----------------------------------------------------------------------
def _example() -> dict:
    return yaml.safe_load(EXAMPLE.read_text())


def test_example_config_loads_typed():
    cfg = load_simulation_config(EXAMPLE)
    assert cfg.seed == 7 and cfg.sensor.unit == "raw" and cfg.sensor.quantum == 1.0
    assert cfg.sensor.noise == (4.0, 4.0, 4.0) and len(cfg.plan.directions) == 22
    assert cfg.temperature is not None and cfg.temperature.plateau == 36.0


@pytest.mark.parametrize("edit,message", [
    (lambda d: d.update(colour="red"), "sim.yaml: colour: unknown key 'colour' (fix: allowed top-level keys: seed, gravity"),
    (lambda d: d["sensor"].update(nois=3), "sensor.nois: unknown key 'nois' (fix: allowed keys here:"),
    (lambda d: d["sensor"].update(preset="bmi"), "sensor.preset: unknown preset 'bmi'"),
    (lambda d: d["sensor"].update(b=[1, -1, 1]), "sensor.b: scales must be positive"),
    (lambda d: d["sensor"].update(noise=[1, 2]), "sensor.noise: [1, 2] must be three finite numbers"),
    (lambda d: d["sensor"]["effects"].update(wobble={"x": 1}), "unknown effect 'wobble'"),
    (lambda d: d["sensor"]["effects"]["bias_temperature"].update(bias_temperature_q=1),
     "unknown parameter 'bias_temperature_q' of effect bias_temperature"),
    (lambda d: d.pop("temperature"), "temperature: the sensor has a temperature effect but there is no temperature"),
    (lambda d: d["plan"].update(directions="dodecahedron"), "plan.directions: unknown direction set"),
    (lambda d: d["plan"].update(hold=0), "hold, transition and rate must be positive"),
    (lambda d: d["temperature"].update(tau=-1), "temperature.tau: tau -1 must be a positive number of seconds"),
    (lambda d: d.update(seed=-3), "seed: seed -3 must be an integer from 0 to"),
    (lambda d: d["plan"].update(directions="random", n_random=0),
     "plan.n_random: no directions: 'random' needs n_random > 0"),
])
def test_bad_simulation_configs_name_the_field(edit, message):
    d = _example()
    edit(d)
    with pytest.raises(ImucalError) as exc:
        simulation_from_dict(d, "sim.yaml")
    assert message in str(exc.value)
    assert str(exc.value).startswith("sim.yaml: ")


def test_simulate_cli_bad_config_exits_2(tmp_path, capsys):
    p = tmp_path / "bad.yaml"
    p.write_text("seed: 1\nsensor: {preset: si}\nplan: {hold: -2}\n")
    code, _, err = _cli(capsys, "simulate", p, "--out", tmp_path / "x.csv")
    assert code == 2 and "plan.hold" in err and not (tmp_path / "x.csv").exists()
    p.write_text("seed: [\n")
    code, _, err = _cli(capsys, "simulate", p, "--out", tmp_path / "x.csv")
    assert code == 2 and "is not valid YAML" in err


@pytest.mark.parametrize("edit", [lambda d: d["sensor"]["effects"]["bias_temperature"].update(bias_temperature_x=1e308),
                                  lambda d: d["sensor"].update(random_walk=[1e300, 0, 0])])
def test_a_simulation_beyond_what_imucal_reads_is_refused(edit, tmp_path, capsys):
    """Sizes no sensor has wrote -inf or 1e300 columns (with numpy warnings) that every command then
    refused as corrupt: the simulation is refused instead, naming the file, nothing written."""
    d = _example()
    edit(d)
    p = tmp_path / "sim.yaml"
    p.write_text(yaml.safe_dump(d))
    code, _, err = _cli(capsys, "simulate", p, "--out", tmp_path / "x.csv", "--truth", tmp_path / "t.json")
    assert code == 2 and err.startswith(f"imucal: error: {p}: sensor: the simulated readings reach"), err
    assert len(err.strip().splitlines()) == 1 and not (tmp_path / "x.csv").exists()


def test_explicit_directions_and_no_temperature():
    d = {"seed": 3, "sensor": {"preset": "si", "noise": 0.01},
         "plan": {"directions": [[1, 0, 0], [0, 2, 0], [0, 0, -1]], "n_random": 2, "hold": 2.0}}
    cfg = simulation_from_dict(d)
    sim = cfg.run()
    assert sim.temp is None and "temp" not in sim.to_csv_text().splitlines()[0]
    assert len(cfg.plan.directions) == 5
    np.testing.assert_allclose(np.linalg.norm(cfg.plan.directions, axis=1), 1.0)


def test_sensor_from_fitted_values_replays_the_recording():
    """A SensorSpec built from the true values reproduces the simulator's noise-free readings."""
    case = draw_effect_case(5, effect="bias_drift", axes=(0, 2), snr=50)
    s = case.config.sensor
    from imucal.model.effects import effects_from_coefficients

    replay = sensor_from_values(s.values(), tuple(effects_from_coefficients(s.effects)), unit=s.unit)
    m = np.random.default_rng(0).normal(0, 5, (20, 3))
    t = np.linspace(0, 100, 20)
    np.testing.assert_allclose(replay.forward(m, t, None), s.forward(m, t, None), rtol=1e-12)


def test_discover_cli_temperature_effect_in_config_without_temp(tmp_path, capsys):
    """A config that asks for a temperature effect on a recording with no temp column."""
    case = draw_effect_case(8200, effect=None, with_temperature=False)
    data = tmp_path / "notemp.csv"
    data.write_text(case.config.run().to_csv_text())
    cfg = tmp_path / "run.yaml"
    cfg.write_text(f"data: {{path: {data}, unit: {case.config.sensor.unit}}}\n"
                   "fit: {effects: [{name: bias_temperature, axes: [x]}]}\n")
    code, _, err = _cli(capsys, "discover", "--config", cfg)
    assert code == 2 and err.count("\n") == 1
    assert "effect bias_temperature needs temperature but the data have no temp column" in err
    assert "notemp.csv" in err and "fix:" in err
