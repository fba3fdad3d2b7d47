"""NSI and SINDy with ``element=`` on a structure's hammer record and free decay (2 DOFs): the hardening Duffing and
the seed-like double well of ``impact_records`` as the element between a sprung fixture (DOF 1: 1 kg on a 25 Hz, 2 %
spring to the ground) and the device's mass (DOF 2), written with scipy's DOP853 (``fixture_hammer_record``,
``fixture_decay_record``), not negstiff's simulator. The hammer hits the device's mass (half-sine pulses of 40 N,
4 ms; its channel offset by 0.5 N with 0.05 N of noise); the decay is a release from rest. Both lasers read
1 um of white noise.

Acceptance (the issue "Hammer and decay tests", 2-DOF): each mode's frequency within 1 %, its damping ratio within
10 %, the element's cubic within 5 %. The modes are the method's own (NSI's subspace poles; SINDy's model's
linearisation) of the well the record rings down in; what each fit reached is in the comments (seed 1).
"""

import warnings

import numpy as np
import pytest
from impact_records import DOUBLE_WELL, DUFFING, MASS, fixture_decay_record, fixture_hammer_record

from negstiff import NSI, SINDy, from_arrays
from negstiff.inference.analysis.record_kind import record_kind
from negstiff.models import Model
from negstiff.models.structure import Structure

FS = 1000.0
FIXTURE = {"fixture_mass": 1.0, "fixture_hz": 25.0, "fixture_zeta": 0.02}
HITS = (0.5, 3.0, 5.5, 8.0)
"""Four hits 2.5 s apart on the device's mass, the last in the held-out tail."""
LASER_M = 1e-6
"""Each displacement channel's noise [m rms] (a laser vibrometer's). At 5 um SINDy's structure decay selected a
double well 20 % off in its plus well's frequency (the weak form's test functions widened to the noise)."""

LIGHT_DUFFING = Model(m=MASS, k1=DUFFING.k1, k2=0.0, k3=DUFFING.k3, c=DUFFING.c / 3, k0=0.0)
"""The Duffing at 0.5 % damping (alone on a rigid base): its decay still reaches the cubic's range where the
estimators score their candidates (at 1.5 % it has rung down to the noise there)."""


def _structure(device: Model) -> Structure:
    return Structure.on_fixture(device, **FIXTURE)


def _hammer(device, seed):
    _, f, z = fixture_hammer_record(device, FIXTURE, FS, HITS, 40.0, 0.004, 10.0, force_dof=2)
    rng = np.random.default_rng(seed)
    force = f + 0.5 + 0.05 * rng.standard_normal(f.size)
    zm = z + LASER_M * rng.standard_normal(z.shape)
    return from_arrays(force, zm, FS, input_name="force", masses=(FIXTURE["fixture_mass"], MASS), force_dof=2,
                       gravity=device.k0 / MASS, source="hammer on a fixture")  # fmt: skip


def _decay(device, z0, seed, duration):
    _, z = fixture_decay_record(device, FIXTURE, z0, FS, duration)
    zm = z + LASER_M * np.random.default_rng(seed).standard_normal(z.shape)
    return from_arrays(np.zeros(zm.shape[1]), zm, FS, input_name="force", masses=(FIXTURE["fixture_mass"], MASS),
                       gravity=device.k0 / MASS, source="decay on a fixture")  # fmt: skip


def _fit(est, rec):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return est.fit(rec)


def _check(est, device, wells, kind):
    assert est.record_kind_.kind == kind
    truth = _structure(device)
    for well in wells:
        for got, true in zip(est.modal_[well], truth.modes(well), strict=True):
            assert got.f_hz == pytest.approx(true.f_hz, rel=0.01), (well, got, true)
            assert got.zeta == pytest.approx(true.zeta, rel=0.10), (well, got, true)
    assert est.element_["k3"] == pytest.approx(device.k3, rel=0.05)


