"""Which test next for a device fixed to the ground (a hammer's record or a free decay): hammer hits over their
peak force and count, releases from a held position away from the rest well or towards the saddle, ranked as the
shaker-table's tests are (``analysis.design``), within the hammer's force and the device's stroke; bad input refused
in one line.

The first record is written with scipy's DOP853, not negstiff's simulator (``impact_records.measured_hammer``: the
seed-like double well, 40 N hits of 4 ms, the force channel offset by 0.5 N with 0.05 N of noise, 1 um of laser
noise). The realised check (the chosen test run, fitted jointly, its widths against the predicted) is measured on
the virtual rig in ``docs/methods/design.md``.
"""

import json
import warnings

import numpy as np
import pytest
from impact_records import DOUBLE_WELL, measured_hammer

from negstiff import Posterior
from negstiff.cli import main
from negstiff.errors import InputError
from negstiff.inference.analysis.design import RING_DOWN_TESTS, design
from negstiff.inference.analysis.separation import separation

QUICK = {"candidates": 12, "draws": 2, "search": 0, "seed": 0}


@pytest.fixture(scope="module")
def hammer_posterior(tmp_path_factory):
    rec = measured_hammer(DOUBLE_WELL, seed=1, laser_m=1e-6)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        # two ensembles of 1000 steps at most: c_nl's optimum lies on its bound (0), where the sampler mixes slowly
        # (its autocorrelation time 96 steps, the default fit 26 s); the design reads the posterior's moments
        res = Posterior(seed=0, n_ensembles=2, max_steps=1000).fit(rec).result()
    path = tmp_path_factory.mktemp("ring_down") / "hammer_post.json"
    path.write_text(json.dumps(res))
    return path


@pytest.fixture(scope="module")
def planned(hammer_posterior):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return design(hammer_posterior, **QUICK)


def test_a_hammer_record_s_design_ranks_hits_and_releases(planned):
    rows = planned["ranked"]
    assert {r["kind"] for r in rows} == set(RING_DOWN_TESTS)
    assert {r["hits"] for r in rows if r["kind"] == "hammer"} >= {2, 4, 8}
    assert any(r["release_offset_m"] > 0 for r in rows if r["kind"] == "release")
    assert any(r["release_offset_m"] < 0 for r in rows if r["kind"] == "release")
    best, ref = planned["best"], planned["default_test"]
    # every test adds windows of free decay: none leaves the intervals as wide as they are (the reference is ranked
    # among the candidates, so the first-ranked teaches at least as much by construction)
    assert best["feasible"] and ref["score"] > 1.0
    assert ref["kind"] == "hammer" and ref["hits"] == 4
    assert planned["settings"]["bench"] == "ring-down" and planned["settings"]["max_table_acc_m_s2"] is None
    # no stroke stated, and the criterion grows with the motion until a stop: said
    assert any("no stroke was stated" in w for w in planned["warnings"])
    scores = [r["score"] for r in rows if r["feasible"]]
    assert scores == sorted(scores, reverse=True)


def test_a_larger_release_teaches_more_within_one_well(planned):
    # the physics the ranking must show: a release farther out in the rest well (away from the saddle, so it rings
    # down in that well) reaches further up the cubic's stiffening, so it pins k3 down more
    out = sorted((r for r in planned["ranked"] if r["kind"] == "release" and r["release_offset_m"] > 0
                  and r["cost"]["draws_visiting_both_wells"] == 0.0), key=lambda r: r["release_offset_m"])  # fmt: skip
    assert len(out) >= 2
    assert out[-1]["shrink"]["k3"] > out[0]["shrink"]["k3"]


