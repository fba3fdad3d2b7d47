"""Output-error refinement (issue: models that predict real data), first stage: the library function.
Known truth first (a rig record of a polynomial model, the refinement started off the truth), then
the Silverbox benchmark against the output-error Duffing fit the issue quotes."""

import numpy as np
import pytest
from records import SILVERBOX_ARROW, SILVERBOX_TEST, SILVERBOX_TRAIN, silverbox_prediction_mv

from negstiff.inference.estimators.nsi import NSI
from negstiff.inference.estimators.sindy import SINDy
from negstiff.inference.record.derivatives import state_derivatives
from negstiff.inference.record.measurement import from_arrays
from negstiff.inference.steps.refine import refine
from negstiff.inference.steps.validation import boundedness, free_run_rms, simulate_record
from negstiff.models import Model, simulate
from negstiff.models.device import AS_BUILT, SEED_LIKE_CROSS_WELL_RMS, SEED_LIKE_CUBIC
from negstiff.models.rig import Rig, Sensors


def test_refinement_returns_to_the_truth_from_a_perturbed_start():
    # Fact: started 5 % off in k1-k3 and 30 % off in c, c_nl, the simulation-error minimum of a
    # noise-free cross-well record is the truth: k1-k3 and c within 0.1 % (0.002 % measured); c_nl within
    # 1 % (0.1 % measured: it trades with c on 20 s, and the rig's 4x oversampled input differs from the
    # band-limited interpolation of its 512 Hz samples); the windows' error falls to the floor the truth
    # itself reaches (0.79 um measured, 2.5x allowed), from 400 um at the start
    truth = SEED_LIKE_CUBIC
    rec = Rig(truth, seed=6, sensors=Sensors.noiseless()).random(duration=20, rms=SEED_LIKE_CROSS_WELL_RMS)
    m = from_arrays(rec.columns["base_acc"], rec.columns["z"], rec.fs, mass=truth.m)
    start = Model.from_dict({**truth.to_dict(), "k1": truth.k1 * 1.05, "k2": truth.k2 * 0.95, "k3": truth.k3 * 1.05,
                             "c": truth.c * 1.3, "c_nl": truth.c_nl * 0.7})  # fmt: skip
    r = refine(start, m)
    for k in ("k1", "k2", "k3", "c"):
        assert getattr(r.model, k) == pytest.approx(getattr(truth, k), rel=1e-3), k
    assert r.model.c_nl == pytest.approx(truth.c_nl, rel=0.01)
    assert [s["window_s"] for s in r.stages if "rms_end_m" in s][-1] >= 1.0, "fitted up to 1 s free runs"
    assert r.stages[-1]["rms_end_m"] < 2.5 * 0.79e-6 < 0.05 * r.stages[0]["rms_start_m"]
    assert r.initial_model == start


def test_silverbox_input_between_samples_decides_the_prediction(silverbox):
    # Fact: the Silverbox's input (610 Hz, excited to 200 Hz) passed an anti-aliasing filter; drawn as a
    # straight line between samples it loses sinc^2(f/fs) of its high band (31 % at 200 Hz), and the
    # same equation-error SINDy model then predicts the multisine test at 2.67 mV instead of 0.24 mV
    # (measured). Band-limited stage inputs with the step refined to omega h <= 0.25 give the latter.
    train, test = silverbox.segment(*SILVERBOX_TRAIN), silverbox.segment(*SILVERBOX_TEST)
    zs, v, _, _ = state_derivatives(test.z, test.fs, purpose="state")
    model = SINDy(refine=False).fit(train).model_
    staged = 1e3 * free_run_rms(model, test.segment(50, test.n), x0=(zs[50], v[50]))
    lin = simulate(model, test.u[50:], test.dt, z0=zs[50], v0=v[50], input_kind="force").z[0]
    linear = 1e3 * np.sqrt(np.mean((lin - test.z[50:]) ** 2))
    assert staged < 0.30 and linear > 5 * staged, (staged, linear)


