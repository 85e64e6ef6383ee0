"""imucal batch: a simulated fleet of 20 units (2 defective, 2 corrupt files) calibrated on
processes and on a dask.distributed LocalCluster, compared with single-unit `imucal calibrate`
runs; resuming after a kill; manifests refused in one line."""
from __future__ import annotations

import contextlib
import csv
import io
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from imucal.analysis.simulate import load_simulation_config
from imucal.cli.main import main
from imucal.fleet.manifest import Tolerances, load_manifest
from imucal.fleet.population import draw_fleet, write_fleet
from imucal.fleet.report import fleet_table, robust_z
from imucal.fleet.run import DONE_FILE, read_marker
from imucal.model.parameters import BASE_NAMES

ROOT = Path(__file__).resolve().parents[1]
N_UNITS, N_DEFECTIVE, N_CORRUPT = 20, 2, 2
#: Columns that differ between two runs of the same units (timing, whether skipped).
VOLATILE = ("seconds", "cpu_seconds", "skipped")


def _main(args: list) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main([str(a) for a in args])
    return code, out.getvalue(), err.getvalue()


def _table(folder: Path) -> dict[str, dict]:
    with open(folder / "fleet.csv", newline="") as f:
        return {r["unit"]: r for r in csv.DictReader(f)}


@pytest.fixture(scope="module")
def fleet(tmp_path_factory) -> Path:
    """The simulated fleet: OUT/<unit>.csv, truth.csv, manifest.yaml (no figures: fast)."""
    d = tmp_path_factory.mktemp("fleet")
    cfg = load_simulation_config(str(ROOT / "configs" / "simulate_fleet.yaml"))
    units = draw_fleet(cfg, N_UNITS, N_DEFECTIVE, N_CORRUPT)
    write_fleet(units, d / "sim", [], settings={"output": {"figures": False}})
    return d / "sim"


@pytest.fixture(scope="module")
def truth(fleet) -> dict[str, dict]:
    with open(fleet / "truth.csv", newline="") as f:
        return {r["unit"]: r for r in csv.DictReader(f)}


@pytest.fixture(scope="module")
def batch(fleet, tmp_path_factory) -> tuple[Path, int, str, str]:
    out = tmp_path_factory.mktemp("batch") / "res"
    code, stdout, stderr = _main(["batch", fleet / "manifest.yaml", "--out", out, "--workers", "2", "--no-figures"])
    return out, code, stdout, stderr


def test_simulated_fleet_has_the_asked_defects(truth):
    assert len(truth) == N_UNITS
    assert sum(bool(r["defect"]) for r in truth.values()) == N_DEFECTIVE
    assert sum(bool(r["corrupt"]) for r in truth.values()) == N_CORRUPT
    assert not any(r["defect"] and r["corrupt"] for r in truth.values())


def test_batch_calibrates_every_good_unit_and_reports(batch, truth):
    out, code, stdout, stderr = batch
    assert code == 0, stderr
    assert stderr == ""  # no progress bar when stderr is not a terminal
    table = _table(out)
    assert set(table) == set(truth)
    for uid, t in truth.items():
        row = table[uid]
        assert row["status"] == ("error" if t["corrupt"] else "ok"), (uid, row["error"])
        assert (Path(out) / uid / DONE_FILE).is_file()
        if not t["corrupt"]:
            assert (Path(out) / uid / "calibration.yaml").is_file()
    assert f"fleet: {N_UNITS} units: {N_UNITS - N_CORRUPT} calibrated" in stdout
    good = N_UNITS - N_CORRUPT - N_DEFECTIVE
    assert f"yield: {good}/{N_UNITS}" in stdout


def test_corrupt_units_carry_their_one_line_error(batch, truth):
    out = batch[0]
    table = _table(out)
    for uid in (u for u, t in truth.items() if t["corrupt"]):
        err = table[uid]["error"]
        assert f"{uid}.csv" in err and "(fix:" in err and "\n" not in err
        assert table[uid]["verdict"] == "fail"
        assert err.split(": ", 1)[1] in batch[2]  # printed in the summary too


def test_defective_units_flagged_and_good_units_pass(batch, truth):
    table = _table(batch[0])
    for uid, t in truth.items():
        row = table[uid]
        if t["defect"]:
            assert row["verdict"] == "fail" and row["outlier"], row
            expect = "bias_" if t["defect"] == "bias" else "_from_90_deg"
            assert expect in row["reasons"]
        elif not t["corrupt"]:
            assert row["verdict"] == "pass" and not row["outlier"], row


