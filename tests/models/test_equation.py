"""The equation of motion (seed Eqs. 1-7) and the model file."""

import math

import numpy as np
import pytest

from negstiff.models import G, Model


def test_equilibria_zero_the_restoring_force_and_alternate_in_stability(cubic_model):
    eq = cubic_model.equilibria()
    zs = np.array([eq.z_minus, eq.z_0, eq.z_plus])
    assert eq.z_minus < eq.z_0 < eq.z_plus
    # K(z*) = 0 to rounding: compare with the force scale k1 * |z*|
    assert np.all(np.abs(cubic_model.restoring_force(zs)) < 1e-9 * cubic_model.k1 * np.abs(zs).max())
    k = cubic_model.stiffness(zs)
    assert k[0] > 0 and k[1] < 0 and k[2] > 0, "stable, unstable, stable"


def test_shifted_coefficients_follow_eq7_and_back_transform(cubic_model):
    for well in ("minus", "plus"):
        uls = cubic_model.uls(well)
        zs = uls.z_ref
        assert uls.k2_tilde == pytest.approx(cubic_model.k2 + 3 * cubic_model.k3 * zs)
        assert uls.k1_tilde == pytest.approx(3 * cubic_model.k3 * zs**2 + 2 * cubic_model.k2 * zs - cubic_model.k1)
        # Eq. (7): K(x + z*) equals the shifted cubic for any x
        x = np.linspace(-0.02, 0.02, 9)
        shifted = cubic_model.k3 * x**3 + uls.k2_tilde * x**2 + uls.k1_tilde * x
        assert np.allclose(cubic_model.restoring_force(x + zs), shifted, atol=1e-9)
        assert uls.f_hz == pytest.approx(math.sqrt(uls.k1_tilde / cubic_model.m) / (2 * math.pi))
        back = Model.from_shifted(zs, uls.k1_tilde, uls.k2_tilde, uls.k3, m=cubic_model.m)
        assert back.k1 == pytest.approx(cubic_model.k1, rel=1e-10)
        assert back.k2 == pytest.approx(cubic_model.k2, rel=1e-10)
        assert back.k0 == pytest.approx(cubic_model.k0, rel=1e-8)


def test_potential_is_the_integral_of_the_restoring_force(cubic_model):
    z = np.linspace(-0.03, 0.03, 2001)
    u_num = np.concatenate(
        [[0], np.cumsum(0.5 * (cubic_model.restoring_force(z[1:]) + cubic_model.restoring_force(z[:-1])) * np.diff(z))]
    )
    u = cubic_model.potential(z) - cubic_model.potential(z[0])
    assert np.max(np.abs(u - u_num)) < 1e-6 * np.ptp(u)


def test_model_json_round_trip_and_defaults():
    m = Model.from_dict({"m": 0.2, "k1": 426.0, "k2": -3060.0, "k3": 7.77e5})
    assert m.k0 == pytest.approx(0.2 * G) and m.c == 0 and dict(m.extra) == {}
    m2 = Model.from_dict({**m.to_dict(), "extra": {"coulomb_friction": 0.05, "end_stop": {"k": 2e4, "z": 0.035}}})
    assert Model.from_dict(m2.to_dict()) == m2


@pytest.mark.parametrize(
    "bad, message",
    [
        ({"m": 0.2, "k1": 1, "k2": 0}, "lacks k3"),
        ({"m": -1, "k1": 1, "k2": 0, "k3": 1}, "positive"),
        ({"m": 1, "k1": 1, "k2": 0, "k3": 1, "extra": {"magic": 1}}, "unknown extra effect"),
        ({"m": 1, "k1": 1, "k2": 0, "k3": 1, "bogus": 1}, "unknown fields"),
    ],
)
def test_bad_models_are_refused_with_a_clear_message(bad, message):
    with pytest.raises(ValueError, match=message):
        Model.from_dict(bad)


def test_extra_effects_add_their_forces():
    base = Model(m=1.0, k1=100.0, k2=0.0, k3=1e5, k0=0.0)
    fx = Model(
        m=1.0,
        k1=100.0,
        k2=0.0,
        k3=1e5,
        k0=0.0,
        extra={"quartic_stiffness": 2e6, "cubic_damping": 3.0, "end_stop": {"k": 1e4, "z": 0.02}},
    )
    z, v = np.array([0.01, 0.03]), np.array([0.5, -0.5])
    diff = fx.total_force(z, v) - base.total_force(z, v)
    expected = 2e6 * z**4 + 3.0 * v**3 + np.array([0.0, 1e4 * 0.01])
    assert np.allclose(diff, expected)
