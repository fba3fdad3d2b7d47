"""negstiff as a library (issue "A library people build on"): one front door, the CLI's checks in the
library, one identification pipeline with typed results, arviz as its users expect, reprs that help.
Written as a user writes a script, with ``from negstiff import ...`` only, on records written here with
scipy (a bistable oscillator integrated by DOP853 under a continuous multisine base acceleration)."""

import json
import re
import subprocess
import sys
import warnings

import numpy as np
import pytest
from records import FS, TRUTH, dop853_record, write_csv

from negstiff import (
    NSI,
    Discrepancy,
    Identification,
    InputError,
    Measurement,
    NegstiffWarning,
    NotFittedError,
    Posterior,
    Rig,
    SINDy,
    characterise,
    frf,
    from_arrays,
    load,
    nfrc,
    simulate,
)
from negstiff.cli import main


@pytest.fixture(scope="module")
def scipy_record(tmp_path_factory):
    """A 40 s cross-well record written by scipy, 3 um laser noise, with its mass and rest positions."""
    d = tmp_path_factory.mktemp("library")
    t, u, z, _ = dop853_record(duration=40.0)
    z = z + 3e-6 * np.random.default_rng(1).standard_normal(z.size)
    eq = TRUTH.equilibria()
    meta = {"mass": TRUTH.m, "z_minus_rest": f"{eq.z_minus:.6f}", "z_plus_rest": f"{eq.z_plus:.6f}"}
    return write_csv(d / "rec.csv", {"t": t, "base_acc": u, "z": z}, meta)


@pytest.fixture(scope="module")
def scipy_fits(scipy_record):
    """NSI and SINDy with their defaults on the scipy record, fitted once for the tests that check facts about
    those same fits (deterministic: a second fit is the same numbers)."""
    rec = load(scipy_record)
    return {"nsi": NSI().fit(rec), "sindy": SINDy().fit(rec)}


# --- 1. one front door ------------------------------------------------------------------------------------
def test_the_front_door_exports_every_public_name_lazily():
    import negstiff
    import negstiff.inference
    import negstiff.models

    for module in (negstiff, negstiff.inference, negstiff.models):
        for name in module.__all__:
            assert getattr(module, name) is not None, f"{module.__name__}.{name}"
    # importing the package, and building the command line's parser for `negstiff --help` or for a command
    # that fits nothing, loads no compiled simulator (a fitting command's options import their estimator)
    for only in ("", "rig", "frf", "characterise"):
        code = ("import negstiff, sys; from negstiff.cli import build_parser; "
                f"build_parser(only={only!r}); print('numba' in sys.modules)")  # fmt: skip
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
        assert out.stdout.strip() == "False", (only, out.stderr)


# --- 2. the checks are the library's ------------------------------------------------------------------------
def test_a_record_in_mm_warns_from_python_as_from_the_cli(tmp_path, capsys):
    # the probe's finding: NSI().fit(load("rec_in_mm.csv")) returned k1 = -922 and no warning at all
    Rig(seed=1).random(duration=20.0).write(tmp_path / "rec.csv")
    lines = (tmp_path / "rec.csv").read_text().splitlines()
    head = [x for x in lines if x.startswith("#")] + [lines[len([x for x in lines if x.startswith("#")])]]
    data = np.loadtxt(lines[len(head) :], delimiter=",")
    data[:, 2:] *= 1e3  # y, base_disp, z in mm, the header saying nothing
    mm = tmp_path / "mm.csv"
    mm.write_text("\n".join(head) + "\n" + "\n".join(",".join(f"{x:.10g}" for x in r) for r in data) + "\n")
    with pytest.warns(NegstiffWarning, match="in mm"):  # said at once, when the record is read
        rec = load(mm)
    with pytest.warns(NegstiffWarning, match="in mm"):  # and with the result, which carries it
        nsi = NSI(refine=False).fit(rec)
    assert any("in mm" in w for w in nsi.warnings_)
    # the record's dynamics weigh the input the 1000 times that z in mm gives it (the weak fit's own error:
    # 999 and 1000 were read on this record)
    weighs = [re.search(r"weigh base_acc ([0-9.e+]+) times", w) for w in nsi.warnings_]
    ratio = [float(m.group(1)) for m in weighs if m]
    assert len(ratio) == 1 and ratio[0] == pytest.approx(1000, rel=0.01), nsi.warnings_
    out = tmp_path / "mm.json"
    assert main(["identify", "nsi", str(mm), "--no-refine", "-o", str(out), "--quiet"]) == 0
    cli = json.loads(out.read_text())
    assert cli["warnings"] == nsi.result()["warnings"], "the CLI prints the library's warnings, no more"
    err = capsys.readouterr().err
    assert all(f"WARNING: {w}" in err for w in cli["warnings"])


