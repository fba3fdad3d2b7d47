"""Structures of several degrees of freedom (issue "Beyond one degree of freedom"): the single-DOF model is the
structure of one DOF, the structure's statics and modes are physics, and NSI and SINDy identify a device on a
fixture that is not rigid from a record written here with plain numpy (``records.rk4_fixture_record``)."""

import dataclasses
import json
import math
import warnings

import numpy as np
import pytest
from records import FIXTURE, TRUTH, assert_result_answers_alike, rk4_fixture_record, stepped_sweep, write_csv

from negstiff import NSI, Discrepancy, InputError, Model, SINDy
from negstiff.inference.record.measurement import from_arrays
from negstiff.inference.record.reading import load
from negstiff.inference.steps.validation import restarted_structure_runs as free_run_error
from negstiff.models.simulator import simulate_batch, stage_input
from negstiff.models.structure import Structure, simulate_structures


def _command(capsys, name, *args):
    """``negstiff NAME ARGS`` in this process: its exit code and what it said on stderr (its warnings among it)."""
    from negstiff.cli import main

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the CLI says them on stderr
        code = main([name, *map(str, args)])
    return code, capsys.readouterr().err


FS = 512.0
ON_FIXTURE = Structure.on_fixture(TRUTH, fixture_mass=FIXTURE["m"], fixture_hz=FIXTURE["f_hz"],
                                  fixture_zeta=FIXTURE["zeta"])  # fmt: skip


@pytest.mark.parametrize("input_kind", ["base_acc", "force"])
@pytest.mark.parametrize("staged", [False, True])
def test_the_single_dof_model_is_the_structure_of_one_dof(input_kind, staged):
    # one Runge-Kutta loop for every N: the single-DOF model takes its fused per-member step, any other structure
    # the stage-wise step over the batch; the same operations in the same order, so the same numbers to the last
    # bit, friction and a stop included. ``Structure.single`` checks that the structure's arrays are the model's; the
    # stage-wise step is checked on the model's DOF inside a structure of two (a mass beside it, not coupled to it:
    # on its own spring, the linear structure's loops run; without one, under a force at DOF 1, they are skipped)
    model = Model(m=0.2, k1=426.0, k2=-3060.0, k3=7.77e5, c=0.35, c_nl=0.1,
                  extra={"coulomb_friction": 0.02, "end_stop": {"k": 2e4, "z": 0.03}})  # fmt: skip
    rng = np.random.default_rng(3)
    u = rng.normal(0.0, 8.0 if input_kind == "base_acc" else 1.5, 4096)
    drive = stage_input(u) if staged else u
    ref = simulate_batch(model.kernel_params(), "polynomial", drive, 1 / FS, np.array([0.02, 0.0]),
                         input_kind=input_kind, staged=staged, store_velocity=True)  # fmt: skip
    res = simulate_structures(Structure.single(model), drive, 1 / FS, np.array([0.02, 0.0]), input_kind=input_kind,
                              staged=staged, store_velocity=True)  # fmt: skip
    assert np.array_equal(res.z[:, 0], ref.z) and np.array_equal(res.z_dot[:, 0], ref.z_dot)
    springs = [(np.diag([0.0, 1e4]), np.diag([0.0, 2.0]))] + ([(None, None)] if input_kind == "force" else [])
    for K, C in springs:
        beside = Structure((model.m, 1.0), model, K, C, at=(0, 1))
        res2 = simulate_structures(beside, drive, 1 / FS, np.array([0.02, 0.0, 0.0, 0.0]), input_kind=input_kind,
                                   force_dof=1, staged=staged, store_velocity=True)  # fmt: skip
        assert np.array_equal(res2.z[:, 0], ref.z) and np.array_equal(res2.z_dot[:, 0], ref.z_dot)


def test_one_dof_structure_has_the_models_wells_and_underlying_linear_system():
    s = Structure.single(TRUTH)
    eq = TRUTH.equilibria()
    for well in ("minus", "plus"):
        (mode,) = s.modes(well)
        uls = TRUTH.uls(well)
        assert s.equilibria()[well][0] == pytest.approx(eq.well(well), rel=1e-12)
        assert mode.f_hz == pytest.approx(uls.f_hz, rel=1e-12) and mode.zeta == pytest.approx(uls.zeta, rel=1e-12)


def test_modes_solve_the_quadratic_eigenproblem():
    # lambda^2 M phi + lambda C phi + K phi = 0 for each mode; the fixture's mode is mostly the fixture's
    mass = np.diag(ON_FIXTURE.masses)
    for well in ("minus", "plus"):
        K, C = ON_FIXTURE.linear(well)
        modes = ON_FIXTURE.modes(well)
        assert len(modes) == 2 and modes[0].f_hz < modes[1].f_hz
        for m in modes:
            w = 2 * np.pi * m.f_hz
            lam = w * (-m.zeta + 1j * np.sqrt(1 - m.zeta**2))
            D = lam**2 * mass + lam * C + K
            assert abs(np.linalg.det(D)) < 1e-9 * np.linalg.norm(K) ** 2
        assert abs(modes[1].shape[0]) == pytest.approx(1.0) and abs(modes[1].shape[1]) < 0.3
        # the device's mode is pulled below the device alone on a rigid table by the fixture's compliance
        assert modes[0].f_hz < TRUTH.uls(well).f_hz


def test_a_spring_beside_the_element_moves_its_equilibria():
    # element on the base with a linear spring k_p beside it: F(r) + k_p r = 0
    k_p = 150.0
    s = Structure((TRUTH.m,), TRUTH, np.array([[k_p]]), None, (0, 1))
    roots = np.roots([TRUTH.k3, TRUTH.k2, -TRUTH.k1 + k_p, TRUTH.k0])
    real = np.sort(roots[np.abs(roots.imag) < 1e-9].real)
    assert s.equilibria()["minus"][0] == pytest.approx(real[0], rel=1e-9)
    assert s.equilibria()["plus"][0] == pytest.approx(real[2], rel=1e-9)
    # on the fixture, the fixture's spring is at rest when the element's force vanishes
    zf = ON_FIXTURE.equilibria()["plus"]
    assert zf[0] == pytest.approx(0.0, abs=1e-15) and TRUTH.restoring_force(zf[1]) == pytest.approx(0.0, abs=1e-9)


def test_structure_inputs_are_checked_in_one_line():
    with pytest.raises(InputError, match="mass"):
        Structure((1.0, 0.3), TRUTH, None, None, (1, 2))  # the element moves 0.2 kg, m2 says 0.3
    with pytest.raises(InputError, match="I-J"):
        Structure((1.0, 0.2), TRUTH, None, None, (2, 2))
    with pytest.raises(InputError, match="symmetric"):
        Structure((1.0, 0.2), TRUTH, np.array([[1.0, 2.0], [0.0, 1.0]]), None, (1, 2))


@pytest.fixture(scope="module")
def fixture_record():
    # 300 s of random cross-well motion, 512 Hz, 1 um noise on both DOFs (the issue's acceptance record)
    u, z = rk4_fixture_record(duration=300.0, rms=12.0, seed=1)
    return from_arrays(u, z, FS, masses=(FIXTURE["m"], TRUTH.m), source="fixture record")


@pytest.mark.parametrize("method", [NSI, SINDy])
def test_device_on_a_flexible_fixture_is_identified(fixture_record, method):
    rec = fixture_record
    r = rec.z[1] - rec.z[0]
    assert np.count_nonzero(np.diff(np.sign(r - ON_FIXTURE.element_equilibria().z_0))) > 100  # cross-well
    est = method(element="1-2").fit(rec)
    for well in ("minus", "plus"):
        for got, true in zip(est.modal_[well], ON_FIXTURE.modes(well), strict=True):
            assert got.f_hz == pytest.approx(true.f_hz, rel=0.01)
            assert got.zeta == pytest.approx(true.zeta, rel=0.10)
    for k in ("k1", "k2", "k3"):
        assert est.element_[k] == pytest.approx(getattr(TRUTH, k), rel=0.05), k
    assert est.element_["c"] == pytest.approx(TRUTH.c, rel=0.10)
    # predicts the held-out tail within twice what the truth itself does (noise and chaos: the floor)
    floor = free_run_error(ON_FIXTURE, rec, int(0.8 * rec.n))
    assert est.validation_["rms_percent"] <= 2 * floor["rms_percent"]
    out = est.result()
    assert set(out["modal"]) == {"minus", "plus"} and len(out["modal"]["plus"]) == 2
    assert_result_answers_alike(est)  # as a single DOF's and a state-space structure's result do
    if method is SINDy:  # its support chosen among the admissible ones, as a single DOF's (``selection.choose``)
        path = est.result_.details["path"]
        chosen = next(p for p in path if p["terms"] == est.result_.details["selected_terms"])
        assert chosen["restarted_diverged"] == 0 and chosen["escape_z"] is None and chosen["usable"]
    assert {"k1", "k2", "k3", "c", "c_nl", "extra"} <= set(out["element"]) and "linear" in out


