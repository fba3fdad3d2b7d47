"""One record and one estimator per method for any number of DOFs: a structure's record is a ``Measurement`` read
through ``negstiff.io`` like a single DOF's, and ``NSI``, ``SINDy`` identify a device on a sprung fixture from it
with each channel's zero arbitrary, as a laser's is. The records are written here with a plain RK4 on Python
floats (``records.rk4_fixture_record``), not negstiff's simulator."""

import warnings

import numpy as np
import pytest
from records import FIXTURE, rk4_fixture_record, write_csv

from negstiff import NSI, Discrepancy, InputError, Model, NegstiffWarning, Posterior, SINDy, from_arrays, load
from negstiff.inference.estimators.identification import structure_result
from negstiff.inference.estimators.prediction import structure_runs
from negstiff.inference.steps.refine import refine
from negstiff.inference.steps.validation import restarted_structure_runs as free_run_error
from negstiff.models import SEED_LIKE_CUBIC
from negstiff.models.structure import Structure

FS = 512.0
DEVICE = Model(**{**SEED_LIKE_CUBIC.to_dict(), "m": 0.2, "k0": 0.2 * 9.81})
"""The seed-like asymmetric double well (k2, k3 > 0, the negative linear stiffness -k1 z), 0.2 kg."""
TRUTH = Structure.on_fixture(DEVICE, fixture_mass=FIXTURE["m"], fixture_hz=FIXTURE["f_hz"],
                             fixture_zeta=FIXTURE["zeta"])  # fmt: skip
OFFSETS = np.array([3e-4, -2e-4])
"""Each laser's zero [m]: a few tenths of a millimetre, as a lab's."""
NOISE = 1e-6


@pytest.fixture(scope="module")
def offset_record():
    # 120 s of random cross-well base excitation; each mass's displacement relative to the table, 1 um sensor noise,
    # each channel's zero offset
    u, z = rk4_fixture_record(duration=120.0, rms=12.0, seed=11, device=DEVICE, noise=NOISE)
    return from_arrays(u, z + OFFSETS[:, None], FS, masses=(FIXTURE["m"], DEVICE.m), source="offset record")


@pytest.fixture(scope="module")
def fits(offset_record):
    """NSI's and SINDy's identifications of the offset record with their defaults (refined by output error), and
    the negstiff warnings each issued."""
    out = {}
    for method in (NSI, SINDy):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            est = method(element="1-2").fit(offset_record)
        out[method] = (est, [str(w.message) for w in caught if issubclass(w.category, NegstiffWarning)])
    return out


@pytest.mark.parametrize("method", [NSI, SINDy])
def test_a_structures_fit_predicts_a_record_by_the_structures_own_runs(fits, offset_record, method):
    # predict and score read the whole model the fit learned (the structure, each channel's zero), not its element
    # alone as a single DOF's (an IndexError before): every channel's restarted runs, each window from the record's
    # smoothed state; a model within ppm of the truth scores as the truth does, within a factor 2 on the median
    # window (the noise and the chaos decide each window; measured: NSI 0.56 % on a fixture record, 0.25 s windows)
    est, _ = fits[method]
    pred = est.predict(offset_record, window_s=0.25)
    w = pred.z.shape[-1]
    assert pred.z.shape == pred.measured.shape and pred.z.shape[1] == 2 and w > 0.24 * FS
    assert np.all(np.abs(pred.z[:, :, 0] - pred.measured[:, :, 0]) < 20 * NOISE)  # from the measured states
    truth = structure_runs(TRUTH, offset_record, 0.25, OFFSETS)
    assert pred.score_percent <= 2 * truth.score_percent + 0.05, (pred.score_percent, truth.score_percent)
    assert est.score(offset_record, window_s=0.25) == pred.score_percent and "every channel" in pred.metric
    # simulate runs the structure too, from every channel's measured state at the record's first sample
    run = est.simulate(offset_record.segment(0, 256))
    assert run.z.shape == (1, 2, 256) and not run.diverged[0]
    assert np.all(np.abs(run.z[0, :, 0] + OFFSETS - offset_record.channels[:, 0]) < 20 * NOISE)
    # and its equations are the structure's: one line per DOF, the element's force +g on DOF 2 and -g on DOF 1, then
    # g's law of r = z2 - z1 with the element's own numbers
    lines = est.equations(digits=6)
    assert len(lines) == 3 and lines[0].startswith(f"{FIXTURE['m']:.6g} z1''") and " - g = " in lines[0]
    assert " + g = " in lines[1] and lines[2].startswith("g = ") and lines[2].endswith("r = z2 - z1")
    assert f"{est.structure_.element.k3:.6g} r^3" in lines[2]


