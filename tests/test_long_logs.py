"""Long recordings (issue 30): what a run keeps grows with the intervals, not with the samples or
their square. Memory is bounded by counting allocations (tracemalloc: numpy reports its arrays to
it), never by timing; the speed lives in scripts/bench_memory.py."""
from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

import imucal.data.blocks as blocks_mod
import imucal.data.spill as spill_mod
from conftest import calibrate_file, write_simulation
from imucal.analysis.simulate import cube_directions, frame_matrix, mems_counts_sensor, random_directions
from imucal.calibration.fileformat import to_dict
from imucal.constants import STANDARD_GRAVITY
from imucal.data.load import load_recording
from imucal.data.spec import DataSpec
from imucal.data.static import detect_static
from imucal.errors import ImucalError
from imucal.model.parameters import base_parameters
from imucal.model.sensor import build_model
from imucal.solve.fit import FitData, _sandwich, fit
from imucal.solve.initial import ellipsoid_guess


ROOT = Path(__file__).resolve().parents[1]


def _means(n: int, seed: int = 3) -> FitData:
    """``n`` interval means of a raw-count sensor, with a between-interval excess beyond their noise."""
    rng = np.random.default_rng(seed)
    sensor = mems_counts_sensor(np.random.default_rng(7))
    u = random_directions(n, rng)
    clean = np.asarray(sensor.s) + np.asarray(sensor.b) * (STANDARD_GRAVITY * u @ frame_matrix(np.asarray(sensor.angles)))
    sig = 0.2  # counts per mean
    raw = clean + rng.normal(0, sig, clean.shape) + rng.normal(0, 1.0, (n, 1))  # a bias per visit
    return FitData(raw=raw, cov=np.zeros((n, 0)), raw_var=np.full(raw.shape, sig**2), group=np.arange(n),
                   mode="means", t=np.arange(n) * 10.0)


def test_the_default_fit_of_many_means_holds_no_square_of_them() -> None:
    """weights="auto" on 4000 means: the rows' covariance is diagonal (no walk above
    stochastic.MAX_INTERVALS), kept as a vector: the fit allocates far less than one 4000 x 4000
    matrix (128 MB), which it once held (51 M samples, 38,000 intervals: 11.5 GB)."""
    n = 4000
    data = _means(n)
    g = ellipsoid_guess(data.raw, STANDARD_GRAVITY)
    params = base_parameters(g.s, g.b, g.angles, raw_unit="raw", gravity=STANDARD_GRAVITY)
    tracemalloc.start()
    try:
        res = fit(data, params, build_model(), STANDARD_GRAVITY, weights="auto")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert res.success and res.excess > 0
    assert peak < n * n * 8 / 8, f"peak {peak / 2**20:.0f} MB"


def test_the_sandwich_of_a_diagonal_is_that_of_its_matrix() -> None:
    """The variances as a vector give the covariance the n x n diagonal matrix gives, bit for bit."""
    rng = np.random.default_rng(1)
    J, v = rng.normal(size=(50, 9)), rng.uniform(0.5, 2.0, 50)
    assert _sandwich(J, v, 1.7).tobytes() == _sandwich(J, np.diag(v), 1.7).tobytes()


# --- the reader in chunks: one parse, a binary spill, memory flat in the samples -------------------
def _tiled(tmp_path: Path, k: int, jitter: bool = False) -> Path:
    """A simulated 100 Hz counts recording of 26 poses, tiled ``k`` times (times continued), as
    whitespace text; ``jitter``: stamps of a bursty logger (re-timed on a fitted clock)."""
    r = write_simulation(tmp_path / "one.csv", mems_counts_sensor(np.random.default_rng(5)), cube_directions(), seed=5)
    d = np.loadtxt(r.path, delimiter=",", skiprows=1)
    span = d[-1, 0] - d[0, 0] + 0.01
    rows = np.concatenate([d + [i * span, 0, 0, 0] for i in range(k)])
    if jitter:  # arrival stamps: two samples read at once now and then, 0.4 ms apart
        late = np.random.default_rng(1).uniform(size=len(rows)) < 0.2
        rows[:, 0] += np.where(late, 0.0096, 0.0)
        rows[1:, 0] = np.maximum(rows[1:, 0], rows[:-1, 0] + 4e-4)
    path = tmp_path / f"tiled{k}{'j' if jitter else ''}.txt"
    np.savetxt(path, rows, fmt=["%.5f", "%.0f", "%.0f", "%.0f"])
    return path


