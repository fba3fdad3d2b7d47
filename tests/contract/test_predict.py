"""Every identification predicts a record (restarted free runs from its measured states), scores it (the
median window's error, named), simulates any input and prints its equation; and the method-vs-method
check compares each method's own estimate within their standard errors.

Records: the tests' cubic double well (``records.TRUTH``) under band-limited random base acceleration, a
plain numpy RK4 written in the tests, with white noise on the laser (z) and on the table's accelerometer.
"""

import math
import warnings

import numpy as np
import pytest
from records import FS, TRUTH, rk4_random_records

from negstiff import NSI, Discrepancy, SINDy, from_arrays
from negstiff.errors import InputError
from negstiff.inference.estimators.prediction import SCORE_METRIC, restarted_runs, window_errors
from negstiff.testing import assert_methods_agree

LASER = 3e-6  # [m] rms white noise on z


@pytest.fixture(scope="module")
def record():
    ((u, z),) = rk4_random_records([21], duration=30.0, laser=LASER)
    return from_arrays(u, z, FS, mass=TRUTH.m, source="rk4 record")


@pytest.fixture(scope="module")
def fitted(record):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fits = {"nsi": NSI().fit(record), "sindy": SINDy().fit(record)}
        return fits | {"discrepancy": Discrepancy(max_effects=0).fit(record)}


@pytest.mark.parametrize("name", ["nsi", "sindy", "discrepancy"])
def test_predict_restarts_from_the_measured_states_and_scores_near_the_truth(fitted, record, name):
    est = fitted[name]
    pred = est.predict(record, window_s=0.5)
    w = int(0.5 * FS)
    assert pred.z.shape == pred.measured.shape == (record.n // w, w)
    # each window starts at the record's smoothed state: within a few laser sd of the measured z
    assert np.all(np.abs(pred.z[:, 0] - pred.measured[:, 0]) < 5 * LASER)
    # the score is the median window's error, named; a model within ppm of the truth scores as the truth does,
    # within the spread the record's noise gives each window (a factor 2 on the median, measured ~1.0)
    truth = restarted_runs(TRUTH, record, 0.5)
    assert pred.metric == SCORE_METRIC and "median" in SCORE_METRIC
    assert est.score(record, window_s=0.5) == pred.score_percent
    if name == "discrepancy":  # its baseline (cubic K, viscous c) lacks the truth's z'|z'| damping: worse
        assert truth.score_percent < pred.score_percent < 100
    else:
        assert pred.score_percent <= 2 * truth.score_percent + 0.05
    lo, hi = pred.errors["window_percent_quartiles"]
    assert lo <= pred.score_percent <= hi


def test_the_headline_is_the_median_window_and_one_well_switch_moves_it_one_rank_at_most():
    # six 2 s windows: five at the noise floor, one that switched wells (50x): the pooled rms moves ~20x, the
    # median not at all beyond the next window's rank
    rng = np.random.default_rng(3)
    z = 0.02 * rng.standard_normal(6000)
    ms = (1e-4 * np.array([1.0, 1.1, 0.9, 1.05, 0.95, 1.0]) * 0.02) ** 2
    calm = window_errors(ms, z)
    switched = ms.copy()
    switched[2] *= 50**2
    hit = window_errors(switched, z)
    assert hit["median_window_percent"] <= 1.1 * calm["median_window_percent"]
    assert hit["worst_window_percent"] >= 40 * calm["worst_window_percent"]  # the spread shows it
    pooled = lambda m: math.sqrt(np.mean(m))  # noqa: E731
    assert pooled(switched) > 15 * pooled(ms)


@pytest.mark.parametrize("name", ["nsi", "sindy"])
def test_the_fit_reports_the_median_window_with_its_spread(fitted, name):
    v = fitted[name].validation_
    assert v["windows_scored"] == v["restart_windows"]
    assert v["window_percent_quartiles"][0] <= v["median_window_percent"] <= v["window_percent_quartiles"][1]
    assert "median window" in repr(fitted[name])


def test_simulate_from_a_record_and_from_arrays(fitted, record):
    est = fitted["sindy"]
    run = est.simulate(record)
    zs, _, _, _ = record.states("state")
    assert run.z.shape[-1] == record.n and abs(run.z[0, 0] - zs[0]) < 1e-12  # starts at the measured state
    arr = est.simulate(record.u[:1000], fs=FS, z0=0.02)
    assert arr.z.shape[-1] == 1000 and not arr.diverged[0]
    with pytest.raises(InputError):
        est.simulate(record.u[:1000])  # an array needs its rate


def test_equations_print_the_learned_coefficients(fitted, capsys):
    est = fitted["nsi"]
    (line,) = est.equations()
    m = est.model_
    assert f"{m.k3:.4g} z^3" in line and line.endswith(f"= -{m.m:.4g} base_acc")
    est.print()
    assert capsys.readouterr().out.strip() == line


@pytest.fixture(scope="module")
def noisy():
    # ten times the laser's and the accelerometer's noise: the methods' own estimates differ measurably
    ((u, z),) = rk4_random_records([5], duration=80.0, laser=3e-5, table_noise=0.05)
    return u, z


def test_methods_own_estimates_agree_within_their_standard_errors_and_a_bias_is_caught(noisy):
    u, z = noisy
    rec = from_arrays(u, z, FS, mass=TRUTH.m, source="noisy")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        nsi, sindy = NSI().fit(rec), SINDy().fit(rec)
        own_nsi, own_sindy = nsi.own_estimate(rec), sindy.own_estimate(rec)
    # modal_ is each method's own estimate (NSI's pole, SINDy's equation-error model), not the refined model's
    assert nsi.modal_["minus"]["f_hz"] == own_nsi["modal"]["minus"]["f_hz"]
    assert sindy.modal_["minus"]["f_hz"] == pytest.approx(sindy.initial_model_.uls("minus").f_hz, rel=1e-9)
    diff = abs(nsi.modal_["minus"]["f_hz"] - sindy.modal_["minus"]["f_hz"])
    assert diff > 1e-6 * sindy.modal_["minus"]["f_hz"]  # they differ, measurably
    assert_methods_agree(own_nsi, own_sindy, k=3)
    # a lab's mislabelled sampling rate (3 % high) biases SINDy's frequencies by 3 %: caught
    biased = from_arrays(u, z, FS * 1.03, mass=TRUTH.m, source="noisy, fs mislabelled")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sindy_b = SINDy().fit(biased)
        own_b = sindy_b.own_estimate(biased)
    with pytest.raises(AssertionError, match="own frequencies"):
        assert_methods_agree(own_nsi, own_b, k=3)