def test_an_input_in_g_is_warned_about_by_the_library(scipy_record):
    rec = load(scipy_record)
    in_g = from_arrays(rec.u / 9.80665, rec.z, rec.fs, mass=rec.mass, source="in_g")
    with pytest.warns(NegstiffWarning, match="is base_acc in g"):
        SINDy(refine=False).fit(in_g)


@pytest.mark.parametrize("bad", ["nan", "inf", "negative_fs", "2d"])
def test_from_arrays_is_validated_like_a_file(bad):
    u, z = np.sin(np.arange(2000) / 9), 0.02 + 1e-3 * np.cos(np.arange(2000) / 9)
    kw = {"nan": dict(u=np.where(np.arange(2000) == 7, np.nan, u), z=z, fs=512.0),
          "inf": dict(u=u, z=np.where(np.arange(2000) == 9, np.inf, z), fs=512.0),
          "negative_fs": dict(u=u, z=z, fs=-512.0),
          "2d": dict(u=np.c_[u, u], z=z, fs=512.0)}[bad]  # fmt: skip
    with pytest.raises(InputError):
        from_arrays(**kw)


def test_a_single_well_record_names_its_well_by_where_it_is(tmp_path):
    # 30 s in the minus well (low level, started there); the rest positions are in the metadata
    t, u, z, _ = dop853_record(duration=30.0, rms=1.5, start=TRUTH.equilibria().z_minus, seed=3)
    eq = TRUTH.equilibria()
    assert z.max() < eq.z_0, "the record stays in the minus well"
    rec = load(write_csv(tmp_path / "minus.csv", {"t": t, "base_acc": u, "z": z},
                         {"mass": 0.2, "z_minus_rest": eq.z_minus, "z_plus_rest": eq.z_plus}))  # fmt: skip
    true_f = TRUTH.uls("minus").f_hz
    for est in (NSI(), SINDy()):
        modal = est.fit(rec).modal_
        assert modal["minus"]["f_hz"] == pytest.approx(true_f, rel=0.01), f"{type(est).__name__}: the well's name"
        if modal["plus"]["f_hz"] is not None:  # a model's other well, outside the stroke: said to be extrapolated
            assert any("beyond the stroke the record visited" in w for w in est.warnings_)
    assert NSI().fit(rec).modal_["plus"]["f_hz"] is None, "NSI identifies the well the record visited only"


# --- 3. one pipeline, typed results ----------------------------------------------------------------------
def test_nsi_and_sindy_share_one_pipeline_and_result_type(scipy_record, scipy_fits):
    rec = load(scipy_record)
    nsi, sindy = scipy_fits["nsi"], scipy_fits["sindy"]
    for est in (nsi, sindy):
        r = est.result_
        assert isinstance(r, Identification)
        assert r.identification_samples == round(0.8 * rec.n) == est.settings_["identification_samples"]
        assert type(est.equilibria_).__name__ == "Equilibria"
        assert r.validation.rms_percent == r.validation["rms_percent"]  # a bunch: keys are attributes
        assert set(est.result()) >= {"method", "model", "initial_model", "equilibria", "modal", "validation",
                                     "refinement", "bounded", "warnings", "record"}  # fmt: skip
        with pytest.raises(TypeError):
            r.validation["rms_percent"] = 0.0  # read-only
    # the methods' own estimates differ (each its equation error); refined they meet the same optimum
    assert nsi.initial_model_.k3 != sindy.initial_model_.k3
    for k in ("k1", "k3"):
        assert getattr(nsi.model_, k) == pytest.approx(getattr(TRUTH, k), rel=0.02)
        assert getattr(sindy.model_, k) == pytest.approx(getattr(TRUTH, k), rel=0.02)


