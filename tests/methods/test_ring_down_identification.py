"""NSI and SINDy on a hammer's record and on a free decay (single DOF): the hardening Duffing and the seed-like
double well of ``impact_records`` (scipy's DOP853), with a lab's artefacts: the hammer's force channel offset by
0.5 N with 0.05 N of noise between and during the hits, a displacement sensor's white noise.

Acceptance (the issue "Hammer and decay tests"): each well's frequency within 1 %, its damping ratio within 10 %,
the cubic within 5 %. The frequency and damping are the method's own (NSI's subspace pole; SINDy's own model's
linearisation), the cubic the final model's. The tolerances are the acceptance's; what each fit reached is in the
comments (seed 1).
"""

import json
import warnings

import numpy as np
import pytest
from impact_records import (
    DOUBLE_WELL,
    DUFFING,
    LIGHT_DUFFING,
    MASS,
    accelerometer_hammer,
    decay_record,
    hammer_record,
    measured_decay,
    measured_hammer,
)

from negstiff import NSI, SINDy, from_arrays
from negstiff.errors import MeasurementError
from negstiff.inference.analysis.record_kind import record_kind
from negstiff.models import Model

FS = 1000.0
HITS = (0.5, 3.0, 5.5, 8.0)
"""Four hits 2.5 s apart (the Duffing's ring-down falls 17x between them), the last one in the held-out tail."""

LASER_HAMMER_M = 1e-6
"""The hammer records' displacement noise [m rms], 1 um against a 6 mm response (a laser vibrometer's or a good
triangulation sensor's). At 5 um NSI's own Duffing cubic came out 8-11 % low while its basis held the sensor's
noise (errors in variables: the noise in the -x^3 channel and in the output are correlated); the basis is now
low-passed above the response's band, and the cubic is within 1.3 % at 5 um (a test below)."""

LASER_DECAY_M = 5e-6
"""The decays' displacement noise [m rms] (a laser triangulation sensor's)."""

# LIGHT_DUFFING (impact_records), the Duffing at 0.5 % damping: SINDy scores its candidate supports on the decay's
# later part (samples 60-80 %), which must still reach the cubic's range (at 1.5 % the decay is 0.13 mm there and
# z^3 is not selected)


def _truth(model: Model) -> dict[str, tuple[float, float]]:
    """Each well's linearised frequency [Hz] and damping ratio."""
    eq = model.equilibria()
    out = {}
    for well, z in (("minus", eq.z_minus), ("plus", eq.z_plus)):
        if z is None:
            continue
        k = float(model.stiffness(z))
        out[well] = (np.sqrt(k / model.m) / (2 * np.pi), model.c / (2 * np.sqrt(k * model.m)))
    return out


def _hammer(model, seed, laser_m=LASER_HAMMER_M):
    return measured_hammer(model, seed, laser_m, FS, HITS)


def _decay(model, z0, seed, duration):
    return measured_decay(model, z0, seed, duration, LASER_DECAY_M, FS)


def _fit(est, rec):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return est.fit(rec)


def _check(est, model, kind):
    assert est.result_.details["record_kind"]["kind"] == kind
    truth = _truth(model)
    lo, hi = float(np.min(est.stroke_)), float(np.max(est.stroke_))
    eq = model.equilibria()
    for well, m in est.modal_.items():
        z = eq.z_minus if well == "minus" else eq.z_plus
        if m["f_hz"] is None or not lo <= z <= hi:  # a well the record never visited is the model's extrapolation
            continue
        f, zeta = truth[well]
        assert m["f_hz"] == pytest.approx(f, rel=0.01), well
        assert m["zeta"] == pytest.approx(zeta, rel=0.10), well
    assert any(m["f_hz"] is not None for m in est.modal_.values())
    assert est.model_.k3 == pytest.approx(model.k3, rel=0.05)


@pytest.mark.parametrize("model", [DUFFING, DOUBLE_WELL], ids=["duffing", "double_well"])
@pytest.mark.parametrize("method", [NSI, SINDy], ids=["nsi", "sindy"])
def test_a_hammer_record_is_identified_with_its_force_as_the_input(method, model):
    # the force windowed (each hit's offset off, zero between the pulses) drives the identification. Measured:
    # NSI Duffing 11.99 Hz / 1.50 %, k3 +0.6 %; double well (plus well) 10.316 Hz / 1.94 %, k3 +0.5 %;
    # SINDy Duffing k3 -0.3 %, double well k3 -0.3 %
    rec = _hammer(model, seed=1)
    assert record_kind(rec).kind == "impact"
    _check(_fit(method(), rec), model, "impact")