def test_a_structures_own_estimates_agree_within_their_standard_errors_and_a_bias_is_caught():
    # as a single DOF's (tests/contract/test_predict.py): each method's own estimate of the device on its fixture
    # (110 s, 20 um of laser noise: the blocks of a third of the identification part long enough for SINDy's
    # selection) with its batch-means standard error, every block identified alone: NSI's and SINDy's every mode of
    # both wells agree within three combined standard errors (measured within 0.2), and a lab's sampling rate
    # mislabelled 3 % high moves SINDy's modes by 3 %: caught (the first mode 50 standard errors off, measured)
    from negstiff.report.sections import interval_section
    from negstiff.testing import assert_methods_agree

    u, z = rk4_fixture_record(duration=110.0, rms=12.0, seed=3, noise=2e-5)
    rec = from_arrays(u, z, FS, masses=(FIXTURE["m"], TRUTH.m), source="noisy fixture")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        nsi, sindy = NSI(element="1-2").fit(rec), SINDy(element="1-2").fit(rec)
        own_nsi, own_sindy = nsi.own_estimate(rec), sindy.own_estimate(rec)
        biased = from_arrays(u, z, FS * 1.03, masses=(FIXTURE["m"], TRUTH.m), source="noisy fixture, fs mislabelled")
        own_biased = SINDy(element="1-2").fit(biased).own_estimate(biased)
    for own, est in ((own_nsi, nsi), (own_sindy, sindy)):
        # the estimate is the fit's own (before its refinement), every mode and coefficient with its standard error
        assert own["model"]["k3"] == est.result_.initial_model.k3 and own["dofs"] == 2
        assert [len(own["modal"][w]) for w in ("minus", "plus")] == [2, 2]
        assert all(m["f_hz_se"] > 0 for w in own["modal"] for m in own["modal"][w])
        assert all(own["model_se"][k] > 0 for k in ("k1", "k2", "k3", "c"))
    assert_methods_agree(own_nsi, own_sindy, k=3)
    with pytest.raises(AssertionError, match="mode 1 own frequencies"):
        assert_methods_agree(own_nsi, own_biased, k=3)
    # the report's interval section holds each well's every mode and the element's coefficients
    ((_, (_, table)),) = [b for b in interval_section(own_nsi).blocks if b[0] == "table"]
    rows = [r[0] for r in table]
    assert "f_hz (minus, mode 2) [Hz]" in rows and "k3" in rows


def test_structure_record_file(tmp_path):
    u, z = rk4_fixture_record(duration=2.0, seed=2)
    t = np.arange(u.size) / FS
    path = write_csv(tmp_path / "two.csv", {"t": t, "base_acc": u, "z1": z[0], "z2": z[1]}, {"masses": "1.0,0.2"})
    rec = load(path)
    assert rec.n_dof == 2 and rec.masses == (1.0, 0.2) and rec.fs == pytest.approx(FS)
    assert np.allclose(rec.z, z, rtol=1e-9, atol=1e-15)
    bad = write_csv(tmp_path / "bad.csv", {"t": t, "base_acc": u, "z1": z[0], "z3": z[1]}, {"masses": "1.0,0.2"})
    with pytest.raises(InputError, match="z1 ... zN"):
        load(bad)
    nomass = write_csv(tmp_path / "nomass.csv", {"t": t, "base_acc": u, "z1": z[0], "z2": z[1]})
    with pytest.raises(InputError, match="masses"):
        _ = load(nomass).dof_masses  # a structure's identification needs them; reading the record does not
    with pytest.raises(InputError, match="masses"):
        load(path, masses=[1.0])


def _stepped_sweep(amps, f_hz, state, periods=120, steps=128, full=False):
    """The device on the fixture under b'' = A sin(2 pi f t), A stepped through ``amps`` (each step going on from the
    last state, as a shaker test does), the tests' plain RK4 (``records.stepped_sweep``: ``fixture_rk4_step``'s,
    compiled; ``steps`` a period); per amplitude, the spread of r = z2 - z1 over the last 8 forcing periods at phase 0
    (0 on a period-1 orbit); ``full``: per amplitude (spread, min r, max r over the last period, the final state)."""
    rows = stepped_sweep(amps, f_hz, state, periods=periods, steps=steps)
    return rows if full else np.array([row[0] for row in rows])


@pytest.mark.parametrize(("well", "first", "amps"), [
    ("plus", "period_doubling", np.r_[np.arange(2.0, 7.0, 0.5), np.arange(7.0, 8.6, 0.05)]),
    ("minus", "fold", np.r_[np.arange(2.0, 7.0, 0.5), np.arange(7.0, 8.5, 0.05)]),
])  # fmt: skip
def test_continuation_of_the_device_on_the_fixture_finds_where_a_stepped_test_leaves_the_orbit(well, first, amps):
    # at 9 Hz the positive well's period-1 orbit first doubles; the negative well's first meets a fold (its first
    # doubling lies on the resonant branch beyond, which an upward stepped test from rest does not follow: the next
    # test); a stepped test stays on the period-1 orbit up to there and leaves it within one step of it (0.05 m/s^2,
    # 0.6 %)
    from negstiff import nfrc

    curve = nfrc(ON_FIXTURE, freq=9.0, amplitude=(1.0, 20.0), well=well, max_period=1)
    met = curve["bifurcations"][0]  # the first along the branch from the well's rest
    assert met["type"] == first
    a_bif = met["amplitude"]
    start = ON_FIXTURE.static_positions(ON_FIXTURE.element_equilibria().well(well))
    spread = _stepped_sweep(amps, 9.0, (start[0], start[1], 0.0, 0.0))
    left = np.flatnonzero(spread[3:] > 1e-6)  # the first three amplitudes settle from rest
    assert left.size and left[0] > 0, "the stepped test never stayed on (or never left) the period-1 orbit"
    a_step = amps[3:][left[0]]
    print(f"{well}: {first} at {a_bif:.4f} m/s^2 (continuation), stepped test leaves the orbit at {a_step:.2f}")
    assert abs(a_step / a_bif - 1) < 0.03, (a_step, a_bif)


def test_minus_wells_first_period_doubling_against_a_tapped_stepped_test():
    # the negative well's branch from rest folds at ~8 m/s^2 (above), back to a fold at ~1.7 m/s^2, and turns into
    # the resonant branch, which doubles its period first; a shaker test reaches that branch with a tap: from the
    # well's rest at 3 m/s^2, a 0.6 m/s kick of the device's mass settles on a second, larger period-1 orbit in the
    # same well. Stepped up from there it stays period-1 until it doubles: the period-2 orbit separates its
    # Poincare points by ~1 mm, a transient near the doubling (multiplier ~ -1, decaying ~1 % a period) by far less
    from negstiff import nfrc

    curve = nfrc(ON_FIXTURE, freq=9.0, amplitude=(1.0, 20.0), well="minus", max_period=1)
    a_pd = next(b["amplitude"] for b in curve["bifurcations"] if b["type"] == "period_doubling")
    start = ON_FIXTURE.static_positions(ON_FIXTURE.element_equilibria().well("minus"))
    rest, tapped = ((start[0], start[1], 0.0, tap) for tap in (0.0, 0.6))
    small, big = (_stepped_sweep([3.0], 9.0, state, periods=150, full=True) for state in (rest, tapped))
    (_, lo_s, hi_s, _), (_, lo, hi, state) = small[0], big[0]
    assert hi < 0 and hi - lo > 4 * (hi_s - lo_s), "the tap did not find the larger orbit in the negative well"
    amps = np.r_[3.5, 4.0, 4.5, np.arange(4.6, 5.6, 0.05)]
    rows = _stepped_sweep(amps, 9.0, state, full=True)
    left = [a for a, row in zip(amps, rows, strict=True) if row[0] > 1e-4]
    assert left and left[0] > amps[3], "the stepped test never stayed on (or never left) the period-1 orbit"
    print(f"minus: period doubling at {a_pd:.4f} m/s^2 (continuation), the stepped test doubles at {left[0]:.2f}")
    assert abs(left[0] / a_pd - 1) < 0.03, (left[0], a_pd)


