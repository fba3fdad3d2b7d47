"""Reports on a user's own records (issue "Reports on the user's own records"): ``negstiff report`` on the
Silverbox, on a velocity-only record, a harmonic campaign and a low-level record written here with scipy,
and a report built from Python over records at three amplitudes. Each: exit 0, every analysis present or
its reason shown, the coefficient table with NSI, SINDy and the posterior's interval, the summary first."""

import json

import numpy as np
import pytest
from records import FS, TRUTH, dop853_record, write_csv

from negstiff import NSI, Posterior, Report, SINDy, from_arrays
from negstiff.cli import main

COEFFICIENTS = ("k1", "k2", "k3", "c", "c_nl")


def _run(argv):
    assert main([str(a) for a in argv] + ["--quiet"]) == 0


def _results(folder):
    res = json.loads((folder / "results.json").read_text())
    html = (folder / "index.html").read_text()
    return res, html


def _summary_first(html):
    # the summary, then the contents, then the first numbered section
    assert html.index("class='summary'") < html.index("id='contents'") < html.index("<h2 id='s1-")


def _every_section_or_its_reason(res, kinds):
    got = [s["kind"] for s in res["sections"]]
    for kind in kinds:
        assert kind in got or any(s["kind"] == "failure" for s in res["sections"]), (kind, got)
    for s in res["sections"]:
        if s["kind"] == "failure":
            assert s["title"] and any("not made" in line for line in res["summary"])


def _coefficient_table(res, methods=("NSI", "SINDy")):
    for k in COEFFICIENTS:
        row = res["coefficients"][k]
        for m in methods:
            assert np.isfinite(row[m]), (k, m)
        post = row["posterior"]
        assert post["hdi_low"] <= post["mean"] <= post["hdi_high"], k


@pytest.fixture(scope="module")
def velocity_record(tmp_path_factory):
    """60 s of TRUTH (scipy DOP853) as a vibrometer measures it: relative velocity only (0.1 mm/s noise). 60 s, not
    120 (CI time): SINDy's k1 and k3 on it are within 0.01 % of the truth (measured), the posterior's 30 s are the
    same samples as before (its interval as on 120 s, measured); a 10 s posterior was tried and is not used: on the
    integrated velocity its interval came out narrower than on 30 s and held neither method's estimates."""
    t, u, _, v = dop853_record(duration=60.0, rtol=1e-8)  # integration error far below the 0.1 mm/s noise
    v = v + 1e-4 * np.random.default_rng(4).standard_normal(v.size)
    eq = TRUTH.equilibria()
    d = tmp_path_factory.mktemp("velocity")
    meta = {"mass": TRUTH.m, "z_minus_rest": f"{eq.z_minus:.6f}", "z_plus_rest": f"{eq.z_plus:.6f}"}
    return write_csv(d / "ldv.csv", {"t": t, "base_acc": u, "z_dot": v}, meta)


# a long study: the report's sections on a vibrometer record; tests/records/test_bench_records.py keeps velocity
# records by default
@pytest.mark.slow
def test_report_on_a_velocity_only_record(velocity_record, tmp_path):
    out = tmp_path / "rep"
    _run(["report", velocity_record, "--duration", "30", "-o", out])
    res, html = _results(out)
    _summary_first(html)
    _every_section_or_its_reason(res, ("record", "identification", "posterior", "discrepancy", "frf"))
    _coefficient_table(res)
    record = next(s for s in res["sections"] if s["kind"] == "record")["result"]
    assert record["info"]["response"]["measured"] == "z_dot" and record["info"]["response"]["frame"]
    for k in ("k1", "k3"):  # the truth's polynomial: SINDy recovers it (a sanity check of what is reported)
        assert res["coefficients"][k]["SINDy"] == pytest.approx(getattr(TRUTH, k), rel=0.05), k


