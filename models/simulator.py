"""Fixed-step simulator of the equation of motion, for one system or a batch of thousands.

    z'' = -(D(z') + K(z) + extra(z, z')) / m + w(t),   w = -b''(t) (base excitation) or f(t)/m (force)

Classical fourth-order Runge-Kutta with ``substeps`` steps per sample interval. The sampled input is
linearly interpolated between samples, the one input convention of the whole suite (the virtual rig,
the likelihoods and the identification methods all assume it; holding the input constant per sample
instead costs about 4 % error, ``shared/docs/ecosystem.md`` section 5).

The kernel is compiled by numba with time in the outer loop and the batch in the inner loop, which
lets the compiler vectorise across batch members (measured in ``experiments/benchmarks.py``). Batches
are split over threads (the kernel releases the GIL). Every batch member may read its own input row
(``input_index``), so multiple-shooting windows of a record and MCMC walkers go in one call.

A member that leaves the admissible range (``|z| > z_limit``, a non-finite state, or, for the
geometric device, a displacement the rods cannot reach) is stopped; its remaining samples are NaN and
``SimulationResult.diverged`` says where and why.
"""

from __future__ import annotations

import functools
import math
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numba
import numpy as np
from scipy import signal

from .equation import (
    COULOMB_VELOCITY_SCALE,
    N_PARAMS,
    P_C,
    P_CNL,
    P_COULOMB,
    P_CUBIC_DAMP,
    P_CUBIC_STIFF,
    P_M,
    P_QUAD_STIFF,
    P_QUARTIC,
    P_QUINTIC,
    P_STOP_K,
    P_STOP_Z,
)

KIND_POLYNOMIAL, KIND_DEVICE = 0, 1
KINDS = {"polynomial": KIND_POLYNOMIAL, "device": KIND_DEVICE}
STATUS_OK, STATUS_DIVERGED, STATUS_GEOMETRY = 0, 1, 2
STATUS_TEXT = {
    STATUS_DIVERGED: "diverged (|z| or |z_dot| beyond its limit, or non-finite)",
    STATUS_GEOMETRY: "left the device's stroke (the rods cannot reach that z)",
}
DEFAULT_SUBSTEPS = 2
DEFAULT_Z_LIMIT = 1.0
"""Displacement [m] beyond which a simulation is declared diverged."""
DEFAULT_V_LIMIT = 100.0
"""Speed [m/s] beyond which a simulation is declared diverged. It also catches the spurious bounded
orbits RK4 can settle into when a growing response is no longer resolved by the step (omega h ~ 1)."""


_JIT = {"cache": True, "nogil": True, "error_model": "numpy"}  # numpy error model: no zero-division
# branches in the loop, which is what lets LLVM vectorise over the batch (4x measured here).


@numba.njit(inline="always", **_JIT)
def _force(kind, coulomb, z, v, q):
    """Total non-inertial force D + K + extra [N] for one member's parameter tuple ``q``.

    polynomial: q[1..4] = k0, k1, k2, k3; device: q[1] = k_f, q[2] = L cos(alpha), q[3] = sin(alpha),
    q[4] = D0, q[5] = g (exact rod-frame geometry; NaN where the rods cannot reach z). ``kind`` and
    ``coulomb`` are compile-time constants in each specialised kernel, so their branches vanish.
    """
    if kind == KIND_POLYNOMIAL:
        k = ((q[4] * z + q[3]) * z - q[2]) * z + q[1]
    else:
        bb = q[2] - z * q[3]
        r2 = bb * bb - z * z
        r = math.sqrt(r2) if (r2 > 0.0 and bb > 0.0) else math.nan
        k = 2.0 * q[1] * (r - bb + q[4]) * (q[3] - (bb * q[3] + z) / r) + q[P_M] * q[5]
    k += z * z * (q[P_QUAD_STIFF] + z * (q[P_CUBIC_STIFF] + z * (q[P_QUARTIC] + z * q[P_QUINTIC])))
    # one-sided stop (branch-free): k_s max(z - z_s, 0) for z_s > 0, k_s min(z - z_s, 0) for z_s < 0
    dz = z - q[P_STOP_Z]
    k += 0.5 * q[P_STOP_K] * (dz + math.copysign(1.0, q[P_STOP_Z]) * abs(dz))
    d = v * (q[P_C] + q[P_CNL] * abs(v) + q[P_CUBIC_DAMP] * v * v)
    if coulomb:
        d += q[P_COULOMB] * math.tanh(v / COULOMB_VELOCITY_SCALE)
    return k + d


