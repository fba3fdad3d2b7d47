"""The discrepancy workflow on effects that act briefly and on two effects at once, on records scipy's DOP853
writes here (not negstiff's simulator): the seed-like asymmetric double well (``SEED_LIKE_CUBIC``: cubic K, c and
c_nl) under a random-phase multisine base acceleration (2-30 Hz, 20 m/s^2 rms, cross-well), with a lab's artefacts:
the laser's white noise (5 um rms), the accelerometer's bias (0.05 m/s^2) and noise (0.02 m/s^2 rms), and the
start-up transient from rest kept in the record. The workflow sees only the measured columns.

Each fact is checked by default at one seed on a shorter record (``SHORT``: the first part of seed 1's), and with
``-m slow`` at three seeds on ``DURATION`` records (a study).
"""

import dataclasses
import functools

import numpy as np
import pytest
from records import dop853_record
from scipy.stats import norm

from negstiff.inference.estimators.discrepancy import Discrepancy, share_text
from negstiff.inference.record.measurement import from_arrays
from negstiff.models import SEED_LIKE_CUBIC

FS = 500.0
DURATION = 60.0  # s: the three-seed study's records
SHORT = 30.0  # s: the default tier's records (seed 1's first half: the same trajectory, half the cost)
LASER_NOISE = 5e-6  # m rms
STOP_K = 3000.0  # N/m
STOP_ONSET = {1: 0.026, 2: -0.037, 3: 0.026}  # m: a bumper a few mm inside the reach of the side each seed's
# record visits (acting in 1-5 % of it): seed 2 stays mostly in the minus well (z > 26 mm in 0.4 % of it)
FRICTION = 0.1  # N, 5 % of the moving mass's weight


def study(xfail: dict | None = None, short: float = SHORT) -> list:
    """(seed, duration) parameters: seed 1 on a ``short`` record by default; seeds 1-3 on ``DURATION`` records with
    ``-m slow``, each with its strict xfail mark in ``xfail`` ({seed: mark}) where it has one."""
    xfail = xfail or {}
    slow = [pytest.param(s, DURATION, marks=[pytest.mark.slow, *([xfail[s]] if s in xfail else [])], id=f"{s}")
            for s in (1, 2, 3)]  # fmt: skip
    return [pytest.param(1, short, id="1-short"), *slow]


def _hidden(stop: float | None, friction: bool):
    def force(z, v):
        f = 0.0
        if stop is not None and (z - stop) * np.sign(stop) > 0:
            f += STOP_K * (z - stop)
        if friction:
            f += FRICTION * np.tanh(v / 1e-3)  # Coulomb friction smoothed over 1 mm/s (the registry's law)
        return f

    return force


def _record(seed: int, stop: float | None = None, friction: bool = False, c_nl: float | None = None,
            duration: float = DURATION):  # fmt: skip
    """(measurement, true z) of the seed-like device with the hidden effects, ``duration`` seconds long."""
    model = SEED_LIKE_CUBIC if c_nl is None else dataclasses.replace(SEED_LIKE_CUBIC, c_nl=c_nl)
    _, u, z, _ = dop853_record(duration, rms=20.0, seed=seed, start=0.023, fs=FS, rtol=1e-8, model=model,
                               hidden=_hidden(stop, friction))  # fmt: skip
    rng = np.random.default_rng(1000 + seed)
    z_meas = z + LASER_NOISE * rng.standard_normal(z.size)
    u_meas = u + 0.05 + 0.02 * rng.standard_normal(u.size)
    return from_arrays(u_meas, z_meas, FS, mass=model.m, source=f"dop853-{seed}"), z


