"""The discrepancy workflow on a hammer's record and on a free decay (single DOF), on records scipy's DOP853 writes
(``impact_records``, not negstiff's simulator) with a lab's artefacts: the displacement sensor's white noise and, on a
hammer's record, the force channel's 0.5 N offset and 0.05 N of noise. The workflow reads them as NSI and SINDy do
(``record_kind``): a free decay from the record's own initial state, without an input; a hammer's force windowed,
the weak-form rows and restarted windows that would hold a pulse not read (each window restarted after its hit).

Acceptance (the issue "Hammer and decay tests"): a clean decay names nothing; an effect a ring-down shows well is
named and sized: Coulomb friction within 10 % (a decay's envelope tail, linear in time), an end stop's stiffness
within 20 % and its onset within 1 mm (hit in the first swings after each hammer blow). Each at seed 1 by default,
at three seeds with ``-m slow``; what each fit reached is in the comments (seed 1 unless said).
"""

import functools
import json
import warnings

import numpy as np
import pytest
from impact_records import (
    DOUBLE_WELL,
    DUFFING,
    LIGHT_DUFFING,
    MASS,
    decay_record_with_force,
    fixture_decay_record,
    fixture_hammer_record,
    hammer_record_with_force,
)

from negstiff import Discrepancy, from_arrays

FS = 1000.0
LASER_DECAY_M = 5e-6
"""The decays' displacement noise [m rms] (a laser triangulation sensor's)."""
LASER_HAMMER_M = 1e-6
"""The hammer records' displacement noise [m rms] (as in ``test_ring_down_identification``)."""
HITS = (0.5, 3.0, 5.5, 8.0)
"""Four 40 N, 4 ms hits 2.5 s apart, the last one in the held-out tail."""

FRICTION_N = 0.005
"""Coulomb friction [N] in the light Duffing's decay: its envelope falls 4 F / k = 18 um a cycle whatever the
amplitude, the viscous 0.5 % as much as that at 1 mm, so the decay's last seconds are friction's (the 8 mm release
stops after 7.5 s; the records are cut at 7 s, where it still moves 0.3 mm)."""
FRICTION_DECAY_S = 7.0

STOP_K = 3000.0
"""An end stop's contact stiffness [N/m] (3.6x the plus well's), ``STOP_ABOVE_WELL`` above the double well's plus
well: the 40 N hits swing it 7.7 mm, so each hit's first 3-4 swings reach 1.3 mm into the stop (1.2 % of the
record)."""
STOP_ABOVE_WELL = 0.005


def _friction(z, v):
    return FRICTION_N * np.tanh(v / 1e-3)  # Coulomb friction smoothed over 1 mm/s (the registry's law)


def _stop_at(onset):
    def force(z, v):
        return STOP_K * (z - onset) if z > onset else 0.0

    return force


def _nothing(z, v):
    return 0.0


def _fit(rec, **params) -> dict:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return Discrepancy(**params).fit(rec).result()


def _decay(model, z0, seed, duration, hidden):
    _, z, _ = decay_record_with_force(model, z0, FS, duration, hidden)
    zm = z + LASER_DECAY_M * np.random.default_rng(seed).standard_normal(z.size)
    return from_arrays(np.zeros(z.size), zm, FS, input_name="force", mass=MASS, source=f"decay-{seed}")


def _hammer(seed, hidden, laser_m=LASER_HAMMER_M):
    model = DOUBLE_WELL
    _, f, z, _ = hammer_record_with_force(model, model.equilibria().z_plus, FS, HITS, 40.0, 0.004, 10.0, hidden)
    rng = np.random.default_rng(seed)
    force = f + 0.5 + 0.05 * rng.standard_normal(f.size)
    zm = z + laser_m * rng.standard_normal(z.size)
    return from_arrays(force, zm, FS, input_name="force", mass=MASS, source=f"hammer-{seed}"), z


def _clean_release(seed):
    # released 12 mm beyond the plus well, it crosses into the minus well and rings down there for 7 s (cut at 6 s,
    # seed 2's scoring part, 3.6-4.8 s, held under two blocks of its test functions; at 5 s all three seeds' did)
    return _decay(DOUBLE_WELL, DOUBLE_WELL.equilibria().z_plus + 0.012, seed, 7.0, _nothing)


@functools.cache
def _clean_decay_fit(seed: int) -> dict:
    return _fit(_clean_release(seed))


@functools.cache
def _friction_decay_fit(seed: int) -> dict:
    return _fit(_decay(LIGHT_DUFFING, 0.008, seed, FRICTION_DECAY_S, _friction))


def _stop_onset() -> float:
    return float(DOUBLE_WELL.equilibria().z_plus + STOP_ABOVE_WELL)


