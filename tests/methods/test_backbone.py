"""Backbones from free decays: the frequency and damping against amplitude, measured (Hilbert, peaks) and predicted.

The decays are written here with scipy's DOP853 (``impact_records``) and carry a laser's noise; the truth is the
oscillator's exact conservative backbone (the period of each orbit by quadrature, ``conservative_backbone``),
with its amplitude as each estimator defines it (the fundamental's for Hilbert, half the peak-to-peak for the
peaks). At 1.5-2 % damping the decay's frequency differs from the conservative orbit's by zeta^2/2 (0.02 %).
"""

import warnings

import numpy as np
import pytest
from impact_records import DOUBLE_WELL, DUFFING, DUFFING_HZ, MASS, decay_record, fixture_decay_record, hammer_record

from negstiff import Model
from negstiff.inference.analysis.backbone import backbone, conservative_backbone, decay_start, on_amplitudes
from negstiff.inference.record.measurement import from_arrays
from negstiff.models.structure import Structure

FS = 1024.0
LASER_M = 5e-6
"""A laser triangulation sensor's noise [m rms]: the backbone stops where the band-passed envelope is 100 times
it, where its phase noise moves a period's frequency by under 0.2 %."""


def _decay(model, z0, seed, duration=12.0):
    _, z, _ = decay_record(model, z0, FS, duration)
    zm = z + LASER_M * np.random.default_rng(seed).standard_normal(z.size)
    return from_arrays(np.zeros_like(zm), zm, FS, input_name="force", mass=MASS)


