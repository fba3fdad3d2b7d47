"""Harmonic records as a lab acquires them: coarse sampling whose harmonics fold back, a transient and a
jump between wells at the start, a stated forcing frequency that is not the input's.

Every record here is integrated by scipy's DOP853 from a plain double-well Duffing oscillator written in
this file (per unit mass: z'' + c z' - k1 z + k3 z^3 = -b''), never by negstiff's simulator: wells at
+-20 mm, in-well linear frequency sqrt(2 k1) / 2 pi = 10 Hz, 5 % in-well damping. Sampling is a plain
point sampler (no anti-aliasing filter: harmonics above the Nyquist frequency fold back), the laser's
noise 20 um and the accelerometer's 0.03 m/s^2 rms, white, from a seeded generator.
"""

import functools
import warnings

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from negstiff.cli import main
from negstiff.errors import InputError, RecordWarning
from negstiff.inference.analysis.characterise import characterise
from negstiff.inference.record.measurement import from_arrays

Z_WELL = 0.020  # m
K1 = 0.5 * (2 * np.pi * 10.0) ** 2  # 1/s^2: in-well linear frequency 10 Hz
K3 = K1 / Z_WELL**2  # 1/(m^2 s^2): wells at +-Z_WELL
C = 2 * 0.05 * 2 * np.pi * 10.0  # 1/s: 5 % of critical in the well
LASER_NOISE = 20e-6  # m rms
ACCELEROMETER_NOISE = 0.03  # m/s^2 rms


def _rhs(t, x, a, w):
    z, v = x
    return [v, -(C * v - K1 * z + K3 * z**3) - a * np.sin(w * t)]


def _solve(x0, a, f_hz, t_eval):
    w = 2 * np.pi * f_hz
    return solve_ivp(_rhs, (0.0, t_eval[-1]), x0, args=(a, w), method="DOP853", rtol=1e-8, atol=1e-11,
                     t_eval=t_eval).y  # fmt: skip


def _record(a, f_hz, fs, duration, settle=0.0, seed=0):
    """The Duffing oscillator at rest in the plus well, forced from t = 0 at ``a`` m/s^2 and ``f_hz``,
    recorded from ``settle`` s on for ``duration`` s at ``fs`` (point samples, noise added), with the true
    stroboscopic z (phase 0 of every forcing cycle from 0 to the record's end)."""
    n_settle = int(round(settle * f_hz))
    t_rec = n_settle / f_hz + np.arange(int(round(duration * fs))) / fs
    n_cycles = int(t_rec[-1] * f_hz)
    t_strobe = np.arange(n_cycles + 1) / f_hz
    t_all = np.union1d(t_rec, t_strobe)
    y = _solve([Z_WELL, 0.0], a, f_hz, t_all)
    z_true = y[0][np.searchsorted(t_all, t_rec)]
    strobe = y[0][np.searchsorted(t_all, t_strobe)]
    rng = np.random.default_rng(seed)
    z = z_true + LASER_NOISE * rng.standard_normal(t_rec.size)
    u = a * np.sin(2 * np.pi * f_hz * t_rec) + ACCELEROMETER_NOISE * rng.standard_normal(t_rec.size)
    return from_arrays(u, z, fs), strobe


def _true_period(strobe, tail=60, tol=1e-6):
    s = strobe[-tail:]
    return next((p for p in (1, 2, 4, 8, 16) if np.abs(s[p:] - s[:-p]).max() < tol), None)


@pytest.mark.parametrize("a, seed", [(3.0, 0), (5.0, 1), (7.0, 2), (9.0, 3), (11.0, 4)])
def test_a_period_1_run_at_10_samples_a_period_is_period_1(a, seed):
    # Fact: a settled in-well run at 6.3 Hz repeats every forcing cycle; sampled at 64 Hz (10.2 samples a
    # cycle, the 6th harmonic and above folded back) with 20 um of laser noise, its Poincare points
    # differ by the noise and by the interpolation's error, which depends only on where the forcing's
    # phase falls between two samples: both are allowed for, so all five runs are period 1.
    rec, strobe = _record(a, 6.3, 64.0, 30.0, settle=10.0, seed=seed)
    assert _true_period(strobe) == 1 and rec.z.min() > 0  # in the plus well, period 1
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        c = characterise(rec, 6.3, lle=False)
    assert c["period"] == 1, c["reasons"]
    assert c["spectrum"]["period"] == 1 and c["spectrum"]["agrees"] is True
    assert c["decided_by"] in ("time", "spectrum")


