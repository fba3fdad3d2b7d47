"""The simulator: physics it must respect, accuracy against scipy DOP853, batch = single."""

import numba
import numpy as np
import pytest

from negstiff.models import AS_BUILT, Model, simulate, simulate_batch
from negstiff.models.kernel import STATUS_DIVERGED, STATUS_GEOMETRY
from negstiff.models.reference import reference_solution

FS = 512.0


def _energy_drift(system, well, dz, substeps):
    """Max relative change, over 100 undamped unforced periods, of the oscillation energy above the
    well bottom, E = m v^2/2 + U(z) - U(z*)."""
    zs = system.equilibria().well(well)
    n = int(100 / system.uls(well).f_hz * FS)
    r = simulate(system, np.zeros(n), 1 / FS, z0=zs + dz, v0=0.0, substeps=substeps)
    e = 0.5 * system.m * r.z_dot[0] ** 2 + system.potential(r.z[0]) - system.potential(zs)
    return np.max(np.abs(e - e[0])) / e[0]


@pytest.mark.parametrize(
    "system, well",
    [(Model(m=0.2, k1=426.0, k2=-3060.0, k3=7.77e5), "plus"), (AS_BUILT.with_(c=0.0, c_nl=0.0), "minus")],
)
def test_energy_is_conserved_without_damping_or_forcing(system, well):
    # On an oscillator RK4 multiplies the energy by |R(i w h)|^2 = 1 - (w h)^6 / 72 per step, so the
    # drift per unit time is O(h^5): below 1e-6 over 100 periods at 4 substeps per sample
    # (w h = 0.028), and halving h divides it by 2^5 = 32 (asserted within 20-45).
    fine, coarse = _energy_drift(system, well, 0.004, 8), _energy_drift(system, well, 0.004, 4)
    assert coarse < 1e-6
    assert 20 < coarse / fine < 45, "fifth-order energy convergence of RK4 on an oscillator"


def test_simulator_matches_solve_ivp_on_an_in_well_response():
    # both integrate the same linearly interpolated input; 10 s in-well 9 Hz response
    t = np.arange(0, 10, 1 / FS)
    u = 3.0 * np.sin(2 * np.pi * 9.0 * t)
    zp = AS_BUILT.equilibria().z_plus
    ours = simulate(AS_BUILT, u, 1 / FS, z0=zp).z[0]

    ref = reference_solution(AS_BUILT, u, 1 / FS, zp)
    assert np.max(np.abs(ours - ref)) < 1e-7


def test_force_input_is_divided_by_the_mass():
    # m z'' + ... = f  is the same motion as base excitation with b'' = -f/m
    m = Model(m=0.5, k1=426.0, k2=-3060.0, k3=7.77e5, c=2.0)
    u = np.sin(np.arange(2000) / FS * 2 * np.pi * 7)
    a = simulate(m, u, 1 / FS, input_kind="force").z[0]
    b = simulate(m, -u / m.m, 1 / FS, input_kind="base_acc").z[0]
    assert np.allclose(a, b, rtol=0, atol=1e-15)


def test_batch_path_gives_the_same_result_as_the_single_path(rng):
    t = np.arange(0, 20, 1 / FS)
    u = rng.normal(0, 8, t.size)
    devs = [
        AS_BUILT.with_(E=AS_BUILT.E * f, c=AS_BUILT.c * g)
        for f, g in zip([0.98, 1.0, 1.02], [1.0, 1.2, 0.8], strict=True)
    ]
    P = np.column_stack([d.kernel_params() for d in devs])
    zp = AS_BUILT.equilibria().z_plus
    batch = simulate_batch(P, "device", u, 1 / FS, np.array([zp, 0.0]), threads=2)
    for i, d in enumerate(devs):
        single = simulate(d, u, 1 / FS, z0=zp).z[0]
        assert np.allclose(batch.z[i], single, rtol=0, atol=1e-13)


def test_each_member_may_read_its_own_input_row(rng):
    m = Model(m=0.2, k1=426.0, k2=-3060.0, k3=7.77e5, c=1.5)
    U = rng.normal(0, 5, (2, 3000))
    P = np.repeat(m.kernel_params()[:, None], 4, axis=1)
    r = simulate_batch(P, "polynomial", U, 1 / FS, np.array([m.equilibria().z_plus, 0]), input_index=[0, 1, 1, 0])
    assert np.array_equal(r.z[0], r.z[3]) and np.array_equal(r.z[1], r.z[2])
    assert not np.allclose(r.z[0], r.z[1])


def test_divergence_is_detected_and_reported():
    # negative damping feeds energy in: the response grows beyond any physical bound
    m = Model(m=0.2, k1=426.0, k2=-3060.0, k3=7.77e5, c=-3.0)
    r = simulate(m, np.zeros(int(60 * FS)), 1 / FS, z0=m.equilibria().z_plus + 0.001)
    assert r.status[0] == STATUS_DIVERGED and np.isfinite(r.fail_time[0])
    assert np.all(np.isnan(r.z[0][int(r.fail_time[0] * FS) :]))
    assert "diverged" in r.describe_failures()


def test_leaving_the_device_stroke_is_detected():
    # a violent base excitation throws the mass beyond the rods' reach
    r = simulate(AS_BUILT, np.full(2000, 400.0), 1 / FS)
    assert r.status[0] == STATUS_GEOMETRY
    assert "stroke" in r.describe_failures()


@pytest.mark.parametrize(
    "kw, message",
    [({"dt": -1.0}, "positive"), ({"u": np.array([0.0, np.nan, 1.0])}, "NaN"), ({"substeps": 0}, "substeps")],
)
def test_bad_simulation_arguments_are_refused(kw, message):
    m = Model(m=0.2, k1=426.0, k2=-3060.0, k3=7.77e5)
    args = {"u": np.zeros(10), "dt": 1 / FS, "substeps": 2, **kw}
    with pytest.raises(ValueError, match=message):
        simulate_batch(
            m.kernel_params(), "polynomial", args["u"], args["dt"], np.array([0.02, 0]), substeps=args["substeps"]
        )


def test_one_compiled_signature_whatever_the_callers_arrays(rng):
    # a strided or read-only input, a read-only (broadcast) start state, one member or many: the kernel
    # sees one array type per argument, so a fresh install compiles each kernel once (every extra
    # signature is another 5-10 s compile; the old code compiled three here)
    from negstiff.models import SEED_LIKE_CUBIC
    from negstiff.models.kernel import _integrate, kernel_flags

    p = SEED_LIKE_CUBIC.kernel_params()
    u = rng.standard_normal((3, 40))
    read_only = u[0].copy()
    read_only.setflags(write=False)
    x0 = np.zeros(2)
    x0.setflags(write=False)
    simulate_batch(p, "polynomial", u[0], 1e-3, x0)  # one member, read-only start state
    simulate_batch(p, "polynomial", read_only, 1e-3, x0)
    simulate_batch(np.column_stack([p, p]), "polynomial", u.T.T[:, ::2], 1e-3, np.zeros((2, 2)), input_index=[0, 2])
    simulate_batch(p, "polynomial", np.asfortranarray(u), 1e-3, x0, input_index=[1])
    # the polynomial's fused kernel (its seven flags, ``kernel``) in one signature, whatever else this process compiled
    flags = [numba.typeof(f) for f in kernel_flags(0, p[:, None], np.zeros((0, 5), np.int64))]
    polynomial = [sig for sig in _integrate.signatures if list(sig[:7]) == flags]
    assert len(polynomial) == 1, polynomial