def _quiet(fn, *a, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return fn(*a, **kw)


def _against_truth(r, model, well):
    """The largest |f/f_true - 1| of the Hilbert and peak backbones over the amplitudes each covers, and the
    measured Hilbert curve's damping ratios beside the slow flow's."""
    truth = conservative_backbone(model, well, 0.03, n=80)
    h, p = r["measured"]["hilbert"], r["measured"]["peaks"]
    f_h = on_amplitudes(truth, np.array(h["amplitude_m"]))
    f_p = on_amplitudes({"amplitude_m": truth["peak_amplitude_m"], "f_hz": truth["f_hz"]}, np.array(p["amplitude_m"]))
    z_h = on_amplitudes(truth, np.array(h["amplitude_m"]), "zeta")
    assert np.all(np.isfinite(f_h)) and np.all(np.isfinite(f_p))  # the truth covers the whole measured range
    return (np.max(np.abs(np.array(h["f_hz"]) / f_h - 1)), np.max(np.abs(np.array(p["f_hz"]) / f_p - 1)),
            np.abs(np.array(h["zeta"]) / z_h - 1))  # fmt: skip


def test_duffing_decay_backbone_within_one_percent_of_the_exact_one():
    # released from rest at 15 mm: the hardening Duffing's frequency falls from 13.6 to 12 Hz as it rings down;
    # both estimators follow the exact backbone within 1 % from 12 mm to 0.1 mm (measured: 0.27 % and 0.18 %),
    # the damping ratio the slow flow's (viscous c: zeta falls from 1.5 % to 1.2 %; measured median 0.2 %, the
    # first periods, where the band-pass starts, up to 20 %)
    r = _quiet(backbone, _decay(DUFFING, 0.015, 1), model=DUFFING)
    lo, hi = r["amplitude_range_m"]
    assert hi > 0.01 and lo < 5e-4  # the record covers 10 mm down to under 0.5 mm
    err_h, err_p, err_z = _against_truth(r, DUFFING, "plus")
    assert err_h < 0.01 and err_p < 0.01
    assert np.median(err_z) < 0.10
    assert r["linear"]["f_hz"] == pytest.approx(DUFFING.uls("plus").f_hz, rel=0.01)
    # the model's own decay (negstiff's simulator from the record's state), measured alike: the same curve
    assert r["predicted"]["difference_percent"] < 1.0 and r["predicted"]["covered_share"] == 1.0


@pytest.mark.parametrize(("z0", "well"), [(0.0255, "plus"), (-0.0215, "minus")])
def test_double_well_decay_backbone_within_one_percent(z0, well):
    # the seed-like asymmetric double well released from rest 5.5-6.5 mm away from a well (within its basin):
    # softening in both wells (the quadratic term wins), 9.7 -> 10.3 Hz (plus) and 10.4 -> 11.2 Hz (minus);
    # measured 0.2 % (Hilbert) and 0.6 % (peaks) from the exact backbone, within 1 %
    r = _quiet(backbone, _decay(DOUBLE_WELL, z0, 2), model=DOUBLE_WELL)
    err_h, err_p, err_z = _against_truth(r, DOUBLE_WELL, well)
    assert err_h < 0.01 and err_p < 0.01
    assert np.median(err_z) < 0.10
    assert r["decay"]["rest_m"] == pytest.approx(DOUBLE_WELL.equilibria().well(well), abs=1e-4)
    assert r["predicted"]["difference_percent"] < 1.0


def test_the_models_forced_response_peaks_on_its_backbone_over_the_decays_range():
    # the forced responses drawn with the backbone (as SSMLearn and FrID draw them): a lightly damped oscillator's
    # displacement resonance lies at its backbone's frequency times sqrt(1 - 2 zeta^2) (the linear one's, at every
    # amplitude while the damping is light): -0.0225 % at 1.5 %, measured -0.0224 to -0.0237 % against the exact
    # backbone (the continuation's peak between its points, to 0.002 %). The levels' peaks climb through the
    # decay's amplitudes, and at the top level the hardening curve bends past its folds (an unstable middle
    # branch: the jump a sweep up shows)
    r = _quiet(backbone, _decay(DUFFING, 0.008, 3, duration=8.0), model=DUFFING)
    forced = r["forced"]
    assert forced["well"] == "plus" and len(forced["curves"]) == 3 and forced["warnings"] == []
    truth = conservative_backbone(DUFFING, "plus", 0.01, n=80)
    shift = np.sqrt(1 - 2 * DUFFING.uls("plus").zeta ** 2) - 1
    a_max = max(r["measured"]["peaks"]["amplitude_m"])
    peaks = []
    for c in forced["curves"]:
        f_true = np.interp(c["peak"]["amplitude_m"], truth["peak_amplitude_m"], truth["f_hz"])
        assert c["peak"]["f_hz"] / f_true - 1 == pytest.approx(shift, abs=3e-5)
        assert c["peak_off_backbone_percent"] == pytest.approx(100 * shift, abs=3e-3)
        peaks.append(c["peak"]["amplitude_m"])
    assert peaks == sorted(peaks) and peaks[-1] > 0.8 * a_max
    assert not all(forced["curves"][-1]["stable"]) and all(forced["curves"][0]["stable"])


def test_the_forced_levels_reach_the_decays_amplitudes_under_quadratic_damping():
    # quadratic damping (c_nl = 2 N s^2/m^2: at 8 mm and 12 Hz 2.4x the viscous c's dissipation) grows with the
    # amplitude: the levels are set by the energy the model's damping takes from the harmonic orbit at each target
    # amplitude, so each curve's peak reaches its target (0.25, 0.5, 0.9 of the decay's largest half peak-to-peak)
    # within 5 %, what the orbit's harmonics (a cosine is assumed) allow (measured: 0.250, 0.501, 0.904); the well's
    # linear damping alone put the peaks at 0.19, 0.32 and 0.49 (measured)
    model = Model(m=MASS, k1=DUFFING.k1, k2=0.0, k3=DUFFING.k3, c=DUFFING.c, c_nl=2.0, k0=0.0)
    r = _quiet(backbone, _decay(model, 0.008, 4, duration=8.0), model=model)
    a_max = max(r["measured"]["peaks"]["amplitude_m"])
    for level, c in zip((0.25, 0.5, 0.9), r["forced"]["curves"], strict=True):
        assert c["peak"]["amplitude_m"] == pytest.approx(level * a_max, rel=0.05), (level, c["peak"])


def test_decay_after_a_hammer_hit_and_the_offset_of_its_force():
    # a hard hit (40 N over 4 ms, 6 mm) on the Duffing, the force channel with its offset and noise: the decay
    # starts after the pulse, and its backbone is the exact one within 1 %
    rng = np.random.default_rng(4)
    _, f, z, _ = hammer_record(DUFFING, 0.0, FS, [0.5], 40.0, 0.004, 10.0)
    rec = from_arrays(f + 0.5 + 0.01 * rng.standard_normal(f.size), z + LASER_M * rng.standard_normal(z.size), FS,
                      input_name="force", mass=MASS)  # fmt: skip
    start, _ = decay_start(rec)
    assert 0.504 <= start / FS < 0.52
    r = _quiet(backbone, rec)
    err_h, err_p, _ = _against_truth(r, DUFFING, "plus")
    assert err_h < 0.01 and err_p < 0.01


def test_posterior_draws_give_a_band_that_holds_the_truth():
    # draws of k3 within +-5 % of the truth: the predicted backbone's 90 % band brackets the truth's prediction and
    # is as wide as k3 makes it: at 8 mm the cubic holds 12 % of w^2 (3/4 k3 a^2 / m against w0^2), so the draws'
    # 90 % span of k3 (9 %) spans 1.1 % of w^2, 0.55 % of f; at 0.5 mm the cubic holds 0.05 % of w^2 and the band
    # is the estimator's own scatter between the draws' decays (measured: up to 0.15 %), under 0.2 %
    rec = _decay(DUFFING, 0.015, 5)
    draws = [Model(m=MASS, k1=DUFFING.k1, k2=0.0, k3=DUFFING.k3 * s, c=DUFFING.c, k0=0.0)
             for s in (0.95, 0.975, 1.0, 1.025, 1.05)]  # fmt: skip
    r = _quiet(backbone, rec, model=DUFFING, draws=draws)
    band = r["credible"]
    a = np.array(band["amplitude_m"])
    f_true = on_amplitudes(r["predicted"]["hilbert"], a)
    lo, hi = np.array(band["f_hz_low"]), np.array(band["f_hz_high"])
    ok = np.isfinite(f_true) & np.isfinite(lo)
    assert np.all((lo[ok] <= f_true[ok] * 1.0005) & (f_true[ok] <= hi[ok] * 1.0005))
    width = (hi - lo) / f_true
    assert 0.004 < width[np.argmin(np.abs(a - 0.008))] < 0.007
    assert np.all(width[a < 5e-4] < 0.002)


def test_cli_backbone_with_a_model(tmp_path, capsys):
    # negstiff backbone DATA --model M.json: the measured and predicted curves in the JSON, a figure beside it
    import json

    from negstiff.cli import main

    _, z, _ = decay_record(DUFFING, 0.012, FS, 8.0)
    zm = z + LASER_M * np.random.default_rng(6).standard_normal(z.size)
    data = tmp_path / "decay.csv"
    np.savetxt(data, np.column_stack([np.zeros_like(zm), zm]), delimiter=",", header="force,z", comments="# fs: 1024\n")
    model = tmp_path / "model.json"
    model.write_text(json.dumps(DUFFING.to_dict()))
    out = tmp_path / "bb.json"
    assert main(["backbone", str(data), "--model", str(model), "-o", str(out)]) == 0
    r = json.loads(out.read_text())
    assert r["predicted"]["difference_percent"] < 1.0
    assert r["linear"]["f_hz"] == pytest.approx(DUFFING_HZ, rel=0.01)
    assert [c["force_n"] for c in r["forced"]["curves"]] == sorted(c["force_n"] for c in r["forced"]["curves"])
    assert (tmp_path / "bb.png").exists() and "small-amplitude" in capsys.readouterr().err


FIXTURE = {"fixture_mass": 1.0, "fixture_hz": 25.0, "fixture_zeta": 0.02}
STRUCTURE_FS = 1000.0


@pytest.fixture(scope="module")
def structure_decay():
    """The hardening Duffing between a sprung fixture (DOF 1: 1 kg, 25 Hz, 2 %) and its mass (DOF 2), both released
    at rest 3 mm from their rests in opposite directions, so both modes ring (11.66 Hz, 1.42 % and 25.73 Hz, 2.14 %
    at rest); 8 s at 1 kHz written with scipy's DOP853 (``fixture_decay_record``), 1 um of laser noise on each
    channel: the record, the truth's structure."""
    _, z = fixture_decay_record(DUFFING, FIXTURE, (0.003, -0.003), STRUCTURE_FS, 8.0)
    zm = z + 1e-6 * np.random.default_rng(4).standard_normal(z.shape)
    rec = from_arrays(np.zeros(zm.shape[1]), zm, STRUCTURE_FS, input_name="force", masses=(1.0, MASS), gravity=0.0,
                      source="a structure's decay")  # fmt: skip
    return rec, Structure.on_fixture(DUFFING, **FIXTURE)


@pytest.mark.parametrize(("dof", "mode"), [(2, 0), (1, 1)])
def test_a_structures_decay_gives_the_backbone_of_the_mode_each_channel_shows(structure_decay, dof, mode):
    # a structure's decay rings in its modes at once; band-passed between the decay's resonances (the channels'
    # periodogram peaks; ``mode_band``), the mode a channel shows most rings as a single DOF on its own
    # backbone: the device's mass (DOF 2) the 11.7 Hz mode, the fixture (DOF 1) the 25.7 Hz one (measured: 11.661 Hz
    # / 1.424 %, 25.727 Hz / 2.140 %). At the smallest amplitudes each is its underlying-linear mode, within 0.5 % in
    # frequency (the noise's phase error in a period stays under 0.2 % above the backbone's floor) and 10 % in
    # damping (the single DOF's tolerance); the truth's structure, decayed by negstiff's simulator from the record's
    # state and measured alike, follows the measured curve within 0.5 % (measured 0.11 %, 0.08 %)
    rec, truth = structure_decay
    r = _quiet(backbone, rec, model=truth, dof=dof)
    true = truth.modes("plus")[mode]
    assert r["dof"] == dof and len(r["modes_hz"]) == 2
    assert r["linear"]["f_hz"] == pytest.approx(true.f_hz, rel=0.005)
    assert r["linear"]["zeta"] == pytest.approx(true.zeta, rel=0.10)
    assert r["predicted"]["difference_percent"] < 0.5 and r["predicted"]["covered_share"] > 0.9
    if mode == 0:  # the device's mode, the element's: it hardens (the fixture's, mostly the linear spring's, beats
        h = r["measured"]["hilbert"]  # with the device's mode through the element in its first second: 25.3-25.9 Hz)
        a = np.array(h["amplitude_m"])
        assert np.median(np.array(h["f_hz"])[a > np.quantile(a, 0.9)]) > r["linear"]["f_hz"]
    assert any("no forced response drawn for a structure" in w for w in r["warnings"])


def test_the_channel_that_moves_most_is_read_by_default_and_a_bad_one_is_one_line(structure_decay):
    from negstiff.errors import MeasurementError

    rec, truth = structure_decay
    assert _quiet(backbone, rec)["dof"] == 2  # the device's mass moves most
    with pytest.raises(MeasurementError, match="1..2"):
        backbone(rec, dof=3)
    with pytest.raises(MeasurementError, match="1 DOF"):
        backbone(rec, model=DUFFING)


def test_cli_backbone_of_a_structure_writes_the_librarys_numbers(structure_decay, tmp_path, capsys):
    import json

    from records import write_csv

    from negstiff.cli import main

    rec, truth = structure_decay
    t = np.arange(rec.n) / rec.fs
    data = write_csv(tmp_path / "decay.csv", {"t": t, "force": rec.u, "z1": rec.z[0], "z2": rec.z[1]},
                     {"masses": "1.0,0.2"})  # fmt: skip
    model = tmp_path / "structure.json"
    model.write_text(json.dumps(truth.to_dict()))
    out = tmp_path / "bb.json"
    assert main(["backbone", str(data), "--model", str(model), "--dof", "1", "--gravity", "0", "-o", str(out)]) == 0
    r = json.loads(out.read_text())
    lib = _quiet(backbone, rec, model=truth, dof=1)
    assert r["linear"]["f_hz"] == pytest.approx(lib["linear"]["f_hz"], rel=1e-6) and r["dof"] == 1
    assert "DOF 1" in capsys.readouterr().err and (tmp_path / "bb.png").exists()
    single = tmp_path / "single.json"
    single.write_text(json.dumps(DUFFING.to_dict()))
    for bad, why in ((["--dof", "3"], "--dof 3"), (["--model", str(single)], "1 DOF"), (["--band", "0:30"], "--band")):
        assert main(["backbone", str(data), *bad, "-o", str(tmp_path / "x.json")]) == 2
        assert why in capsys.readouterr().err
        assert not (tmp_path / "x.json").exists()


def test_a_structures_model_decays_from_the_record_less_each_channels_zero():
    # a structure's lasers each read from their own zero (measured = physical + offset; its identification finds
    # them, ``offsets_``): the seed-like double well on its fixture released 4 mm above its plus well, the device's
    # laser zeroed 12 mm away. Given the zeros, the truth's structure starts from the physical state (within the
    # smoothing's error) and its backbone follows the measured one within 0.5 % (measured 0.05 %; from the raw
    # readings, 12 mm off its state, 0.34 %)
    from impact_records import DOUBLE_WELL

    s = Structure.on_fixture(DOUBLE_WELL, **FIXTURE)
    x0 = s.static_positions(s.element_equilibria().z_plus) + np.array([0.0, 0.004])
    _, z = fixture_decay_record(DOUBLE_WELL, FIXTURE, tuple(x0), STRUCTURE_FS, 8.0)
    zeros = np.array([0.0004, -0.012])
    zm = z + zeros[:, None] + 1e-6 * np.random.default_rng(4).standard_normal(z.shape)
    rec = from_arrays(np.zeros(zm.shape[1]), zm, STRUCTURE_FS, input_name="force", masses=(1.0, MASS),
                      gravity=DOUBLE_WELL.k0 / MASS)  # fmt: skip
    r = _quiet(backbone, rec, model=s, dof=2, offsets=zeros)
    assert r["predicted"]["initial"]["z0_m"] == pytest.approx(x0[1], abs=1e-5)
    assert r["predicted"]["difference_percent"] < 0.5