def _covers(interval: dict, truth: float, z: float = 3.0) -> bool:
    """The truth within ``z`` of the interval's standard errors of its centre (its half-width over the normal's
    quantile at its ``prob``; 3: 99.7 %). These records are cross-well chaos, so each machine writes another motion
    (the multisine's cosines differ in their last bits between machines, and chaos makes that the whole motion within
    seconds): a 90 % interval misses its truth on one such record in ten, and a test holding three of them would fail
    on about a quarter of machines (it did on one: the stop's k 3006.6 N/m, 1.8 standard errors above 3000). An
    interval half as wide as it should be still fails here (a truth 1.8 true standard errors off is 3.6 of its own).
    """
    lo, hi = interval["interval"]
    half = 0.5 * (hi - lo) / float(norm.ppf(0.95))  # every interval the workflow reports is a 90 % one ("prob": 0.9)
    return abs(0.5 * (lo + hi) - truth) <= z * half


def _second_opinion_names(r: dict, effect: str) -> bool:
    """arviz.compare's LOO over the windows prefers the model with the effect (the frequentist rule named it)."""
    b = r["bayesian"][effect]
    return b["prefers"] == "with" and b["elpd_diff"] > 0


def _assert_stop_found(r: dict, onset: float) -> None:
    """The issue's acceptance for an end stop: named alone; its contact stiffness within 20 % and its onset within
    1 mm (the laser's 5 um noise is far below both; what limits them is how few samples lie beyond the onset); the
    gap in the windows where it acts, scored on their own (at least three), at least halved."""
    assert r["effects"] == ["end_stop"], r["iterations"]
    size = r["effect_size"]["end_stop"]
    assert size["k"] == pytest.approx(STOP_K, rel=0.2)
    assert size["z"] == pytest.approx(onset, abs=1e-3)
    regime = r["gap_regime_percent"]["end_stop"]
    assert regime["windows"] >= 3 and regime["after"] <= regime["before"] / 2, regime


@functools.cache
def _stop_fit(seed: int, duration: float) -> tuple[dict, float]:
    """The workflow's result on seed's end-stop record and the share of it where the stop acts (one fit per
    record, shared by the tests that read it)."""
    onset = STOP_ONSET[seed]
    rec, z = _record(seed, stop=onset, duration=duration)
    return Discrepancy().fit(rec).result(), float(np.mean((z - onset) * np.sign(onset) > 0))


@pytest.mark.parametrize("seed, duration", study())
def test_an_end_stop_acting_briefly_is_named_sized_and_its_regime_gap_halved(seed, duration):
    onset = STOP_ONSET[seed]
    r, share = _stop_fit(seed, duration)
    assert 0.01 <= share <= 0.05, share  # the record's premise: the stop acts in 1-5 % of it
    _assert_stop_found(r, onset)
    # its windows last no longer than the record stays predictable (nor than the motion where it acts, by the models
    # compared), measured before any effect was scored; at seed 3 that is 0.376 s, where the true model's own 1 s runs
    # missed by 103-114 % (measured)
    regime = r["gap_regime_percent"]["end_stop"]
    assert regime["window_s"] <= regime["record_window_s"] == r["predictability"]["window_s"] <= 1.0, regime
    assert r["gap_after_percent"] <= r["gap_before_percent"]
    assert "evidence" in r["iterations"][0] and "regime" in r["iterations"][0]["evidence"]


@pytest.mark.parametrize("seed, duration", study())
def test_an_end_stop_interval_covers_its_truth(seed, duration):
    # the stop's size with its 90 % interval (a Laplace approximation of the output error over the record's
    # restarted windows, window-robust, widened by the distance to their mode) holds the truth within three of its
    # standard errors (``_covers``); the Bayesian second opinion (arviz's LOO over those windows) prefers the model
    # with the stop. At seed 2 the fit's k is 0.8 % off (2976.8 N/m): its interval covers 3000 only with the Hessian
    # inverted in the parameters' scales (in SI units pinv dropped the direction k trades with the onset: +- 0.43 N/m
    # at 90 %, measured)
    r, _ = _stop_fit(seed, duration)
    interval = r["effect_interval"]["end_stop"]
    assert _covers(interval["k"], STOP_K) and _covers(interval["z"], STOP_ONSET[seed]), interval
    assert _second_opinion_names(r, "end_stop"), r["bayesian"]


