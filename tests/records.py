"""Records written in the tests themselves with numpy and scipy (not with negstiff's rig or simulator), and
what they share: the test utility module (imported as ``from records import ...``)."""

import dataclasses
import functools
import hashlib
import math
import os
from collections.abc import Mapping
from pathlib import Path

import numba
import numpy as np
from scipy.integrate import solve_ivp

from negstiff import Model
from negstiff.cli import main
from negstiff.experiments import silverbox as _silverbox

TRUTH = Model(m=0.2, k1=426.0, k2=-3060.0, k3=7.77e5, c=0.35, c_nl=0.1)
FS = 512.0


class _Unkeyed(Exception):
    """An argument ``memoised`` cannot key by value (a function, an object without fields): the call is not kept."""


def _value_key(x):
    """A hashable key of ``x`` by its value: arrays by their shape, type and bytes, dataclasses (a ``Model``, a law)
    by their fields, containers item by item; a callable or another object raises ``_Unkeyed``."""
    if x is None or isinstance(x, (bool, int, float, str, complex, np.generic)):
        return (type(x).__name__, x)
    if isinstance(x, np.ndarray):
        return ("array", x.shape, x.dtype.str, hashlib.sha1(np.ascontiguousarray(x).tobytes()).hexdigest())
    if isinstance(x, (tuple, list)):
        return (type(x).__name__, tuple(_value_key(i) for i in x))
    if isinstance(x, Mapping):
        return ("mapping", tuple((k, _value_key(v)) for k, v in sorted(x.items())))
    if dataclasses.is_dataclass(x) and not isinstance(x, type):
        return (type(x).__qualname__, tuple((f.name, _value_key(getattr(x, f.name))) for f in dataclasses.fields(x)
                                            if not callable(getattr(x, f.name))))  # fmt: skip
    raise _Unkeyed(type(x).__name__)


def _copied(out):
    return (
        tuple(_copied(o) for o in out)
        if isinstance(out, tuple)
        else (out.copy() if isinstance(out, np.ndarray) else out)
    )


def memoised(writer):
    """Keep a deterministic record writer's output for the test process, keyed by its arguments' values: a record
    asked for again (another module's fixture on the same pytest-xdist worker) is not integrated again (22 s of
    DOP853 a full run repeated, measured). Each caller gets its own copies of the arrays; a call with an argument that
    has no value key (a hidden force given as a function) is not kept."""
    store: dict = {}

    @functools.wraps(writer)
    def wrapper(*args, **kwargs):
        try:
            key = (_value_key(args), _value_key(dict(kwargs)))
        except _Unkeyed:
            return writer(*args, **kwargs)
        if key not in store:
            store[key] = writer(*args, **kwargs)
        return _copied(store[key])

    return wrapper


@memoised
def dop853_record(duration=60.0, rms=8.0, seed=7, start=0.024, fs=FS, rtol=1e-9, model=None, hidden=None):
    """(t, base_acc, z, z_dot) of ``model`` (TRUTH by default) under a multisine base acceleration (2-30 Hz),
    integrated by scipy's DOP853 (``rtol``, 1e-9 by default) from rest at ``start``: a record negstiff's
    simulator did not make. ``hidden(z, v)`` is a force [N] the model does not know (an end stop, friction)."""
    model = TRUTH if model is None else model
    from scipy.integrate import solve_ivp

    rng = np.random.default_rng(seed)
    f = np.arange(2.0, 30.0, 0.25)
    w, ph = 2 * np.pi * f, rng.uniform(0, 2 * np.pi, f.size)
    a = rms * np.sqrt(2.0 / f.size)

    def acc(t):
        return a * np.cos(np.multiply.outer(t, w) + ph).sum(axis=-1)

    # the right-hand side on Python floats (the solver calls it some 5,000 times per second of record): the same
    # operations in the same order as the arrays' (K(z) as Model.restoring_force writes it, the multisine's sum over
    # its lines), so the record is the same to the bit, in a third of the time
    m, c, c_nl = float(model.m), float(model.c), float(model.c_nl)
    k0, k1, k2, k3 = (float(model.k0), float(model.k1), float(model.k2), float(model.k3))
    polynomial = type(model) is Model and not model.extra

    def restoring(z):
        return ((k3 * z + k2) * z - k1) * z + k0 if polynomial else model.restoring_force(z)

    def rhs(t, x):
        z, v = float(x[0]), float(x[1])
        extra = 0.0 if hidden is None else hidden(z, v)
        return [v, (-c * v - c_nl * v * abs(v) - restoring(z) - extra) / m - float(a * np.cos(w * t + ph).sum())]

    t = np.arange(int(duration * fs)) / fs
    sol = solve_ivp(rhs, (0, t[-1]), [start, 0.0], t_eval=t, method="DOP853", rtol=rtol, atol=1e-3 * rtol)
    return t, acc(t), sol.y[0], sol.y[1]