@pytest.fixture
def small_blocks(monkeypatch):
    """Blocks of a few thousand lines, read back from the spill in blocks of 5000 rows."""
    monkeypatch.setattr(blocks_mod, "CHUNK_BYTES", 100_000)
    monkeypatch.setattr(spill_mod, "SPILL_ROWS", 5000)


@pytest.mark.parametrize("jitter", [False, True])
def test_the_text_is_parsed_once(tmp_path, small_blocks, monkeypatch, jitter):
    """Every block of text is parsed once, also when the stamps are jitter (their gaps found and the
    times made again on the fitted clock, from the spill): the passes after the parse read numbers."""
    from imucal.data.blocks import TextBlocks
    from imucal.data.stream import StreamedRecording

    path = _tiled(tmp_path, 2, jitter)
    seen: list[int] = []
    parse = TextBlocks.parse
    monkeypatch.setattr(TextBlocks, "parse", lambda self, block, offset: seen.append(offset) or parse(self, block, offset))
    s = StreamedRecording(DataSpec(path=str(path)))
    assert s.recording.time_base.source.value == ("clock" if jitter else "stamps")
    assert len(seen) > 5 and len(seen) == len(set(seen))
    whole = detect_static(*_whole(path))
    np.testing.assert_array_equal(s.intervals.mean, whole.mean)


def _whole(path: Path) -> tuple[np.ndarray, np.ndarray]:
    rec = load_recording(str(path))
    return rec.t, rec.raw


def test_memory_is_flat_in_the_samples(tmp_path, small_blocks, monkeypatch):
    """Ten times the samples, about the same peak allocation: the rows and the moving variance are
    spilled, not kept (once 36 bytes a sample), so only a few numbers per interval grow. (The fixed
    buffers, made small here, and the head the layout is read from, 1 MB, are reached by both sizes.)"""
    import imucal.data.static as static_mod
    from imucal.data import run_pool
    from imucal.data.stream import StreamedRecording

    monkeypatch.setattr(static_mod, "VAR_BLOCK", 997)
    monkeypatch.setattr(static_mod, "_SWEEP", 4096)
    monkeypatch.setattr(run_pool, "BATCH_ROWS", 2000)  # the runs judged together
    StreamedRecording(DataSpec(path=str(_tiled(tmp_path, 1))))  # the modules it imports are no sample's
    peaks = []
    for k in (4, 40):
        path = _tiled(tmp_path, k)
        tracemalloc.start()
        try:
            s = StreamedRecording(DataSpec(path=str(path)))
            for _ in s.static_blocks():
                pass
            peaks.append(tracemalloc.get_traced_memory()[1])
        finally:
            tracemalloc.stop()
        n = s.recording.n
    assert peaks[1] - peaks[0] < 1.0 * (n - n // 10), [p / 2**20 for p in peaks]  # under a byte a sample


def test_the_spill_leaves_nothing_behind(tmp_path, small_blocks, monkeypatch):
    """The spills have no name in the temporary folder, during the run and after it, also when the
    run is refused late in the file."""
    from imucal.data.stream import StreamedRecording

    tmp = tmp_path / "tmp"
    tmp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(tmp))
    path = _tiled(tmp_path, 1)
    s = StreamedRecording(DataSpec(path=str(path)))
    assert list(tmp.iterdir()) == [] and s.intervals.n == 26
    bad = tmp_path / "bad.txt"
    bad.write_text(path.read_text() + "1e9 1 2 3\n0.5 1 2 3\n")
    with pytest.raises(ImucalError, match="time goes back at line"):
        StreamedRecording(DataSpec(path=str(bad)))
    assert list(tmp.iterdir()) == []


def test_a_spill_that_cannot_be_made_is_one_line(tmp_path, monkeypatch, run_cli):
    """No temporary folder to spill into: one line naming it and the way out, exit 2, nothing written."""
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path / "missing"))
    path = _tiled(tmp_path, 1)
    out = tmp_path / "out"
    res = run_cli(["calibrate", "--data", str(path), "--out", str(out), "--stream", "always", "--no-figures"])
    assert res.code == 2 and not out.exists()
    lines = res.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("imucal: error: data.stream: cannot write the parsed rows to a "
                                                   f"temporary file in {tmp_path / 'missing'}"), res.err
    assert "(fix: free space there or point TMPDIR to a folder" in lines[0]