def test_the_hammer_s_force_and_the_device_s_stroke_bound_the_tests(hammer_posterior):
    from negstiff.inference.analysis.design import Candidate, Limits, PosteriorState, evaluate

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = design(hammer_posterior, max_force=60.0, stroke=0.03, **QUICK)
    hammers = [r for r in res["ranked"] if r["kind"] == "hammer"]
    assert max(r["peak_force_n"] for r in hammers) == pytest.approx(60.0)  # the grid reaches the hammer's limit
    for r in res["ranked"]:
        if r["feasible"]:
            assert r["cost"]["peak_travel_m"] <= 0.03
    assert any(not r["feasible"] and "stroke" in r["problems"][0] for r in res["ranked"])
    assert res["best"]["feasible"] and res["default_test"]["peak_force_n"] <= 60.0
    assert not any("no stroke was stated" in w for w in res["warnings"])
    # a hit above the hammer's force, evaluated directly (the grid and the search stay within it): infeasible
    state = PosteriorState.from_json(json.loads(hammer_posterior.read_text()))
    ev = evaluate(state, Candidate("hammer", 100.0, hits=4), Limits(10.0, max_force=60.0), ("k3",),
                  state.draws(1, 0), 0)  # fmt: skip
    assert not ev.feasible and "peak force 100 N above the hammer's 60 N" in ev.problems[0]


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"max_table_acc": 10.0}, "a table's limit"),
        ({"max_table_disp": 0.01}, "a table's limit"),
        ({"max_force": -1.0}, "max_force must be a positive number"),
        ({"stroke": 1e-7}, "laser's noise"),
        ({"max_force": 1.0}, "below the lightest hit"),
    ],
)
def test_a_ring_down_design_refuses_what_does_not_apply_before_the_work(hammer_posterior, kwargs, message):
    with pytest.raises(InputError, match=message):
        design(hammer_posterior, **kwargs)


def test_a_ring_down_posterior_the_hammer_s_force_cannot_be_read_from_is_refused(hammer_posterior):
    res = json.loads(hammer_posterior.read_text())
    unweighed = {**res, "settings": {**res["settings"], "mass": None, "model_mass": None}}
    with pytest.raises(InputError, match="without the device's mass"):
        design(unweighed)
    coarse = {**res, "settings": {**res["settings"], "fs": 200.0}}
    with pytest.raises(InputError, match="needs 500 Hz"):
        design(coarse)


def test_a_separation_is_refused_on_a_ring_down_posterior(hammer_posterior):
    with pytest.raises(InputError, match="a hammer's or a decay's posterior"):
        separation(hammer_posterior, hypotheses={"coulomb_friction": 0.02, "cubic_damping": 0.5})


def test_the_command_plans_hammer_tests_within_the_hammer_s_force(hammer_posterior, tmp_path, capsys):
    out = tmp_path / "next.json"
    argv = ["design", str(hammer_posterior), "-o", str(out), "--max-force", "80", "--candidates", "8", "--draws", "2"]
    assert main(argv) == 0
    res = json.loads(out.read_text())
    assert res["settings"]["max_force_n"] == 80.0 and (tmp_path / res["figure"]).stat().st_size > 10_000
    assert all(r["peak_force_n"] <= 80.0 for r in res["ranked"] if r["kind"] == "hammer" and r["feasible"])
    assert "the default test, 4 hammer hits" in capsys.readouterr().err
    bad = tmp_path / "bad.json"
    assert main(["design", str(hammer_posterior), "-o", str(bad), "--max-acc", "10"]) == 2
    assert not bad.exists() and "a table's limit" in capsys.readouterr().err


def test_the_rig_s_hammer_and_release_records_are_read_as_a_hammer_s_and_a_decay(tmp_path):
    from negstiff.inference.analysis.record_kind import record_kind
    from negstiff.inference.record.measurement import Measurement
    from negstiff.models.rig import Rig

    rig = Rig(DOUBLE_WELL, seed=2, fs=1000.0)
    hit = rig.hammer(peak=40.0, hits=3, duration=6.0)
    kind = record_kind(Measurement.from_rig(hit))
    assert kind.kind == "impact" and kind.impacts.count == 3
    assert np.max(hit.true["force"]) == pytest.approx(40.0, rel=0.01)
    # a 40 N, 4 ms hit gives the 0.2 kg mass an impulse of 2 F w / pi = 0.102 N s: 0.51 m/s just after it
    i = int(round(hit.truth["excitation"]["hit_times_s"][0] * 1000.0)) + 5
    assert hit.true["z_dot"][i] == pytest.approx(0.102 / 0.2, rel=0.05)
    rel = rig.release(DOUBLE_WELL.equilibria().z_plus + 0.005, duration=4.0)
    assert record_kind(Measurement.from_rig(rel)).kind == "decay"
    assert rel.true["z"][0] == pytest.approx(DOUBLE_WELL.equilibria().z_plus + 0.005, abs=1e-12)
    # written and loaded as a lab's file, it is still a free decay (its force column zero)
    from negstiff import load

    back = load(rel.write(tmp_path / "release.csv"), mass=DOUBLE_WELL.m)
    assert back.input_name == "force" and record_kind(back).kind == "decay"