def test_command_line_identifies_a_structure_and_refuses_a_wrong_one(tmp_path, capsys):
    import json

    u, z = rk4_fixture_record(duration=60.0, seed=4)
    t = np.arange(u.size) / FS
    data = write_csv(tmp_path / "two.csv", {"t": t, "base_acc": u, "z1": z[0], "z2": z[1]}, {"masses": "1.0,0.2"})

    def run(*args):
        return _command(capsys, "identify", *args)

    out = tmp_path / "r.json"
    # a structure's low-level FRFs (``negstiff frf --dofs 2``'s result: its modes, here the plus well's as a lab's
    # 0.3 m/s^2 test measured them: 0.1 % low) beside the identified modes (``--frf``): each mode to the nearest
    modes = [m.f_hz for m in ON_FIXTURE.modes("plus")]
    frf = tmp_path / "frf.json"
    frf.write_text(json.dumps({"dofs": [{"dof": 1}, {"dof": 2}], "modes": [{"f_hz": 0.999 * f} for f in modes]}))
    code, err = run("nsi", data, "--dofs", 2, "--element", "1-2", "--frf", frf, "-o", out)
    assert code == 0, err
    result = json.loads(out.read_text())
    assert [m["f_hz"] for m in result["modal"]["plus"]] == pytest.approx(modes, rel=0.01)
    compared = result["frf_comparison"]
    assert [(c["well"], c["mode"]) for c in compared] == [("plus", 1), ("plus", 2)]
    assert all(abs(c["difference_percent"]) < 1.2 for c in compared) and "plus well mode 2: identified" in err
    assert result["element"]["k3"] == pytest.approx(TRUTH.k3, rel=0.05) and result["element_at"] == [1, 2]
    for bad, says in ((("--dofs", 3, "--element", "1-2"), "z1 ... z2"), (("--dofs", 2), "--element"),
                      (("--dofs", 2, "--element", "3-2"), "J must be")):  # fmt: skip
        code, err = run("sindy", data, *bad, "-o", tmp_path / "no.json")
        assert code == 2 and says in err and len(err.strip().splitlines()) == 1
        assert not (tmp_path / "no.json").exists()
    # a wrong mass leaves the identified stiffness lopsided: said loudly, in the result too
    code, err = run("nsi", data, "--dofs", 2, "--element", "1-2", "--masses", "1.0,0.3", "-o", tmp_path / "w.json")
    assert code == 0 and "are the masses right?" in err
    assert any("are the masses right?" in w for w in json.loads((tmp_path / "w.json").read_text())["warnings"])


def test_command_line_posterior_reads_the_dofs_from_the_file(tmp_path, capsys):
    # negstiff posterior on a structure's file: N from its z1, z2 and '# masses:' (--dofs a check), the element
    # sampled with each channel's zero read (0.3 mm on z1 here, within 20 um); a wrong --dofs and a missing
    # --element are one line and exit 2 before any work, no output written
    import json

    u, z = rk4_fixture_record(duration=30.0, seed=3)
    t = np.arange(u.size) / FS
    data = write_csv(tmp_path / "two.csv", {"t": t, "base_acc": u, "z1": z[0] + 3e-4, "z2": z[1]},
                     {"masses": f"{FIXTURE['m']},{TRUTH.m}"})  # fmt: skip

    def run(*args):
        return _command(capsys, "posterior", *args)

    out = tmp_path / "p.json"
    code, err = run(data, "--element", "1-2", "--ensembles", 2, "--max-steps", 100, "--max-windows", 12, "-o", out)
    assert code == 0, err
    result = json.loads(out.read_text())
    assert result["dofs"] == 2 and result["element_at"] == [1, 2] and abs(result["offsets_m"][0] - 3e-4) < 20e-6
    assert result["parameters"]["k3"]["mean"] == pytest.approx(TRUTH.k3, rel=0.01)
    for bad, says in ((("--dofs", 3, "--element", "1-2"), "z1 ... z2"), ((), "element")):
        code, err = run(data, *bad, "-o", tmp_path / "no.json")
        assert code == 2 and says in err and len(err.strip().splitlines()) == 1
        assert not (tmp_path / "no.json").exists()


def test_structure_rig_records_are_seeded_and_read_back(tmp_path):
    from negstiff import Rig

    rig = Rig.device_on_fixture(TRUTH, seed=5)
    a, b = rig.random(duration=6.0, rms=10.0), rig.random(duration=6.0, rms=10.0)
    assert np.array_equal(a.z, b.z) and not np.array_equal(a.z, Rig.device_on_fixture(TRUTH, seed=6)
                                                           .random(duration=6.0, rms=10.0).z)  # fmt: skip
    # the lasers' noise and the double-integrated table: z off the truth by about the laser's 30 um, not more
    err = a.z - a.true["z"]
    assert 10e-6 < np.sqrt(np.mean(err[:, 512:-512] ** 2)) < 100e-6
    rec = load(a.write(tmp_path / "fixture.csv"))
    assert rec.n_dof == 2 and rec.masses == pytest.approx(rig.system.masses) and rec.fs == pytest.approx(FS)
    assert np.allclose(rec.z, a.z, rtol=1e-8, atol=1e-12)
    # the payload campaign: the element on the table moves DOF 1, the payload rides on it (DOF 2)
    pay = Rig.device_with_payload(TRUTH, payload_mass=0.05, payload_hz=30.0, seed=1).system
    assert pay.at == (0, 1) and pay.masses == (TRUTH.m, 0.05)
    plus = pay.modes("plus")
    assert plus[0].f_hz < TRUTH.uls("plus").f_hz and abs(plus[1].shape[1]) == pytest.approx(1.0)


OFFSET_POSTERIOR = {"element": "1-2", "n_ensembles": 2, "min_steps": 100, "max_steps": 300, "max_windows": 24,
                    "seed": 1}  # fmt: skip
"""A short element posterior (24 windows, 300 steps): its point, not its chains' convergence, is what is checked."""


@pytest.fixture(scope="module")
def offset_posterior():
    """30 s of the fixture record with its lasers' zeros 0.3 and -0.2 mm off, and its element posterior from SINDy."""
    from negstiff import Posterior

    u, z = rk4_fixture_record(duration=30.0, seed=3)
    offsets = np.array([3e-4, -2e-4])
    rec = from_arrays(u, z + offsets[:, None], FS, masses=(FIXTURE["m"], TRUTH.m))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a 300-step run has not converged: said, not the point here
        return rec, offsets, Posterior(**OFFSET_POSTERIOR).fit(rec)


def test_posterior_of_the_element_reads_each_channel_zero_it_is_not_told(offset_posterior):
    # the element's posterior on a record whose lasers' zeros sit 0.3 and -0.2 mm off the springs' loaded rest (a
    # laser's zero is arbitrary): the channels are taken to the structure's frame by SINDy's offsets, so the
    # element's stiffness comes out as on a zero-offset record (k1-k3 within 1 %, c within 5 %: the windowed least
    # squares' own bias, test below) and the offsets within 20 um (SINDy's, measured within 20 um on 120 s)
    rec, offsets, post = offset_posterior
    assert np.abs(np.array(post.offsets_) - offsets).max() < 20e-6
    par = post.result()["parameters"]
    for k in ("k1", "k2", "k3", "c", "c_nl"):
        assert par[k]["mean"] == pytest.approx(getattr(TRUTH, k), rel=0.01 if k.startswith("k") else 0.05), k
    assert post.structure_.n_dof == 2 and post.model_.k3 == pytest.approx(par["k3"]["mean"])


def test_the_element_posterior_starts_where_it_is_told(offset_posterior, tmp_path):
    # a structure's posterior starts from a given identification of the structure (its structure and each channel's
    # zero: NSI's here, SINDy is not run), as a single DOF's starts from a given model: it reads the same element, each
    # coefficient's mean within 2 sd (the wider posterior's) of the SINDy-started one's, and says where it started. The
    # start's linear parts are sampled: NSI's structure holds a spring and a damper from the device to the base
    # (-0.013 N/m) that SINDy's selection left out, nearly collinear with the element's k1 and c, which widens their
    # posterior 8x and 5x (measured: k1 425.9769 +- 0.024 against 425.9977 +- 0.0029, 0.87 of the wider sd apart).
    # A start that is not this record's structure is refused before any work, from Python and the command line
    from negstiff import NSI, InputError, Posterior
    from negstiff.cli import main

    rec, _, post = offset_posterior
    nsi = NSI(element="1-2").fit(rec)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        given = Posterior(**OFFSET_POSTERIOR, start=nsi.result_).fit(rec)
    start = given.result()["settings"]["start"]
    assert start["source"] == "given: nsi's identification" and start["structure"] == nsi.structure_.to_dict()
    ref, got = post.result()["parameters"], given.result()["parameters"]
    for k in ("k1", "k2", "k3", "c", "c_nl"):
        assert abs(got[k]["mean"] - ref[k]["mean"]) < 2 * max(ref[k]["sd"], got[k]["sd"]), (k, got[k], ref[k])
    back = Posterior.from_json(given.to_json())  # the start travels with the estimator's parameters
    assert back.start.to_json() == nsi.result_.to_json()
    other = dataclasses.replace(nsi.structure_, masses=(2 * FIXTURE["m"], TRUTH.m))
    for wrong, why in ((other, "masses"), (TRUTH, "starts a structure's posterior|Model"),
                       (Structure.single(TRUTH), "1 DOFs")):  # fmt: skip
        with pytest.raises(InputError, match=why):
            Posterior(element="1-2", start=wrong).check(rec)
    path, single = tmp_path / "rec.csv", tmp_path / "one.json"
    write_csv(path, {"t": np.arange(rec.n) / FS, "base_acc": rec.u, "z1": rec.channels[0], "z2": rec.channels[1]},
              {"masses": f"{FIXTURE['m']},{TRUTH.m}"})  # fmt: skip
    single.write_text(json.dumps(TRUTH.to_dict()))
    assert main(["posterior", str(path), "--element", "1-2", "--start", str(single), "-o", str(tmp_path / "p.json"),
                 "--quiet"]) == 2  # fmt: skip
    assert not (tmp_path / "p.json").exists()
    # the command reads a structure's identify result as the identification it is (its channels' zeros kept)
    ident = tmp_path / "nsi.json"
    ident.write_text(json.dumps(nsi.result()))
    assert main(["posterior", str(path), "--element", "1-2", "--start", str(ident), "--ensembles", "2", "--max-steps",
                 "500", "--max-windows", "24", "-o", str(tmp_path / "p.json"), "--quiet"]) == 0  # fmt: skip
    written = json.loads((tmp_path / "p.json").read_text())["settings"]
    assert written["start"]["source"] == start["source"] and written["start_offsets_m"] == list(nsi.offsets_)


