"""End-to-end through ``imucal.cli.main.main``: calibrate (config or --data), the JSON summary, the
report and figures, and apply's round trip back to the known accelerations."""
from __future__ import annotations

import hashlib
import json
import math

import numpy as np
import pytest
import yaml

import imucal
from imucal.model.gravity import normal_gravity

PNG = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def cli_counts(counts_recording, tmp_path_factory):
    """One full CLI calibration of the counts recording (with figures), shared by the tests."""
    from imucal.cli.main import main

    root = tmp_path_factory.mktemp("cli")
    out, js = root / "out", root / "summary.json"
    code = main(["calibrate", "--data", str(counts_recording.path), "--out", str(out), "--json", str(js)])
    return code, out, js


def test_calibrate_writes_its_files(cli_counts):
    code, out, js = cli_counts
    assert code == 0
    assert sorted(p.name for p in out.iterdir()) == ["before_after.png", "calibration.yaml", "directions.png",
                                                      "recording.png", "report.html", "report.txt", "residuals.png"]
    for fig in ("directions.png", "residuals.png", "recording.png", "before_after.png"):
        assert (out / fig).read_bytes()[:8] == PNG
    assert js.exists()
    assert not [p for p in out.parent.rglob(".*") if p.name.startswith((".imucal-", ".calibration"))]


def test_json_summary_keys_and_values(cli_counts, counts_run, counts_recording):
    _, out, js = cli_counts
    d = json.loads(js.read_text())
    for k in ("status", "params", "std", "rms_residual", "rms_residual_samples", "n_intervals", "gravity"):
        assert k in d, k
    assert d["status"] == "ok"
    for key in ("params", "std"):
        assert len(d[key]["s"]) == 3 and len(d[key]["b"]) == 3
        assert all(isinstance(d[key][a], float) for a in ("phi", "psi", "theta"))
    res = counts_run.result
    assert d["params"]["s"] == [res.params[f"s{i}"].value for i in (1, 2, 3)]
    assert d["params"]["theta"] == res.params["theta"].value
    assert d["std"]["b"] == [res.std[f"b{i}"] for i in (1, 2, 3)]
    assert d["rms_residual"] == pytest.approx(counts_run.calibration.fit["rms_residual"])
    assert d["rms_residual_samples"] == pytest.approx(counts_run.rms_residual_samples)
    assert d["n_intervals"] == counts_recording.n_poses == 26
    assert d["gravity"] == 9.80665
    A = np.array(d["matrix"])
    assert A.shape == (3, 3) and A[0, 1] == A[0, 2] == A[1, 2] == 0.0
    assert d["data"]["sha256"] == hashlib.sha256(counts_recording.path.read_bytes()).hexdigest()


def test_report_reads_like_a_fit_report(cli_counts):
    _, out, _ = cli_counts
    text = (out / "report.txt").read_text()
    for section in ("[[Calibration]]", "[[Fit Statistics]]", "[[Variables]]", "[[Correlations]]",
                    "[[Apply map]]", "[[Static intervals]]"):
        assert section in text
    for what in ("IPOPT", "chi-square", "reduced chi-square", "RMS |a|-g, means", "RMS |a|-g, samples",
                 "# iterations", "sha256", "+/-", "(init =", "angles in degrees"):
        assert what in text, what
    for n in ("s1", "b2", "theta"):
        assert f"    {n}" in text


def test_calibrate_prints_a_summary(run_cli, counts_recording, tmp_path):
    r = run_cli(["calibrate", "--data", counts_recording.path, "--out", tmp_path / "o", "--no-figures"])
    assert r.code == 0 and r.err == ""
    assert "[[Variables]]" in r.out and "wrote" in r.out
    assert sorted(p.name for p in (tmp_path / "o").iterdir()) == ["calibration.yaml", "report.html", "report.txt"]
    q = run_cli(["calibrate", "--data", counts_recording.path, "--out", tmp_path / "q", "--no-figures", "--quiet"])
    assert q.code == 0 and q.out.strip().startswith("wrote") and len(q.out.strip().splitlines()) == 1


def test_calibrate_from_yaml_config(run_cli, si_recording, tmp_path):
    (tmp_path / "logs").mkdir()
    (tmp_path / "logs" / "rec.csv").write_bytes(si_recording.path.read_bytes())
    cfg = tmp_path / "conf" / "run.yaml"
    cfg.parent.mkdir()
    cfg.write_text(yaml.safe_dump({
        "data": {"path": "../logs/rec.csv", "unit": "counts"},
        "static": {"window": 0.5, "min_duration": 1.5},
        "gravity": {"latitude": 45.5, "height": 20.0},
        "fit": {"mode": "means", "angle_tolerance": 0.03},
        "output": {"dir": "../results", "figures": False}}))
    r = run_cli(["calibrate", cfg, "--json", tmp_path / "s.json", "--quiet"])
    assert r.code == 0, r.err
    out = tmp_path / "results"  # relative to the YAML file, not the working directory
    assert sorted(p.name for p in out.iterdir()) == ["calibration.yaml", "report.html", "report.txt"]
    d = json.loads((tmp_path / "s.json").read_text())
    assert d["gravity"] == normal_gravity(45.5, 20.0)
    assert d["raw_unit"] == "counts"
    cal = yaml.safe_load((out / "calibration.yaml").read_text())
    assert cal["units"]["input"] == "counts" and cal["parameters"]["s1"]["unit"] == "counts"
    assert cal["parameters"]["phi"]["upper"] == pytest.approx(math.pi / 2 * 1.03)
    assert cal["data"]["file"] == "rec.csv"
    # --out overrides output.dir
    r = run_cli(["calibrate", cfg, "--out", tmp_path / "elsewhere", "--quiet"])
    assert r.code == 0 and (tmp_path / "elsewhere" / "calibration.yaml").exists()


