"""negstiff map: the bifurcation map of a stepped harmonic campaign (seed Figure 4) from records a lab
writes, with continuations drawn over it.

The campaign is written here with scipy's DOP853 (not the suite's simulator), as a lab runs it: the
amplitude stepped without stopping the table (the state carried over), each step's record a CSV of its
own with a rounded time column and sensor noise, no index."""

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from negstiff.cli import main
from negstiff.models import SEED_LIKE_CUBIC

F_HZ = 9.0
FS = 512.0
AMPS = (12.8, 13.0, 13.2, 13.4, 13.6)
"""Around the seed-like cubic's first doubling from z_plus (13.33 m/s^2 by continuation and by the
suite's own stepped sweep, tests/models/test_continuation.py)."""


def _campaign(folder, noise=1e-5, settle=150, keep=48, seed=0):
    m = SEED_LIKE_CUBIC
    rng = np.random.default_rng(seed)

    def rhs(t, x, a):
        z, v = x
        k = ((m.k3 * z + m.k2) * z - m.k1) * z + m.k0
        return [v, -a * np.sin(2 * np.pi * F_HZ * t) - (m.c * v + m.c_nl * v * abs(v) + k) / m.m]

    x, T = [m.equilibria().z_plus, 0.0], 1 / F_HZ
    folder.mkdir()
    for i, a in enumerate(AMPS):
        sol = solve_ivp(rhs, (0, settle * T), x, args=(a,), method="DOP853", rtol=1e-9, atol=1e-12, max_step=T / 16)
        t = np.arange(int(round(keep * T * FS))) / FS
        rec = solve_ivp(rhs, (settle * T, settle * T + t[-1]), sol.y[:, -1], args=(a,), method="DOP853",
                        rtol=1e-9, atol=1e-12, max_step=T / 16, t_eval=settle * T + t, dense_output=True)  # fmt: skip
        x = rec.sol(settle * T + keep * T)  # the table goes on: the next step starts where this one ends
        u = a * np.sin(2 * np.pi * F_HZ * (settle * T + t))
        z = rec.y[0] + noise * rng.standard_normal(t.size)
        rows = "".join(f"{tt:.6f},{uu:.6f},{zz:.7f}\n" for tt, uu, zz in zip(t, u, z, strict=False))
        (folder / f"step{i:02d}_{a:g}.csv").write_text("t,base_acc,z\n" + rows)


def test_the_map_of_a_lab_campaign_sees_the_doubling_the_continuation_predicts(tmp_path):
    # Fact: the first stepped amplitude whose response has period 2 is the first step above the model's
    # first period doubling (13.33 m/s^2): the map's first period 2 is 13.4, and the continuation of the
    # same model, drawn over the map, puts its doubling within the step below it. The amplitudes the map
    # reads from the inputs are the commanded ones (the input is a clean sine: within 1e-5).
    _campaign(tmp_path / "campaign")
    nf = tmp_path / "nf.json"
    model = tmp_path / "m.json"
    model.write_text(json.dumps(SEED_LIKE_CUBIC.to_dict()))
    assert main(["nfrc", str(model), "--freq", "9", "--amplitude", "12:15", "--well", "plus", "--max-period", "1",
                 "-o", str(nf), "--quiet"]) == 0  # fmt: skip
    out = tmp_path / "map.json"
    assert main(["map", str(tmp_path / "campaign"), "--forcing-hz", "9", "--nfrc", str(nf), "-o", str(out),
                 "--quiet"]) == 0  # fmt: skip
    r = json.loads(out.read_text())
    assert np.allclose([p["amplitude"] for p in r["points"]], AMPS, rtol=1e-5)
    assert [p["period"] for p in r["points"]] == [1, 1, 1, 2, 2]
    assert r["sweeps"]["records"]["first_period_2"] == pytest.approx(13.4, rel=1e-4)
    c = r["continuations"][0]
    assert c["map_first_period_2"] == pytest.approx(13.4, rel=1e-4)
    assert 13.2 < c["first_doubling"] <= 13.4
    assert (tmp_path / "map.png").stat().st_size > 1000 and r["warnings"], "no rest positions: said"


WN = 2 * np.pi * 5.0
DUFFING = {"m": 1.0, "k0": 0.0, "k1": -(WN**2), "k2": 0.0, "k3": 4e6, "c": 2 * 0.02 * WN, "c_nl": 0.0}
"""A single-well hardening Duffing oscillator (5 Hz, 2 % damping): at 3 m/s^2 its response curve bends
right, folding at 6.27 and 10.90 Hz (tests/models/test_continuation.py checks those folds)."""