def test_records_of_one_structure_are_fitted_together(offset_posterior, tmp_path):
    # two records of the fixture (another seed; its lasers 4x noisier, 1 -> 4 um, and their zeros elsewhere) fitted
    # together: the element and the linear structure shared, each record its own channels' zeros and sensor noise.
    # Each record's zeros come out as its own (within 20 um, as one record's) and each sigma as its lasers' noise
    # (within 10 %: the windows' model error adds little at 1 um, measured 1.0017 and 3.968 um); the records are
    # independent, so their information adds: the joint sd of each coefficient is 1 / sqrt(sum of 1 / sd^2) of the
    # records' alone, within 20 % (each sd an MCMC estimate of a few hundred effective draws, ~5 % each; measured
    # 0.90-0.95 of it). Records of two structures (other masses) are refused before any work; the design, which reads
    # one record's zeros, refuses the joint posterior with one line; the command fits the records it is given together
    from negstiff import InputError, Posterior
    from negstiff.cli import main
    from negstiff.inference.analysis.design import PosteriorState

    rec_a, offsets_a, post_a = offset_posterior
    u, z = rk4_fixture_record(duration=30.0, seed=5, noise=4e-6)
    offsets_b = np.array([-1e-4, 4e-4])
    rec_b = from_arrays(u, z + offsets_b[:, None], FS, masses=(FIXTURE["m"], TRUTH.m))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a 300-step run has not converged: said, not the point here
        post_b = Posterior(**OFFSET_POSTERIOR).fit(rec_b)
        joint = Posterior(**OFFSET_POSTERIOR).fit([rec_a, rec_b])
    out = joint.result()
    par, nuisance = out["parameters"], out["nuisance_parameters"]
    for r, offsets in ((1, offsets_a), (2, offsets_b)):
        got = [nuisance[f"offset_{k}_r{r}"]["mean"] for k in (1, 2)]
        assert np.abs(np.array(got) - offsets).max() < 20e-6, (r, got)
    assert par["sigma_1"]["mean"] == pytest.approx(1e-6, rel=0.1)
    assert par["sigma_2"]["mean"] == pytest.approx(4e-6, rel=0.1)
    alone = [p.result()["parameters"] for p in (post_a, post_b)]
    for k in ("k1", "k2", "k3", "c", "c_nl"):
        added = 1 / math.sqrt(sum(1 / a[k]["sd"] ** 2 for a in alone))
        assert par[k]["sd"] == pytest.approx(added, rel=0.2), (k, par[k]["sd"], added)
        assert par[k]["mean"] == pytest.approx(getattr(TRUTH, k), rel=0.01 if k.startswith("k") else 0.05), k
    records = out["settings"]["records"]
    assert [r["windows"] for r in records] == [24, 24] and out["settings"]["windows"] == 48
    assert out["offsets_m"] == records[0]["offsets_m"]  # the structure's own zeros: the first record's
    other = from_arrays(u, z, FS, masses=(2 * FIXTURE["m"], TRUTH.m))
    with pytest.raises(InputError, match="masses"):
        Posterior(element="1-2").check([rec_a, other])
    with pytest.raises(InputError, match="joint posterior of 2 records of a structure"):
        PosteriorState.from_json(out)
    paths = [tmp_path / "a.csv", tmp_path / "b.csv"]
    for path, rec in zip(paths, (rec_a, rec_b), strict=True):
        write_csv(path, {"t": np.arange(rec.n) / FS, "base_acc": rec.u, "z1": rec.channels[0], "z2": rec.channels[1]},
                  {"masses": f"{FIXTURE['m']},{TRUTH.m}"})  # fmt: skip
    assert main(["posterior", *map(str, paths), "--element", "1-2", "--ensembles", "2", "--max-steps", "300",
                 "--max-windows", "24", "--seed", "1", "-o", str(tmp_path / "p.json"), "--quiet"]) == 0  # fmt: skip
    written = json.loads((tmp_path / "p.json").read_text())
    assert set(written["parameters"]) == set(par) and len(written["settings"]["records"]) == 2


# a long study: emcee over the element; the test above keeps the structure's posterior running by default
@pytest.mark.slow
def test_posterior_of_the_element_on_its_fixture():
    # emcee over the element's coefficients, the linear structure and the zeros sampled as nuisances from SINDy's: its
    # mean recovers the stiffness within 1 % and the damping within 5 % (the windowed least squares' own bias and the
    # damping's small share of the response: over 12 records, k1-k3 within 1.9 %, c within 14 %, c_nl 27 % at worst)
    # with converged chains. Coverage over many records: the slow test below.
    from negstiff import Posterior

    u, z = rk4_fixture_record(duration=60.0, seed=4, noise=1e-5)
    rec = from_arrays(u, z, FS, masses=(FIXTURE["m"], TRUTH.m))
    post = Posterior(element="1-2", window_s=0.1, max_windows=40, n_ensembles=2, max_steps=3000, seed=1).fit(rec)
    out = post.result()
    for k in ("k1", "k2", "k3", "c", "c_nl"):
        p = out["parameters"][k]
        assert p["mean"] == pytest.approx(getattr(TRUTH, k), rel=0.01 if k.startswith("k") else 0.05), k
        assert p["r_hat"] < 1.01 and p["hdi_low"] < p["mean"] < p["hdi_high"]
    assert out["parameters"]["sigma"]["mean"] == pytest.approx(1e-5, rel=0.5)  # the lasers' noise, and a little model
    assert set(out["parameters"]) == {"k1", "k2", "k3", "c", "c_nl", "sigma"} and "fixed" in out["settings"]


@pytest.mark.slow  # twelve posteriors, ~90 s; run with -m slow
def test_element_posterior_intervals_cover_the_truth_over_records():
    # the posterior's spread against its error over 12 records of the tests' fixture (60 s, 10 um noise, 40 windows):
    # a calibrated posterior puts the truth at z = (mean - truth) / sd with rms 1 (+-0.2 over 12 records) and inside
    # its 90 % interval 90 % of the time. Measured with the windows' starts refined and the linear structure and the
    # channels' zeros sampled (2026-12-01): rms z 0.74 / 1.08 / 0.80 / 0.67 / 0.77 (k1, k2, k3, c, c_nl), coverage
    # 92-100 %, the intervals 1-20x narrower than before; with smoothed starts and the linear structure and zeros
    # held at SINDy's: 1.48 / 1.20 / 1.14 / 1.33 / 1.24, coverage 67-100 %, k1 biased by -1.4 sd; the tempered
    # likelihood before that: rms z 2.0-4.4, coverage 17-67 % (six records). The claim tested stays "within 1.6x of
    # calibrated".
    from negstiff import Posterior

    names = ("k1", "k2", "k3", "c", "c_nl")
    z, inside = [], []
    for seed in range(1, 13):
        u, zz = rk4_fixture_record(duration=60.0, seed=seed, noise=1e-5)
        rec = from_arrays(u, zz, FS, masses=(FIXTURE["m"], TRUTH.m))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            post = Posterior(element="1-2", window_s=0.1, max_windows=40, n_ensembles=2, max_steps=3000, seed=1).fit(
                rec
            )
        par = post.result()["parameters"]
        z.append([(par[k]["mean"] - getattr(TRUTH, k)) / par[k]["sd"] for k in names])
        inside.append([par[k]["hdi_low"] <= getattr(TRUTH, k) <= par[k]["hdi_high"] for k in names])
    rms = np.sqrt(np.mean(np.square(z), axis=0))
    print("rms z", rms.round(2), "coverage", np.mean(inside, axis=0).round(2))
    assert np.all(rms < 1.6) and np.all(np.mean(inside, axis=0) >= 0.6), (rms, np.mean(inside, axis=0))


