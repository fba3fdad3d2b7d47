"""Hammer and free-decay records of a single DOF, written with scipy's DOP853 (not negstiff's simulator), and the
two oscillators they share: a hardening Duffing and the seed-like asymmetric double well. Imported by the tests
as ``from impact_records import ...``."""

import numpy as np
from records import memoised
from scipy.integrate import solve_ivp

from negstiff import Model, from_arrays

MASS = 0.2
"""Moving mass [kg] of both oscillators."""

DUFFING_HZ, DUFFING_ZETA = 12.0, 0.015
_K = MASS * (2 * np.pi * DUFFING_HZ) ** 2
DUFFING = Model(m=MASS, k1=-_K, k2=0.0, k3=3.0e6, c=2 * DUFFING_ZETA * MASS * 2 * np.pi * DUFFING_HZ, k0=0.0)
"""Hardening Duffing: 12 Hz, 1.5 %, k3 = 3e6 N/m^3 (its frequency 4 % up at 5 mm), horizontal (k0 = 0)."""

_ROOTS = (-0.015, 0.004, 0.020)
_P = np.poly(_ROOTS) * 1.5e6
DOUBLE_WELL = Model(m=MASS, k1=-_P[2], k2=_P[1], k3=1.5e6, c=0.5, k0=_P[3])
"""Seed-like asymmetric double well: K(z) = k3 (z + 15 mm)(z - 4 mm)(z - 20 mm), k3 = 1.5e6 N/m^3 (negative
stiffness between the wells, k1 = 420 N/m entering as -k1 z), wells at -15 / +20 mm at 11.24 / 10.31 Hz, damping
1.8 / 1.9 % there (c = 0.5 N s/m)."""


def _force_law(model: Model):
    k0, k1, k2, k3 = model.k0, model.k1, model.k2, model.k3

    def force(z, v):
        return k3 * z**3 + k2 * z**2 - k1 * z + k0 + model.c * v

    return force


def _pulses(hits, peak_n, width_s):
    def pulse(tt):
        return sum(peak_n * np.sin(np.pi * (tt - h) / width_s) * ((tt >= h) & (tt <= h + width_s)) for h in hits)

    return pulse


def _piecewise(rhs, x0, t, hits, width_s, duration):
    """The states at ``t`` of ``x' = rhs(t, x)`` from ``x0``: DOP853 piece by piece (short steps inside each pulse,
    none imposed between), rows of the state."""
    edges = sorted({0.0, float(duration), *hits, *[h + width_s for h in hits]})
    x = np.asarray(x0, float)
    out = np.empty((x.size, t.size))
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        sel = (t >= a) & ((t < b) | (b == edges[-1]))
        inside = any(abs(a - h) < 1e-12 for h in hits)
        sol = solve_ivp(rhs, (a, b), x, method="DOP853", rtol=1e-10, atol=1e-13, dense_output=True,
                        max_step=width_s / 16 if inside else np.inf)  # fmt: skip
        if sel.any():
            out[:, sel] = sol.sol(t[sel])
        x = sol.y[:, -1]
    return out


@memoised
def hammer_record(model, z_rest, fs, hits, peak_n, width_s, duration):
    """(t, force, z, z_dot) of ``model`` at rest at ``z_rest`` hit at the times ``hits`` [s] by half-sine pulses
    of ``peak_n`` [N] lasting ``width_s``: DOP853 piece by piece (short steps inside each pulse, none imposed
    between), noise-free and without offsets (the test adds the lab's)."""
    law = _force_law(model)
    t = np.arange(int(round(duration * fs))) / fs
    pulse = _pulses(hits, peak_n, width_s)

    def rhs(tt, x):
        return [x[1], (pulse(tt) - law(x[0], x[1])) / model.m]

    z, v = _piecewise(rhs, [z_rest, 0.0], t, hits, width_s, duration)
    return t, pulse(t), z, v


