"""The physically-based device model (device-model.md)."""

import numpy as np
import pytest

from negstiff.experiments import seed
from negstiff.models import AS_BUILT, NOMINAL, GeometryError


def _central_derivatives(f, h):
    """First, second and third derivatives at 0 by central differences (truncation O(h^2))."""
    k = f(np.array([-2 * h, -h, 0.0, h, 2 * h]))
    return ((k[3] - k[1]) / (2 * h), (k[3] - 2 * k[2] + k[1]) / h**2, (k[4] - 2 * k[3] + 2 * k[1] - k[0]) / (2 * h**3))


def test_closed_form_taylor_cubic_matches_a_finite_difference_expansion():
    # Finite differences of the exact K(z) only (no analytic derivative), Richardson-extrapolated
    # from h and 2h: truncation O((h/L)^4) ~ 1e-7 at h = 1 mm, L = 60 mm; rounding of the third
    # difference ~ eps K / h^3 ~ 1e-12 relative. Tolerance 1e-5 leaves room for the O(h^4) constant.
    def exact(z):
        return AS_BUILT.restoring_force(z, include_extra=False)

    h = 1e-3
    d_h, d_2h = _central_derivatives(exact, h), _central_derivatives(exact, 2 * h)
    d1, d2, d3 = ((4 * a - b) / 3 for a, b in zip(d_h, d_2h, strict=False))
    cubic = AS_BUILT.taylor_cubic()
    assert -cubic.k1 == pytest.approx(d1, rel=1e-5)
    assert cubic.k2 == pytest.approx(d2 / 2, rel=1e-5)
    assert cubic.k3 == pytest.approx(d3 / 6, rel=1e-5)
    assert cubic.k0 == pytest.approx(float(exact(np.array([0.0]))[0]), rel=1e-12)


def test_equilibria_zero_the_exact_restoring_force_with_stable_outer_wells():
    for dev in (NOMINAL, AS_BUILT):
        eq = dev.equilibria()
        zs = np.array([eq.z_minus, eq.z_0, eq.z_plus])
        assert np.all(np.abs(dev.restoring_force(zs)) < 1e-9)
        ks = dev.stiffness(zs)
        assert ks[0] > 0 and ks[1] < 0 and ks[2] > 0


def test_analytic_stiffness_is_the_derivative_of_the_restoring_force():
    z = np.linspace(-0.04, 0.035, 31)
    h = 1e-6
    num = (AS_BUILT.restoring_force(z + h) - AS_BUILT.restoring_force(z - h)) / (2 * h)
    assert np.allclose(AS_BUILT.stiffness(z), num, rtol=1e-5, atol=1e-3)


def test_as_built_device_is_calibrated_to_the_seed_headline_figures():
    # The calibration solved three equations (two frequencies, z_plus) in E and alpha with the
    # fixed geometry rounded to 0.1 mm and E, alpha rounded: within 1 % of the seed's numbers.
    f = AS_BUILT.features()
    assert f["f_minus"] == pytest.approx(seed.TABLE1["minus"]["f_hz"], rel=0.01)
    assert f["f_plus"] == pytest.approx(seed.TABLE1["plus"]["f_hz"], rel=0.01)
    assert f["z_plus"] == pytest.approx(seed.Z_PLUS, rel=0.01)


def test_features_depend_on_E_and_m_only_through_E_over_m():
    a = AS_BUILT.features()
    b = AS_BUILT.with_(E=AS_BUILT.E * 1.3, m=AS_BUILT.m * 1.3).features()
    for k in a:
        assert b[k] == pytest.approx(a[k], rel=1e-9)


def test_outside_the_stroke_the_model_says_so_instead_of_returning_nan():
    lo, hi = AS_BUILT.stroke_limits()
    with pytest.raises(GeometryError, match="outside the device's stroke"):
        AS_BUILT.restoring_force(hi + 1e-3)
    with pytest.raises(GeometryError):
        AS_BUILT.potential(np.array([0.0, lo - 1e-3]))


def test_least_squares_cubic_departs_from_taylor_model_form_gap():
    tay, lsq = AS_BUILT.taylor_cubic(), AS_BUILT.lsq_cubic()
    z = np.linspace(-0.03, 0.03, 301)
    exact = AS_BUILT.restoring_force(z)
    # the least-squares cubic fits the exact force over the stroke better than the Taylor cubic
    assert np.sqrt(np.mean((lsq.restoring_force(z) - exact) ** 2)) < np.sqrt(
        np.mean((tay.restoring_force(z) - exact) ** 2)
    )
    assert abs(lsq.k3 / tay.k3 - 1) > 0.2, "the two cubics differ by more than 20 % in k3 (device-model.md)"


def test_the_population_features_are_each_devices_own():
    # Fact: features_many (the GA's whole population at once: the same grid brackets, Newton from each
    # cell's secant point, bisection where Newton leaves its cell) gives every device's features() to
    # Brent's tolerance (1e-14 relative on a 30 mm root), and says "no double well" exactly where
    # features() has none. Devices inside the GA's bounds and far outside them (stiff, soft, steep).
    rng = np.random.default_rng(5)
    n = 200
    E = NOMINAL.E * np.concatenate([1 + 0.25 * rng.uniform(-1, 1, n), [0.05, 0.3, 3.0, 8.0]])
    alpha = np.concatenate([NOMINAL.alpha_deg + 5 * rng.uniform(-1, 1, n), [20.0, -5.0, 1.0, 40.0]])
    m = NOMINAL.m * np.concatenate([1 + 0.25 * rng.uniform(-1, 1, n), [0.5, 2.0, 1.0, 0.8]])
    with np.errstate(invalid="ignore", divide="ignore"):
        F, ok = NOMINAL.features_many(E, alpha, m)
    for i in range(E.size):
        try:
            d = NOMINAL.with_(E=E[i], alpha_deg=alpha[i], m=m[i]).features()
        except (ValueError, TypeError):  # no double well (a single well's features() has no z_minus)
            assert not ok[i], i
            continue
        assert ok[i], i
        ref = [d["f_minus"], d["f_plus"], d["z_minus"], d["z_plus"]]
        assert np.allclose(F[i], ref, rtol=1e-12, atol=0), (i, F[i], ref)
    # the bisection fallback on its own: x^3 - 2 on [1, 2] to the last representable point
    root = NOMINAL._bisect(
        lambda x, rows: x**3 - 2.0, np.array([0]), np.array([1.0]), np.array([2.0]), np.array([-1.0])
    )
    assert abs(root[0] - 2.0 ** (1 / 3)) <= 4 * np.spacing(2.0 ** (1 / 3))
    with pytest.raises(ValueError, match="extra effects"):
        NOMINAL.with_(extra={"end_stop": {"k": 1.0, "z": 0.01}}).features_many(E[:2], alpha[:2], m[:2])