@pytest.mark.parametrize("method", [NSI, SINDy], ids=["nsi", "sindy"])
def test_a_free_decay_of_the_double_well_is_identified_from_its_initial_state(method):
    # released 12 mm beyond the plus well, it crosses into the minus well and rings down there: both wells.
    # Measured: NSI minus 11.238 / 1.74 %, plus 10.299 / 1.86 %, k3 within 0.1 %; SINDy minus 11.239 / 1.78 %
    rec = _decay(DOUBLE_WELL, DOUBLE_WELL.equilibria().z_plus + 0.012, seed=1, duration=6.0)
    assert record_kind(rec).kind == "decay"
    _check(_fit(method(), rec), DOUBLE_WELL, "decay")


def test_nsi_identifies_a_free_decay_of_the_duffing():
    # the decay form: the feedback channels alone, read against the pole's own FRF. Measured: 11.993 Hz / 1.43 %,
    # the refined k3 within 0.1 %
    _check(_fit(NSI(), _decay(DUFFING, 0.008, seed=1, duration=6.0)), DUFFING, "decay")


def test_sindy_identifies_a_lightly_damped_free_decay_of_the_duffing():
    # the weak form without an input term, the mass given
    _check(_fit(SINDy(), _decay(LIGHT_DUFFING, 0.008, seed=1, duration=10.0)), LIGHT_DUFFING, "decay")


def test_a_decay_without_a_mass_is_identified_per_unit_mass():
    # no input to scale by: the coefficients per unit mass (m = 1), and the result says so
    rec = _decay(DOUBLE_WELL, DOUBLE_WELL.equilibria().z_plus + 0.012, seed=2, duration=6.0)
    rec = from_arrays(rec.u, rec.z, FS, input_name="force", mass=None)
    est = _fit(NSI(), rec)
    assert est.mass_normalised_ and est.model_.m == 1.0
    assert est.model_.k3 == pytest.approx(DOUBLE_WELL.k3 / MASS, rel=0.05)


def test_a_constant_input_without_a_ring_down_is_refused():
    # a record at rest with a dead input is neither a forced record nor a decay: one line saying both
    z = 0.02 + 1e-5 * np.random.default_rng(0).standard_normal(6000)
    for method in (NSI, SINDy):
        with pytest.raises(MeasurementError, match="the input force is constant .* does not ring down"):
            method().fit(from_arrays(np.zeros(6000), z, FS, input_name="force", mass=MASS, source="quiet.csv"))


def test_sindy_refuses_a_decay_that_has_rung_down_before_its_scoring_part():
    # at 1.5 % the Duffing's decay is at its noise (5 um) by 60-80 % of a 10 s record, where SINDy scores its
    # candidate supports: one line saying so before the fit, not a model without its cubic
    rec = _decay(DUFFING, 0.008, seed=1, duration=10.0)
    with pytest.raises(MeasurementError, match="cannot score its candidate models on this ring-down"):
        SINDy().check(rec)


@pytest.mark.parametrize("method", ["nsi", "sindy"])
def test_identify_on_a_hammer_file_says_how_it_read_it(tmp_path, capsys, method):
    # the command line: the lab's file (force with its offset, the response), identified and said to be a hammer's
    from negstiff.cli import main

    rec = _hammer(DUFFING, seed=3)
    path = tmp_path / "hammer.csv"
    with open(path, "w") as fh:
        fh.write(f"# mass: {MASS}\nt,force,z\n")
        np.savetxt(fh, np.column_stack([np.arange(rec.n) / FS, rec.u, rec.z]), delimiter=",", fmt="%.9g")
    out = tmp_path / "r.json"
    assert main(["identify", method, str(path), "-o", str(out)]) == 0
    assert "read as a hammer's record: 4 hammer hit(s)" in capsys.readouterr().err
    res = json.loads(out.read_text())
    assert res["record_kind"]["kind"] == "impact"
    assert res["modal"]["plus"]["f_hz"] == pytest.approx(12.0, rel=0.01)


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_nsi_cubic_of_a_hammer_record_at_a_triangulation_sensors_noise(seed):
    # at 5 um (1 kHz, the band states' window 5 samples: no room to average the noise) NSI's own k3 came out -8.2
    # to -10.6 % over seeds 0-5: the noise in the -x^3 channel and in the output are correlated (errors in
    # variables). The basis is now built from z low-passed where the record's PSD falls under 1000x its noise
    # floor, not below twice the response's band (``derivatives.BASIS_SNR``; here at 92 Hz): k3 +0.4, +0.7, -0.6,
    # -0.3 % over seeds 0-3, the refinement off (measured); noise-free the same record reads -1.6 to +0.9 % (the
    # force channel's noise), so what is left of the sensor's noise is inside that scatter
    est = _fit(NSI(refine=False), _hammer(DUFFING, seed=seed, laser_m=5e-6))
    assert est.model_.k3 == pytest.approx(DUFFING.k3, rel=0.05)
    assert est.modal_["plus"]["f_hz"] == pytest.approx(12.0, rel=0.01)


