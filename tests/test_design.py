"""Pose design (imucal.analysis.design, `imucal plan-poses`): Fisher information, CRLB, criteria, optimiser."""
from __future__ import annotations

import json
import math

import casadi as ca
import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from imucal.analysis import design as D
from imucal.errors import ImucalError
from imucal.model.sensor import build_model
from imucal.model.parameters import BASE_NAMES
from imucal.analysis.simulate import cube_directions, frame_matrix, mems_counts_sensor, random_directions

G = 9.80665


def _sensor(seed: int = 3) -> tuple:
    s = mems_counts_sensor(np.random.default_rng(seed))
    return s, D.DesignSensor(tuple(s.s), tuple(s.b), tuple(s.angles))


def test_sensitivity_matches_casadi_model() -> None:
    """The closed-form dr/dp and dr/draw equal CasADi's derivatives of the model's residual."""
    spec, ds = _sensor()
    model = build_model()
    raw, p = ca.SX.sym("raw", 3), ca.SX.sym("p", 9)
    r = model.residual(raw, ca.SX(0, 1), p, G)
    f = ca.Function("f", [raw, p], [r, ca.jacobian(r, p), ca.jacobian(r, raw)])
    u = random_directions(20, np.random.default_rng(1))
    J = D.sensitivity(u, ds, G)
    E = frame_matrix(np.asarray(spec.angles))
    pv = np.array([ds.values()[n] for n in BASE_NAMES])
    for k in range(len(u)):
        rk, Jp, Jr = f(np.asarray(spec.s) + np.asarray(spec.b) * (G * u[k] @ E), pv)
        assert abs(float(rk)) < 1e-9  # the truth satisfies g = a_nonorth
        np.testing.assert_allclose(np.asarray(Jp).ravel(), J[k], rtol=1e-9, atol=1e-12 * np.abs(J[k]).max())
        np.testing.assert_allclose(np.asarray(Jr).ravel(), -J[k, :3], rtol=1e-9, atol=1e-15)


def test_fisher_equals_fit_information_at_the_same_point() -> None:
    """F from design equals J^T W J built from imucal.solve.fit's own Jacobian rows."""
    from imucal.solve.fit import FitData, jacobian_rows
    from imucal.model.parameters import base_parameters

    spec, ds = _sensor(5)
    u = D.scheme_directions("wedge-24")
    E = frame_matrix(np.asarray(spec.angles))
    raw = np.asarray(spec.s) + np.asarray(spec.b) * (G * u @ E)
    params = base_parameters(spec.s, spec.b, spec.angles, gravity=G)
    data = FitData(raw=raw, cov=np.zeros((len(u), 0)), raw_var=np.full(raw.shape, 0.04), group=np.arange(len(u)),
                   mode="means")
    Jfit = jacobian_rows(data, params, model=build_model(), gravity=G) / np.array([params[n].scale for n in BASE_NAMES])
    sig = D.residual_sigma(u, 0.2, ds, G)
    F = D.fisher(u, sig, ds, G)
    F_fit = (Jfit / sig[:, None]).T @ (Jfit / sig[:, None])
    np.testing.assert_allclose(F, F_fit, rtol=1e-8, atol=1e-12 * np.abs(F).max())


@pytest.mark.parametrize("n", [12, 18, 24])
def test_planned_matches_or_beats_common_schemes_on_d(n: int) -> None:
    planned = D.optimal_design(n, "D")
    comp = D.compare(planned, n_random=50)
    labels = {o.label for o in comp.others}
    assert "best cube subset" in labels
    for o in comp.others:
        assert planned.log_det_fisher >= o.log_det_fisher - 1e-9, o.label
    assert planned.value >= comp.random_best
    assert planned.n_distinct >= 9


def test_edges_are_near_optimal_at_twelve_and_planned_beats_the_cube_at_nine() -> None:
    planned = D.optimal_design(12, "D")
    edges = D.evaluate(D.scheme_directions("edges"), "D")
    assert 0.95 <= edges.d_efficiency(planned) <= 1.0 + 1e-12
    p9 = D.optimal_design(9, "D")
    sub9 = D.best_cube_subset(9, "D")
    assert p9.d_efficiency(sub9) > 1.05  # off the cube grid at N = 9


@pytest.mark.parametrize("criterion", ["A", "E"])
def test_planned_matches_or_beats_edges_on_a_and_e(criterion: str) -> None:
    planned = D.optimal_design(12, criterion)
    edges = D.evaluate(D.scheme_directions("edges"), criterion)
    if criterion == "A":
        assert planned.value <= edges.value * (1 + 1e-9)
    else:
        assert planned.value >= edges.value * (1 - 1e-9)


def test_six_parameter_model_faces_are_d_optimal() -> None:
    planned = D.optimal_design(6, "D", free=D.SIX_NAMES)
    faces = D.evaluate(D.scheme_directions("faces"), "D", free=D.SIX_NAMES)
    assert planned.log_det_fisher >= faces.log_det_fisher - 1e-9
    assert faces.d_efficiency(planned) > 0.999


