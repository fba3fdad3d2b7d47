"""Real public records shipped with the tests: a measured free decay of a hardening oscillator and a measured hammer
hit (issue "Hammer and decay tests").

FrID (T. Breunung, B. Balachandran, "Frequency response based identification of nonlinear oscillators", J. Sound
Vib. 2024, 118651; https://github.com/tbreunung/FrID, MIT License) holds the strain-gauge record of a cantilever
beam stiffened by magnets (a hardening single-DOF oscillator) ringing down after a shaker driving it at 42.05 Hz
is switched off, and the authors' SINDy model fitted to that decay (a MATLAB figure). Both are in
``tests/data/frid_magneto_mechanical_decay`` (the record cut to the authors' decay window, 12.1-19.1 s; its
README says what was cut and why the reference is the SINDy fit).

Acceptance (the issue): the identified linear frequency within 1 % of the published value, the backbone within 2 %.
The published value is the authors' identification of this record: their SINDy model's free decay, read cycle by
cycle here with plain numpy (period between upward zero crossings, half peak-to-peak amplitude). The tolerances
are the acceptance's; what each estimate reached is in the comments.

The Engineering Vibration Toolbox for Python (J. C. Slater, R. Timbó; https://github.com/vibrationtoolbox/
vibration_toolbox, MIT License) ships ``case1.mat``, a two-channel analyser's record of one hammer hit (force and
response, 1280 Hz, 3.2 s) on a lightly damped structure, and identifies its mode in a doctest of ``sdof_cf``:
212.0925 Hz. The file is in ``tests/data/vibration_toolbox_hammer_case1``, unchanged (its README says what the
source documents and what it does not: the channels' units and the response's quantity). Acceptance (the issue):
``frf``'s frequency of the hit within 1 % of the published one. NSI and SINDy are not compared on it: the record is
a continuous structure's (its response outside 180-245 Hz is half the mode's rms in the first 50 ms) sampled at
six samples per cycle of its mode, not a single DOF's, and both refuse it (NSI: no stable underdamped pole; SINDy:
its model diverges in the free runs).
"""

import json
import warnings
from functools import cache
from pathlib import Path

import numpy as np
import pytest
from scipy.io import loadmat
from scipy.signal import butter, hilbert, sosfiltfilt

from negstiff import NSI, SINDy
from negstiff.inference.analysis.backbone import backbone, on_amplitudes
from negstiff.inference.analysis.frf import frf
from negstiff.inference.record.impacts import find_impacts
from negstiff.inference.record.reading import load

FRID = Path(__file__).parents[1] / "data" / "frid_magneto_mechanical_decay"
RECORD = FRID / "decay_f_42p05_ampl_2p0_0_12p1-19p1s.lvm"
COLUMNS = "force=Sine with Gaussian Noise,z=Strain_0"
"""The generator's output as the input (0 throughout the cut: a free decay), the beam's strain gauge as z (in the
gauge's units, ~2e-4 at the start: the frequencies do not depend on the scale)."""

SMALL_CYCLES = 5
"""The reference's linear frequency: the mean over its last (smallest) five cycles, 4.7e-6 to 5.4e-6 strain, where
its frequency has stopped falling (36.818-36.822 Hz)."""


