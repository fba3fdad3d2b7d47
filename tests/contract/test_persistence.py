"""Fitted estimators and results are kept: pickled (and by joblib) whole, and through their JSON
(``to_json`` -> ``from_json``), each giving back the same ``result()``; a posterior's arviz data, its draws and
its provenance through NetCDF.

The record: the tests' cubic double well (``records.TRUTH``) under band-limited random base acceleration,
a plain numpy RK4 written in the tests, with a laser's 3 um and an accelerometer's 5 mm/s^2 of white noise.
Keeping a result is exact (the same numbers), so the checks compare the JSON texts, not within a tolerance.
"""

import json
import pickle
import subprocess
import sys
import warnings

import joblib
import numpy as np
import pytest
from records import FS, TRUTH, rk4_random_records

from negstiff import NSI, Posterior, SINDy, from_arrays
from negstiff.inference.estimators.identification import Identification
from negstiff.inference.estimators.posterior import PosteriorResult


def text(d) -> str:
    """A result JSON as canonical text (arrays and numpy numbers as JSON's)."""
    return json.dumps(d, sort_keys=True, default=lambda o: o.tolist() if hasattr(o, "tolist") else str(o))


@pytest.fixture(scope="module")
def record():
    ((u, z),) = rk4_random_records([11], duration=30.0)
    return from_arrays(u, z, FS, mass=TRUTH.m, source="scipy-free rk4 record")


@pytest.fixture(scope="module")
def fits(record):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return {"nsi": NSI().fit(record), "sindy": SINDy().fit(record)}


@pytest.fixture(scope="module")
def posterior(record):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a short chain: not converged, said in the result
        return Posterior(seed=1, n_ensembles=2, min_steps=40, max_steps=80, chunk=40, max_windows=32).fit(record)


@pytest.mark.parametrize("name", ["nsi", "sindy"])
def test_identification_pickles_and_round_trips_its_json(fits, name, tmp_path):
    # keeping a fit changes nothing it learned: pickle, joblib and the JSON give back the same result
    est = fits[name]
    for back in (pickle.loads(pickle.dumps(est)), joblib.load(joblib.dump(est, tmp_path / "est.joblib")[0])):
        assert text(back.result()) == text(est.result())
        assert back.model_ == est.model_
        assert np.array_equal(back.validation_["window_ms"], est.validation_["window_ms"], equal_nan=True)
    path = tmp_path / "est.json"
    path.write_text(text(est.to_json()))
    for source in (est.to_json(), text(est.to_json()), path):
        back = type(est).from_json(source)
        assert back.fitted and back.model_ == est.model_
        assert text(back.to_json()) == text(est.to_json())
        if isinstance(est, SINDy):  # the terms it selected and its ensemble come back with it
            assert back.selected_ == est.selected_ and back.ensemble_ == est.ensemble_
    assert est.to_json()["estimator"]["class"] == type(est).__name__
    # the result object alone, both ways
    res = est.result_
    assert text(pickle.loads(pickle.dumps(res)).to_json()) == text(res.to_json())
    assert text(Identification.from_json(res.to_json()).to_json()) == text(res.to_json())


def test_a_command_line_result_without_the_estimator_key_is_read(fits):
    # what `negstiff identify` wrote (result() alone) rebuilds an estimator with the default parameters
    est = fits["nsi"]
    back = NSI.from_json(est.result())
    assert text(back.result()) == text(est.result())
    with pytest.raises(Exception, match="SINDy's, not a NSI's"):
        NSI.from_json(fits["sindy"].to_json())


def test_a_fitted_posterior_pickles_with_its_arviz_data(posterior):
    # the arviz data was never asked for before pickling, and is there after (its builder travels along)
    back = pickle.loads(pickle.dumps(posterior))
    assert text(back.result()) == text(posterior.result())
    tree = back.result_.idata
    assert tree is not None and "posterior" in tree.children
    assert tree["posterior"].dataset["k3"].dims == ("chain", "draw")
    assert tree.attrs["record_source"] == "scipy-free rk4 record" and tree.attrs["negstiff_version"]
    assert json.loads(tree.attrs["settings_json"])["seed"] == 1
    res = pickle.loads(pickle.dumps(posterior.result_))
    assert res.idata is not None


def test_a_posterior_round_trips_its_json_and_its_netcdf(posterior, tmp_path):
    back = Posterior.from_json(posterior.to_json())
    assert text(back.to_json()) == text(posterior.to_json())
    assert back.model_ == posterior.model_
    path = tmp_path / "post.nc"
    posterior.result_.to_netcdf(path)
    res = PosteriorResult.from_netcdf(path)
    assert np.array_equal(res.samples, posterior.result_.samples)  # (ensemble, step, walker, parameter)
    assert res.summary == posterior.result_.summary and res.names == posterior.result_.names
    assert res.provenance["record_source"] == "scipy-free rk4 record"
    assert set(res.idata.children) >= {"posterior", "log_likelihood", "observed_data"}
    assert "negstiff_run" not in res.idata.children


def test_posterior_model_is_the_posterior_mean(posterior):
    # model_ after a fit: the coefficients' posterior means with the record's mass
    s = posterior.result_.summary
    assert posterior.model_.m == TRUTH.m
    assert posterior.model_.k3 == s["k3"]["mean"] and posterior.model_.c == s["c"]["mean"]