@pytest.mark.slow  # 48 s: the Silverbox's identification and prediction are the default tier's (test_nsi, test_sindy)
def test_report_on_the_silverbox(silverbox, tmp_path):
    from records import write_npz_channels

    train = silverbox.segment(40650, 105712)
    data = write_npz_channels(tmp_path / "silverbox_train.npz", {"V1": train.u, "V2": train.z})
    out = tmp_path / "rep"
    _run(["report", data, "--columns", "force=V1,z=V2", "--fs", "610.35", "--duration", "20", "-o", out])
    res, html = _results(out)
    _summary_first(html)
    _every_section_or_its_reason(res, ("record", "identification", "posterior", "discrepancy", "frf"))
    _coefficient_table(res)


def _harmonic_record(amplitude, seed, cycles=60):
    from scipy.integrate import solve_ivp

    f = 9.0
    w = 2 * np.pi * f

    def rhs(t, x):
        z, v = x
        return [v, (-TRUTH.c * v - TRUTH.c_nl * v * abs(v) - TRUTH.restoring_force(z)) / TRUTH.m
                - amplitude * np.sin(w * t)]  # fmt: skip

    n_settle = int(60 / f * FS)
    t = np.arange(n_settle + int(cycles / f * FS)) / FS
    sol = solve_ivp(rhs, (0, t[-1]), [TRUTH.equilibria().z_plus, 0.0], t_eval=t, method="DOP853", rtol=1e-9,
                    atol=1e-12)  # fmt: skip
    z = sol.y[0] + 2e-5 * np.random.default_rng(seed).standard_normal(t.size)
    u = amplitude * np.sin(w * t)
    return (t - t[n_settle])[n_settle:], u[n_settle:], z[n_settle:]


def test_report_on_a_harmonic_campaign_and_one_harmonic_record(tmp_path):
    eq = TRUTH.equilibria()
    meta = {"forcing_hz": 9, "z_minus_rest": eq.z_minus, "z_plus_rest": eq.z_plus, "mass": TRUTH.m}
    camp = tmp_path / "camp"
    camp.mkdir()
    for i, a in enumerate((3.0, 6.0, 9.0)):
        t, u, z = _harmonic_record(a, i)
        write_csv(camp / f"step{i}.csv", {"t": t, "base_acc": u, "z": z}, meta)
    out = tmp_path / "map"
    _run(["report", camp, "-o", out])
    res, html = _results(out)
    _summary_first(html)
    assert [s["kind"] for s in res["sections"]] == ["record", "map"]
    assert len(next(s for s in res["sections"] if s["kind"] == "map")["result"]["points"]) == 3
    out = tmp_path / "one"
    _run(["report", camp / "step0.csv", "-o", out])
    res, html = _results(out)
    _summary_first(html)
    char = next(s for s in res["sections"] if s["kind"] == "characterisation")["result"]
    assert char["period"] == 1, "3 m/s^2 at 9 Hz: the in-well period-1 response"


@pytest.mark.slow  # 23 s: the low-level FRF is the default tier's (test_frf), the report's machinery the others'
def test_report_on_a_low_level_record(tmp_path):
    eq = TRUTH.equilibria()
    t, u, z, _ = dop853_record(duration=40.0, rms=1.5, start=eq.z_minus, seed=3)
    z = z + 3e-6 * np.random.default_rng(5).standard_normal(z.size)
    rec = write_csv(tmp_path / "low.csv", {"t": t, "base_acc": u, "z": z},
                    {"mass": TRUTH.m, "z_minus_rest": eq.z_minus, "z_plus_rest": eq.z_plus})  # fmt: skip
    out = tmp_path / "rep"
    _run(["report", rec, "--duration", "20", "-o", out])
    res, html = _results(out)
    _summary_first(html)
    _every_section_or_its_reason(res, ("record", "identification", "posterior", "discrepancy", "frf"))
    frf = next(s for s in res["sections"] if s["kind"] == "frf")["result"]
    assert frf["well"] == "minus"
    assert frf["f_hz"] == pytest.approx(TRUTH.uls("minus").f_hz, rel=0.01), "the low-level FRF: the well's own"


