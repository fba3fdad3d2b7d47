"""Laws as parts every identification reads (``models.laws``), on records negstiff did not make: a magnet
harvester, oblique springs, a septic polynomial and the reference device's rod frame, each written with numpy,
scipy or a compiled RK4 of ``tests/law_records.py``'s own, through a lab's sensor chain (an absolute vibrometer of
unknown gain drifting, a laser's zero off, coarse sampling).

Each record is compared in its own frame: a laser's zero and a velocity integral's constant are the lab's, so a
well's position is the truth's plus the record's frame offset (the mean of the record's z minus the truth's).
"""

import warnings

import numpy as np
import pytest
from law_records import magnet_chaos_record, oblique_springs_record, rod_frame_record, septic_record

from negstiff import NSI, SINDy, pin_frame
from negstiff.inference.steps.shape import fit_shape
from negstiff.models import Model, laws, simulate
from negstiff.models.reference import reference_solution

WRITERS = {"rod_frame": rod_frame_record, "septic": septic_record, "oblique_springs": oblique_springs_record,
           "magnet": magnet_chaos_record}  # fmt: skip
LAW_OF = {"rod_frame": "geometric", "septic": "septic", "oblique_springs": "oblique_springs", "magnet": "magnet"}
DURATION = {"rod_frame": 60.0, "septic": 60.0, "oblique_springs": 60.0, "magnet": 120.0}


@pytest.fixture(scope="module")
def records(tmp_path_factory):
    """Each record, read as a user reads it, its z made physical (``pin_frame``), with its truth and frame offset."""
    out = {}
    folder = tmp_path_factory.mktemp("laws")
    for name, writer in WRITERS.items():
        r = writer(folder, duration=DURATION[name])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            rec = pin_frame(r.load())
        t0 = int(round((r.truth.t.size - rec.n) / 2))  # the loader trims the same span off either end
        offset = float(np.mean(rec.z - r.truth.z[t0 : t0 + rec.n]))
        out[name] = (r, rec, offset)
    return out


def test_a_shaped_law_simulates_as_scipy_integrates_it():
    # The simulator's table of a magnet's dipole force (cubic Hermite segments over +-8 gaps) integrates as scipy's
    # DOP853 integrates the formula itself: in-well, 8 Hz, RK4 at 8 substeps, the error is RK4's own O(h^4), far
    # below a micrometre on millimetres of motion.
    m, d = 0.05, 0.02
    model = Model(m=m, k1=-1944.8 * m, k2=0.0, k3=0.0, k0=0.0, c=0.17, extra={"magnet": {"A": 5.62e-6 * m, "d": d}})
    fs = 512.0
    t = np.arange(0, 8.0, 1 / fs)
    u = 0.5 * np.sin(2 * np.pi * 8.0 * t)
    z0 = model.equilibria().z_plus
    sim = simulate(model, u, 1 / fs, z0=z0, substeps=8).z[0]
    ref = reference_solution(model, u, 1 / fs, z0)
    assert np.max(np.abs(sim - ref)) < 1e-4 * np.ptp(ref)


@pytest.mark.parametrize("name", ["rod_frame", "septic", "oblique_springs", "magnet"])
def test_the_shape_of_a_law_is_the_records(records, name):
    # Variable projection on the weak form finds the shaped part's nonlinear parameters: the rod frame's length and
    # angle, the springs' half-span, the magnets' gap, each within 2 % of the truth's (the equation error's
    # noise floor is far below: the shapes are sharp minima of the weak residual).
    r, rec, _ = records[name]
    fit = fit_shape(rec, LAW_OF[name], "quadratic")
    p = r.truth.params
    if name == "rod_frame":
        assert fit.shape["rod_frame"]["L"] == pytest.approx(p["L"], rel=0.02)
        assert fit.shape["rod_frame"]["alpha_deg"] == pytest.approx(p["alpha_deg"], rel=0.02)
    elif name == "oblique_springs":
        assert fit.shape["oblique_springs"]["a"] == pytest.approx(p["a"], rel=0.02)
    elif name == "magnet":
        assert fit.shape["magnet"]["d"] == pytest.approx(p["d"], rel=0.02)
    else:
        assert fit.shape == {}


def _force_error(model: Model, truth, offset: float, stroke) -> float:
    """The rms difference of the model's and the truth's force per unit mass over the stroke, relative to the
    truth's rms force there (the truth's force in the record's frame: K(z - offset))."""
    z = np.linspace(stroke[0], stroke[1], 201)
    k_true = truth.force(z - offset)
    k_model = model.restoring_force(z) / model.m
    return float(np.sqrt(np.mean((k_model - k_true) ** 2)) / np.sqrt(np.mean(k_true**2)))