@pytest.mark.parametrize("args, g", [(["--gravity", "9.81"], 9.81),
                                     (["--latitude", "-33.9", "--height", "20"], normal_gravity(-33.9, 20.0))])
def test_gravity_options(run_cli, si_recording, tmp_path, args, g):
    js = tmp_path / "s.json"
    r = run_cli(["calibrate", "--data", si_recording.path, "--out", tmp_path / "o", "--json", js,
                 "--no-figures", "--quiet", *args])
    assert r.code == 0, r.err
    assert json.loads(js.read_text())["gravity"] == g
    assert yaml.safe_load((tmp_path / "o" / "calibration.yaml").read_text())["gravity"] == g


def test_fix_angles_and_samples_mode_options(run_cli, si_recording, tmp_path):
    js = tmp_path / "s.json"
    r = run_cli(["calibrate", "--data", si_recording.path, "--out", tmp_path / "o", "--json", js,
                 "--no-figures", "--quiet", "--fix-angles"])
    assert r.code == 0, r.err
    d = json.loads(js.read_text())
    assert d["params"]["phi"] == d["params"]["psi"] == d["params"]["theta"] == math.pi / 2
    assert d["std"]["phi"] is None


# --- apply ---------------------------------------------------------------------------------
def _read_out(path):
    head = path.read_text().splitlines()[0]
    assert head == "t,ax,ay,az"
    return np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)


@pytest.mark.parametrize("which", ["counts", "si"])
def test_apply_round_trip_to_known_accelerations(run_cli, request, tmp_path, which):
    """Raw data made from known accelerations come back to within the noise."""
    rec = request.getfixturevalue(f"{which}_recording")
    request.getfixturevalue(f"{which}_run").calibration.save(tmp_path / "cal.yaml")
    out = tmp_path / "acc.csv"
    r = run_cli(["apply", tmp_path / "cal.yaml", "--data", rec.path, "--out", out])
    assert r.code == 0, r.err
    assert f"wrote {rec.sim.t.size} calibrated samples" in r.out
    arr = _read_out(out)
    assert arr.shape == (rec.sim.t.size, 4)
    np.testing.assert_allclose(arr[:, 0], rec.sim.t, atol=1e-6)
    err = arr[:, 1:] - rec.sim.accel  # frame f of the Theorem is the simulator's frame
    noise = np.sqrt(np.array(rec.sensor.noise) ** 2 + rec.sensor.quantum**2 / 12) / np.array(rec.sensor.b)
    rms = np.sqrt(np.mean(err**2, axis=0))
    np.testing.assert_array_less(rms, 1.1 * noise)
    np.testing.assert_array_less(0.9 * noise, rms)
    # and no bias: the mean error over ~10^4 samples is a small fraction of the noise
    np.testing.assert_array_less(np.abs(err.mean(axis=0)), 0.1 * noise)


def test_apply_without_time_column_needs_a_rate(run_cli, counts_run, counts_recording, tmp_path):
    counts_run.calibration.save(tmp_path / "cal.yaml")
    raw = counts_recording.sim.raw[:500]
    data = tmp_path / "xyz.txt"
    np.savetxt(data, raw, fmt="%.0f")
    r = run_cli(["apply", tmp_path / "cal.yaml", "--data", data, "--out", tmp_path / "a.csv"])
    assert r.code == 2 and "no time column and no sample rate" in r.err
    assert not (tmp_path / "a.csv").exists()
    r = run_cli(["apply", tmp_path / "cal.yaml", "--data", data, "--out", tmp_path / "a.csv", "--sample-rate", "50"])
    assert r.code == 0, r.err
    arr = _read_out(tmp_path / "a.csv")
    np.testing.assert_allclose(arr[:3, 0], [0, 0.02, 0.04])
    np.testing.assert_allclose(arr[:, 1:], counts_run.calibration.apply(raw), rtol=1e-8, atol=1e-8)


def test_version_and_help(run_cli):
    r = run_cli(["--version"])
    assert r.code == 0 and r.out.strip() == f"imucal {imucal.__version__}"
    r = run_cli(["calibrate", "--help"])
    assert r.code == 0 and "--json" in r.out and "--no-figures" in r.out and "--fix-angles" in r.out
    r = run_cli([])
    assert r.code == 2