@pytest.mark.parametrize("friction", [0.0, 0.05])
def test_discrepancy_names_friction_in_the_element_on_its_fixture(friction):
    # a record whose element has Coulomb friction beside its model (the model's own smoothed-sign law): the workflow
    # names it (the single DOF's paired block rule), its value within 25 % (the sign's smoothing and the viscous
    # terms share it), and the held-out error falls by at least 10 % to within 10 % of the truth's own; a clean
    # record names nothing
    import math

    from negstiff.models.effects import COULOMB_VELOCITY_SCALE

    hidden = (lambda r, v: friction * math.tanh(v / COULOMB_VELOCITY_SCALE)) if friction else None
    # the friction compiled with the steps: the same record to the bit as on Python floats (hashed)
    u, z = rk4_fixture_record(duration=120.0, seed=7, noise=3e-6, hidden=hidden, compile_hidden=True)
    rec = from_arrays(u, z, FS, masses=(FIXTURE["m"], TRUTH.m))
    d = Discrepancy(element="1-2").fit(rec)
    # located as the single DOF's is, on the element's relative motion: friction's error most where the relative
    # velocity changes sign (measured 1.4x its share of the record), a clean record's spread evenly (every regime
    # within 0.95-1.03x: the weak residual is the noise's)
    regimes = d.result()["details"]["regimes_before"]
    worst = max(regimes, key=lambda k: regimes[k]["ratio"])
    if not friction:
        assert all(0.8 < r["ratio"] < 1.2 for r in regimes.values()), regimes
        assert d.effects_ == ["none"] and d.structure_.element.extra == {}
        return
    assert worst == "near zero velocity" and regimes[worst]["ratio"] > 1.2, regimes
    assert d.effects_ == ["coulomb_friction"]
    # the Bayesian second opinion (PSIS-LOO over the held-out windows, with and without it) agrees with the rule
    assert d.result()["details"]["bayesian"]["coulomb_friction"]["prefers"] == "with"
    assert d.structure_.element.extra["coulomb_friction"] == pytest.approx(friction, rel=0.25)
    truth = ON_FIXTURE.with_element(Model(**{**TRUTH.to_dict(), "extra": {"coulomb_friction": friction}}))
    floor = free_run_error(truth, rec, int(0.8 * rec.n), 0.25)["rms_percent"]
    assert d.gap_after_["rms_percent"] <= 0.9 * d.gap_before_["rms_percent"]
    assert d.gap_after_["rms_percent"] <= 1.1 * floor, (d.gap_after_, floor)


def test_an_effect_that_does_not_help_the_structures_prediction_is_left_out():
    # the structure's judgement of named effects (``_rounds.judged``, the single DOF's pooled rule): the same
    # restarted windows of the held-out tail run by the model before and after, paired. On a record of the truth
    # on its fixture, a friction the truth does not have (0.2 N; the element's viscous force at its rms relative speed
    # is 0.28 N) predicts worse (measured: the windows' rms error 21x) and is not kept; the truth against a baseline
    # with half its cubic is kept (the error falls 99 %)
    from negstiff.inference.estimators.discrepancy._rounds import judged

    u, z = rk4_fixture_record(duration=30.0, seed=3, noise=1e-6)
    rec = from_arrays(u, z, FS, masses=(FIXTURE["m"], TRUTH.m))
    n_id, zeros = int(0.8 * rec.n), np.zeros(2)
    el = ON_FIXTURE.element.to_dict()
    spurious = ON_FIXTURE.with_element(Model(**{**el, "extra": {"coulomb_friction": 0.2}}))
    worse = judged(rec, ON_FIXTURE.place, n_id, False, (ON_FIXTURE, zeros), (spurious, zeros), ["coulomb_friction"])
    assert not worse["kept"] and worse["pooled"]["gain_percent"] < 0, worse
    assert worse["text"].startswith("coulomb_friction: named by the equation error but not kept: with it the held-out")
    assert "rose" in worse["text"] and "a worse prediction" in worse["text"], worse["text"]
    softer = ON_FIXTURE.with_element(Model(**{**el, "k3": 0.5 * el["k3"]}))
    better = judged(rec, ON_FIXTURE.place, n_id, False, (softer, zeros), (ON_FIXTURE, zeros), ["cubic"])
    assert better["kept"] and better["pooled"]["significant"], better


def test_an_effect_acting_only_in_a_burst_test_s_bursts_is_judged_where_it_acts():
    # a burst test (the table's random acceleration loud for 2 s in every 10 s, a quarter of that level between):
    # the element's cubic damping (0.1 v^3; its viscous force c v is 0.14 N at the rms relative speed) acts only in
    # the bursts. As a single DOF's effect, a structure's is judged on the held-out windows where it acts (its force
    # beyond a quarter of its rms) beside the rest: there the truth with it against the structure without it lowers
    # the windows' rms error far more than over the whole tail, where the quiet windows dilute it (measured: 76 %,
    # 69-81 % within one se, on 18 of the tail's 47 windows, against 43 % pooled; it acts in 10 % of the tail), and
    # the quiet windows are predicted no worse beyond their uncertainty (measured 4.0 % better)
    from negstiff.inference.estimators.discrepancy._rounds import judged
    from negstiff.models.structure import relative

    c3 = 0.1
    u, z = rk4_fixture_record(duration=60.0, seed=3, noise=1e-6, hidden=lambda r, v: c3 * v**3, compile_hidden=True,
                              envelope=lambda t: np.where(t % 10.0 < 2.0, 1.0, 0.25))  # fmt: skip
    rec = from_arrays(u, z, FS, masses=(FIXTURE["m"], TRUTH.m))
    n_id, zeros = int(0.8 * rec.n), np.zeros(2)
    truth = ON_FIXTURE.with_element(Model(**{**ON_FIXTURE.element.to_dict(), "extra": {"cubic_damping": c3}}))
    v = relative(rec.channel_states(ON_FIXTURE.place)[1], ON_FIXTURE.place)
    verdict = judged(rec, ON_FIXTURE.place, n_id, False, (ON_FIXTURE, zeros), (truth, zeros), ["cubic_damping"],
                     force=c3 * v**3)  # fmt: skip
    regime, pooled = verdict["regime"], verdict["pooled"]
    assert verdict["kept"], verdict["text"]
    assert verdict["text"].startswith(f"cubic_damping: kept: the {regime['windows']} held-out windows where it acts")
    assert regime["acting_share_of_tail"] < 0.25 and 3 <= regime["windows"] < pooled["windows"], regime
    acts = regime["acting"]
    assert acts["significant"] and acts["gain_interval_percent"][0] > pooled["gain_percent"], (acts, pooled)
    assert not (regime["rest"]["gain_percent"] < 0 and regime["rest"]["significant"]), regime["rest"]


def test_an_effect_the_held_out_tail_does_not_reach_is_judged_by_cross_validated_blocks():
    # a burst test whose bursts (2 s at full level every 10 s) end at 27 s of the 60 s record, the drive between them
    # at a quarter of their level and from 35 s on at a tenth: the element's cubic damping (0.1 v^3) acts nowhere in
    # the held-out tail (the last 12 s; its force beyond a quarter of its rms over the record). As a single DOF's
    # effect the tail barely reaches, it is judged on the windows where it acts anywhere in the record, in five
    # contiguous blocks, each predicted by the structure fitted without that block's data: every block's fit sizes it
    # within 3 % of the truth (measured 0.0984-0.0997) and with it the blocks' windows are predicted better
    # (measured: their rms error 19 % lower, 14-24 % within one se, over 65 windows; the pooled rule on the quiet
    # tail would keep it too, the viscous term without it being biased)
    c3 = 0.1
    level = lambda t: np.where(t < 40.0, np.where(t % 10.0 < 2.0, 1.0, 0.25), 0.1)  # noqa: E731 (t: settling too)
    u, z = rk4_fixture_record(duration=60.0, seed=3, noise=1e-6, hidden=lambda r, v: c3 * v**3, compile_hidden=True,
                              envelope=level)  # fmt: skip
    d = Discrepancy(element="1-2").fit(from_arrays(u, z, FS, masses=(FIXTURE["m"], TRUTH.m)))
    assert d.effects_ == ["cubic_damping"]
    (verdict,) = d.result()["details"]["judgement"]
    assert verdict["regime"]["windows"] < 3 and verdict["kept"], verdict["text"]
    folds = verdict["folds"]
    assert "windows of the record (in 5 blocks, each predicted by fits without it) where it acts" in verdict["text"]
    sizes = [f["size"] for f in folds["folds"]]
    assert len(sizes) == 5 and all(x == pytest.approx(c3, rel=0.03) for x in sizes), folds
    # each block's own fit (without its data): the five differ (measured by 1.3 % of the truth; one fit for all: 0)
    assert max(sizes) - min(sizes) > 1e-4 * c3, sizes
    # the report says each round's verdict, on which windows it was judged
    from negstiff.report.sections import discrepancy_section

    tables = [rows for kind, (header, rows) in
              ((k, b) for k, b in discrepancy_section(d).blocks if k == "table") if header[0] == "round"]  # fmt: skip
    assert tables and tables[0][0][1] == verdict["text"], tables
    assert folds["acting"]["significant"] and folds["acting"]["gain_percent"] > 0, folds["acting"]