@pytest.mark.parametrize("kind", ["hammer", "decay"])
def test_the_discrepancy_workflow_reads_a_ring_down_as_the_identifications_do(kind):
    # the discrepancy workflow reads a hammer's record and a free decay as NSI and SINDy do (its findings on them:
    # test_discrepancy_ring_downs); its checks pass both, before any work (it refused them in one line, and before
    # that said "too short" of a 10 s hammer's record and "a dead sensor?" of a free decay)
    from negstiff import Discrepancy

    if kind == "hammer":
        t, f, z, _ = hammer_record(DUFFING, 0.0, 1000.0, (0.5, 3.0, 5.5, 8.0), 40.0, 0.004, 10.0)
        rec = from_arrays(f + 0.5, z, 1000.0, input_name="force", mass=DUFFING.m)
    else:
        t, z, _ = decay_record(DUFFING, 0.008, 1000.0, 10.0)
        rec = from_arrays(np.zeros_like(t), z, 1000.0, input_name="force", mass=DUFFING.m)
    assert record_kind(Discrepancy().check(rec)).kind == ("impact" if kind == "hammer" else "decay")


def test_the_discrepancy_workflow_refuses_a_decay_rung_down_before_its_scoring_part():
    # as SINDy does (below): at 1.5 % the Duffing's decay is at its 5 um noise by 60-80 % of a 10 s record, where the
    # workflow scores its candidate effects: one line saying so before any work
    from negstiff import Discrepancy
    from negstiff.inference.estimators.discrepancy import DiscrepancyError

    with pytest.raises(DiscrepancyError, match="cannot score its candidate effects on this ring-down") as err:
        Discrepancy().check(_decay(DUFFING, 0.008, seed=1, duration=10.0))
    assert len(str(err.value).splitlines()) == 1


def test_a_decay_whose_force_channel_reads_noise_is_named_a_decay():
    # a force sensor left connected through a release reads its offset and noise: the record is a free decay, but
    # its input column is not constant. Read as force-driven, NSI's cubic came out 2.9 % low and SINDy refused the
    # record as too short; named a decay (decay=True, --decay), the column is not used and both read the Duffing
    # (k3 within 1 %, 12 Hz within 0.1 %: 1 um of sensor noise on an 8 mm release)
    t, z, _ = decay_record(DUFFING, 0.008, 1000.0, 10.0)
    rng = np.random.default_rng(3)
    noise = 0.3 + 0.05 * rng.standard_normal(t.size)
    zm = z + 1e-6 * rng.standard_normal(t.size)
    assert record_kind(from_arrays(noise, zm, 1000.0, input_name="force", mass=DUFFING.m)).kind == "force"
    rec = from_arrays(noise, zm, 1000.0, input_name="force", mass=DUFFING.m, decay=True)
    assert record_kind(rec).kind == "decay"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for cls in (NSI, SINDy):
            est = cls().fit(rec)
            assert est.model_.k3 == pytest.approx(DUFFING.k3, rel=0.01), cls
            assert est.modal_["plus"]["f_hz"] == pytest.approx(12.0, rel=0.001), cls


