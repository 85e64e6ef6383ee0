"""Issue 25, trust at the edges: still intervals that end where a slow motion starts, `apply` of a
calibration to data in another unit, internal errors on bad input to `noise` and `fit.fix`, and a
noise file in the wrong unit.

Each case generates its data here; error paths check the one-line message (file, field, fix), the
exit status 2 and that nothing was left behind.
"""
from __future__ import annotations

import numpy as np
import pytest

from imucal.analysis.simulate import (PosePlan, cube_directions, frame_matrix, mems_counts_sensor, si_sensor,
                                      simulate)
from imucal.data.static import detect_static, still_span

#: A slow, smooth change of pose: 10 s from one hold to the next, no vibration (the moving variance
#: of its first second stays below the threshold).
SLOW = dict(hold=3.0, transition=10.0, rate=100.0, vibration=0.0)


def one_line_error(err: str, *parts: str) -> None:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("imucal: error: "), err
    for p in parts:
        assert p in lines[0], (p, lines[0])


def _slow_recording(kind: str, seed: int):
    sensor = si_sensor(np.random.default_rng(seed)) if kind == "si" else mems_counts_sensor(np.random.default_rng(seed))
    return sensor, simulate(sensor, PosePlan(cube_directions(), **SLOW), seed=seed)


# --- 1. still intervals end before a slow motion starts -----------------------------------------
@pytest.mark.parametrize("kind", ["si", "counts"])
def test_intervals_stop_where_a_slow_motion_starts(kind):
    """Every hold gives one interval; none reaches more than 0.4 s beyond its hold (before the fix:
    1.2 s), and no sample in it is more than 3 noise sigmas from the hold's noise-free reading
    (before: 20 sigma)."""
    sensor, sim = _slow_recording(kind, seed=1)
    iv = detect_static(sim.t, sim.raw)
    assert iv.n == len(sim.hold_bounds)
    clean = sim.accel @ frame_matrix(np.array(sensor.angles)) * np.array(sensor.b)  # raw less shift
    for k, (a, b) in enumerate(zip(iv.start, iv.end)):
        ha, hb = sim.hold_bounds[k]
        assert ha - 40 <= a < b <= hb + 40, (k, a, b, ha, hb)
        off = np.abs(clean[a:b] - clean[ha]) / np.array(sensor.noise)
        assert off.max() < 3.0, (k, off.max())


def test_a_still_run_keeps_its_edges():
    """White noise, a linear drift (settling) and a single spike are not the start of a motion."""
    rng = np.random.default_rng(7)
    n = 600
    x = rng.normal(0, 1.0, (n, 3)) + 1000.0
    assert still_span(x, 10) == (0, n)
    drift = x + np.linspace(0, 3.0, n)[:, None]  # 3 sigma over the run
    assert still_span(drift, 10) == (0, n)
    spike = x.copy()
    spike[n - 40] += 8.0
    assert still_span(spike, 10) == (0, n)


def test_a_slow_start_is_cut_where_it_began():
    """A quadratic departure from the last 150 rows on: the cut lies within 40 rows of its start."""
    rng = np.random.default_rng(3)
    n, onset = 600, 450
    x = rng.normal(0, 1.0, (n, 3))
    u = np.maximum(np.arange(n) - onset, 0)
    x[:, 1] += 40.0 * (u / (n - onset)) ** 2  # 40 sigma at the end of the run
    lo, hi = still_span(x, 10)
    assert lo == 0 and onset - 40 <= hi <= onset + 40
    lo_r, hi_r = still_span(x[::-1], 10)  # the same motion ending a run's start
    assert (lo_r, hi_r) == (n - hi, n)


def test_streamed_slow_recording_gives_the_same_intervals(tmp_path, monkeypatch):
    import imucal.data.blocks as blocks_mod
    import imucal.data.spill as spill_mod
    from imucal.data.spec import DataSpec
    from imucal.data.stream import StreamedRecording

    monkeypatch.setattr(blocks_mod, "CHUNK_BYTES", 50_000)
    monkeypatch.setattr(spill_mod, "SPILL_ROWS", 997)
    _, sim = _slow_recording("counts", seed=2)
    path = tmp_path / "slow.csv"
    path.write_text(sim.to_csv_text())
    iv = detect_static(sim.t, sim.raw)
    s = StreamedRecording(DataSpec(path=str(path)), keep_samples=True)
    np.testing.assert_array_equal(s.intervals.start, iv.start)
    np.testing.assert_array_equal(s.intervals.end, iv.end)
    np.testing.assert_array_equal(s.samples.raw, sim.raw[iv.sample_mask(sim.t.size)])