# the double well released at rest 12 mm beyond its plus well (the fixture at its rest): it crosses the barrier
# within 0.25 s (1.5 cycles in the plus well) and rings down in the minus well, whose modes the record measures
DOUBLE_WELL_RELEASE = (0.0, DOUBLE_WELL.equilibria().z_plus + 0.012)


def test_a_structures_hammer_and_decay_records_are_read_by_their_kind():
    # the hammer's hits found in its force channel whatever DOF they hit; a zero input column is a free decay
    assert record_kind(_hammer(DUFFING, seed=1)).kind == "impact"
    assert record_kind(_decay(DOUBLE_WELL, DOUBLE_WELL_RELEASE, seed=1, duration=4.0)).kind == "decay"


@pytest.mark.parametrize("device", [DUFFING, DOUBLE_WELL], ids=["duffing", "double_well"])
def test_nsi_identifies_a_hammer_record_on_a_fixture(device):
    # the force windowed (each hit's offset off, zero between pulses) drives the structure's NSI, the masses given
    # scaling its level (the sampled pulse's own level is 5 % low). Measured: Duffing 11.658 / 1.40 % and 25.724 /
    # 2.09 % (truth 11.662 / 1.42 %, 25.726 / 2.14 %), k3 +1.9 %; double well (plus) 10.112 / 1.82 %, 25.505 / 2.17 %
    # (truth 10.111 / 1.84 %, 25.503 / 2.17 %), k3 -2.6 % (-5.0 % noise-free with the input column's level). Over
    # seeds 2-4 the modes stay within 0.04 % and 1.4 %, k3 -5.2 to +1.2 % (Duffing) and -2.0 to +0.4 % (double well):
    # the Duffing's cubic at 1 um is at the acceptance's edge. With the basis low-passed above the response's band
    # (``derivatives.BASIS_SNR``) the Duffing's k3 reads +2.0, -1.8, -6.6, +1.8 % over seeds 1-4 (measured): a
    # scatter (three hits, the force channel's noise) the low-pass does not narrow, not the sensor noise's bias
    _check(_fit(NSI(element="1-2"), _hammer(device, seed=1)), device, ["plus"], "impact")


def test_sindy_identifies_a_free_decay_of_the_double_well_on_a_fixture():
    # the weak form without an input term, every damper in every support (a ring-down dissipates). Measured: minus
    # 10.969 / 1.68 %, 25.619 / 2.17 % (truth 10.969 / 1.68 %, 25.618 / 2.17 %), k3 +0.001 %
    est = _fit(SINDy(element="1-2"), _decay(DOUBLE_WELL, DOUBLE_WELL_RELEASE, seed=1, duration=4.0))
    _check(est, DOUBLE_WELL, ["minus"], "decay")


def test_nsi_identifies_a_free_decay_of_the_double_well_on_a_fixture():
    # the decay form: the feedback channels alone, the masses given scale the level. Measured: minus 10.973 / 1.62 %,
    # 25.621 / 2.20 %, k3 +0.1 % (its plus well, seen for 1.5 cycles: 9.94 Hz, -1.7 %)
    est = _fit(NSI(element="1-2"), _decay(DOUBLE_WELL, DOUBLE_WELL_RELEASE, seed=1, duration=4.0))
    _check(est, DOUBLE_WELL, ["minus"], "decay")


def test_nsi_identifies_a_free_decay_of_the_duffing_on_a_fixture():
    # released at rest 8 mm from its equilibrium (the fixture at rest): one well, no weight (a horizontal device, its
    # frame pinned by the element's zero force). Measured: 11.6614 / 1.35 %, 25.757 / 2.12 % (truth 11.6616 / 1.42 %,
    # 25.726 / 2.14 %), k3 -1.0 %; over seeds 2-4 damping -4.6 to -1.0 %, k3 -1.6 to -0.4 %
    est = _fit(NSI(element="1-2"), _decay(DUFFING, (0.0, 0.008), seed=1, duration=6.0))
    _check(est, DUFFING, ["plus"], "decay")