@numba.njit(inline="always", **_JIT)
def _member(p, b, kind):
    """Parameter tuple of member b, with the device's angle rows turned into L cos(a), sin(a)."""
    q = (
        p[0, b],
        p[1, b],
        p[2, b],
        p[3, b],
        p[4, b],
        p[5, b],
        p[6, b],
        p[7, b],
        p[8, b],
        p[9, b],
        p[10, b],
        p[11, b],
        p[12, b],
        p[13, b],
        p[14, b],
        p[15, b],
        p[16, b],
    )
    if kind == KIND_DEVICE:
        q = (q[0], q[1], q[2] * math.cos(q[3]), math.sin(q[3])) + q[4:]
    return q


@numba.njit(inline="always", **_JIT)
def _integrate(
    kind, coulomb, p, gain, u, uidx, dt, nsub, z0, v0, z_limit, v_limit, out_z, out_v, store_v, status, fail_step
):
    """RK4 over the N sample intervals of each member's input row ``u[uidx[b]]``; outputs time-major.

    ``out_z.shape[0]`` is N + 1 output samples. The input row holds either the N + 1 samples (linearly
    interpolated inside each interval) or, when it has 2 ``nsub`` N + 1 columns, the input at every
    Runge-Kutta stage time (``stage_input``), read as it is."""
    nb = p.shape[1]
    n = out_z.shape[0]
    staged = u.shape[1] != n
    h = dt / nsub
    z = z0.copy()
    v = v0.copy()
    ua = np.empty(nb)
    ub = np.empty(nb)
    wa = np.empty(nb)
    wm = np.empty(nb)
    wb = np.empty(nb)
    alive = np.ones(nb, dtype=np.bool_)
    for b in range(nb):
        out_z[0, b] = z[b]
        if store_v:
            out_v[0, b] = v[b]
    for k in range(n - 1):
        if not staged:
            for b in range(nb):  # gather the input once per sample, outside the vectorised loop
                ua[b] = gain[b] * u[uidx[b], k]
                ub[b] = gain[b] * u[uidx[b], k + 1]
        for j in range(nsub):
            if staged:  # the input at the step's start, midpoint and end
                c = 2 * (k * nsub + j)
                for b in range(nb):
                    wa[b] = gain[b] * u[uidx[b], c]
                    wm[b] = gain[b] * u[uidx[b], c + 1]
                    wb[b] = gain[b] * u[uidx[b], c + 2]
            else:
                fa = j / nsub
                fm = (j + 0.5) / nsub
                fb = (j + 1.0) / nsub
                for b in range(nb):
                    du = ub[b] - ua[b]
                    wa[b] = ua[b] + fa * du
                    wm[b] = ua[b] + fm * du
                    wb[b] = ua[b] + fb * du
            for b in range(nb):
                q = _member(p, b, kind)
                im = 1.0 / q[P_M]
                zb = z[b]
                vb = v[b]
                a1 = wa[b] - _force(kind, coulomb, zb, vb, q) * im
                z2 = zb + 0.5 * h * vb
                v2 = vb + 0.5 * h * a1
                a2 = wm[b] - _force(kind, coulomb, z2, v2, q) * im
                z3 = zb + 0.5 * h * v2
                v3 = vb + 0.5 * h * a2
                a3 = wm[b] - _force(kind, coulomb, z3, v3, q) * im
                z4 = zb + h * v3
                v4 = vb + h * a3
                a4 = wb[b] - _force(kind, coulomb, z4, v4, q) * im
                z[b] = zb + h / 6.0 * (vb + 2.0 * v2 + 2.0 * v3 + v4)
                v[b] = vb + h / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4)
        for b in range(nb):
            if alive[b] and not (abs(z[b]) < z_limit and abs(v[b]) < v_limit):
                alive[b] = False
                fail_step[b] = k + 1
                status[b] = STATUS_GEOMETRY if (kind == KIND_DEVICE and not math.isfinite(z[b])) else STATUS_DIVERGED
            if not alive[b]:
                z[b] = math.nan
                v[b] = math.nan
            out_z[k + 1, b] = z[b]
            if store_v:
                out_v[k + 1, b] = v[b]
    return 0