def write_csv(path, cols, meta=None):
    head = "".join(f"# {k}: {v}\n" for k, v in (meta or {}).items()) + ",".join(cols) + "\n"
    rows = np.column_stack(list(cols.values())).tolist()
    line = ",".join(["%.10g"] * len(cols))  # printf's %g is format()'s: the same text, one operation per row (2x)
    path.write_text(head + "\n".join(line % tuple(r) for r in rows) + "\n")
    return path


def write_npz_channels(path, channels, meta=None):
    """Channels under a lab's own names (``V1``, ``V2``), as a DAQ saves them: a foreign file, read with a map."""
    import json

    with open(path, "wb") as fh:
        np.savez(fh, **channels, **({"meta": json.dumps(meta)} if meta else {}))
    return path


def rk4_harmonic(model, amplitudes, f_hz, duration, sim_fs, z0, settle_cycles=100, breathe=0.0, breathe_hz=0.05):
    """(t, base_acc, z) of ``model`` under harmonic base accelerations a sin(2 pi f t), one column per
    amplitude in ``amplitudes``, integrated together by a plain fixed-step RK4 at ``sim_fs`` written here
    (not negstiff's kernel) from rest at ``z0``; the amplitude breathes by ``breathe`` (a fraction) at
    ``breathe_hz``. The first ``settle_cycles`` forcing cycles are dropped."""
    a = np.asarray(amplitudes, float)
    w, h = 2 * np.pi * f_hz, 1.0 / sim_fs
    m = model

    def acc(t):
        return a * (1 + breathe * np.sin(2 * np.pi * breathe_hz * t + 1.0)) * np.sin(w * t)

    def rhs(t, z, v):
        return v, -(m.c * v + m.c_nl * v * np.abs(v) + m.restoring_force(z)) / m.m - acc(t)

    n = int(round((duration + settle_cycles / f_hz) * sim_fs))
    z, v = np.full(a.shape, float(z0)), np.zeros(a.shape)
    if not m.extra:  # the polynomial model: the same RK4, compiled (a 30 s record took 4 s)
        zs = _rk4_harmonic_polynomial(a, w, h, n, float(z0), breathe, 2 * np.pi * breathe_hz,
                                      (m.m, m.k0, m.k1, m.k2, m.k3, m.c, m.c_nl))  # fmt: skip
    else:
        zs = np.empty((n, a.size))
    for i in range(0 if not m.extra else n):
        t = i * h
        zs[i] = z
        k1 = rhs(t, z, v)
        k2 = rhs(t + h / 2, z + h / 2 * k1[0], v + h / 2 * k1[1])
        k3 = rhs(t + h / 2, z + h / 2 * k2[0], v + h / 2 * k2[1])
        k4 = rhs(t + h, z + h * k3[0], v + h * k3[1])
        z = z + h / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
        v = v + h / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
    t = np.arange(n) * h
    keep = t >= settle_cycles / f_hz
    return t[keep] - t[keep][0], acc(t[keep][:, None]), zs[keep]


@numba.njit(cache=True)
def _rk4_harmonic_polynomial(a, w, h, n, z0, breathe, wb, p):  # pragma: no cover (compiled)
    """``rk4_harmonic``'s RK4 for a model whose restoring force is the cubic ((k3 z + k2) z - k1) z + k0, one
    amplitude at a time on floats: the numpy loop, step for step."""
    m, k0, k1, k2, k3, c, c_nl = p
    zs = np.empty((n, a.size))
    for j in range(a.size):
        z, v = z0, 0.0
        for i in range(n):
            t = i * h
            zs[i, j] = z
            a0 = a[j] * (1 + breathe * np.sin(wb * t + 1.0)) * np.sin(w * t)
            tm = t + h / 2
            am = a[j] * (1 + breathe * np.sin(wb * tm + 1.0)) * np.sin(w * tm)
            t1 = t + h
            a1 = a[j] * (1 + breathe * np.sin(wb * t1 + 1.0)) * np.sin(w * t1)
            z1, v1 = z, v
            p1 = -(c * v1 + c_nl * v1 * abs(v1) + (((k3 * z1 + k2) * z1 - k1) * z1 + k0)) / m - a0
            z2, v2 = z + h / 2 * v1, v + h / 2 * p1
            p2 = -(c * v2 + c_nl * v2 * abs(v2) + (((k3 * z2 + k2) * z2 - k1) * z2 + k0)) / m - am
            z3, v3 = z + h / 2 * v2, v + h / 2 * p2
            p3 = -(c * v3 + c_nl * v3 * abs(v3) + (((k3 * z3 + k2) * z3 - k1) * z3 + k0)) / m - am
            z4, v4 = z + h * v3, v + h * p3
            p4 = -(c * v4 + c_nl * v4 * abs(v4) + (((k3 * z4 + k2) * z4 - k1) * z4 + k0)) / m - a1
            z = z + h / 6 * (v1 + 2 * v2 + 2 * v3 + v4)
            v = v + h / 6 * (p1 + 2 * p2 + 2 * p3 + p4)
    return zs


# A horizontal bistable harvester in the Moon-Holmes magneto-elastic form, per unit mass:
# z'' + d z' - a z + b z^3 - theta v = -base_acc, wells at +-L; with a piezo layer, v' = -v / (R C) - kappa z'.
HARVESTER = {"L": 0.010, "f0": 4.0, "delta": 0.25, "gamma": 0.3, "m": 0.01}


