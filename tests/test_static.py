"""Static-interval detection: moving variance, window and minimum duration in seconds,
threshold from the data, intervals reported as a table (start, end, mean, std, direction)."""
from __future__ import annotations


import numpy as np
import pytest

from conftest import real_file
from imucal.data.load import load_recording
from imucal.data.spec import DataSpec
from imucal.errors import ImucalError
from imucal.analysis.simulate import cube_directions, frame_matrix, mems_counts_sensor, si_sensor
from imucal.data.static import StaticSettings, detect_static, moving_variance


def detect(rec, settings: StaticSettings = StaticSettings()):
    return detect_static(rec.sim.t, rec.sim.raw, settings)


def _assert_matches_holds(iv, sim):
    """One interval per hold, each entirely inside its hold (no moving sample)."""
    assert iv.n == len(sim.hold_bounds)
    for k, (a, b) in enumerate(zip(iv.start, iv.end)):
        ha, hb = sim.hold_bounds[k]
        assert ha <= a < b <= hb, (k, a, b, ha, hb)
        assert sim.still[a:b].all()


@pytest.mark.parametrize("which", ["counts_recording", "si_recording"])
def test_one_interval_per_known_hold(request, which):
    rec = request.getfixturevalue(which)
    iv = detect(rec)
    _assert_matches_holds(iv, rec.sim)
    # 3 s holds: at least min_duration (1.5 s) kept after trimming, at most the hold itself
    dur = iv.t_end - iv.t_start
    assert np.all(dur >= 1.5) and np.all(dur <= 3.0)


def test_interval_means_and_noise(counts_recording):
    rec = counts_recording
    sim, sensor = rec.sim, rec.sensor
    iv = detect(rec)
    E = frame_matrix(np.array(sensor.angles))
    truth = np.array(sensor.s) + np.array(sensor.b) * (sim.accel[iv.start] @ E)  # noise-free raw
    n = iv.n_samples[:, None]
    noise = np.array(sensor.noise)
    # means within 5 standard errors of the noise-free reading (quantisation adds 1/12 count^2)
    assert np.all(np.abs(iv.mean - truth) < 5 * np.sqrt(noise**2 + 1 / 12) / np.sqrt(n))
    # within-interval std estimates the white noise
    assert np.median(iv.std) == pytest.approx(np.sqrt(noise[0] ** 2 + 1 / 12), rel=0.1)
    # standard error of the mean: white noise, so the batch-means inflation stays near 1
    assert 1.0 <= iv.noise_inflation < 1.6
    np.testing.assert_allclose(iv.mean_std, iv.std / np.sqrt(n) * np.sqrt(iv.noise_inflation), rtol=1e-12)
    np.testing.assert_allclose(iv.t_mid, [sim.t[a:b].mean() for a, b in zip(iv.start, iv.end)])


def test_window_and_duration_are_seconds_not_samples(sim_csv):
    """The same plan sampled at 50 and 200 Hz gives the same intervals in seconds."""
    sensor = si_sensor(np.random.default_rng(5))
    dirs = cube_directions("faces+corners")
    slow = sim_csv("rate50", sensor, dirs, seed=3, rate=50.0)
    fast = sim_csv("rate200", sensor, dirs, seed=3, rate=200.0)
    a, b = detect(slow), detect(fast)
    assert a.n == b.n == len(dirs)
    np.testing.assert_allclose(a.t_start, b.t_start, atol=0.1)
    np.testing.assert_allclose(a.t_end, b.t_end, atol=0.1)


def test_min_duration_drops_short_holds(counts_recording):
    assert detect(counts_recording, StaticSettings(min_duration=3.5)).n == 0
    assert detect(counts_recording, StaticSettings(min_duration=1.0)).n == counts_recording.n_poses


def test_threshold_is_set_from_the_data(counts_recording):
    """Automatic threshold: scale-free, so a change of raw unit finds the same intervals."""
    sim = counts_recording.sim
    base = detect_static(sim.t, sim.raw)
    for k in (1e-3, 0.37, 1000.0):
        iv = detect_static(sim.t, sim.raw * k + 5.0)
        np.testing.assert_array_equal(iv.start, base.start)
        np.testing.assert_array_equal(iv.end, base.end)
        assert iv.threshold == pytest.approx(base.threshold * k**2, rel=0.2)


def test_threshold_lies_between_noise_floor_and_motion(counts_recording):
    sim = counts_recording.sim
    iv = detect(counts_recording)
    var = moving_variance(sim.raw, int(round(0.5 * 100)))
    still_var = np.median(var[sim.still])
    moving_var = np.median(var[~sim.still])
    assert still_var < iv.threshold < moving_var


def test_explicit_threshold(counts_recording):
    sim = counts_recording.sim
    assert detect_static(sim.t, sim.raw, StaticSettings(threshold=1e-6)).n == 0
    assert detect_static(sim.t, sim.raw, StaticSettings(threshold=1e-6)).threshold == 1e-6