@memoised
def decay_record(model, z0, fs, duration, v0=0.0):
    """(t, z, z_dot) of ``model`` released at ``z0`` [m] with ``v0`` [m/s] (DOP853, noise-free)."""
    law = _force_law(model)
    t = np.arange(int(round(duration * fs))) / fs
    sol = solve_ivp(lambda tt, x: [x[1], -law(x[0], x[1]) / model.m], (0.0, t[-1]), [z0, v0], t_eval=t,
                    method="DOP853", rtol=1e-10, atol=1e-13)  # fmt: skip
    return t, sol.y[0], sol.y[1]


def measured_hammer(model, seed, laser_m, fs=1000.0, hits=(0.5, 3.0, 5.5, 8.0)):
    """A hammer's record of ``model`` at rest in its plus well, as a lab measures it: 40 N half-sine hits of 4 ms
    (``hammer_record``), the force channel with a 0.5 N offset and 0.05 N of noise, the laser with ``laser_m``
    of white noise; 10 s at ``fs``, as a ``Measurement``."""
    _, f, z, _ = hammer_record(model, model.equilibria().z_plus, fs, hits, 40.0, 0.004, 10.0)
    rng = np.random.default_rng(seed)
    force = f + 0.5 + 0.05 * rng.standard_normal(f.size)
    zm = z + laser_m * rng.standard_normal(z.size)
    return from_arrays(force, zm, fs, input_name="force", mass=MASS, source="hammer.csv")


def measured_decay(model, z0, seed, duration, laser_m, fs=1000.0):
    """A free decay of ``model`` released from rest at ``z0`` (``decay_record``), the laser with ``laser_m`` of
    white noise, as a ``Measurement`` whose force column is zero."""
    _, z, _ = decay_record(model, z0, fs, duration)
    zm = z + laser_m * np.random.default_rng(seed).standard_normal(z.size)
    return from_arrays(np.zeros(z.size), zm, fs, input_name="force", mass=MASS, source="decay.csv")


def fixture_rhs(device, fixture_mass, fixture_hz, fixture_zeta, force=None, force_dof=2):
    """The equations of motion of ``device`` on a fixture (DOF 1: ``fixture_mass`` on its spring and damper to the
    ground, ``fixture_hz`` and ``fixture_zeta`` of the fixture alone; DOF 2 the device's mass on the element between
    them, the element's force, k0 included, on DOF 2 and oppositely on DOF 1), displacements from the springs'
    loaded rest; ``force(t)`` [N] on DOF ``force_dof``. State (z1, z2, v1, v2)."""
    law = _force_law(device)
    m1, m2 = fixture_mass, device.m
    k_f = m1 * (2 * np.pi * fixture_hz) ** 2
    c_f = 2 * fixture_zeta * np.sqrt(k_f * m1)

    def rhs(tt, x):
        z1, z2, v1, v2 = x
        el = law(z2 - z1, v2 - v1)
        p = 0.0 if force is None else force(tt)
        return [v1, v2, (-k_f * z1 - c_f * v1 + el + (p if force_dof == 1 else 0.0)) / m1,
                (-el + (p if force_dof == 2 else 0.0)) / m2]  # fmt: skip

    return rhs


def fixture_hammer_record(device, fixture, fs, hits, peak_n, width_s, duration, force_dof=2, well="plus"):
    """(t, force, z (2, T)) of ``device`` on ``fixture`` (``fixture_rhs``'s keywords) at rest in its element's
    ``well`` (the fixture's spring unloaded), hit on DOF ``force_dof`` at the times ``hits`` [s] by half-sine pulses
    of ``peak_n`` [N] lasting ``width_s``: DOP853 piece by piece, noise-free and without offsets."""
    eq = device.equilibria()
    r0 = eq.z_plus if well == "plus" else eq.z_minus
    t = np.arange(int(round(duration * fs))) / fs
    pulse = _pulses(hits, peak_n, width_s)
    x = _piecewise(fixture_rhs(device, **fixture, force=pulse, force_dof=force_dof), [0.0, r0, 0.0, 0.0], t, hits,
                   width_s, duration)  # fmt: skip
    return t, pulse(t), x[:2]