def harvester_truth(m=HARVESTER["m"]):
    """The harvester's model in negstiff's terms (K = -k1 z + k3 z^3: k1, k3 > 0, no k2; k0 = 0: no weight to carry)."""
    w0 = 2 * np.pi * HARVESTER["f0"]
    a = w0**2
    return Model(m=m, k1=a * m, k2=0.0, k3=a / HARVESTER["L"] ** 2 * m, c=HARVESTER["delta"] * w0 * m, c_nl=0.0, k0=0.0)


def harvester_record(duration=120.0, fs=2048.0, theta=0.0, kappa=0.0, rc_s=0.05, seed=3, broadband=False):
    """``_harvester_record``'s arrays, written once per process and arguments (the harvester's tests ask for the same
    record from several module fixtures); copies."""
    return tuple(x.copy() for x in _harvester_record(duration, fs, theta, kappa, rc_s, seed, broadband))


@functools.lru_cache(maxsize=4)
def _harvester_record(duration, fs, theta, kappa, rc_s, seed, broadband):
    """(t, base_acc, z, z_dot, v) of the harvester under the Moon-Holmes chaotic forcing (gamma 0.3 at the
    linear frequency f0, delta 0.25: cross-well chaos), or with ``broadband`` a multisine (1-20 Hz, 2.5 m/s^2
    rms: cross-well), integrated by scipy's DOP853 from the plus well; ``theta`` [m/s^2/V] couples a piezo
    voltage ``v`` (v' = -v / rc_s - kappa z'), 0 by default."""
    from scipy.integrate import solve_ivp

    L, f0 = HARVESTER["L"], HARVESTER["f0"]
    w0 = 2 * np.pi * f0
    a, b, d = w0**2, w0**2 / L**2, HARVESTER["delta"] * w0
    amp = HARVESTER["gamma"] * L * w0**2
    rng = np.random.default_rng(seed)
    phase = rng.uniform(0, 2 * np.pi)

    lines = np.arange(1.0, 20.0, 0.125)
    phases = rng.uniform(0, 2 * np.pi, lines.size)

    def acc(t):
        if broadband:
            return 2.5 * np.sqrt(2 / lines.size) * np.cos(np.multiply.outer(t, 2 * np.pi * lines) + phases).sum(-1)
        return amp * np.cos(w0 * t + phase)

    # the right-hand side on Python floats, the same operations in the same order as on numpy's scalars (the records
    # equal to the bit, hashed over the tests' three configurations): DOP853 calls it twelve times a step
    a_, b_, d_, amp_, w0_, ph_ = (float(x) for x in (a, b, d, amp, w0, phase))

    def rhs(t, x):
        z, v, volt = x.tolist()
        drive = float(acc(t)) if broadband else amp_ * math.cos(w0_ * t + ph_)
        return [v, -d_ * v + a_ * z - b_ * z**3 + theta * volt - drive, -volt / rc_s - kappa * v]

    t = np.arange(int(duration * fs)) / fs
    sol = solve_ivp(rhs, (0, t[-1]), [L, 0.0, 0.0], t_eval=t, method="DOP853", rtol=1e-10, atol=1e-13)
    return t, acc(t), sol.y[0], sol.y[1], sol.y[2]


def rk4_random_records(
    seeds,
    duration=20.0,
    rms=8.0,
    band=(2.0, 30.0),
    oversample=8,
    settle=5.0,
    laser=3e-6,
    table_noise=0.005,
    start=0.023,
    model=None,
    fs=FS,
):
    """Records of ``model`` (TRUTH by default) as another lab's simulator writes them, one per seed: a plain
    numpy fixed-step RK4 at ``oversample`` x fs, vectorised across the records, its base acceleration
    band-limited Gaussian noise (``band``, ``rms`` m/s^2) made by FFT at the fine rate and linear between
    the fine steps (the midpoint stages see the average); ``settle`` s dropped; sampled at fs with white
    noise on z (``laser`` m) and on the table's accelerometer (``table_noise`` m/s^2).
    Returns [(base_acc, z)], the measured columns."""
    model = TRUTH if model is None else model
    h = 1.0 / (fs * oversample)
    n = int(round((duration + settle) * fs)) * oversample
    rngs = [np.random.default_rng(s) for s in seeds]
    acc = []
    for rng in rngs:
        spec = np.fft.rfft(rng.standard_normal(n))
        f = np.fft.rfftfreq(n, h)
        spec[(f < band[0]) | (f > band[1])] = 0
        a = np.fft.irfft(spec, n)
        acc.append(a * rms / a.std())
    acc = np.array(acc)

    z, v = np.full(len(seeds), start), np.zeros(len(seeds))
    if not model.extra:  # the polynomial model: the same RK4, compiled (8x faster; a 30 s record took 11 s)
        Z = _rk4_polynomial(acc, h, z, model.m, model.k0, model.k1, model.k2, model.k3, model.c, model.c_nl)
    else:
        Z = _rk4_numpy(acc, h, z, v, model)
    k0 = int(round(settle * fs))
    out = []
    for b, rng in enumerate(rngs):
        zb, ub = Z[b, ::oversample][k0:], acc[b, ::oversample][k0:]
        out.append((ub + table_noise * rng.standard_normal(ub.size), zb + laser * rng.standard_normal(zb.size)))
    return out