def test_fitted_bias_recovers_the_truth(batch, truth):
    table = _table(batch[0])
    for uid, t in truth.items():
        if not t["corrupt"]:
            for a in "xyz":
                assert abs(float(table[uid][f"bias_{a}"]) - float(t[f"bias_{a}"])) < 0.02


def test_units_identical_to_single_calibrate_runs(batch, truth, fleet, tmp_path):
    """Every good unit: the batch's parameters equal `imucal calibrate --data`'s, to the last bit."""
    table = _table(batch[0])
    for uid in (u for u, t in truth.items() if not t["corrupt"]):
        js = tmp_path / f"{uid}.json"
        code, _, err = _main(["calibrate", "--data", fleet / "recordings" / f"{uid}.csv", "--out", tmp_path / uid,
                              "--json", js, "--no-figures", "--quiet"])
        assert code == 0, err
        single = json.loads(js.read_text())
        p = single["params"]
        values = [*p["s"], *p["b"], p["phi"], p["psi"], p["theta"]]
        assert [float(table[uid][n]) for n in BASE_NAMES] == values, uid
        assert float(table[uid]["rms_residual"]) == single["rms_residual"]
        batch_summary = json.loads((batch[0] / uid / "summary.json").read_text())
        assert batch_summary["params"] == single["params"] and batch_summary["std"] == single["std"]
        assert (batch[0] / uid / "calibration.yaml").read_text().split("created")[0] == \
            (tmp_path / uid / "calibration.yaml").read_text().split("created")[0]


def test_dask_local_cluster_gives_the_same_table(batch, fleet, tmp_path):
    import distributed  # the test extra (imucal-nlp[fleet] for users)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                                  silence_logs=50) as cluster:
        code, stdout, err = _main(["batch", fleet / "manifest.yaml", "--out", tmp_path / "dask",
                                   "--scheduler", cluster.scheduler_address, "--no-figures"])
    assert code == 0, err
    a, b = _table(batch[0]), _table(tmp_path / "dask")
    assert set(a) == set(b)
    for uid in a:
        assert {k: v for k, v in a[uid].items() if k not in VOLATILE} == \
            {k: v for k, v in b[uid].items() if k not in VOLATILE}, uid
    assert "0 skipped" in stdout


def test_rerun_skips_done_units_and_redoes_the_others(batch, fleet, tmp_path):
    out = tmp_path / "res"
    shutil.copytree(batch[0], out)
    redo = ["unit03", "unit07", "unit15"]
    for uid in redo:
        (out / uid / DONE_FILE).unlink()
    kept = out / "unit01" / "calibration.yaml"
    before = kept.stat().st_mtime_ns
    code, stdout, err = _main(["batch", fleet / "manifest.yaml", "--out", out, "--workers", "2", "--no-figures"])
    assert code == 0, err
    assert f"({N_UNITS - len(redo)} skipped: already done)" in stdout
    assert kept.stat().st_mtime_ns == before
    table = _table(out)
    assert [u for u, r in table.items() if r["skipped"] == "False"] == redo
    old = _table(batch[0])
    for uid in table:
        assert {k: v for k, v in table[uid].items() if k not in VOLATILE} == \
            {k: v for k, v in old[uid].items() if k not in VOLATILE}


def test_changed_input_or_settings_run_again(batch, fleet, tmp_path):
    sim = tmp_path / "sim"
    shutil.copytree(fleet, sim)
    out = tmp_path / "res"
    shutil.copytree(batch[0], out)
    # another recording for unit02 (same bytes as unit04): its SHA-256 changes
    shutil.copyfile(sim / "recordings" / "unit04.csv", sim / "recordings" / "unit02.csv")
    code, stdout, err = _main(["batch", sim / "manifest.yaml", "--out", out, "--workers", "1", "--no-figures"])
    assert code == 0, err
    assert f"({N_UNITS - 1} skipped" in stdout
    t = _table(out)
    assert t["unit04"]["status"] == "ok" and t["unit02"]["s1"] == t["unit04"]["s1"]
    assert t["unit02"]["skipped"] == "False"
    # tolerances are not settings: the verdicts change, nothing is fitted again
    m = yaml.safe_load((sim / "manifest.yaml").read_text())
    m["tolerances"]["bias_abs_max"] = 0.01
    (sim / "manifest.yaml").write_text(yaml.safe_dump(m))
    code, stdout, _ = _main(["batch", sim / "manifest.yaml", "--out", out, "--workers", "1", "--no-figures"])
    assert f"({N_UNITS} skipped" in stdout and f"yield: 0/{N_UNITS}" in stdout
    # a per-unit override changes that unit's settings hash only
    m["units"][5]["settings"] = {"gravity": {"value": 9.81}}
    (sim / "manifest.yaml").write_text(yaml.safe_dump(m))
    code, stdout, _ = _main(["batch", sim / "manifest.yaml", "--out", out, "--workers", "1", "--no-figures"])
    assert f"({N_UNITS - 1} skipped" in stdout
    assert read_marker(out / m["units"][5]["id"])["summary"]["gravity"] == 9.81


