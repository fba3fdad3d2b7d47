"""The coefficient posterior on a hammer's record and on a free decay (single DOF): the hardening Duffing and the
seed-like double well of ``impact_records`` (scipy's DOP853, not negstiff's simulator), with a lab's artefacts (the
hammer's force channel offset by 0.5 N with 0.05 N of noise; 1 um of white noise on the displacement).

A ring-down's likelihood windows are the record's restarted windows between the hammer's pulses (all of a decay's):
each a free decay from its start state, no input in it (``Windows.free_windows``). The acceptance (the issue "Hammer
and decay tests"): the 90 % interval covers the truth's frequency (the well the record rings down in) and cubic.
"""

import warnings

import numpy as np
import pytest
from impact_records import DOUBLE_WELL, DUFFING, MASS, measured_decay, measured_hammer

from negstiff import Posterior
from negstiff.inference.analysis.record_kind import identification_record, record_kind
from negstiff.inference.estimators.posterior.parametrisation import coefficient_parametrisation
from negstiff.inference.estimators.posterior.windows import Windows
from negstiff.models import Model

FS = 1000.0
HITS = (0.5, 3.0, 5.5, 8.0)
LASER_M = 1e-6


def _hammer(model, seed):
    return measured_hammer(model, seed, LASER_M, FS, HITS)


def _decay(model, z0, seed, duration):
    return measured_decay(model, z0, seed, duration, LASER_M, FS)


def _well_hz(k1, k2, k3, k0, z_near):
    """The linear frequency [Hz] of the well nearest ``z_near`` of each draw (m the record's)."""
    out = np.empty(k1.size)
    for i in range(k1.size):
        roots = np.roots([k3[i], k2[i], -k1[i], k0[i]])
        z = roots[np.argmin(np.abs(roots - z_near))].real
        out[i] = np.sqrt((3 * k3[i] * z**2 + 2 * k2[i] * z - k1[i]) / MASS) / (2 * np.pi)
    return out


def _covers(res, model: Model, well: str):
    names = list(res.names)
    draws = res.samples.reshape(-1, len(names))[::20]
    z_well = getattr(model.equilibria(), f"z_{well}")
    f = _well_hz(*(draws[:, names.index(n)] for n in ("k1", "k2", "k3", "k0")), z_well)
    f_true = float(np.sqrt(model.stiffness(z_well) / model.m) / (2 * np.pi))
    lo, hi = np.quantile(f, [0.05, 0.95])
    assert lo <= f_true <= hi, (lo, f_true, hi)
    k3 = res.summary["k3"]
    assert k3["hdi_low"] <= model.k3 <= k3["hdi_high"], k3
    return (lo, hi), k3


def _posterior(rec):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return Posterior(seed=1, n_ensembles=2, max_steps=3000).fit(rec).result_


def test_a_ring_downs_windows_are_free_decays_between_the_pulses():
    # the windows kept hold no pulse sample, and the truth followed from each kept window's start state (refined,
    # as the posterior's profile over the nuisance states) misses it by the sensor's noise alone: 1 um, within 25 %
    # (rms over 125 samples less the two start states); each hit's force window (its pulse and the foot before it)
    # takes one or two of the 80 windows (here the hits fall on the windows' boundaries: two each)
    rec = _hammer(DUFFING, seed=1)
    kind = record_kind(rec)
    ident = identification_record(rec, kind)
    win = Windows.cut(ident, 0.125, None, free=True)
    assert 80 - 2 * len(HITS) <= win.n_windows < 80
    assert not np.any(win.u)
    assert all(not np.any(ident.u[s : s + win.length]) for s in win.starts)
    par = coefficient_parametrisation(DUFFING)
    p = par.to_params(np.array([[getattr(DUFFING, n) for n in par.names]]))
    win.refine_states(p[:, 0], par.kind)
    win.set_sensitivities(p[:, 0], par.kind)
    zsim, _ = win.simulate(p, par.kind)
    rms = float(np.sqrt(win.sum_squares(zsim).sum() / win.dof))
    assert rms == pytest.approx(LASER_M, rel=0.25)