def test_each_block_is_predicted_by_fits_that_never_saw_it():
    # the blocks' isolation (``_rounds.fold_evidence``), on its own fits recorded: the structure without and with the
    # effect that predict a block's windows are fitted on the same weak rows, in every DOF's equation alike, none of
    # whose test functions touches a sample of the block's windows, while every row whose test function lies wholly
    # outside the block's span is kept (nothing beyond the block is dropped)
    from negstiff.inference.estimators.discrepancy._rounds import HeldOut, fold_evidence
    from negstiff.inference.estimators.discrepancy._runs import acting_mask
    from negstiff.inference.steps.equations import _Weak, weak_system
    from negstiff.models.structure import relative

    u, z = rk4_fixture_record(duration=30.0, seed=3, noise=1e-6)
    rec = from_arrays(u, z, FS, masses=(FIXTURE["m"], TRUTH.m))
    at, n_id = ON_FIXTURE.place, int(0.8 * rec.n)
    held = HeldOut(rec, at, n_id, False)
    ident = rec.segment(0, n_id)
    zs, v, _ = ident.channel_states(at)
    form = _Weak.of(relative(zs, at), rec.fs)
    per_dof = weak_system(ident, at, zs, v, form, [])[3]
    acting = acting_mask(relative(held.v, at) ** 3)  # a cubic damping's force: at the fast parts of the motion
    seen = []

    def fitted(cols, names, keep):
        seen.append(np.asarray(keep).copy())
        return ON_FIXTURE, np.zeros(2), np.array([0.1])

    out = fold_evidence(held, acting, fitted, ([0], []), ([0, 1], ["cubic_damping"]), form, per_dof)
    windows = held.record_windows()
    groups = np.array_split(windows.starts[windows.measured(acting).any(axis=1)], 5)
    assert len(out["folds"]) == 5 and len(seen) == 10, out
    lo = np.arange(per_dof) * form.stride
    hi = lo + form.phi.size  # each row's test function spans samples [lo, hi)
    for k, idx in enumerate(groups):
        without, with_it = seen[2 * k], seen[2 * k + 1]
        assert np.array_equal(without, with_it) and without.size == 2 * per_dof
        keep = without[:per_dof]
        assert np.array_equal(keep, without[per_dof:])  # every DOF's equation alike
        block = np.zeros(rec.n + form.phi.size, bool)
        block[(idx[:, None] + np.arange(windows.length)[None, :]).ravel()] = True
        cum = np.concatenate([[0], np.cumsum(block)])
        touches = cum[hi] - cum[lo] > 0
        assert not np.any(keep & touches), k
        outside = (hi <= idx[0]) | (lo >= idx[-1] + windows.length)
        assert np.all(keep[outside]), k
        assert (~keep).sum() < per_dof / 2, (k, (~keep).sum())


def test_what_no_registered_effect_names_in_the_element_is_the_unnamed_term(tmp_path, capsys):
    # the element has a stiffness bump at its barrier beside its cubic, a r exp(-(r / w)^2) (100 N/m over 1 cm; the
    # cubic's k1 is 426 N/m), which no registered effect is: the rounds name the quintic stiffness, the nearest, and
    # the unnamed term (``discrepancy --unnamed``, the single DOF's hybrid term on the element's relative motion and
    # the input) carries the rest. Fitted with the structure held, the held-out tail's restarted windows are predicted
    # better beyond one standard error (measured: their rms error 20 % lower, 7-32 %; the median window 3.4 % -> 2.3 %
    # of the channels' rms); fitted jointly with the structure, better still (37 %, 26-46 %; 2.0 %), by a term of
    # about 2 % of the restoring force (measured 2.2 %), and the joint refit undoes what the quintic had bent: the
    # element's k1, 5.7 % under the truth's 426 N/m with the quintic, comes back within 0.2 % (moved by 42 of its
    # standard errors). Through the command line, whose account of a structure's workflow had failed after writing
    # its JSON.
    import json
    import math

    from negstiff.cli import main

    u, z = rk4_fixture_record(duration=60.0, seed=7, noise=3e-6, compile_hidden=True,
                              hidden=lambda r, v: 100.0 * r * math.exp(-((r / 0.01) ** 2)))  # fmt: skip
    z = z + np.array([3e-4, -2e-4])[:, None]  # each sensor's zero off (the term lives in the physical frame)
    t = np.arange(u.size) / FS
    path = write_csv(tmp_path / "bump.csv", {"t": t, "base_acc": u, "z1": z[0], "z2": z[1]},
                     {"masses": f"{FIXTURE['m']},{TRUTH.m}", "element": "1-2"})  # fmt: skip
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert main(["discrepancy", str(path), "--unnamed", "-o", str(tmp_path / "d.json")]) == 0
    details = json.loads((tmp_path / "d.json").read_text())["details"]
    assert details["effects"] == ["quintic_stiffness"], details["effects"]
    un = details["unnamed"]
    gap = un["gap"]
    for paired in (gap["paired_held"], gap["paired"]):
        assert paired["significant"] and paired["gain_percent"] > 0, gap
    medians = [gap[f"{k}_median_window_percent"] for k in ("hybrid", "held", "physics")]
    assert medians == sorted(medians), gap
    assert 0.5 < un["term_percent_of_restoring_force"] < 5.0, un["term_percent_of_restoring_force"]
    k1 = un["joint"]["coefficients"]["k1"]
    assert abs(k1["held"] / TRUTH.k1 - 1) > 0.03 and abs(k1["joint"] / TRUTH.k1 - 1) < 0.02, k1
    assert k1["shift_in_se"] > 3, k1
    said = capsys.readouterr().err  # the command's account of its work
    assert f"unnamed: a non-parametric term of {un['term_percent_of_restoring_force']:.3g} % of the" in said, said


def test_a_structures_extra_force_hook_at_zero_weights_is_the_structure_itself():
    # the element's hybrid term runs inside the structure's Runge-Kutta loop (``simulate_structures(hook=...)``, the
    # kernel's extra force): at zero weights the runs are the structure's own (the same arithmetic plus zero: equal to
    # the last few bits), and a hook without the stage-time input it reads is refused. (The element with a quintic:
    # the kernel the unnamed term's test above compiles, one compile for both.)
    from negstiff.inference.estimators.hybrid import Basis, _hook
    from negstiff.models.simulator import stage_input

    s = ON_FIXTURE.with_element(Model(**{**TRUTH.to_dict(), "extra": {"quintic_stiffness": 2e7}}))
    rng = np.random.default_rng(4)
    u = rng.standard_normal(2000) * 10.0
    staged = stage_input(u, 2)[None]
    x0 = np.r_[s.static_positions(s.element_equilibria().z_plus), 0.0, 0.0][None]
    basis = Basis.over(np.linspace(-0.03, 0.03, 50), np.linspace(-0.5, 0.5, 50), u, 4, 3, 2)
    plain = simulate_structures(s, staged, 1 / FS, x0, substeps=2, staged=True)
    hook = _hook(basis, np.zeros(basis.size))
    hooked = simulate_structures(s, staged, 1 / FS, x0, substeps=2, staged=True, hook=hook)
    assert not plain.diverged.any() and np.abs(plain.z).max() > 0
    assert np.allclose(hooked.z, plain.z, rtol=0, atol=1e-12 * np.abs(plain.z).max())
    with pytest.raises(InputError, match="reads the input at the stage times"):
        simulate_structures(s, u[None], 1 / FS, x0, hook=hook)


@pytest.mark.slow  # a second record and kernel (the element's plain cubic with the term): the fact's other side
def test_an_element_missing_nothing_leaves_the_unnamed_term_at_the_noise():
    # the truth on its fixture, nothing missing: the term stays below 0.1 % of the restoring force and the median
    # held-out window is predicted no worse than by the structure alone beyond 2 % (measured: 0.017 %; jointly
    # 0.134 % against 0.132 %, with the structure held 0.129 %). (The joint refit moved c by 3.1 of its standard
    # errors and the rest by 2.5 at most: not asserted, the single DOF's moved none beyond 1.4.)
    u, z = rk4_fixture_record(duration=60.0, seed=7, noise=3e-6)
    d = Discrepancy(element="1-2", unnamed=True).fit(from_arrays(u, z, FS, masses=(FIXTURE["m"], TRUTH.m)))
    un = d.result()["details"]["unnamed"]
    assert d.effects_ == ["none"]
    assert un["term_percent_of_restoring_force"] < 0.1, un["term_percent_of_restoring_force"]
    gap = un["gap"]
    assert gap["hybrid_median_window_percent"] <= 1.02 * gap["physics_median_window_percent"], gap
    # the report says it
    from negstiff.report.sections import discrepancy_section

    said = [b for kind, b in discrepancy_section(d).blocks if kind == "p" and b.startswith("Unnamed term")]
    assert said and "% of the restoring force; held-out median window" in said[0], said


