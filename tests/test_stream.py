"""Reading in chunks (imucal.data.stream) gives what reading whole gives: the same samples, time
base, messages, static intervals and fitted parameters, on every real recording and on edge cases.
Chunk and variance-block sizes are made small here so that every file spans many of both."""
from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import imucal.data.static as static_mod
import imucal.data.load as load_mod
import imucal.data.blocks as blocks_mod
import imucal.data.spill as spill_mod
from conftest import real_file
from imucal.data.load import load_recording
from imucal.data.spec import DataSpec
from imucal.data.static import MovingVariance, detect_static, moving_variance
from imucal.data.load import has_gyro, use_stream
from imucal.data.stream import StreamedRecording
from imucal.errors import ImucalError
from imucal.pipeline import calibrate_accelerometer, static_samples
from test_trust_data import ACC, OTHER, ids

INTERVAL_FIELDS = ("start", "end", "t_start", "t_end", "mean", "std", "mean_std", "t_mid")


@pytest.fixture(autouse=True)
def small_chunks(monkeypatch):
    monkeypatch.setattr(blocks_mod, "CHUNK_BYTES", 50_000)
    monkeypatch.setattr(spill_mod, "SPILL_ROWS", 997)  # the spill read back in uneven blocks
    monkeypatch.setattr(static_mod, "VAR_BLOCK", 997)


def spec_of(case) -> DataSpec:
    parts, extra = case
    return DataSpec(path=str(real_file(*parts)), **extra)


def same_intervals(a, b) -> None:
    for f in INTERVAL_FIELDS:
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f), err_msg=f)
    assert (a.threshold, a.noise_inflation, a.meta) == (b.threshold, b.noise_inflation, b.meta)


# --- every real recording ------------------------------------------------------------------------
@pytest.mark.parametrize("case", ACC + OTHER, ids=ids)
def test_streamed_recording_equals_the_loaded_one(case):
    spec = spec_of(case)
    rec = load_recording(spec)
    iv = detect_static(rec.t, rec.raw, temp=rec.temp)
    s = StreamedRecording(spec, keep_samples=True)
    same_intervals(iv, s.intervals)
    r = s.recording
    assert (r.n, r.sha256, r.time_unit, r.time_note, r.time_column, r.sample_rate, r.duration) == (
        rec.n, rec.sha256, rec.time_unit, rec.time_note, rec.time_column, rec.sample_rate, rec.duration)
    assert r.sha256 == hashlib.sha256(Path(spec.path).read_bytes()).hexdigest()
    whole = static_samples(iv, rec)
    np.testing.assert_array_equal(s.samples.raw, whole.raw)
    np.testing.assert_array_equal(s.samples.t, whole.t)
    blocks = list(StreamedRecording(spec).static_blocks())  # re-read, a block at a time
    np.testing.assert_array_equal(np.concatenate([b.raw for b in blocks]), whole.raw)