# a long study: three records and their posteriors; the reports on the Silverbox, a harmonic campaign and a
# low-level record keep the report engine in the default suite
@pytest.mark.slow
def test_a_report_built_from_python_over_three_amplitudes(tmp_path):
    # an experiment script's report: each record's SINDy and NSI, and one posterior, in one coefficient table.
    # 30 s records (40 s before; CI time): with 3 um of laser noise SINDy's k3 errs by ~1e-5 relative on 30 s
    # (measured, as on 40 s), far inside the 5 % sanity bound. Not shorter: SINDy's held-out selection needs ~21 s,
    # and on 24 s the 10 m/s^2 record's held-out part (4.8 s) is too short for NSI's restarted free runs (warned).
    # The posterior on 5 s of the last record (20 s before): its interval's width is not what is tested here, only
    # that it sits in the table (4x fewer windows, and its wider sd needs fewer RK4 substeps)
    rep = Report("Three amplitudes")
    fits = {}
    for rms in (6.0, 8.0, 10.0):
        t, u, z, _ = dop853_record(duration=30.0, rms=rms, seed=int(rms), rtol=1e-8)
        rec = from_arrays(u, z + 3e-6 * np.random.default_rng(int(rms)).standard_normal(z.size), FS, mass=TRUTH.m,
                          source=f"rms {rms:g}")  # fmt: skip
        label = f"{rms:g} m/s^2"
        fits[label] = SINDy().fit(rec)
        rep.add(fits[label], label=label).add(NSI().fit(rec), label=label)
    rep.add(Posterior(seed=1).fit(rec.segment(0, int(5 * FS))), label="10 m/s^2")
    rep.add_text("SINDy's k3 at each amplitude, one record each.", heading="How k3 moves with amplitude")
    rep.add_table(["amplitude", "k3"], [[lab, f.model_.k3] for lab, f in fits.items()])
    rep.write(tmp_path / "rep")
    res, html = _results(tmp_path / "rep")
    _summary_first(html)
    k3 = res["coefficients"]["k3"]
    for label in fits:
        assert k3[f"SINDy ({label})"] == pytest.approx(TRUTH.k3, rel=0.05)
        assert f"NSI ({label})" in k3
    post = k3["posterior (10 m/s^2)"]
    assert post["hdi_low"] < post["mean"] < post["hdi_high"]
    assert "How k3 moves with amplitude" in html


def test_the_identification_summary_gives_the_final_models_wells_and_the_own_step_beside_them():
    # an in-well sine sweep (2 m/s^2 over 60 s, the plus well at 8.253 Hz): NSI's subspace step puts the well at
    # 9.79 Hz and its refined model at 8.161 Hz (measured; SINDy's own equation-error model at 5.95 Hz, its refined
    # one at 8.165), and the summary said "finds the wells at 9.79". It now gives the final model's well, within 2 %
    # of the truth's (the refined model's error, 1.1 %), with the own step's beside it; the table gives both
    from negstiff.inference.record.measurement import Measurement
    from negstiff.models import SEED_LIKE_CUBIC
    from negstiff.models.rig import Rig
    from negstiff.report.sections import identification_section

    rec = Measurement.from_rig(Rig(SEED_LIKE_CUBIC, seed=1).sine_sweep(amplitude=2.0, duration=60.0))
    sec = identification_section(NSI().fit(rec))
    truth_hz = float(np.sqrt(SEED_LIKE_CUBIC.stiffness(SEED_LIKE_CUBIC.equilibria().z_plus) / SEED_LIKE_CUBIC.m))
    truth_hz /= 2 * np.pi
    (line,) = [s for s in sec.summary if "has its wells at" in s]
    said = float(line.split("plus ")[1].split(" Hz")[0])
    assert said == pytest.approx(truth_hz, rel=0.02), line
    assert "its own step's estimate: plus" in line, line
    header = next(b[1][0] for b in sec.blocks if b[0] == "table")
    assert header[1:] == ["own f [Hz]", "own zeta [%]", "final f [Hz]", "final zeta [%]"]