def test_flat_24_position_scheme_is_refused_with_the_reason() -> None:
    with pytest.raises(ImucalError) as exc:
        D.evaluate(D.scheme_directions("cube-24"), "D", label="cube-24")
    msg = str(exc.value)
    assert "only 6 distinct gravity directions for 9 parameters" in msg
    assert "phi, psi, theta" in msg and "--fix-angles" in msg
    wedge = D.evaluate(D.scheme_directions("wedge-24"), "D")
    assert wedge.n_distinct == 24
    # on its own terms the flat scheme is fine for the 6-parameter model
    assert D.evaluate(D.scheme_directions("cube-24"), "D", free=D.SIX_NAMES).n_distinct == 6


def test_too_few_poses_and_bad_criterion_are_refused() -> None:
    with pytest.raises(ImucalError, match="8 poses cannot determine 9 parameters"):
        D.optimal_design(8)
    with pytest.raises(ImucalError, match="unknown criterion 'Q'"):
        D.optimal_design(12, "Q")
    with pytest.raises(ImucalError, match="noise .* must be a positive number"):
        D.evaluate(D.scheme_directions("edges"), noise=-1.0)
    with pytest.raises(ImucalError, match="finite non-zero vector"):
        D.evaluate(np.zeros((12, 3)))


def test_singular_information_names_the_undetermined_parameters() -> None:
    ang = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    planar = np.column_stack([np.cos(ang), np.sin(ang), np.zeros(12)])  # gravity never along z
    with pytest.raises(ImucalError) as exc:
        D.evaluate(planar, "D", check_distinct=False)
    assert "undetermined" in str(exc.value) and "s3" in str(exc.value)


def test_optimiser_is_deterministic_for_a_seed() -> None:
    a = D.optimal_design(10, "D", seed=4)
    b = D.optimal_design(10, "D", seed=4)
    np.testing.assert_array_equal(a.directions, b.directions)


def test_predicted_std_matches_a_closed_form() -> None:
    """For the 6 faces of an ideal sensor (6-parameter model): var(s_i) = sigma^2 / 2 exactly."""
    d = D.evaluate(D.scheme_directions("faces"), "D", noise=0.002, free=D.SIX_NAMES)
    for i in (1, 2, 3):
        assert d.std[f"s{i}"] == pytest.approx(0.002 / math.sqrt(2), rel=1e-12)
        assert d.std[f"b{i}"] == pytest.approx(0.002 / math.sqrt(2) / G, rel=1e-12)


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 10_000), n=st.integers(9, 30), noise=st.floats(1e-4, 0.1))
def test_information_properties(seed: int, n: int, noise: float) -> None:
    """F is symmetric PSD; adding a pose never lowers log det; std scales with the noise;
    D-efficiencies do not depend on the parameter units (natural vs acceleration-equivalent)."""
    rng = np.random.default_rng(seed)
    _, ds = _sensor(seed % 7)
    u = random_directions(n, rng)
    F = D.fisher(u, noise, ds, G)
    assert np.allclose(F, F.T)
    w = np.linalg.eigvalsh(F / np.abs(F).max())
    assert w[0] > -1e-12
    F2 = D.fisher(np.vstack([u, random_directions(1, rng)]), noise, ds, G)
    assert np.linalg.slogdet(F2)[1] >= np.linalg.slogdet(F)[1] - 1e-9
    # The remaining identities hold to 1e-9 only where the poses determine the parameters: a
    # random set of 9 can be (nearly) degenerate (condition 3e16 at seed 9143, n 9).
    assume(np.linalg.cond(F) < 1e10)
    a = D.evaluate(u, "D", noise, ds, G, check_distinct=False)
    b = D.evaluate(u, "D", 2 * noise, ds, G, check_distinct=False)
    for k in a.std:
        assert b.std[k] == pytest.approx(2 * a.std[k], rel=1e-9)
    ref = D.evaluate(cube_directions("edges"), "D", noise, ds, G)
    # efficiency from det F (natural units) equals that from the criterion (normalised units)
    assert a.d_efficiency(ref) == pytest.approx(math.exp((a.value - ref.value) / 9), rel=1e-9)