@pytest.mark.parametrize("seed, duration", study())
def test_quadratic_damping_with_coulomb_friction_both_found(seed, duration):
    # c_nl = 1 N s^2/m^2 (twice the seed's) with 0.1 N of friction: c_nl is the baseline's own term, so it is
    # found there (not as an extra effect, not as cubic damping), and friction is named beside it
    rec, _ = _record(seed, friction=True, c_nl=1.0, duration=duration)
    r = Discrepancy().fit(rec).result()
    assert r["effects"] == ["coulomb_friction"], r["iterations"]
    # friction within 10 %: 0.1 N against the inertial force's ~4 N rms; the velocity's noise blurs its sign
    # change over ~1 mm/s, which the library's erf column carries
    assert r["effect_size"]["coulomb_friction"] == pytest.approx(FRICTION, rel=0.1)
    assert r["model"]["c_nl"] == pytest.approx(1.0, rel=0.2)
    assert "quadratic_damping" not in r["model"]["extra"] and "cubic_damping" not in r["model"]["extra"]
    # 0.1 N within three of its 90 % interval's standard errors (``_covers``)
    assert _covers(r["effect_interval"]["coulomb_friction"], FRICTION), r["effect_interval"]
    assert _second_opinion_names(r, "coulomb_friction"), r["bayesian"]
    # the round's own second opinion: LOO over the held-out tail's windows prefers the model with friction
    # (measured at seed 1: elpd +1011 +- 53 over 6 windows)
    assert r["iterations"][0]["evidence"]["bayesian"]["prefers"] == "with", r["iterations"][0]["evidence"]


# 40 s by default: in seed 1's first 30 s friction, the second effect, is not named (measured)
@pytest.mark.parametrize("seed, duration", study(short=40.0))
def test_an_end_stop_with_friction_both_named_one_per_round(seed, duration):
    onset = STOP_ONSET[seed]
    rec, _ = _record(seed, stop=onset, friction=True, duration=duration)
    r = Discrepancy().fit(rec).result()
    assert sorted(r["effects"]) == ["coulomb_friction", "end_stop"], r["iterations"]
    # one effect per round, each judged with the ones before it in place: the rounds' order is the effects'
    kept = [it["named"] for it in r["iterations"] if it.get("kept")]
    assert kept == r["effects"]
    assert r["effect_size"]["coulomb_friction"] == pytest.approx(FRICTION, rel=0.1)
    assert r["effect_size"]["end_stop"]["k"] == pytest.approx(STOP_K, rel=0.2)
    assert r["effect_size"]["end_stop"]["z"] == pytest.approx(onset, abs=1e-3)
    # each named effect's truth within three of its 90 % interval's standard errors, the other in place (``_covers``)
    intervals = r["effect_interval"]
    assert _covers(intervals["coulomb_friction"], FRICTION), intervals
    assert _covers(intervals["end_stop"]["k"], STOP_K) and _covers(intervals["end_stop"]["z"], onset), intervals


@pytest.mark.parametrize("seed, duration", study())
def test_a_clean_record_names_nothing(seed, duration):
    # the seed's own model form made the record: nothing is missing, and no regime is called out by a share
    # printed as "0 %"
    rec, _ = _record(seed, duration=duration)
    r = Discrepancy().fit(rec).result()
    assert r["effects"] == ["none"], r["iterations"]
    assert r["gap_regime_percent"] == {} and r["effect_interval"] == {} and r["bayesian"] == {}
    assert " 0 % of the record" not in r["where"]