# One compiled kernel per (restoring-force kind, Coulomb friction present): the flags are constants
# inside each, so the batch loop has no data-dependent branches. (A factory of closures would
# repeat less, but numba's on-disk cache cannot tell such closures apart.)
# fmt: off
@numba.njit(**_JIT)
def _kernel_poly(p, gain, u, uidx, dt, nsub, z0, v0, zl, vl, oz, ov, sv, st, fs):
    return _integrate(KIND_POLYNOMIAL, False, p, gain, u, uidx, dt, nsub, z0, v0, zl, vl, oz, ov, sv, st, fs)


@numba.njit(**_JIT)
def _kernel_poly_coulomb(p, gain, u, uidx, dt, nsub, z0, v0, zl, vl, oz, ov, sv, st, fs):
    return _integrate(KIND_POLYNOMIAL, True, p, gain, u, uidx, dt, nsub, z0, v0, zl, vl, oz, ov, sv, st, fs)


@numba.njit(**_JIT)
def _kernel_device(p, gain, u, uidx, dt, nsub, z0, v0, zl, vl, oz, ov, sv, st, fs):
    return _integrate(KIND_DEVICE, False, p, gain, u, uidx, dt, nsub, z0, v0, zl, vl, oz, ov, sv, st, fs)


@numba.njit(**_JIT)
def _kernel_device_coulomb(p, gain, u, uidx, dt, nsub, z0, v0, zl, vl, oz, ov, sv, st, fs):
    return _integrate(KIND_DEVICE, True, p, gain, u, uidx, dt, nsub, z0, v0, zl, vl, oz, ov, sv, st, fs)
# fmt: on


_KERNELS = {
    (KIND_POLYNOMIAL, False): _kernel_poly,
    (KIND_POLYNOMIAL, True): _kernel_poly_coulomb,
    (KIND_DEVICE, False): _kernel_device,
    (KIND_DEVICE, True): _kernel_device_coulomb,
}


@dataclass(frozen=True)
class SimulationResult:
    """Outcome of a (batched) simulation.

    Attributes
    ----------
    t : sample times [s], shape (N,)
    z, z_dot : displacement [m] and velocity [m/s], shape (B, N) (``z_dot`` None unless stored)
    status : per member, 0 ok, 1 diverged, 2 left the device's stroke
    fail_time : per member, time [s] of the first bad sample (NaN when ok)
    """

    t: np.ndarray
    z: np.ndarray
    z_dot: np.ndarray | None
    status: np.ndarray
    fail_time: np.ndarray

    @property
    def diverged(self) -> np.ndarray:
        """Boolean mask of members that were stopped."""
        return self.status != STATUS_OK

    def describe_failures(self, limit: int = 3) -> str:
        """One line naming the failed members, what happened and when."""
        bad = np.flatnonzero(self.diverged)
        parts = [
            f"member {b}: {STATUS_TEXT[int(self.status[b])]} at t = {self.fail_time[b]:.3f} s" for b in bad[:limit]
        ]
        more = f" (+{bad.size - limit} more)" if bad.size > limit else ""
        return "; ".join(parts) + more