@numba.njit(cache=True)
def _rk4_polynomial(acc, h, z0, m, k0, k1, k2, k3, c, c_nl):  # pragma: no cover (compiled)
    """``rk4_random_records``' RK4 for a model whose restoring force is the cubic ((k3 z + k2) z - k1) z + k0,
    record by record on floats: the numpy loop below, step for step."""
    S, n = acc.shape
    Z = np.empty((S, n))
    for b in range(S):
        z, v = z0[b], 0.0
        for i in range(n):
            Z[b, i] = z
            if i == n - 1:
                break
            a0, a1 = acc[b, i], acc[b, i + 1]
            am = 0.5 * (a0 + a1)
            z1, v1 = z, v
            p1 = (-c * v1 - c_nl * v1 * abs(v1) - (((k3 * z1 + k2) * z1 - k1) * z1 + k0)) / m - a0
            z2, v2 = z + h / 2 * v1, v + h / 2 * p1
            p2 = (-c * v2 - c_nl * v2 * abs(v2) - (((k3 * z2 + k2) * z2 - k1) * z2 + k0)) / m - am
            z3, v3 = z + h / 2 * v2, v + h / 2 * p2
            p3 = (-c * v3 - c_nl * v3 * abs(v3) - (((k3 * z3 + k2) * z3 - k1) * z3 + k0)) / m - am
            z4, v4 = z + h * v3, v + h * p3
            p4 = (-c * v4 - c_nl * v4 * abs(v4) - (((k3 * z4 + k2) * z4 - k1) * z4 + k0)) / m - a1
            z = z + h / 6 * (v1 + 2 * v2 + 2 * v3 + v4)
            v = v + h / 6 * (p1 + 2 * p2 + 2 * p3 + p4)
    return Z


def _rk4_numpy(acc, h, z, v, model):
    """``rk4_random_records``' RK4 for any model (its extra terms through ``restoring_force``), vectorised across
    the records."""

    def f(z, v, a):
        return v, (-model.c * v - model.c_nl * v * np.abs(v) - model.restoring_force(z)) / model.m - a

    n = acc.shape[1]
    Z = np.empty_like(acc)
    for i in range(n):
        Z[:, i] = z
        if i == n - 1:
            break
        a0, a1 = acc[:, i], acc[:, i + 1]
        am = 0.5 * (a0 + a1)
        k1 = f(z, v, a0)
        k2 = f(z + h / 2 * k1[0], v + h / 2 * k1[1], am)
        k3 = f(z + h / 2 * k2[0], v + h / 2 * k2[1], am)
        k4 = f(z + h * k3[0], v + h * k3[1], a1)
        z = z + h / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
        v = v + h / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
    return Z


# the Silverbox benchmark's split and protocol, from the one Silverbox module (experiments/silverbox.py)
SILVERBOX_TRAIN, SILVERBOX_TEST, SILVERBOX_ARROW = _silverbox.TRAIN, _silverbox.TEST, _silverbox.ARROW


def silverbox_prediction_mv(model, m, part) -> float:
    """Free-run rms error [mV] over ``part`` of the Silverbox record (the benchmark's protocol:
    ``experiments.silverbox.prediction_error_mv``)."""
    return _silverbox.prediction_error_mv(model, m, part)


FIXTURE = {"m": 1.0, "f_hz": 25.0, "zeta": 0.02}
"""The acceptance's fixture: 1 kg on a 25 Hz, 2 % spring to the table (issue "Beyond one degree of freedom")."""