@pytest.mark.slow
def test_the_posterior_of_a_hammer_record_covers_the_truth():
    # measured (seed 1, 32 s): 12 Hz within [11.99988, 12.00007] Hz, k3 3.0003e6 +- 780 in [2.99900e6, 3.00156e6]
    _covers(_posterior(_hammer(DUFFING, seed=1)), DUFFING, "plus")


@pytest.mark.slow
def test_the_posterior_of_a_free_decay_covers_the_truth():
    # released 12 mm beyond the plus well, the double well crosses into its minus well and rings down there.
    # Measured (seed 1, 30 s): the minus well's 11.2398 Hz within [11.23975, 11.23990] Hz, k3 1499984 +- 16 in
    # [1499958, 1500010]
    rec = _decay(DOUBLE_WELL, DOUBLE_WELL.equilibria().z_plus + 0.012, seed=1, duration=6.0)
    _covers(_posterior(rec), DOUBLE_WELL, "minus")


def test_an_input_noise_on_a_ring_down_is_refused_before_any_work():
    # its windows hold no input: a noise of the input reaches none of them, said in one line
    from negstiff.errors import InputError

    with pytest.raises(InputError, match="free decays between the pulses: no input's noise"):
        Posterior(input_noise=0.05).fit(_hammer(DUFFING, seed=1))


@pytest.mark.parametrize(
    ("seed", "peak_n", "hits"),
    [(104, 244.685, 4), (102, 228.0, 8), (102, 266.0, 8)],
)
def test_the_map_search_reaches_the_truth_s_cost_on_cross_well_hammer_records(seed, peak_n, hits):
    """The MAP search's cost (the windows' squared residuals, their start states refined) is no more than the
    truth's, to 1 %, on hammer records whose hits throw the double well across its saddle (the virtual rig's, 1 kHz,
    its 30 um laser). Before, three rounds of the search and the start states stopped short on the first (its cost
    1.42x the truth's: c 0.486 for 0.5), and the search stalled where c_nl's optimum lies on its bound (0) on the
    other two (1.23x and 1.73x: k1 419.2-419.5 for 420). Each fact fails without its own mend (measured)."""
    from negstiff.inference.record.measurement import Measurement
    from negstiff.models.rig import Rig

    rec = Measurement.from_rig(Rig(DOUBLE_WELL, seed=seed, fs=FS).hammer(peak=peak_n, hits=hits, duration=10.0))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        par, win, theta = Posterior(seed=0).point_estimate(rec)[:3]
    costs = []
    for th in (theta, np.array([getattr(DOUBLE_WELL, n) for n in par.names])):
        p = par.to_params(th[None])[:, 0]
        win.refine_states(p, par.kind)
        zsim, _ = win.simulate(par.to_params(th[None]), par.kind)
        costs.append(float(win.sum_squares(zsim)[0].sum()))
    assert costs[0] <= 1.01 * costs[1], costs


def test_a_hammer_record_and_a_free_decay_are_fitted_together():
    # both are read as windows of free decay between the pulses: a lab's hammer test and its release test are one
    # device's runs (a forced record's windows carry its input: it is not fitted with them). The joint MAP point
    # reads both records' windows (72 and 32) and lands as near the truth as the hammer's record alone does (measured:
    # k1 0.36 %, k3 0.10 %, c 0.00 % off jointly; 0.43 %, 0.12 %, 0.00 % from the hammer alone): within 1 %, about
    # twice the hammer alone's error
    light = _hammer(DOUBLE_WELL, seed=1)
    decay = _decay(DOUBLE_WELL, DOUBLE_WELL.equilibria().z_plus + 0.006, seed=3, duration=4.0)
    assert Posterior().check([light, decay]) == [light, decay]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        par, win, theta = Posterior(seed=0).point_estimate([light, decay])[:3]
    assert win.n_groups == 2 and np.bincount(win.groups).min() >= 4
    got = dict(zip(par.names, theta, strict=True))
    for name in ("k1", "k3", "c"):
        assert got[name] == pytest.approx(getattr(DOUBLE_WELL, name), rel=0.01), name