def test_a_pickled_fit_reloads_in_a_new_process(fits, tmp_path):
    # what a cache or a dask worker does: pickle here, load in another interpreter, the same result
    path = tmp_path / "sindy.pkl"
    path.write_bytes(pickle.dumps(fits["sindy"]))
    code = f"import pickle, json; e = pickle.load(open({str(path)!r}, 'rb')); print(json.dumps(e.result()['model']))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert json.loads(out) == json.loads(text(fits["sindy"].result()["model"]))


def test_ga_updater_pickles_and_round_trips(tmp_path):
    from negstiff import GAUpdater

    targets = {"f_minus": 11.45, "f_plus": 9.20, "z_minus": -0.0287, "z_plus": 0.0228}
    ga = GAUpdater(fixed_mass=0.212, generations=4, pop_size=8, seed=2).fit(targets)
    assert text(pickle.loads(pickle.dumps(ga)).result()) == text(ga.result())
    back = GAUpdater.from_json(text(ga.to_json()))
    assert text(back.to_json()) == text(ga.to_json())
    assert back.device_.E == ga.device_.E


def test_discrepancy_pickles_and_round_trips(record):
    from negstiff import Discrepancy

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        disc = Discrepancy(max_effects=1).fit(record)
    back = pickle.loads(pickle.dumps(disc))
    assert text(back.result()) == text(disc.result())
    back = Discrepancy.from_json(disc.to_json())
    assert text(back.to_json()) == text(disc.to_json())
    assert back.fitted and back.model_ == disc.model_


def test_seed_takes_none_an_integer_or_a_generator():
    # scikit-learn's random_state: a Generator's next draw seeds the run, and the integer used is recorded
    from negstiff import GAUpdater
    from negstiff.errors import InputError

    targets = {"f_minus": 11.45, "f_plus": 9.20, "z_minus": -0.0287, "z_plus": 0.0228}
    runs = [GAUpdater(fixed_mass=0.212, generations=2, pop_size=8, seed=s).fit(targets)
            for s in (5, None, np.random.default_rng(1), np.random.default_rng(1))]  # fmt: skip
    seeds = [r.result()["settings"]["seed"] for r in runs]
    assert seeds[0] == 5 and isinstance(seeds[1], int) and seeds[2] == seeds[3]
    assert runs[2].device_.E == runs[3].device_.E  # the same generator state, the same run
    with pytest.raises(InputError, match="Generator"):
        GAUpdater(seed=-1).fit(targets)


def test_models_drawn_from_a_posterior_carry_its_draws_and_its_seed(posterior):
    # each drawn model is the posterior mean's model (its mass) with one draw's coefficients: their
    # spread is the posterior's, the same seed draws the same models, and a fit rebuilt from its JSON (no draws)
    # says so in one error
    from negstiff import InputError

    draws = posterior.draw_models(40, seed=3)
    assert len(draws) == 40 and all(d.m == posterior.model_.m for d in draws)
    k3 = np.array([d.k3 for d in draws])
    s = posterior.result()["parameters"]["k3"]
    # 40 draws of correlated chains (a short run's): their mean within one posterior sd of the posterior's (a
    # standard error of sd / 6 for independent draws, a few times that for these), their sd within a factor 2
    assert abs(k3.mean() - s["mean"]) < s["sd"] and 0.5 < k3.std() / s["sd"] < 2
    assert [d.k3 for d in posterior.draw_models(40, seed=3)] == list(k3)
    with pytest.raises(InputError, match="holds no draws"):
        Posterior.from_json(json.dumps(posterior.to_json())).draw_models(5)
    with pytest.raises(InputError, match="n must be"):
        posterior.draw_models(0)


def test_an_nsi_pickled_before_its_basis_moved_still_loads(fits):
    # NSI's law basis moved from the NSI module to the laws (``laws.FeedbackBasis``); a fit pickled before names
    # the old place: it loads, its basis and result the same
    old = pickle.dumps(fits["nsi"], protocol=0)
    assert b"cnegstiff.models.laws\nFeedbackBasis\n" in old
    old = old.replace(b"cnegstiff.models.laws\nFeedbackBasis\n", b"cnegstiff.inference.estimators.nsi\nBasis\n")
    back = pickle.loads(old)
    assert back.basis_ == fits["nsi"].basis_
    assert text(back.result()) == text(fits["nsi"].result())


def test_a_cached_fit_that_no_longer_loads_is_refitted(fits, record, tmp_path, monkeypatch):
    # negstiff.testing.cached_fit: a kept pickle that does not load (an older negstiff's, or cut short) is refitted
    # and replaced, never an error in the user's test session
    from negstiff.testing import cached_fit

    made = []

    def fit(self, data):
        made.append(1)
        return fits["nsi"]

    monkeypatch.setattr(NSI, "fit", fit)
    cached_fit(NSI(), record, tmp_path)
    (kept,) = tmp_path.glob("NSI-*.pkl")
    kept.write_bytes(b"\x80\x05not a pickle")
    again = cached_fit(NSI(), record, tmp_path)
    assert len(made) == 2 and text(again.result()) == text(fits["nsi"].result())
    assert text(pickle.loads(kept.read_bytes()).result()) == text(fits["nsi"].result())