def test_a_structures_simulate_starts_from_each_channels_least_error_state(fits, offset_record):
    # simulate(record) starts the structure where a single DOF's starts: each channel's least-error state at the
    # record's first sample (``free_run_states``), as the held-out windows do. From 40 starts over the record (0.5 s
    # records: their first sample is an edge, where a smoothed velocity errs most), the fit's run misses the first
    # 0.25 s by less than half what a run from the band-smoothed states (NSI's basis) misses, at the median (measured:
    # 15 um against 1.1 mm here; with the truth on a 60 s record and 128-sample records, 16 um against 54 um)
    from negstiff.models.structure import simulate_structures

    est, _ = fits[NSI]
    n, w = offset_record.n, int(0.25 * FS)
    ours, band = [], []
    for s in range(0, n - 2 * w, n // 40):
        seg = offset_record.segment(s, s + 2 * w)
        run = est.simulate(seg)
        zs, vs, _ = seg.channel_states(est.structure_.place)
        x0 = np.concatenate([zs[:, 0] - est.offsets_, vs[:, 0]])[None]
        old = simulate_structures(est.structure_, seg.u[None], seg.dt, x0, input_kind="base_acc")
        for z, out in ((run.z[0], ours), (old.z[0], band)):
            out.append(np.sqrt(np.mean((z[:, :w] + np.asarray(est.offsets_)[:, None] - seg.channels[:, :w]) ** 2)))
    assert np.median(ours) < 0.5 * np.median(band), (np.median(ours), np.median(band))


@pytest.mark.parametrize("method", [NSI, SINDy])
def test_a_device_on_a_fixture_is_identified_whatever_each_lasers_zero(fits, method):
    # the physics does not depend on where each laser reads zero: the modes within 1 % in frequency and 10 % in
    # damping, k1-k3 within 5 %, c within 10 % (the acceptance), each channel's zero found to well within the
    # 0.1 mm an unmodelled offset moved SINDy's k1 by 13 % (a few um: the constant forces over the springs'
    # stiffness), and no warning: a right model misses its held-out windows by what noise and chaos leave any model
    est, caught = fits[method]
    for well in ("minus", "plus"):
        for got, true in zip(est.modal_[well], TRUTH.modes(well), strict=True):
            assert got.f_hz == pytest.approx(true.f_hz, rel=0.01), (well, got, true)
            assert got.zeta == pytest.approx(true.zeta, rel=0.10), (well, got, true)
    for k in ("k1", "k2", "k3"):
        assert est.element_[k] == pytest.approx(getattr(DEVICE, k), rel=0.05), k
    assert est.element_["c"] == pytest.approx(DEVICE.c, rel=0.10)
    assert np.allclose(est.offsets_, OFFSETS, atol=2e-5), est.offsets_
    assert not caught, caught
    out = est.result()
    assert out["dofs"] == 2 and out["element_at"] == [1, 2] and len(out["offsets_m"]) == 2
    assert {"modal", "element", "linear", "equilibria", "validation", "warnings", "refinement"} <= set(out)


def test_refined_by_output_error_nsi_and_sindy_agree_on_a_structure(fits):
    # both methods end with the one output-error refinement (refine.refine_stage, a single DOF's too) over every
    # channel, the channels' zeros refined with the element and the fixture: their equation-error elements differ
    # (k2 +0.67 % and +0.47 % off the truth, NSI's damping +0.22 %, measured) and their refined ones agree to the
    # noise: every coefficient within 0.3 % of the truth (measured 0.001-0.09 %; 1 um of sensor noise on mm of
    # motion) and within 0.2 % of each other, each zero within 1 um (measured 0.15 um), the fixture's spring
    # within 0.01 % (measured 1e-3 %). The refinement is kept: it predicts the held-out windows within 2 % of the
    # equation error's (the noise floor both sit at)
    refined = {}
    for method, (est, _) in fits.items():
        res = est.result_
        assert res.refinement["applied"], res.refinement["reason"]
        assert set(res.refinement["standard_errors"]) == set(res.refinement["parameters"])
        assert res.initial_model != res.model  # the equation error's element is kept beside it
        for k in ("k1", "k2", "k3", "c", "c_nl"):
            assert getattr(res.model, k) == pytest.approx(getattr(DEVICE, k), rel=3e-3), (method.__name__, k)
        assert np.allclose(res.offsets_m, OFFSETS, atol=1e-6), res.offsets_m
        assert res.structure.K[0, 0] == pytest.approx(TRUTH.K[0, 0], rel=1e-4)
        refined[method] = res.model
    for k in ("k1", "k2", "k3", "c", "c_nl"):
        assert getattr(refined[NSI], k) == pytest.approx(getattr(refined[SINDy], k), rel=2e-3), k


def test_output_error_refinement_of_a_structure_finds_the_truth_from_a_start_off_by_percents(offset_record):
    # the refinement alone (refine.refine on a Structure, the channels' zeros given): from the element's k1, k3 and
    # c 3-10 % off, the fixture's spring 3 % off and each channel's zero 20 um off, the output error over the
    # identification part's windows reaches the truth: k1-k3, c, c_nl within 0.3 % (measured 0.003-0.09 %), the
    # fixture's spring within 0.01 %, each zero within 1 um (measured 0.08 um); the element's constant held at the
    # weight its frame pins
    rec = offset_record
    element = Model(**{**DEVICE.to_dict(), "k1": 1.03 * DEVICE.k1, "k3": 1.05 * DEVICE.k3, "c": 1.1 * DEVICE.c})
    K = np.array(TRUTH.K)
    K[0, 0] *= 1.03
    start = Structure(TRUTH.masses, element, K, TRUTH.C, TRUTH.place)
    r = refine(start, rec.segment(0, int(0.8 * rec.n)), held=("k0",), offsets=OFFSETS + np.array([2e-5, -2e-5]))
    assert isinstance(r.model, Structure) and "K[1,1]" in r.parameters and "offset[2]" in r.parameters
    for k in ("k1", "k2", "k3", "c", "c_nl"):
        assert getattr(r.model.element, k) == pytest.approx(getattr(DEVICE, k), rel=3e-3), k
    assert r.model.element.k0 == start.element.k0
    assert r.model.K[0, 0] == pytest.approx(TRUTH.K[0, 0], rel=1e-4)
    assert np.allclose(r.offsets, OFFSETS, atol=1e-6), r.offsets


def test_a_structure_is_judged_as_a_single_dof_is(offset_record):
    # the one judgement (plausibility.judgement, model_warnings), a single DOF's model being the structure of one
    # DOF on the base: the truth passes it without a line; its element's damping negative, a damper matrix that
    # feeds energy in, a structure with no damping on a record its random input does work on (the energy balance),
    # a held-out error beyond the record's rms, a method's own modes 20 % off the structure's (each of both wells'
    # two modes) and an element whose wells lie ten times beyond the relative motion's stroke are each said
    from negstiff.inference.steps.plausibility import judgement, model_warnings
    from negstiff.models.structure import Mode

    rec = offset_record
    fine = {"rms_percent": 1.0}
    modal = {w: TRUTH.modes(w) for w in ("minus", "plus")}
    assert judgement(TRUTH, rec, fine, modal, modal, offsets=OFFSETS) == []
    assert model_warnings(TRUTH, rec, OFFSETS) == []

    def said(structure, validation=fine, own=None):
        return " | ".join(judgement(structure, rec, validation, modal, own, offsets=OFFSETS))

    def element(**kw):
        return TRUTH.with_element(Model(**{**DEVICE.to_dict(), **kw}))

    assert "negative viscous damping c = -0.1" in said(element(c=-0.1))
    feeding = np.array(TRUTH.C)
    feeding[0, 0] = -1.0
    assert "damping matrix has the eigenvalue -1" in said(
        Structure(TRUTH.masses, DEVICE, TRUTH.K, feeding, TRUTH.place)
    )
    undamped = Structure(TRUTH.masses, Model(**{**DEVICE.to_dict(), "c": 0.0, "c_nl": 0.0}), TRUTH.K, None, TRUTH.place)
    assert "the model has no damping, but the record dissipates" in said(undamped)
    assert "worse than predicting zero" in said(TRUTH, {"rms_percent": 150.0})
    # where a right model misses the held-out part as much (a decay rung down into its noise), the part judges nothing
    at_noise = said(TRUTH, {"rms_percent": 150.0, "floor_percent": 200.0})
    assert "at the sensors' noise" in at_noise and "worse than predicting zero" not in at_noise
    assert "worse than predicting zero" in said(TRUTH, {"rms_percent": 150.0, "floor_percent": 20.0})
    off = {w: [Mode(1.2 * m.f_hz, m.zeta, m.shape) for m in ms] for w, ms in modal.items()}
    assert said(TRUTH, own=off).count("contradicts the model's own linearisation") == 4
    far = model_warnings(TRUTH.with_element(Model(**{**DEVICE.to_dict(), "k3": DEVICE.k3 / 100})), rec, OFFSETS)
    assert len(far) == 2 and all("beyond the stroke" in w for w in far), far


def test_a_model_that_misses_the_held_out_windows_warns(offset_record):
    # a stiffness 3 % off misses the held-out windows by many times what a right model misses on a record of its
    # own (measured ~20 % against ~2 %): one warning, in the result and through Python's warnings
    rec = offset_record
    wrong = TRUTH.with_element(Model(**{**DEVICE.to_dict(), "k3": 1.03 * DEVICE.k3}))
    n_id = int(0.8 * rec.n)
    with pytest.warns(NegstiffWarning, match="misses its own record's held-out windows"):
        res = structure_result("sindy", rec, wrong, OFFSETS, n_id, None, [], {}, {})
    assert any("held-out windows" in w for w in res.warnings)
    right = free_run_error(TRUTH, rec, n_id, offsets=OFFSETS)["rms_percent"]
    assert res.validation["rms_percent"] > 2 * right


def test_a_structures_file_is_read_through_the_one_reader(tmp_path):
    # z1 ... zN with their units and a column map, as any record: converted to SI per channel, checked per channel
    u, z = rk4_fixture_record(duration=2.0, seed=2, device=DEVICE)
    t = np.arange(u.size) / FS
    path = write_csv(tmp_path / "lab.csv", {"t": t, "base_acc": u, "z1 [mm]": 1e3 * z[0], "LASER2 [mm]": 1e3 * z[1]},
                     {"masses": "1.0, 0.2"})  # fmt: skip
    rec = load(path, columns="z2=LASER2*0.001")
    assert rec.n_dof == 2 and rec.masses == (1.0, 0.2) and rec.fs == pytest.approx(FS)
    assert np.allclose(rec.z, z, rtol=1e-8, atol=1e-12)
    one = load(write_csv(tmp_path / "one.csv", {"t": t, "base_acc": u, "z1": z[1]}, {"masses": "0.2"}))
    assert one.n_dof == 1 and one.z.ndim == 1 and one.mass == 0.2  # N = 1 is the single DOF's record
    bad = z.copy()
    bad[1, 10] = np.nan
    with pytest.raises(InputError, match="z2 is NaN or inf at row 11"):
        from_arrays(u, bad, FS, masses=(1.0, 0.2))
    with pytest.raises(InputError, match="needs the element's place"):
        NSI().fit(from_arrays(u, z, FS, masses=(1.0, 0.2)))
    with pytest.raises(InputError, match="masses"):
        SINDy(element="1-2").fit(from_arrays(u, z, FS))
    # a force record of a structure without masses: the refusal names what reads it (NSI through its sensors),
    # not only how to give masses a lab may not know (a ground vibration test's)
    forced = from_arrays(u, z, FS, input_name="force", force_dof=1)
    for refuses in (SINDy(element="1-2"), Posterior(element="1-2"), Discrepancy(element="1-2")):
        with pytest.raises(InputError, match=r"masses are not given .*only NSI reads a structure, through its sensors"):
            refuses.check(forced)
    with pytest.raises(InputError, match=r"NSI\(refine=True\): .*without masses.*not refined by output error"):
        NSI(element="1-2", refine=True).fit(from_arrays(u, z, FS))  # a state-space structure's: refused, not ignored