def fixture_decay_record(device, fixture, z0, fs, duration):
    """(t, z (2, T)) of ``device`` on ``fixture`` released at rest from ``z0`` = (z1, z2) [m] (DOP853,
    noise-free)."""
    t = np.arange(int(round(duration * fs))) / fs
    sol = solve_ivp(fixture_rhs(device, **fixture), (0.0, t[-1]), [z0[0], z0[1], 0.0, 0.0], t_eval=t,
                    method="DOP853", rtol=1e-10, atol=1e-13)  # fmt: skip
    return t, sol.y[:2]


LIGHT_DUFFING = Model(m=MASS, k1=DUFFING.k1, k2=0.0, k3=DUFFING.k3, c=DUFFING.c / 3, k0=0.0)
"""The Duffing at 0.5 % damping: a decay that rings for seconds (a friction's linear envelope shows over many
cycles)."""


def hammer_record_with_force(model, z_rest, fs, hits, peak_n, width_s, duration, hidden):
    """``hammer_record`` of ``model`` with a force ``hidden(z, z_dot)`` [N] it does not know (an end stop, friction)
    acting on the mass beside its own: (t, force, z, z_dot), DOP853 piece by piece, noise-free."""
    law = _force_law(model)
    t = np.arange(int(round(duration * fs))) / fs
    pulse = _pulses(hits, peak_n, width_s)

    def rhs(tt, x):
        return [x[1], (pulse(tt) - law(x[0], x[1]) - hidden(x[0], x[1])) / model.m]

    z, v = _piecewise(rhs, [z_rest, 0.0], t, hits, width_s, duration)
    return t, pulse(t), z, v


def decay_record_with_force(model, z0, fs, duration, hidden, v0=0.0):
    """``decay_record`` of ``model`` with a force ``hidden(z, z_dot)`` [N] it does not know acting beside its own:
    (t, z, z_dot), released at ``z0`` [m] with ``v0`` [m/s] (DOP853, noise-free)."""
    law = _force_law(model)
    t = np.arange(int(round(duration * fs))) / fs
    sol = solve_ivp(lambda tt, x: [x[1], -(law(x[0], x[1]) + hidden(x[0], x[1])) / model.m], (0.0, t[-1]),
                    [z0, v0], t_eval=t, method="DOP853", rtol=1e-10, atol=1e-13)  # fmt: skip
    return t, sol.y[0], sol.y[1]


def accelerometer_hammer(model, seed, fs=1000.0, hits=(0.5, 3.0, 5.5, 8.0), oversample=20):
    """A hammer's record of ``model`` at rest in its plus well read by an accelerometer through an analyser: the
    acceleration and the force written at ``oversample`` x ``fs`` (DOP853, ``hammer_record``), each low-passed by the
    analyser's anti-alias FIR and decimated to ``fs`` (``scipy.signal.decimate``, zero-phase), the accelerometer's
    zero 0.3 m/s^2 and its noise 0.05 m/s^2, the force's 0.5 N offset and 0.05 N of noise. Returns (force, y_acc,
    the true z at ``fs``)."""
    from scipy import signal

    law = _force_law(model)
    _, f, z, v = hammer_record(model, model.equilibria().z_plus, oversample * fs, hits, 40.0, 0.004, 10.0)
    a = (f - law(z, v)) / model.m
    rng = np.random.default_rng(seed)
    acc = signal.decimate(a, oversample, ftype="fir", zero_phase=True)
    acc = acc + 0.3 + 0.05 * rng.standard_normal(acc.size)
    force = signal.decimate(f, oversample, ftype="fir", zero_phase=True) + 0.5 + 0.05 * rng.standard_normal(acc.size)
    return force, acc, z[::oversample]