@pytest.mark.parametrize("method", [NSI, SINDy])
@pytest.mark.parametrize("name", ["rod_frame", "septic", "oblique_springs"])
def test_each_method_reads_the_records_law(records, name, method):
    # With the truth's law named, each method finds the wells within 2 % of their positions (in the record's
    # frame), their underlying-linear frequencies within 2 % and their damping ratios within 10 %, and a force
    # within 3 % rms of the truth's over the stroke.
    r, rec, offset = records[name]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = method(law=LAW_OF[name]).fit(rec).result_
    truth = r.truth
    eq = res.equilibria
    for well, z in truth.wells.items():
        got = eq.z_plus if well == "plus" else eq.z_minus
        half = 0.5 * (truth.stroke[1] - truth.stroke[0])
        scale = abs(z) if abs(z) > 0.05 * half else half  # a well at the origin: 2 % of the stroke's half-width
        assert abs(got - (z + offset)) < 0.02 * scale, (well, got, z + offset)
        assert res.modal[well]["f_hz"] == pytest.approx(truth.f_hz[well], rel=0.02)
        assert res.modal[well]["zeta"] == pytest.approx(truth.zeta[well], rel=0.10)
    stroke = np.quantile(rec.z, (0.005, 0.995))
    assert _force_error(res.model, truth, offset, stroke) < 0.03
    assert res.settings["law"] == LAW_OF[name]


def test_every_law_is_a_composition_of_registered_parts():
    # A law is one entry: its parts are the registry's, its columns map onto a model's fields, and a law added in a
    # test is read by name and then gone.
    for law in laws.LAWS:
        shape = law.shape_guesses((-0.03, 0.03))[0]
        z = np.linspace(-0.02, 0.02, 11)
        cols = law.columns(z, np.full(11, 0.1), shape)
        assert cols.shape == (11, len(law.column_list(shape)))
        assert np.all(np.isfinite(cols))
    toy = laws.Law("quartic_only", "restoring", ("k0", "k1"), ("quartic_stiffness",), "K = k0 - k1 z + k4 z^4")
    with laws.registered(toy):
        assert laws.get("quartic_only") is toy
        assert "quartic_only" in laws.names("restoring")
    with pytest.raises(ValueError, match="unknown restoring law 'quartic_only'"):
        laws.get("quartic_only", "restoring")


def test_every_law_keeps_a_scalars_shape():
    # A model of any law evaluated at one z gives one number: its force, stiffness and potential (a backbone's
    # energy levels read the potential at single points; a spline's gave an array of one and the report's backbone
    # of FrID's decay failed with a TypeError)
    for law in laws.names("restoring"):
        lw = laws.get(law)
        shape = lw.shape_guesses((-0.03, 0.03))[0]
        n = len(lw.column_list(shape))
        model = laws.compose(lw, laws.get("viscous"), np.r_[np.linspace(-2.0, -1.0, n), 0.5], 1.0, shape)
        for z in (0.01, np.float64(0.01), np.array(0.01)):
            for f in (model.restoring_force, model.stiffness, model.potential):
                assert np.shape(f(z)) == (), (law, f.__name__)
        assert np.shape(model.potential(np.zeros((2, 3)))) == (2, 3), law


def test_an_unknown_law_and_a_law_on_a_structure_are_refused_in_one_line(tmp_path):
    # An unknown name is refused by the parameter's declaration (the CLI reads the same), naming the known laws;
    # a law on a structure's record (an element's own basis) is refused before any work.
    from negstiff import Rig, load
    from negstiff.errors import InputError

    with pytest.raises(InputError, match="law must be one of 'cubic'"):
        NSI(law="parabola")._validate_params()
    with pytest.raises(InputError, match="damping must be one of 'viscous'"):
        SINDy(law="magnet", damping="cubic")._validate_params()
    rec = load(Rig.device_on_fixture(seed=1).random(duration=8.0).write(tmp_path / "fixture.csv"))
    # a structure with its masses: SINDy's element has its own library, NSI's the cubic (NSI reads a law on a
    # structure without masses: test_structure_state_space)
    for method, said in ((NSI, "a structure with its masses reads the cubic element"),
                         (SINDy, "a law is read on a single DOF's record")):  # fmt: skip
        with pytest.raises(InputError, match=said):
            method(law="magnet", element="1-2").fit(rec)


