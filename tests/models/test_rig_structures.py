"""The one rig carries a structure of N DOFs as it carries a single DOF: every excitation and every response sensor.

The structure's records are checked against what the rig did not compute: its hammer and release records against
scipy's ``solve_ivp`` (an adaptive Runge-Kutta of its own, on the hits' half-sines as written in the truth), its
sensors against the truth's displacements after the file's round trip through ``load``.
"""

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from negstiff import Measurement, Rig, load
from negstiff.errors import MeasurementError
from negstiff.models import Model
from negstiff.models.records import RigError
from negstiff.models.rig import Sensors
from negstiff.models.structure import Structure

DEVICE = Model(m=0.212, k1=438.6, k2=1001.0, k3=6.72e5, c=0.6, c_nl=0.4)
"""A double-well cubic (wells near +-25 mm) with viscous and quadratic damping."""
FIXTURE = Structure.on_fixture(DEVICE, fixture_mass=1.0, fixture_hz=25.0, fixture_zeta=0.02)


def scipy_run(structure: Structure, force, x0: np.ndarray, t_out: np.ndarray, dof: int,
              max_step: float = np.inf) -> np.ndarray:  # fmt: skip
    """The structure's z (N, T) at ``t_out`` from the state ``x0`` under ``force(t)`` on DOF ``dof``, by scipy's
    DOP853 (its own error control, tolerance 1e-10; ``max_step`` below a pulse's width, so no step jumps a hit),
    the element's law written out here: F(r, r') = k0 - k1 r + k2 r^2 + k3 r^3 + c r' + c_nl r'|r'| across its
    place (I, J).
    """
    el, (i, j) = structure.element, structure.place
    n = structure.n_dof
    m, K, C = np.asarray(structure.masses), np.asarray(structure.K), np.asarray(structure.C)
    lvec = np.zeros(n)
    lvec[j - 1] = 1.0
    if i:
        lvec[i - 1] = -1.0
    k0 = float(el.to_dict()["k0"])  # the model's constant (its m g where it hangs)

    def rhs(t, x):
        z, v = x[:n], x[n:]
        r, rd = lvec @ z, lvec @ v
        f_el = k0 - el.k1 * r + el.k2 * r**2 + el.k3 * r**3 + el.c * rd + el.c_nl * rd * abs(rd)
        load_ = np.zeros(n)
        load_[dof - 1] = force(t)
        return np.r_[v, (load_ - K @ z - C @ v - lvec * f_el) / m]

    sol = solve_ivp(rhs, (t_out[0], t_out[-1]), x0, method="DOP853", t_eval=t_out, rtol=1e-10, atol=1e-13,
                    max_step=max_step)  # fmt: skip
    assert sol.success
    return sol.y[:n]


def test_a_structures_hammer_record_is_the_structure_hit_on_its_dof():
    # the hammer on DOF 1 (the fixture) of the device on its fixture: the rig's noise-free z of both DOFs is the
    # structure's response to the half-sine hits as scipy integrates it from rest in the plus well, within 2e-3 of
    # the response's range. The rig reads a pulse as 16 samples, band-limited between them: a single DOF's hammer
    # record (the same rig) differs from the same scipy run by 6.6e-4 of its range, this structure's by 4.8e-4
    # (measured); scipy's structure hit on DOF 2 instead misses it by 1.6 times its range
    rig = Rig(FIXTURE, sensors=Sensors.noiseless(), seed=2)
    rec = rig.hammer(peak=30.0, hits=2, duration=2.0, dof=1)
    exc = rec.truth["excitation"]
    assert rec.meta["force_dof"] == "1" and exc["force_dof"] == 1 and rec.meta["masses"] == "1,0.212"

    def force(t):
        for h in exc["hit_times_s"]:
            if h <= t <= h + exc["width_s"]:
                return exc["peak_n"] * math.sin(math.pi * (t - h) / exc["width_s"])
        return 0.0

    t = rec.columns["t"]
    x0 = np.r_[FIXTURE.equilibria()["plus"], 0.0, 0.0]
    z = scipy_run(FIXTURE, force, x0, t, dof=1, max_step=exc["width_s"] / 4)
    span = np.ptp(z, axis=1)
    assert np.all(span > 1e-5)  # both DOFs ring
    assert np.max(np.abs(rec.true["z"] - z) / span[:, None]) < 2e-3
    assert np.array_equal(rec.z, rec.true["z"])  # noise-free sensors: the lasers read the truth
    # the file, read back: a structure's force record with the DOF it was hit on
    m = Measurement.from_rig(rec)
    assert m.n_dof == 2 and m.input_name == "force" and m.force_dof == 1 and m.masses == (1.0, 0.212)