def test_killed_batch_resumes(fleet, tmp_path):
    """SIGTERM in the middle: exit 130, finished units kept; the rerun does only the rest."""
    out = tmp_path / "res"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    cmd = [sys.executable, "-m", "imucal", "batch", str(fleet / "manifest.yaml"), "--out", str(out),
           "--workers", "1", "--no-figures"]
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and len(list(out.glob(f"*/{DONE_FILE}"))) < 3:
        time.sleep(0.05)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert "rerun the same command to resume" in err
    done = len(list(out.glob(f"*/{DONE_FILE}")))
    assert 3 <= done < N_UNITS
    assert not list(out.glob("*/.imucal-*"))  # no staging folder left behind
    code, stdout, err = _main(["batch", fleet / "manifest.yaml", "--out", out, "--workers", "2", "--no-figures"])
    assert code == 0, err
    assert f"({done} skipped: already done)" in stdout
    assert len(list(out.glob(f"*/{DONE_FILE}"))) == N_UNITS


def test_outlier_inside_tolerance_is_flagged(batch, truth):
    """A unit whose bias sits far from the fleet's yet inside the tolerance: pass, but an outlier."""
    records = [read_marker(batch[0] / u) for u in truth]
    good = [r for r, t in zip(records, truth.values()) if not t["corrupt"] and not t["defect"]]
    target = good[0]
    others = [r["summary"]["params"]["s"][0] / r["summary"]["params"]["b"][0] for r in good[1:]]
    moved = json.loads(json.dumps(target))
    b1 = moved["summary"]["params"]["b"][0]
    med, mad = float(np.median(others)), float(np.median(np.abs(np.array(others) - np.median(others))))
    bias = med + 12 * mad / 0.6745  # robust z of about 12
    assert abs(bias) < 0.5
    moved["summary"]["params"]["s"][0] = bias * b1
    table = fleet_table([moved, *good[1:]], Tolerances(bias_abs_max=0.5, angle_deg_from_90_max=0.5, rms_max=0.01))
    row = table.rows[0]
    assert row["verdict"] == "pass" and row["outlier"].startswith("s1 z=+")
    assert not any(r["outlier"] for r in table.rows[1:])


def test_robust_z_ignores_a_held_parameter():
    assert not robust_z(np.full(10, 1.5707963)).any()
    z = robust_z(np.array([0.0, 1.0, -1.0, 0.5, -0.5, 40.0]))
    assert abs(z[-1]) > 5 and all(abs(z[:-1]) < 5)


def test_parquet_beside_csv(batch):
    import pyarrow  # noqa: F401  (the test extra: fleet.parquet is written only with it)
    import pyarrow.parquet as pq

    t = pq.read_table(batch[0] / "fleet.parquet").to_pylist()
    assert [r["unit"] for r in t] == list(_table(batch[0]))