def test_the_command_line_names_a_decay_with_its_noisy_force_channel(tmp_path, capsys):
    # the same record from a lab's file: identify --decay reads it as a decay, and so does backbone --decay (its
    # decay from the first sample, not after the noise's 'last activity')
    from negstiff.cli import main

    t, z, _ = decay_record(DUFFING, 0.008, 1000.0, 10.0)
    rng = np.random.default_rng(3)
    path = tmp_path / "release.csv"
    with open(path, "w") as fh:
        fh.write(f"# mass: {DUFFING.m}\nt,force,z\n")
        force, zm = 0.3 + 0.05 * rng.standard_normal(t.size), z + 1e-6 * rng.standard_normal(t.size)
        np.savetxt(fh, np.column_stack([t, force, zm]), delimiter=",", fmt="%.9g")
    out = tmp_path / "nsi.json"
    assert main(["identify", "nsi", str(path), "--decay", "-o", str(out), "--quiet"]) == 0
    res = json.loads(out.read_text())
    assert res["record_kind"]["kind"] == "decay"
    assert res["model"]["k3"] == pytest.approx(DUFFING.k3, rel=0.01)
    bb = tmp_path / "bb.json"
    assert main(["backbone", str(path), "--decay", "-o", str(bb), "--quiet"]) == 0
    b = json.loads(bb.read_text())
    assert b["decay"]["start_s"] == pytest.approx(0.0, abs=1e-9)
    assert b["linear"]["f_hz"] == pytest.approx(12.0, rel=0.01)


def _accelerometer_file(tmp_path, model):
    force, acc, z = accelerometer_hammer(model, seed=1)
    path = tmp_path / "hammer_acc.csv"
    with open(path, "w") as fh:
        fh.write(f"# mass: {MASS}\n# fs: {FS:g}\nforce,y_acc\n")
        np.savetxt(fh, np.column_stack([force, acc]), delimiter=",", fmt="%.9g")
    return path, z


def _load_warned(path):
    from negstiff.inference.record.reading import load

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        rec = load(path)
    return rec, [str(w.message) for w in caught]


def test_an_accelerometers_hammer_record_is_read_whole_and_identified(tmp_path):
    # a hammer test measured by an accelerometer (an analyser's anti-aliased, decimated channels; the sensor's zero
    # and noise): its z is the acceleration integrated twice from rest (before the first hit) to rest (after the
    # last ring-down), above a tenth of the displacement's dominant frequency (1.2 Hz), no sample cut: the four hits
    # stay in the record (the trim of a stationary record's integral, 4 s at each end, left one). What the integral
    # cannot hold is the response below the corner (the hits' static part, impulse / k) and, the record ending at
    # 28 % of its loudest tenth, the last ring-down's rest: z within 8 % rms of the truth (measured 6.3 %); both
    # said in warnings. SINDy's weak form reads the Duffing from it: 12 Hz within 1 %, k3 within 5 % (measured
    # 11.989 Hz, -0.02 %). NSI's cubic does not survive the slow error (it refuses), said in docs/methods/nsi.md
    path, z = _accelerometer_file(tmp_path, DUFFING)
    rec, said = _load_warned(path)
    assert rec.n == z.size and "integrated from rest" in rec.info["response"]["derived"]
    assert any("below 1.2 Hz is lost" in w for w in said) and any("ends still ringing (28 %" in w for w in said)
    assert record_kind(rec).kind == "impact" and "4 hammer hit" in record_kind(rec).how
    err = (rec.z - rec.z.mean()) - (z - z.mean())
    assert np.sqrt(np.mean(err**2)) < 0.08 * z.std()
    est = _fit(SINDy(), rec)
    assert est.modal_["plus"]["f_hz"] == pytest.approx(12.0, rel=0.01)
    assert est.model_.k3 == pytest.approx(DUFFING.k3, rel=0.05)


def test_an_accelerometers_record_says_what_its_integral_loses(tmp_path):
    # the seed-like double well hit four times: its asymmetric well shifts its mean with the amplitude, a slow part
    # (the decay's envelope, ~0.4 Hz) below any accelerometer integral's corner: z errs by a quarter of its rms
    # (measured 24 %) and the warning names the quadratic stiffness as unreliable. The lightly damped Duffing's
    # record still rings at 62 % of its loudest tenth at its end: refused in one line that says why, not
    # integrated to a rest it never reaches (its z erred by 22 %, measured)
    path, z = _accelerometer_file(tmp_path, DOUBLE_WELL)
    rec, said = _load_warned(path)
    assert any("k2 read from it is not reliable" in w for w in said)
    light, _ = _accelerometer_file(tmp_path, LIGHT_DUFFING)
    with pytest.raises(MeasurementError, match="still rings at its end \\(6[0-9] %") as err:
        _load_warned(light)
    assert len(str(err.value).splitlines()) == 1