@pytest.mark.parametrize("method", ["nsi", "sindy"])
def test_silverbox_identified_with_defaults_predicts_below_the_published_best(silverbox, silverbox_fits, method):
    # The acceptance: trained on 40650-105712 only, free run on the multisine test (first 50
    # samples not scored) <= 0.85 mV; measured 0.24 mV for both methods with their defaults (refinement
    # included), below the best published model the issue quotes (GP-NARX 0.30 mV). Neither diverges on
    # the arrow, and the arrow's extrapolating last third stays within the 1.0 mV (0.31 mV).
    est = silverbox_fits[method]
    mv = silverbox_prediction_mv(est.model_, silverbox, SILVERBOX_TEST)
    arrow = silverbox_prediction_mv(est.model_, silverbox, SILVERBOX_ARROW)
    assert mv <= 0.30 and arrow <= 1.0, (mv, arrow)
    assert est.refinement_["applied"], est.refinement_["reason"]
    assert est.refinement_["heldout"]["refined"]["restarted_rms_percent"] is not None
    # the equation-error estimate is kept beside the refined model, and predicts worse
    assert silverbox_prediction_mv(est.initial_model_, silverbox, SILVERBOX_TEST) > mv


def test_boundedness_flags_a_model_that_escapes_just_past_the_stroke():
    # Fact: the true cubic confines the motion beyond the recorded stroke and survives the training input
    # scaled by 1.2; the same model with a negative z^5 term (-1e9 N/m^5: 12 N at 4 cm, beside the
    # cubic's ~20 N) has its potential fall away just past the stroke and diverges under that input.
    truth = SEED_LIKE_CUBIC
    rec = Rig(truth, seed=6).random(duration=60, rms=SEED_LIKE_CROSS_WELL_RMS)
    m = from_arrays(rec.columns["base_acc"], rec.columns["z"], rec.fs, mass=truth.m)
    ok = boundedness(truth, m)
    assert ok["ok"] and ok["over_stroke"] and ok["globally"] and not ok["diverged_at_margin"]
    bad = boundedness(Model.from_dict({**truth.to_dict(), "extra": {"quintic_stiffness": -1e9}}), m)
    assert not bad["ok"] and not bad["over_stroke"] and not bad["globally"] and bad["diverged_at_margin"]
    lo, hi = bad["stroke_m"]
    assert bad["escape_z"] <= lo or bad["escape_z"] >= hi
    assert "not bounded" in bad["warning"]
    # a device's rods reach only so far: its geometry confines it
    assert boundedness(AS_BUILT, m, free_run=False)["globally"]


def test_silverbox_report_number_is_what_negstiff_simulate_gives(silverbox, silverbox_fits, tmp_path):
    # The issue: "the numbers in the report match a free run of negstiff simulate with the written
    # model". The refined SINDy model written as a model file, the multisine test (from its 50th sample)
    # written as a lab CSV; `negstiff simulate` starts from the file's own first state (a different
    # smoothing edge than the report's), a start difference the damped circuit forgets in a few cycles.
    import json

    from negstiff.cli import main

    est = silverbox_fits["sindy"]
    (tmp_path / "model.json").write_text(json.dumps(est.model_.to_dict()))
    test = silverbox.segment(*SILVERBOX_TEST).segment(50, None)
    np.savetxt(tmp_path / "test.csv", np.column_stack([np.arange(test.n) / test.fs, test.u, test.z]),
               delimiter=",", fmt="%.9g", header="t,force,z", comments="")  # fmt: skip
    assert main(["simulate", str(tmp_path / "model.json"), str(tmp_path / "test.csv"), "-o",
                 str(tmp_path / "sim.csv"), "--quiet"]) == 0  # fmt: skip
    sim = np.loadtxt(tmp_path / "sim.csv", delimiter=",", skiprows=1)
    cli_mv = 1e3 * np.sqrt(np.mean((sim[:, 2] - test.z) ** 2))
    assert cli_mv == pytest.approx(silverbox_prediction_mv(est.model_, silverbox, SILVERBOX_TEST), rel=0.05)


