"""studies/mc_uncertainty.py: one replicate runs, is deterministic, and refuses a plan of 6 directions."""
from __future__ import annotations

import importlib.util
import math
import sys

import numpy as np
import pytest

from imucal.analysis import design as D
from imucal.model.parameters import BASE_NAMES
from studies.tests.helpers import study


def _mc_script():
    spec = importlib.util.spec_from_file_location("mc_uncertainty", study("mc_uncertainty"))
    mod = importlib.util.module_from_spec(spec)
    sys.modules["mc_uncertainty"] = mod
    spec.loader.exec_module(mod)
    return mod


def test_mc_script_replicate_runs_and_is_deterministic() -> None:
    mc = _mc_script()
    s = mc.Setting("edges", "counts")
    a, b = mc.one_replicate(s, 3, 0), mc.one_replicate(s, 3, 0)
    np.testing.assert_array_equal(a["err"], b["err"])
    assert a["free"] == BASE_NAMES and a["crlb"].shape == (9,)
    assert a["newton"] < 1e-3  # the reported estimate sits at the optimum
    six = mc.one_replicate(mc.Setting("cube-24", "si", orthogonal=True), 0, 0)
    assert six["free"] == D.SIX_NAMES
    assert "only 6 distinct gravity directions" in mc.refusal_message(mc.Setting("cube-24", "si"))


def test_t_quantile_against_tables() -> None:
    t_quantile = _mc_script().t_quantile
    for dof, want in ((1, 12.7062047), (3, 3.18244631), (15, 2.13144955), (100, 1.98397152)):
        assert t_quantile(0.975, dof) == pytest.approx(want, rel=1e-6)
    assert t_quantile(0.975, math.inf) == pytest.approx(1.959964, rel=1e-4)
