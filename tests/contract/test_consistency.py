"""Consistency checks (issue 9): the suite's methods, run on one rig record, agree with each other
within their own stated uncertainty. A disagreement fails with a message naming the methods and the
parameter."""

import dataclasses

import pytest

from negstiff.inference.estimators.discrepancy import Discrepancy
from negstiff.inference.estimators.nsi import NSI
from negstiff.inference.estimators.posterior import Posterior, result_json
from negstiff.inference.estimators.sindy import SINDy
from negstiff.inference.estimators.updating import GAUpdater, fitness, targets_from
from negstiff.inference.record.measurement import from_arrays
from negstiff.models import SEED_LIKE_CROSS_WELL_RMS, SEED_LIKE_CUBIC
from negstiff.models.rig import Rig

PARAMS = ("k1", "k2", "k3", "c", "c_nl")

# Each method's stated uncertainty (relative, one side): NSI and SINDy have no posterior of their own,
# so their issues' acceptance tolerances stand for it (NSI: issue 4, k3 3 %, k1 and k2 5 %, damping
# 15 %; SINDy: issue 6, k1-k3 5 %, c 15 %; c_nl 15 % for both); the posterior states 3 sd.
STATED = {
    "NSI": {"k1": 0.05, "k2": 0.05, "k3": 0.03, "c": 0.15, "c_nl": 0.15},
    "SINDy": {"k1": 0.05, "k2": 0.05, "k3": 0.05, "c": 0.15, "c_nl": 0.15},
}


@pytest.fixture(scope="module")
def record():
    r = Rig(SEED_LIKE_CUBIC, seed=31).random(duration=150, rms=SEED_LIKE_CROSS_WELL_RMS)
    return from_arrays(r.columns["base_acc"], r.columns["z"], r.fs, mass=float(r.meta["mass"]), source="rig")


@pytest.fixture(scope="module")
def estimates(record):
    nsi = NSI().fit(record)
    sindy = SINDy().fit(record)
    # two ensembles (four by default; CI time): R-hat still compares two, each converged by emcee's 50 tau rule
    post = Posterior(seed=1, n_ensembles=2).fit(record.segment(0, int(5 * record.fs))).result_
    j = result_json(post, 0.9)
    return {"NSI": nsi, "SINDy": sindy, "posterior": j}


def _band(method, est, name):
    """(value, half-width of the stated uncertainty) of one method's estimate."""
    if method == "posterior":
        p = est["parameters"][name]
        return p["mean"], 3 * p["sd"]
    value = getattr(est.model_, name)
    return value, STATED[method][name] * abs(value)


@pytest.mark.parametrize("pair", [("NSI", "SINDy"), ("NSI", "posterior"), ("SINDy", "posterior")])
def test_identification_methods_agree_within_their_stated_uncertainty(estimates, pair):
    a, b = pair
    for name in PARAMS:
        va, ua = _band(a, estimates[a], name)
        vb, ub = _band(b, estimates[b], name)
        assert abs(va - vb) <= ua + ub, (
            f"{a} and {b} disagree on {name}: {va:.6g} +- {ua:.3g} against {vb:.6g} +- {ub:.3g}"
        )


def test_ga_updated_device_reproduces_the_nsi_features(estimates):
    nsi = estimates["NSI"]
    targets = targets_from(nsi.result())
    ga = GAUpdater(generations=60, seed=2).fit(targets)
    feats = ga.device_.features()
    # the GA's own fitness (seed Eq. 9, %) is its stated misfit; the features must match within it
    assert fitness(feats, targets) == pytest.approx(ga.fitness_, rel=1e-6)
    for k in ("f_minus", "f_plus", "z_minus", "z_plus"):
        assert feats[k] == pytest.approx(targets[k], rel=max(0.02, 2 * ga.fitness_ / 100)), (
            f"GA-updated device and NSI disagree on {k}: {feats[k]:.5g} against {targets[k]:.5g}"
        )


def test_discrepancy_says_none_on_a_record_the_baseline_explains():
    base = dataclasses.replace(SEED_LIKE_CUBIC, c_nl=0.0)
    r = Rig(base, seed=32).random(duration=120, rms=SEED_LIKE_CROSS_WELL_RMS)
    rec = from_arrays(r.columns["base_acc"], r.columns["z"], r.fs, mass=float(r.meta["mass"]), source="rig")
    res = Discrepancy().fit(rec).result()
    assert res["effect"] == "none", f"discrepancy named {res['effect']} on a record its baseline explains"