def test_still_only_log_is_one_interval(sim_csv):
    sensor = mems_counts_sensor(np.random.default_rng(1))
    rec = sim_csv("still", sensor, np.array([[0.0, 0.0, 1.0]]), seed=1, hold=60.0)
    assert detect(rec).n == 1


def test_motion_only_log_has_no_interval():
    rng = np.random.default_rng(0)
    t = np.arange(6000) / 100.0
    raw = 1000 * np.column_stack([np.sin(0.7 * t), np.cos(1.1 * t), np.sin(0.3 * t + 1)])
    raw += rng.normal(0, 4, raw.shape)  # slow continuous motion, never still
    assert detect_static(t, raw).n == 0


def test_trim_removes_edges(counts_recording):
    sim = counts_recording.sim
    a = detect_static(sim.t, sim.raw, StaticSettings(trim=0.0))
    b = detect_static(sim.t, sim.raw, StaticSettings(trim=0.25))
    np.testing.assert_array_equal(b.start - a.start, 25)
    np.testing.assert_array_equal(a.end - b.end, 25)


def test_table_has_start_end_mean_std_direction(counts_run):
    run = counts_run
    iv = run.intervals
    text = iv.table(run.directions)
    head = text.splitlines()[0].split()
    for col in ("start", "end", "t_start", "t_end", "mean_x", "mean_y", "mean_z", "std_x", "std_y", "std_z",
                "dir_x", "dir_y", "dir_z"):
        assert col in head
    assert len(text.splitlines()) == iv.n + 1
    row = text.splitlines()[1].split()
    assert int(row[1]) == iv.start[0] and int(row[2]) == iv.end[0]
    assert float(row[3]) == pytest.approx(iv.t_start[0], abs=0.01)
    assert float(row[6]) == pytest.approx(iv.mean[0, 0], rel=1e-5)
    np.testing.assert_allclose(np.linalg.norm(run.directions, axis=1), 1.0, atol=1e-12)


def test_subset_and_masks(counts_recording):
    iv = detect(counts_recording)
    sub = iv.subset(np.arange(0, iv.n, 2))
    assert sub.n == (iv.n + 1) // 2
    np.testing.assert_array_equal(sub.mean, iv.mean[::2])
    mask = iv.sample_mask(counts_recording.sim.t.size)
    assert mask.sum() == iv.n_samples.sum()
    idx = iv.sample_index()
    assert idx.size == mask.sum() and idx[0] == 0 and idx[-1] == iv.n - 1


@pytest.mark.parametrize("kw, field, match", [
    ({"window": 0}, "static.window", "window 0 must be a positive number of seconds"),
    ({"window": -1.0}, "static.window", "must be a positive number of seconds"),
    ({"min_duration": float("nan")}, "static.min_duration", "must be a positive number of seconds"),
    ({"min_duration": "2s"}, "static.min_duration", "must be a positive number of seconds"),
    ({"trim": -0.1}, "static.trim", "trim -0.1 must be a non-negative number of seconds"),
    ({"threshold": 0.0}, "static.threshold", "threshold 0.0 must be positive"),
    ({"threshold": "auto"}, "static.threshold", "must be positive"),
])
def test_bad_settings(kw, field, match):
    with pytest.raises(ImucalError, match=match) as ei:
        StaticSettings(**kw)
    assert ei.value.field == field


def test_too_few_samples():
    with pytest.raises(ImucalError, match="only 2 samples") as ei:
        detect_static(np.array([0.0, 0.01]), np.zeros((2, 3)), source="r.csv")
    assert str(ei.value).startswith("r.csv: data:")


# --- real recordings: the counts their READMEs list ------------------------------------------
@pytest.mark.parametrize("parts, spec, expected", [
    (("xsens-mti-imutk", "xsens_acc.mat"), {}, 38),
    (("ros-imu-getovermassif", "data2", "acc_data.txt"), {}, 41),
    (("ros-imu-getovermassif", "data3", "acc_data.txt"), {}, 28),
    (("ros-imu-getovermassif", "data4", "acc_data.txt"), {}, 23),
    (("mpu6050-tomisuarez", "example_data_calibration.csv"), {"sample_rate": 100.0}, 10),
    (("imucal-ferraris", "annotated_session.csv"), {"sample_rate": 204.8}, 6),
])
def test_real_recordings_interval_counts(parts, spec, expected):
    rec = load_recording(DataSpec(path=str(real_file(*parts)), **spec))
    iv = detect_static(rec.t, rec.raw)
    assert iv.n == expected