# --- 3. bad input to `noise` and `fit.fix`: one line, exit 2, not an internal error --------------
def _still_log(path, scale: float = 1.0, const_axis: int | None = None, n: int = 3000):
    rng = np.random.default_rng(11)
    y = rng.normal(0.0, 1.0, (n, 3)) * scale
    if const_axis is not None:
        y[:, const_axis] = 9.81
    t = np.arange(n) / 100.0
    np.savetxt(path, np.column_stack([t, y]), delimiter=",", header="t,ax,ay,az", comments="", fmt="%.17g")
    return path


def test_noise_on_an_axis_that_never_changes_is_refused(run_cli, tmp_path, unchanged):
    src = _still_log(tmp_path / "stuck.csv", const_axis=2)
    with unchanged():
        r = run_cli(["noise", "--data", src, "--json", tmp_path / "n.json"])
    assert r.code == 2
    one_line_error(r.err, "stuck.csv: data: axis z reads 9.81 in all 3000 still samples: it never changes",
                   "(fix: check axis z of the sensor, or record it at its full resolution)")


@pytest.mark.parametrize("scale", [1e-200, 1e-30, 1e25])
def test_noise_of_tiny_or_huge_readings_is_that_of_the_same_readings_scaled(run_cli, tmp_path, scale):
    """Readings of 1e-200 gave 'SVD did not converge' (exit 3): each axis's curve and fit are now
    computed in units of its own size, so the estimates scale with the readings."""
    import json

    ref, big = tmp_path / "ref.json", tmp_path / "scaled.json"
    assert run_cli(["noise", "--data", _still_log(tmp_path / "one.csv"), "--json", ref]).code == 0
    r = run_cli(["noise", "--data", _still_log(tmp_path / "s.csv", scale=scale), "--json", big])
    assert r.code == 0, r.err
    a, b = json.loads(ref.read_text())["axes"], json.loads(big.read_text())["axes"]
    for axis in "xyz":
        assert b[axis]["white_density"] == pytest.approx(a[axis]["white_density"] * scale, rel=1e-6)
        assert b[axis]["bias_instability"] == pytest.approx(a[axis]["bias_instability"] * scale, rel=1e-6)


def test_fit_fix_with_every_parameter_is_refused(run_cli, tmp_path, unchanged):
    from conftest import write_simulation

    write_simulation(tmp_path / "si.csv", si_sensor(np.random.default_rng(1)), cube_directions(), seed=1)
    cfg = tmp_path / "all_fixed.yaml"
    cfg.write_text("data: {path: si.csv, unit: m/s^2}\nfit:\n  fix: [s1, s2, s3, b1, b2, b3, phi, psi, theta]\n")
    with unchanged():
        r = run_cli(["calibrate", cfg, "--out", tmp_path / "out", "--no-figures"])
    assert r.code == 2
    one_line_error(r.err, "all_fixed.yaml: fit.fix: all 9 parameters are fixed, so nothing is left to fit",
                   "(fix: drop at least one from fit.fix")
    # ... the angles by flag and the rest in the file: the same refusal
    cfg.write_text("data: {path: si.csv, unit: m/s^2}\nfit:\n  fix: [s1, s2, s3, b1, b2, b3]\n")
    with unchanged():
        r = run_cli(["calibrate", cfg, "--fix-angles", "--out", tmp_path / "out", "--no-figures"])
    assert r.code == 2 and "fit.fix: all 9 parameters are fixed" in r.err


def test_fit_fix_with_every_base_parameter_beside_an_effect_is_a_fit():
    from imucal.config.run import config_from_dict

    cfg = config_from_dict({"data": {"path": "x.csv"},
                            "fit": {"fix": ["s1", "s2", "s3", "b1", "b2", "b3", "phi", "psi", "theta"],
                                    "effects": ["bias_drift"]}})
    assert len(cfg.fit.fix) == 9


# --- 2. apply refuses data in another unit than its calibration's --------------------------------
@pytest.fixture(scope="module")
def two_units(tmp_path_factory):
    """A counts recording with its calibration, and an m/s^2 recording with its own."""
    from conftest import calibrate_file, write_simulation

    root = tmp_path_factory.mktemp("units")
    counts = write_simulation(root / "counts.csv", mems_counts_sensor(np.random.default_rng(4)), cube_directions(),
                              seed=4)
    si = write_simulation(root / "si.csv", si_sensor(np.random.default_rng(5)), cube_directions(), seed=5)
    cals = {}
    for name, rec, unit in (("counts", counts, "raw"), ("si", si, "m/s^2")):
        cals[name] = root / f"{name}.yaml"
        calibrate_file(rec.path, data={"unit": unit}).calibration.save(cals[name])
    return root, {"counts": counts.path, "si": si.path}, cals


