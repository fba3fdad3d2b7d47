"""``negstiff report`` picks its sections by what the record is: a hammer's record gets the FRF, the
identifications and the estimate's interval; a free decay the identifications and the backbone (measured and
the identified model's); a record with nothing to report is refused (exit 2, one line), never an empty report.

The records are written here with scipy's DOP853 (``impact_records``) and carry a lab's artefacts (the
hammer's 0.5 N offset and 0.05 N noise, the sensor's white noise).
"""

import json

import numpy as np
import pytest
from impact_records import DOUBLE_WELL, DUFFING, DUFFING_HZ, MASS, decay_record, hammer_record, measured_hammer

from negstiff.cli import main
from negstiff.models import Model

FS = 1000.0
LIGHT_DUFFING = Model(m=MASS, k1=DUFFING.k1, k2=0.0, k3=DUFFING.k3, c=DUFFING.c / 3, k0=0.0)
"""The Duffing at 0.5 % damping (its decay still reaches the cubic's range where SINDy scores its supports)."""


def _write(path, t, force, z):
    with open(path, "w") as fh:
        fh.write(f"# mass: {MASS}\nt,force,z\n")
        np.savetxt(fh, np.column_stack([t, force, z]), delimiter=",", fmt="%.9g")
    return path


def _hammer_file(tmp_path, seed):
    """The Duffing hit four times as a lab measures it (``measured_hammer``: the force's 0.5 N offset and 0.05 N of
    noise, 1 um of laser noise), written as the lab's CSV."""
    rec = measured_hammer(DUFFING, seed, 1e-6, FS)
    return _write(tmp_path / "hammer.csv", np.arange(rec.n) / FS, rec.u, rec.z)


def _sections(out):
    return json.loads((out / "results.json").read_text())["sections"]


def test_a_hammer_record_reports_its_frf_identification_and_interval(tmp_path):
    rec = _hammer_file(tmp_path, seed=1)
    out = tmp_path / "out"
    # a hammer's report holds the posterior too (the slow test below); these facts need the rest alone
    assert main(["report", str(rec), "-o", str(out), "--quiet", "--only", "frf,nsi,sindy,interval"]) == 0
    secs = _sections(out)
    kinds = [s["kind"] for s in secs]
    assert kinds == ["record", "frf", "identification", "identification", "interval"]
    # the FRF of a nonlinear oscillator hit at 6 mm: its peak within the cubic's shift (4 % at 5 mm) of 12 Hz
    assert secs[1]["result"]["f_hz"] == pytest.approx(DUFFING_HZ, rel=0.04)
    # NSI's own pole within the acceptance's 1 % and 10 %; its interval holds the true k3
    nsi = secs[2]["result"]
    assert nsi["modal"]["plus"]["f_hz"] == pytest.approx(DUFFING_HZ, rel=0.01)
    own = secs[4]["result"]
    assert own["method"] == "nsi" and len(own["blocks"]) == 3
    assert abs(own["model"]["k3"] - DUFFING.k3) < 5 * own["model_se"]["k3"]
    assert (out / "frf_record.png").is_file()


def test_a_hammer_records_report_holds_the_discrepancy_workflow(tmp_path):
    # the discrepancy workflow reads a hammer's record as the identifications do (its windows after the hits): on a
    # Duffing hit four times (the force channel offset by 0.5 N), the seed's model form and nothing more, it names
    # nothing and says how it read the record
    rec = _hammer_file(tmp_path, seed=2)
    out = tmp_path / "out"
    assert main(["report", str(rec), "-o", str(out), "--quiet", "--only", "discrepancy"]) == 0
    secs = _sections(out)
    assert [s["kind"] for s in secs] == ["record", "discrepancy"]
    res = secs[1]["result"]
    assert res["effects"] == ["none"], res["iterations"]
    assert res["record_kind"]["kind"] == "impact"


def test_a_free_decay_reports_its_identification_and_backbone(tmp_path):
    t, z, _ = decay_record(LIGHT_DUFFING, 0.008, FS, 10.0)
    zm = z + 5e-6 * np.random.default_rng(2).standard_normal(t.size)
    out = tmp_path / "out"
    # a decay's report holds the posterior and its band too (the slow test below); these facts need the rest alone
    assert main(["report", str(_write(tmp_path / "decay.csv", t, np.zeros_like(t), zm)), "-o", str(out),
                 "--quiet", "--only", "nsi,sindy,backbone"]) == 0  # fmt: skip
    secs = _sections(out)
    assert [s["kind"] for s in secs] == ["record", "identification", "identification", "backbone"]
    bb = secs[3]["result"]
    # the decay's small-amplitude frequency is the linear one, 12 Hz (within the Hilbert estimate's 0.3 %)
    assert bb["linear"]["f_hz"] == pytest.approx(DUFFING_HZ, rel=0.01)
    # NSI's model, decayed from the record's state and measured alike, traces the measured backbone within 1 %
    assert bb["predicted"]["difference_percent"] < 1.0
    # with it, the forced response NSI's model predicts about the same well, three levels spanning the decay's
    # amplitudes, each peak on that model's backbone (light damping: zeta^2 = 0.0025 % below it; 0.01 % allowed
    # for the continuation's resolution), and the report says what the grey curves are
    curves = bb["forced"]["curves"]
    assert bb["forced"]["well"] == "plus" and len(curves) == 3
    assert all(abs(c["peak_off_backbone_percent"]) < 0.01 for c in curves)
    assert "forced response" in (out / "index.md").read_text()
    assert (out / "backbone_record.png").is_file()


