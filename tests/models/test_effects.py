"""The effect registry (models/effects.py): one entry is an effect the whole suite knows.

A toy effect, a linear-in-|z| stiffness a |z| (an asymmetric spring no catalogue effect or base term
can mimic: |z| is not a polynomial), is registered here and nowhere else. The simulator must integrate
it as an independent scipy integrator does; the rig must hide it in its records; SINDy must select its
library term and size it; the discrepancy workflow must name it. Nothing outside this file and the
registry mentions it."""

import dataclasses
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from negstiff.inference.estimators.discrepancy import Discrepancy, catalogue
from negstiff.inference.estimators.sindy import SINDy
from negstiff.inference.record.measurement import from_arrays
from negstiff.inference.steps.weak import terms
from negstiff.models import SEED_LIKE_CROSS_WELL_RMS, SEED_LIKE_CUBIC, Model, effects, simulate
from negstiff.models.rig import Rig

TOY = effects.Effect("abs_stiffness", effects.Monomial(1, False), "N/m")
TOY_VALUE = 60.0
"""a [N/m]: 1.8 N at the 30 mm stroke, a few % of the restoring force there (the size of the
catalogue tests' hidden effects)."""


@pytest.fixture
def toy():
    with effects.registered(TOY):
        yield TOY


def test_the_registry_derives_the_model_the_library_and_the_catalogue(toy):
    assert "|z|" in terms() and "abs_stiffness" in catalogue()
    m = Model(**{**SEED_LIKE_CUBIC.to_dict(), "extra": {"abs_stiffness": TOY_VALUE}})
    z = np.linspace(-0.03, 0.03, 7)
    base = Model(**{**SEED_LIKE_CUBIC.to_dict(), "extra": {}})
    # the force is a |z|, its potential a z |z| / 2 (zero at 0, derivative the force)
    assert np.allclose(m.restoring_force(z) - base.restoring_force(z), TOY_VALUE * np.abs(z), rtol=1e-12, atol=1e-12)
    h = 1e-6
    du = (m.potential(z + h) - base.potential(z + h) - m.potential(z - h) + base.potential(z - h)) / (2 * h)
    assert np.allclose(du, TOY_VALUE * np.abs(z), rtol=1e-6, atol=TOY_VALUE * h)  # the kink: a h / 2 at 0
    assert Model.from_dict(m.to_dict()).extra["abs_stiffness"] == TOY_VALUE
    with pytest.raises(ValueError, match="already"):
        with effects.registered(TOY):
            pass
    # the toy's monomial has no fixed row: it gets the layout's last row, after the registry's own (z^6, z^7)
    assert m.kernel_params().size == effects.layout().size
    assert effects.layout().rows["abs_stiffness"] == (effects.layout().size - 1,)


def test_outside_the_block_the_effect_is_unknown():
    with pytest.raises(ValueError, match="unknown extra effect 'abs_stiffness'"):
        Model(m=1.0, k1=1.0, k2=0.0, k3=1.0, extra={"abs_stiffness": 1.0})
    assert "|z|" not in terms()


# a long study: a DOP853 reference at rtol 1e-10; the toy's SINDy and discrepancy test keeps it by default
@pytest.mark.slow
def test_the_simulator_integrates_the_toy_as_scipy_does(toy):
    """RK4 with 8 substeps against scipy's DOP853 at rtol 1e-10 on the same equation, written here:
    m z'' + c z' + c_nl z'|z'| + K(z) + a |z| = -m b'' with b'' linearly interpolated."""
    m = Model(**{**SEED_LIKE_CUBIC.to_dict(), "extra": {"abs_stiffness": TOY_VALUE}})
    fs, n = 512.0, 2048
    t = np.arange(n) / fs
    u = 6.0 * np.sin(2 * np.pi * 7.0 * t) + 3.0 * np.sin(2 * np.pi * 13.0 * t)
    z0 = m.equilibria().z_plus
    sim = simulate(m, u, 1 / fs, z0=z0, substeps=8).z[0]

    def rhs(tt, x):
        ub = np.interp(tt, t, u)
        k = ((m.k3 * x[0] + m.k2) * x[0] - m.k1) * x[0] + m.k0 + TOY_VALUE * abs(x[0])
        d = m.c * x[1] + m.c_nl * x[1] * abs(x[1])
        return [x[1], -ub - (k + d) / m.m]

    ref = solve_ivp(rhs, (0, t[-1]), [z0, 0.0], t_eval=t, method="DOP853", rtol=1e-10, atol=1e-13, max_step=1 / fs)
    # the toy's kink at z = 0 is not crossed here (in-well), so RK4's error is its smooth O(h^4): the
    # 7 and 13 Hz response, h = 1/4096 s, well below 1e-4 of the stroke
    err = np.max(np.abs(sim - ref.y[0]))
    assert err < 1e-4 * np.ptp(ref.y[0]), err
    # and the effect matters: without it the response differs by far more than that
    plain = simulate(Model(**{**m.to_dict(), "extra": {}}), u, 1 / fs, z0=z0, substeps=8).z[0]
    assert np.max(np.abs(plain[: n // 2] - ref.y[0][: n // 2])) > 100 * err


BASE = dataclasses.replace(SEED_LIKE_CUBIC, c_nl=0.0)
"""The discrepancy baseline's own form (cubic K, viscous c), as in the catalogue's tests."""


def _record(seed: int):
    r = Rig(BASE, effects={"abs_stiffness": TOY_VALUE}, seed=seed).random(duration=120.0, rms=SEED_LIKE_CROSS_WELL_RMS)
    assert r.truth["effects"] == {"abs_stiffness": TOY_VALUE}
    return from_arrays(r.columns["base_acc"], r.columns["z"], r.fs, mass=float(r.meta["mass"]), source="rig")


def test_sindy_and_the_discrepancy_workflow_find_the_toy_in_a_rig_record(toy):
    """At the rig's default sensor noise, the toy's 1.8 N at the stroke is identifiable: SINDy selects
    |z| and sizes it, the discrepancy workflow (cubic baseline) names it, within 20 % (the tolerance of
    the catalogue's own hidden-effect tests)."""
    rec = _record(seed=1)
    s = SINDy().fit(rec)
    assert "|z|" in s.selected_, s.selected_
    assert s.model_.extra["abs_stiffness"] == pytest.approx(TOY_VALUE, rel=0.2)
    d = Discrepancy().fit(rec).result()
    assert d["effects"] == ["abs_stiffness"], d["ranking"]
    assert d["effect_size"]["abs_stiffness"] == pytest.approx(TOY_VALUE, rel=0.2)
    assert d["gap_after_percent"] <= d["gap_before_percent"] / 2
    assert math.isfinite(d["gap_after_percent"])