@pytest.mark.parametrize("cal, data, looks, takes", [
    ("counts", "si", "m/s^2", "raw counts"),
    ("si", "counts", "raw counts", "m/s^2"),
])
def test_apply_to_data_in_another_unit_is_refused(run_cli, two_units, tmp_path, unchanged, cal, data, looks, takes):
    root, recs, cals = two_units
    with unchanged():
        r = run_cli(["apply", cals[cal], "--data", recs[data], "--out", tmp_path / "a.csv"])
    assert r.code == 2
    one_line_error(r.err, f"{recs[data]}: data.unit: |a| at rest ", "m/s^2 after calibration, where the calibration's "
                   "gravity is 9.807 m/s^2 (median of 26 still intervals)",
                   f"the data look like {looks} (|reading| at rest ", f"while the calibration takes {takes}",
                   "--no-gravity-check writes the output anyway)")


def test_apply_with_no_gravity_check_writes_and_warns(run_cli, two_units, tmp_path):
    root, recs, cals = two_units
    r = run_cli(["apply", cals["counts"], "--data", recs["si"], "--out", tmp_path / "a.csv", "--no-gravity-check"])
    assert r.code == 0 and (tmp_path / "a.csv").exists()
    assert r.err.startswith("imucal: warning: |a| at rest ") and "the data look like m/s^2" in r.err


@pytest.mark.parametrize("which", ["counts", "si"])
def test_apply_to_its_own_unit_reports_a_at_rest(run_cli, two_units, tmp_path, which):
    root, recs, cals = two_units
    r = run_cli(["apply", cals[which], "--data", recs[which], "--out", tmp_path / "a.csv"])
    assert r.code == 0 and r.err == ""
    assert "; |a| at rest 9.81 m/s^2 after calibration, where the calibration's gravity is 9.807 m/s^2" in r.out


def test_apply_to_a_log_without_still_spans_says_it_was_not_checked(run_cli, two_units, tmp_path):
    root, recs, cals = two_units
    t = np.arange(3000) / 100.0
    moving = np.column_stack([t, 9.0 * np.sin(0.7 * t), 9.0 * np.cos(1.1 * t), 3.0 * np.sin(0.3 * t)])
    src = tmp_path / "moving.csv"
    np.savetxt(src, moving, delimiter=",", header="t,ax,ay,az", comments="", fmt="%.9g")
    r = run_cli(["apply", cals["si"], "--data", src, "--out", tmp_path / "a.csv"])
    assert r.code == 0 and "; no still span: |a| at rest not checked" in r.out


# --- 4. a noise file in another unit than the recording's ----------------------------------------
def _noise_json(path, density: float, unit: str):
    import json

    axis = {"white_density": density}
    path.write_text(json.dumps({"unit": unit, "axes": {"x": axis, "y": axis, "z": axis}}))
    return path


def _noise_run(tmp_path, data, unit: str, noise):
    """The run file that calibrates ``data`` with the noise file ``noise``, and the command."""
    cfg = tmp_path / "run.yaml"
    cfg.write_text(f"data: {{path: {data}, unit: {unit}}}\nfit: {{noise: {noise.name}}}\n")
    return ["calibrate", cfg, "--out", tmp_path / "out", "--no-figures", "--quiet"]


#: White-noise densities of the simulated sensors at 100 Hz: 4 counts and 0.01 m/s^2 per sample.
COUNTS_DENSITY, SI_DENSITY = 4.0 / 10.0, 0.01 / 10.0


@pytest.mark.parametrize("data, unit, density, label, ratio", [
    ("counts", "raw", SI_DENSITY, "raw", "0.00"),  # an m/s^2 log's noise, labelled raw: was "reduced chi-square 1e5"
    ("si", "m/s^2", COUNTS_DENSITY, "m/s^2", "4"),  # a counts log's noise: was "b1, b2, b3 undetermined"
])
def test_a_noise_file_in_another_unit_is_refused_naming_both(run_cli, two_units, tmp_path, unchanged,
                                                             data, unit, density, label, ratio):
    root, recs, cals = two_units
    noise = _noise_json(tmp_path / "noise.json", density, label)
    args = _noise_run(tmp_path, recs[data], unit, noise)
    with unchanged():
        r = run_cli(args)
    assert r.code == 2
    one_line_error(r.err, "noise.json: unit: its noise of an interval mean is " + ratio,
                   f"times the noise the recording {recs[data]} shows at rest (median over 26 still intervals",
                   f"the noise file is in another unit than the recording (both labelled {label})",
                   "(fix: measure the noise on a still log in the recording's unit")