def test_the_windows_last_as_long_as_the_record_stays_predictable():
    # a run restarted from a measured state starts from an estimate (the laser's noise in z, the filter's in z'), and
    # in cross-well chaos two runs from states that differ by that noise part: the record's horizon is the time by
    # which the baseline's runs from noise-moved states have parted by 10 % of rms z, pooled over restarts every
    # 0.1 s. 24 s of seed 3's clean record (the seed whose runs part within the 1 s cap; at seeds 1 and 2 they do
    # not, measured)
    from negstiff.inference.steps.validation import RestartWindows, restart_windows, simulate_windows

    rec, z = _record(3, duration=24.0)
    d = Discrepancy(max_effects=0).fit(rec)
    p = d.result()["predictability"]
    assert p["limited"] and p["horizon_s"] < 1.0 and p["window_s"] == pytest.approx(p["horizon_s"], abs=1 / FS), p
    # the true model's own runs from the measured states (the accelerometer's 0.05 m/s^2 bias is its k0's), restarted
    # as the baseline's were, part from the record over windows of the horizon by about that much (pooled rms error
    # over the windows, measured: 9.5 % of rms z; the noise-moved pairs part by 10 % at the windows' end) and by more
    # over 1 s windows (measured: 13.0 %): the horizon is the truth's as well as the baseline's
    truth = dataclasses.replace(SEED_LIKE_CUBIC, k0=SEED_LIKE_CUBIC.k0 - SEED_LIKE_CUBIC.m * 0.05)
    zs, v, _, _ = rec.states("state")
    n_id = d.result()["settings"]["identification_samples"]
    every = restart_windows(n_id, FS, 0.1)
    starts = every.starts[every.starts + int(FS) <= n_id]
    z_rms = np.sqrt(np.mean(rec.displacement[:n_id] ** 2))

    def parted(seconds: float) -> float:
        windows = RestartWindows.at(starts, int(round(seconds * FS)))
        run = simulate_windows(truth, rec, windows, zs, v)
        err = run.z[~run.diverged] - windows.measured(rec.displacement)[~run.diverged]
        return float(np.sqrt(np.mean(err**2)) / z_rms)

    at_horizon, at_cap = parted(p["horizon_s"]), parted(1.0)
    assert at_horizon < 1.5 * p["fraction"] and at_horizon < at_cap, (at_horizon, at_cap)
    # the same motion measured with 4x the laser's noise: a perturbation that grows exponentially from 4x the size
    # reaches 10 % of rms z sooner (measured: 0.758 s -> 0.380 s)
    noisier = from_arrays(rec.u, z + 4 * LASER_NOISE * np.random.default_rng(7).standard_normal(z.size), FS,
                          mass=SEED_LIKE_CUBIC.m, source="dop853-3-noisier")  # fmt: skip
    q = Discrepancy(max_effects=0).fit(noisier).result()["predictability"]
    assert q["horizon_s"] < p["horizon_s"], (q, p)


def test_a_share_is_printed_with_the_digits_it_needs():
    # a regime holding 0.35 % of the record is not "0 %"; large shares keep no decimals
    assert share_text(0.94) == "94"
    assert share_text(0.023) == "2.3"
    assert share_text(0.0035) == "0.35"
    assert share_text(4.1e-5) == "0.0041"
    assert share_text(0.0) == "0"