@functools.cache
def _stop_hammer_fit(seed: int) -> tuple[dict, float]:
    """The result on seed's hammer record with the stop, and the share of the record beyond its onset."""
    rec, z = _hammer(seed, _stop_at(_stop_onset()))
    return _fit(rec), float(np.mean(z > _stop_onset()))


def seeds() -> list:
    """Seed 1 by default, seeds 2 and 3 with ``-m slow`` (three seeds in all)."""
    return [1, *(pytest.param(s, marks=pytest.mark.slow) for s in (2, 3))]


def _covers(interval: dict, truth: float) -> bool:
    lo, hi = interval["interval"]
    return lo <= truth <= hi


@pytest.mark.parametrize("seed", seeds())
def test_a_clean_free_decay_of_the_double_well_names_nothing(seed):
    # the seed's model form is the truth here: no effect lowers the held-out weak residual beyond its noise.
    # Measured (seeds 1-3): none named, the held-out gap 0.034-0.036 % (the restarted runs from the measured states:
    # 5 um of noise on a decay from 32 mm), k3 within 0.002 %
    r = _clean_decay_fit(seed)
    assert r["record_kind"]["kind"] == "decay"
    assert r["effects"] == ["none"], r["iterations"]
    assert r["iterations"][0]["named"] == "none"
    assert r["gap_after_percent"] == r["gap_before_percent"]  # nothing added: the same model, the same runs
    assert r["effect_interval"] == {} and r["bayesian"] == {}


@pytest.mark.parametrize("seed", seeds())
def test_coulomb_friction_in_a_free_decay_is_named_sized_and_its_gap_closed(seed):
    # the decay's last part is friction's (its envelope linear in time): the held-out tail judges it. Measured:
    # named 5.010 mN (+0.2 %), 90 % interval [3.72, 6.30] mN, the held-out gap 16.4 % -> 2.4 %, in the tail's
    # windows where it acts 8.2 % -> 2.4 %; LOO prefers the model with it
    r = _friction_decay_fit(seed)
    assert r["record_kind"]["kind"] == "decay"
    assert r["effects"] == ["coulomb_friction"], r["iterations"]
    # within the 10 %: friction is 0.4-2 % of the restoring force over the decay, sized over every cycle
    assert r["effect_size"]["coulomb_friction"] == pytest.approx(FRICTION_N, rel=0.1)
    first = r["iterations"][0]
    assert first["kept"] and {"pooled", "regime", "bayesian"} <= set(first["evidence"]), first
    regime = r["gap_regime_percent"]["coulomb_friction"]
    assert regime["windows"] >= 3 and regime["after"] <= regime["before"] / 2, regime
    assert r["gap_after_percent"] <= r["gap_before_percent"] / 2
    assert _covers(r["effect_interval"]["coulomb_friction"], FRICTION_N), r["effect_interval"]
    assert r["bayesian"]["coulomb_friction"]["prefers"] == "with", r["bayesian"]
    # its blocks and windows shortened to the ring-down (a 7 s record: its scoring part 1.4 s)
    assert r["settings"]["window_s"] < 2.0


@pytest.mark.parametrize("seed", seeds())
def test_an_end_stop_hit_after_each_hammer_blow_is_named_and_sized(seed):
    # each hit's first swings reach into the stop; the held-out tail holds one hit, so the stop's windows anywhere
    # in the record are judged by blocked cross-validation (one block per hit). Measured: named, k 3003.6 N/m, onset
    # 25.0002 mm (truth 25.000), interval k [2555, 3453] N/m, the gap where it acts 7.1 % -> 0.30 % over 4 windows
    onset = _stop_onset()
    r, share = _stop_hammer_fit(seed)
    assert 0.005 <= share <= 0.03, share  # the record's premise: the stop acts briefly after each hit
    assert r["record_kind"]["kind"] == "impact"
    assert r["effects"] == ["end_stop"], r["iterations"]
    size = r["effect_size"]["end_stop"]
    assert size["k"] == pytest.approx(STOP_K, rel=0.2)  # the 20 %
    assert size["z"] == pytest.approx(onset, abs=1e-3)  # the 1 mm
    regime = r["gap_regime_percent"]["end_stop"]
    assert regime["windows"] >= 3 and regime["after"] <= regime["before"] / 2, regime
    assert r["gap_after_percent"] <= r["gap_before_percent"]
    interval = r["effect_interval"]["end_stop"]
    assert _covers(interval["k"], STOP_K) and _covers(interval["z"], onset), interval
    assert r["bayesian"]["end_stop"]["prefers"] == "with", r["bayesian"]
    # not refined by output error (its windows would cross the pulses), and the result says why
    assert not r["refinement"]["applied"] and "hammer" in r["refinement"]["reason"]


