"""A time column that wraps as an unsigned counter (Arduino's micros(): every 2**32 us, 71.6 min) is unwrapped,
whole and in chunks alike (imucal.data.counter_wrap); before, it was refused with "sort the rows by time",
which would have scrambled the file. Stamps that repeat or go back otherwise are refused, each by its name."""
from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import imucal.data.blocks as blocks_mod
import imucal.data.spill as spill_mod
import imucal.data.static as static_mod
from imucal.data.counter_wrap import CounterWrap
from imucal.data.load import load_recording
from imucal.data.spec import DataSpec
from imucal.data.static import detect_static
from imucal.data.stream import StreamedRecording
from imucal.errors import ImucalError

M32 = 2.0 ** 32


def _feed(raw: np.ndarray, cuts: list[int]) -> tuple[np.ndarray, CounterWrap]:
    w = CounterWrap()
    parts = np.split(raw, sorted(set(c for c in cuts if 0 < c < raw.size)))
    return np.concatenate([w.feed(p.copy()) for p in parts]), w


@settings(max_examples=60, deadline=None)
@given(start=st.integers(0, 2**32 - 1), step=st.integers(1, 50_000), n=st.integers(2, 3000),
       cuts=st.lists(st.integers(0, 3000), max_size=8))
def test_a_32_bit_counter_is_unwrapped_the_same_in_any_chunks(start, step, n, cuts):
    true = start + step * np.arange(n, dtype=np.float64)
    out, w = _feed(np.mod(true, M32), cuts)
    np.testing.assert_array_equal(out, true)
    assert w.wraps == int(true[-1] // M32)


def test_a_16_bit_counter_wraps_many_times():
    true = np.arange(20_000) * 10.0  # ms, 200 s: three wraps of 65.536 s
    out, w = _feed(np.mod(true, 2.0 ** 16), [5000, 12000])
    np.testing.assert_array_equal(out, true)
    assert w.wraps == 3 and "16-bit" in w.note and "3 times" in w.note


@pytest.mark.parametrize("stamps", [
    [0.0, 10, 20, 15, 30],  # rows out of order
    [4.0e9 + 0.5, 4294967295.5, 100.5],  # fractional: no counter
    [3.0e9, 3.1e9, 1.0e9],  # a step back from mid-range
    [4.2e9, 4.29e9, 2.0e9],  # lands mid-range
    [5.0e9, 4.29e9, 10.0],  # a stamp beyond 2**32 was read: no 32-bit counter
    [-5.0, 65_000, 10],  # a negative stamp
])
def test_what_is_no_wrap_is_left_as_read(stamps):
    x = np.array(stamps, float)
    out, w = _feed(x, [])
    np.testing.assert_array_equal(out, x)
    assert w.wraps == 0 and w.note == ""


def _micros_file(path, counts_recording, wrap_at: float, name: str = "t_us") -> np.ndarray:
    """The counts recording with its time as micros() that wraps ``wrap_at`` s into it."""
    rec = load_recording(counts_recording.path)
    us = np.round(rec.t * 1e6).astype(np.int64) + int(M32 - wrap_at * 1e6)
    rows = [f"{u % int(M32)},{a:.0f},{b:.0f},{c:.0f}" for u, (a, b, c) in zip(us, rec.raw)]
    path.write_text(f"{name},ax,ay,az\n" + "\n".join(rows) + "\n")
    return rec.raw


def test_a_wrapped_micros_column_reads_as_the_clean_one_whole_and_in_chunks(tmp_path, counts_recording, monkeypatch):
    p = tmp_path / "micros.csv"
    raw = _micros_file(p, counts_recording, wrap_at=41.3)
    whole = load_recording(p)
    ref = load_recording(counts_recording.path)
    np.testing.assert_allclose(whole.t, ref.t, atol=1e-6)
    np.testing.assert_array_equal(whole.raw, raw)
    assert np.all(np.diff(whole.t_source) > 0) and whole.t_source[-1] > M32
    assert "wrapped 1 time as an unsigned 32-bit counter" in whole.time_note
    monkeypatch.setattr(blocks_mod, "CHUNK_BYTES", 50_000)  # the wrap falls inside a later block
    monkeypatch.setattr(spill_mod, "SPILL_ROWS", 997)
    monkeypatch.setattr(static_mod, "VAR_BLOCK", 997)
    chunks = StreamedRecording(DataSpec(path=str(p)))
    assert chunks.recording.time_note == whole.time_note
    np.testing.assert_array_equal(chunks.intervals.t_start, detect_static(whole.t, whole.raw).t_start)


def test_calibrate_on_a_wrapped_log_gives_the_clean_logs_parameters_and_says_so(tmp_path, counts_recording, run_cli):
    p = tmp_path / "micros.csv"
    _micros_file(p, counts_recording, wrap_at=20.0)
    outs = {}
    for name, data, stream in (("clean", counts_recording.path, "never"), ("whole", p, "never"),
                               ("chunks", p, "always")):
        r = run_cli(["calibrate", "--data", data, "--out", tmp_path / name, "--no-figures", "--quiet",
                     "--stream", stream, "--json", tmp_path / f"{name}.json"])
        assert r.code == 0, r.err
        outs[name] = json.loads((tmp_path / f"{name}.json").read_text())["params"]
    for name in ("whole", "chunks"):
        for k, v in outs["clean"].items():
            np.testing.assert_allclose(np.asarray(outs[name][k], float), np.asarray(v, float), rtol=1e-9, atol=1e-9)
    assert "unsigned 32-bit counter" in (tmp_path / "whole" / "report.txt").read_text()


@pytest.mark.parametrize("stamps, words", [
    ("0 1000 2000 3000000000 1000000000 1000001000", "time goes back at line 6 (1000000000 after 3000000000)"),
    ("0 10 10 20", "time stamp 10 repeats at line 4"),
])
def test_a_step_back_that_is_no_wrap_is_refused_by_its_name(tmp_path, stamps, words):
    p = tmp_path / "r.csv"
    p.write_text("t_us,ax,ay,az\n" + "".join(f"{s},1,2,3\n" for s in stamps.split()))
    for read in (load_recording, lambda q: StreamedRecording(DataSpec(path=str(q)))):
        with pytest.raises(ImucalError) as e:
            read(p)
        assert words in str(e.value) and "data.columns.t" in str(e.value) and "fix:" in str(e.value)


def test_apply_writes_a_wrapped_counter_unwrapped_and_says_so(tmp_path, counts_recording, run_cli):
    p = tmp_path / "micros.csv"
    _micros_file(p, counts_recording, wrap_at=20.0)
    r = run_cli(["calibrate", "--data", p, "--out", tmp_path / "cal", "--no-figures", "--quiet"])
    assert r.code == 0, r.err
    r = run_cli(["apply", tmp_path / "cal" / "calibration.yaml", "--data", p, "--out", tmp_path / "a.csv"])
    assert r.code == 0, r.err
    assert "(us, a wrapped counter unwrapped)" in r.out + r.err
    t = np.loadtxt(tmp_path / "a.csv", delimiter=",", skiprows=1, usecols=0)
    assert np.all(np.diff(t) > 0) and t[-1] > M32