def test_histograms_written(fleet, batch, tmp_path):
    out = tmp_path / "res"
    shutil.copytree(batch[0], out)
    code, stdout, err = _main(["batch", fleet / "manifest.yaml", "--out", out, "--workers", "1"])
    assert code == 0, err
    pngs = sorted(p.name for p in out.glob("fleet_*.png"))
    assert pngs == sorted(f"fleet_{n}.png" for n in (*BASE_NAMES, "rms_residual"))
    assert all((out / p).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" for p in pngs)
    page = (out / "report.html").read_text()
    assert page.count("data:image/png;base64,") == len(pngs)  # the same histograms, inline


def test_fleet_page_puts_the_yield_first_and_flags_the_bad_units(batch, truth):
    out = batch[0]
    page = (Path(out) / "report.html").read_text()
    good = N_UNITS - N_CORRUPT - N_DEFECTIVE
    assert "Content-Security-Policy" in page and "<script" not in page.lower()
    head, rest = page.split('id="flagged"', 1)
    assert f"yield {good}/{N_UNITS} = {100 * good / N_UNITS:.1f} % pass" in head
    flagged, every = rest.split('id="units"', 1)
    bad = {u for u, t in truth.items() if t["corrupt"] or t["defect"]}
    assert all(f"<td>{u}</td>" in flagged for u in bad)
    assert not any(f"<td>{u}</td>" in flagged for u in set(truth) - bad if not _outlier(out, u))
    assert all(f"<td>{u}</td>" in every for u in truth)


def _outlier(out: Path, unit: str) -> bool:
    return bool(_table(Path(out))[unit]["outlier"])


def test_csv_manifest_and_folder(fleet, tmp_path):
    listing = tmp_path / "units.csv"
    listing.write_text(f"unit,data,gravity.value,fit.mode\nA1,{fleet / 'recordings' / 'unit01.csv'},9.81,\n"
                       f"A2,{fleet / 'recordings' / 'unit02.csv'},,samples\n")
    m = load_manifest(listing)
    assert [u.id for u in m.units] == ["A1", "A2"]
    assert m.units[0].config.gravity.value == 9.81 and m.units[0].config.fit.mode == "means"
    assert m.units[1].config.gravity.value is None and m.units[1].config.fit.mode == "samples"
    assert m.units[0].settings_hash != m.units[1].settings_hash
    run = tmp_path / "run.yaml"
    run.write_text("data: {path: ignored.csv}\nfit: {weights: uniform}\n")
    f = load_manifest(fleet / "recordings", config=run)
    assert len(f.units) == N_UNITS and f.units[0].id == "unit01"
    assert all(u.config.fit.weights == "uniform" and u.config.data.path.endswith(f"{u.id}.csv") for u in f.units)


BAD_MANIFESTS = [
    ("units: [{id: ../evil, data: a.csv}]", "units[0].id: unit id '../evil' is not a safe folder name"),
    ("units: [{id: a/b, data: a.csv}]", "is not a safe folder name"),
    ("units: [{id: U1, data: a.csv}, {id: u1, data: b.csv}]", "unit id 'u1' is given twice (units[0])"),
    ("units: [{id: U1}]", "units[0].data: no data file"),
    ("units: [{id: U1, data: a.csv, colour: red}]", "units[0].colour: unknown key 'colour'"),
    ("unit: [{id: U1, data: a.csv}]", "unknown key 'unit'"),
    ("tolerances: {bias_max: 1}\nunits: [{id: U1, data: a.csv}]", "tolerances.bias_max: unknown key 'bias_max'"),
    ("tolerances: {rms_max: -1}\nunits: [{id: U1, data: a.csv}]", "tolerances.rms_max: -1 must be a non-negative"),
    ("settings: {fit: {mode: fast}}\nunits: [{id: U1, data: a.csv}]", "units[0]: fit.mode: unknown fit mode 'fast'"),
    ("settings: {data: {path: x.csv}}\nunits: [{id: U1, data: a.csv}]", "settings.data.path: files are named per unit"),
    ("format_version: 2\nunits: [{id: U1, data: a.csv}]", "format_version 2 is not supported"),
    ("units: []", "no units"),
    ("units: [{id: Fleet.csv, data: a.csv}]", "unit id 'Fleet.csv' is the name of a fleet report file"),
    ("folder: nowhere", "nowhere: folder: is not a folder"),
    ("- a\n- b", "top level must be a mapping"),
]


@pytest.mark.parametrize("text,message", BAD_MANIFESTS)
def test_bad_manifest_exit_2_one_line(tmp_path, run_cli, text, message):
    m = tmp_path / "manifest.yaml"
    m.write_text(text + "\n")
    r = run_cli(["batch", m, "--out", tmp_path / "res"])
    assert r.code == 2 and r.out == ""
    assert r.err.startswith("imucal: error: ") and r.err.count("\n") == 1, r.err
    assert message in r.err, r.err
    assert not (tmp_path / "res").exists()


def test_bad_csv_manifest_and_options(tmp_path, run_cli):
    m = tmp_path / "units.csv"
    m.write_text("id,file\nU1,a.csv\n")
    r = run_cli(["batch", m, "--out", tmp_path / "res"])
    assert r.code == 2 and "header 'id,file' lacks unit and data" in r.err and r.err.count("\n") == 1
    m.write_text("unit,data,fit.speed\nU1,a.csv,1\n")
    r = run_cli(["batch", m, "--out", tmp_path / "res"])
    assert r.code == 2 and "header: unknown column 'fit.speed'" in r.err, r.err
    m.write_text("unit,data,gravity.colour\nU1,a.csv,\n")  # an empty cell overrides nothing ...
    r = run_cli(["batch", m, "--out", tmp_path / "res"])  # ... but the column is still checked
    assert r.code == 2 and "unknown column 'gravity.colour'" in r.err, r.err
    m2 = tmp_path / "ok.yaml"
    m2.write_text("units: [{id: U1, data: a.csv}]\n")
    r = run_cli(["batch", m2, "--out", tmp_path / "res", "--workers", "2", "--scheduler", "tcp://x:1"])
    assert r.code == 2 and "--workers and --scheduler both given" in r.err
    r = run_cli(["batch", m2, "--out", tmp_path / "res", "--workers", "0"])
    assert r.code == 2 and "--workers 0 must be an integer from 1" in r.err
    r = run_cli(["batch", m2, "--out", m2])
    assert r.code == 2 and "parent is not a directory" in r.err
    r = run_cli(["batch", tmp_path, "--out", tmp_path / "."])
    assert r.code == 2 and "--out: is the folder of recordings" in r.err


def test_missing_file_is_a_unit_error_not_a_batch_error(tmp_path, run_cli):
    m = tmp_path / "manifest.yaml"
    m.write_text("units: [{id: U1, data: absent.csv}]\n")
    r = run_cli(["batch", m, "--out", tmp_path / "res", "--workers", "1", "--no-figures"])
    assert r.code == 0, r.err
    row = _table(tmp_path / "res")["U1"]
    assert row["status"] == "error" and "file not found" in row["error"]
    assert not (tmp_path / "res" / "U1" / DONE_FILE).exists()  # nothing to hash: tried again next time
    assert "absent.csv: data: file not found" in r.out


def test_simulate_fleet_options(tmp_path, run_cli):
    cfg = ROOT / "configs" / "simulate_fleet.yaml"
    r = run_cli(["simulate", cfg, "--out", tmp_path / "x.csv", "--defective", "1"])
    assert r.code == 2 and "need --fleet N" in r.err
    r = run_cli(["simulate", cfg, "--out", tmp_path / "f", "--fleet", "3", "--defective", "4"])
    assert r.code == 2 and "--defective 4 must be an integer from 0 to 3" in r.err
    r = run_cli(["simulate", cfg, "--out", tmp_path / "f", "--fleet", "3", "--spread", "bias=x"])
    assert r.code == 2 and "'x' is not a number" in r.err
    r = run_cli(["simulate", cfg, "--out", tmp_path / "f", "--fleet", "3", "--spread", "bias=0.1,angle=0"])
    assert r.code == 0, r.err
    assert sorted(p.name for p in (tmp_path / "f").iterdir()) == ["manifest.yaml", "recordings", "truth.csv"]
    assert sorted(p.name for p in (tmp_path / "f" / "recordings").iterdir()) == ["unit1.csv", "unit2.csv", "unit3.csv"]
    assert len(load_manifest(tmp_path / "f" / "manifest.yaml").units) == 3


def test_progress_bar_on_a_terminal_only(capsys):
    from imucal.fleet.run import progress_bar

    with progress_bar(2, enabled=True) as step:
        step({"status": "ok"})
        step({"status": "error"})
    err = capsys.readouterr().err
    assert "2/2" in err and "1 not ok" in err
    with progress_bar(2) as step:  # stderr is not a terminal under pytest
        step({"status": "ok"})
    assert capsys.readouterr().err == ""


def test_binary_file_is_a_unit_error(tmp_path, run_cli):
    from imucal.fleet.population import _damage

    (tmp_path / "U1.csv").write_bytes(_damage("", "binary bytes"))
    r = run_cli(["batch", tmp_path, "--out", tmp_path / "res", "--workers", "1", "--no-figures"])
    assert r.code == 0, r.err
    assert "U1: fail: " in r.out and "is a binary file (NUL bytes)" in r.out
    assert read_marker(tmp_path / "res" / "U1")["status"] == "error"


def test_unreachable_scheduler_one_line(tmp_path, run_cli, monkeypatch):
    import distributed  # noqa: F401  (the test extra)
    import imucal.fleet.run as fleet_run

    monkeypatch.setattr(fleet_run, "SCHEDULER_TIMEOUT", "1s")
    m = tmp_path / "m.yaml"
    m.write_text("units: [{id: U1, data: a.csv}]\n")
    r = run_cli(["batch", m, "--out", tmp_path / "res", "--scheduler", "tcp://127.0.0.1:9"])
    assert r.code == 2 and r.err.count("\n") == 1, r.err
    assert "--scheduler: cannot reach the scheduler 'tcp://127.0.0.1:9'" in r.err
    assert not (tmp_path / "res").exists()