def fixture_rk4_step(device, fixture=FIXTURE, hidden=None):
    """One classical RK4 step, on Python floats, of ``device`` on the sprung fixture (DOF 1 the fixture, DOF 2 the
    device's mass; the element's force, k0 included, on DOF 2 and oppositely on DOF 1; ``hidden(r, r')`` a force
    beside it): ``step(z1, z2, v1, v2, h, a0, am, a1)`` -> the state after h under the base acceleration a0, am,
    a1 at the step's start, middle and end. Written here, not negstiff's kernel."""
    m1, m2 = fixture["m"], device.m
    k_f = m1 * (2 * np.pi * fixture["f_hz"]) ** 2
    c_f = 2 * fixture["zeta"] * np.sqrt(k_f * m1)
    k0, k1, k2, k3, c, cn = device.k0, device.k1, device.k2, device.k3, device.c, device.c_nl

    def rhs(z1, z2, v1, v2, ab):
        r, vr = z2 - z1, v2 - v1
        force = ((k3 * r + k2) * r - k1) * r + k0 + c * vr + cn * vr * abs(vr)
        if hidden is not None:
            force += hidden(r, vr)
        return (-k_f * z1 - c_f * v1 + force) / m1 - ab, -force / m2 - ab

    def step(z1, z2, v1, v2, h, a0, am, a1):
        p1, q1 = rhs(z1, z2, v1, v2, a0)
        s1, s2 = v1 + 0.5 * h * p1, v2 + 0.5 * h * q1
        p2, q2 = rhs(z1 + 0.5 * h * v1, z2 + 0.5 * h * v2, s1, s2, am)
        t1, t2 = v1 + 0.5 * h * p2, v2 + 0.5 * h * q2
        p3, q3 = rhs(z1 + 0.5 * h * s1, z2 + 0.5 * h * s2, t1, t2, am)
        w1, w2 = v1 + h * p3, v2 + h * q3
        p4, q4 = rhs(z1 + h * t1, z2 + h * t2, w1, w2, a1)
        return (z1 + h / 6 * (v1 + 2 * s1 + 2 * t1 + w1), z2 + h / 6 * (v2 + 2 * s2 + 2 * t2 + w2),
                v1 + h / 6 * (p1 + 2 * p2 + 2 * p3 + p4), v2 + h / 6 * (q1 + 2 * q2 + 2 * q3 + q4))  # fmt: skip

    return step


def _fixture_params(device, fixture) -> tuple[float, ...]:
    """The compiled steps' parameters (``_fixture_step``): the fixture's mass, spring and damper, the device's mass
    and polynomial element."""
    m1 = fixture["m"]
    k_f = m1 * (2 * np.pi * fixture["f_hz"]) ** 2
    return (m1, k_f, 2 * fixture["zeta"] * np.sqrt(k_f * m1), device.m, device.k0, device.k1, device.k2, device.k3,
            device.c, device.c_nl)  # fmt: skip


@numba.njit(inline="always")
def _fixture_step(z1, z2, v1, v2, h, a0, am, a1, p, hidden=None):  # pragma: no cover (compiled)
    """``fixture_rk4_step``'s step, operation for operation, compiled: the state after h under the base acceleration
    a0, am, a1 at the step's start, middle and end; ``hidden(r, r')`` a compiled force beside the element's (None:
    none, its branch pruned)."""
    m1, k_f, c_f, m2, k0, k1, k2, k3, c, cn = p
    # stage 1
    r, vr = z2 - z1, v2 - v1
    f = ((k3 * r + k2) * r - k1) * r + k0 + c * vr + cn * vr * abs(vr)
    if hidden is not None:
        f += hidden(r, vr)
    p1, q1 = (-k_f * z1 - c_f * v1 + f) / m1 - a0, -f / m2 - a0
    s1, s2 = v1 + 0.5 * h * p1, v2 + 0.5 * h * q1
    # stage 2
    y1, y2 = z1 + 0.5 * h * v1, z2 + 0.5 * h * v2
    r, vr = y2 - y1, s2 - s1
    f = ((k3 * r + k2) * r - k1) * r + k0 + c * vr + cn * vr * abs(vr)
    if hidden is not None:
        f += hidden(r, vr)
    p2, q2 = (-k_f * y1 - c_f * s1 + f) / m1 - am, -f / m2 - am
    t1, t2 = v1 + 0.5 * h * p2, v2 + 0.5 * h * q2
    # stage 3
    y1, y2 = z1 + 0.5 * h * s1, z2 + 0.5 * h * s2
    r, vr = y2 - y1, t2 - t1
    f = ((k3 * r + k2) * r - k1) * r + k0 + c * vr + cn * vr * abs(vr)
    if hidden is not None:
        f += hidden(r, vr)
    p3, q3 = (-k_f * y1 - c_f * t1 + f) / m1 - am, -f / m2 - am
    w1, w2 = v1 + h * p3, v2 + h * q3
    # stage 4
    y1, y2 = z1 + h * t1, z2 + h * t2
    r, vr = y2 - y1, w2 - w1
    f = ((k3 * r + k2) * r - k1) * r + k0 + c * vr + cn * vr * abs(vr)
    if hidden is not None:
        f += hidden(r, vr)
    p4, q4 = (-k_f * y1 - c_f * w1 + f) / m1 - a1, -f / m2 - a1
    return (
        z1 + h / 6 * (v1 + 2 * s1 + 2 * t1 + w1),
        z2 + h / 6 * (v2 + 2 * s2 + 2 * t2 + w2),
        v1 + h / 6 * (p1 + 2 * p2 + 2 * p3 + p4),
        v2 + h / 6 * (q1 + 2 * q2 + 2 * q3 + q4),
    )