HAMMER_FRICTION_N = 0.02
"""Coulomb friction [N] on the hammered double well: 4 F / k = 95 um a cycle, the viscous 1.9 % as much at 0.8 mm,
so each hit's ring-down ends (0.36 mm before the next hit) in friction's part."""


def _friction_hammer_fit(seed: int) -> dict:
    rec, _ = _hammer(seed, lambda z, v: HAMMER_FRICTION_N * np.tanh(v / 1e-3))
    return _fit(rec)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_coulomb_friction_in_a_hammer_records_ring_downs_is_named_and_sized(seed):
    # the fast sibling: friction in a free decay (above). Measured: named 20.87, 20.79, 20.71 mN (+3.5 to +4.3 %; c
    # 2 % low and c_nl 0.02-0.03 N s^2/m^2 beside it: the three share the ring-downs' dissipation), the gap where it
    # acts 0.29-0.43 % -> 0.03-0.04 % over 10-12 cross-validated windows; the 90 % intervals, +-5 % ([19.75, 21.98],
    # [19.73, 21.85], [19.74, 21.67] mN), hold 20 mN near their lower ends
    r = _friction_hammer_fit(seed)
    assert r["record_kind"]["kind"] == "impact"
    assert r["effects"] == ["coulomb_friction"], r["iterations"]
    assert r["effect_size"]["coulomb_friction"] == pytest.approx(HAMMER_FRICTION_N, rel=0.1)  # the 10 %
    regime = r["gap_regime_percent"]["coulomb_friction"]
    assert regime["windows"] >= 3 and regime["after"] <= regime["before"] / 2, regime
    assert _covers(r["effect_interval"]["coulomb_friction"], HAMMER_FRICTION_N), r["effect_interval"]
    assert r["bayesian"]["coulomb_friction"]["prefers"] == "with", r["bayesian"]


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_an_end_stop_after_hammer_blows_at_a_triangulation_sensors_noise(seed):
    # the default test's record with 5 um of displacement noise (1 um there). Measured: named, k 2994, 2993, 2983
    # N/m, onsets within 2.3 um, intervals covering both, the gap where it acts 4.0-8.3 % -> 0.20-0.45 %
    rec, _ = _hammer(seed, _stop_at(_stop_onset()), laser_m=5e-6)
    r = _fit(rec)
    assert r["effects"] == ["end_stop"], r["iterations"]
    size = r["effect_size"]["end_stop"]
    assert size["k"] == pytest.approx(STOP_K, rel=0.2)
    assert size["z"] == pytest.approx(_stop_onset(), abs=1e-3)
    regime = r["gap_regime_percent"]["end_stop"]
    assert regime["windows"] >= 3 and regime["after"] <= regime["before"] / 2, regime
    interval = r["effect_interval"]["end_stop"]
    assert _covers(interval["k"], STOP_K) and _covers(interval["z"], _stop_onset()), interval


def test_a_clean_hammer_record_names_nothing_and_reads_its_damping_between_the_hits():
    # the same hits without the stop. With the rows and windows across the 4-sample pulses read, the fit traded the
    # impulse its samples miss (5 %) for damping: c 0.561 and c_nl -0.303 N s^2/m^2 (truth 0.5, 0), the held-out gap
    # 3.9 %. Measured now: none named, c 0.5006, the gap 0.36 % (the true model's own 0.32 %; seeds 2 and 3: c
    # 0.4983 and 0.4999, the gap 0.097 and 0.025 %)
    rec, _ = _hammer(1, _nothing)
    r = _fit(rec)
    assert r["record_kind"]["kind"] == "impact"
    assert r["effects"] == ["none"], r["iterations"]
    # the damping's truth within 2 %: 1 um of noise over four ring-downs of 2.5 s
    assert r["model"]["c"] == pytest.approx(DOUBLE_WELL.c, rel=0.02)
    assert r["gap_before_percent"] < 1.0  # 3x the true model's own: runs restarted across a hit miss by mm


def _write(path, u, z):
    with open(path, "w") as fh:
        fh.write(f"# mass: {MASS}\nt,force,z\n")
        np.savetxt(fh, np.column_stack([np.arange(z.size) / FS, u, z]), delimiter=",", fmt="%.9g")
    return path