def _plus_well_then_minus_record(seed: int = 1, duration: float = 30.0, onset: float = 0.025):
    """(measurement, true z) of a record whose held-out tail never reaches the stop: the device starts in its plus
    well, where a bumper ``onset`` above the centre is hit in ~3 % of the record, under a random-phase multisine
    base acceleration (2-30 Hz at 0.1 Hz: no 4 s period) of 7 m/s^2 rms that rises to 10 m/s^2 at 40 % of the
    record: the device then jumps to the deeper minus well and stays there, so the held-out tail (the last 20 %)
    never reaches the stop. DOP853, the laser's 5 um noise, the accelerometer's bias and noise.
    """
    from scipy.integrate import solve_ivp

    m = SEED_LIKE_CUBIC
    rng = np.random.default_rng(seed)
    w = 2 * np.pi * np.arange(2.0, 30.0, 0.1)
    ph = rng.uniform(0, 2 * np.pi, w.size)

    def acc(t):
        level = 7.0 + 3.0 / (1 + np.exp(-(t - 0.4 * duration) / 0.5))  # m/s^2 rms, a smooth step
        return level * np.sqrt(2.0 / w.size) * np.cos(np.multiply.outer(t, w) + ph).sum(axis=-1)

    def rhs(t, x):
        z, v = x
        contact = STOP_K * (z - onset) if z > onset else 0.0
        return [v, (-m.c * v - m.c_nl * v * abs(v) - m.restoring_force(z) - contact) / m.m - acc(t)]

    t = np.arange(int(duration * FS)) / FS
    z = solve_ivp(rhs, (0, t[-1]), [0.022, 0.0], t_eval=t, method="DOP853", rtol=1e-8, atol=1e-11).y[0]
    noise = np.random.default_rng(1000 + seed)
    u_meas = acc(t) + 0.05 + 0.02 * noise.standard_normal(z.size)
    z_meas = z + LASER_NOISE * noise.standard_normal(z.size)
    return from_arrays(u_meas, z_meas, FS, mass=m.m, source="plus-then-minus"), z


def test_an_end_stop_the_held_out_tail_never_reaches_is_judged_where_it_acts():
    # the stop acts in 1-5 % of the record, all of it before the held-out tail, so the tail holds no window where
    # it acts; it is judged on the windows where it acts anywhere in the record, each predicted by fits made without
    # its block's data (blocked cross-validation), and named
    onset = 0.025
    rec, z = _plus_well_then_minus_record(onset=onset)
    acting = z > onset
    assert 0.01 <= acting.mean() <= 0.05 and not acting[int(0.8 * z.size) :].any()  # the record's premise
    r = Discrepancy().fit(rec).result()
    assert r["effects"] == ["end_stop"], r["iterations"]
    size = r["effect_size"]["end_stop"]
    # stiffness within 20 % and onset within 1 mm (5 um noise; ~460 samples beyond the onset)
    assert size["k"] == pytest.approx(STOP_K, rel=0.2)
    assert size["z"] == pytest.approx(onset, abs=1e-3)
    evidence = r["iterations"][0]["evidence"]
    assert evidence["regime"]["windows"] < 3  # the tail barely reaches it: the old rule had nothing to judge
    folds = evidence["folds"]
    assert folds["windows"] >= 3 and folds["acting"]["significant"] and len(folds["folds"]) >= 3
    # each block's fit without that block's data sizes the stop alike (within the acceptance's bounds)
    for f in folds["folds"]:
        assert f["size"]["k"] == pytest.approx(STOP_K, rel=0.2) and f["size"]["z"] == pytest.approx(onset, abs=1e-3)
    regime = r["gap_regime_percent"]["end_stop"]
    assert regime["judged_on"].startswith("cross-validated")
    assert regime["after"] <= regime["before"] / 2, regime  # the gap where it acts halved (measured: 3.7 -> 0.034 %)
    # the truth within three of its 90 % interval's standard errors (``_covers``)
    interval = r["effect_interval"]["end_stop"]
    assert _covers(interval["k"], STOP_K) and _covers(interval["z"], onset), interval
    assert _second_opinion_names(r, "end_stop"), r["bayesian"]
    assert evidence["bayesian"]["prefers"] == "with", evidence["bayesian"]


ISSUE_ONSET = 0.028  # m: 28 mm above the origin, on the plus well's side (z_plus = 21.9 mm, z_minus = -28.4 mm)
ISSUE_DURATION = 120.0  # s


