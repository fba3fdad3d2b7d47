"""A record made directly is checked as ``from_arrays`` checks it; a missing mass is said, not silent; SINDy's
seed is scikit-learn's ``random_state`` (an integer, None or a numpy Generator)."""

import warnings

import numpy as np
import pytest

from negstiff import from_arrays
from negstiff.errors import InputError
from negstiff.inference.estimators.sindy import SINDy
from negstiff.inference.record.measurement import Measurement

FS = 512.0


def _hardening_oscillator(duration: float = 30.0, seed: int = 7):
    """(base_acc, z) of a hardening Duffing oscillator per unit mass (9 Hz, 3 %, z^3 coefficient 2e6 1/(m^2 s^2))
    under white base acceleration (3 m/s^2 rms, held over each sample), hand-written RK4 at 8x the sampling rate,
    with a 1 um displacement sensor's noise and a 0.5 mm zero offset."""
    rng = np.random.default_rng(seed)
    n, sub = int(duration * FS), 8
    a = 3.0 * rng.standard_normal(n)
    wn, zeta, k3 = 2 * np.pi * 9.0, 0.03, 2e6
    h = 1 / (FS * sub)

    def f(x, ak):
        return np.array([x[1], -ak - 2 * zeta * wn * x[1] - wn**2 * x[0] - k3 * x[0] ** 3])

    x, z = np.zeros(2), np.empty(n)
    for i in range(n):
        z[i] = x[0]
        for _ in range(sub):
            k1 = f(x, a[i])
            k2 = f(x + h / 2 * k1, a[i])
            k3_ = f(x + h / 2 * k2, a[i])
            k4 = f(x + h * k3_, a[i])
            x = x + h / 6 * (k1 + 2 * k2 + 2 * k3_ + k4)
    return a, z + 5e-4 + 1e-6 * rng.standard_normal(n)


# --- a Measurement made directly ------------------------------------------------------------------------------
def _columns(n: int = 1024):
    t = np.arange(n) / FS
    return np.sin(2 * np.pi * 9 * t), 1e-3 * np.sin(2 * np.pi * 9 * t - 0.3)


@pytest.mark.parametrize(
    "change",
    [
        {"fs": -512.0},
        {"fs": 0.0},
        {"fs": float("nan")},
        {"input_name": "voltage"},
        {"u": np.r_[_columns()[0][:-1], np.nan]},
        {"z": np.r_[_columns()[1][:-1], np.inf]},
        {"z": _columns()[1][:-5]},
        {"u": np.zeros(1), "z": np.zeros(1)},
        {"u": _columns()[0] + 1j},
        {"z": 1e7 * _columns()[1]},  # 10,000 km: not a record in metres
        {"mass": -0.2},
        {"mass": True},
        {"z_dot": np.ones(3)},
        {"aux": {"volt": np.r_[np.ones(1023), np.nan]}},
    ],
    ids=lambda c: ",".join(c),
)
def test_a_measurement_made_directly_is_checked_as_from_arrays_checks_it(change):
    # the arrays a constructor is given are the same record as from_arrays's: one InputError naming the problem,
    # never numpy's or scipy's error later
    u, z = _columns()
    kw = {"fs": FS, "input_name": "base_acc", "u": u, "z": z, **change}
    with pytest.raises(InputError):
        Measurement(**kw)


def test_a_measurement_made_directly_from_lists_is_the_from_arrays_record():
    u, z = _columns()
    rec = Measurement(FS, "base_acc", list(u), list(z), mass=0.2)
    ref = from_arrays(u, z, FS, mass=0.2)
    assert isinstance(rec.u, np.ndarray) and rec.n == ref.n and rec.mass == ref.mass
    assert np.array_equal(rec.z, ref.z)


# --- the mass, and SINDy's seed ---------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def duffing():
    return _hardening_oscillator()


def test_missing_mass_warns_and_a_generator_seeds_sindy(duffing):
    # without a mass, a base-excited record's coefficients are per unit mass (the contract allows it): the result
    # says so (mass_normalised) and warns, in its warnings and through Python's warnings; a numpy Generator seeds
    # the bagging ensemble with its next draw, which the fit records
    a, z = duffing
    rec = from_arrays(a, z, FS)
    with pytest.warns(UserWarning, match="per unit mass"):
        est = SINDy(seed=np.random.default_rng(11), n_models=10, refine=False).fit(rec)
    res = est.result()
    assert res["mass_normalised"] is True
    assert any("per unit mass" in w for w in res["warnings"])
    assert isinstance(est.seed_, int) and res["settings"]["seed"] == est.seed_

    # the integer it drew gives the same ensemble; with the mass given, no per-unit-mass warning, and every
    # coefficient is the per-unit-mass one times the mass (the same weak-form fit, scaled)
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        again = SINDy(seed=est.seed_, n_models=10, refine=False).fit(from_arrays(a, z, FS, mass=0.2))
    assert not any("per unit mass" in str(w.message) for w in seen)
    assert again.result()["mass_normalised"] is False
    assert again.selected_ == est.selected_
    for term, e in est.ensemble_.items():
        assert again.ensemble_[term]["inclusion_probability"] == pytest.approx(e["inclusion_probability"], abs=1e-12)
    assert again.model_.k3 == pytest.approx(0.2 * est.model_.k3, rel=1e-6)


@pytest.mark.parametrize("seed", [None, -1, 1.5, "3"], ids=["none", "negative", "float", "text"])
def test_sindy_seed_takes_what_random_state_takes(seed):
    # None is fresh entropy (accepted); a negative, a fraction or a string is one InputError before any work
    est = SINDy(seed=seed)
    if seed is None:
        est._validate_params()
    else:
        with pytest.raises(InputError):
            est._validate_params()
