"""Records as labs write them: other response sensors, rounded time columns, units in g, low rates,
sensor offsets. Every contract command either succeeds within a stated tolerance of the truth or
refuses with exit 2 and one line (issue: measurements negstiff did not make)."""

import json

import numpy as np
import pytest

from negstiff import load, pin_frame
from negstiff.cli import main
from negstiff.inference.estimators.nsi import NSI
from negstiff.models.device import SEED_LIKE_CROSS_WELL_RMS, SEED_LIKE_CUBIC
from negstiff.models.rig import Rig, Sensors

TRUTH = SEED_LIKE_CUBIC


def _strip_rest(path):
    """A lab with a vibrometer has no laser rest positions: drop them from the metadata."""
    lines = path.read_text().splitlines(keepends=True)
    path.write_text("".join(line for line in lines if "_rest:" not in line))
    return path


@pytest.fixture(scope="module")
def velocity_record(tmp_path_factory):
    """The NSI test's 300 s cross-well record (seed 2), as a vibrometer measures it: relative velocity
    only (0.1 mm/s noise), time printed with 5 decimals, no rest positions."""
    d = tmp_path_factory.mktemp("lab")
    rec = Rig(TRUTH, seed=2, sensors=Sensors(response="velocity")).random(duration=300, rms=SEED_LIKE_CROSS_WELL_RMS)
    path = rec.write(d / "ldv.csv", time_decimals=5)
    return rec, _strip_rest(path)


def test_velocity_record_pins_its_frame_by_gravity(velocity_record):
    # Fact: z = integral of z_dot + C; gravity (K(0) = m g) fixes C. The integral's own error is a
    # random walk of the vibrometer noise, sigma_v sqrt(T dt / 3) = 44 um; the frame's error is what
    # the fit leaves (stated as its standard error), far below the 0.5 mm that would make k2 meaningless.
    rec, path = velocity_record
    m = load(path)  # reading fits nothing: the frame is pinned by the step that needs it, named
    assert not m.info["response"]["z_constant_known"] and "frame" not in m.info["response"]
    m = pin_frame(m)
    info = m.info["response"]
    assert info["measured"] == "z_dot" and not info["z_constant_known"]
    assert info["integration_error_m"] == pytest.approx(44e-6, rel=0.2)
    err = m.z - rec.true["z"]
    assert abs(err.mean()) < 5 * max(info["frame_offset_se_m"], 2e-6) and abs(err.mean()) < 1e-4
    assert (err - err.mean()).std() < 3 * info["integration_error_m"]
    assert m.info["time"]["jitter_s"] <= 0.5e-5 * 1.001  # 5 decimals: half a unit of 1e-5 s


def test_nsi_on_a_velocity_record_recovers_the_truth(velocity_record):
    # Acceptance: well frequencies within 1 %, k1-k3 within 5 % (on the displacement record of the same
    # seed NSI gives k2 -1.2 %; the frame adds 3 k3 dC / k2 = 0.2 % per um)
    _, path = velocity_record
    est = NSI().fit(load(path))
    for well in ("minus", "plus"):
        assert est.modal_[well]["f_hz"] == pytest.approx(TRUTH.uls(well).f_hz, rel=0.01)
    for k in ("k1", "k2", "k3"):
        assert getattr(est.model_, k) == pytest.approx(getattr(TRUTH, k), rel=0.05), k


@pytest.mark.slow  # default-suite time (CI near its limit, 2026-11-23); run with -m slow
def test_sindy_and_the_posterior_run_on_a_velocity_record(velocity_record, tmp_path):
    _, path = velocity_record
    out = tmp_path / "s.json"
    assert main(["identify", "sindy", str(path), "-o", str(out), "--quiet"]) == 0
    r = json.loads(out.read_text())
    assert r["record"]["response"]["measured"] == "z_dot"
    for well in ("minus", "plus"):  # a weak-form fit of the same physics: the wells' frequencies within 2 %
        assert r["modal"][well]["f_hz"] == pytest.approx(TRUTH.uls(well).f_hz, rel=0.02)
    out = tmp_path / "p.json"
    args = ["posterior", str(path), "--duration", "5", "--ensembles", "2", "--walkers", "16", "--max-steps", "600"]
    assert main([*args, "-o", str(out), "--quiet"]) == 0
    p = json.loads(out.read_text())
    assert p["record"]["response"]["measured"] == "z_dot"
    assert p["parameters"]["k3"]["mean"] == pytest.approx(TRUTH.k3, rel=0.1)


VARIANTS = {
    # name: (sensors, write options, column map, duration [s], rms [m/s^2], fs [Hz])
    "displacement": ({}, {}, None, 40, 20.0, 512.0),
    "velocity_5_decimals": ({"response": "velocity"}, {"time_decimals": 5}, None, 40, 20.0, 512.0),
    "absolute_laser": ({"response": "absolute"}, {}, None, 48, 20.0, 512.0),
    "accelerometer_in_well": ({"response": "accelerometer"}, {}, None, 48, 3.0, 512.0),
    "g_units": ({}, {"acc_unit": "g"}, "base_acc=base_acc_g*9.81", 40, 20.0, 512.0),
    "low_rate_128_hz": ({}, {"time_decimals": 6}, None, 60, 20.0, 128.0),
    "laser_zero_offset": ({"response_offset": 0.005}, {}, None, 40, 20.0, 512.0),
}