@pytest.mark.slow
@pytest.mark.parametrize("device", [DUFFING, DOUBLE_WELL], ids=["duffing", "double_well"])
def test_sindy_identifies_a_hammer_record_on_a_fixture(device):
    # measured: Duffing 11.652 / 1.32 %, 25.711 / 2.07 %, k3 +1.7 %; double well (plus) 10.115 / 1.72 %,
    # 25.469 / 2.27 %, k3 +0.2 % (the record stays in the plus well)
    _check(_fit(SINDy(element="1-2"), _hammer(device, seed=1)), device, ["plus"], "impact")


@pytest.mark.slow
def test_sindy_identifies_a_lightly_damped_free_decay_of_the_duffing_on_a_fixture():
    # released at rest 8 mm from its equilibrium (the fixture at rest). Measured: 11.663 / 0.52 %, 25.731 / 1.96 %
    # (truth 11.662 / 0.52 %, 25.726 / 1.99 %), k3 -0.2 %
    est = _fit(SINDy(element="1-2"), _decay(LIGHT_DUFFING, (0.0, 0.008), seed=1, duration=10.0))
    _check(est, LIGHT_DUFFING, ["plus"], "decay")


@pytest.mark.slow
def test_nsi_cubic_of_a_lightly_damped_free_decay_of_the_duffing_on_a_fixture():
    # k3 came out -8.9 % (noise-free +0.7 %) while the basis held the sensor's noise (10 s, the ring-down's long tail
    # at the noise's level: the output's noise and the -x^3 channel's correlated); with the basis low-passed above
    # the response's band (``derivatives.BASIS_SNR``) k3 +1.1, -1.3, +0.2, -1.6 % over seeds 1-4 (measured)
    est = _fit(NSI(element="1-2"), _decay(LIGHT_DUFFING, (0.0, 0.008), seed=1, duration=10.0))
    _check(est, LIGHT_DUFFING, ["plus"], "decay")


def _posterior(rec, **kw):
    from negstiff import Posterior

    return _fit(Posterior(element="1-2", **kw), rec)


def test_the_elements_posterior_reads_a_structures_free_decay():
    # the element's posterior on the double well's decay on a fixture: the windows are free decays from their own
    # states, the linear structure and the channels' zeros sampled from SINDy's as nuisances. A short run (two
    # ensembles, 400 steps: not converged, and it says so) is enough for the facts: the record is read as a decay, the
    # posterior mean's k3 is the truth's within 0.1 % (measured -0.002 %; 1 um on a 12 mm release) and its modes the
    # truth's within 1 %. Before, it failed after the work ("no start point of positive posterior density": c_nl's least
    # squares at -2.4e-4 put the walkers' start ball across the dampers' bound)
    rec = _decay(DOUBLE_WELL, DOUBLE_WELL_RELEASE, seed=1, duration=4.0)
    post = _posterior(rec, n_ensembles=2, min_steps=200, max_steps=400, max_windows=24)
    res = post.result()
    assert res["parameters"]["k3"]["mean"] == pytest.approx(DOUBLE_WELL.k3, rel=1e-3)
    assert res["parameters"]["c_nl"]["hdi_low"] >= 0.0
    for got, true in zip(post.structure_.modes("minus"), _structure(DOUBLE_WELL).modes("minus"), strict=True):
        assert got.f_hz == pytest.approx(true.f_hz, rel=0.01)
    assert {"offset_1", "offset_2", "spring_0-1", "damper_0-1"} <= set(res["nuisance_parameters"])


