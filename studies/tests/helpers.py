"""What the studies' checks share: the real recordings (or a skip) and a simulated recording on disk."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from imucal.analysis.simulate import PosePlan, SensorSpec, simulate
from imucal.constants import STANDARD_GRAVITY

ROOT = Path(__file__).resolve().parents[2]
#: The real recordings beside the repository (../shared), and the one the repository ships.
REAL_DATA = ROOT.parent / "shared" / "data" / "real"
REPO_DATA = ROOT / "data"
#: Short plans keep the checks quick: 3 s holds, 1.5 s transitions, 100 Hz.
HOLD, TRANSITION, RATE = 3.0, 1.5, 100.0


def study(name: str) -> Path:
    """The program of a study (studies/NAME.py); the checks run it as a program or load it by path."""
    return ROOT / "studies" / f"{name}.py"


def real_file(*parts: str) -> Path:
    """Path of a real recording, or skip the check when the shared data are not present."""
    p = REAL_DATA.joinpath(*parts)
    if not p.exists() and REPO_DATA.joinpath(*parts).exists():
        p = REPO_DATA.joinpath(*parts)
    if not p.exists():
        pytest.skip(f"real recording {p} not present")
    return p


def write_simulation(path: Path, sensor: SensorSpec, directions: np.ndarray, seed: int) -> None:
    """Simulate ``sensor`` held in ``directions`` (short holds) and write the CSV (t, ax, ay, az)."""
    plan = PosePlan(np.asarray(directions, float), hold=HOLD, transition=TRANSITION, rate=RATE)
    path.write_text(simulate(sensor, plan, gravity=STANDARD_GRAVITY, seed=seed).to_csv_text())