# --- 4. posteriors: warnings through Python, arviz as its users expect -----------------------------------
# a long study: two posteriors; test_posterior.py keeps arviz's data and the convergence warnings by default
@pytest.mark.slow
def test_an_unconverged_posterior_warns_and_its_arviz_data_agree_with_its_summary(scipy_record):
    import arviz as az

    # 10 s (20 s before; CI time): what is checked is the warning of a short chain and that arviz's summary of
    # the samples is the posterior's own, neither of which needs the longer record's narrower posterior
    rec = load(scipy_record).segment(0, int(10 * FS))
    with pytest.raises(InputError, match="hdi_prob"):  # before any sampling
        Posterior(hdi_prob=90).fit(rec)
    with pytest.warns(NegstiffWarning, match="ESS|R-hat"):
        post = Posterior(seed=1, max_steps=120, min_steps=120, n_ensembles=2).fit(rec)
    assert post.result()["warnings"] and not post.result()["converged"]
    post = Posterior(seed=1).fit(rec)
    idata = post.result_.idata
    assert idata.posterior.sizes["chain"] == post.n_ensembles, "chain = independent ensemble"
    assert not [d for d in idata.log_likelihood.z.dims if d.endswith("_dim_0") or "_dim_" in d]
    assert set(idata.observed_data.z.dims) == {"window", "time"}
    s = az.summary(idata)
    for name, own in post.result()["parameters"].items():
        assert float(s.loc[name, "r_hat"]) == pytest.approx(own["r_hat"], abs=0.01), name


# --- 5. reprs ---------------------------------------------------------------------------------------------
def test_reprs_are_short_summaries(scipy_record):
    assert repr(Rig()) == "Rig(the as-built device, fs=512 Hz, oversample=4, seed=0, sensor=displacement)"
    assert repr(SINDy()) == "SINDy()  [not fitted]" and len(repr(SINDy(n_models=10))) < 60
    rec = load(scipy_record)
    assert "array" not in repr(rec) and "20480 samples at 512 Hz" in repr(rec)
    assert repr(TRUTH).startswith("Model(m=0.2, k1=426, k2=-3060, k3=777000")
    with pytest.raises(NotFittedError):
        NSI().result()


# --- acceptance: the whole workflow from Python, and the same JSON from the command line -------------------
def _same(a, b, path=""):
    """Equal JSON, timings aside."""
    if isinstance(a, dict):
        assert set(a) == set(b), f"{path}: keys {sorted(set(a) ^ set(b))}"
        for k in a:
            if k not in ("seconds", "elapsed_s"):
                _same(a[k], b[k], f"{path}/{k}")
    elif isinstance(a, list):
        assert len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b, strict=False)):
            _same(x, y, f"{path}[{i}]")
    else:
        assert a == b, f"{path}: {a!r} != {b!r}"


def test_the_whole_workflow_from_python_gives_the_cli_json(scipy_record, scipy_fits, tmp_path):
    from negstiff.cli.common import _finite

    warnings.simplefilter("ignore", NegstiffWarning)
    rec = load(scipy_record)
    short = str(tmp_path / "short.csv")
    # the posterior's record: 10 s (20 s before; CI time): the JSON is what is compared, not the posterior's width
    raw = np.loadtxt(scipy_record, delimiter=",", skiprows=4)[: int(10 * FS)]
    write_csv(tmp_path / "short.csv", {"t": raw[:, 0], "base_acc": raw[:, 1], "z": raw[:, 2]}, {"mass": 0.2})
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)  # numpy's notices leaked from Discrepancy.fit once
        disc = Discrepancy().fit(rec).result()
    runs = {
        # the module's NSI and SINDy fits of this record with their defaults (the same fits a script makes)
        "nsi": (scipy_fits["nsi"].result(), ["identify", "nsi", str(scipy_record)]),
        "sindy": (scipy_fits["sindy"].result(), ["identify", "sindy", str(scipy_record)]),
        # a short chain of two ensembles (the JSON is what is compared, not the sampler's convergence)
        "posterior": (
            Posterior(seed=0, max_steps=300, n_ensembles=2).fit(load(short)).result(),
            ["posterior", short, "--max-steps", "300", "--ensembles", "2"],
        ),  # fmt: skip
        "discrepancy": (disc, ["discrepancy", str(scipy_record)]),
    }
    for name, (py, argv) in runs.items():
        out = tmp_path / f"{name}.json"
        assert main([*argv, "-o", str(out), "--quiet"]) == 0
        _same(json.loads(json.dumps(_finite(py))), json.loads(out.read_text()), name)
    # simulate and continue the identified model, as a script does
    model = scipy_fits["nsi"].model_
    sim = simulate(model, rec.u, rec.dt, z0=rec.z[0], v0=0.0)
    assert not sim.diverged[0]
    nf = nfrc(model, freq=9.0, amplitude=(2.0, 6.0), well="plus")
    assert nf["branches"] and all(p["stable"] in (True, False) for p in nf["branches"][0]["points"])
    assert isinstance(rec, Measurement) and callable(characterise) and callable(frf)