def test_a_structures_ring_down_posterior_plans_its_next_hits_and_releases():
    # the test design reads a structure's free-decay posterior as a single DOF's: the candidates are hammer hits on
    # the DOF the element moves and releases of the element (the table still), simulated on the structure, each
    # record read as the element's posterior reads one (windows of free decay); the first-ranked within the limits
    # and at least as good as the default four hits; a hammer's force limit bounds every hit planned
    from negstiff.inference.analysis.design import design

    rec = _decay(DOUBLE_WELL, DOUBLE_WELL_RELEASE, seed=1, duration=4.0)
    post = _posterior(rec, n_ensembles=2, min_steps=200, max_steps=400, max_windows=24)
    quick = {"candidates": 8, "draws": 2, "search": 0, "seed": 0}
    plan = design(post, **quick)
    assert plan["settings"]["bench"] == "ring-down"
    assert {r["kind"] for r in plan["ranked"]} == {"hammer", "release"}
    assert plan["best"]["feasible"] and plan["best"]["score"] >= plan["default_test"]["score"] - 1e-9
    assert plan["default_test"]["test"].startswith("4 hammer hits")
    light = design(post, **quick, max_force=5.0)
    hits = [r for r in light["ranked"] if r["kind"] == "hammer" and r["feasible"]]
    assert hits and all(r["peak_force_n"] <= 5.0 + 1e-9 for r in hits)


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["hammer", "decay"])
def test_the_elements_posterior_on_a_structures_ring_down_holds_the_cubic(kind):
    # the default sampler on the Duffing's hammer record (windows between the hits only: a 4 ms pulse is not
    # resolved by the simulator's staged input) and on the double well's decay: every coefficient of the element
    # within 3 posterior sd of the truth (a calibrated posterior misses it 0.3 % of the time). Its windows start where
    # the element follows them best and the linear structure and channels' zeros are sampled with it (nuisances):
    # measured z of k1, k2, k3, c, c_nl on the decay, seeds 1-4: k3 -1.75 / -0.86 / -0.21 / +1.13, all within 1.9; on
    # the hammer record, seeds 1-2, within 1.6. (Held at SINDy's, the linear structure had put the hammer's c at
    # 0.465 [0.464, 0.465] for 0.452, and the windows' smoothed starts had inflated the intervals enough to hide it:
    # this test asked only that k3's 90 % interval hold the truth, which a calibrated posterior misses 10 % of the
    # time; seed 1's decay does, at z = -1.75.)
    device, rec = ((DUFFING, _hammer(DUFFING, seed=1)) if kind == "hammer"
                   else (DOUBLE_WELL, _decay(DOUBLE_WELL, DOUBLE_WELL_RELEASE, seed=1, duration=4.0)))  # fmt: skip
    par = _posterior(rec).result()["parameters"]
    for k in ("k1", "k2", "k3", "c", "c_nl"):
        assert abs(par[k]["mean"] - getattr(device, k)) < 3 * par[k]["sd"], (k, par[k])


def test_a_decay_whose_held_out_tail_is_its_noise_is_said_to_judge_nothing():
    # the hardening Duffing on its fixture, both released 3 mm from rest (8 s): it rings above its 1 um noise for
    # about 6 s, so the part that scores the candidates rings (the structure is read: k3 within 1 %, measured
    # +0.01 %) while the held-out tail (6.4 s on) is the sensors' noise (78.7 % of its rms), where the truth's own
    # runs on the same windows miss as much as the fit's (measured 90.85 % and 90.80 %; 319 % both when the windows
    # started from the band-smoothed states): the held-out error judges nothing there, and the result says so instead
    # of "explains nothing"
    from negstiff.inference.analysis.record_kind import identification_record, record_kind
    from negstiff.inference.steps.validation import restarted_structure_runs

    rec = _decay(DUFFING, (0.003, -0.003), 4, 8.0)
    est = _fit(NSI(element="1-2"), rec)
    assert est.element_["k3"] == pytest.approx(DUFFING.k3, rel=0.01)
    v, n_id = est.result_.validation, est.result_.settings["identification_samples"]
    truth = restarted_structure_runs(_structure(DUFFING), identification_record(rec, record_kind(rec)), n_id,
                                     v["window_s"])  # fmt: skip
    assert v["rms_percent"] <= truth["rms_percent"] * (1 + 0.01) and v["noise_floor_percent"] >= 50
    assert any("at the sensors' noise" in w for w in est.result_.warnings)
    assert not any("explains nothing" in w for w in est.result_.warnings)