def test_a_kalibr_noise_file_in_g_for_a_counts_log_names_its_unit(run_cli, two_units, tmp_path, unchanged):
    """Kalibr's density is in m/s^2 (converted by each axis's scale): one written in g is 9.81 times too small."""
    root, recs, cals = two_units
    right = 4.0 / (16384.0 / 9.80665) / 10.0  # 4 counts at 16384 counts per g, 100 Hz [m/s^2/sqrt(Hz)]
    noise = tmp_path / "imu.yaml"
    noise.write_text(f"accelerometer_noise_density: {right / 9.80665!r}\n")
    args = _noise_run(tmp_path, recs["counts"], "raw", noise)
    with unchanged():
        r = run_cli(args)
    assert r.code == 2
    one_line_error(r.err, "imu.yaml: unit: its noise of an interval mean is 0.1",
                   "(noise file: m/s^2, data.unit: raw)")
    noise.write_text(f"accelerometer_noise_density: {right!r}\n")
    assert run_cli(args).code == 0


@pytest.mark.parametrize("data, unit, density", [("counts", "raw", COUNTS_DENSITY), ("si", "m/s^2", SI_DENSITY)])
def test_a_noise_file_in_the_recordings_unit_is_used(run_cli, two_units, tmp_path, data, unit, density):
    root, recs, cals = two_units
    r = run_cli(_noise_run(tmp_path, recs[data], unit, _noise_json(tmp_path / "noise.json", density, unit)))
    assert r.code == 0, r.err


def _edge_cut_reference(line, m: int, sides: str = "both"):
    """imucal.data.static._edge_cut as it was written first (each edge's z apart, numpy's own row
    reductions): the faster one must give the same cut on every run."""
    from imucal.data.static import EDGE_BACK, EDGE_CORE_WINDOWS, EDGE_Z, _running, _std_rows

    res, r = line.res, line.r
    n = res.shape[0]
    c0, c1 = n // 4, n - n // 4
    cs = np.zeros((n + 1, res.shape[1]))
    np.cumsum(res, axis=0, out=cs[1:])
    scales, rows, w = [], [], m
    while w * EDGE_CORE_WINDOWS <= line.nc or not scales:
        rows.append(np.maximum(_std_rows(_running(cs[c0:c1 + 1], w)) * np.sqrt(w),
                               np.maximum(line.white, line.floor) if not rows else rows[-1]))
        scales.append(w)
        w *= 2
    ws, rows_w = np.array(scales), np.array(rows)

    def z(size, at, mean):
        row = rows_w[np.maximum(np.searchsorted(ws, size, side="right") - 1, 0)]
        return (np.abs(mean) / line.sigma(row, at, size.astype(float))).max(axis=1)

    i = np.arange(c1, n)
    z_end = z(n - i, (r[i] + r[-1]) / 2, (cs[n] - cs[i]) / (n - i)[:, None])
    j = np.arange(1, c0 + 1)
    z_start = z(j, (r[0] + r[j - 1]) / 2, cs[j] / j[:, None])
    top_end = z_end.max(initial=0.0) if sides != "start" else 0.0
    top_start = z_start.max(initial=0.0) if sides != "end" else 0.0
    if max(top_end, top_start) <= EDGE_Z:
        return None
    dev = _running(cs, m)
    near = (np.abs(dev) <= EDGE_BACK * line.sigma(rows_w[0], r[:n - m + 1] + (m - 1) / 2,
                                                  np.full(n - m + 1, float(m)))).all(axis=1)
    if top_end >= top_start:
        k = int(i[np.argmax(z_end)])
        back = np.flatnonzero(near[:max(k - m + 1, 0)])
        return 0, (int(back[-1]) + m if back.size else k)
    k = int(j[np.argmax(z_start)])
    ahead = np.flatnonzero(near[k:])
    return (k + int(ahead[0]) if ahead.size else k), n


@pytest.mark.parametrize("seed", range(40))
def test_the_edge_cut_is_the_reference_one(seed):
    """The edge test (issue 30: fewer numpy calls) cuts every run where its first version did: white
    noise, counts, drifts and slow starts at either edge, at each side."""
    from imucal.data.static import _edge_cut, _Line

    rng = np.random.default_rng(seed)
    n = int(rng.integers(40, 3000))
    x = rng.normal(0, rng.uniform(0.5, 50), (n, 3)) + rng.uniform(-3e4, 3e4, 3)
    if seed % 3 == 0:
        x = np.round(x)  # counts
    if seed % 4 == 1:
        x += np.linspace(0, rng.uniform(0, 20), n)[:, None]  # a drift
    if seed % 2 == 0:
        onset = int(rng.integers(n // 2, n))
        u = np.maximum(np.arange(n) - onset, 0) / max(n - onset, 1)
        x[:, int(rng.integers(3))] += rng.uniform(0, 60) * u ** 2
        if seed % 8 == 0:
            x = x[::-1].copy()
    q = 1.0 if seed % 3 == 0 else 0.0
    m = int(rng.integers(3, max(4, n // 8)))
    line = _Line.of(x, q)
    for sides in ("both", "start", "end"):
        assert _edge_cut(line, m, sides) == _edge_cut_reference(line, m, sides), (seed, sides)