def test_a_structures_release_decays_from_the_held_element_into_a_well():
    # the element held 8 mm past the plus well, every DOF where the structure rests under that hold, then let go:
    # scipy's run from that state gives the same decay within 1e-6 of its range (no input to sample: the rig's RK4
    # at 4 steps a sample against DOP853 at 1e-10, measured 4.5e-9), and the structure comes to rest in a well
    rig = Rig(FIXTURE, sensors=Sensors.noiseless())
    r0 = FIXTURE.element_equilibria().z_plus + 0.008
    rec = rig.release(r0, duration=4.0)
    t = rec.columns["t"]
    z = scipy_run(FIXTURE, lambda t: 0.0, np.r_[FIXTURE.static_positions(r0), 0.0, 0.0], t, dof=2)
    assert np.max(np.abs(rec.true["z"] - z)) < 1e-6 * np.ptp(z)
    rest = rec.true["z"][:, -1]
    assert min(np.abs(rest - w).max() for w in FIXTURE.equilibria().values()) < 1e-4


@pytest.mark.parametrize("response", ["displacement", "velocity", "absolute", "accelerometer"])
def test_each_dof_carries_the_sensor_the_rig_names_and_load_reads_it_back(tmp_path, response):
    # a low-level random test in the plus well (0.5 m/s^2: the device's z2 moves 0.5 mm rms, near-linear, so an
    # accelerometer's z, which loses what lies below 1 Hz, holds), each DOF its own sensor; the file read back
    # derives each DOF's z as a single DOF's: within twice the chain's largest noise (the lasers' 30 um; measured
    # 28-29 um through lasers, 8-18 um through vibrometers and accelerometers) of the truth, each channel's constant
    # aside (a structure's identification estimates it). DOFs swapped would miss by their difference, 0.45 mm rms
    rig = Rig.device_on_fixture(DEVICE, seed=4, sensors=Sensors(response=response))
    rec = rig.random(duration=30.0, rms=0.5)
    named = {"displacement": "z{}", "velocity": "z{}_dot", "absolute": "y{}", "accelerometer": "y{}_acc"}[response]
    assert sorted(rec.columns) == sorted(["t", "base_acc", named.format(1), named.format(2)])
    m = load(rec.write(tmp_path / f"{response}.csv"))
    assert m.n_dof == 2 and m.masses == (1.0, 0.212)
    k = int(round(m.t0 * rec.fs))
    truth = rec.true["z"][:, k : k + m.n]
    err = (m.z - m.z.mean(axis=1, keepdims=True)) - (truth - truth.mean(axis=1, keepdims=True))
    inner = slice(m.n // 10, -m.n // 10)  # an integral's ends
    assert np.sqrt(np.mean(err[:, inner] ** 2, axis=1)).max() < 2 * rig.sensors.laser_noise


def test_the_one_rig_refuses_for_a_structure_what_it_cannot_do():
    rig = Rig.device_on_fixture(DEVICE)
    with pytest.raises(RigError, match="the hammer hits a DOF 1..2"):
        rig.hammer(dof=3)
    with pytest.raises(RigError, match="starting well must be"):
        rig.random(duration=5.0, start="left")
    # a record whose sensor measured no z is derived through its file, not guessed at
    acc = Rig.device_on_fixture(DEVICE, sensors=Sensors(response="accelerometer")).random(duration=5.0, rms=2.0)
    with pytest.raises(RigError, match="no measured z"):
        _ = acc.z
    with pytest.raises(MeasurementError, match="is read from its file"):
        Measurement.from_rig(acc)


def test_a_structures_record_states_its_element_and_the_estimators_read_it(tmp_path, capsys):
    # the rig's header names the element's place ('# element: 1-2') as it names the masses: identify reads it as it
    # reads '# masses:' (no --element needed), the estimators likewise; a header naming a place the record's DOFs
    # cannot hold is refused in one line naming the file
    import json

    from negstiff import NSI
    from negstiff.cli import main
    from negstiff.errors import InputError

    path = Rig.device_on_fixture(DEVICE, seed=1).random(duration=20.0, rms=14.0).write(tmp_path / "fixture.csv")
    out = tmp_path / "nsi.json"
    assert main(["identify", "nsi", str(path), "-o", str(out), "--quiet"]) == 0
    assert json.loads(out.read_text())["element_at"] == [1, 2]
    assert NSI().fit(load(path)).result_.structure.place == (1, 2)
    bad = tmp_path / "bad.csv"
    bad.write_text(path.read_text().replace("# element: 1-2", "# element: 3-1"))
    with pytest.raises(InputError, match="bad.csv: '# element: 3-1'"):
        NSI().fit(load(bad))