@functools.lru_cache(maxsize=8)
def antialias_fir(q: int) -> np.ndarray:
    """The acquisition's anti-aliasing filter for decimation (or interpolation) by ``q``: linear phase, Kaiser window,
    passband flat to 1e-5 up to 0.8 of the output Nyquist frequency, 100 dB down from it on (a
    delta-sigma converter's digital filter is this flat: +-0.005 dB). scipy's default decimation FIR
    (Hamming, 20 q + 1 taps) rippled by 0.1-0.3 % in the excitation band, an error the nonlinear
    response turns into 0.07-0.7 % biases of k3, c and c_nl for any model fitted to the records
    (measured with the posterior's forward model on noise-free records)."""
    numtaps, beta = signal.kaiserord(100.0, 0.2 / q)
    return signal.firwin(numtaps | 1, 0.9 / q, window=("kaiser", beta))


def stage_input(u: np.ndarray, substeps: int = DEFAULT_SUBSTEPS) -> np.ndarray:
    """The sampled input at every Runge-Kutta stage time (``simulate_batch(..., staged=True)``):
    band-limited interpolation by 2 ``substeps`` (``scipy.signal.resample_poly`` with the acquisition's
    own flat FIR, ``antialias_fir``; the ends extended along a fitted line).

    A record's input went through an anti-aliasing filter: it is band-limited, and between samples it
    is not the straight line the linear convention draws. Linear interpolation attenuates a component
    at f by sinc^2(f / fs) (0.69 at 0.33 fs); a model that sees that input predicts a smaller response.
    On the Silverbox (610 Hz, excited to 200 Hz), SINDy's model predicted the multisine test with
    2.67 mV rms error under linearly interpolated input and 0.25 mV under this one (measured).
    ``u``: (N,) or (R, N); returns (2 substeps (N - 1) + 1,) or (R, ...)."""
    u = np.asarray(u, dtype=np.float64)
    r = 2 * int(substeps)
    n = u.shape[-1]
    fine = signal.resample_poly(u, r, 1, axis=-1, window=antialias_fir(r), padtype="line")
    return np.ascontiguousarray(fine[..., : r * (n - 1) + 1])


def input_gain(input_kind: str, masses: np.ndarray) -> np.ndarray:
    """Map the measured input to w in z'' = ... + w: -1 for base_acc, 1/m for force."""
    if input_kind == "base_acc":
        return -np.ones_like(masses)
    if input_kind == "force":
        return 1.0 / masses
    raise ValueError(f"input kind must be 'base_acc' or 'force', got {input_kind!r}")


@functools.lru_cache(maxsize=4)
def _pool(n: int) -> ThreadPoolExecutor:
    """A thread pool kept for the process (threads started once, not per call: an MCMC run calls the
    simulator tens of thousands of times, and starting the threads cost as much as a small batch)."""
    return ThreadPoolExecutor(n, thread_name_prefix="negstiff-sim")