def test_a_record_with_nothing_to_report_is_refused_in_one_line(tmp_path, capsys):
    # a dead input and a response at rest: neither a forced record nor a decay
    t = np.arange(6000) / FS
    z = 0.01 + 1e-5 * np.random.default_rng(0).standard_normal(t.size)
    out = tmp_path / "out"
    assert main(["report", str(_write(tmp_path / "quiet.csv", t, np.zeros_like(t), z)), "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "does not ring down" in err[0]
    assert not out.exists()


def test_a_double_wells_decay_across_the_barrier_reports_the_last_wells_backbone(tmp_path):
    # released 12 mm beyond the plus well, the double well crosses the barrier and rings down in the minus well:
    # the backbone is that well's (its small-amplitude frequency the minus well's linear one, 11.24 Hz)
    eq = DOUBLE_WELL.equilibria()
    t, z, _ = decay_record(DOUBLE_WELL, eq.z_plus + 0.012, FS, 6.0)
    zm = z + 5e-6 * np.random.default_rng(1).standard_normal(t.size)
    out = tmp_path / "out"
    assert main(["report", str(_write(tmp_path / "decay.csv", t, np.zeros_like(t), zm)), "-o", str(out),
                 "--quiet", "--only", "nsi,sindy,backbone"]) == 0  # fmt: skip
    bb = _sections(out)[-1]["result"]
    f_minus = np.sqrt(DOUBLE_WELL.stiffness(eq.z_minus) / MASS) / (2 * np.pi)
    assert bb["linear"]["f_hz"] == pytest.approx(f_minus, rel=0.01)
    assert bb["predicted"]["difference_percent"] < 1.0


@pytest.mark.slow  # a posterior (about 30 s); the backbone's facts without it stay in the default tier above
def test_a_free_decays_report_gives_the_posterior_and_its_backbone_band(tmp_path):
    # the whole decay report: the coefficient posterior (its windows free decays from their own states) holds the
    # true cubic in its 90 % interval, and the backbone's band of posterior draws holds the true model's backbone
    # (measured alike) over most of the measured range: the band is the posterior's, 24 draws
    from negstiff.inference.analysis.backbone import backbone
    from negstiff.inference.record.reading import load

    t, z, _ = decay_record(LIGHT_DUFFING, 0.008, FS, 10.0)
    zm = z + 5e-6 * np.random.default_rng(2).standard_normal(t.size)
    path = _write(tmp_path / "decay.csv", t, np.zeros_like(t), zm)
    out = tmp_path / "out"
    assert main(["report", str(path), "-o", str(out), "--quiet"]) == 0
    secs = _sections(out)
    assert [s["kind"] for s in secs] == ["record", "identification", "identification", "posterior", "discrepancy",
                                         "backbone"]  # fmt: skip
    k3 = secs[3]["result"]["parameters"]["k3"]
    assert k3["hdi_low"] <= LIGHT_DUFFING.k3 <= k3["hdi_high"], k3
    # the record is the seed's model form alone: the discrepancy workflow names nothing on it
    assert secs[4]["result"]["effects"] == ["none"], secs[4]["result"]["iterations"]
    band = secs[5]["result"]["credible"]
    assert band["draws"] == 24 and band["prob"] == pytest.approx(0.9)
    truth = backbone(load(path), model=LIGHT_DUFFING)["predicted"]["hilbert"]
    order = np.argsort(truth["amplitude_m"])  # a decay's amplitudes fall with time
    f_true = np.interp(band["amplitude_m"], np.asarray(truth["amplitude_m"])[order], np.asarray(truth["f_hz"])[order])
    # the band's width is the posterior's (0.01 % here); the measured Hilbert backbone's own scatter about the true
    # model's, its noise (5 um on 0.2-7 mm), sets how close the band can hold it: within 0.05 % of the band's ends
    lo, hi = np.asarray(band["f_hz_low"]), np.asarray(band["f_hz_high"])
    inside = (f_true >= lo * (1 - 5e-4)) & (f_true <= hi * (1 + 5e-4))
    assert inside.mean() >= 0.9, inside.mean()


def test_a_structures_record_without_its_elements_place_is_refused_in_one_line_before_any_work(tmp_path, capsys):
    # a 2-DOF hammer record (z1, z2 and the masses, no '# element:'): once it crashed with a traceback in its record
    # section; a structure's report (tests/cli/test_report_structure.py) needs the element's place, and without it
    # one line asks for it, exit 2, no output
    t, f, z, _ = hammer_record(DUFFING, 0.0, FS, (0.5,), 40.0, 0.004, 3.0)
    path = tmp_path / "structure.csv"
    with open(path, "w") as fh:
        fh.write(f"# masses: 1.0, {MASS}\n# force_dof: 2\n# fs: {FS:g}\nt,force,z1,z2\n")
        np.savetxt(fh, np.column_stack([t, f, 0.1 * z, z]), delimiter=",", fmt="%.9g")
    out = tmp_path / "out"
    assert main(["report", str(path), "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "2 DOFs" in err[0] and "--element" in err[0]
    assert not out.exists()