def _stepped_sine(folder, freqs, direction, a=3.0, settle=60, keep=24, seed=1):
    """A stepped-sine sweep with scipy's DOP853, the table not stopped between steps (the state carried
    over; each step from phase 0 of its own forcing): a CSV a step, its frequency in its metadata."""
    d, rng = DUFFING, np.random.default_rng(seed)

    def rhs(t, x, f):
        z, v = x
        return [v, -a * np.sin(2 * np.pi * f * t) - (d["c"] * v + d["k3"] * z**3 - d["k1"] * z) / d["m"]]

    x = [0.0, 0.0]
    for i, f in enumerate(freqs):
        T = 1 / f
        t = np.arange(int(round(keep * T * FS))) / FS
        sol = solve_ivp(rhs, (0, settle * T + keep * T), x, args=(f,), method="DOP853", rtol=1e-9, atol=1e-12,
                        max_step=T / 16, t_eval=settle * T + t, dense_output=True)  # fmt: skip
        x = sol.sol(settle * T + keep * T)  # the next step starts where this one ends: at phase 0
        u = a * np.sin(2 * np.pi * f * (settle * T + t))
        z = sol.y[0] + 1e-6 * rng.standard_normal(t.size)
        rows = "".join(f"{tt:.6f},{uu:.6f},{zz:.8f}\n" for tt, uu, zz in zip(t, u, z, strict=False))
        (folder / f"{direction}{i:02d}.csv").write_text(f"# forcing_hz: {f:g}\nt,base_acc,z\n" + rows)


# a long study: a stepped sweep each way; the lab campaign's map test keeps the folds' prediction by default
@pytest.mark.slow
def test_a_stepped_sine_jumps_just_past_the_continued_folds(tmp_path):
    # Fact: sweeping up, the response stays on the resonant branch until its fold (10.90 Hz) and drops;
    # sweeping down, it stays on the low branch until the lower fold (6.27 Hz) and climbs. The jump is
    # read between the last step before it and the first after: each continued fold lies within that
    # 0.1 Hz step.
    up, down = tmp_path / "up", tmp_path / "down"
    up.mkdir()
    down.mkdir()
    # 0.5 Hz steps to 0.5 Hz from a fold, 0.1 Hz steps across it (a coarse step near a fold knocks the
    # response off its branch early: 0.25 Hz steps dropped at 10.5-10.75 Hz, before the 10.9 Hz fold);
    # up from below the hysteresis (the resonant branch), down from inside it (the low branch)
    _stepped_sine(up, np.r_[np.arange(5.5, 10.3, 0.5), np.arange(10.4, 11.25, 0.1)], "up")
    _stepped_sine(down, np.r_[7.5, 7.0, np.arange(6.7, 5.85, -0.1)], "down")
    model = tmp_path / "duffing.json"
    model.write_text(json.dumps(DUFFING))
    nf = tmp_path / "nf.json"
    assert main(["nfrc", str(model), "--freq", "4:12", "--amplitude", "3", "--max-period", "1", "-o", str(nf),
                 "--quiet"]) == 0  # fmt: skip
    folds = sorted(b["f_hz"] for b in json.loads(nf.read_text())["bifurcations"] if b["type"] == "fold")
    for folder, fold in ((up, folds[1]), (down, folds[0])):
        out = tmp_path / f"{folder.name}.json"
        assert main(["map", str(folder), "--nfrc", str(nf), "-o", str(out), "--quiet"]) == 0
        r = json.loads(out.read_text())
        assert r["axis"] == "f_hz" and r["forcing_hz"] is None
        jump = r["sweeps"]["records"]["jump_hz"]
        assert abs(jump - fold) <= 0.05 + 1e-9, (folder.name, jump, fold)
        assert r["continuations"][0]["folds"] == pytest.approx(folds)
        assert r["continuations"][0]["map_jumps_hz"]["records"] == jump


@pytest.mark.parametrize("steps", [["--amplitudes", "4:6:1"], ["--freqs", "7:9:1", "--amplitude", "3"]])
def test_a_rig_campaign_folder_is_read_by_its_index(tmp_path, steps):
    # The rig's campaign folder: its index.json gives each record's forcing frequency, starting well and
    # direction, so the map groups the sweeps (up and down from z_plus); a campaign in amplitude at 9 Hz is
    # the seed's map, a stepped sine ('--freqs') a map along the frequency. Each record's forcing amplitude,
    # read from its input, is the commanded one (the accelerometer's noise and bias: within 1 %)
    camp = tmp_path / "camp"
    assert main(["rig", "campaign", "--model", str(_model(tmp_path)), *steps, "--direction", "both",
                 "--settle-periods", "20", "--periods", "24", "-o", str(camp), "--quiet"]) == 0  # fmt: skip
    out = tmp_path / "map.json"
    assert main(["map", str(camp), "-o", str(out), "--quiet"]) == 0
    r = json.loads(out.read_text())
    assert set(r["sweeps"]) == {"plus up", "plus down"}
    assert r["wells_used"] is not None, "the rig's records carry their rest positions"
    up = [p for p in r["points"] if p["direction"] == "up"]
    if steps[0] == "--freqs":
        assert r["axis"] == "f_hz" and [p["f_hz"] for p in up] == [7.0, 8.0, 9.0]
        assert np.allclose([p["amplitude"] for p in up], 3.0, rtol=0.01)
        assert set(r["sweeps"]["plus up"]) == {"sequence", "jump_hz"}
    else:
        assert r["axis"] == "amplitude" and r["forcing_hz"] == 9.0
        assert np.allclose([p["amplitude"] for p in up], [4.0, 5.0, 6.0], rtol=0.01)
    assert all(p["period"] == 1 and p["regime"] == "in-well-plus" for p in r["points"])