def _old_moving_variance(x: np.ndarray, w: int) -> np.ndarray:
    """The detector's moving variance before the chunked one: global centring, index arrays."""
    n = x.shape[0]
    w = max(2, min(int(w), n))
    xc = x - x.mean(axis=0)
    c1 = np.vstack([np.zeros((1, x.shape[1])), np.cumsum(xc, axis=0)])
    c2 = np.vstack([np.zeros((1, x.shape[1])), np.cumsum(xc * xc, axis=0)])
    lo = np.clip(np.arange(n) - w // 2, 0, n - w)
    s1, s2 = c1[lo + w] - c1[lo], c2[lo + w] - c2[lo]
    return (np.maximum(s2 / w - (s1 / w) ** 2, 0.0) * w / (w - 1)).sum(axis=1)


def _old_runs(t: np.ndarray, raw: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Static intervals as the detector found them before (float64 variance, one histogram)."""
    dt = float(np.median(np.diff(t)))
    var = _old_moving_variance(raw, max(3, int(round(0.5 / dt))))
    q = 1.0 if np.all(raw[:20000] == np.round(raw[:20000])) else 0.0
    floor = max(float(np.percentile(var, 5)), q**2 / 12 * 3, 1e-300)
    hist, edges = np.histogram(np.log10(np.maximum(var, floor * 1e-3)), bins=256)
    c = 0.5 * (edges[:-1] + edges[1:])
    w0 = np.cumsum(hist)
    m0 = np.cumsum(hist * c)
    with np.errstate(divide="ignore", invalid="ignore"):
        between = (m0[-1] * w0 / w0[-1] - m0) ** 2 / (w0 * (w0[-1] - w0))
    between[~np.isfinite(between)] = -1
    thr = min(max(10 ** c[int(np.argmax(between))], 4 * floor), 100 * floor)
    edges = np.diff(np.concatenate([[0], (var <= thr).view(np.int8), [0]]))
    trim = int(round(0.25 / dt))
    a, b = np.flatnonzero(edges == 1) + trim, np.flatnonzero(edges == -1) - trim
    ok = (b - a >= 3)
    a, b = a[ok], b[ok]
    ok = t[b - 1] - t[a] >= 1.5
    return a[ok], b[ok]


@pytest.mark.parametrize("case", ACC + OTHER, ids=ids)
def test_detector_finds_the_intervals_it_found_before(case, monkeypatch):
    monkeypatch.setattr(static_mod, "VAR_BLOCK", 1 << 16)
    monkeypatch.setattr(static_mod, "EDGE_ROUNDS", 0)  # the runs before their edges are tested
    rec = load_recording(spec_of(case))
    a, b = _old_runs(rec.t, rec.raw)
    iv = detect_static(rec.t, rec.raw)
    np.testing.assert_array_equal(iv.start, a)
    np.testing.assert_array_equal(iv.end, b)


def test_slice_differences_equal_the_index_formula():
    rng = np.random.default_rng(3)
    x = np.cumsum(rng.normal(0, 5, (20_000, 3)), axis=0) + 30000
    for w in (2, 3, 50, 997, 998, 5000):
        new = moving_variance(x, w)
        old = _old_moving_variance(x, w)
        np.testing.assert_allclose(new, old, rtol=2e-6, atol=1e-9 * old.max())
        mv = MovingVariance(w)  # fed in uneven chunks: the same numbers
        for part in np.array_split(x, [1, 7, 5000, 5001, 13_000]):
            mv.add(part)
        np.testing.assert_array_equal(mv.finish().array(), new)


@pytest.mark.parametrize("name", ["xsens-mti-imutk", "ros-imu-data2", "ros-imu-data3", "ros-imu-data4",
                                  "mpu6050-tomisuarez", "imucal-ferraris-6param"])
def test_calibration_in_chunks_equals_the_whole_file(name):
    """The same parameters (to 1e-9 relative; in fact identical), intervals and report figures, on every
    real recording's run file in configs/ (phi held on the MPU-6050, 6 parameters on mad-lab's session)."""
    import dataclasses

    from imucal.config.run import load_config

    cfg = load_config(Path(__file__).resolve().parents[1] / "configs" / f"{name}.yaml")
    if not (cfg.base_dir / cfg.data.path).exists():
        pytest.skip(f"real recording {cfg.base_dir / cfg.data.path} not present")
    runs = [calibrate_accelerometer(dataclasses.replace(cfg, data=dataclasses.replace(cfg.data, stream=how)))
            for how in ("never", "always")]
    whole, chunks = runs
    assert chunks.recording.raw is None and chunks.sample_residuals is None  # read in chunks
    same_intervals(whole.intervals, chunks.intervals)
    for p in whole.result.params.names:
        v0, v1 = whole.result.params[p].value, chunks.result.params[p].value
        assert v1 == pytest.approx(v0, rel=1e-9, abs=1e-300), p
        s0, s1 = whole.result.std[p], chunks.result.std[p]
        assert s1 == pytest.approx(s0, rel=1e-9) or (np.isnan(s0) and np.isnan(s1)), p
    assert chunks.rms_residual_samples == pytest.approx(whole.rms_residual_samples, rel=1e-12)
    assert chunks.calibration.data == whole.calibration.data


# --- the loader's messages, from any block ------------------------------------------------------
def _long_file(path: Path, n: int, bad_row: int | None = None, token: str = "abc", col: int = 2) -> None:
    t = np.arange(n) * 0.01
    rows = [f"{x:.2f} 1 2 3" for x in t]
    if bad_row is not None:
        f = rows[bad_row].split()
        f[col] = token
        rows[bad_row] = " ".join(f)
    path.write_text("# a comment line\n" + "\n".join(rows) + "\n")


@pytest.mark.parametrize("token, col, message", [
    ("abc", 2, "line {line} column 3: 'abc' is not a number"),
    ("nan", 1, "line {line} holds NaN or Inf"),
    ("1e31", 3, "line {line} holds a value beyond +-1e+30 (corrupt)"),
    ("0.00", 0, "time goes back at line {line} (0 after "),
])
def test_bad_value_deep_in_the_file_names_the_same_line(tmp_path, token, col, message):
    p = tmp_path / "long.txt"
    _long_file(p, 30_000, bad_row=23_456, token=token, col=col)
    with pytest.raises(ImucalError) as whole:
        load_recording(p)
    with pytest.raises(ImucalError) as chunks:
        StreamedRecording(p)
    assert str(chunks.value) == str(whole.value)
    assert message.format(line=23_458) in str(chunks.value) and "\n" not in str(chunks.value)


def test_bad_field_at_row_three_million_exits_2_and_writes_nothing(tmp_path, run_cli, unchanged, monkeypatch):
    monkeypatch.setattr(blocks_mod, "CHUNK_BYTES", 16 * 1024**2)
    p = tmp_path / "long.txt"
    n, bad = 3_000_010, 3_000_000
    t = np.char.mod("%.2f", np.arange(n) * 0.01)
    lines = np.char.add(t, " 1 2 3")
    lines = lines.tolist()
    lines[bad] = lines[bad].replace(" 2 ", " x2 ")
    p.write_bytes("\n".join(lines).encode() + b"\n")
    out = tmp_path / "out"
    r = run_cli(["calibrate", "--data", str(p), "--out", str(out), "--stream", "always"])
    assert r.code == 2
    assert r.err.strip().splitlines() == [f"imucal: error: {p}: data: line {bad + 1} column 3: 'x2' is not a number "
                                         "(fix: remove non-numeric rows or map the right columns)"]
    assert not out.exists()


def test_step_guessed_from_the_first_block_is_corrected(tmp_path):
    """The first block logs at 100 Hz, the rest at 50 Hz: the window comes from the whole file."""
    rng = np.random.default_rng(0)
    t = np.concatenate([np.arange(3000) * 0.01, 30 + np.arange(1, 20_000) * 0.02])
    raw = rng.normal(0, 1, (t.size, 3)) + np.repeat(rng.normal(0, 300, (40, 3)), -(-t.size // 40), axis=0)[:t.size]
    p = tmp_path / "r.txt"
    np.savetxt(p, np.column_stack([t, raw]), fmt="%.6f")
    rec = load_recording(p)
    same_intervals(detect_static(rec.t, rec.raw), StreamedRecording(p).intervals)


_TOKENS = st.sampled_from(["0", "1", "-1", "0.01", "0.02", "10", "123.0", "1e300", "-1e31", "nan", "x", "",
                           "  ", "# c", '"1"', "1,", "0x1"])
_LINE = st.lists(_TOKENS, min_size=1, max_size=6).flatmap(
    lambda toks: st.sampled_from([" ", ",", ";", "\t"]).map(lambda sep: sep.join(toks)))


@given(lines=st.lists(_LINE, min_size=1, max_size=30), rate=st.sampled_from([None, 100.0]),
       eol=st.sampled_from(["\n", "\r\n", "\x0c"]))
@settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
def test_odd_text_gives_the_loaders_answer(tmp_path, monkeypatch, lines, rate, eol):
    monkeypatch.setattr(blocks_mod, "CHUNK_BYTES", 16)  # a block a line or two
    p = tmp_path / "f.txt"
    p.write_text(eol.join(["0 1 2 3"] + lines) + "\n", newline="")
    spec = DataSpec(path=str(p), sample_rate=rate)
    try:
        rec = load_recording(spec)
        iv = detect_static(rec.t, rec.raw, source=rec.source)
    except ImucalError as exc:
        with pytest.raises(ImucalError) as ei:
            StreamedRecording(spec)
        assert str(ei.value) == str(exc)
        return
    same_intervals(iv, StreamedRecording(spec).intervals)


# --- when the pipeline reads in chunks ----------------------------------------------------------
def test_auto_reads_large_files_in_chunks(tmp_path, monkeypatch):
    p = tmp_path / "r.txt"
    _long_file(p, 2000)
    assert not use_stream(DataSpec(path=str(p)))
    monkeypatch.setattr(load_mod, "STREAM_BYTES", 1000)
    assert use_stream(DataSpec(path=str(p)))
    assert not use_stream(DataSpec(path=str(p), stream="never"))
    assert not use_stream(DataSpec(path=str(p), gyro_path="g.txt"))
    g = tmp_path / "g.csv"
    g.write_text("t,ax,ay,az,gx,gy,gz\n" + "".join(f"{i * 0.01:.2f},1,2,3,0,0,0\n" for i in range(200)))
    assert not use_stream(DataSpec(path=str(g)))  # the gyroscope fit needs every sample: read whole
    assert has_gyro(DataSpec(path=str(g))) and not has_gyro(DataSpec(path=str(p)))


def test_calibrate_refuses_gyroscope_data_in_chunks(tmp_path, run_cli):
    g = tmp_path / "g.csv"
    g.write_text("t,ax,ay,az,gx,gy,gz\n" + "".join(f"{i * 0.01:.2f},1,2,3,0,0,0\n" for i in range(200)))
    r = run_cli(["calibrate", "--data", str(g), "--out", str(tmp_path / "o"), "--stream", "always"])
    assert r.code == 2 and "--stream: has gyroscope data, which reading in chunks does not keep" in r.err
    assert not (tmp_path / "o").exists()


def test_stream_setting_is_checked():
    with pytest.raises(ImucalError, match="data.stream: unknown stream setting 'yes'"):
        DataSpec(path="x", stream="yes")
