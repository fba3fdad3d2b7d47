"""The discrepancy workflow (issue 8): each hidden effect named, sized and its gap closed; `none` when
nothing is missing; the device's model-form gap; the Silverbox from a linear start. The hidden-effect
data are generated here; the workflow sees only the measured columns."""

import dataclasses

import pytest
from records import (
    SILVERBOX_ARROW,
    SILVERBOX_TEST,
    SILVERBOX_TRAIN,
    assert_result_answers_alike,
    silverbox_prediction_mv,
)

from negstiff.inference.estimators.discrepancy import LINEAR_BASELINE, Discrepancy
from negstiff.inference.record.measurement import from_arrays
from negstiff.models import AS_BUILT, SEED_LIKE_CROSS_WELL_RMS, SEED_LIKE_CUBIC
from negstiff.models.rig import Rig

BASE = dataclasses.replace(SEED_LIKE_CUBIC, c_nl=0.0)
"""The seed-like coefficients without c_nl (the hidden quadratic damping's record puts it back)."""

HIDDEN = {
    # realistic sizes: each a few % of the restoring force at the stroke's ends, or the seed's own c_nl
    "coulomb_friction": 0.1,  # N, 5 % of the device's weight
    "quadratic_damping": 0.5,  # N s^2/m^2, the seed's c_nl
    "cubic_damping": 0.3,  # N s^3/m^3, 0.3 N at 1 m/s
    "quartic_stiffness": 2e6,  # N/m^4, 1.6 N at 30 mm (the as-built geometry's own is ~5e6 with 1.7e8 z^5)
    "quintic_stiffness": 1e8,  # N/m^5, 2.4 N at 30 mm
    "end_stop": {"k": 2000.0, "z": -0.036},  # a bumper 3 mm inside the minus side's reach
}


def _record(effects, seed, duration=120.0):
    r = Rig(BASE, effects=effects, seed=seed).random(duration=duration, rms=SEED_LIKE_CROSS_WELL_RMS)
    return from_arrays(r.columns["base_acc"], r.columns["z"], r.fs, mass=float(r.meta["mass"]), source="rig")


@pytest.mark.parametrize("seed", [1, pytest.param(2, marks=pytest.mark.slow)])  # seed 2: the replication, with -m slow
@pytest.mark.parametrize("effect", sorted(HIDDEN))
def test_a_hidden_effect_is_named_sized_and_its_gap_closed(effect, seed):
    rec = _record({effect: HIDDEN[effect]}, seed)
    d = Discrepancy().fit(rec)
    r = d.result()
    if effect == "quadratic_damping":
        # the baseline is the seed's model, c_nl z'|z'| included: quadratic damping is not missing, it is c_nl
        # (one home for one term: never also an extra effect), and nothing else is named
        assert r["effects"] == ["none"], r["ranking"]
        assert r["model"]["c_nl"] == pytest.approx(HIDDEN[effect], rel=0.2)
        assert effect not in r["model"]["extra"]
        return
    assert r["effects"] == [effect], r["ranking"]
    size, truth = r["effect_size"][effect], HIDDEN[effect]
    if effect == "end_stop":
        assert size["k"] == pytest.approx(truth["k"], rel=0.2)
        assert size["z"] == pytest.approx(truth["z"], abs=1e-3)
    else:
        assert size == pytest.approx(truth, rel=0.2)
    # the held-out gap (restarted free runs) shrinks by at least 2, or to the true model's own gap on the record
    # (measured alike): no model closes it further than the noise and the motion's chaos let the truth. Cubic
    # damping at seed 2: 0.190 -> 0.117 %, the truth's 0.131 % (measured)
    before, after = r["gap_before_percent"], r["gap_after_percent"]
    if after > before / 2:
        truth = dataclasses.replace(BASE, extra={effect: HIDDEN[effect]})
        floor = d._gap(rec, truth)["median_window_percent"]
        assert after <= floor, (before, after, floor)
    assert effect in r["model"]["extra"]


@pytest.mark.parametrize("seed", [1, pytest.param(2, marks=pytest.mark.slow)])  # seed 2: the replication, with -m slow
def test_nothing_missing_gives_none(seed):
    d = Discrepancy().fit(_record({}, seed))
    r = d.result()
    assert r["effect"] == "none" and r["effects"] == ["none"]
    assert r["ranking"][0]["effect"] in {e["effect"] for e in r["ranking"]}
    assert "spread evenly" in r["where"] or r["regimes_before"]
    # the workflow's result is an identification's (one result class): its JSON is the command's, its model the one
    # the workflow kept, its validation the held-out gap
    assert_result_answers_alike(d)
    assert d.result_.to_json() == r and d.result_.model is d.model_ and d.result_.layout == "workflow"
    assert d.result_.validation.median_window_percent == r["gap_after_percent"]


def test_the_device_model_form_gap_points_at_higher_order_stiffness():
    r = Rig(AS_BUILT, seed=5).random(duration=120.0)
    rec = from_arrays(r.columns["base_acc"], r.columns["z"], r.fs, mass=float(r.meta["mass"]), source="as-built")
    res = Discrepancy(offer_laws=False).fit(rec).result()
    # the exact geometric K stiffens beyond the cubic at large stroke: the catalogue's first effect (no law offered:
    # with the laws, the geometric law itself is named, tests/methods/test_discrepancy_laws.py) is a stiffening of z
    # alone, a higher power or a one-sided stop (with c_nl in the baseline, seed 5 names the stop: its held-out weak
    # residual 1.68 % against z^5's 1.76 %, and the gap 2.1 -> 0.92 %)
    assert res["effect"] in ("quartic_stiffness", "quintic_stiffness", "end_stop")
    assert res["gap_after_percent"] < res["gap_before_percent"] / 2


def test_silverbox_from_a_linear_start_names_cubic_stiffness(silverbox):
    # real data, a known answer: from a linear baseline the workflow names the Silverbox's cubic
    # stiffness first, and the named model predicts the multisine test far better than the linear one
    d = Discrepancy(baseline=LINEAR_BASELINE).fit(silverbox.segment(*SILVERBOX_TRAIN))
    assert d.effects_[0] == "cubic_stiffness"
    before = silverbox_prediction_mv(d.baseline_model_, silverbox, SILVERBOX_TEST)
    after = silverbox_prediction_mv(d.model_, silverbox, SILVERBOX_TEST)
    assert after < before / 2, (before, after)


def test_silverbox_with_defaults_predicts_the_test_and_the_arrow(silverbox):
    # The acceptance for the discrepancy model (cubic baseline, refinement, defaults; trained on
    # 40650-105712 only): multisine test <= 0.85 mV, the full arrow (its last third beyond the training
    # amplitude) <= 1.0 mV; measured 0.24 and 0.31 mV. No catalogue effect beats the refined Duffing
    # form on the held-out part (the study reports 'none'), and the model stays bounded.
    d = Discrepancy().fit(silverbox.segment(*SILVERBOX_TRAIN))
    assert silverbox_prediction_mv(d.model_, silverbox, SILVERBOX_TEST) <= 0.85
    assert silverbox_prediction_mv(d.model_, silverbox, SILVERBOX_ARROW) <= 1.0
    assert d.bounded_["ok"]