def _model(tmp_path):
    p = tmp_path / "model.json"
    p.write_text(json.dumps(SEED_LIKE_CUBIC.to_dict()))
    return p


@pytest.mark.parametrize(
    "case, message",
    [
        ("nfrc in frequency", "a continuation in amplitude at 9 Hz is needed"),
        ("no files", "no measurement files"),
        ("no frequency", "no forcing frequency"),
        ("bad wells", "--wells"),
        ("zero frequency", "is not a positive number"),
    ],
)
def test_bad_map_input_gets_one_line_and_exit_2_before_any_work(tmp_path, capsys, case, message):
    folder = tmp_path / "f"
    folder.mkdir()
    (folder / "a.csv").write_text("t,base_acc,z\n" + "".join(f"{i / 512:.6f},{np.sin(i / 9):.4f},0.02\n"
                                                              for i in range(2048)))  # fmt: skip
    args = ["map", str(folder), "--forcing-hz", "9", "-o", str(tmp_path / "o.json"), "--quiet"]
    if case == "nfrc in frequency":
        nf = tmp_path / "nf.json"
        nf.write_text(json.dumps({"settings": {"parameter": "f_hz", "fixed": 3.0, "well": "plus"}, "branches": [],
                                  "bifurcations": []}))  # fmt: skip
        args += ["--nfrc", str(nf)]
    elif case == "no files":
        (folder / "a.csv").unlink()
    elif case == "no frequency":
        args.remove("--forcing-hz")
        args.remove("9")
    elif case == "zero frequency":
        (folder / "a.csv").write_text("# forcing_hz: 0\n" + (folder / "a.csv").read_text())
        args.remove("--forcing-hz")
        args.remove("9")
    else:
        args += ["--wells", "0.02,-0.03"]
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0], err
    assert not (tmp_path / "o.json").exists() and not (tmp_path / "o.png").exists()


def test_a_folder_without_an_index_is_read_in_its_files_natural_order(tmp_path):
    # a lab's files step2 ... step10: by their numbers, not their characters (step10 sorts before step2)
    from negstiff.inference.analysis.campaign import campaign_records

    for i in (1, 2, 10, 11):
        (tmp_path / f"step{i}.csv").write_text("t,base_acc,z\n0,0,0\n")
    (tmp_path / "step1.truth.json").write_text("{}")
    names = [Path(p["file"]).name for p in campaign_records([str(tmp_path)])]
    assert names == ["step1.csv", "step2.csv", "step10.csv", "step11.csv"]


def test_a_structures_campaign_is_mapped_by_its_elements_relative_motion(tmp_path):
    # a stepped campaign of the device on a 25 Hz fixture (the rig's structure records: z1, z2, the element's place and
    # its relative rests in their headers) is mapped as a single DOF's is, each point the element's relative
    # displacement z2 - z1, its wells the headers' rests: at 2 and 4 m/s^2 around its plus well, period 1 at both, the
    # larger response at the larger step; it had been refused
    from negstiff.models.structure import Structure

    fixture = tmp_path / "fixture.json"
    s = Structure.on_fixture(SEED_LIKE_CUBIC, fixture_mass=1.0, fixture_hz=25.0, fixture_zeta=0.02)
    fixture.write_text(json.dumps(s.to_dict()))
    camp = tmp_path / "camp"
    assert main(["rig", "campaign", "--model", str(fixture), "--freq", "9", "--amplitudes", "2,4", "--start", "plus",
                 "--direction", "up", "--periods", "40", "-o", str(camp), "--quiet"]) == 0  # fmt: skip
    eq = s.element_equilibria()
    out = tmp_path / "map.json"
    assert main(["map", str(camp), "-o", str(out), "--quiet"]) == 0
    res = json.loads(out.read_text())
    assert res["wells_used"] == pytest.approx([eq.z_minus, eq.z_plus], abs=1e-5)
    assert not any("no rest positions" in w for w in res["warnings"])
    points = res["points"]
    assert [p["period"] for p in points] == [1, 1] and all(p["regime"] == "in-well-plus" for p in points)
    assert points[0]["amplitudes"][0] < points[1]["amplitudes"][0]
