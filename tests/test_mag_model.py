"""The magnetometer's model (issue 26): once in CasADi, the accelerometer's maths with a field for gravity."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from imucal.errors import ImucalError
from imucal.mag.evidence import MagRows, dip_rows, norm_rows, sample_variance, shift, windows
from imucal.mag.frame import SIGNED_PERMUTATIONS
from imucal.mag.model import DIP, NAMES, NORM, build_mag_model, mag_parameters, rotation, vectorized
from imucal.mag.units import field_magnitude
from imucal.model.sensor import build_model

AK8963 = (0, 1, 0, 1, 0, 0, 0, 0, -1)  #: mx = ay, my = ax, mz = -az (a 180 deg rotation)


def _params(rng: np.random.Generator) -> np.ndarray:
    v = {"s1": 0.3, "s2": -0.2, "s3": 0.1, "b1": 1.1, "b2": 0.9, "b3": 1.05, "phi": 1.62, "psi": 1.52,
         "theta": 1.6, "rx": 0.4, "ry": -0.7, "rz": 1.2, "F": 0.48, "dip": -0.9}
    return np.array([v[n] * (1 + 0.01 * rng.normal()) for n in NAMES])


def test_apply_inverts_forward_for_every_mounting():
    rng = np.random.default_rng(1)
    p = _params(rng)
    h = rng.normal(size=(50, 3))
    for axes in SIGNED_PERMUTATIONS:
        m = build_mag_model(axes)
        raw = vectorized(m, "forward")(h.T, p)[0]
        back = vectorized(m, "field")(raw, p)[0].T
        assert np.max(np.abs(back - h)) < 1e-12


def test_generated_numpy_equals_casadi():
    rng = np.random.default_rng(2)
    m, p = build_mag_model(AK8963), _params(rng)
    raw, a = rng.normal(size=(3, 20)), rng.normal(size=(3, 20))
    cov = np.vstack([np.r_[np.zeros(10), np.ones(10)], a])
    vec = vectorized(m, "residual")(raw, cov, p, [0.0])[0][0]
    one = [float(m.residual(raw[:, k], cov[:, k], p, 0.0)) for k in range(20)]
    assert np.allclose(vec, one, rtol=0, atol=1e-14)


def test_field_norm_is_the_accelerometers_residual_with_F_for_g():
    """|h| - F of the magnetometer and |a| - g of the accelerometer are one formula (Proposition 2)."""
    rng = np.random.default_rng(3)
    p = _params(rng)
    mag, acc = build_mag_model(AK8963), build_model()
    for _ in range(10):
        raw = rng.normal(size=3)
        r_mag = float(mag.residual(raw, [NORM, 0, 0, 0], p, 0.0))
        r_acc = float(acc.residual(raw, [], p[:9], p[NAMES.index("F")]))
        assert r_mag == pytest.approx(r_acc, abs=1e-13)


def test_dip_residual_against_an_independent_formula():
    rng = np.random.default_rng(4)
    m, p = build_mag_model(AK8963), _params(rng)
    raw, a = rng.normal(size=3), rng.normal(size=3)
    h = np.asarray(m.field(raw, p)).ravel()
    want = math.asin(a @ h / (np.linalg.norm(a) * np.linalg.norm(h))) - p[NAMES.index("dip")]
    assert float(m.residual(raw, [DIP, *a], p, 0.0)) == pytest.approx(want, abs=1e-13)


def test_rotation_is_exact_at_large_angles():
    """Rz Ry Rx built from the exact trigonometry: orthonormal and equal to the product of the three."""
    rx, ry, rz = 1.1, -0.6, 2.5
    R = np.asarray(rotation(rx, ry, rz))
    c, s = math.cos, math.sin
    Rx = np.array([[1, 0, 0], [0, c(rx), -s(rx)], [0, s(rx), c(rx)]])
    Ry = np.array([[c(ry), 0, s(ry)], [0, 1, 0], [-s(ry), 0, c(ry)]])
    Rz = np.array([[c(rz), -s(rz), 0], [s(rz), c(rz), 0], [0, 0, 1]])
    assert np.allclose(R, Rz @ Ry @ Rx, atol=1e-15)
    assert np.allclose(R @ R.T, np.eye(3), atol=1e-15)


def test_noise_is_the_propagated_scatter():
    """A row's sigma is |dr/draw| sigma_raw and |dr/da| sigma_acc: checked by finite differences."""
    rng = np.random.default_rng(5)
    m, p = build_mag_model(AK8963), _params(rng)
    raw, a = rng.normal(size=3), rng.normal(size=3)
    var_r, var_a = np.array([1e-4, 2e-4, 3e-4]), np.array([4e-4, 5e-4, 6e-4])
    cov = np.r_[DIP, a]
    eps = 1e-6

    def grad(f, x):
        return np.array([(f(x + eps * e) - f(x - eps * e)) / (2 * eps) for e in np.eye(3)])

    gr = grad(lambda x: float(m.residual(x, cov, p, 0.0)), raw)
    ga = grad(lambda x: float(m.residual(raw, np.r_[DIP, x], p, 0.0)), a)
    want = math.sqrt(gr**2 @ var_r + ga**2 @ var_a)
    assert float(m.noise(raw, cov, p, 0.0, var_r, var_a)) == pytest.approx(want, rel=1e-6)


