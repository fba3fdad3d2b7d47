"""Fixed-step simulator of the equation of motion, for one system or a batch of thousands.

    z'' = -(D(z') + K(z) + extra(z, z')) / m + w(t),   w = -b''(t) (base excitation) or f(t)/m (force)

Classical fourth-order Runge-Kutta with ``substeps`` steps per sample interval. The sampled input is
linearly interpolated between samples, the one input convention of the whole suite (the virtual rig,
the likelihoods and the identification methods all assume it; holding the input constant per sample
instead costs about 4 % error, ``docs/ecosystem.md`` section 5).

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
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from negstiff.errors import InputError

from . import compile_ahead, effects
from .kernel import KINDS, NO_HOOK, P_M, STATUS_DIVERGED, STATUS_GEOMETRY, STATUS_OK, _integrate, kernel_flags

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


@dataclass(frozen=True)
class SimulationResult:
    """Outcome of a (batched) simulation.

    Attributes
    ----------
    z, z_dot : displacement [m] and velocity [m/s], shape (B, N); of a structure of D DOFs (``models.structure``)
        (B, D, N) (``z_dot`` None unless stored)
    status : per member, 0 ok, 1 diverged, 2 left the device's stroke
    fail_time : per member, time [s] of the first bad sample (NaN when ok)
    dt : sample interval [s]
    t : sample times [s], shape (N,), made when first read (a 300 s record's took 8 % of its simulation: a fresh
        array's pages are faulted in one by one)
    """

    z: np.ndarray
    z_dot: np.ndarray | None
    status: np.ndarray
    fail_time: np.ndarray
    dt: float

    @functools.cached_property
    def t(self) -> np.ndarray:
        """Sample times [s], shape (N,)."""
        return np.arange(self.z.shape[-1]) * self.dt

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
    (measured with the posterior's forward model on noise-free records).
    """
    from scipy import signal  # imported where used: a kernel's compile-ahead helper (``compile_ahead``) needs none

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
    ``u``: (N,) or (R, N); returns (2 substeps (N - 1) + 1,) or (R, ...).
    """
    from scipy import signal

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
    raise InputError(f"input kind must be 'base_acc' or 'force', got {input_kind!r}")


def cores() -> int:
    """The cores negstiff's own threads (simulator batches, posterior ensembles) may use: the running
    command's thread budget (the cores the process may use: ``resources.thread_budget``), else the cores the
    process may run on, ``$NEGSTIFF_THREADS`` capping both (a machine shared with other jobs). Thread counts
    never change a number: the threads' parts are independent.
    """
    from negstiff.resources import thread_budget

    return thread_budget()


@functools.lru_cache(maxsize=4)
def _pool(n: int) -> ThreadPoolExecutor:
    """A thread pool kept for the process (threads started once, not per call: an MCMC run calls the
    simulator tens of thousands of times, and starting the threads cost as much as a small batch).
    """
    return ThreadPoolExecutor(n, thread_name_prefix="negstiff-sim")


def checked_input(u, dt: float, substeps: int, input_index, nb: int, staged: bool = False
                  ) -> tuple[np.ndarray, np.ndarray, int]:  # fmt: skip
    """The input rows, each member's row index and the output samples as the Runge-Kutta loop takes them (``integrate``:
    one DOF or N alike), or a one-line ValueError.
    """
    # one array type per kernel argument, whatever the caller passes: each distinct numba signature (a
    # strided input, a read-only start state) was compiled again, 5-10 s each on a fresh install
    u2 = np.require(np.atleast_2d(np.asarray(u, dtype=np.float64)), requirements=("C", "W"))
    if u2.ndim != 2 or u2.shape[1] < 2:
        raise InputError("input needs at least two samples")
    if not np.all(np.isfinite(u2)):
        raise InputError("input contains NaN or inf")
    if not (dt > 0 and math.isfinite(dt)):
        raise InputError(f"sample interval must be positive, got {dt}")
    if int(substeps) < 1:
        raise InputError("substeps must be >= 1")
    uidx = np.zeros(nb, dtype=np.int64) if input_index is None else np.asarray(input_index, dtype=np.int64)
    if uidx.shape != (nb,) or uidx.min() < 0 or uidx.max() >= u2.shape[0]:
        raise InputError("input_index must give one valid input row per batch member")
    n = u2.shape[1]
    if staged:
        r = 2 * int(substeps)
        if (n - 1) % r or n < r + 1:
            raise InputError(f"a staged input needs 2 substeps (N - 1) + 1 columns (substeps {substeps}), got {n}")
        n = (n - 1) // r + 1
    return u2, uidx, n


def _checked(params, lay: effects.Layout, kind: str, u, dt: float, substeps: int, input_index, x0, staged: bool):
    """``simulate_batch``'s arguments as the kernel takes them, or a one-line ValueError."""
    p = np.asarray(params, dtype=np.float64)
    if p.ndim == 1:
        p = p[:, None]
    if p.shape[0] not in (lay.size, lay.size + effects.TABLE_ROWS):
        raise InputError(
            f"params must have {lay.size} rows (the effect registry's layout; {lay.size + effects.TABLE_ROWS} with a "
            f"table of shaped parts), got shape {p.shape}: kernel parameters made before an effect was registered?"
        )
    nb = p.shape[1]
    if not np.all(np.isfinite(p)):
        raise InputError("simulation parameters contain NaN or inf")
    if np.any(p[P_M] <= 0):
        raise InputError("simulation mass must be positive")
    if kind not in KINDS:
        raise InputError(f"kind must be one of {sorted(KINDS)}, got {kind!r}")
    u2, uidx, n = checked_input(u, dt, substeps, input_index, nb, staged)
    x0 = np.broadcast_to(np.asarray(x0, dtype=np.float64), (nb, 2))
    if not np.all(np.isfinite(x0)):
        raise InputError("initial state contains NaN or inf")
    return p, u2, uidx, x0, n


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
    hook: tuple | None = None,
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
    hook : the extra force hook's arguments (``kernel.extra_term``: weights, bumps; with a staged input), added
        to every member's force (the hybrid model's term, ``inference.estimators.hybrid``)
    """
    lay = effects.layout()
    p, u2, uidx, x0, n = _checked(params, lay, kind, u, dt, substeps, input_index, x0, staged)
    nb = p.shape[1]
    one = lambda a: np.ascontiguousarray(np.asarray(a)[None, :])  # noqa: E731  (the single DOF's row)
    no_structure = np.zeros((1, 1, nb))
    oz, ov, status, fail = integrate(
        KINDS[kind], p, one(1.0 / p[P_M]), no_structure, no_structure, one(input_gain(input_kind, p[P_M])), u2,
        uidx, n, dt, substeps, one(x0[:, 0]), one(x0[:, 1]), place=(0, 1), store_velocity=store_velocity,
        z_limit=z_limit, v_limit=v_limit, threads=threads, hook=hook,
    )  # fmt: skip
    fail_time = np.where(fail >= 0, fail * dt, np.nan)
    return SimulationResult(oz[:, 0, :].T, None if ov is None else ov[:, 0, :].T, status, fail_time, dt)


def integrate(kind: int, p: np.ndarray, minv: np.ndarray, lk: np.ndarray, lc: np.ndarray, gain: np.ndarray,
              u2: np.ndarray, uidx: np.ndarray, n: int, dt: float, substeps: int, z0: np.ndarray, v0: np.ndarray, *,
              place: tuple[int, int], store_velocity: bool = False, z_limit: float = DEFAULT_Z_LIMIT,
              v_limit: float = DEFAULT_V_LIMIT, threads: int | None = None, hook: tuple | None = None,
              ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray, np.ndarray]:  # fmt: skip
    """The one call of the compiled Runge-Kutta loop (``kernel._integrate``), split over threads in batch chunks:
    B systems of N DOFs, the element between DOF ``place[1]`` and DOF ``place[0]`` (0: the base).

    ``p`` (P, B) the element's kernel parameters, ``minv``, ``gain``, ``z0``, ``v0`` (N, B), ``lk``, ``lc``
    (N, N, B) the linear structure (zeros: none), ``u2``, ``uidx``, ``n`` (output samples) as ``checked_input``
    returns them, ``hook`` the extra force hook's arguments (``kernel.extra_term``). Returns z, z' (T, N, B) (z'
    None unless stored), each member's status and failing step (-1: none). The single-DOF model is N = 1, one DOF
    on the base.
    """
    nd, nb = minv.shape
    if lk.shape != (nd, nd, nb) or lc.shape != (nd, nd, nb) or gain.shape != (nd, nb) or p.shape[1] != nb:
        raise ValueError(f"the kernel's arrays disagree on N = {nd} DOFs and B = {nb} members")
    status = np.zeros(nb, dtype=np.int64)
    fail = np.full(nb, -1, dtype=np.int64)
    if threads is None:
        # a thread pays for its hand-off (~0.2 ms) only with enough work: 64 members and ~2e5 member-steps
        # each (an MCMC step's batch of 0.125 s windows ran slower on two threads than on one, measured)
        work = nb * n * int(substeps) * nd
        threads = min(cores(), max(1, nb * nd // 64), max(1, work // 200_000))
    chunks = [c for c in np.array_split(np.arange(nb), max(1, int(threads))) if c.size]
    lay = effects.layout()
    mono = lay.monomials
    if mono.shape[0]:  # only the monomial rows some member uses: a model without them keeps the fast kernels
        mono = np.ascontiguousarray(mono[np.any(p[mono[:, 0]] != 0.0, axis=1)])
    table = p.shape[0] > lay.size  # a table of shaped parts (``effects.tabulate``) after the layout's rows
    ts = lay.size if table else -1
    # one DOF on the base without a linear structure runs the fused step; anything else the stage-wise loops
    staged = not (nd == 1 and place[0] == 0 and not (np.any(lk) or np.any(lc)))
    flags = kernel_flags(kind, p, mono, hook is not None, table, staged)
    hook_args = NO_HOOK if hook is None else tuple(hook)
    compile_ahead.wait_for(flags)  # a helper compiling this kernel (a fresh install's first fit): its cache entry

    def c_(a):
        # one array type per kernel argument (C-contiguous, writable), whatever the caller passed: each distinct
        # numba signature (a strided input, a read-only start state) is another 5-10 s compile on a fresh install
        return a if a.flags.c_contiguous and a.flags.writeable else np.require(a, requirements=("C", "W"))

    def run(c):
        # each thread writes its own time-major block: shared rows would false-share cache lines
        sl = slice(c[0], c[-1] + 1)
        oz = np.empty((n, nd, c.size))
        ov = np.empty((n, nd, c.size)) if store_velocity else np.empty((1, nd, c.size))
        _integrate(*flags, c_(p[:, sl]), mono, ts, place[0] - 1, place[1] - 1, c_(minv[:, sl]),
                   c_(lk[:, :, sl]), c_(lc[:, :, sl]), c_(gain[:, sl]), u2, c_(uidx[sl]), float(dt), int(substeps),
                   c_(z0[:, sl]), c_(v0[:, sl]), float(z_limit), float(v_limit), oz, ov, store_velocity, status[sl],
                   fail[sl], hook_args)  # fmt: skip
        return oz, ov

    outs = [run(chunks[0])] if len(chunks) == 1 else list(_pool(len(chunks)).map(run, chunks))
    oz = outs[0][0] if len(outs) == 1 else np.concatenate([o[0] for o in outs], axis=2)
    ov = None
    if store_velocity:
        ov = outs[0][1] if len(outs) == 1 else np.concatenate([o[1] for o in outs], axis=2)
    return oz, ov, status, fail


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
    force_dof: int | None = None,
) -> SimulationResult:
    """Simulate one ``Model`` or ``Device`` under a sampled input.

    Runge-Kutta 4 (numba) with the input interpolated band-limited at every stage, the step refined to
    ``substeps`` per sample; a run that leaves ``z_limit`` or ``v_limit`` is stopped and flagged.

    Parameters
    ----------
    system : Model, Device or Structure
        The system (a ``Structure`` of N DOFs: ``z`` and ``z_dot`` of shape (1, N, T), its input band-limited
        between samples, from rest with the element's relative displacement at ``z0``).
    u : numpy.ndarray
        The input, (N,): base acceleration [m/s^2] or force [N].
    dt : float
        Sampling interval [s].
    z0 : float, optional
        Initial z [m]; default: rest at the positive well.
    v0 : float, default 0
        Initial velocity [m/s].
    input_kind : {"base_acc", "force"}, default "base_acc"
        What ``u`` is.
    substeps : int, default 2
        Runge-Kutta steps per sample.
    z_limit, v_limit : float
        Bounds [m, m/s] beyond which a run counts as diverged.
    force_dof : int, optional
        The DOF a force acts on (1..N; default: the DOF the element moves; a single DOF's is 1).

    Returns
    -------
    SimulationResult
        ``z`` and ``z_dot`` of shape (1, N) (a batch of one: ``.z[0]``) and ``diverged`` (1,).

    Examples
    --------
    >>> import numpy as np
    >>> from negstiff import simulate
    >>> from negstiff.models import AS_BUILT
    >>> t = np.arange(0, 5.0, 1 / 512)
    >>> res = simulate(AS_BUILT, 3.0 * np.sin(2 * np.pi * 9.0 * t), 1 / 512)
    >>> res.z.shape, bool(res.diverged[0])
    ((1, 2560), False)
    """
    if hasattr(system, "n_dof"):  # a structure of N DOFs simulates itself (``Structure.simulate``)
        if v0:
            raise InputError("a structure starts from rest (v0 = 0); give z0, the element's relative displacement")
        return system.simulate(u, dt, z0=z0, input_kind=input_kind, force_dof=force_dof, substeps=substeps,
                               z_limit=z_limit, v_limit=v_limit)  # fmt: skip
    if force_dof not in (None, 1):
        raise InputError(f"a single DOF's force acts on DOF 1, got force_dof={force_dof!r}")
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