def simulate_batch(
    params: np.ndarray,
    kind: str,
    u: np.ndarray,
    dt: float,
    x0: np.ndarray,
    *,
    input_kind: str = "base_acc",
    input_index: np.ndarray | None = None,
    substeps: int = DEFAULT_SUBSTEPS,
    store_velocity: bool = False,
    z_limit: float = DEFAULT_Z_LIMIT,
    v_limit: float = DEFAULT_V_LIMIT,
    threads: int | None = None,
    staged: bool = False,
) -> SimulationResult:
    """Integrate B parameter sets at once.

    Parameters
    ----------
    params : (P, B) kernel parameter vectors (``Model.kernel_params()`` / ``Device.kernel_params()``
        stacked as columns), or (P,) for one member
    kind : ``"polynomial"`` or ``"device"`` (the restoring-force law the rows encode)
    u : input samples, (N,) shared by all members or (R, N) rows selected by ``input_index``; with
        ``staged``, the input at every Runge-Kutta stage time instead, 2 ``substeps`` (N - 1) + 1
        columns (``stage_input``)
    dt : sample interval [s]
    x0 : initial states [z0, v0], (2,) or (B, 2) [m, m/s]
    input_kind : ``"base_acc"`` [m/s^2] or ``"force"`` [N]
    input_index : (B,) row of ``u`` for each member (default: row 0 for all)
    substeps : RK4 steps per sample interval
    store_velocity : also return z_dot
    z_limit, v_limit : |z| [m] and |z_dot| [m/s] beyond which a member is declared diverged
    threads : worker threads over batch chunks (default: the machine's cores, at most 1 per 64 members
        and per 2e5 member-steps)
    staged : ``u`` holds the input at the stage times (band-limited records), not the samples
    """
    p = np.asarray(params, dtype=np.float64)
    if p.ndim == 1:
        p = p[:, None]
    if p.shape[0] != N_PARAMS:
        raise ValueError(f"params must have {N_PARAMS} rows, got shape {p.shape}")
    nb = p.shape[1]
    if not np.all(np.isfinite(p)):
        raise ValueError("simulation parameters contain NaN or inf")
    if np.any(p[P_M] <= 0):
        raise ValueError("simulation mass must be positive")
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {sorted(KINDS)}, got {kind!r}")
    u2 = np.atleast_2d(np.asarray(u, dtype=np.float64))
    if u2.ndim != 2 or u2.shape[1] < 2:
        raise ValueError("input needs at least two samples")
    if not np.all(np.isfinite(u2)):
        raise ValueError("input contains NaN or inf")
    if not (dt > 0 and math.isfinite(dt)):
        raise ValueError(f"sample interval must be positive, got {dt}")
    if int(substeps) < 1:
        raise ValueError("substeps must be >= 1")
    uidx = np.zeros(nb, dtype=np.int64) if input_index is None else np.asarray(input_index, dtype=np.int64)
    if uidx.shape != (nb,) or uidx.min() < 0 or uidx.max() >= u2.shape[0]:
        raise ValueError("input_index must give one valid input row per batch member")
    x0 = np.broadcast_to(np.asarray(x0, dtype=np.float64), (nb, 2))
    if not np.all(np.isfinite(x0)):
        raise ValueError("initial state contains NaN or inf")
    gain = input_gain(input_kind, p[P_M])
    n = u2.shape[1]
    if staged:
        r = 2 * int(substeps)
        if (n - 1) % r or n < r + 1:
            raise ValueError(f"a staged input needs 2 substeps (N - 1) + 1 columns (substeps {substeps}), got {n}")
        n = (n - 1) // r + 1
    status = np.zeros(nb, dtype=np.int64)
    fail = np.full(nb, -1, dtype=np.int64)
    k = KINDS[kind]
    z0 = np.ascontiguousarray(x0[:, 0])
    v0 = np.ascontiguousarray(x0[:, 1])
    if threads is None:
        # a thread pays for its hand-off (~0.2 ms) only with enough work: 64 members and ~2e5 member-steps
        # each (an MCMC step's batch of 0.125 s windows ran slower on two threads than on one, measured)
        work = nb * n * int(substeps)
        threads = min(os.cpu_count() or 1, max(1, nb // 64), max(1, work // 200_000))
    chunks = [c for c in np.array_split(np.arange(nb), max(1, int(threads))) if c.size]
    kernel = _KERNELS[(k, bool(np.any(p[P_COULOMB] != 0.0)))]

    def run(c):
        # each thread writes its own time-major block: shared rows would false-share cache lines
        sl = slice(c[0], c[-1] + 1)
        oz = np.empty((n, c.size))
        ov = np.empty((n, c.size)) if store_velocity else np.empty((1, c.size))
        kernel(
            np.ascontiguousarray(p[:, sl]),
            gain[sl],
            u2,
            uidx[sl],
            float(dt),
            int(substeps),
            z0[sl],
            v0[sl],
            float(z_limit),
            float(v_limit),
            oz,
            ov,
            store_velocity,
            status[sl],
            fail[sl],
        )
        return oz, ov

    if len(chunks) == 1:
        parts = [run(chunks[0])]
    else:
        parts = list(_pool(len(chunks)).map(run, chunks))
    out_z = parts[0][0] if len(parts) == 1 else np.hstack([q[0] for q in parts])
    out_v = None
    if store_velocity:
        out_v = parts[0][1] if len(parts) == 1 else np.hstack([q[1] for q in parts])
    t = np.arange(n) * dt
    fail_time = np.where(fail >= 0, fail * dt, np.nan)
    return SimulationResult(t, out_z.T, None if out_v is None else out_v.T, status, fail_time)


def simulate(
    system,
    u: np.ndarray,
    dt: float,
    *,
    z0: float | None = None,
    v0: float = 0.0,
    input_kind: str = "base_acc",
    substeps: int = DEFAULT_SUBSTEPS,
    z_limit: float = DEFAULT_Z_LIMIT,
    v_limit: float = DEFAULT_V_LIMIT,
) -> SimulationResult:
    """Simulate one ``Model`` or ``Device`` under the sampled input ``u`` (N,), interval ``dt`` [s].

    The initial state defaults to rest at the positive well. Returns z and z_dot of shape (N,)
    wrapped in a ``SimulationResult`` with a batch dimension of one (``.z[0]``).
    """
    if z0 is None:
        z0 = system.equilibria().z_plus
    return simulate_batch(
        system.kernel_params(),
        system.kind,
        u,
        dt,
        np.array([z0, v0]),
        input_kind=input_kind,
        substeps=substeps,
        store_velocity=True,
        z_limit=z_limit,
        v_limit=v_limit,
    )


def reference_solution(
    system, u: np.ndarray, dt: float, z0: float, v0: float = 0.0, rtol: float = 1e-10, input_kind: str = "base_acc"
) -> np.ndarray:
    """z at the samples by scipy's adaptive DOP853 (``rtol``), with the same linearly
    interpolated input: the independent reference the simulator is checked against.

    The input has a kink at every sample, which an adaptive integrator at tight tolerance crawls
    through; so each sample interval, where the input is smooth, is integrated on its own
    (scipy's DOP853 stepper restarted from the previous end state) with a scalar right-hand side.
    """
    p = system.kernel_params()
    m = p[P_M]
    gain = -1.0 if input_kind == "base_acc" else 1.0 / m
    u = np.asarray(u, float)
    n = u.size
    slope = np.diff(u, append=u[-1])
    ul, sl = u.tolist(), slope.tolist()
    ca, sa = math.cos(p[3]), math.sin(p[3])
    q = p.tolist()

    def force(z: float, v: float) -> float:
        if system.kind == "polynomial":
            k = ((q[4] * z + q[3]) * z - q[2]) * z + q[1]
        else:
            bb = q[2] * ca - z * sa
            r = math.sqrt(bb * bb - z * z)
            k = 2.0 * q[1] * (r - bb + q[4]) * (sa - (bb * sa + z) / r) + m * q[5]
        k += z * z * (q[P_QUAD_STIFF] + z * (q[P_CUBIC_STIFF] + z * (q[P_QUARTIC] + z * q[P_QUINTIC])))
        dz = z - q[P_STOP_Z]
        k += 0.5 * q[P_STOP_K] * (dz + math.copysign(1.0, q[P_STOP_Z]) * abs(dz))
        d = v * (q[P_C] + q[P_CNL] * abs(v) + q[P_CUBIC_DAMP] * v * v)
        return k + d + q[P_COULOMB] * math.tanh(v / COULOMB_VELOCITY_SCALE)

    from scipy.integrate import DOP853

    out = np.empty(n)
    out[0] = z0
    state = [z0, v0]
    for k in range(n - 1):
        uk, sk = ul[k], sl[k]

        def rhs(t: float, x, uk=uk, sk=sk):
            return np.array((x[1], gain * (uk + sk * t / dt) - force(x[0], x[1]) / m))

        solver = DOP853(rhs, 0.0, state, dt, rtol=rtol, atol=1e-13)
        while solver.status == "running":
            solver.step()
        state = solver.y
        out[k + 1] = state[0]
    return out


@numba.njit(cache=True, error_model="numpy")
def _benettin(kind, p, gain, u, dt, nsub, z0, v0, renorm):
    """RK4 of the state and one tangent vector; the tangent is renormalised every ``renorm`` samples
    and its log growth accumulated (Benettin et al. 1980). Jacobian of the force by central
    differences of the same force law the simulator integrates."""
    q = _member(p, 0, kind)
    im = 1.0 / q[P_M]
    h = dt / nsub
    z, v, dz, dv = z0, v0, 1.0, 0.0
    n = u.shape[0]
    logs = np.zeros((n - 1) // renorm)
    acc = 0.0
    k_out = 0
    for k in range(n - 1):
        u0 = gain * u[k]
        du = gain * u[k + 1] - u0
        for j in range(nsub):
            st = np.empty((4, 4))
            zz, vv, ddz, ddv = z, v, dz, dv
            for s in range(4):
                c = 0.0 if s == 0 else (0.5 if s < 3 else 1.0)
                if s > 0:
                    zz = z + c * h * st[s - 1, 0]
                    vv = v + c * h * st[s - 1, 1]
                    ddz = dz + c * h * st[s - 1, 2]
                    ddv = dv + c * h * st[s - 1, 3]
                frac = (j + c) / nsub
                w = u0 + frac * du
                f = _force(kind, False, zz, vv, q) + q[P_COULOMB] * math.tanh(vv / COULOMB_VELOCITY_SCALE)
                ez = 1e-7 * max(1e-3, abs(zz))
                ev = 1e-6 * max(1e-2, abs(vv))
                fz = (_force(kind, False, zz + ez, vv, q) - _force(kind, False, zz - ez, vv, q)) / (2 * ez)
                fv = (_force(kind, False, zz, vv + ev, q) - _force(kind, False, zz, vv - ev, q)) / (2 * ev)
                fv += q[P_COULOMB] / COULOMB_VELOCITY_SCALE / math.cosh(vv / COULOMB_VELOCITY_SCALE) ** 2
                st[s, 0] = vv
                st[s, 1] = w - f * im
                st[s, 2] = ddv
                st[s, 3] = -(fz * ddz + fv * ddv) * im
            z += h / 6.0 * (st[0, 0] + 2 * st[1, 0] + 2 * st[2, 0] + st[3, 0])
            v += h / 6.0 * (st[0, 1] + 2 * st[1, 1] + 2 * st[2, 1] + st[3, 1])
            dz += h / 6.0 * (st[0, 2] + 2 * st[1, 2] + 2 * st[2, 2] + st[3, 2])
            dv += h / 6.0 * (st[0, 3] + 2 * st[1, 3] + 2 * st[2, 3] + st[3, 3])
        if (k + 1) % renorm == 0:
            norm = math.sqrt(dz * dz + dv * dv)
            acc += math.log(norm)
            dz /= norm
            dv /= norm
            logs[k_out] = acc
            k_out += 1
    return logs


def lyapunov_benettin(
    system,
    u: np.ndarray,
    dt: float,
    z0: float,
    v0: float = 0.0,
    *,
    input_kind: str = "base_acc",
    substeps: int = 4,
    renorm_every: int = 16,
    transient_s: float = 10.0,
) -> dict:
    """Largest Lyapunov exponent [1/s] of ``system`` driven by ``u`` from the variational equations
    (ground truth for the model). The tangent norm is measured in (z [m], z' [m/s]); the exponent does
    not depend on that choice. The first ``transient_s`` seconds are discarded.

    Returns ``{"value", "running"(t, estimate)}``."""
    p = system.kernel_params()
    gain = -1.0 if input_kind == "base_acc" else 1.0 / p[P_M]
    logs = _benettin(
        KINDS[system.kind],
        np.ascontiguousarray(p[:, None]),
        gain,
        np.asarray(u, float),
        float(dt),
        int(substeps),
        float(z0),
        float(v0),
        int(renorm_every),
    )
    t = (np.arange(logs.size) + 1) * renorm_every * dt
    k0 = int(np.searchsorted(t, transient_s))
    if logs.size - k0 < 2:
        raise ValueError("record too short for a Lyapunov exponent after the transient")
    lam = (logs[-1] - logs[k0]) / (t[-1] - t[k0])
    running = (logs[k0:] - logs[k0]) / np.maximum(t[k0:] - t[k0], 1e-12)
    return {"value": float(lam), "t": t[k0:], "running": running}
