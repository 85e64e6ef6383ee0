"""imu_tk's calibration files: read, and converted to the paper's nine parameters (export/peers.py)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from imucal.calibration.frozen import Calibration
from imucal.model.parameters import base_parameters
from imucal.export.peers import AffineCalibration, read_imutk_calib

ROOT = Path(__file__).resolve().parents[1]


def test_peer_conversion_round_trip():
    """A calibration written as a = M (raw - o) converts back to the same nine parameters."""
    p = base_parameters([10, -20, 30], [400, 410, 420], [1.56, 1.58, 1.575], gravity=9.81)
    cal = Calibration(params=p, std={}, gravity=9.81)
    A, c = cal.linear_map()
    o = -np.linalg.solve(A, c)
    peer = AffineCalibration(M=A, o=o)
    got = peer.nine_parameters()
    for n, v in p.value_dict().items():
        assert got[n] == pytest.approx(v, rel=1e-12, abs=1e-9)
    # Any rotation of the output frame leaves the parameters unchanged.
    th = 0.3
    Rz = np.array([[np.cos(th), -np.sin(th), 0], [np.sin(th), np.cos(th), 0], [0, 0, 1]])
    got2 = AffineCalibration(M=Rz @ A, o=o).nine_parameters()
    for n, v in p.value_dict().items():
        assert got2[n] == pytest.approx(v, rel=1e-12, abs=1e-9)


def test_read_imutk_calib_shipped():
    peer = read_imutk_calib(ROOT / "data" / "xsens-mti-imutk" / "imutk_test_imu_acc.calib")
    np.testing.assert_allclose(np.diag(peer.M), [0.00241278, 0.00242712, 0.00241168])
    np.testing.assert_allclose(peer.o, [33124.2, 33275.2, 32364.4])