@pytest.mark.parametrize("mode", ["means", "samples"])
def test_whole_and_in_chunks_give_the_same_calibration_file(tmp_path, small_blocks, mode):
    """The calibration files of the two readers agree value by value (the residuals' RMS over
    samples summed over the same pieces either way), but for the time they were written."""
    path = _tiled(tmp_path, 2)
    got = {}
    for how in ("never", "always"):
        run = calibrate_file(path, data={"stream": how}, fit={"mode": mode})
        d = to_dict(run.calibration)
        d.pop("created")
        got[how] = d
    assert got["never"] == got["always"]


def _tenfold(item: tuple) -> int:
    return item[0] * 10


def _fails_at_5(item: tuple) -> int:
    if item[0] == 5:
        raise ValueError("run 5")
    return item[0]


def _dies_at_3(item: tuple) -> int:
    if item[0] == 3:
        os._exit(9)  # as a worker killed from outside
    return item[0]


@pytest.mark.parametrize("workers", [0, 2])
def test_the_runs_are_judged_in_order_and_few_at_a_time(workers):
    """The runs' results come back in the order of the runs, at most BATCHES_IN_FLIGHT per worker sent
    ahead; an error in one is raised and little after it is read."""
    from imucal.data import run_pool

    taken, back = [0], []

    def items(n):
        for k in range(n):
            taken[0] += 1
            yield (k,)

    held = 0
    for item, r in run_pool.ordered_map(_tenfold, items(40), workers):
        back.append((item[0], r))
        held = max(held, taken[0] - len(back))
    assert back == [(k, 10 * k) for k in range(40)]
    assert held <= run_pool.BATCHES_IN_FLIGHT * workers + 1
    taken[0] = 0
    with pytest.raises(ValueError, match="run 5"):
        for _ in run_pool.ordered_map(_fails_at_5, items(100), workers):
            pass
    assert taken[0] <= 6 + run_pool.BATCHES_IN_FLIGHT * workers + 1


def test_a_worker_that_dies_is_one_line():
    """A worker killed (from outside, or out of memory) ends the run with one line naming the way out."""
    from imucal.data import run_pool

    with pytest.raises(ImucalError) as err:
        for _ in run_pool.ordered_map(_dies_at_3, [(k,) for k in range(20)], 2):
            pass
    assert str(err.value).startswith("data.stream: a worker process judging the still intervals ended unexpectedly")
    assert "--stream never" in str(err.value)


def test_workers_end_with_the_process_that_started_them(tmp_path):
    """A run killed by SIGKILL (no cleanup) leaves no worker behind: each watches its parent."""
    import psutil

    code = ("import sys, time\nfrom imucal.data import run_pool\n"
            "if __name__ == '__main__':\n"
            "    for _ in run_pool.ordered_map(time.sleep, [30.0] * 4, 2):\n        pass\n")
    script = tmp_path / "slow.py"
    script.write_text(code)
    proc = subprocess.Popen([sys.executable, str(script)], env={**os.environ, "PYTHONPATH": str(ROOT)})
    try:
        parent = psutil.Process(proc.pid)
        deadline = time.monotonic() + 60
        while len(workers := [c for c in parent.children() if "spawn_main" in " ".join(c.cmdline())]) < 2:
            assert time.monotonic() < deadline, "the workers did not start"
            time.sleep(0.1)
    finally:
        proc.kill()
        proc.wait()
    gone, alive = psutil.wait_procs(workers, timeout=30)
    assert not alive, alive


@pytest.mark.parametrize("mode", ["means", "samples"])
def test_workers_give_the_same_calibration_file(tmp_path, small_blocks, monkeypatch, mode):
    """Runs judged on worker processes give the calibration file of the runs judged in one process."""
    from imucal.data import run_pool

    if len(os.sched_getaffinity(0)) < 2:
        pytest.skip("one core: no workers are started")
    monkeypatch.setattr(run_pool, "POOL_RUNS", 1)
    monkeypatch.setattr(run_pool, "BATCH_ROWS", 2000)  # several batches
    monkeypatch.setattr(run_pool, "_allowed", [False])
    path = _tiled(tmp_path, 2)
    got = []
    for allowed in (False, True):
        run_pool.allow_workers(allowed)
        assert run_pool.run_workers(50) == (2 if allowed else 0)
        d = to_dict(calibrate_file(path, data={"stream": "always"}, fit={"mode": mode}).calibration)
        d.pop("created")
        got.append(d)
    assert got[0] == got[1]
