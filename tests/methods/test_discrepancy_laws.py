"""The discrepancy workflow reads restoring laws (issue 55): its baseline may be a law (``Discrepancy(law=...)``,
``negstiff discrepancy --law``), and the other laws are candidates beside the catalogue's effects (``law:NAME``: a
law replaces the restoring force rather than adding a term to it), scored by the same held-out rules, so that "the
force is not a cubic" can be what it names.

Records: the lab-style records of non-cubic devices written in ``tests/law_records.py`` with numpy, scipy and numba
of their own (the as-built rod frame, a septic polynomial, oblique springs), the rig's default record of the as-built
device (``negstiff rig random --seed 5``), and the real FrID free decay of a beam stiffened by magnets
(``tests/data/frid_magneto_mechanical_decay``). The acceptance for a named law (the issue's): the truth's law, or
one whose force is within 3 % rms of the truth's over the stroke. What each fit reached is in the comments (seed 1
unless said).
"""

import functools
import json
import warnings
from pathlib import Path

import numpy as np
import pytest
from law_records import WRITERS, rod_frame_record

from negstiff.cli import main
from negstiff.errors import InputError
from negstiff.inference.estimators.discrepancy import LINEAR_BASELINE, Discrepancy
from negstiff.inference.record.reading import load
from negstiff.models import laws

FORCE_TOLERANCE = 0.03
"""A named law's force may differ from the truth's by at most 3 % rms over the stroke (the issue's acceptance)."""
CATALOGUE_STIFFENING = {"quadratic_stiffness", "cubic_stiffness", "quartic_stiffness", "quintic_stiffness", "end_stop"}
"""What the catalogue alone names for a force that is not a cubic: polynomial terms and a one-sided stop."""

FRID = Path(__file__).parents[1] / "data" / "frid_magneto_mechanical_decay" / "decay_f_42p05_ampl_2p0_0_12p1-19p1s.lvm"
FRID_COLUMNS = "force=Sine with Gaussian Noise,z=Strain_0"
"""The generator's output (0 throughout the cut: a free decay) and the beam's strain gauge (test_public_impact_...)."""


def force_error(model, truth) -> float:
    """The model's restoring force per unit mass against the truth's, rms over the stroke the record visited (its
    0.5-99.5 % quantiles, 400 points, in the physical frame), as a share of the truth's rms there."""
    z = np.linspace(*truth.stroke, 400)
    f = model.restoring_force(z + (truth.frame_offset or 0.0)) / model.m
    return float(np.sqrt(np.mean((f - truth.force(z)) ** 2) / np.mean(truth.force(z) ** 2)))


@functools.cache
def _rod_frame(directory: str):
    """The as-built rod frame's 60 s random run (law_records), written once per session's folder."""
    return rod_frame_record(Path(directory), seed=1, duration=60.0)


@pytest.fixture(scope="module")
def rod_frame(tmp_path_factory):
    return _rod_frame(str(tmp_path_factory.mktemp("rod_frame")))


@pytest.fixture(scope="module")
def rod_frame_cubic(rod_frame):
    """The workflow with the reference study's baseline (cubic K, c and c_nl) on the rod frame's record."""
    return Discrepancy().fit(rod_frame.load())


def test_the_rod_frames_force_is_named_as_a_law_not_as_stiffening_terms(rod_frame, rod_frame_cubic):
    # the as-built device's exact geometric K is no cubic: with the cubic baseline the catalogue alone named
    # stiffening terms and a stop the device does not have; offered the laws, the workflow replaces the restoring
    # force by the geometric law (its held-out weak residual 0.26 % against the septic's 0.27 %, the quintic's
    # 0.53 %, the catalogue's best, the stop, 3.2 %, the baseline 6.4 %), its force 0.06 % rms from the truth's over
    # the stroke, and nothing after it (gap 6.5 -> 0.20 %)
    d, truth = rod_frame_cubic, rod_frame.truth
    r = d.result()
    assert r["baseline_law"]["restoring"] == "cubic" and r["baseline_law"]["damping"] == "quadratic"
    assert set(r["laws_offered"]) == set(laws.names("restoring")) - {"cubic"}
    assert r["effects"][0].startswith("law:"), r["iterations"][0]["ranking"]
    assert not CATALOGUE_STIFFENING & set(r["effects"]), r["effects"]
    assert r["law"] == r["effects"][0][len("law:") :]
    assert force_error(d.model_, truth) <= FORCE_TOLERANCE
    eq = d.model_.equilibria()
    assert eq.z_minus == pytest.approx(truth.wells["minus"], rel=0.02)
    assert eq.z_plus == pytest.approx(truth.wells["plus"], rel=0.02)
    assert r["gap_after_percent"] < r["gap_before_percent"] / 2
    # each round says why the candidate ranked first was or was not named
    for it in r["iterations"]:
        first = it["first"]
        assert first["effect"] == it["ranking"][0]["effect"]
        assert it["named"] == first["effect"] if first["named"] else first["why"]


