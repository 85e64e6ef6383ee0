"""Shared fixtures: simulated recordings with known truth, calibrations of them, the CLI runner.

Everything here is seeded and session-scoped where it is expensive (a simulated recording is
~10 k samples; a fit takes well under a second). Real recordings live in ../shared/data/real
and are skipped, with a reason, when absent.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable, NamedTuple

import os

import numpy as np
import pytest
from hypothesis import settings as _hyp_settings

# CI explores the same examples every run (reproducible verdicts); locally, hypothesis explores.
_hyp_settings.register_profile("ci", derandomize=True, print_blob=True)
if os.environ.get("CI"):
    _hyp_settings.load_profile("ci")

from imucal.analysis.simulate import (PosePlan, SensorSpec, Simulation, cube_directions, mems_counts_sensor,
                             si_sensor, simulate)

#: The real recordings shared by all engineers (README.md there lists each folder).
REAL_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "real"
#: Recordings shipped in the repository (the Xsens log), used when the shared copy is absent.
REPO_DATA = Path(__file__).resolve().parents[1] / "data"

#: Short plans keep the suite fast: 3 s holds, 1.5 s transitions, 100 Hz.
HOLD, TRANSITION, RATE = 3.0, 1.5, 100.0


def real_file(*parts: str) -> Path:
    """Path of a real recording, or skip the test when the shared data are not present."""
    p = REAL_DATA.joinpath(*parts)
    if not p.exists() and REPO_DATA.joinpath(*parts).exists():
        p = REPO_DATA.joinpath(*parts)
    if not p.exists():
        pytest.skip(f"real recording {p} not present")
    return p


@dataclass(frozen=True)
class SimRecording:
    """A simulated recording written to CSV, with the truth it was made from."""

    sim: Simulation
    path: Path
    sensor: SensorSpec

    @property
    def truth(self) -> dict[str, float]:
        return self.sensor.values()

    @property
    def n_poses(self) -> int:
        return len(self.sim.hold_bounds)


def write_simulation(path: Path, sensor: SensorSpec, directions: np.ndarray, seed: int,
                     hold: float = HOLD, transition: float = TRANSITION, rate: float = RATE,
                     gravity: float | None = None, raw_factor: float = 1.0) -> SimRecording:
    """Simulate ``sensor`` held in ``directions`` and write the CSV (t, ax, ay, az) to ``path``.

    ``raw_factor`` multiplies the raw readings after simulation (a change of raw unit).
    """
    from dataclasses import replace

    from imucal.constants import STANDARD_GRAVITY

    plan = PosePlan(np.asarray(directions, float), hold=hold, transition=transition, rate=rate)
    sim = simulate(sensor, plan, gravity=STANDARD_GRAVITY if gravity is None else gravity, seed=seed)
    if raw_factor != 1.0:  # no longer integer counts: write all digits (quantum 0)
        sim = replace(sim, raw=sim.raw * raw_factor, sensor=replace(sensor, quantum=0.0))
    path.write_text(sim.to_csv_text())
    return SimRecording(sim, path, sensor)


@pytest.fixture(scope="session")
def sim_csv(tmp_path_factory) -> Callable[..., SimRecording]:
    """Factory: ``sim_csv(name, sensor, directions, seed, **plan)`` -> SimRecording (session tmp dir)."""
    root = tmp_path_factory.mktemp("sim")

    def make(name: str, sensor: SensorSpec, directions: np.ndarray, seed: int, **kw) -> SimRecording:
        return write_simulation(root / f"{name}.csv", sensor, directions, seed, **kw)

    return make


@pytest.fixture(scope="session")
def counts_recording(sim_csv) -> SimRecording:
    """Raw-count MEMS sensor (16384 LSB/g, 4 counts noise, quantised), 26 cube poses."""
    sensor = mems_counts_sensor(np.random.default_rng(2024))
    return sim_csv("counts", sensor, cube_directions(), seed=4)


@pytest.fixture(scope="session")
def si_recording(sim_csv) -> SimRecording:
    """Factory-scaled sensor reporting m/s^2 (0.01 m/s^2 noise), 26 cube poses."""
    sensor = si_sensor(np.random.default_rng(2025))
    return sim_csv("si", sensor, cube_directions(), seed=5)


def calibrate_file(path: Path | str, **sections):
    """Run the library pipeline on ``path`` with YAML-like sections (fit=..., static=..., ...)."""
    from imucal.config.run import config_from_dict
    from imucal.pipeline import calibrate_accelerometer

    data = dict(sections.pop("data", {}))
    data.setdefault("path", str(path))
    return calibrate_accelerometer(config_from_dict({"data": data, **sections}))


@pytest.fixture(scope="session")
def counts_run(counts_recording):
    return calibrate_file(counts_recording.path)


@pytest.fixture(scope="session")
def si_run(si_recording):
    return calibrate_file(si_recording.path)


class CliResult(NamedTuple):
    """What ``run_cli`` returns; unpacks as ``code, out, err``."""

    code: int
    out: str
    err: str


@pytest.fixture
def run_cli(capsys) -> Callable[[list[str]], CliResult]:
    """``run_cli(args)`` calls ``imucal.cli.main.main`` in-process and returns (code, stdout, stderr)."""
    from imucal.cli.main import main

    def run(args: list[str]) -> CliResult:
        capsys.readouterr()  # drop anything printed before
        try:
            code = main([str(a) for a in args])
        except SystemExit as exc:  # argparse errors and --help/--version
            code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 2)
        out, err = capsys.readouterr()
        return CliResult(int(code), out, err)

    return run


def tree_state(root: Path) -> dict[str, tuple[int, bytes]]:
    """Every file and folder under ``root`` with its mode and content (folders: b"")."""
    import hashlib

    out: dict[str, tuple[int, bytes]] = {}
    for p in sorted(Path(root).rglob("*")):
        st = p.lstat()
        data = hashlib.sha256(p.read_bytes()).digest() if p.is_file() and not p.is_symlink() else b""
        out[str(p.relative_to(root))] = (st.st_mode, data)
    return out


@pytest.fixture
def unchanged(tmp_path):
    """``with unchanged(folder): ...`` asserts that the block changed nothing under ``folder``
    (no input modified, no output, staging or lock file left behind)."""
    from contextlib import contextmanager

    @contextmanager
    def check(root: Path = tmp_path):
        before = tree_state(root)
        yield
        after = tree_state(root)
        added = sorted(set(after) - set(before))
        removed = sorted(set(before) - set(after))
        changed = sorted(k for k in before.keys() & after.keys() if before[k] != after[k])
        assert not (added or removed or changed), f"added {added}, removed {removed}, changed {changed}"

    return check


def gyro_rate(raw: np.ndarray, bias, scale, mis, gsens=None, acc: np.ndarray | None = None) -> np.ndarray:
    """The gyroscope's inverse model written directly in numpy, independently of imucal.model.gyroscope:
    omega = M_g^-1 (B_g^-1 (raw - s_g) - G_s a), M_g unit diagonal with off-diagonal ``mis`` (m_xy, m_xz,
    m_yx, m_yz, m_zx, m_zy), G_s [(rad/s) per (m/s^2)]."""
    M = np.eye(3)
    for k, (i, j) in enumerate(((0, 1), (0, 2), (1, 0), (1, 2), (2, 0), (2, 1))):
        M[i, j] = mis[k]
    y = (np.atleast_2d(raw) - np.asarray(bias, float)) / np.asarray(scale, float)
    if gsens is not None and acc is not None:
        y = y - np.atleast_2d(acc) @ np.asarray(gsens, float).T
    return np.linalg.solve(M, y.T).T


def rk4_directions(t: np.ndarray, rate: np.ndarray, seg) -> np.ndarray:
    """Gravity-direction error [deg] per motion segment, integrated by imu_tk's quaternion RK4 step in
    plain numpy, stepping every segment together: independent of imucal.gyro.attitude's generated code."""
    def omega(w: np.ndarray) -> np.ndarray:
        x, y, c = w[:, 0], w[:, 1], w[:, 2]
        O = np.zeros((w.shape[0], 4, 4))
        O[:, 0, 1:], O[:, 1:, 0] = -w, w
        O[:, 1, 2], O[:, 1, 3], O[:, 2, 1], O[:, 2, 3], O[:, 3, 1], O[:, 3, 2] = c, -y, -c, x, y, -x
        return O

    steps = seg.last - seg.first
    q = np.tile([1.0, 0, 0, 0], (seg.n, 1))
    for j in range(int(steps.max(initial=0))):
        act = j < steps
        i = np.minimum(seg.first + j, seg.last - 1)
        dt = np.where(act, t[i + 1] - t[i], 0.0)[:, None]
        w0, w1 = rate[i], rate[i + 1]
        O0, Om, O1 = omega(w0), omega(0.5 * (w0 + w1)), omega(w1)
        k1 = 0.5 * np.einsum("nij,nj->ni", O0, q)
        k2 = 0.5 * np.einsum("nij,nj->ni", Om, q + 0.5 * dt * k1)
        k3 = 0.5 * np.einsum("nij,nj->ni", Om, q + 0.5 * dt * k2)
        k4 = 0.5 * np.einsum("nij,nj->ni", O1, q + dt * k3)
        qn = q + dt * (k1 + 2 * k2 + 2 * k3 + k4) / 6
        q = qn / np.linalg.norm(qn, axis=1, keepdims=True)
    w, x, y, z = q.T
    R = np.stack([np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], 1),
                  np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], 1),
                  np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], 1)], 1)
    carried = np.einsum("nji,nj->ni", R, seg.u0)
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(carried, seg.u1), axis=1), np.sum(carried * seg.u1, axis=1)))