@numba.njit(cache=True)
def _rk4_fixture_polynomial(acc, h, oversample, z2, p, hidden=None):  # pragma: no cover (compiled)
    """``rk4_fixture_record``'s RK4 (``_fixture_step``) compiled; ``hidden`` a compiled force beside the element's."""
    n = acc.size
    out = np.empty((4, n // oversample))  # z1, z2, v1, v2
    z1, v1, v2 = 0.0, 0.0, 0.0
    for i in range(n):
        if i % oversample == 0:
            out[0, i // oversample], out[1, i // oversample] = z1, z2
            out[2, i // oversample], out[3, i // oversample] = v1, v2
        a0 = acc[i]
        a1 = acc[i + 1] if i + 1 < n else a0
        z1, z2, v1, v2 = _fixture_step(z1, z2, v1, v2, h, a0, 0.5 * (a0 + a1), a1, p, hidden)
    return out


@numba.njit(cache=True)
def _stepped_sweep_polynomial(p, amps, f_hz, state, periods, steps):  # pragma: no cover (compiled)
    """``_fixture_step`` under b'' = A sin(2 pi f t), A stepped through ``amps`` each going on from the last state:
    per amplitude (spread of r = z2 - z1 over the last 8 periods at phase 0, min r and max r over the last period)
    and the state after each amplitude."""
    h = 1.0 / (f_hz * steps)
    sines = np.sin(np.pi * np.arange(2 * steps + 1) / steps)  # at every half step of a period
    z1, z2, v1, v2 = state[0], state[1], state[2], state[3]
    rows = np.empty((amps.size, 3))
    states = np.empty((amps.size, 4))
    for j in range(amps.size):
        A = amps[j]
        lo, hi, sec_lo, sec_hi = np.inf, -np.inf, np.inf, -np.inf
        for period in range(periods):
            for k in range(steps):
                z1, z2, v1, v2 = _fixture_step(z1, z2, v1, v2, h, A * sines[2 * k], A * sines[2 * k + 1],
                                               A * sines[2 * k + 2], p)  # fmt: skip
                if period == periods - 1:
                    lo, hi = min(lo, z2 - z1), max(hi, z2 - z1)
            if period >= periods - 8:
                sec_lo, sec_hi = min(sec_lo, z2 - z1), max(sec_hi, z2 - z1)
        rows[j, 0], rows[j, 1], rows[j, 2] = sec_hi - sec_lo, lo, hi
        states[j, 0], states[j, 1], states[j, 2], states[j, 3] = z1, z2, v1, v2
    return rows, states


def stepped_sweep(amps, f_hz, state, device=None, fixture=FIXTURE, periods=120, steps=128):
    """``device`` (TRUTH by default) on the sprung fixture under b'' = A sin(2 pi f t), A stepped through ``amps``
    (each step going on from the last state, as a shaker test does), by ``fixture_rk4_step``'s plain RK4 compiled
    (``steps`` a period; in Python floats it took 4 s a sweep): per amplitude (spread of r = z2 - z1 over the last 8
    periods at phase 0, min r, max r over the last period, the state after it)."""
    p = _fixture_params(TRUTH if device is None else device, fixture)
    rows, states = _stepped_sweep_polynomial(p, np.asarray(amps, float), float(f_hz), np.asarray(state, float),
                                             int(periods), int(steps))  # fmt: skip
    return [(float(r[0]), float(r[1]), float(r[2]), tuple(map(float, s))) for r, s in zip(rows, states, strict=True)]


def rk4_fixture_record(duration=60.0, rms=12.0, band=(2.0, 40.0), seed=1, oversample=8, settle=5.0, noise=1e-6,
                       device=None, fixture=FIXTURE, fs=FS, hidden=None, velocity=False,
                       compile_hidden=False, envelope=None):  # fmt: skip
    """(base_acc, z (2, T)) of ``device`` (TRUTH by default) on a sprung fixture, as another lab's code writes it: a
    plain fixed-step RK4 on Python floats at ``oversample`` x fs (not negstiff's kernel), the base acceleration
    band-limited Gaussian noise made by FFT at the fine rate (linear between fine steps), ``settle`` s dropped,
    sampled at fs with white noise ``noise`` [m] on both displacements. DOF 1 the fixture (its spring and damper to
    the table), DOF 2 the device's mass on the element between them; z relative to the table, from the springs'
    loaded rest (the element's force, k0 included, acts on DOF 2 and oppositely on DOF 1). ``hidden(r, r')``: a
    force [N] the element has beside its model (friction), acting like the element's. ``velocity``: also the
    integrator's own velocities (2, T) relative to the table, noise-free (a model without a hidden force).
    ``compile_hidden``: the hidden force compiled with the steps (``numba.njit(hidden)``; a 120 s record 10 s -> 0.5
    s), the same record to the last bit where the force's operations compile to the same (a tanh: hashed equal; a
    power r**5 is libm's pow on Python floats, products compiled, and a chaotic record's realisation moves).
    ``envelope(t)``: the base acceleration's level over time (t [s] from the start, settle included; a burst test)."""
    dev = TRUTH if device is None else device
    h = 1.0 / (fs * oversample)
    n = int(round((duration + settle) * fs)) * oversample
    rng = np.random.default_rng(seed)
    spec = np.fft.rfft(rng.standard_normal(n))
    f = np.fft.rfftfreq(n, h)
    spec[(f < band[0]) | (f > band[1])] = 0
    a = np.fft.irfft(spec, n)
    a = a * rms / a.std()
    if envelope is not None:
        a = a * envelope(np.arange(n) * h)
    acc = a.tolist()
    k0, k1, k2, k3 = dev.k0, dev.k1, dev.k2, dev.k3

    # start at rest in the positive well of the element (F(r) = 0, the fixture's spring unloaded)
    roots = np.roots([k3, k2, -k1, k0])
    z2 = float(max(roots[np.abs(roots.imag) < 1e-9].real))
    z1, v1, v2 = 0.0, 0.0, 0.0
    compiled = hidden is None or compile_hidden
    if compiled:  # the same steps, compiled (a 300 s record took 16 s)
        out = _rk4_fixture_polynomial(np.asarray(acc), h, oversample, z2, _fixture_params(dev, fixture),
                                      None if hidden is None else numba.njit(hidden))  # fmt: skip
    elif velocity:
        raise ValueError("velocity=True: the compiled route only (no hidden force, or compile_hidden)")
    else:
        out = np.empty((2, n // oversample))
        step = fixture_rk4_step(dev, fixture, hidden)
    velocities = out[2:] if compiled else None
    out = out[:2]
    for i in range(0 if compiled else n):
        if i % oversample == 0:
            out[0, i // oversample], out[1, i // oversample] = z1, z2
        a0 = acc[i]
        a1 = acc[i + 1] if i + 1 < n else a0
        z1, z2, v1, v2 = step(z1, z2, v1, v2, h, a0, 0.5 * (a0 + a1), a1)
    k = int(round(settle * fs))
    u = np.asarray(acc[::oversample])[k:]
    z = out[:, k:]
    z = z + noise * rng.standard_normal(z.shape)
    return (u, z, velocities[:, k:]) if velocity else (u, z)


# --- a refusal as the contract states it (the probes' files share it) ----------------------------------
def snapshot(d: Path) -> dict:
    """Every regular file under ``d`` and its SHA-256."""
    return {str(p.relative_to(d)): hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(d.rglob("*"))
            if p.is_file() and not p.is_symlink()}  # fmt: skip


def refused(lab: Path, capsys, argv, outputs=()) -> str:
    """A command line the CLI refuses as the contract says: exit 2, one line naming an error, no traceback, no
    output written, every file under ``lab`` unchanged and no temporary file left behind. Returns the line."""
    before = snapshot(lab)
    try:
        rc = main([str(a) for a in argv])
    except SystemExit as exc:  # argparse's errors
        rc = exc.code
    err = capsys.readouterr().err
    lines = [x for x in err.strip().splitlines() if x.strip()]
    assert rc == 2, f"exit {rc} for {argv}: {err}"
    assert len(lines) == 1 and "error" in lines[0] and "Traceback" not in err, err
    for o in outputs:
        assert not os.path.exists(o), f"{o} was written"
    assert snapshot(lab) == before, "an input was modified"
    assert not [p for p in lab.rglob("*.part")], "a temporary file was left behind"
    return lines[0]


CHAIN_FIXTURE = ((1.0, 25.0, 0.02), (0.5, 40.0, 0.02))
"""The chain's linear DOFs below the device, from the ground up: (mass [kg], its frequency on its own spring
alone [Hz], damping ratio) of each."""


def _chain_rhs(n_dof, device, input_kind, excitation, force_dof):
    """The equations of motion of a chain of ``n_dof`` DOFs, written here with numpy: DOFs 1 .. N-1 the linear
    ``CHAIN_FIXTURE`` (each on its spring and damper to the DOF below, DOF 1 to the ground), DOF N the device's mass
    on the element ``device`` (a polynomial law, k0 included) between DOF N - 1 (the base for N = 1) and N;
    ``excitation(t)`` the base's acceleration (z relative to the base) or a force on DOF ``force_dof``."""
    lin = CHAIN_FIXTURE[: n_dof - 1]
    m = np.array([f[0] for f in lin] + [device.m])
    k = np.array([f[0] * (2 * np.pi * f[1]) ** 2 for f in lin])
    c = np.array([2 * f[2] * np.sqrt(kk * f[0]) for f, kk in zip(lin, k, strict=True)])

    k0, k1, k2, k3, cd, cn = device.k0, device.k1, device.k2, device.k3, device.c, device.c_nl
    ks, cs, ms = k.tolist(), c.tolist(), m.tolist()
    base = input_kind == "base_acc"

    def rhs(t, x):  # on Python floats: a chain of a few DOFs, called ~10^5 times a record
        xs = x.tolist()
        z, v = xs[:n_dof], xs[n_dof:]
        links = []  # the force of the link below each DOF, on it (DOF 1's: the ground's)
        zb = vb = 0.0
        for j in range(n_dof):
            r, vr = z[j] - zb, v[j] - vb
            if j < n_dof - 1:
                links.append(ks[j] * r + cs[j] * vr)
            else:
                links.append(((k3 * r + k2) * r - k1) * r + k0 + cd * vr + cn * vr * abs(vr))
            zb, vb = z[j], v[j]
        e = excitation(t)
        acc = []
        for j in range(n_dof):
            f = -links[j] + (links[j + 1] if j + 1 < n_dof else 0.0)  # the link above pulls it up
            a = f / ms[j]
            if base:
                a -= e
            elif j == force_dof - 1:
                a += e / ms[j]
            acc.append(a)
        return v + acc

    return rhs, m


@memoised
def chain_record(n_dof, device, kind, fs, duration, seed=1, level=8.0, release_m=0.006, hits=(0.5, 3.0, 5.5, 8.0)):
    """(input, z (N, T), masses, force_dof) of the chain of ``_chain_rhs`` as scipy's DOP853 writes it (not negstiff's
    simulator), from rest with the element unloaded: ``kind`` ``"base"`` (band-limited random base acceleration of
    ``level`` m/s^2 rms, 64 sines over 3-50 Hz of random phases), ``"force"`` (the same on DOF 1, ``level`` times
    the chain's mass in N rms), ``"hammer"`` (40 N half-sine hits of 4 ms on the device's mass, DOF N, at ``hits``
    s) or ``"decay"`` (the device's mass released at rest ``release_m`` from its rest, the rest of the chain at
    rest). Noise-free."""
    rng = np.random.default_rng(seed)
    f_j = np.linspace(3.0, 50.0, 64)
    phase = rng.uniform(0.0, 2 * np.pi, f_j.size)
    amp = np.full(f_j.size, np.sqrt(2.0 / f_j.size))
    w = 2 * np.pi * f_j
    width = 0.004
    t = np.arange(int(round(duration * fs))) / fs
    force_dof = None
    if kind in ("base", "force"):
        scale = level if kind == "base" else level * sum(f[0] for f in CHAIN_FIXTURE[: n_dof - 1]) + level * device.m

        def excitation(tt):
            return scale * float(np.dot(amp, np.sin(w * tt + phase)))

        u = scale * (amp[None, :] * np.sin(np.outer(t, w) + phase[None, :])).sum(axis=1)
        force_dof = 1 if kind == "force" else None
    elif kind == "hammer":

        def excitation(tt):
            for h in hits:
                if h <= tt < h + width:
                    return 40.0 * np.sin(np.pi * (tt - h) / width)
            return 0.0

        u = np.array([excitation(tt) for tt in t])
        force_dof = n_dof
    else:

        def excitation(tt):
            return 0.0

        u = np.zeros(t.size)
    rhs, m = _chain_rhs(n_dof, device, "base_acc" if kind == "base" else "force", excitation, force_dof or 1)
    x0 = np.zeros(2 * n_dof)
    if kind == "decay":
        x0[n_dof - 1] = release_m
    edges = sorted({0.0, float(t[-1]), *(x for h in hits if kind == "hammer" for x in (h, h + width) if x < t[-1])})
    z = np.empty((n_dof, t.size))
    for a, b in zip(edges[:-1], edges[1:], strict=True):  # piece by piece: short steps inside a pulse only
        sel = (t >= a) & ((t <= b) if b == edges[-1] else (t < b))
        te = t[sel] if sel.any() and t[sel][-1] == b else np.append(t[sel], b)
        pulse = kind == "hammer" and any(h <= a < h + width for h in hits)
        sol = solve_ivp(rhs, (a, b), x0, t_eval=te, method="DOP853", rtol=1e-8, atol=1e-11,
                        max_step=width / 8 if pulse else np.inf)  # fmt: skip
        z[:, sel] = sol.y[:n_dof, : int(sel.sum())]
        x0 = sol.y[:, -1]
    return u, z, tuple(float(x) for x in m), force_dof


def assert_result_answers_alike(est):
    """A fitted identification's result answers as every result does (``estimators.results``): ``validation`` a
    read-only bunch (``validation.rms_percent``), ``refinement`` None or a bunch, ``summary()`` one line that the
    estimator's repr shows, the JSON round trip through ``from_json`` exact."""
    res = est.result_
    # the held-out headline: an identification's one free run over the tail; the discrepancy workflow's on the device
    # runs none (cross-well motion diverges), its gap is the restarted windows' median
    key = "median_window_percent" if res.layout == "workflow" else "rms_percent"
    assert getattr(res.validation, key) == res.validation[key] and res.validation[key] > 0
    with np.testing.assert_raises(TypeError):
        res.validation[key] = 0.0  # read-only
    assert res.refinement is None or res.refinement.applied in (True, False)
    line = res.summary()
    assert isinstance(line, str) and "\n" not in line and line in repr(est), (line, repr(est))
    assert type(res).from_json(res.to_json()).to_json() == res.to_json()
    assert isinstance(res.warnings, tuple) and res.method in ("nsi", "sindy", "discrepancy")
    # one result class for any structure: the same class at every N and linear part, read back from its JSON as such,
    # the identified system's DOFs and the element's place read alike
    from negstiff import Identification

    assert type(res) is Identification and type(Identification.from_json(res.to_json())) is Identification
    assert res.linear_part in ("none", "physical", "state_space")
    assert res.dofs == res.to_json().get("dofs", 1) and len(res.element_at) == 2
    assert (res.linear_part == "none") == (res.element_at == (0, 1) and res.dofs == 1)