def test_a_period_2_record_from_rest_is_period_2_after_its_transient():
    # Fact: forced at 9.5 m/s^2 and 9 Hz from rest in the plus well, the oscillator jumps into the minus
    # well within its first cycles and settles there on a period-2 orbit (the true stroboscopic map
    # repeats every 2 cycles at the end). Recorded at 512 Hz from t = 0, transient kept: period 2, and
    # the steady state found starts after the last jump between wells, no later than a few cycles after
    # the true orbit is within the laser's noise.
    f, fs = 9.0, 512.0
    rec, strobe = _record(9.5, f, fs, 30.0, seed=7)
    assert _true_period(strobe) == 2 and strobe[-1] < 0  # period 2 in the minus well
    crossed = np.flatnonzero(np.diff(np.sign(rec.z)) != 0)
    assert crossed.size, "the transient should jump between the wells"
    last_jump_s = rec.t[crossed[-1]] - rec.t0
    off = np.abs(strobe[2:] - strobe[:-2]) > LASER_NOISE
    settled_s = (np.flatnonzero(off)[-1] + 3) / f  # the true orbit within the noise from here on
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        c = characterise(rec, f, lle=False)
    assert c["period"] == 2 and len(c["amplitudes"]) == 2, c["reasons"]
    assert last_jump_s < c["steady_from_s"] <= settled_s + 10 / f
    assert c["regime"] == "cross-well" or c["regime"] == "in-well-minus"


@pytest.mark.parametrize("a, fs", [(12.0, 512.0), (12.0, 64.0), (14.0, 64.0)])
def test_a_chaotic_cross_well_record_has_no_period(a, fs):
    # Fact: at 12 and 14 m/s^2 and 9 Hz the oscillator wanders between its wells without repeating (its
    # true stroboscopic map has no period up to 16): neither sampling rate's allowance for noise and
    # interpolation makes it periodic. At 64 Hz (7 samples a cycle) the white floor of the record is the
    # chaos's own, 14 m/s^2 reads it as 3.7 mm of "noise" (the laser's is 20 um), whose tolerance
    # rejects nothing (it was called period 1): the spectrum's broadband decides, no period.
    rec, strobe = _record(a, 9.0, fs, 24.0, settle=6.0, seed=int(a))
    assert _true_period(strobe) is None and rec.z.min() < -Z_WELL / 2 < Z_WELL / 2 < rec.z.max()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        c = characterise(rec, 9.0, lle=False)
    assert c["period"] is None and c["chaotic"], c
    assert c["regime"] == "cross-well"


@functools.cache
def _at_18_hz():
    """An in-well run forced at 18.0 Hz (4.1 m/s^2 rms), 12 s at 512 Hz."""
    return _record(5.8, 18.0, 512.0, 12.0, settle=2.0, seed=3)[0]


def test_a_stated_frequency_that_is_not_the_inputs_is_refused():
    # Fact: a base acceleration at 18.0 Hz carries at 9.1 Hz only the accelerometer's noise (about
    # 0.03 m/s^2 of 4.1 m/s^2 rms, under 10 %): analysed as a 9.1 Hz record it is refused, in one line
    # naming both frequencies, before any analysis.
    rec = _at_18_hz()
    with pytest.raises(InputError, match=r"9\.1 Hz.*18(\.0)? Hz|18(\.0)? Hz.*9\.1 Hz") as err:
        characterise(rec, 9.1, lle=False)
    assert "\n" not in str(err.value)


