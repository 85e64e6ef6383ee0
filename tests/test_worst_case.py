"""Worst-case analysis (paper, Section 4): the paper's numbers, certificates, multi-start, CLI."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from imucal.analysis import worst_case as wcm
from imucal.cli.main import main
from imucal.constants import RIGHT_ANGLE, STANDARD_GRAVITY
from imucal.analysis.worst_case import (CERTIFICATE_TOL, AngleBox, CertificateError, GramBounds, certify,
                               gram_bounds, gram_np, linearisation_samples, max_abs_error,
                               max_linearisation_error, max_rel_error, max_tolerance)

PAPER_BOX = AngleBox.from_tolerance(0.02)
C = math.sin(0.01 * math.pi)  # cosine bound of the paper's box


@pytest.fixture(scope="module")
def problem1():
    return max_abs_error(PAPER_BOX, STANDARD_GRAVITY)


def _one_line_error(capsys, *needles: str) -> str:
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("imucal: error:"), err
    for n in needles:
        assert n in err, err
    return err


# --- the paper's numbers --------------------------------------------------------------------------
def test_problem1_reproduces_paper_with_standard_gravity(problem1):
    # Paper: 0.3130299 m/s^2; we use g = 9.80665 (standard gravity) and agree to 1e-6.
    assert abs(problem1.value - 0.3130299) < 1e-6
    assert problem1.certificate.kind == "exact"
    assert abs(problem1.certificate.gap) <= CERTIFICATE_TOL * STANDARD_GRAVITY


def test_problem1_maximiser_is_the_papers_point(problem1):
    # Paper: a_x = a_y = a_z ~ 5.48114, phi = psi = theta ~ 1.60221 (reported: the all-positive one).
    assert np.allclose(problem1.acceleration, 5.48114, atol=1e-5)
    assert np.allclose(problem1.angles, 1.60221, atol=1e-5)
    assert np.allclose(problem1.angles, RIGHT_ANGLE * 1.02, atol=1e-7)
    # Every maximiser found has |m_i| equal, angles at bounds and the same value.
    for m in problem1.maximisers:
        assert np.allclose(np.abs(m[:3]), 5.48114, atol=1e-5)
        assert all(min(abs(a - RIGHT_ANGLE * 0.98), abs(a - RIGHT_ANGLE * 1.02)) < 1e-6 for a in m[3:])


def test_problem1_closed_form_certificate(problem1):
    assert problem1.certificate.bound == pytest.approx(STANDARD_GRAVITY * (1 - math.sqrt(1 - 2 * C)),
                                                       rel=1e-14)
    # The paper's maximiser attains it: m = g sqrt((1 - 2c)/3) (1, 1, 1).
    assert STANDARD_GRAVITY * math.sqrt((1 - 2 * C) / 3) == pytest.approx(5.48114, abs=1e-5)


@pytest.mark.parametrize("range_g", [4, 8, 16])
def test_problem2_paper_value_for_each_range(range_g):
    e = max_rel_error(PAPER_BOX, range_g * STANDARD_GRAVITY)
    assert 100 * e.value == pytest.approx(3.192, abs=5e-4)  # paper: 3.192 %
    assert abs(e.certificate.gap) <= CERTIFICATE_TOL
    assert e.certificate.bound == pytest.approx(1 - math.sqrt(1 - 2 * C), rel=1e-14)
    assert np.all(np.abs(e.acceleration) <= range_g * STANDARD_GRAVITY * (1 + 1e-6))
    # The maximiser points along the lambda_min eigenvector of G at its angles.
    lam, vec = np.linalg.eigh(gram_np(e.angles))
    u = np.asarray(e.acceleration) / np.linalg.norm(e.acceleration)
    assert abs(abs(u @ vec[:, 0]) - 1) < 1e-6 and lam[0] == pytest.approx(1 - 2 * C, abs=1e-7)


def test_rescaled_problems_give_the_same_answer():
    # Problem 1 scales with g; problem 2 does not depend on the range (direction only).
    a1 = max_abs_error(PAPER_BOX, 1.0)
    a2 = max_abs_error(PAPER_BOX, 2 * STANDARD_GRAVITY)
    assert a2.value == pytest.approx(2 * STANDARD_GRAVITY * a1.value, rel=1e-8)
    r1, r2 = max_rel_error(PAPER_BOX, 1.0), max_rel_error(PAPER_BOX, 1e3)
    assert r1.value == pytest.approx(r2.value, rel=1e-8)


# --- the certificate's eigenvalue extremes are at vertices ------------------------------------------
def test_paper_box_eigen_extremes_at_vertices_and_closed_form():
    b = gram_bounds(PAPER_BOX)
    assert b.lambda_min == pytest.approx(1 - 2 * C, abs=1e-14)
    assert b.lambda_max == pytest.approx(1 + 2 * C, abs=1e-14)
    rng = np.random.default_rng(1)
    ang = PAPER_BOX.mid + PAPER_BOX.half * rng.uniform(-1, 1, (20000, 3))
    ev = np.linalg.eigvalsh(gram_np(ang))
    assert ev[:, 0].min() >= b.lambda_min - 1e-14
    assert ev[:, -1].max() <= b.lambda_max + 1e-14
    assert ev[:, 0].min() < b.lambda_min + 5e-3  # the samples come close: the bound is tight


@settings(max_examples=30, deadline=None)
@given(st.lists(st.floats(1.3, 1.85), min_size=3, max_size=3),
       st.lists(st.floats(0.0, 0.1), min_size=3, max_size=3))  # lambda_min >= 0.28: valid boxes
def test_eigen_extremes_at_vertices_for_random_boxes(mid, half):
    box = AngleBox.around(mid, half, 1.0)
    b = gram_bounds(box)
    ang = box.mid + box.half * np.random.default_rng(0).uniform(-1, 1, (3000, 3))
    ev = np.linalg.eigvalsh(gram_np(ang))
    assert ev[:, 0].min() >= b.lambda_min - 1e-12
    assert ev[:, -1].max() <= b.lambda_max + 1e-12


def test_fixed_angles_equal_the_closed_form_and_widening_grows_it():
    ang = (1.56715, 1.56112, 1.54944)
    lam = np.linalg.eigvalsh(gram_np(ang))
    fixed = max_abs_error(AngleBox.around(ang), 9.81)
    expect = 9.81 * max(1 - math.sqrt(lam[0]), math.sqrt(lam[-1]) - 1)
    assert fixed.value == pytest.approx(expect, abs=1e-7)
    assert np.allclose(fixed.angles, ang)
    wide = max_abs_error(AngleBox.around(ang, (1e-3,) * 3, 3.0), 9.81)
    assert wide.value > fixed.value + 1e-3


# --- multi-start -----------------------------------------------------------------------------------
def test_multistart_is_reproducible_with_the_seed():
    a = max_rel_error(PAPER_BOX, 40.0, starts=6, seed=7)
    b = max_rel_error(PAPER_BOX, 40.0, starts=6, seed=7)
    c = max_rel_error(PAPER_BOX, 40.0, starts=6, seed=8)
    assert a == b
    assert (a.seed, a.starts) == (7, 6) and 1 <= a.converged <= 6
    assert a.acceleration != c.acceleration  # another seed, other starts
    assert c.value == pytest.approx(a.value, abs=CERTIFICATE_TOL)


# --- linearised model --------------------------------------------------------------------------------
def test_linearised_frame_is_the_small_angle_misalignment_matrix():
    import casadi as ca

    a = ca.SX.sym("a", 3)
    _, L_lin = wcm._linearised_frame(a)
    f = ca.Function("f", [a], [L_lin])
    d = np.array([0.01, -0.02, 0.03])
    expect = np.array([[1, 0, 0], [d[0], 1, 0], [d[1], d[2], 1]])
    assert np.allclose(np.asarray(f(RIGHT_ANGLE + d)), expect, atol=1e-12)


def test_linearisation_error_positive_and_matches_dense_samples():
    R = 4 * STANDARD_GRAVITY
    e = max_linearisation_error(PAPER_BOX, R, samples=3000)
    lb = linearisation_samples(PAPER_BOX, R, 3000, seed=5)
    assert e.value > 0.05  # it matters: > 0.05 m/s^2 over +-4 g
    assert e.value >= lb - CERTIFICATE_TOL * R  # the NLP reaches every sample
    assert e.value <= lb * (1 + 1e-4)  # and the vertex samples come within 1e-4 of it
    assert e.certificate.kind == "lower"
    # Linear in the range (the difference is linear in m).
    assert max_linearisation_error(PAPER_BOX, 2 * R, samples=3000).value == pytest.approx(2 * e.value,
                                                                                          rel=1e-6)


# --- certificates fail loudly ------------------------------------------------------------------------
def test_certify_raises_on_disagreement():
    certify("exact", 1.0, 1.0 + 5e-8, 1e-7, "f", "p")
    with pytest.raises(CertificateError, match="disagrees with the certificate"):
        certify("exact", 1.0, 1.001, 1e-7, "f", "p")
    with pytest.raises(CertificateError):
        certify("exact", 1.001, 1.0, 1e-7, "f", "p")
    certify("lower", 2.0, 1.0, 1e-7, "f", "p")  # above a lower bound is fine
    with pytest.raises(CertificateError):
        certify("lower", 1.0, 2.0, 1e-7, "f", "p")


def test_cli_certificate_failure_exits_1_and_writes_nothing(tmp_path, capsys, monkeypatch):
    real = wcm.gram_bounds

    def wrong(box):
        b = real(box)
        return GramBounds(b.lambda_min * 0.99, b.lambda_max, b.at_min, b.at_max)

    monkeypatch.setattr(wcm, "gram_bounds", wrong)
    out = tmp_path / "wc.json"
    assert main(["worst-case", "--json", str(out)]) == 1
    _one_line_error(capsys, "certificate failed")
    assert not out.exists()


# --- command line ------------------------------------------------------------------------------------
def test_cli_worst_case_json(tmp_path, capsys):
    out = tmp_path / "wc.json"
    assert main(["worst-case", "--range-g", "8", "--starts", "8", "--seed", "3", "--json", str(out)]) == 0
    assert "0.3130303 m/s^2" in capsys.readouterr().out
    d = json.loads(out.read_text())
    assert d["gravity"] == STANDARD_GRAVITY and d["range_g"] == 8
    a, r = d["abs_error_max"], d["rel_error_max"]
    for e in (a, r, d["linearisation_error_max"]):
        assert {"value", "acceleration", "angles", "bound"} <= set(e)
        assert len(e["acceleration"]) == 3 and len(e["angles"]) == 3
        assert e["multistart"] == {"starts": 8, "converged": e["multistart"]["converged"], "seed": 3}
    assert abs(a["value"] - 0.3130299) < 1e-6
    assert abs(a["bound"]["difference"]) <= a["bound"]["tolerance"]
    assert r["value"] == pytest.approx(0.03192, abs=5e-6)
    assert a["unit"] == "m/s^2" and r["unit"] == "fraction"


def _calibration_file(path, angles, std=1e-3):
    from imucal.calibration import frozen as cal_mod
    from imucal.model.parameters import base_parameters

    params = base_parameters([0.1, -0.2, 0.3], [1.01, 0.99, 1.02], angles, raw_unit="m/s^2")
    cal = cal_mod.Calibration(params=params, std={n: std for n in params}, gravity=9.81,
                              raw_unit="m/s^2", fit={"rms_residual": 0.004})
    cal.save(path)
    return path


def test_cli_worst_case_with_calibration(tmp_path, capsys):
    ang = (1.56, 1.58, 1.55)
    cal = _calibration_file(tmp_path / "cal.yaml", ang)
    out = tmp_path / "wc.json"
    assert main(["worst-case", "--calibration", str(cal), "--starts", "4", "--json", str(out)]) == 0
    d = json.loads(out.read_text())
    lam = np.linalg.eigvalsh(gram_np(ang))
    assert d["gravity"] == 9.81
    assert np.allclose(d["abs_error_max"]["angles"], ang)
    assert d["abs_error_max"]["value"] == pytest.approx(9.81 * (1 - math.sqrt(lam[0])), abs=1e-7)
    out2 = tmp_path / "wc2.json"
    assert main(["worst-case", "--calibration", str(cal), "--widen", "2", "--starts", "4",
                 "--json", str(out2)]) == 0
    d2 = json.loads(out2.read_text())
    assert d2["angle_box"]["phi"] == pytest.approx([1.558, 1.562])
    assert d2["abs_error_max"]["value"] > d["abs_error_max"]["value"]


@pytest.mark.parametrize("args, needles", [
    (["--tolerance", "0"], ["tolerance 0.0 must be positive"]),
    (["--tolerance", "-0.1"], ["must be positive"]),
    (["--tolerance", "0.34"], ["degenerate frame", f"below {max_tolerance():.4f}"]),
    (["--tolerance", "1.5"], ["outside (0, pi)"]),
    (["--range-g", "0"], ["range 0 g must be positive"]),
    (["--range-g", "-4"], ["must be positive"]),
    (["--gravity", "-9.8"], ["gravity -9.8 m/s^2 is not a local gravity on Earth"]),
])
def test_cli_bad_input_one_line_exit_2_nothing_written(tmp_path, capsys, args, needles):
    out = tmp_path / "wc.json"
    assert main(["worst-case", *args, "--json", str(out)]) == 2
    _one_line_error(capsys, *needles)
    assert list(tmp_path.iterdir()) == []


def test_cli_widened_calibration_outside_0_pi_refused(tmp_path, capsys):
    cal = _calibration_file(tmp_path / "cal.yaml", (1.56, 1.58, 1.55), std=1.0)
    out = tmp_path / "wc.json"
    assert main(["worst-case", "--calibration", str(cal), "--widen", "2", "--json", str(out)]) == 2
    _one_line_error(capsys, "outside (0, pi)")
    assert not out.exists()


def test_angle_box_refuses_bad_angles():
    with pytest.raises(Exception, match=r"outside \(0, pi\)"):
        AngleBox.around((0.0, 1.5, 1.5))
    with pytest.raises(Exception, match=r"outside \(0, pi\)"):
        AngleBox.around((1.5, 3.2, 1.5))
    with pytest.raises(Exception, match="degenerate frame"):
        AngleBox.around((2.1, 2.1, 2.1))  # three axes at 120 deg: nearly coplanar
    assert max_tolerance() == pytest.approx(2 / math.pi * math.asin(0.495))


@pytest.mark.parametrize("kind", ["abs", "rel", "lin"])
def test_problems_invariant_under_axis_sign_flips(kind):
    # The symmetry behind the canonical maximiser: m_i -> -m_i with its two angles -> pi - angle.
    _, value = wcm._problem(kind)
    box = AngleBox.from_tolerance(0.05)
    p = np.concatenate([box.mid, box.half, [1.0]])
    rng = np.random.default_rng(2)
    for _ in range(5):
        x, u = rng.uniform(-1, 1, 3), rng.uniform(-1, 1, 3)
        v = float(value(np.r_[x, u], p)[0])
        for i in range(3):
            x2, u2 = x.copy(), u.copy()
            x2[i] = -x2[i]
            u2[list(wcm._AXIS_ANGLES[i])] *= -1
            assert float(value(np.r_[x2, u2], p)[0]) == pytest.approx(v, rel=1e-12)
