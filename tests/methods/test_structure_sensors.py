"""A structure's responses as a lab's sensors measure them, channel by channel: each DOF's z measured by a laser
(``zK``) or derived from its own sensor (``zK_dot``, a vibrometer's relative velocity; ``yK``, ``yK_dot``,
``yK_acc``, absolute), as a single DOF's z is, each channel's units and scale read per channel. The records are
written here with a plain RK4 (``records.rk4_fixture_record``, its own velocities), not negstiff's simulator."""

import warnings

import numpy as np
import pytest
from records import FIXTURE, rk4_fixture_record, write_csv

from negstiff import InputError, Model, SINDy, load
from negstiff.models import SEED_LIKE_CUBIC
from negstiff.models.structure import Structure

FS = 512.0
DEVICE = Model(**{**SEED_LIKE_CUBIC.to_dict(), "m": 0.2, "k0": 0.2 * 9.81})
TRUTH = Structure.on_fixture(DEVICE, fixture_mass=FIXTURE["m"], fixture_hz=FIXTURE["f_hz"],
                             fixture_zeta=FIXTURE["zeta"])  # fmt: skip
V_NOISE = 1e-5
"""A vibrometer's white noise [m/s] (its integral walks by ~1 um over the record)."""
V_BIAS = np.array([2e-4, -1.5e-4])
"""Each vibrometer's zero error [m/s]: its integral drifts by 12 and -9 mm over 60 s if left in."""
BIASED = pytest.mark.xfail(strict=True, reason="a vibrometer's constant zero error: the integral's drift is removed "
                           "by a 0.05 Hz high-pass (sensors.velocity_to_z), which leaves 29 and 190 um rms of slow "
                           "error on the two channels (1.4 and 1.1 um without the bias) and moves SINDy's plus-well "
                           "mode from 8.53 to 10.1 Hz. A straight line taken off in its place (measured 2026-11-29) "
                           "leaves 16 / 82 um: "
                           "the record's own motion has a straight-line trend over 60 s that a constant zero error "
                           "cannot be told from (16 / 82 um without any bias), and a wandering zero is then kept (the "
                           "magnet harvester's, 0.70 mm). Next: each channel's zero rate as a parameter the "
                           "identification fits with the structure")  # fmt: skip


@pytest.fixture(scope="module", params=[0.0, pytest.param(1.0, marks=BIASED)], ids=["zero-right", "zero-error"])
def vibrometer_file(tmp_path_factory, request):
    # 60 s of random base excitation of the device on its fixture; each DOF's velocity relative to the table as a
    # vibrometer reads it (white noise, and in the second case a zero error), the fixture's in mm/s as its export
    # labels it
    u, z, v = rk4_fixture_record(duration=60.0, rms=12.0, seed=11, device=DEVICE, noise=0.0, velocity=True)
    rng = np.random.default_rng(4)
    vm = v + request.param * V_BIAS[:, None] + V_NOISE * rng.standard_normal(v.shape)
    path = tmp_path_factory.mktemp("sensors") / "vibrometers.csv"
    t = np.arange(u.size) / FS
    write_csv(path, {"t": t, "base_acc": u, "z1_dot [mm/s]": 1e3 * vm[0], "z2_dot": vm[1]},
              {"masses": f"{FIXTURE['m']},{DEVICE.m}"})  # fmt: skip
    return path, z


def test_each_dofs_z_is_derived_from_its_own_vibrometer(vibrometer_file):
    # the integral of each channel's velocity, its zero error's drift separated, is the DOF's displacement up to a
    # constant: within a few tens of um of the integrator's own z over the record (a 40 mm stroke), each channel
    # in its own units (mm/s on DOF 1)
    path, z_true = vibrometer_file
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the drift notes
        rec = load(path)
    assert rec.n_dof == 2
    k = (z_true.shape[1] - rec.n) // 2  # the samples cut at each end, if any
    truth = z_true[:, k : k + rec.n]
    err = (rec.channels - rec.channels.mean(axis=1, keepdims=True)) - (truth - truth.mean(axis=1, keepdims=True))
    rms = np.sqrt(np.mean(err**2, axis=1))
    assert np.all(rms < 5e-5), rms
    acc = rec.info["response"]["channels"]
    assert [a["column"] for a in acc] == ["z1_dot", "z2_dot"] and all(a["measured"] == "z_dot" for a in acc)


def test_a_structure_measured_by_vibrometers_is_identified_as_by_lasers(vibrometer_file):
    # the physics does not depend on the sensor: SINDy on the vibrometers' record reads the device's modes within
    # 1 % in frequency and 10 % in damping, k1-k3 within 5 % (the lasers' acceptance)
    path, _ = vibrometer_file
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        est = SINDy(element="1-2").fit(load(path))
    for well in ("minus", "plus"):
        for got, true in zip(est.modal_[well], TRUTH.modes(well), strict=True):
            assert got.f_hz == pytest.approx(true.f_hz, rel=0.01), (well, got, true)
            assert got.zeta == pytest.approx(true.zeta, rel=0.10), (well, got, true)
    for name in ("k1", "k2", "k3"):
        assert est.element_[name] == pytest.approx(getattr(DEVICE, name), rel=0.05), name


def test_a_dofs_sensor_is_read_by_the_column_map_and_a_bad_one_refused(tmp_path):
    # a map names each DOF's sensor like a single DOF's; a DOF with two responses, a response no sensor gives
    # (an acceleration relative to the table) and a gap in the DOFs are one line each, before any work
    u, z = rk4_fixture_record(duration=4.0, seed=2, device=DEVICE)
    t = np.arange(u.size) / FS
    path = tmp_path / "lab.csv"
    write_csv(path, {"t": t, "ACC": u, "LASER1": 1e3 * z[0], "LASER2": z[1]}, {"masses": "1,0.2"})
    rec = load(path, columns="base_acc=ACC,z1=LASER1*0.001,z2=LASER2")
    assert rec.n_dof == 2 and np.allclose(rec.channels, z)
    bad = {
        "z1=LASER1*0.001,z1_dot=LASER2": "DOF 1 has two responses",
        "z1=LASER1*0.001,z2_acc=LASER2": "z2_acc: a DOF's response is one of",
        "z1=LASER1*0.001,z3=LASER2": "z1 ... zN",
    }
    for cmap, why in bad.items():
        with pytest.raises(InputError, match=why):
            load(path, columns=f"base_acc=ACC,{cmap}")