def test_discrepancy_names_each_missing_effect_of_the_element_in_turn():
    # an element with two effects beside its model, a quintic stiffness (k5 r^5, 10 % of the cubic's force at the
    # stroke's end) and Coulomb friction (0.05 N): as the single DOF's workflow, the structure's names the effect that
    # lowers the held-out score most, adds it to the base and offers the rest again: the quintic first, the friction
    # next, then nothing; the held-out error falls with each (measured 9.4 % -> 2.1 %, 2.9 % with the quintic alone).
    # The weak form's values (the quintic +0.03 %, the friction +15 %: the sign's smoothing and the viscous terms
    # share it) are then refined by output error, which is kept: the quintic within 1 % (measured +0.07 %), the
    # friction within 2 % (measured -0.3 %), and each effect's 90 % interval (the refinement's window-robust
    # standard error, 0.1 % and 0.4 %) holds the truth
    import math

    from negstiff.models.effects import COULOMB_VELOCITY_SCALE

    k5, friction = 3e7, 0.05

    def hidden(r, v):
        return friction * math.tanh(v / COULOMB_VELOCITY_SCALE) + k5 * r**5

    u, z = rk4_fixture_record(duration=120.0, seed=7, noise=3e-6, hidden=hidden)
    rec = from_arrays(u, z, FS, masses=(FIXTURE["m"], TRUTH.m))
    d = Discrepancy(element="1-2").fit(rec)
    assert d.effects_ == ["quintic_stiffness", "coulomb_friction"]
    # where the baseline errs: at the element's large relative stroke, where the quintic acts (measured 2.9x its share
    # of the record on a 60 s record), and no longer there once both are named
    details = d.result()["details"]
    assert details["where"].startswith("the baseline's equation error is concentrated at large stroke")
    assert details["regimes_after"]["large stroke"]["ratio"] < 1.5 < details["regimes_before"]["large stroke"]["ratio"]
    # the Bayesian second opinion on each (PSIS-LOO over the held-out windows with and without it, the rest held)
    # prefers it, by more than two standard errors of the difference (measured on 60 s records: 880 and 1022 against
    # 214 and 173)
    assert all(
        details["bayesian"][e]["prefers"] == "with" and details["bayesian"][e]["beyond_two_se"]
        for e in ("quintic_stiffness", "coulomb_friction")
    ), details["bayesian"]
    extra = d.structure_.element.extra
    assert d.result_.refinement["applied"], d.result_.refinement["reason"]
    assert extra["quintic_stiffness"] == pytest.approx(k5, rel=0.01)
    assert extra["coulomb_friction"] == pytest.approx(friction, rel=0.02)
    intervals = d.result()["details"]["effect_interval"]
    for name, truth in (("quintic_stiffness", k5), ("coulomb_friction", friction)):
        lo, hi = intervals[name]["interval"]
        assert lo <= truth <= hi, (name, intervals[name])
    rounds = d.result()["details"]["iterations"]
    assert [r["named"] for r in rounds] == ["quintic_stiffness", "coulomb_friction", "none"]
    # each kept because it predicts the held-out windows better, as a single DOF's round's effect is kept (paired
    # windows beyond one standard error; measured: the quintic lowers their rms error 64 %, 61-67 % within one se,
    # the friction then 22 %, 17-27 %)
    judgement = details["judgement"]
    assert [j["effect"] for j in judgement] == ["quintic_stiffness", "coulomb_friction"], judgement
    assert all(j["kept"] and j["pooled"]["significant"] and j["pooled"]["gain_percent"] > 0 for j in judgement)
    # and where each acts (its force beyond a quarter of its rms): the quintic at the element's large stroke (measured
    # 40 % of the tail), the friction at every speed but the turning points (97 %); every 0.25 s window holds some,
    # so the windows where each acts are the tail's
    shares = [j["regime"]["acting_share_of_tail"] for j in judgement]
    assert shares[0] < 0.6 and shares[1] > 0.9, shares
    for j in judgement:  # the same windows, the same comparison (floats compared to their last digits, not bitwise)
        acting, pooled = j["regime"]["acting"], j["pooled"]
        assert acting["windows"] == pooled["windows"] and acting["significant"] == pooled["significant"], j
        assert acting["gain_percent"] == pytest.approx(pooled["gain_percent"], rel=1e-12), j
    one = Discrepancy(element="1-2", max_effects=1).fit(rec)  # the first round alone
    assert one.effects_ == ["quintic_stiffness"]
    assert d.gap_after_["rms_percent"] < one.gap_after_["rms_percent"] < 0.5 * d.gap_before_["rms_percent"]


def test_stabilisation_diagram_keeps_both_modes_of_each_well():
    # over orders 4..8 (2..4 per DOF) and two Hankel depths, each well's two physical modes recur within 1 % / 5 %
    u, z = rk4_fixture_record(duration=60.0, seed=4)
    rec = from_arrays(u, z, FS, masses=(FIXTURE["m"], TRUTH.m))
    nsi = NSI(element="1-2").fit(rec)
    rows = nsi.stabilisation(rec, orders=(2, 3, 4), block_rows=(20, 40))
    for well in ("minus", "plus"):
        for true in ON_FIXTURE.modes(well):
            stable = [p for r in rows if r["well"] == well for p in r.get("poles", [])
                      if p["stable"] and abs(p["f_hz"] / true.f_hz - 1) < 0.01]  # fmt: skip
            assert len(stable) >= 3, (well, true.f_hz, len(stable))  # of 4 (orders 6 and 8 x 2 depths)


def test_simulate_a_structure_from_python_and_the_command_line(tmp_path):
    import json
    import subprocess
    import sys

    from negstiff import load_system, simulate

    t = np.arange(0, 4.0, 1 / FS)
    u = 6.0 * np.sin(2 * np.pi * 9.0 * t)
    model = tmp_path / "structure.json"
    model.write_text(json.dumps(ON_FIXTURE.to_dict()))
    assert load_system(model) == ON_FIXTURE
    res = simulate(ON_FIXTURE, u, 1 / FS)
    assert res.z.shape == (1, 2, t.size) and not res.diverged[0]
    # from rest in the plus well, the relative displacement stays in it at 6 m/s^2 (below the first doubling)
    r = res.z[0, 1] - res.z[0, 0]
    assert r.min() > ON_FIXTURE.element_equilibria().z_0
    data = write_csv(tmp_path / "input.csv", {"t": t, "base_acc": u})
    out = tmp_path / "sim.csv"
    done = subprocess.run([sys.executable, "-m", "negstiff", "simulate", str(model), str(data), "-o", str(out)],
                          capture_output=True, text=True)  # fmt: skip
    assert done.returncode == 0, done.stderr
    cols = np.genfromtxt(out, delimiter=",", names=True)
    same = simulate(ON_FIXTURE, cols["base_acc"], 1 / FS)  # the input as the file printed it (10 digits)
    assert np.allclose(cols["z1"], same.z[0, 0], rtol=1e-8, atol=1e-15)
    assert np.allclose(cols["z2_dot"], same.z_dot[0, 1], rtol=1e-8, atol=1e-12)
    bad = subprocess.run([sys.executable, "-m", "negstiff", "simulate", str(model), str(data), "--v0", "0.1", "-o",
                          str(tmp_path / "no.csv")], capture_output=True, text=True)  # fmt: skip
    assert bad.returncode == 2 and "--v0" in bad.stderr and not (tmp_path / "no.csv").exists()


def test_frf_of_a_structure_finds_both_modes_of_the_well(tmp_path):
    # a low-level random test in the plus well (0.3 m/s^2): the FRFs to the two lasers show the well's two
    # underlying-linear modes, within 1 % in frequency and 10 % in damping (4 % softening of a 1 m/s^2 test gone)
    import json
    import subprocess
    import sys

    from negstiff.models.rig import Rig, Sensors

    rig = Rig.device_on_fixture(TRUTH, seed=2, sensors=Sensors(laser_noise=1e-6))
    path = rig.random(duration=120.0, rms=0.3, start="plus").write(tmp_path / "low.csv")
    out = tmp_path / "frf.json"
    done = subprocess.run([sys.executable, "-m", "negstiff", "frf", str(path), "--dofs", "2", "-o", str(out)],
                          capture_output=True, text=True)  # fmt: skip
    assert done.returncode == 0, done.stderr
    res = json.loads(out.read_text())
    assert (tmp_path / "frf.png").exists() and [d["dof"] for d in res["dofs"]] == [1, 2]
    for true in ON_FIXTURE.modes("plus"):
        near = [m for m in res["modes"] if abs(m["f_hz"] / true.f_hz - 1) < 0.01]
        assert near and near[0]["zeta"] == pytest.approx(true.zeta, rel=0.10), (true, res["modes"])