def _random_record_from_the_plus_well(seed: int):
    """(measurement, true z) of the scenario in which a stop hit only from the plus well went unnamed: the seed-like
    device with a bumper of 3000 N/m ``ISSUE_ONSET`` above the centre, started at rest in its plus well under a
    band-limited Gaussian random base acceleration (2-40 Hz, the rig's band, 20 m/s^2 rms), which throws it into
    the deeper minus well within a second: it returns to the plus well, and to the bumper, only briefly. The
    acceleration is white noise at 8x the sampling rate through a zero-phase 4th-order Butterworth band-pass, a
    cubic spline between its samples for the integrator; DOP853, the laser's 5 um noise, the accelerometer's bias
    and noise.
    """
    from scipy import signal
    from scipy.integrate import solve_ivp
    from scipy.interpolate import CubicSpline

    m = SEED_LIKE_CUBIC
    rng = np.random.default_rng(seed)
    fine = 8 * FS
    t_fine = np.arange(int((ISSUE_DURATION + 1.0) * fine)) / fine
    sos = signal.butter(4, [2.0, 40.0], btype="band", fs=fine, output="sos")
    a = signal.sosfiltfilt(sos, rng.standard_normal(t_fine.size))
    a *= 20.0 / np.sqrt(np.mean(a**2))
    spline = CubicSpline(t_fine, a)
    pieces = spline.c.T.tolist()  # each interval's cubic, highest power first: evaluated by hand (a spline's
    # own call costs more than the rest of the right-hand side, which the integrator calls ~600,000 times)

    def rhs(t, x):
        z, v = x
        i = int(t * fine)
        s = t - i / fine
        c3, c2, c1, c0 = pieces[i]
        acc = ((c3 * s + c2) * s + c1) * s + c0
        contact = STOP_K * (z - ISSUE_ONSET) if z > ISSUE_ONSET else 0.0
        k = ((m.k3 * z + m.k2) * z - m.k1) * z + m.k0
        return [v, (-m.c * v - m.c_nl * v * abs(v) - k - contact) / m.m - acc]

    t = np.arange(int(ISSUE_DURATION * FS)) / FS
    z = solve_ivp(rhs, (0, t[-1]), [0.022, 0.0], t_eval=t, method="DOP853", rtol=1e-8, atol=1e-11).y[0]
    noise = np.random.default_rng(1000 + seed)
    u_meas = spline(t) + 0.05 + 0.02 * noise.standard_normal(z.size)
    z_meas = z + LASER_NOISE * noise.standard_normal(z.size)
    return from_arrays(u_meas, z_meas, FS, mass=m.m, source=f"plus-well-start-{seed}"), z


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2])
def test_an_end_stop_hit_from_the_plus_well_alone_is_named_on_a_long_random_record(seed):
    # the scenario the stop was first missed on: 120 s at 20 m/s^2 rms, the stop 28 mm above, the record starting
    # in the plus well and living in the minus well; the stop acts in a fraction of a percent of the record
    # (measured: 0.24 % at seed 1, 0.16 % at seed 2), beyond the 0.5 % of the stroke the onset's search once
    # started from (it then settled at 24.3 mm with k ~600 N/m and the stop was not named)
    rec, z = _random_record_from_the_plus_well(seed)
    z_0 = SEED_LIKE_CUBIC.equilibria().z_0
    acting = z > ISSUE_ONSET
    assert z[0] > z_0 and np.mean(z > z_0) < 0.05, np.mean(z > z_0)  # starts in the plus well, lives in the minus
    assert 0 < acting.mean() < 0.01, acting.mean()
    r = Discrepancy().fit(rec).result()
    assert "plus well" in r["where"].split(";")[0], r["where"]  # the baseline's error sits where the stop is
    # measured: 2986 N/m and 27.998 mm at seed 1, 3006 N/m and 28.000 mm at seed 2; the gap where it acts 15.8 ->
    # 0.17 % over 11 windows at seed 1, 12.2 -> 0.10 % over 6 at seed 2, cross-validated (the held-out tail reaches
    # it in 1-2 windows)
    _assert_stop_found(r, ISSUE_ONSET)
    interval = r["effect_interval"]["end_stop"]
    assert _covers(interval["k"], STOP_K) and _covers(interval["z"], ISSUE_ONSET), interval
