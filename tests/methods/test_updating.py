"""GA model updating (seed Eq. 9; issue 5)."""

import json

import pytest

from negstiff.cli import main
from negstiff.inference.estimators.updating import GAUpdater, UpdatingError, fitness, targets_from
from negstiff.models import AS_BUILT, NOMINAL


def test_fitness_is_zero_at_the_truths_own_features_and_positive_elsewhere():
    t = AS_BUILT.features()
    assert fitness(t, t) == 0.0
    assert fitness(NOMINAL.features(), t) > 1.0


def test_fitness_follows_eq9():
    est = {"f_minus": 10.0, "f_plus": 8.0, "z_minus": -0.02, "z_plus": 0.02}
    mod = {"f_minus": 11.0, "f_plus": 8.0, "z_minus": -0.02, "z_plus": 0.021}
    # eps_w = RMS{10 %, 0} = 7.071 %, eps_z = RMS{0, 5 %} = 3.536 %
    assert fitness(mod, est) == pytest.approx(10 / 2**0.5 + 5 / 2**0.5)


@pytest.fixture(scope="module")
def exact_run():
    return GAUpdater(generations=60, seed=3).fit(AS_BUILT.features())


def test_ga_recovers_a_known_target_for_a_fixed_seed(exact_run):
    # the features determine E/m and alpha (device-model.md): 1 % / 0.5 deg on exact features
    d = exact_run.device_
    assert d.E / d.m == pytest.approx(AS_BUILT.E / AS_BUILT.m, rel=0.01)
    assert d.alpha_deg == pytest.approx(AS_BUILT.alpha_deg, abs=0.5)
    assert exact_run.fitness_ < 0.1
    h = exact_run.history_
    assert len(h) == 60 and h[-1]["best"] <= h[0]["best"], "elitist: the best never gets worse"
    assert all(b["best"] <= a["best"] + 1e-12 for a, b in zip(h, h[1:], strict=False))


def test_the_same_seed_gives_identical_results(exact_run):
    again = GAUpdater(generations=60, seed=3).fit(AS_BUILT.features())
    assert again.result()["E"] == exact_run.result()["E"]
    assert again.history_ == exact_run.history_


def test_a_weighed_mass_pins_E():
    ga = GAUpdater(generations=40, seed=5, fixed_mass=AS_BUILT.m).fit(AS_BUILT.features())
    assert ga.device_.m == AS_BUILT.m
    assert ga.device_.E == pytest.approx(AS_BUILT.E, rel=0.01)


def test_targets_come_from_an_identify_result_or_a_flat_json():
    ident = {
        "modal": {"minus": {"f_hz": 11.4, "zeta": 0.1}, "plus": {"f_hz": 9.2, "zeta": 0.1}},
        "equilibria": {"z_minus": -0.028, "z_0": 0.005, "z_plus": 0.023},
    }
    assert targets_from(ident) == {"f_minus": 11.4, "f_plus": 9.2, "z_minus": -0.028, "z_plus": 0.023}
    with pytest.raises(UpdatingError, match="single-well"):
        targets_from(
            {
                "modal": {"minus": {"f_hz": None}, "plus": {"f_hz": 60.0}},
                "equilibria": {"z_minus": None, "z_0": None, "z_plus": 0.0},
            }
        )


def test_update_command_writes_the_contract_keys_and_refuses_bad_targets(tmp_path, capsys):
    tgt = tmp_path / "t.json"
    tgt.write_text(json.dumps(AS_BUILT.features()))
    out = tmp_path / "u.json"
    assert main(["update", str(tgt), "-o", str(out), "--generations", "5", "--seed", "1", "--quiet"]) == 0
    r = json.loads(out.read_text())
    assert {"E", "alpha_deg", "m", "fitness_percent", "generations"} <= set(r)
    assert len(r["generations"]) == 5 and {"best", "mean"} <= set(r["generations"][0])
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"f_minus": 11.0}))
    assert main(["update", str(bad), "-o", str(tmp_path / "x.json"), "--quiet"]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1
    assert not (tmp_path / "x.json").exists()


def test_ga_from_an_as_built_record_recovers_the_device():
    # The acceptance: from a 300 s as-built rig record (realistic sensor noise), the GA updated
    # against the identified restoring force over the stroke the record visited puts alpha within
    # 0.2 deg and E/m within 1 % (measured with SINDy's model, which selects z^4 and z^5 here: +0.11 deg,
    # +0.42 %). Like with like: both sides are K(z)/m at the same states, so neither the polynomial's
    # form nor where the record went biases the comparison the way Eq. 9's features did (9.44 deg).
    # The seed's Eq. 9 fitness is still reported, and it is small at the recovered device.
    from negstiff.inference.estimators.sindy import SINDy
    from negstiff.inference.record.measurement import from_arrays
    from negstiff.models.rig import Rig

    rec = Rig(AS_BUILT, seed=2).random(duration=300.0)
    m = from_arrays(rec.columns["base_acc"], rec.columns["z"], rec.fs, mass=float(rec.meta["mass"]))
    targets = targets_from(SINDy().fit(m).result())
    assert "stroke_z" in targets and "model" in targets
    ga = GAUpdater(generations=120, seed=1).fit(targets)
    d = ga.device_
    assert ga.compared_.startswith("the restoring force")
    assert d.alpha_deg == pytest.approx(AS_BUILT.alpha_deg, abs=0.2)
    assert d.E / d.m == pytest.approx(AS_BUILT.E / AS_BUILT.m, rel=0.01)
    assert ga.fitness_ < 2.0, "seed Eq. 9 against the identified model's features"
    assert ga.result()["objective_percent"] == ga.objective_