def test_continuation_follows_the_structures_doubled_branch():
    # past the plus well's first doubling the period-2 orbit is found and continued: its multipliers are those of
    # the 4 states, and its own doubling lies above the first
    from negstiff import nfrc

    curve = nfrc(ON_FIXTURE, freq=9.0, amplitude=(1.0, 12.0), well="plus", max_period=2)
    periods = sorted({b["period"] for b in curve["branches"]})
    assert periods == [1, 2]
    two = next(b for b in curve["branches"] if b["period"] == 2)
    assert len(two["points"][0]["multipliers"]) == 4 and len(two["points"][0]["state"]) == 4
    first = next(b for b in curve["bifurcations"] if b["type"] == "period_doubling" and b["period"] == 1)
    second = [b for b in curve["bifurcations"] if b["type"] == "period_doubling" and b["period"] == 2]
    assert second and second[0]["amplitude"] > first["amplitude"]


def test_a_force_on_the_device_identifies_the_same_structure():
    # a shaker force on the device's mass (DOF 2) instead of the table's motion: the force path (input gain 1/m2 on
    # DOF 2 only) through the simulator, NSI and SINDy; the element within 1 %, the modes within 0.5 %
    from negstiff.models.simulator import stage_input

    rng = np.random.default_rng(5)
    n = int(65 * FS)
    spec = np.fft.rfft(rng.standard_normal(n))
    spec[(np.fft.rfftfreq(n, 1 / FS) < 2.0) | (np.fft.rfftfreq(n, 1 / FS) > 40.0)] = 0
    force = np.fft.irfft(spec, n)
    force *= 2.4 / force.std()  # N: cross-well, like 12 m/s^2 of table motion on 0.2 kg
    x0 = np.r_[ON_FIXTURE.equilibria()["plus"], 0.0, 0.0]
    res = simulate_structures(ON_FIXTURE, stage_input(force), 1 / FS, x0, input_kind="force", staged=True)
    k = int(5 * FS)
    z = res.z[0][:, k:] + 1e-6 * rng.standard_normal((2, n - k))
    rec = from_arrays(force[k:], z, FS, masses=(FIXTURE["m"], TRUTH.m), input_name="force", force_dof=2)
    r = z[1] - z[0]
    assert np.count_nonzero(np.diff(np.sign(r - ON_FIXTURE.element_equilibria().z_0))) > 50
    for method in (NSI, SINDy):
        est = method(element="1-2").fit(rec)
        for k3 in ("k1", "k2", "k3", "c", "c_nl"):
            assert est.element_[k3] == pytest.approx(getattr(TRUTH, k3), rel=0.01), (method.__name__, k3)
        for got, true in zip(est.modal_["plus"], ON_FIXTURE.modes("plus"), strict=True):
            assert got.f_hz == pytest.approx(true.f_hz, rel=0.005)


def test_a_structures_posterior_on_a_record_that_starts_under_a_force():
    # a chain driven from rest by a force on its fixture (DOF 1: 1 kg at 25 Hz; DOF 2 the hardening Duffing's mass
    # on the element), written by scipy's DOP853: the first window once started at the record's first samples,
    # whose input at the stage times the interpolating filter reads partly from beyond the record; its run missed
    # by 3.5 mm rms against 1 um in the others and moved k3 to 2.6 times the truth, with no word. The windows start
    # past that edge, and the element's posterior holds the truth within 4 of its standard deviations (measured
    # within 1.2)
    from impact_records import DUFFING
    from records import chain_record

    from negstiff import Posterior

    u, z, masses, force_dof = chain_record(2, DUFFING, "force", 512.0, 30.0)
    rng = np.random.default_rng(2)
    rec = from_arrays(u + 0.02 * rng.standard_normal(u.size), z + 1e-6 * rng.standard_normal(z.shape), 512.0,
                      input_name="force", masses=masses, force_dof=force_dof, gravity=0.0,
                      source="driven chain")  # fmt: skip
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the short run's ConvergenceWarning
        post = Posterior(element="1-2", n_ensembles=2, min_steps=50, max_steps=100, max_windows=12).fit(rec)
    p = post.result()["parameters"]
    for k in ("k1", "k3", "c"):
        assert abs(p[k]["mean"] - getattr(DUFFING, k)) < 4 * p[k]["sd"], (k, p[k])


def test_nsi_judges_reciprocity_on_the_pairs_a_chain_couples():
    # a 3-DOF chain (fixture masses 1 and 0.5 kg, the Duffing's 0.2 kg on the element between DOFs 2 and 3; scipy's
    # DOP853) driven by a force on DOF 1: its DOFs 1 and 3 are not coupled, and their fitted stiffness (a few N/m of
    # noise) read as a coupling 89-112 % asymmetric: "are the masses right?" on an identification within 0.1 % of the
    # truth. Judged on the pairs coupled by at least 1 % of their own stiffness, the right masses give 0.2 % and no
    # warning; the device's mass stated 30 % high gives 23 %, and the warning. The judgement is NSI's own step's
    # (each well's underlying-linear system): the output-error refinement after it is not run (refine=False)
    from impact_records import DUFFING
    from records import chain_record

    u, z, masses, force_dof = chain_record(3, DUFFING, "force", 512.0, 20.0)
    rng = np.random.default_rng(3)
    u, z = u + 0.02 * rng.standard_normal(u.size), z + 1e-6 * rng.standard_normal(z.shape)
    for scale, warned in ((1.0, False), (1.3, True)):
        stated = (*masses[:2], masses[2] * scale)
        rec = from_arrays(u, z, 512.0, input_name="force", masses=stated, force_dof=force_dof, gravity=0.0,
                          source="driven chain")  # fmt: skip
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            est = NSI(element="2-3", refine=False).fit(rec)
        said = [w for w in est.warnings_ if "not symmetric" in w]
        assert bool(said) is warned, (scale, est.warnings_)
        if not warned:
            assert est.element_["k3"] == pytest.approx(DUFFING.k3, rel=0.01)


def test_a_structures_decay_gone_to_its_noise_before_the_judging_part_is_refused_before_any_work():
    # a 2-DOF chain (scipy's DOP853, ``records.chain_record``) released 6 mm from its rest, the 1.5 % Duffing ringing
    # into its 1 um sensor noise by about 7 s of a 30 s record: the part that judges the models (from 18 s on) holds
    # the sensors' noise only. Every estimator of a structure refuses it in one line before any work (SINDy had
    # fitted k3 28x the truth on such a record, the posterior's windows all unmatched, NSI 'unstable'); the same
    # record cut at 9 s, where it still rings, is read: k3 within 1 % (measured -0.005 %)
    from impact_records import DUFFING
    from records import chain_record

    from negstiff import Posterior

    u, z, masses, _ = chain_record(2, DUFFING, "decay", FS, 30.0)
    z = z + 1e-6 * np.random.default_rng(0).standard_normal(z.shape)
    rec = from_arrays(u, z, FS, "force", masses=masses, decay=True)
    for est in (NSI(element="1-2"), SINDy(element="1-2"), Discrepancy(element="1-2"), Posterior(element="1-2")):
        with pytest.raises(InputError, match="rings down into its sensors' noise by [0-9.]+ s, before the part"):
            est.check(rec)
    cut = rec.segment(0, int(9.0 * FS))
    assert SINDy(element="1-2").fit(cut).structure_.element.k3 == pytest.approx(DUFFING.k3, rel=0.01)


def test_command_line_discrepancy_reads_a_structure_from_its_options(tmp_path, capsys):
    # negstiff discrepancy on a lab's structure file whose header says nothing of it: --masses and --element give
    # what '# masses:' and '# element:' would (before, only the header could, and the file was refused); the
    # command's numbers are the library's on the same record, and a wrong --dofs or a missing --element is one line
    # and exit 2 before any work, no output written
    import json
    import warnings

    from negstiff import Discrepancy, load

    u, z = rk4_fixture_record(duration=30.0, seed=3)
    t = np.arange(u.size) / FS
    data = write_csv(tmp_path / "two.csv", {"t": t, "base_acc": u, "z1": z[0], "z2": z[1]})
    masses = f"{FIXTURE['m']},{TRUTH.m}"

    def run(*args):
        return _command(capsys, "discrepancy", *args)

    out = tmp_path / "d.json"
    code, err = run(data, "--masses", masses, "--element", "1-2", "--max-effects", 1, "--quiet", "-o", out)
    assert code == 0, err
    result = json.loads(out.read_text())
    assert result["dofs"] == 2 and result["element_at"] == [1, 2]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        library = Discrepancy(element="1-2", max_effects=1).fit(load(data, masses=(FIXTURE["m"], TRUTH.m))).result()
    for key in ("effects", "gap_before_percent", "gap_after_percent"):
        assert result["details"][key] == library["details"][key], key
    assert result["element"] == library["element"]
    for bad, says in ((("--dofs", 3, "--masses", masses, "--element", "1-2"), "z1 ... z2"),
                      (("--masses", masses), "element")):  # fmt: skip
        code, err = run(data, *bad, "-o", tmp_path / "no.json")
        assert code == 2 and says in err and len(err.strip().splitlines()) == 1
        assert not (tmp_path / "no.json").exists()