def test_the_device_and_the_geometric_law_are_one_force():
    # The GA's and the posterior's device (E, alpha, m with the drawings' geometry) and the geometric law's model
    # (the rod frame's part with the device's k_f, D0, L, alpha) are the same force: equal restoring force and
    # stiffness over the stroke, the same wells and well frequencies, and the same motion when simulated (the
    # device's compiled geometry against the law's table).
    from negstiff.models import AS_BUILT

    law = AS_BUILT.law_model()
    lo, hi = AS_BUILT.stroke_limits()
    z = np.linspace(0.9 * lo, 0.9 * hi, 301)
    scale = np.max(np.abs(AS_BUILT.restoring_force(z)))
    assert np.allclose(law.restoring_force(z), AS_BUILT.restoring_force(z), rtol=0, atol=1e-12 * scale)
    for well in ("minus", "plus"):
        assert law.uls(well).z_ref == pytest.approx(AS_BUILT.uls(well).z_ref, rel=1e-9)
        assert law.uls(well).f_hz == pytest.approx(AS_BUILT.uls(well).f_hz, rel=1e-9)
    fs = 512.0
    u = 6.0 * np.sin(2 * np.pi * 9.0 * np.arange(0, 4.0, 1 / fs))
    a, b = simulate(AS_BUILT, u, 1 / fs).z[0], simulate(law, u, 1 / fs).z[0]
    assert np.max(np.abs(a - b)) < 1e-6 * np.ptp(a)  # the table's interpolation error, far below any noise


@pytest.mark.slow
@pytest.mark.parametrize("method", [NSI, SINDy])
@pytest.mark.parametrize("name", ["rod_frame", "septic", "oblique_springs", "magnet"])
def test_the_law_chosen_is_the_truths_or_as_good(records, name, method):
    # Every law compared on what it predicts (law="auto"): the one chosen is the truth's, or one whose force is
    # within 3 % rms of the truth's over the stroke; its wells within 2 % (in the record's frame), their
    # underlying-linear frequencies within 2 % and damping ratios within 10 %.
    r, rec, offset = records[name]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = method(law="auto").fit(rec).result_
    choice = res.details["law_choice"]
    stroke = np.quantile(rec.z, (0.005, 0.995))
    assert choice["chosen"] == LAW_OF[name] or _force_error(res.model, r.truth, offset, stroke) < 0.03, choice
    truth = r.truth
    for well, z in truth.wells.items():
        got = res.equilibria.z_plus if well == "plus" else res.equilibria.z_minus
        half = 0.5 * (truth.stroke[1] - truth.stroke[0])
        scale = abs(z) if abs(z) > 0.05 * half else half
        assert abs(got - (z + offset)) < 0.02 * scale, (well, got, z + offset)
        assert res.modal[well]["f_hz"] == pytest.approx(truth.f_hz[well], rel=0.02)
        assert res.modal[well]["zeta"] == pytest.approx(truth.zeta[well], rel=0.10)


def test_a_laws_numerical_failure_is_said_as_the_fits():
    # numpy's bare "SVD did not converge in Linear Least Squares" stood in the law comparison's table on FrID's decay
    # (the rod frame's columns at a strain gauge's scale), read as a fault of negstiff's
    from negstiff.inference.steps.law_choice import said

    text = said(np.linalg.LinAlgError("SVD did not converge in Linear Least Squares"))
    assert text.startswith("its least-squares fit failed on this record") and "SVD did not converge" in text
    assert said(ValueError("a  plain\n message")) == "a plain message"


def test_a_law_whose_identified_parts_are_not_physical_is_said_so():
    # NSI's rod frame on FrID's strain-gauge decay (a beam between magnets, no rod frame): the frame's stiffness it
    # identifies is negative; the model's own check ("rod_frame needs k_f, D0, L > 0 ...") reached the user bare
    from pathlib import Path

    from negstiff import load
    from negstiff.inference.estimators.nsi import NSIError

    frid = Path(__file__).parents[1] / "data" / "frid_magneto_mechanical_decay"
    frid = frid / "decay_f_42p05_ampl_2p0_0_12p1-19p1s.lvm"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rec = load(frid, columns="force=Sine with Gaussian Noise,z=Strain_0", gravity=0.0)
        with pytest.raises(NSIError, match="the geometric law's identified parameters are not physical"):
            NSI(law="geometric").fit(rec)
