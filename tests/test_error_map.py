"""Relative-error map (paper, Figs. 3 and 4): the numbers behind the figures, the PNGs, the CLI."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from imucal.cli.main import main
from imucal.analysis.error_map import (PAPER_ANGLES, compute_error_map, relative_error)
from imucal.analysis.worst_case import gram_np


@pytest.fixture(scope="module")
def emap():
    return compute_error_map(samples=200_000, seed=0)


def test_relative_error_matches_the_casadi_model():
    from imucal.model.sensor import build_model

    model = build_model()
    rng = np.random.default_rng(0)
    m = rng.uniform(-20, 20, (50, 3))
    p = np.array([0, 0, 0, 1, 1, 1, *PAPER_ANGLES])  # s = 0, b = 1: raw = m
    a_nonorth = np.array([float(model.norm(mi, [], p)) for mi in m])  # Proposition 2
    expect = np.abs(a_nonorth - np.linalg.norm(m, axis=1)) / a_nonorth
    assert np.allclose(relative_error(m, PAPER_ANGLES), expect, rtol=1e-12, atol=1e-15)


def test_relative_error_depends_on_direction_only():
    m = np.random.default_rng(1).normal(size=(100, 3))
    e = relative_error(m, PAPER_ANGLES)
    assert np.allclose(relative_error(7.3 * m, PAPER_ANGLES), e, rtol=1e-12)
    assert np.allclose(relative_error(-m, PAPER_ANGLES), e, rtol=1e-12)


def test_sample_stays_within_the_eigenvalue_bound(emap):
    lam = np.linalg.eigvalsh(gram_np(PAPER_ANGLES))
    bound = max(1 - math.sqrt(lam[0]), math.sqrt(lam[-1]) - 1)
    assert emap.errors.max() <= bound + 1e-15
    assert emap.errors.max() > bound - 2e-4  # dense sample comes close
    assert emap.plateau == pytest.approx(1 - math.sqrt(lam[0]), rel=1e-12)
    assert 0.014 < emap.plateau < 0.016  # the paper's jump between 1.4 % and 1.6 %


def test_histogram_jumps_at_one_minus_sqrt_lambda_min(emap):
    counts, edges = emap.histogram(200)
    k = int(np.searchsorted(edges, emap.plateau)) - 1  # bin holding the jump
    assert abs(int(np.argmax(counts)) - k) <= 1  # the spike sits at the jump
    below = counts[k - 3:k].mean()
    above = counts[k + 2:k + 8].mean()
    assert above < below / 5  # the drop across the jump


def test_cones_around_the_simple_eigenvector(emap):
    cones = emap.cones()
    v = emap.eigenvectors[:, 2]
    u = emap.points / np.linalg.norm(emap.points, axis=1, keepdims=True)
    ang = np.degrees(np.arccos(np.clip(np.abs(u @ v), 0, 1)))
    a16 = cones["0.016 (a_orth > a_nonorth)"]
    assert np.all(emap.errors[ang < a16 - 0.05] >= 0.016)
    assert np.all(emap.errors[ang > a16 + 0.05] < 0.016)
    assert np.all(emap.errors[np.abs(ang - cones["zero"]) < 0.05] < 1e-3)


def test_domain_shares_are_complementary(emap):
    d = emap.to_dict()["domains"]
    assert d["<=0.014"] + d[">=0.014"] == pytest.approx(1.0)
    assert d["<=0.016"] + d[">=0.016"] == pytest.approx(1.0)
    assert 0.1 < d[">=0.016"] < d[">=0.014"] < 0.6


def _check_png(path, min_w, min_h):
    import matplotlib.image as mpimg

    img = mpimg.imread(path)
    h, w = img.shape[:2]
    assert w >= min_w and h >= min_h
    rgb = img[..., :3].reshape(-1, 3)
    assert rgb.std() > 0.05  # not blank
    assert np.mean(np.all(rgb > 0.97, axis=1)) < 0.95  # not (nearly) all white
    assert len(np.unique((rgb * 255).astype(int), axis=0)) > 50  # drawn content, colours


def test_cli_error_map_writes_figures_and_summary(tmp_path, capsys):
    out = tmp_path / "map"
    rc = main(["error-map", "--angles", "1.53938", "1.60221", "1.60221", "--out", str(out),
               "--samples", "20000", "--grid", "6", "--seed", "4"])
    assert rc == 0
    assert "jump at 1.583" in capsys.readouterr().out
    _check_png(out / "relative_error_histogram.png", 800, 500)
    _check_png(out / "relative_error_domains.png", 1000, 900)
    d = json.loads((out / "error_map.json").read_text())
    assert d["samples"] == 20000 and d["seed"] == 4 and d["box"] == [-20.0, 20.0]
    assert d["jump_at"] == pytest.approx(0.015831, abs=1e-6)
    assert d["bound"] == pytest.approx(0.030931, abs=1e-6)
    assert sum(d["histogram"]["counts"]) == 20000
    assert sorted(p.name for p in out.iterdir()) == ["error_map.json", "relative_error_domains.png",
                                                     "relative_error_histogram.png"]


@pytest.mark.parametrize("args, needle", [
    (["--angles", "1.5", "3.2", "1.5"], "outside (0, pi)"),
    (["--angles", "0", "1.5", "1.5"], "outside (0, pi)"),
    (["--angles", "2.1", "2.1", "2.1"], "degenerate frame"),
    (["--angles", "1.5", "1.6", "1.6", "--range", "0"], "range 0 must be positive"),
    (["--angles", "1.5", "1.6", "1.6", "--range", "-20"], "range -20 must be positive"),
    (["--angles", "1.5", "1.6", "1.6", "--samples", "10"], "samples 10 must be"),
    (["--angles", "1.5", "1.6", "1.6", "--levels", "150"], "levels"),
])
def test_cli_error_map_bad_input(tmp_path, capsys, args, needle):
    out = tmp_path / "map"
    assert main(["error-map", *args, "--out", str(out), "--samples", "20000"] if "--samples" not in args
                else ["error-map", *args, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("imucal: error:") and needle in err, err
    assert not out.exists() or list(out.iterdir()) == []