def _cycles(t: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each cycle between two upward zero crossings (linear interpolation): its half peak-to-peak amplitude and
    its frequency 1 / period."""
    s = np.sign(x)
    i = np.flatnonzero((s[:-1] < 0) & (s[1:] >= 0))
    tc = t[i] - x[i] * (t[i + 1] - t[i]) / (x[i + 1] - x[i])
    amp = np.array([np.ptp(x[a + 1 : b + 1]) / 2 for a, b in zip(i[:-1], i[1:], strict=True)])
    return amp, 1.0 / np.diff(tc)


@cache
def _published() -> dict[str, np.ndarray]:
    """The authors' SINDy model's free decay (the figure's line 'SinDy'), cycle by cycle."""
    fig = loadmat(FRID / "SinDy_decay_fit.fig", squeeze_me=True, struct_as_record=False)["hgS_070000"]
    axes = next(c for c in np.atleast_1d(fig.children) if c.type == "axes")
    line = next(c.properties for c in np.atleast_1d(axes.children)
                if "line" in c.type and c.properties.DisplayName == "SinDy")  # fmt: skip
    amp, f = _cycles(np.asarray(line.XData, float), np.asarray(line.YData, float))
    return {"amplitude_m": amp, "f_hz": f}


@cache
def _record():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return load(RECORD, columns=COLUMNS, gravity=0.0)


@cache
def _measured() -> dict:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return backbone(_record())


def test_the_lvm_record_is_read_as_a_free_decay_from_its_first_sample():
    # the file as LabVIEW wrote it (twelve channels, three of them 1 Hz and empty between their samples), the
    # generator's output at 0 throughout: a decay from 12.100 s, the authors' own start
    rec = _record()
    assert rec.fs == pytest.approx(1000.0) and rec.n == 7000 and rec.t0 == pytest.approx(12.1)
    assert np.all(np.asarray(rec.u) == 0.0)
    assert _measured()["decay"]["start_s"] == pytest.approx(12.1, abs=1e-9)


def test_the_linear_frequency_of_the_decay_is_the_published_one():
    # the published model's smallest cycles: 36.820 Hz; the Hilbert backbone's smallest fifth of amplitudes
    # (1.3e-5 to 1.9e-5): 36.888 Hz, +0.18 %
    f_published = float(np.mean(_published()["f_hz"][-SMALL_CYCLES:]))
    assert _measured()["linear"]["f_hz"] == pytest.approx(f_published, rel=0.01)


@pytest.mark.parametrize("estimator", ["hilbert", "peaks"])
def test_the_backbone_of_the_decay_is_the_published_one(estimator):
    # hardening from 36.8 Hz to 41.3 Hz over the decay; at each of 12 amplitudes (geometric, over the range both
    # curves cover) the measured frequency within 2 % of the published model's. Measured (Hilbert): +0.04 % at
    # 1.7e-5 to +1.63 % at 1.6e-4; the peaks +0.18 % to +1.48 % where they reach. The authors' own filtered decay
    # read cycle by cycle is 1.7 % above their model at 1.6e-4: the fit's error, not the estimators'.
    pub, meas = _published(), _measured()
    lo = max(pub["amplitude_m"].min(), meas["amplitude_range_m"][0])
    hi = min(pub["amplitude_m"].max(), meas["amplitude_range_m"][1])
    grid = np.geomspace(lo, hi, 12)
    f_pub = on_amplitudes(pub, grid)
    f_meas = on_amplitudes(meas["measured"][estimator], grid)
    covered = np.isfinite(f_meas)
    assert covered.sum() >= (12 if estimator == "hilbert" else 8), covered
    assert hi / lo > 10  # the comparison spans the decay, not its tail
    np.testing.assert_allclose(f_meas[covered], f_pub[covered], rtol=0.02)
    assert f_meas[covered][-1] > 1.08 * f_meas[covered][0]  # the hardening is read, not a flat line


@pytest.mark.parametrize("method", [NSI, SINDy], ids=["nsi", "sindy"])
def test_nsi_and_sindy_identify_the_decays_linear_frequency(method):
    # each on the decay (no input, per unit mass): its well's linearised frequency. Measured: NSI 36.838 Hz
    # (+0.05 %), SINDy 36.649 Hz (-0.46 %), both models with quadratic and cubic stiffness; a second or two each
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        est = method().fit(_record())
    assert est.result_.details["record_kind"]["kind"] == "decay"
    f_published = float(np.mean(_published()["f_hz"][-SMALL_CYCLES:]))
    found = [m["f_hz"] for m in est.modal_.values() if m["f_hz"] is not None]
    assert found and min(abs(f / f_published - 1) for f in found) < 0.01, found


HAMMER = Path(__file__).parents[1] / "data" / "vibration_toolbox_hammer_case1" / "case1.mat"
HAMMER_FS = 1280.0
"""The analyser's rate (``Time_Sample_Rate``): the file's single-precision time column drifts off it by up to 7e-8 s a
step, which ``load`` rightly refuses as a clock."""

HAMMER_COLUMNS = "force=Time_chan_1,z=Time_chan_2"
"""The hammer's channel as the force, the response as z. The response's quantity is not documented; a mode damped
0.09 % peaks at the same frequency in receptance, mobility and accelerance (within zeta^2 ~ 1e-6), so reading it as
z moves nothing the tests measure. Its units are not documented either (it spans 14 'm'): frequencies and damping
do not depend on the scale."""

HAMMER_F_PUBLISHED_HZ = 212.092530551
"""The toolbox's identification of this file: ``vtb.sdof_cf(Freq_domain, Hf_chan_2, 500, 1000)`` -> ``nf``, printed
212.092530551... in its docstring example (``vibration_toolbox/ema.py``, a doctest): an SDOF fit of the analyser's
averaged FRF over 156-312 Hz."""


@cache
def _hammer_record():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the response's span in 'm' (units not documented)
        return load(HAMMER, columns=HAMMER_COLUMNS, fs=HAMMER_FS, gravity=0.0)


@cache
def _hammer_frf() -> dict:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # one hit: its coherence is 1 by construction (said in the result)
        return frf(_hammer_record())


def test_the_mat_record_is_one_hammer_hit_at_its_start():
    # the analyser's export as the toolbox ships it (variables of three lengths; the time record is 4096 samples):
    # one pulse of a few ms at the block's start (the analyser triggered on it), on a channel settled at an offset
    rec = _hammer_record()
    assert rec.fs == HAMMER_FS and rec.n == 4096 and rec.input_name == "force"
    hits = find_impacts(rec.u, rec.fs)
    assert hits is not None and hits.count == 1
    assert hits.starts[0] < 4  # the block opens on the hit's rise: no pre-trigger to read the offset from
    assert 2e-3 < (hits.pulse_ends[0] - hits.starts[0]) / rec.fs < 10e-3  # a hammer's contact: 4.7 ms here
    # (its peak stands 32 floor deviations high, just over the 30 an impact needs: a light tap or a 1280 Hz
    # analyser's few samples of the pulse)


def test_frf_of_the_hammer_hit_is_the_published_frequency():
    # the hit's H1 (force window, the exponential window the 4.7 % ring-down at the block's end needs, one SDOF
    # receptance fitted): 212.0987 Hz, +0.003 % from the toolbox's 212.0925 Hz (from the analyser's FRF averaged
    # over hits the file does not hold); the band-passed ring-down's zero crossings over 0.5-3 s give 212.105 Hz.
    # The acceptance is 1 %; the FRF's bins (zero-padded 4x) are 0.078 Hz apart, 0.04 % of the mode
    r = _hammer_frf()
    assert r["impacts"]["hits"] == 1 and r["impacts"]["exponential_tau_s"] is not None
    assert r["f_hz"] == pytest.approx(HAMMER_F_PUBLISHED_HZ, rel=0.01)
    assert len(r["peaks"]) == 1  # the only mode fitted in the hammer's band (0.6-415 Hz): one local maximum at
    # 34 Hz is set aside (its SDOF fit erred by over 5 % of its peak)


def test_frf_damping_of_the_hammer_hit_is_the_ring_downs_own():
    # the exponential window's added decay (1/tau = 0.48 1/s, 0.036 % at 212 Hz) taken off the fit: 0.087 %. The
    # ring-down's own decay, independent of the FRF: the envelope (Hilbert) of the response band-passed around the
    # mode (180-245 Hz, 4th-order Butterworth forward and back), a straight line in log over 0.3-2.5 s, where the
    # early transient of the other modes has died: 0.089 % (0.086-0.097 % over windows from 0.3-1 s to 2.5-3 s, the
    # FRF's 0.087 % 3 % below this one, 10 % below the highest). Within 15 %: the windowed fit, uncorrected
    # (0.123 %), is 38 % above
    rec, r = _hammer_record(), _hammer_frf()
    x = np.asarray(rec.z, float)
    t = np.arange(x.size) / rec.fs
    env = np.abs(hilbert(sosfiltfilt(butter(4, [180.0, 245.0], btype="band", fs=rec.fs, output="sos"), x)))
    on = (t >= 0.3) & (t <= 2.5)
    sigma = -np.polyfit(t[on], np.log(env[on]), 1)[0]
    zeta_ring_down = sigma / (2 * np.pi * r["f_hz"])
    assert r["zeta"] == pytest.approx(zeta_ring_down, rel=0.15)
    assert r["peaks"][0]["windowed"]["zeta"] > 1.3 * zeta_ring_down  # the correction is what brings it there


def test_cli_frf_reads_the_hammer_mat_file(tmp_path):
    # the command a user runs on the analyser's file: its columns mapped, its rate given; the same mode
    from negstiff.cli import main

    out = tmp_path / "case1.json"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert main(["frf", str(HAMMER), "--columns", HAMMER_COLUMNS, "--fs", str(HAMMER_FS), "--gravity", "0",
                     "--quiet", "-o", str(out)]) == 0  # fmt: skip
    r = json.loads(out.read_text())
    assert r["impacts"]["hits"] == 1
    assert r["f_hz"] == pytest.approx(HAMMER_F_PUBLISHED_HZ, rel=0.01)


def test_a_short_accelerometer_hammer_record_is_read():
    # if the response is an accelerometer's (the file does not say; other exports of this analyser's layout hold an
    # acceleration in g), mapping it so reads the whole 3.2 s block (before, load refused it: the trim of a
    # stationary record's integral, 4 s at each end): a hammer's record is integrated from rest, above a tenth of
    # its dominant frequency (21 Hz). Read as an acceleration the block's lower mode near 34 Hz is the receptance's
    # largest peak (divided by w^2: 39x the 212 Hz mode's weight), so the mode is asked for in its band, as a user
    # would: within 1 % of the published value (measured +0.000 %)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rec = load(HAMMER, columns="force=Time_chan_1,y_acc=Time_chan_2", fs=HAMMER_FS, gravity=0.0)
        r = frf(rec, band=(150.0, 300.0))
    assert rec.n == 4096 and "integrated from rest" in rec.info["response"]["derived"]
    assert r["f_hz"] == pytest.approx(HAMMER_F_PUBLISHED_HZ, rel=0.01)


def test_the_coefficient_posterior_reads_the_real_decay():
    # the posterior on the strain gauge's record (per unit mass, in the gauge's units: k3 ~ 6e11): its start was
    # moved off its bound by a millionth of a prior span floored at 1e-3 of k3's magnitude, which put c at 5000
    # and the start diverged ("not made" in the report). A short run (two ensembles, 400 steps: not converged, and
    # it says so) gives a mean model whose well is the published frequency within 1 % (measured 36.852 Hz)
    from negstiff import Posterior

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        post = Posterior(n_ensembles=2, min_steps=200, max_steps=400).fit(_record())
    model = post.model_
    z = model.equilibria().well("plus")
    f_well = float(np.sqrt(model.stiffness(z) / model.m) / (2 * np.pi))
    f_published = float(np.mean(_published()["f_hz"][-SMALL_CYCLES:]))
    assert f_well == pytest.approx(f_published, rel=0.01)
    assert post.result()["parameters"]["c"]["hdi_high"] < 100  # the viscous c where the data put it, not at 5000


def test_the_laws_model_follows_the_decays_damping_as_it_rises_and_falls():
    # The measured damping ratio rises from 0.3 % to 0.7 % with amplitude and falls back to 0.58 % (the Hilbert
    # backbone): c z' + c_nl z'|z'| can only rise, so the cubic with the reference study's damping misses it by
    # 0.18 % rms over 0.0135-0.19 mm (measured 0.177 %). The spline with polynomial damping (c3 < 0) follows it
    # within 0.030 % rms, about the measured curve's own scatter from one Hilbert point to the next (0.02-0.04 %),
    # and its frequency within 0.13 % (the cubic's 0.61 %)
    from negstiff import NSI
    from negstiff.inference.analysis.backbone import measure_backbone, on_amplitudes, predict_backbone

    rec = _record()
    measured = measure_backbone(rec)
    amplitudes = np.geomspace(0.0135e-3, 0.19e-3, 30)
    rms = {}
    for law, damping in (("spline", "polynomial_damping"), ("cubic", "quadratic")):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            model = NSI(law=law, damping=damping).fit(rec).model_
        predicted = predict_backbone(model, rec, measured)
        dz = on_amplitudes(measured["hilbert"], amplitudes, "zeta") - on_amplitudes(predicted["hilbert"], amplitudes,
                                                                                     "zeta")  # fmt: skip
        assert np.isfinite(dz).sum() >= 25, law
        rms[law] = float(np.sqrt(np.nanmean(dz**2)))
    assert rms["spline"] < 0.0006 < 0.0012 < rms["cubic"], rms
    assert rms["spline"] < rms["cubic"] / 3, rms


def test_the_report_of_a_law_compares_each_force_with_the_posteriors_band(tmp_path):
    # The decay's damping ratio rises with amplitude and falls back (the backbone: 0.3 -> 0.7 -> 0.58 %), which
    # c z' + c_nl z'|z'| + c3 z'^3 follows with c3 < 0. The posterior's prior had held every damping term >= 0, so
    # its start (c3 < 0) had no point of positive density and no posterior was made; now the law's damping as a
    # whole dissipates at every speed the record reached, and c3's sign is the data's: a short run (two ensembles,
    # 150 steps) puts c3 below zero and holds NSI's c, c_nl and c3 inside its 90 % intervals (measured: NSI's c
    # 0.870 in 0.74-1.05, c_nl 196.5 in 176-216, c3 -3351 in -3800 to -2990). SINDy's too: its selection keeps c
    # alone (the weak form barely sees the small damping terms), and its refinement now frees every field of the
    # named laws (it held c_nl at zero, at c 2.9, three times the posterior's): c 0.80, c_nl 202, c3 -3433.
    # The report compares a spline by its
    # force (its coefficients weigh basis functions on knots each fit chooses): NSI's inside the posterior's band
    # over most of the stroke (measured 76-81 %)
    import json

    from negstiff.cli import main

    out = tmp_path / "out"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert main(["report", str(RECORD), "--columns", COLUMNS, "--gravity", "0", "--only", "nsi,sindy,posterior",
                     "--law", "spline", "--damping", "polynomial_damping", "--max-steps", "150", "--ensembles", "2",
                     "--quiet", "-o", str(out)]) == 0  # fmt: skip
    res = json.loads((out / "results.json").read_text())
    summary = res["summary"]
    inside = next(line for line in summary if line.startswith("Estimates inside"))
    assert "NSI 3 of 3 (c, c_nl, cubic_damping)" in inside and "SINDy 3 of 3 (c, c_nl, cubic_damping)" in inside
    band = next(line for line in summary if line.startswith("The restoring force inside the posterior's 90 % band"))
    assert int(band.split("NSI over ")[1].split(" %")[0]) >= 60, band
    assert not any(k.startswith("spline.") for k in res["coefficients"])
    assert res["coefficients"]["cubic_damping"]["posterior"]["hdi_high"] < 0


def test_a_laws_start_outside_the_posteriors_support_is_refused_naming_the_check_it_fails():
    # the cubic with polynomial damping: the deterministic start's c3 outgrows c and c_nl within the record's speeds
    # (its damping feeds energy in near 0.06 m/s), refused before any sampling with the check named (the message had
    # listed every prior)
    from negstiff import Posterior
    from negstiff.inference.estimators.posterior.windows import PosteriorError

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(PosteriorError, match="it fails the damping dissipates at every speed up to"):
            Posterior(law="cubic", damping="polynomial_damping").fit(_record())


def test_the_reports_posterior_of_the_law_the_record_asks_for_is_the_identifications_choice(tmp_path):
    # report --law auto: the posterior (which samples a named law) samples the law NSI chose (it refused 'auto',
    # and the report failed in a second)
    import json

    from negstiff.cli import main

    out = tmp_path / "out"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert main(["report", str(RECORD), "--columns", COLUMNS, "--gravity", "0", "--only", "nsi,posterior",
                     "--law", "auto", "--max-steps", "150", "--ensembles", "2", "--quiet",
                     "-o", str(out)]) == 0  # fmt: skip
    sections = {s["kind"]: s["result"] for s in json.loads((out / "results.json").read_text())["sections"]}
    chosen = sections["identification"]["law_choice"]["chosen"]
    assert (
        sections["posterior"]["settings"]["law"]["restoring"] == chosen == sections["identification"]["settings"]["law"]
    )


def test_the_reports_identification_says_what_its_held_out_error_is_made_of(tmp_path):
    # on the real decay NSI's one free run over the held-out tail errs by 42 % of the tail's rms (the tail rings at
    # 1e-6 against the gauge's 3.3e-7 of noise); over half of that squared error is a constant offset between the
    # model's rest and the record's (-4.3e-7: measured 54 %), which the report says beside the number
    from negstiff.cli import main

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert main(["report", str(RECORD), "--columns", COLUMNS, "--gravity", "0", "--only", "nsi", "--quiet",
                     "-o", str(tmp_path / "out")]) == 0  # fmt: skip
    text = (tmp_path / "out" / "index.md").read_text()
    assert "squared error is a constant offset" in text