def test_the_command_line_reads_a_hammer_file(tmp_path, capsys):
    # the lab's file (force with its offset and noise, the response): read as a hammer's, the stop named. The
    # non-parametric force (--unnamed) is not fitted there, and the result says why: fitted and judged on windows
    # across the pulses it closed the gap they make (4.4 -> 1.2 %, the named model's own gap 0.38 %: measured)
    from negstiff.cli import main

    rec, _ = _hammer(1, _stop_at(_stop_onset()))
    path = _write(tmp_path / "hammer.csv", rec.u, rec.z)
    out = tmp_path / "r.json"
    assert main(["discrepancy", str(path), "--unnamed", "-o", str(out)]) == 0
    err = capsys.readouterr().err
    assert "read as a hammer's record: 4 hammer hit(s)" in err
    assert "refinement: not run on a hammer's record" in err
    assert "unnamed: not fitted on a hammer's record" in err
    res = json.loads(out.read_text())
    assert res["record_kind"]["kind"] == "impact" and res["effects"] == ["end_stop"]
    assert "pulses" in res["unnamed"]["reason"]


def test_the_command_line_names_a_decay_with_its_noisy_force_channel(tmp_path, capsys):
    # a force sensor left connected through a release reads its offset and noise: --decay names the record a free
    # decay (its input not used), as identify --decay does; without it the channel is read as a force's
    from negstiff.cli import main

    rec = _clean_release(2)
    rng = np.random.default_rng(3)
    path = _write(tmp_path / "release.csv", 0.3 + 0.05 * rng.standard_normal(rec.n), rec.z)
    out = tmp_path / "r.json"
    assert main(["discrepancy", str(path), "--decay", "-o", str(out)]) == 0
    assert "read as a free decay's record: named a free decay by the caller" in capsys.readouterr().err
    res = json.loads(out.read_text())
    assert res["record_kind"]["kind"] == "decay" and res["effects"] == ["none"]


@pytest.mark.parametrize("kind", ["hammer", "decay"])
def test_a_structures_ring_down_is_read_as_a_single_dofs(kind):
    # a 2-DOF hammer record and free decay (the Duffing on a sprung fixture, 1 kg at 25 Hz; scipy's DOP853), read as
    # NSI and SINDy read them (the force windowed, the blocks shortened to the ring-down) and judged on the held-out
    # windows between the pulses, each a free decay from a state no pulse smoothed: on a clean record nothing is
    # named, and the final model misses those windows by less than twice what the truth misses there. A hammer's
    # record is not refined unless asked: its model is the weak form's (k3 +2.1 %, c -4.5 %, as NSI's and SINDy's
    # damping 5-25 % off), which the windows, started from each channel's least-error state, tell from the truth
    # (2.16x its 0.60 %; 1.56x its 1.19 % from the band-smoothed states): refined (refine=True) it misses them as the
    # truth does (measured 1.00x) and its weak form's coefficients are within 5 % and 10 %. Before, refused: read raw,
    # its windows across the hits, where the truth itself misses 4.2 % against 1.2 % between them
    from negstiff.inference.analysis.record_kind import identification_record, record_kind
    from negstiff.inference.steps.validation import restarted_structure_runs
    from negstiff.models.structure import Structure

    fixture = {"fixture_mass": 1.0, "fixture_hz": 25.0, "fixture_zeta": 0.02}
    rng = np.random.default_rng(4)
    device = DUFFING if kind == "hammer" else LIGHT_DUFFING
    if kind == "hammer":
        _, f, z = fixture_hammer_record(device, fixture, FS, HITS, 40.0, 0.004, 10.0, force_dof=2)
        f = f + 0.5 + 0.05 * rng.standard_normal(f.size)
    else:
        _, z = fixture_decay_record(device, fixture, (0.0, 0.008), FS, 8.0)
        f = np.zeros(z.shape[1])
    z = z + LASER_HAMMER_M * rng.standard_normal(z.shape)
    rec = from_arrays(f, z, FS, input_name="force", masses=(1.0, MASS), force_dof=2, gravity=0.0,
                      source=f"fixture {kind}")  # fmt: skip
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        d = Discrepancy(element="1-2").fit(rec)
    out = d.result()
    assert d.effects_ == ["none"], out["ranking"]
    read, n_id = identification_record(rec, record_kind(rec)), out["settings"]["identification_samples"]
    truth = Structure.on_fixture(device, **fixture)
    right = restarted_structure_runs(truth, read, n_id, out["validation"]["window_s"], between_pulses=True)
    if kind == "hammer":  # the weak form's model (not refined unless asked), then the refined one
        el = d.structure_.element
        assert el.k3 == pytest.approx(device.k3, rel=0.05) and el.c == pytest.approx(device.c, rel=0.10)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            d = Discrepancy(element="1-2", refine=True).fit(rec)
        out = d.result()
        assert d.effects_ == ["none"] and out["refinement"]["applied"], out["ranking"]
    assert out["validation"]["rms_percent"] <= 2 * right["rms_percent"], (out["validation"], right)
    if kind == "hammer":
        across = restarted_structure_runs(truth, read, n_id, out["validation"]["window_s"])
        assert across["rms_percent"] > 3 * right["rms_percent"]
