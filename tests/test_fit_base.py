"""fit.base (issue 27): a run file takes what a temperature sweep's few poses cannot determine from a
multi-pose log's calibration: its values start the fit and the parameters in fit.fix are held at them."""
from __future__ import annotations

import numpy as np

from imucal.calibration.frozen import load_calibration
from imucal.config.run import config_from_dict, load_config
from imucal.model.parameters import BASE_NAMES
from test_thermal import sweep

HELD = ["b1", "b2", "b3", "phi", "psi", "theta"]


def test_the_base_calibrations_values_are_held(si_run, run_cli, tmp_path):
    """The sweep's calibration holds b1..theta at the multi-pose calibration's values (a path relative to the
    run file), fits the offsets and the temperature terms; the run file's own initial values win."""
    base = tmp_path / "base.yaml"
    si_run.calibration.save(base)
    want = si_run.calibration.params.value_dict()
    data = sweep(tmp_path / "sweep.csv", hours=1.0)
    run = tmp_path / "run.yaml"
    run.write_text(f"data: {{path: {data.name}, time_unit: s}}\nfit:\n  base: base.yaml\n  fix: {HELD}\n"
                   .replace("'", ""))
    cfg = load_config(run)
    assert {n: cfg.fit.initial[n] for n in BASE_NAMES} == {n: want[n] for n in BASE_NAMES}
    r = run_cli(["discover", "--config", run, "--out", tmp_path / "cal"])
    assert r.code == 0, r.err
    cal = load_calibration(tmp_path / "cal" / "calibration.yaml")
    got = cal.params.value_dict()
    for n in HELD:
        assert got[n] == want[n] and cal.params[n].fixed, n
    assert not np.allclose([got[n] for n in ("s1", "s2", "s3")], [want[n] for n in ("s1", "s2", "s3")])
    own = config_from_dict({"data": {"path": str(data), "time_unit": "s"},
                            "fit": {"base": str(base), "fix": {"phi": 1.5}}})
    assert own.fit.initial["phi"] == 1.5 and own.fit.initial["b1"] == want["b1"]


def test_a_missing_or_foreign_base_is_one_line(si_run, run_cli, tmp_path, unchanged):
    data = sweep(tmp_path / "sweep.csv", hours=0.2)
    run = tmp_path / "run.yaml"
    run.write_text(f"data: {{path: {data.name}, time_unit: s}}\nfit: {{base: nowhere.yaml, fix: [phi]}}\n")
    with unchanged():
        r = run_cli(["calibrate", run, "--out", tmp_path / "o"])
    assert r.code == 2 and r.err.count("\n") == 1 and "fit.base" in r.err and "nowhere.yaml" in r.err, r.err
    si_run.calibration.save(tmp_path / "base.yaml")
    run.write_text(f"data: {{path: {data.name}, time_unit: s, unit: m/s^2}}\nfit: {{base: base.yaml, fix: [phi]}}\n")
    r = run_cli(["calibrate", run, "--out", tmp_path / "o"])
    assert r.code == 2 and "raw unit" in r.err and "fit.base" in r.err, r.err
    assert not (tmp_path / "o").exists()


def test_a_hostile_base_path_is_one_line(run_cli, tmp_path, unchanged):
    """fit.base naming a FIFO, a directory, a C-comment-like name or a recording: one line, exit 2, nothing
    written, and the FIFO never opened for reading (the run would hang)."""
    import os

    data = sweep(tmp_path / "sweep.csv", hours=0.2)
    os.mkfifo(tmp_path / "fifo.yaml")
    (tmp_path / "dir.yaml").mkdir()
    run = tmp_path / "run.yaml"
    for base, words in (("fifo.yaml", "FIFO"), ("dir.yaml", "directory"), ("'*/'", "not found"),
                        (data.name, "not a calibration file")):
        run.write_text(f"data: {{path: {data.name}, time_unit: s}}\nfit: {{base: {base}, fix: [phi]}}\n")
        with unchanged():
            r = run_cli(["calibrate", run, "--out", tmp_path / "o"])
        assert r.code == 2 and r.err.count("\n") == 1 and "fit.base" in r.err and words in r.err, r.err