def test_improper_axes_refused():
    with pytest.raises(ImucalError) as e:
        build_mag_model((1, 0, 0, 0, 1, 0, 0, 0, -1))
    assert "not a proper signed permutation" in str(e.value) and "mag.axes" in str(e.value)


def test_parameters_carry_units_and_the_field():
    p = mag_parameters([0.1, 0.2, 0.3], [1, 1, 1], field_magnitude=0.45, raw_unit="gauss", field_unit="gauss")
    assert p.names == NAMES
    assert p["b1"].unit == "gauss/gauss" and p["s1"].unit == "gauss" and p["F"].unit == "gauss"
    assert p["s1"].scale == pytest.approx(0.45)  # one field's worth of raw output
    assert p["rx"].unit == "rad" and p["dip"].lower == pytest.approx(-math.pi / 2)


@pytest.mark.parametrize("value, unit, sensor, want", [
    (48.0, "uT", "gauss", (0.48, "gauss")), (48000.0, "nT", "uT", (48.0, "uT")), (480.0, "mG", "gauss", (0.48, "gauss")),
    (48.0, "uT", "counts", (48.0, "uT")), (0.48, None, "gauss", (0.48, "gauss")), (600.0, None, "counts", (600.0, "counts"))])
def test_field_magnitude_in_any_unit(value, unit, sensor, want):
    F, u = field_magnitude(value, unit, sensor)
    assert F == pytest.approx(want[0]) and u == want[1]


def test_field_magnitude_refuses_a_unit_mixup():
    with pytest.raises(ImucalError) as e:
        field_magnitude(48000.0, "uT", "gauss", source="run.yaml")
    msg = str(e.value)
    assert msg.startswith("run.yaml: mag.field: field magnitude 48000 uT") and "check the unit" in msg


def test_sample_variance_of_a_moving_log():
    """The second difference sees the white noise, not a smooth motion."""
    rng = np.random.default_rng(6)
    t = np.arange(20000)
    smooth = np.column_stack([np.sin(t / 300.0), np.cos(t / 170.0), np.sin(t / 90.0 + 1)])
    sigma = np.array([0.002, 0.003, 0.004])
    var = sample_variance(smooth + rng.normal(size=smooth.shape) * sigma)
    assert np.allclose(np.sqrt(var), sigma, rtol=0.05)


def test_rows_and_shift():
    raw = np.arange(30.0).reshape(10, 3)
    acc = np.ones((10, 3))
    rows = MagRows.stack(norm_rows(raw, np.ones(3)), dip_rows(raw, acc, windows(10, 5), np.ones(3), np.ones(3)))
    assert rows.count(NORM) == 10 and rows.count(DIP) == 2
    assert np.allclose(rows.raw[10], raw[:5].mean(axis=0)) and np.allclose(rows.var_raw[10], 0.2)
    assert np.allclose(shift(raw, 1.0)[:-1], raw[1:]) and np.allclose(shift(raw, 0.5)[0], raw[:2].mean(axis=0))


def test_reader_takes_mx_my_mz_by_default(tmp_path):
    from imucal.data.load import DataSpec, load_recording
    from imucal.model.channels import MAGNETIC_FIELD, require

    path = tmp_path / "log.csv"
    path.write_text("ax,ay,az,mx,my,mz\n" + "".join(f"0,0,1,{k},{2 * k},{3 * k}\n" for k in range(5)))
    rec = load_recording(DataSpec(path=str(path), sample_rate=25.0))
    assert np.array_equal(rec.mag[:, 1], 2 * np.arange(5.0)) and MAGNETIC_FIELD in rec.channels
    plain = tmp_path / "plain.csv"
    plain.write_text("ax,ay,az\n" + "0,0,1\n" * 5)
    with pytest.raises(ImucalError) as e:
        require((MAGNETIC_FIELD,), load_recording(DataSpec(path=str(plain), sample_rate=25.0)).channels,
                source=str(plain), what="the magnetometer")
    assert str(e.value) == (f"{plain}: data.columns.mx: the magnetometer reads magnetic field but the data have no mx "
                            "column (fix: add mx/my/mz (raw) or drop what needs magnetic_field)")


def test_reader_refuses_part_of_the_magnetometer(tmp_path):
    from imucal.data.load import DataSpec, load_recording

    path = tmp_path / "log.csv"
    path.write_text("ax,ay,az,mx,my\n" + "0,0,1,1,2\n" * 5)
    with pytest.raises(ImucalError) as e:
        load_recording(DataSpec(path=str(path), sample_rate=25.0))
    assert str(e.value) == (f"{path}: data.columns: only mx, my of mx, my, mz mapped "
                            "(fix: map all three magnetometer columns or none)")


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(-1.3, 1.3), min_size=3, max_size=3), st.sampled_from(SIGNED_PERMUTATIONS))
def test_field_norm_does_not_see_the_rotation(r, axes):
    """Property: |h| - F is invariant under the rotation to the accelerometer's frame and the mounting
    (only the DIP rows determine them)."""
    rng = np.random.default_rng(8)
    p = _params(rng)
    raw = rng.normal(size=(3, 6))
    cov = np.zeros((4, 6))
    base = vectorized(build_mag_model(), "residual")(raw, cov, p, [0.0])[0]
    q = p.copy()
    q[[NAMES.index(n) for n in ("rx", "ry", "rz")]] = r
    turned = vectorized(build_mag_model(axes), "residual")(raw, cov, q, [0.0])[0]
    assert np.allclose(turned, base, rtol=0, atol=1e-12)
