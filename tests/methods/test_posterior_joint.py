"""The joint posterior of several records of one device (a lab's runs fitted together): the device's parameters
shared, each record its own windows, input noise and sensor noise (``sigma_1``, ``sigma_2``).

The records are written here with scipy's DOP853, not negstiff's simulator: the reference study's double-well
polynomial under a multisine base acceleration (2-40 Hz, cross-well), its z read by a laser of the record's own
noise, its input by an accelerometer with white noise.
"""

import json

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from negstiff.cli import main
from negstiff.inference.estimators.posterior import Posterior
from negstiff.inference.estimators.posterior.windows import PosteriorError
from negstiff.inference.record.measurement import from_arrays
from negstiff.models import SEED_LIKE_CROSS_WELL_RMS, SEED_LIKE_CUBIC

TRUTH = SEED_LIKE_CUBIC
FS = 512.0
DURATION = 8.0
ACC_NOISE = 0.005  # m/s^2 rms
TARGETS = ("k1", "k3", "c", "c_nl")


def _record(seed: int, laser_noise: float, fs: float = FS):
    """A cross-well record of the truth written with DOP853: multisine base acceleration, laser and accelerometer
    noise; z in the frame the posterior reads (the device's own, gravity in k0 as the truth's)."""
    rng = np.random.default_rng(seed)
    f = np.linspace(2.0, 40.0, 96)
    phase = rng.uniform(0.0, 2 * np.pi, f.size)
    amp = SEED_LIKE_CROSS_WELL_RMS * np.sqrt(2.0 / f.size)

    def u(t):
        return np.cos(2 * np.pi * np.multiply.outer(np.atleast_1d(t), f) + phase) @ np.full(f.size, amp)

    def rhs(t, x):
        acc = -u(t)[0] - (TRUTH.restoring_force(x[0]) + TRUTH.damping_force(x[1])) / TRUTH.m
        return [x[1], acc]

    t = np.arange(int(DURATION * fs)) / fs
    z0 = TRUTH.equilibria().z_plus
    # DOP853's error at rtol 1e-8 is far below the laser's noise (30-300 um on +-20 mm)
    sol = solve_ivp(rhs, (0.0, t[-1]), [z0, 0.0], t_eval=t, method="DOP853", rtol=1e-8, atol=1e-11)
    z = sol.y[0] + laser_noise * rng.standard_normal(t.size)
    acc = u(t) + ACC_NOISE * rng.standard_normal(t.size)
    return from_arrays(acc, z, fs, mass=TRUTH.m, source=f"DOP853 record {seed}")


@pytest.fixture(scope="module")
def records():
    return _record(1, 30e-6), _record(2, 90e-6)  # the second record's laser 3x noisier


@pytest.fixture(scope="module")
def fits(records):
    quiet, loud = records
    return {
        "quiet": Posterior(seed=0, n_ensembles=2).fit(quiet).result(),
        "loud": Posterior(seed=0, n_ensembles=2).fit(loud).result(),
        "joint": Posterior(seed=0, n_ensembles=2).fit([quiet, loud]).result(),
    }


def _width(res, name):
    p = res["parameters"][name]
    return p["hdi_high"] - p["hdi_low"]