def test_ferraris_intervals_are_the_annotated_static_parts():
    """mad-lab-fau's session annotates its six static parts: each interval lies in one of them."""
    p = real_file("imucal-ferraris", "annotated_session.csv")
    rec = load_recording(DataSpec(path=str(p), sample_rate=204.8))
    parts = np.loadtxt(p, delimiter=",", skiprows=1, usecols=0, dtype=str)
    iv = detect_static(rec.t, rec.raw)
    seen = set()
    for a, b in zip(iv.start, iv.end):
        labels, counts = np.unique(parts[a:b], return_counts=True)
        main = labels[np.argmax(counts)]
        # the annotation's rotation parts start with a short still lead-in, so allow 20 %
        assert main in {"x_p", "x_a", "y_p", "y_a", "z_p", "z_a"} and counts.max() >= 0.8 * (b - a)
        seen.add(main)
    assert len(seen) == 6


# --- low rates and long holds (issue 27: a 1 Hz, 74.5 h temperature sweep) -----------------------
def test_a_1hz_log_finds_its_holds_with_the_default_settings():
    """At 1 Hz the default 0.5 s window is under one sample: it is stretched to MIN_WINDOW_SAMPLES
    samples, and the minimum duration and trim with it; every hold is found, inside its bounds."""
    from imucal.analysis.simulate import PosePlan, simulate
    from imucal.data.static import MIN_WINDOW_SAMPLES, at_rate

    plan = PosePlan(cube_directions("faces"), hold=600.0, transition=20.0, rate=1.0)
    sim = simulate(si_sensor(np.random.default_rng(3)), plan, seed=3)
    iv = detect_static(sim.t, sim.raw)
    _assert_matches_holds(iv, sim)
    assert np.all(iv.t_end - iv.t_start > 500.0)
    s = at_rate(StaticSettings(), 1.0)
    assert (s.window, s.min_duration, s.trim) == (MIN_WINDOW_SAMPLES, 3 * MIN_WINDOW_SAMPLES, MIN_WINDOW_SAMPLES / 2)
    assert at_rate(StaticSettings(), 0.01) == StaticSettings()  # 100 Hz: as given


def test_a_hold_of_hours_that_drifts_with_temperature_is_kept_whole():
    """A still hold whose reading follows temperature (a fast cool-down at its start, a warm-up at its
    end: curves no line follows) is one interval: the edge test judges each edge in its own
    neighbourhood, not against the line of the hold's central half."""
    rng = np.random.default_rng(4)
    rate, hours = 1.0, 6.0
    n_move, n_hold = 60, int(hours * 3600 * rate)
    t = np.arange(n_move + n_hold + n_move) / rate
    raw = np.tile([0.0, 0.0, -9.81], (t.size, 1)) + rng.normal(0, 0.02, (t.size, 3))
    th = np.arange(n_hold) / rate / 3600  # [h]
    drift = 0.05 * np.exp(-th / 0.3) + 0.04 / (1 + np.exp(-(th - hours + 1.0) / 0.3))  # [m/s^2]
    raw[n_move:n_move + n_hold, 0] += drift
    for a, b in ((0, n_move), (n_move + n_hold, t.size)):
        raw[a:b] += rng.normal(0, 3.0, (b - a, 3))  # handling before and after
    iv = detect_static(t, raw)
    assert iv.n == 1
    assert iv.t_end[0] - iv.t_start[0] > 0.99 * hours * 3600


def test_the_real_thermal_sweep_finds_its_four_long_holds():
    """thermal-cats-skdivemove: z, x (twice: the knock at 38.3 h), then y along -g, found with the
    default settings (before: "no static intervals found", or 3 intervals with hand-tuned ones)."""
    rec = load_recording(DataSpec(path=str(real_file("thermal-cats-skdivemove", "cats_temperature_calib.nc"))))
    iv = detect_static(rec.t, rec.raw, temp=rec.temp)
    long = np.flatnonzero(iv.t_end - iv.t_start > 10 * 3600)
    assert long.size == 4
    axis = np.argmax(np.abs(iv.mean[long]), axis=1)
    np.testing.assert_array_equal(axis, [2, 0, 0, 1])
    hours = np.column_stack([iv.t_start[long], iv.t_end[long]]) / 3600
    assert hours[0, 0] < 0.5 and hours[-1, 1] > 74.0  # the cool-down of the first hour is kept
    assert 38.2 < hours[1, 1] < hours[2, 0] < 38.6  # split at the knock
    assert np.sum(hours[:, 1] - hours[:, 0]) > 73.0


@pytest.mark.parametrize("k", range(1, 11))
def test_row_sums_and_column_extremes_are_numpys_numbers(k):
    """The moving variance's row sums and the rails' extremes, a column at a time (imucal.data.static):
    bit for bit what numpy's axis reductions give, over values of very different sizes."""
    from imucal.data.static import column_extremes, row_sums

    rng = np.random.default_rng(k)
    x = rng.normal(size=(5000, k)) * rng.choice([1e-9, 1.0, 1e9], size=(5000, k))
    assert np.array_equal(row_sums(x), x.sum(axis=1))
    lo, hi = column_extremes(x)
    assert np.array_equal(lo, x.min(axis=0)) and np.array_equal(hi, x.max(axis=0))