# --- the command ----------------------------------------------------------------------------
def test_cli_plans_writes_json_and_scores_it_back(run_cli, tmp_path) -> None:
    out = tmp_path / "plan.json"
    r = run_cli(["plan-poses", "--n", "12", "--json", out])
    assert r.code == 0, r.err
    assert "[[Comparison at N = 12]]" in r.out and "edges" in r.out and "best cube subset" in r.out
    assert "[[Efficiency]] against this plan: the 12 cube edges 97.0 %" in r.out
    obj = json.loads(out.read_text())
    assert obj["format"] == "imucal-pose-plan" and obj["n"] == 12
    P = np.array(obj["poses"])
    assert P.shape == (12, 3)
    np.testing.assert_allclose(np.linalg.norm(P, axis=1), 1.0, atol=1e-12)
    assert set(obj["predicted_std"]) == set(BASE_NAMES)
    assert obj["hold_order"] == list(range(1, 13)) and "[[Hold order]]" not in r.out
    r2 = run_cli(["plan-poses", "--evaluate", out, "--no-compare"])
    assert r2.code == 0, r2.err
    assert f"{obj['criterion_value']:.6g}" in r2.out


def test_cli_revisit_prints_and_writes_the_hold_order_for_discovery(run_cli, tmp_path) -> None:
    out = tmp_path / "plan.json"
    r = run_cli(["plan-poses", "--scheme", "faces+edges", "--no-compare", "--revisit", "--json", out])
    assert r.code == 0, r.err
    order = json.loads(out.read_text())["hold_order"]
    assert order == list(range(1, 19)) + list(range(18, 0, -1))
    assert "[[Hold order]] every pose twice, the second pass in reverse (36 holds; for discover): 1 2 3" in r.out
    assert r.out.rstrip().splitlines()[-2].endswith(" 3 2 1")


def test_cli_refuses_the_flat_24_positions(run_cli, tmp_path) -> None:
    r = run_cli(["plan-poses", "--scheme", "cube-24"])
    assert r.code == 2
    assert "only 6 distinct gravity directions for 9 parameters" in r.err
    assert len(r.err.strip().splitlines()) == 1
    plan = tmp_path / "cube24.json"
    plan.write_text(json.dumps({"poses": D.scheme_directions("cube-24").tolist()}))
    r = run_cli(["plan-poses", "--evaluate", plan])
    assert r.code == 2 and "only 6 distinct" in r.err
    r = run_cli(["plan-poses", "--evaluate", plan, "--fix-angles", "--no-compare"])
    assert r.code == 0 and "6 parameters" in r.out


@pytest.mark.parametrize("content, message", [
    ("not json", "is not readable JSON"),
    ('{"format": "imucal-calibration"}', "is not a pose plan"),
    ('{"format_version": 9, "poses": [[0, 0, 1]]}', "unknown format_version 9"),
    ('{"n": 3}', "missing key 'poses'"),
    ('{"poses": [[0, 0]]}', "poses must be a non-empty list"),
])
def test_cli_bad_plan_files(run_cli, tmp_path, content: str, message: str) -> None:
    p = tmp_path / "plan.json"
    p.write_text(content)
    r = run_cli(["plan-poses", "--evaluate", p])
    assert r.code == 2 and message in r.err


def test_cli_argument_errors(run_cli) -> None:
    r = run_cli(["plan-poses"])
    assert r.code == 2 and "give exactly one of --n, --evaluate, --scheme" in r.err
    r = run_cli(["plan-poses", "--n", "5"])
    assert r.code == 2 and "5 poses cannot determine 9 parameters" in r.err
    r = run_cli(["plan-poses", "--scheme", "dodecahedron"])
    assert r.code == 2 and "unknown scheme 'dodecahedron'" in r.err


@pytest.mark.parametrize("noise", ["1e-310", "1e300"])
def test_cli_refuses_a_noise_no_design_can_be_scored_at(run_cli, noise) -> None:
    """1e-310 made F = J^T J / noise^2 overflow (LinAlgError, exit 3); 1e300 called the poses singular."""
    r = run_cli(["plan-poses", "--n", "12", "--noise", noise])
    assert r.code == 2, r.err
    lines = r.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("imucal: error: --noise: noise "), r.err
    assert "outside 1e-09 to 100 m/s^2" in lines[0] and "fix:" in lines[0]


def test_plan_poses_says_how_efficient_a_scheme_is(run_cli, tmp_path) -> None:
    """Issue 29: scoring the 12 cube edges says they are 97 % efficient: the D-efficiency against the
    best 12-pose plan plan-poses finds, computed here from the two designs."""
    out = tmp_path / "edges.json"
    r = run_cli(["plan-poses", "--scheme", "edges", "--no-compare", "--json", out])
    assert r.code == 0, r.err
    want = D.evaluate(D.scheme_directions("edges"), "D").d_efficiency(D.optimal_design(12, "D"))
    assert 0.95 < want < 0.99
    assert f"the 12 cube edges: {100 * want:.1f} % efficient against the best 12-pose plan found" in r.out
    assert json.loads(out.read_text())["efficiency_vs_best_found"] == pytest.approx(want, rel=1e-12)
    r = run_cli(["plan-poses", "--scheme", "faces", "--fix-angles", "--no-compare"])
    assert "the 6 cube faces: as good as the best 6-pose plan found" in r.out and "--fix-angles finds" in r.out