def test_each_record_keeps_its_own_sensor_noise_and_the_records_information_adds(fits):
    # one test of the fits (a module fixture is made once per pytest-xdist worker that runs a test of it)
    joint = fits["joint"]["parameters"]
    assert "sigma" not in joint and {"sigma_1", "sigma_2"} <= set(joint)
    # each laser's noise, read from its own windows' residuals: within 10 % (the projection's 2 of 64 samples per
    # window and the integration's own error; measured 2-5 % low on single records)
    assert joint["sigma_1"]["mean"] == pytest.approx(30e-6, rel=0.1)
    assert joint["sigma_2"]["mean"] == pytest.approx(90e-6, rel=0.1)
    settings = fits["joint"]["settings"]
    assert [r["source"] for r in settings["records"]] == ["DOP853 record 1", "DOP853 record 2"]
    assert len(settings["input_noise"]["rms"]) == 2

    # Two records of one device: the joint posterior's precision is the sum of each record's (Gaussian
    # posteriors, flat priors), 1 / w^2 = 1 / w1^2 + 1 / w2^2 for the 90 % widths. Each width carries its
    # curvature adjustment, read from the spread of ~60 windows' scores (a variance to ~20 %, so a width to
    # ~10 %), and the Monte Carlo error of an HDI (~4 % at two ensembles' ESS): 25 % holds both with room.
    for name in TARGETS:
        w1, w2, wj = (_width(fits[k], name) for k in ("quiet", "loud", "joint"))
        predicted = (w1**-2 + w2**-2) ** -0.5
        assert wj == pytest.approx(predicted, rel=0.25), name
        assert wj < min(w1, w2), name
    # the Laplace parts a design adds a test's to (settings.laplace): the joint fit's model information and its
    # windows' score covariance are each record's, summed (each read at its own MAP point: the Jacobian moves with
    # the points' difference, a few sd of a 8 s record, and the scores' spread estimates a variance to ~20 %)
    parts = {k: fits[k]["settings"]["laplace"] for k in fits}
    assert parts["joint"]["parameters"] == parts["quiet"]["parameters"] == ["k1", "k2", "k3", "c", "c_nl", "k0"]
    for key, rel in (("information", 0.02), ("score_covariance", 0.25)):  # measured: 0.2 % and 8 %
        joint, summed = (np.diag(parts["joint"][key]), np.diag(parts["quiet"][key]) + np.diag(parts["loud"][key]))
        assert joint == pytest.approx(summed, rel=rel), (key, joint / summed)
    # the truth within 3 sd of the joint mean for every coefficient (the intervals' own calibration is
    # checked on many records elsewhere)
    for name in ("k1", "k2", "k3", "c", "c_nl"):
        p = fits["joint"]["parameters"][name]
        assert abs(p["mean"] - getattr(TRUTH, name)) < 3 * p["sd"], name


def test_records_that_are_not_one_device_s_runs_are_refused_before_the_work(records):
    quiet, _ = records
    other_rate = _record(3, 30e-6, fs=400.0)
    with pytest.raises(PosteriorError, match="400 Hz"):
        Posterior().check([quiet, other_rate])
    heavier = from_arrays(np.asarray(quiet.u), np.asarray(quiet.z), FS, mass=2 * TRUTH.m, source="heavier")
    with pytest.raises(PosteriorError, match="mass"):
        Posterior().check([quiet, heavier])


def test_a_noisier_shorter_record_keeps_its_windows(records):
    # each record's windows are judged against its own median residual (a window the model cannot follow is dropped):
    # against the pooled median, a record 10x noisier and half as long lost every window (all "3x the median")
    quiet, _ = records
    loud = _record(4, 300e-6)
    loud = loud.segment(0, loud.n // 2)
    post = Posterior(seed=0)
    post.check([quiet, loud])
    _, win, _, _, sigma = post.point_estimate([quiet, loud])
    assert np.bincount(win.groups).tolist() == [64, 32] and not win.dropped
    assert sigma[0] == pytest.approx(30e-6, rel=0.1) and sigma[1] == pytest.approx(300e-6, rel=0.1)


def test_the_command_reads_several_records(records, tmp_path, capsys):
    paths = []
    for i, rec in enumerate(records):
        p = tmp_path / f"run{i + 1}.csv"
        t = np.arange(rec.n) / rec.fs
        np.savetxt(p, np.column_stack([t, rec.u, rec.z]), delimiter=",", header="t,base_acc,z", comments="")
        paths.append(str(p))
    out = tmp_path / "joint.json"
    argv = ["posterior", *paths, "--mass", str(TRUTH.m), "--max-steps", "40", "-o", str(out), "--quiet"]
    assert main(argv) == 0
    res = json.loads(out.read_text())
    assert {"sigma_1", "sigma_2"} <= set(res["parameters"])
    assert [r["source"] for r in res["settings"]["records"]] == paths
    # an output that is one of the inputs: refused before any work, the input untouched
    before = (tmp_path / "run1.csv").read_bytes()
    assert main(["posterior", *paths, "-o", paths[0], "--quiet"]) == 2
    assert (tmp_path / "run1.csv").read_bytes() == before
    capsys.readouterr()