def test_a_stated_frequency_that_is_not_the_inputs_exits_2(tmp_path, capsys):
    # Fact: the command line turns the refusal into exit code 2, one line on stderr, no result file.
    rec = _at_18_hz()
    path, out = tmp_path / "run.csv", tmp_path / "r.json"
    np.savetxt(path, np.column_stack([rec.t, rec.u, rec.z]), delimiter=",", header="t,base_acc,z", comments="",
               fmt="%.9g")  # fmt: skip
    assert main(["characterise", str(path), "--forcing-hz", "9.1", "-o", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "9.1" in err[0] and "18" in err[0] and "Traceback" not in err[0]
    assert not out.exists()


def test_a_slightly_mislabelled_frequency_uses_the_measured_one_with_a_warning():
    # Fact: a run forced at 9.05 Hz and stated as 9.0 Hz is the same experiment: the input's line is
    # measured (within a hundredth of a frequency bin's worth of the truth, 1 / 20 s), used, and the
    # difference (0.6 %, beyond a shaker controller's error) is said in a warning.
    rec, strobe = _record(5.0, 9.05, 512.0, 20.0, settle=3.0, seed=5)
    assert _true_period(strobe) == 1
    with pytest.warns(RecordWarning, match="9.05"):
        c = characterise(rec, 9.0, lle=False)
    assert abs(c["forcing"]["measured_hz"] - 9.05) < 0.01 / 20.0
    assert c["period"] == 1
    assert any("9.05" in w for w in c["warnings"])


def _wandering(relative_wander, seed=0, f_hz=9.0, fs=500.0, n_cycles=200):
    """A period-1 response (a fundamental and its third harmonic, 10 mm) whose amplitude wanders slowly
    (Gaussian noise low-passed at f / 5, ``relative_wander`` rms) with 1 % white sensor noise."""
    from scipy import signal

    rng = np.random.default_rng(seed)
    t = np.arange(int(n_cycles / f_hz * fs)) / fs
    wander = signal.sosfiltfilt(signal.butter(2, f_hz / 5, fs=fs, output="sos"), rng.standard_normal(t.size))
    wander *= relative_wander / wander.std()
    z = (1 + wander) * (np.sin(2 * np.pi * f_hz * t + 0.3) + 0.3 * np.sin(2 * np.pi * 3 * f_hz * t))
    z += 0.01 * rng.standard_normal(t.size)
    return from_arrays(np.sin(2 * np.pi * f_hz * t), 0.01 * z, fs)


def test_the_spectrum_decides_where_the_points_nearly_repeat():
    # Fact: a period-1 response whose amplitude wanders by 16 % (no sub-harmonic line in its spectrum)
    # repeats from cycle to cycle beyond the noise's tolerance but within 3x it: the time domain cannot
    # decide, the spectrum's lines say period 1. Wandering by 60 %, far beyond, it has no period.
    from negstiff.inference.analysis.periodicity import UNDECIDED_RATIO, periodicity

    p = periodicity(_wandering(0.16), 9.0)
    ratio = p["residuals"][1] / p["tolerances"][1]
    assert 1 < ratio <= UNDECIDED_RATIO  # the premise: the points nearly repeat
    assert p["period"] == 1 and p["decided_by"] == "spectrum" and p["spectrum"]["period"] == 1
    p = periodicity(_wandering(0.60), 9.0)
    assert min(p["residuals"][q] / p["tolerances"][q] for q in p["residuals"]) > UNDECIDED_RATIO
    assert p["period"] is None and p["decided_by"] == "time"


@functools.cache
def _cascade_record(a):
    """The oscillator forced at ``a`` m/s^2 and 9 Hz, settled 30 s, recorded 100 s at 512 Hz, with its true
    stroboscopic z: 10.1 m/s^2 is period 4, 10.17 period 8 (checked on the strobe in each test)."""
    return _record(a, 9.0, 512.0, 100.0, settle=30.0, seed=1)


def _slow_wander(n, fs, fraction_of, seed):
    """What a derived z carries from its sensor chain: a narrow-band wander at 0.47-0.53 Hz (some 18
    cycles of a 9 Hz forcing; the table's slow motion that a lab's double integration, high-passed near
    1 Hz, takes out of the base displacement and so leaves in z = y - b), scaled to ``fraction_of``."""
    from scipy import signal

    sos = signal.butter(2, [0.47, 0.53], "bandpass", fs=fs, output="sos")
    w = signal.sosfilt(sos, np.random.default_rng(seed).standard_normal(n + int(20 * fs)))[int(20 * fs) :]
    return fraction_of * w / w.std()


@pytest.mark.parametrize("seed", [1, 2])
def test_a_period_4_record_with_a_slow_sensor_wander_is_period_4(seed):
    # Fact: the true stroboscopic map repeats every 4 cycles. A z that wanders by 4 % of its spread at
    # ~0.5 Hz (18 forcing cycles) makes lag 4's points differ beyond their tolerance, while lag 16 (16/18
    # of the wander's period) cancels most of it: the points alone said period 16 (so did the rig's
    # "period-4" run at 15.4 m/s^2). The lines decide over the whole steady state, which resolves the lines
    # of 1/8 and 1/16 and finds none: period 4.
    from negstiff.inference.analysis.periodicity import periodicity

    rec, strobe = _cascade_record(10.1)
    assert _true_period(strobe, tail=120) == 4
    z = rec.z + _slow_wander(rec.n, rec.fs, 0.04 * rec.z.std(), seed)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        p = periodicity(from_arrays(rec.u, z, rec.fs), 9.0)
    assert p["residuals"][4] > p["tolerances"][4] and p["residuals"][16] < p["tolerances"][16]  # the premise
    assert p["period"] == 4 and p["decided_by"] == "spectrum", p
    assert "1/16" in p["spectrum"]["line_ratio_db"] and p["spectrum"]["line_ratio_db"]["1/16"] < 20


def test_a_period_8_record_whose_split_is_below_the_tolerance_is_period_8():
    # Fact: at 10.17 m/s^2 the true map repeats every 8 cycles, its points 4 apart differing by a third of
    # the noise's tolerance (the time domain alone says 4); the spectrum's 1/8 line stands 44 dB over its
    # floor (20 dB is significant): period 8, decided by the spectrum.
    from negstiff.inference.analysis.periodicity import periodicity

    rec, strobe = _cascade_record(10.17)
    assert _true_period(strobe, tail=200) == 8
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        p = periodicity(rec, 9.0)
    assert p["residuals"][4] < p["tolerances"][4]  # the premise: lag 4 passes
    assert p["period"] == 8 and p["decided_by"] == "spectrum" and p["spectrum"]["line_ratio_db"]["1/8"] > 20
