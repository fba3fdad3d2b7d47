"""A study over many records (``fit_many``): every estimator fitted on every record, serially or on a dask
cluster, the fitted estimators returned whole, kept on disk and reloaded in a new process with the same
results; the posteriors' coverage of the truths; and dask an optional extra.

Records: the tests' cubic double well (``records.TRUTH``) under band-limited random base acceleration, a
plain numpy RK4 written in the tests (one seed per record), with a laser's 3 um and an accelerometer's
5 mm/s^2 of white noise. 30 s each: SINDy's selection needs 20 s of identification part.
"""

import json
import pickle
import subprocess
import sys

import pytest
from records import FS, TRUTH, rk4_random_records

from negstiff import NSI, Posterior, SINDy, from_arrays
from negstiff.errors import InputError
from negstiff.inference.estimators.many import fit_many

TINY_POSTERIOR = {"seed": 1, "n_ensembles": 2, "min_steps": 20, "max_steps": 40, "chunk": 20, "max_windows": 16}


def records(n):
    return [from_arrays(u, z, FS, mass=TRUTH.m, source=f"rk4 record {i}")
            for i, (u, z) in enumerate(rk4_random_records(range(100, 100 + n), duration=30.0))]  # fmt: skip


def text(d):
    return json.dumps(d, sort_keys=True, default=lambda o: o.tolist() if hasattr(o, "tolist") else str(o))


def kept_and_reloaded(study, tmp_path):
    """Pickle every fit to disk, reload them in a new interpreter, and compare each result() there."""
    expected = {}
    for name, fits in study.fits.items():
        for i, est in enumerate(fits):
            path = tmp_path / f"{name}-{i}.pkl"
            path.write_bytes(pickle.dumps(est))
            expected[path.name] = text(est.result())
    code = (
        "import json, pickle, pathlib, sys\n"
        "out = {p.name: pickle.loads(p.read_bytes()).result() for p in pathlib.Path(sys.argv[1]).glob('*.pkl')}\n"
        "print(json.dumps(out, sort_keys=True, default=lambda o: o.tolist() if hasattr(o, 'tolist') else str(o)))"
    )
    done = subprocess.run([sys.executable, "-c", code, str(tmp_path)], capture_output=True, text=True, check=True)
    reloaded = json.loads(done.stdout)
    assert set(reloaded) == set(expected)
    for key, value in reloaded.items():
        assert text(value) == expected[key], key


def run_study(n, tmp_path):
    recs = records(n)
    truths = [{"k1": TRUTH.k1, "k3": TRUTH.k3, "c": TRUTH.c}] * n
    study = fit_many([NSI(), SINDy(), Posterior(**TINY_POSTERIOR)], recs, truths=truths, scheduler="local", workers=2)
    assert all(e is None for errs in study.errors.values() for e in errs), study.errors
    assert all(est.fitted for fits in study.fits.values() for est in fits)
    # the posterior's coverage of the truths, per parameter (a short chain: counted, not judged calibrated)
    cov = study.coverage["Posterior"]
    assert set(cov) == {"k1", "k3", "c"} and all(c["records"] == n and 0 <= c["share"] <= 1 for c in cov.values())
    assert "NSI" not in study.coverage  # not a posterior
    kept_and_reloaded(study, tmp_path)


def test_two_records_on_a_two_worker_local_cluster_kept_and_reloaded(tmp_path):
    run_study(2, tmp_path)


@pytest.mark.slow  # its fast sibling: test_two_records_on_a_two_worker_local_cluster_kept_and_reloaded
def test_eight_records_on_a_two_worker_local_cluster_kept_and_reloaded(tmp_path):
    run_study(8, tmp_path)


def test_serial_study_gives_the_same_fits_as_the_estimators_alone():
    (rec,) = records(1)
    study = fit_many({"nsi": NSI()}, [rec])
    alone, in_study = NSI().fit(rec).result(), study.fits["nsi"][0].result()
    for key in ("model", "initial_model", "modal", "validation"):  # all but the run's elapsed seconds
        assert text(in_study[key]) == text(alone[key])


def test_dask_missing_is_one_input_error_naming_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)  # as if dask were not installed
    with pytest.raises(InputError, match=r"negstiff\[dask\]"):
        fit_many([NSI()], records(1), scheduler="local")


def test_arviz_summary_uses_negstiffs_interval():
    import warnings

    (rec,) = records(1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        post = Posterior(**TINY_POSTERIOR).fit(rec)
    table = post.result_.arviz_summary(0.9)
    assert "hdi90_lb" in table.columns, list(table.columns)  # arviz's default would be an 89 % ETI
    k3 = post.result()["parameters"]["k3"]
    lo = float(table.loc["k3", "hdi90_lb"])
    assert abs(lo - k3["hdi_low"]) <= 0.5 * k3["sd"]  # the same 90 % HDI, from the thinned draws