@pytest.fixture(scope="module")
def variant_files(tmp_path_factory):
    d = tmp_path_factory.mktemp("variants")
    out = {}
    for name, (sens, write, cmap, duration, rms, fs) in VARIANTS.items():
        rec = Rig(TRUTH, seed=4, fs=fs, sensors=Sensors(**sens)).random(
            duration=duration, rms=rms, band=(2.0, min(40.0, 0.3 * fs))
        )
        out[name] = (rec, rec.write(d / f"{name}.csv", **write), cmap)
    return out


@pytest.mark.parametrize("name", list(VARIANTS))
def test_every_variant_loads_to_the_truths_z(variant_files, name):
    # Fact: whatever the sensor, the derived z is the true relative displacement within the sensor
    # chain's error: 30 um laser noise (plus the base's double integration), 44 um of vibrometer random
    # walk, 0.1 mm of an accelerometer's band-limited double integral on in-well motion; a laser zero
    # 5 mm off stays 5 mm off (a measured z keeps the lab's frame, and is warned about elsewhere).
    rec, path, cmap = variant_files[name]
    m = pin_frame(load(path, columns=cmap))
    k = int(round(m.t0 * m.fs))
    err = m.z - rec.true["z"][k : k + m.n]
    offset = 0.005 if name == "laser_zero_offset" else 0.0
    tol = {"accelerometer_in_well": 3e-4, "velocity_5_decimals": 1.5e-4}.get(name, 1e-4)
    if name == "accelerometer_in_well":  # one well visited, two rest positions: the frame is not guessed
        assert m.info["response"]["frame_offset_m"] is None
        assert any("one well" in w for w in m.info["response"]["warnings"])
        err = err - err.mean()
    assert abs(err.mean() - offset) < tol and err.std() < tol, (err.mean(), err.std())
    assert m.fs == pytest.approx(rec.fs, rel=1e-6)


@pytest.mark.parametrize("name", list(VARIANTS))
def test_identify_nsi_on_every_variant(variant_files, name, tmp_path, capsys):
    # Success within tolerance of the truth's well frequencies (2 % on 40-60 s records; NSI's own
    # scatter at this length is ~0.5 %), or a clean refusal. A laser zero 5 mm off is warned about.
    rec, path, cmap = variant_files[name]
    out = tmp_path / "r.json"
    args = ["identify", "nsi", str(path), "-o", str(out)] + (["--columns", cmap] if cmap else [])
    rc = main(args)
    err = capsys.readouterr().err
    assert "Traceback" not in err
    if rc == 2:
        assert not out.exists() and len([x for x in err.splitlines() if "error" in x]) == 1
        assert name == "accelerometer_in_well", f"{name} was refused: {err}"
        return
    assert rc == 0
    r = json.loads(out.read_text())
    if name == "accelerometer_in_well":  # one well visited: its frequency only
        wells = ["plus"]
    else:
        wells = ["minus", "plus"]
    for well in wells:
        assert r["modal"][well]["f_hz"] == pytest.approx(TRUTH.uls(well).f_hz, rel=0.02), well
    if name == "laser_zero_offset":
        assert any("off the rods-horizontal position" in w for w in r["warnings"])


COMMANDS = {
    "simulate": lambda p, o: ["simulate", "MODEL", str(p), "-o", str(o)],
    "identify nsi": lambda p, o: ["identify", "nsi", str(p), "-o", str(o)],
    "identify sindy": lambda p, o: ["identify", "sindy", str(p), "-o", str(o)],
    "posterior": lambda p, o: [
        "posterior",
        str(p),
        "-o",
        str(o),
        "--duration",
        "4",
        "--ensembles",
        "2",
        "--walkers",
        "16",
        "--max-steps",
        "300",
    ],  # fmt: skip
    "discrepancy": lambda p, o: ["discrepancy", str(p), "-o", str(o), "--max-effects", "1"],
}


@pytest.mark.slow
@pytest.mark.parametrize("command", list(COMMANDS))
@pytest.mark.parametrize("name", list(VARIANTS))
def test_every_contract_command_on_every_variant(variant_files, name, command, tmp_path, capsys):
    rec, path, cmap = variant_files[name]
    model = tmp_path / "model.json"
    model.write_text(json.dumps(TRUTH.to_dict()))
    out = tmp_path / ("o.csv" if command == "simulate" else "o.json")
    args = [a if a != "MODEL" else str(model) for a in COMMANDS[command](path, out)]
    rc = main(args + (["--columns", cmap] if cmap else []) + ["--quiet"])
    err = capsys.readouterr().err
    assert "Traceback" not in err and rc in (0, 2), err
    if rc == 2:
        assert not out.exists() and len(err.strip().splitlines()) == 1, err
        return
    if command == "simulate":
        assert np.all(np.isfinite(np.loadtxt(out, delimiter=",", skiprows=1)))
    else:
        r = json.loads(out.read_text())
        assert r["record"]["response"]["measured"] is not None
