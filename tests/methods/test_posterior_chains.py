"""A posterior's emcee chains saved to an HDF5 file as they run (emcee's HDFBackend, ``Posterior(chain_file=...)``)
and resumed (``resume=True``): a run stopped after k steps and resumed is the run that was never stopped, because
emcee's backend keeps each ensemble's walkers and random state and the stopping rule is judged on the whole chain.

The record: the tests' cubic double well (``records.TRUTH``) under band-limited random base acceleration, a plain
numpy RK4 written in the tests, a laser's 3 um and an accelerometer's 5 mm/s^2 of white noise; 10 s and short runs
(the chain's bookkeeping is checked, not the posterior's convergence).
"""

import json
import warnings

import h5py
import numpy as np
import pytest
from records import FS, TRUTH, rk4_random_records

from negstiff import InputError, Posterior, from_arrays

RUN = {"seed": 3, "n_ensembles": 2, "min_steps": 60, "max_steps": 60, "chunk": 20, "max_windows": 16}
"""60 steps in chunks of 20 (min_steps = max_steps: the rule cannot stop a run early, so k + (60 - k) steps)."""


@pytest.fixture(scope="module")
def record():
    ((u, z),) = rk4_random_records([11], duration=10.0)
    return from_arrays(u, z, FS, mass=TRUTH.m, source="rk4 record")


def fit(record, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a short run: not converged, said in the result
        return Posterior(**{**RUN, **kw}).fit(record)


@pytest.fixture(scope="module")
def uninterrupted(record):
    return fit(record)


@pytest.mark.parametrize("k", [20, 30])  # at a chunk's end and within one
def test_a_run_stopped_after_k_steps_and_resumed_is_the_uninterrupted_run(record, uninterrupted, tmp_path, k):
    # emcee's state (walkers, log probabilities, the moves' random state) comes back from the file: the resumed
    # chain is the one uninterrupted run of the same seed, draw for draw (the same arithmetic in the same order,
    # so equal, not close)
    path = tmp_path / "chains.h5"
    first = fit(record, max_steps=k, chain_file=path)
    assert first.result_.settings["resumed_steps"] == [0, 0]
    with h5py.File(path, "r") as f:
        assert [int(f[f"ensemble_{e}"].attrs["iteration"]) for e in range(2)] == [k, k]
    resumed = fit(record, chain_file=path, resume=True)
    assert resumed.result_.settings["resumed_steps"] == [k, k]
    assert resumed.result_.samples.shape == uninterrupted.result_.samples.shape
    assert np.array_equal(resumed.result_.samples, uninterrupted.result_.samples)
    assert resumed.result()["parameters"] == uninterrupted.result()["parameters"]
    with h5py.File(path, "r") as f:  # the whole chain is in the file, as emcee wrote it
        assert f["ensemble_0"]["chain"].shape == (RUN["max_steps"], 16, 7)


def test_a_saved_run_is_the_in_memory_run_and_resuming_a_finished_run_adds_nothing(record, uninterrupted, tmp_path):
    path = tmp_path / "chains.h5"
    saved = fit(record, chain_file=path)
    assert np.array_equal(saved.result_.samples, uninterrupted.result_.samples)
    again = fit(record, chain_file=path, resume=True)  # max_steps reached: the saved chain read back
    assert again.result_.settings["resumed_steps"] == [RUN["max_steps"]] * 2
    assert np.array_equal(again.result_.samples, saved.result_.samples)


def test_chain_files_that_cannot_be_used_are_refused_before_any_work(record, tmp_path):
    with pytest.raises(InputError, match="resume=True continues the chains saved in chain_file"):
        Posterior(resume=True).fit(record)
    with pytest.raises(InputError, match="no such chain file"):
        Posterior(resume=True, chain_file=tmp_path / "absent.h5").fit(record)
    with pytest.raises(InputError, match=r"chain_file must be None or the path of an HDF5 file"):
        Posterior(chain_file=tmp_path / "chains.csv").fit(record)
    other = tmp_path / "other.h5"  # somebody's HDF5 file: never overwritten
    with h5py.File(other, "w") as f:
        f["data"] = np.arange(3)
    with pytest.raises(InputError, match="not a negstiff chain file"):
        Posterior(chain_file=other).fit(record)
    with h5py.File(other, "r") as f:
        assert list(f["data"][...]) == [0, 1, 2]


def test_resuming_another_runs_chains_is_refused(record, tmp_path):
    # the saved walkers live in the coordinates of their run (seed, centre, scale): another seed's are refused
    path = tmp_path / "chains.h5"
    fit(record, max_steps=20, chain_file=path)
    with pytest.raises(InputError, match="another run's"):
        fit(record, seed=4, chain_file=path, resume=True)
    with pytest.raises(InputError, match="holds the saved chains of 2 of the 3 ensembles"):
        Posterior(**{**RUN, "n_ensembles": 3}, chain_file=path, resume=True).fit(record)


@pytest.mark.slow
def test_a_structures_run_stopped_and_resumed_is_the_uninterrupted_run(tmp_path):
    # the same at N = 2 (the element's posterior on a device on a sprung fixture, 30 s, a plain RK4, 1 um noise)
    from records import FIXTURE, rk4_fixture_record

    u, z = rk4_fixture_record(duration=30.0, rms=12.0, seed=3)
    rec = from_arrays(u, z, 512.0, masses=(FIXTURE["m"], TRUTH.m), source="two DOFs")
    run = {"element": "1-2", "max_windows": 12}
    full = fit(rec, **run)
    fit(rec, **run, max_steps=30, chain_file=tmp_path / "chains.h5")
    resumed = fit(rec, **run, chain_file=tmp_path / "chains.h5", resume=True)
    assert resumed.result_.settings["resumed_steps"] == [30, 30]
    assert np.array_equal(resumed.result_.samples, full.result_.samples)


def test_the_command_line_saves_and_resumes_a_chain(tmp_path, capsys):
    # a run stopped by its step cap and resumed from its chain file carries on from the saved steps; --resume
    # without a chain file is one line before any work
    from negstiff.cli import main

    rec = tmp_path / "r.csv"
    assert main(["rig", "random", "-o", str(rec), "--duration", "12", "--quiet"]) == 0
    chains, out1, out2 = tmp_path / "ch.h5", tmp_path / "p1.json", tmp_path / "p2.json"
    base = ["posterior", str(rec), "--walkers", "16", "--ensembles", "2", "--quiet", "--chain-file", str(chains)]
    assert main([*base, "-o", str(out1), "--max-steps", "40"]) == 0 and chains.exists()
    assert main([*base, "-o", str(out2), "--max-steps", "80", "--resume"]) == 0
    assert json.loads(out2.read_text())["settings"]["resumed_steps"] == [40, 40]
    capsys.readouterr()
    assert main(["posterior", str(rec), "-o", str(tmp_path / "p3.json"), "--resume", "--quiet"]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1