@pytest.fixture(scope="module")
def independent_duffing():
    """A record negstiff did not make: a hardening Duffing oscillator (m 0.5 kg, 10 Hz, zeta 1.6 %,
    cubic 7 % of the linear force at rms z) integrated by scipy's DOP853 (rtol 1e-9) under a force
    that is a continuous multisine (2-30 Hz every 0.5 Hz: band-limited, like a lab's filtered input),
    sampled at 100 Hz (10 samples per resonance period: the Silverbox's regime), z with 0.5 % rms
    white noise. Returns the record, the truth model, the noise-free states."""
    from scipy.integrate import solve_ivp

    m_, c_, k_, k3_ = 0.5, 2.0, 2000.0, 2.0e7
    fs, T = 100.0, 120.0
    rng = np.random.default_rng(7)
    w = 2 * np.pi * np.arange(4, 61) * 0.5
    ph = rng.uniform(0, 2 * np.pi, w.size)
    a = 3.0 / np.sqrt(w.size)

    def rhs(t, x):
        force = a * np.cos(w * t + ph).sum()
        return [x[1], (force - c_ * x[1] - k_ * x[0] - k3_ * x[0] ** 3) / m_]

    t = np.arange(int(T * fs)) / fs
    sol = solve_ivp(rhs, (0, t[-1]), [0.0, 0.0], t_eval=t, method="DOP853", rtol=1e-9, atol=1e-12)
    u = a * np.cos(w[None, :] * t[:, None] + ph[None, :]).sum(axis=1)
    z = sol.y[0] + 0.005 * sol.y[0].std() * rng.standard_normal(t.size)
    rec = from_arrays(u, z, fs, input_name="force", mass=m_, source="solve_ivp Duffing")
    return rec, Model(m=m_, k0=0.0, k1=-k_, k2=0.0, k3=k3_, c=c_), sol.y


@pytest.mark.parametrize("method", ["nsi", "sindy"])
def test_refinement_on_an_independent_simulator_reaches_the_truths_prediction(independent_duffing, method):
    # Known truth on a record another integrator wrote. Facts: (1) the truth itself, simulated with
    # negstiff's band-limited stage input from the exact state, follows the noise-free record within
    # 5 um (2.8 um measured: the interpolator's floor), while the input drawn straight between samples
    # errs by over 100 um (400 um measured). (2) Identified on the first 75 % with defaults, the refined
    # model's k1, k3 are within 0.1 % and c within 0.5 % of the truth (0.001-0.005 % measured at 0.5 %
    # noise), SINDy's selection (z, z^3, v) is kept by the refinement (unselected terms stay zero), and
    # the refined model predicts the held-out quarter free-run as well as the truth does (within 5 %;
    # both ~16 um, the noise's 13.6 um plus the start state's transient).
    rec, truth, states = independent_duffing
    n = int(0.75 * rec.n)
    clean = from_arrays(rec.u, states[0], rec.fs, input_name="force", mass=truth.m).segment(n, rec.n)
    x0 = (states[0][n], states[1][n])
    staged = simulate_record(truth, clean, x0)
    lin = simulate(truth, clean.u, clean.dt, z0=x0[0], v0=x0[1], input_kind="force", substeps=8)
    assert np.sqrt(np.mean((staged.z[0] - clean.z) ** 2)) < 5e-6
    assert np.sqrt(np.mean((lin.z[0] - clean.z) ** 2)) > 100e-6

    est = (NSI() if method == "nsi" else SINDy()).fit(rec.segment(0, n))
    for k in ("k1", "k3"):
        assert getattr(est.model_, k) == pytest.approx(getattr(truth, k), rel=1e-3), k
    assert est.model_.c == pytest.approx(truth.c, rel=5e-3)
    if method == "sindy":
        assert est.selected_ == ["z", "z^3", "v"]
        assert est.model_.k2 == 0.0 and est.model_.c_nl == 0.0 and est.model_.k0 == 0.0
    zs, vs, _, _ = state_derivatives(rec.z, rec.fs, purpose="state")
    test = rec.segment(n, rec.n)
    floor = free_run_rms(truth, test, x0=(zs[n], vs[n]))
    assert free_run_rms(est.model_, test, x0=(zs[n], vs[n])) <= 1.05 * floor
