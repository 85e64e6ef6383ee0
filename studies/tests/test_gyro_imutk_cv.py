"""studies/gyro_imutk_cv.py: pairing imu_tk's motion segments with ours, the paired bootstrap (issue 11)."""
from __future__ import annotations

import importlib.util

import numpy as np
import pytest

from imucal.errors import ImucalError

from studies.tests.helpers import study

spec = importlib.util.spec_from_file_location("gyro_imutk_cv", study("gyro_imutk_cv"))
gyro_imutk_cv = importlib.util.module_from_spec(spec)
spec.loader.exec_module(gyro_imutk_cv)

OURS = np.array([[1.0, 3.0], [5.0, 7.0], [9.0, 12.0]])


def test_segments_pair_by_overlap_even_shifted_and_reordered():
    theirs = OURS[[2, 0, 1]] + np.array([0.4, -0.6])  # other detector: edges moved, listed in another order
    assert gyro_imutk_cv.match_segments(OURS, theirs).tolist() == [1, 2, 0]


def test_segments_that_do_not_pair_are_refused():
    with pytest.raises(ImucalError, match="one to one"):  # one of theirs spans two of ours
        gyro_imutk_cv.match_segments(OURS, np.array([[0.0, 8.0], [20.0, 21.0], [9.0, 12.0]]))
    with pytest.raises(ImucalError, match="one to one"):  # one of ours overlaps none
        gyro_imutk_cv.match_segments(OURS, np.array([[1.0, 3.0], [5.0, 7.0], [30.0, 31.0]]))


def test_ratio_interval_is_paired_and_brackets_the_ratio():
    e = np.random.default_rng(1).rayleigh(0.5, 37)
    lo, hi = gyro_imutk_cv.ratio_interval(0.8 * e, e)
    assert lo == pytest.approx(0.8) and hi == pytest.approx(0.8)  # paired: a constant ratio has no spread
    lo, hi = gyro_imutk_cv.ratio_interval(e[::-1], e)
    assert lo < 1.0 < hi


def test_driver_segment_list_is_checked(tmp_path):
    good = tmp_path / "segments.txt"
    good.write_text("0 51.9 55.2 1\n1 63.3 67.7 0\n")
    assert gyro_imutk_cv.read_segments(good)[:, 3].tolist() == [1, 0]
    bad = tmp_path / "bad.txt"
    bad.write_text("1 51.9 55.2 1\n")
    with pytest.raises(ImucalError, match="driver"):
        gyro_imutk_cv.read_segments(bad)