def test_with_the_geometric_law_as_its_baseline_nothing_is_missing(rod_frame, tmp_path):
    # the same record from the command line, its baseline the device's own law (--law geometric) with the reference
    # study's damping: its shape from the record (L 0.0600 m, alpha 6.90 degrees), no effect and no other law beats it
    # (the catalogue's best, quadratic stiffness, by 0.26 % of the held-out weak residual, one standard error 0.25 %)
    out = tmp_path / "disc.json"
    code = main(["discrepancy", str(rod_frame.path), "--columns", rod_frame.columns, "--law", "geometric",
                 "--damping", "quadratic", "-o", str(out), "--quiet"])  # fmt: skip
    assert code == 0
    r = json.loads(out.read_text())
    assert r["effects"] == ["none"], r["iterations"][0]["ranking"][:4]
    base = r["baseline_law"]
    assert (base["requested"], base["restoring"], base["damping"], r["law"]) == ("geometric",) * 2 + (
        "quadratic", "geometric")  # fmt: skip
    assert set(r["laws_offered"]) == set(laws.names("restoring")) - {"geometric"}
    assert {e["effect"] for e in r["ranking"]} >= {f"law:{n}" for n in r["laws_offered"]}
    first = r["iterations"][0]["first"]
    assert not first["named"] and first["why"]
    # the frame's shape as built: the rods' length within 1 % (weak form, 60 s), the angle within half a degree
    shape = base["shape"]["shape"]["rod_frame"]
    assert shape["L"] == pytest.approx(rod_frame.truth.params["L"], rel=0.01)
    assert shape["alpha_deg"] == pytest.approx(rod_frame.truth.params["alpha_deg"], abs=0.5)


def test_a_real_decay_stiffened_by_magnets_names_a_smooth_force_not_a_contact():
    # FrID's beam ringing down between magnets hardens smoothly (36.8 -> 41.3 Hz over the decay): the cubic baseline
    # misses it, and the catalogue alone named an end stop whose onset lay inside the motion (a contact passed on
    # every large cycle is a smooth stiffening, not a contact). Offered the laws, the spline over the stroke is named
    # (held-out weak residual 13.9 % against the septic's 19.1 %, the stop's 24.0 %, the baseline's 43.3 %) and no
    # contact after it; gap 56 -> 37 %
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rec = load(FRID, columns=FRID_COLUMNS, gravity=0.0)
        r = Discrepancy().fit(rec).result()
    assert r["record_kind"]["kind"] == "decay"
    assert "end_stop" not in r["effects"], r["iterations"]
    assert r["effects"][0] in ("law:spline", "law:magnet"), r["iterations"][0]["ranking"][:4]
    assert r["gap_after_percent"] < r["gap_before_percent"]


def test_a_law_and_baseline_terms_are_one_baseline_too_many():
    with pytest.raises(InputError, match="give a law or baseline terms"):
        Discrepancy(law="geometric", baseline=LINEAR_BASELINE)._validate()


def test_the_command_line_refuses_a_law_with_a_linear_baseline_in_one_line(rod_frame, tmp_path, capsys):
    out = tmp_path / "disc.json"
    code = main(["discrepancy", str(rod_frame.path), "--columns", rod_frame.columns, "--law", "magnet",
                 "--baseline", "linear", "-o", str(out), "--quiet"])  # fmt: skip
    assert code == 2 and not out.exists()
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "law" in err[0]


# --- long studies (-m slow) ----------------------------------------------------------------------------------------
@functools.cache
def _rig_record_5(directory: str) -> Path:
    """``negstiff rig random --seed 5``: the as-built device's default 300 s rig record."""
    path = Path(directory) / "rig5.csv"
    assert main(["rig", "random", "--seed", "5", "-o", str(path), "--quiet"]) == 0
    return path


@pytest.mark.slow
def test_the_default_rig_record_names_the_geometric_law_not_a_stop_it_does_not_have(tmp_path_factory):
    # the record: before, quintic stiffness, quartic stiffness and an end stop at 28.7 mm (k 270 N/m) that the
    # rig does not have; now the geometric law (held-out weak residual 0.280 % against the septic's 0.286 %, the
    # stop's 3.04 %, the baseline's 4.69 %), gap 2.85 -> 0.118 %, and nothing after it. With the geometric law as its
    # baseline, and with the law the record asks for (auto: geometric, median window 0.131 %, weight 1.00), nothing
    path = _rig_record_5(str(tmp_path_factory.mktemp("rig5")))
    rec = load(path)
    r = Discrepancy().fit(rec).result()
    assert r["effects"] == ["law:geometric"], r["iterations"][0]["ranking"][:4]
    assert r["gap_after_percent"] < r["gap_before_percent"] / 10
    for law in ("geometric", "auto"):
        r = Discrepancy(law=law).fit(rec).result()
        assert r["effects"] == ["none"], (law, r["iterations"][0]["ranking"][:4])
        assert r["law"] == "geometric" and r["baseline_law"]["restoring"] == "geometric"
    assert r["baseline_law"]["choice"]["chosen"] == "geometric"


@pytest.mark.slow
@pytest.mark.parametrize("name", ["septic", "oblique_springs"])
def test_a_non_cubic_device_is_named_by_its_own_law(name, tmp_path):
    # the septic double well (256 Hz, a laser whose zero is off): law:septic, its force 0.018 % rms from the truth's;
    # the oblique-spring isolator (one well, a relative-velocity sensor): law:oblique_springs (0.473 % against the
    # septic's 0.463 %, within one standard error with four parameters fewer), 0.16 %
    lr = WRITERS[name](tmp_path, seed=1, duration=60.0)
    d = Discrepancy().fit(lr.load())
    r = d.result()
    assert r["effects"][0].startswith("law:"), r["iterations"][0]["ranking"][:4]
    assert not CATALOGUE_STIFFENING & set(r["effects"]), r["effects"]
    assert r["effects"][0] == f"law:{lr.truth.name}" or force_error(d.model_, lr.truth) <= FORCE_TOLERANCE
    assert force_error(d.model_, lr.truth) <= FORCE_TOLERANCE
