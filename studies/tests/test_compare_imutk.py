"""Side by side with imu_tk on the shipped Xsens recording (studies/compare_imutk.py, issue 2 'Must show')."""
from __future__ import annotations

import importlib.util

import numpy as np
import pytest

from studies.tests.helpers import study

spec = importlib.util.spec_from_file_location("compare_imutk", study("compare_imutk"))
compare_imutk = importlib.util.module_from_spec(spec)
spec.loader.exec_module(compare_imutk)

#: imu_tk's residual on its own intervals, as quoted in the issue.
IMUTK_RMS = 0.00112


@pytest.fixture(scope="module")
def noise():
    return compare_imutk.compare("noise")


@pytest.fixture(scope="module")
def uniform():
    return compare_imutk.compare("uniform")


def test_rms_no_worse_than_imutk(noise, uniform):
    assert noise["rms_ours"] <= IMUTK_RMS
    # On the very same intervals, both of our fits beat imu_tk's parameters.
    assert noise["rms_ours"] < noise["rms_imutk"]
    assert uniform["rms_ours"] < noise["rms_imutk"]
    # ... and noise weighting gives the smaller chi-square, as it must.
    assert noise["run"].result.chi2 < noise["chi2_imutk"]


def test_biases_and_scales_agree_within_standard_errors(noise, uniform):
    for res in (noise, uniform):
        rows = {r[0]: r for r in res["rows"]}
        for n in ("s1", "s2", "s3"):
            assert abs(rows[n][4]) < 2.0, rows[n]
        for n in ("b1", "b2", "b3"):
            assert abs(rows[n][4]) < 3.5, rows[n]
    # imu_tk's K against 1/b: same to 4e-4 relative.
    np.testing.assert_allclose(noise["K_ours"], noise["K_imutk"], rtol=4e-4)
