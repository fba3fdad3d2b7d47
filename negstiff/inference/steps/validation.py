"""Validation of a model against a record by simulation: the free runs every method is judged by.

One route for every free run of a model under a measured input (``simulate_record``): the input at
each Runge-Kutta stage time by band-limited interpolation (``simulator.stage_input``: a record's
input passed an anti-aliasing filter, it is not piecewise linear between samples), the step refined
where the model is fast for the sampling rate (``record_substeps``), and the start state from the
record's least-error velocity (``derivatives.state_derivatives``).
"""

from __future__ import annotations

import copy
import dataclasses
import math
from typing import Any, TypedDict, Unpack

import numpy as np
from scipy import optimize, signal

from negstiff.errors import MeasurementError
from negstiff.inference.record.derivatives import derivative_window, noise_floor
from negstiff.inference.record.measurement import Measurement
from negstiff.inference.steps.frame import pin_frame
from negstiff.models import Model, simulate, simulate_batch
from negstiff.models.effects import measured_channels
from negstiff.models.simulator import (
    DEFAULT_SUBSTEPS,
    DEFAULT_V_LIMIT,
    DEFAULT_Z_LIMIT,
    SimulationResult,
    input_gain,
    stage_input,
)
from negstiff.models.structure import Structure, relative, simulate_structures


class Limits(TypedDict, total=False):
    """The simulator's divergence bounds: |z| [m] and |z'| [m/s] (either may be left at its default)."""

    z_limit: float
    v_limit: float


def divergence_limits(z: np.ndarray, v: np.ndarray) -> Limits:
    """|z| and |z'| a simulation may reach before it counts as diverged: ten times the record's (the
    simulator's defaults, 1 m and 100 m/s, are a shaker device's; an electronic benchmark's volts per
    second exceed them).
    """
    return Limits(z_limit=10 * float(np.abs(z).max()) + 1e-12, v_limit=10 * float(np.abs(v).max()) + 1e-12)


STEP_OMEGA = 0.25
"""Largest omega h of a Runge-Kutta step at the stiffest point of the record's range. At omega h = 0.4
(the Silverbox at two steps per sample) the integration error was 15 % of the model's 0.24 mV
prediction error; at 0.2 it was below the data's (measured on the multisine test)."""
MAX_SUBSTEPS = 16


RK4_LIMIT = 2.8
"""The largest omega h at which the classical Runge-Kutta step is stable on an undamped oscillator (2 sqrt 2)."""


def record_substeps(system, rec: Measurement) -> int:
    """Runge-Kutta steps per sample for simulating ``system`` against ``rec``: the simulator's default,
    more where the system's stiffest point over the range the record visits makes omega h exceed
    ``STEP_OMEGA`` (a fast resonance sampled slowly: the Silverbox's 60-90 Hz at 610 Hz); at most
    ``MAX_SUBSTEPS`` (a system beyond them diverges, said by its result: ``check_resolved`` refuses it first).
    """
    omega, _ = stiffest(system, rec)
    need = math.ceil(min(omega * rec.dt / STEP_OMEGA, MAX_SUBSTEPS))
    return int(min(MAX_SUBSTEPS, max(DEFAULT_SUBSTEPS, need)))


def check_resolved(system, rec: Measurement, what: str) -> None:
    """Refuse (``MeasurementError``, one line naming the mass and the stiffness) a system whose stiffest linear
    frequency over the record's range is beyond what ``MAX_SUBSTEPS`` Runge-Kutta steps a sample resolve
    (``RK4_LIMIT``): its run can only diverge (m = 1e-300 kg with k = 1e300 N/m overflowed the count of steps).
    """
    omega, k_max = stiffest(system, rec)
    top = RK4_LIMIT * MAX_SUBSTEPS / rec.dt
    if not omega <= top:
        raise MeasurementError(
            f"{what}: the model's stiffest linear frequency sqrt(|K'(z)| / m) = sqrt({k_max:.3g} N/m / {system.m:.3g} "
            f"kg) = {omega / (2 * math.pi):.3g} Hz over the record's range is beyond what {MAX_SUBSTEPS} Runge-Kutta "
            f"steps a sample resolve at {rec.fs:g} Hz (up to {top / (2 * math.pi):.3g} Hz): is m in kg and K in N/m?"
        )


def check_structure_run(structure: Structure, z0: float | None, z_limit: float = DEFAULT_Z_LIMIT) -> None:
    """Refuse (``MeasurementError``, one line naming the value) a structure no simulation under a record can run:
    a mass beyond what a lab's structure holds (``MASS_RANGE_KG``), a linear stiffness or damping matrix that is
    not positive semi-definite (a spring that pushes its masses away, a damper that feeds energy in: a negative
    stiffness is the element's ``k1``), a start ``z0`` [m] across the element beyond the simulation's bound
    ``z_limit``. Each ran and said "diverged at t = 0.002 s" instead.
    """
    from negstiff.io.schema import MASS_RANGE_KG

    lo, hi = MASS_RANGE_KG
    for i, m in enumerate(structure.masses):
        if not lo <= m <= hi:
            raise MeasurementError(f"the structure's mass m{i + 1} = {m:g} kg is beyond the masses a lab's structure "
                                   f"holds ({lo:g} to {hi:g} kg)")  # fmt: skip
    for name, matrix, unit, why in (
        (
            "stiffness",
            structure.stiffness,
            "N/m",
            "a spring that pushes its masses away (a negative stiffness is the element's k1)",
        ),
        ("damping", structure.damping, "N s/m", "a damper that feeds energy in"),
    ):
        eig = np.linalg.eigvalsh(np.asarray(matrix, float))
        if eig.size and eig.min() < -1e-12 * max(1.0, float(np.abs(eig).max())):
            raise MeasurementError(f"the structure's linear {name} matrix has the eigenvalue {eig.min():g} {unit}: "
                                   f"{why}; it must be positive semi-definite")  # fmt: skip
    if z0 is not None and not abs(z0) < z_limit:
        raise MeasurementError(f"a start z0 = {z0:g} m across the element lies beyond the simulation's bound |z| < "
                               f"{z_limit:g} m")  # fmt: skip


def stiffest(system, rec: Measurement) -> tuple[float, float]:
    """The system's stiffest linear angular frequency [rad/s] over the range the record visits (the model's wells
    and what lies between for an input-only record), and that |K'(z)| [N/m]. A structure's: the highest of its
    tangent modes with the element's |K'(r)| over the relative motion the record's channels show
    (``structure_stiffest``).
    """
    if isinstance(system, Structure):
        return structure_stiffest(system, relative(rec.channels, system.place))
    if rec.z is not None:
        lo, hi = float(np.min(rec.z)), float(np.max(rec.z))
    else:  # an input-only record: the model's wells and what lies between
        try:
            eq = system.equilibria()
            wells = [z for z in (eq.z_minus, eq.z_plus) if z is not None]
            lo, hi = min(wells), max(wells)
        except (ValueError, AttributeError):
            lo = hi = 0.0
    grid = np.linspace(lo, hi, 65)
    with np.errstate(all="ignore"):
        k = np.abs(np.asarray(system.stiffness(grid), float))
        k = k[np.isfinite(k)]
        k_max = float(k.max()) if k.size else 0.0
        return float(np.sqrt(np.float64(k_max) / system.m)), k_max


def structure_stiffest(structure: Structure, r: np.ndarray) -> tuple[float, float]:
    """A structure's stiffest tangent angular frequency [rad/s] over the element's relative motion ``r`` (the
    square root of the largest eigenvalue of M^-1 (K + l l^T |K_e'(r)|), the element's tangent stiffness taken
    positive as ``stiffest`` takes a single DOF's), and the largest |K_e'(r)| [N/m].
    """
    grid = np.linspace(float(np.min(r)), float(np.max(r)), 65)
    with np.errstate(all="ignore"):
        k = np.abs(np.asarray(structure.element.stiffness(grid), float))
    k = k[np.isfinite(k)]
    k_max = float(k.max()) if k.size else 0.0
    inv_sqrt_m = 1.0 / np.sqrt(np.asarray(structure.masses, float))
    lvec = structure.coupling
    tangent = np.asarray(structure.K, float) + k_max * np.outer(lvec, lvec)
    top = float(np.linalg.eigvalsh(inv_sqrt_m[:, None] * tangent * inv_sqrt_m[None, :]).max())
    return math.sqrt(max(top, 0.0)), k_max


def simulate_record(
    system,
    rec: Measurement,
    x0,
    substeps: int | None = None,
    staged_input: np.ndarray | None = None,
    **limits: Unpack[Limits],
) -> SimulationResult:
    """A free run of ``system`` under ``rec``'s input from the state ``x0``: the input at every
    Runge-Kutta stage time by band-limited interpolation (``stage_input``; ``staged_input``: the caller's,
    staged for ``substeps``), the step refined where the system is fast for the sampling rate
    (``record_substeps``). The velocity is stored.
    """
    sub = record_substeps(system, rec) if substeps is None else int(substeps)
    if not limits and rec.z is not None:
        _, vs, _, _ = rec.states("state")
        limits = divergence_limits(rec.z, vs)
    u = rec.staged(system, sub) if staged_input is None else staged_input
    return simulate_batch(system.kernel_params(), system.kind, u, rec.dt,
                          np.asarray(x0, float), input_kind=rec.input_name, substeps=sub, staged=True,
                          store_velocity=True, **limits)  # fmt: skip


def start_state(system, rec: Measurement, guess=None, periods: float = 2.0) -> tuple[float, float]:
    """The state [z, z'] at ``rec``'s first sample that makes ``system``'s free run match the first
    ``periods`` of the record best (least squares over the two start values).

    A record's edge is where a derivative estimate is worst: a polynomial through the first samples
    spans most of a period when the sampling is slow for the resonance (the Silverbox: 7-10 samples per
    period; its quadratic start missed z' by 40 %, which doubled the free-run error of a good model).
    The window: ``periods`` periods of the system's median linearised frequency over the record's range
    (at least 16 samples). ``guess``: the start of the search (default: the smoothed state at sample 0).
    """
    zs, vs, _, _ = rec.states("state")
    x0 = np.array([zs[0], vs[0]] if guess is None else guess, float)
    lo, hi = float(np.min(rec.displacement)), float(np.max(rec.displacement))
    with np.errstate(all="ignore"):
        k = np.asarray(system.stiffness(np.linspace(lo, hi, 65)), float)
    k = k[np.isfinite(k) & (k > 0)]
    omega = math.sqrt(float(np.median(k)) / system.m) if k.size else 2 * math.pi / rec.duration
    length = int(min(rec.n, max(16, math.ceil(periods * 2 * math.pi / omega * rec.fs))))
    head = rec.segment(0, length)
    limits = divergence_limits(rec.displacement, vs)
    sub = record_substeps(system, rec)
    scale = np.array([max(float(np.std(rec.displacement)), 1e-12), max(float(np.std(vs)), 1e-12)])

    def residual(x):
        res = simulate_record(system, head, x * scale, substeps=sub, **limits)
        r = res.z[0] - head.z
        return np.where(res.diverged[0], 10 * np.abs(head.z).max(), r)

    sol = optimize.least_squares(residual, x0 / scale, method="lm", diff_step=1e-6, max_nfev=50)
    z0, v0 = sol.x * scale
    return float(z0), float(v0)


def simulate_measured(
    system,
    rec: Measurement,
    z0: float | None = None,
    v0: float | None = None,
    interpolation: str = "band-limited",
    substeps: int | None = None,
) -> SimulationResult:
    """``system`` under ``rec``'s input (``negstiff simulate``): from (``z0``, ``v0``) where given, else from
    the record's own start (``start_state``: the state whose free run matches its first periods; the
    record's z pinned to the physical frame first where it was derived), else from rest at ``z_plus``
    (an input-only record). Bounded by ten times the record's stroke and speed (``divergence_limits``; the
    shaker defaults for an input-only record). ``interpolation``: the input between samples band-limited
    (a record through an anti-aliasing filter) or ``"linear"`` (a piecewise-linear drive).
    """
    if interpolation not in ("band-limited", "linear"):
        raise MeasurementError(f"interpolation is 'band-limited' or 'linear', got {interpolation!r}")
    check_resolved(system, rec, f"simulation under {rec.source}")
    limits = Limits(z_limit=DEFAULT_Z_LIMIT, v_limit=DEFAULT_V_LIMIT)
    start: tuple[float | None, float] = (None, 0.0)
    if rec.z is not None:
        rec = pin_frame(rec)
        limits = divergence_limits(rec.displacement, rec.states("state")[1])
        if z0 is None or v0 is None:
            start = start_state(system, rec)
    z0 = start[0] if z0 is None else z0
    v0 = start[1] if v0 is None else v0
    if z0 is None:
        z0 = system.equilibria().z_plus
    if interpolation == "linear":
        return simulate(system, rec.driving(system), rec.dt, z0=z0, v0=v0, input_kind=rec.input_name,
                        substeps=substeps or 2,
                        **limits)  # fmt: skip
    return simulate_record(system, rec, (z0, v0), substeps=substeps, **limits)


@dataclasses.dataclass(frozen=True)
class RestartWindows:
    """Windows of a record each restarted from the record's measured state at its first sample: the one
    cutting of every restarted free run (``restart_windows``).

    Attributes
    ----------
    starts : numpy.ndarray
        (W,) each window's first sample.
    length : int
        Samples each window spans (its start included).
    step : int
        Samples from one window's start to the next's (before any pick of ``max_windows``).
    """

    starts: np.ndarray
    length: int
    step: int

    @classmethod
    def at(cls, starts, length: int) -> RestartWindows:
        """Windows of ``length`` samples at chosen ``starts`` (not evenly stepped: the discrepancy workflow's
        windows before each episode where an effect acts); ``step`` is ``length``.
        """
        return cls(np.asarray(starts, dtype=np.int64).reshape(-1), int(length), int(length))

    def __len__(self) -> int:
        return int(self.starts.size)

    @property
    def index(self) -> np.ndarray:
        """(W, length) the samples of every window."""
        return self.starts[:, None] + np.arange(self.length)[None, :]

    def measured(self, x: np.ndarray) -> np.ndarray:
        """A signal's samples in every window: (W, length) of a 1-D ``x``, (W, N, length) of (N, T) channels."""
        x = np.asarray(x)
        return x[self.index] if x.ndim == 1 else np.transpose(x[:, self.index], (1, 0, 2))

    def start_states(self, z: np.ndarray, v: np.ndarray) -> np.ndarray:
        """The measured state at every window's start, rows [z, z'] (1-D ``z``, ``v``) or [z_1..z_N, z'_1..z'_N]
        ((N, T) channels).
        """
        z, v = np.asarray(z), np.asarray(v)
        if z.ndim == 1:
            return np.column_stack([z[self.starts], v[self.starts]])
        return np.hstack([z[:, self.starts].T, v[:, self.starts].T])


def restart_windows(n: int, fs: float, window_s: float, *, start: int = 0, extra: int = 0, min_step: int = 1,
                    max_windows: int | None = None) -> RestartWindows:  # fmt: skip
    """The restarted windows over samples [``start``, ``n``) of a record sampled at ``fs``: one every
    ``window_s`` seconds (``round(window_s fs)`` samples, at least ``min_step``), each spanning that step and
    ``extra`` more samples (a structure's windows end on the next one's first sample: ``extra=1``), as many as
    fit whole; at most ``max_windows``, then picked evenly over the span (every regime the record visits seen).

    The callers' settings are theirs: a single DOF's held-out validation (``restarted_free_runs``: 2 s windows
    from the split), a structure's (``restarted_structure_runs``: 0.25 s, at least 8 samples, ``extra=1``),
    the hybrid's gap (``hybrid.Hybrid.restarted_gap``, as the single DOF's) and the posterior's likelihood
    windows (``posterior.windows.Windows.cut``: 0.125 s over the whole record, ``max_windows``).
    """
    step = max(int(min_step), int(round(window_s * fs)))
    length = step + int(extra)
    count = (n - start - length) // step + 1 if n - start >= length else 0
    picks = np.arange(count)
    if max_windows is not None and count > max_windows:
        picks = np.unique(np.round(np.linspace(0, count - 1, max_windows)).astype(int))
    return RestartWindows(start + step * picks, length, step)


def simulate_windows(model: Model, rec: Measurement, windows: RestartWindows, zs: np.ndarray, v: np.ndarray,
                     **limits: Unpack[Limits]) -> SimulationResult:  # fmt: skip
    """``model``'s free runs over ``windows`` of ``rec``, each restarted from the measured state (``zs``, ``v``)
    at its start, in one batched simulation: the input at every stage time (``staged_windows``).
    """
    n_win = len(windows)
    U, sub = staged_windows(model, rec, windows.starts, windows.length)
    P = np.repeat(model.kernel_params()[:, None], n_win, axis=1)
    return simulate_batch(P, model.kind, U, rec.dt, windows.start_states(zs, v), input_kind=rec.input_name,
                          input_index=np.arange(n_win), substeps=sub, staged=True, **limits)  # fmt: skip


PREDICTABILITY_FRACTION = 0.1
"""The record's predictability horizon (``predictability``) is the time by which runs restarted from state
estimates that differ by their noise have parted by this fraction of the motion's amplitude (pooled over restarts:
``motion_amplitude``)."""


def motion_amplitude(z: np.ndarray) -> float:
    """The motion's amplitude [m]: half the range between z's 5 and 95 % quantiles (a sine's amplitude within 1.3 %),
    the scale the predictability's runs part on. Where z's zero lies does not matter: its rms about zero, the scale
    before, moved a chaotic record's horizon from 0.40 s to 0.58 s with z read 50 mm lower (measured).
    """
    lo, hi = np.quantile(np.asarray(z, float), [0.05, 0.95])
    return float(hi - lo) / 2


def start_noise(rec: Measurement) -> tuple[float, float]:
    """The noise of a restarted run's start state: the displacement's sensor noise [m] and the state velocity's
    predicted noise [m/s] (``Measurement.states``' ``noise_std`` and ``velocity_noise_std``; 0 where not finite).
    """
    _, _, _, info = rec.states("state")
    sz, sv = (float(info[k]) if np.isfinite(info[k]) else 0.0 for k in ("noise_std", "velocity_noise_std"))
    return sz, sv


def parting_sample(model: Model, rec: Measurement, windows: RestartWindows, z0: np.ndarray, v0: np.ndarray, n_id: int,
                   draws: int, min_pairs: int) -> int | None:  # fmt: skip
    """The first sample at which ``model``'s runs from ``windows``' start states (``z0``, ``v0``: the record's
    states) and from those states moved by ``draws`` draws of their noise each (``start_noise``; seeded, the same
    draws for every model) part by more than ``PREDICTABILITY_FRACTION`` of the amplitude of the record's first
    ``n_id`` samples (``motion_amplitude``: where z's zero lies does not matter), their rms separation pooled over
    the windows and the draws; None where they never do or fewer than ``min_pairs`` pairs ran without diverging.
    """
    sz, sv = start_noise(rec)
    rng = np.random.default_rng(0)
    dz, dv = (scale * rng.standard_normal((draws, len(windows))) for scale in (sz, sv))
    a = simulate_windows(model, rec, windows, z0, v0)
    seps = []
    for k in range(draws):  # every window's start state moved by one draw at a time
        zp, vp = z0.copy(), v0.copy()
        zp[windows.starts] += dz[k]
        vp[windows.starts] += dv[k]
        b = simulate_windows(model, rec, windows, zp, vp)
        ok = ~a.diverged & ~b.diverged
        seps.append(a.z[ok] - b.z[ok])
    sep = np.concatenate(seps)
    if sep.shape[0] < min_pairs:
        return None
    limit = PREDICTABILITY_FRACTION * motion_amplitude(rec.displacement[:n_id])
    over = np.sqrt(np.mean(sep**2, axis=0)) > limit
    return int(np.argmax(over)) if over.any() else None


def predictability(model: Model, rec: Measurement, n_id: int, window_s: float, z0: np.ndarray,
                   v0: np.ndarray) -> dict[str, Any]:  # fmt: skip
    """How long ``model``'s runs restarted from the record's states (``z0``, ``v0``) stay predictable: pairs of
    runs restarted every ``window_s / 20`` over the first ``n_id`` samples, one from the measured state and one
    from that state moved by a draw of its noise (the displacement's sensor noise and the state velocity's
    predicted noise, ``Measurement.states``' ``noise_std`` and ``velocity_noise_std``; seeded), for at most
    ``window_s / 2``; the horizon is the first time their rms separation, pooled over the pairs, exceeds
    ``PREDICTABILITY_FRACTION`` of the part's amplitude (``motion_amplitude``). A run restarted from noisy states
    misses by that much
    however right its model: a window longer than this scores chaos, not the model (measured: where an end
    stop acted, the true model's own 1 s runs missed by 103-114 % and by 2-3 % over their first 0.25 s).
    Returns ``{"horizon_s", "window_s"`` (the windows that score a model: the horizon, at most ``window_s / 2``
    and at least 8 samples), ``"limited"`` (whether the horizon shortened it), ``"restarts"``, ``"fraction"``,
    ``"method"}``.
    """
    cap = max(8, int(round(window_s * rec.fs / 2)))
    sz, sv = start_noise(rec)
    every = restart_windows(n_id, rec.fs, window_s / 20, min_step=1)
    windows = RestartWindows.at(every.starts[every.starts + cap <= n_id], cap)
    out: dict[str, Any] = {"horizon_s": cap / rec.fs, "window_s": cap / rec.fs, "limited": False,
                           "restarts": len(windows), "fraction": PREDICTABILITY_FRACTION}  # fmt: skip
    out["method"] = (f"pairs of the baseline's runs restarted every {window_s / 20:g} s over the "
                     f"identification part, one from a state moved by its noise ({1e6 * sz:.3g} um, "
                     f"{1e3 * sv:.3g} mm/s rms): the "
                     f"time their pooled rms separation exceeds {100 * PREDICTABILITY_FRACTION:g} % of z's amplitude "
                     f"(half its 5-95 % range), at most {cap / rec.fs:g} s")  # fmt: skip
    if len(windows) < 2:
        return out
    parted = parting_sample(model, rec, windows, z0, v0, n_id, draws=1, min_pairs=2)
    if parted is not None:
        out.update(horizon_s=parted / rec.fs, window_s=max(8, parted) / rec.fs, limited=True)
    return out


def staged_windows(system, rec: Measurement, starts: np.ndarray, length: int,
                   substeps: int | None = None) -> tuple[np.ndarray, int]:  # fmt: skip
    """The input of windows [s, s + length) of ``rec`` at every stage time (rows for
    ``simulate_batch(..., staged=True)``) and the substeps they are staged for (``substeps``, else
    ``record_substeps``'). The span the windows cover is interpolated as one signal (no edge effect at a
    window's start).
    """
    sub = record_substeps(system, rec) if substeps is None else int(substeps)
    r = 2 * sub
    lo, hi = int(np.min(starts)), int(np.max(starts)) + length
    us = rec.staged(system, sub, lo, hi)  # the input plus any measured channel's term
    return np.stack([us[r * (s - lo) : r * (s - lo + length - 1) + 1] for s in starts]), sub


def free_run_rms(model: Model, rec: Measurement, skip: int = 0, x0=None) -> float:
    """Rms of the free-run simulation error over ``rec`` (started at its measured state, or ``x0``),
    the first ``skip`` samples not scored (the benchmarks' transient); inf if the run diverged.
    """
    zs, vs, _, _ = rec.states("state")
    if x0 is None:
        x0 = (zs[0], vs[0])
    res = simulate_record(model, rec, x0, **divergence_limits(rec.displacement, vs))
    if res.diverged[0]:
        return math.inf
    return float(np.sqrt(np.mean((res.z[0, skip:] - rec.displacement[skip:]) ** 2)))


def validate(model: Model, rec: Measurement, start: int, window_s: float = 2.0) -> dict[str, Any]:
    """Free-run validation of ``model`` with the measured input over samples [start, N).

    ``rms_percent`` (the contract's): one free run from the measured state at ``start``
    (Savitzky-Golay z, z'), 100 rms(z_sim - z) / rms(z). Over cross-well records this long run
    diverges even for the true model once the motion is chaotic (device-model.md), so
    ``restarted_rms_percent`` adds free runs of ``window_s`` restarted from the measured state at the
    start of each window (z, z' from the Savitzky-Golay window of least predicted velocity error; all
    windows in one batched simulation): a gap chaos cannot fake.
    """
    tail = rec.segment(start, rec.n)
    if tail.n < 10:
        raise MeasurementError(f"{rec.source}: too few samples for the validation segment ({tail.n})")
    # the measured states free runs start from: the least-error velocity (derivatives.py)
    zs, v, _, _ = rec.states("state")
    sim = simulate_record(model, tail, (float(zs[start]), float(v[start])), **divergence_limits(rec.displacement, v))
    z_sim = sim.z[0]
    out: dict[str, Any] = {
        "segment": [float(tail.t0), float(tail.t0 + tail.duration)],
        "diverged": bool(sim.diverged[0]),
    }
    if sim.diverged[0]:
        out.update(
            rms_percent=float("inf"),
            residual_mean=float("nan"),
            residual_std=float("nan"),
            warning=f"free run diverged: {sim.describe_failures()}",
        )
    else:
        r = z_sim - tail.z
        out.update(
            rms_percent=float(100 * np.sqrt(np.mean(r**2)) / np.sqrt(np.mean(tail.displacement**2))),
            residual_mean=float(r.mean()),
            residual_std=float(r.std()),
            z_sim=z_sim,
            z_meas=tail.z,
            t=tail.t,
        )
    out.update(restarted_free_runs(model, rec, start, window_s, zs, v))
    return out


def restarted_free_runs(
    model: Model, rec: Measurement, start: int, window_s: float, zs: np.ndarray, v: np.ndarray
) -> dict[str, Any]:
    """Free runs of ``window_s`` seconds over [start, N), each restarted from the measured state
    (``zs``, ``v``: the record's smoothed displacement and velocity): ``restart_windows``' windows,
    ``simulate_windows``' runs.
    """
    windows = restart_windows(rec.n, rec.fs, window_s, start=start)
    n_win = len(windows)
    if n_win < 1:
        return {}
    res = simulate_windows(model, rec, windows, zs, v)
    meas = windows.measured(rec.displacement)
    ok = ~res.diverged
    window_ms = np.full(n_win, np.nan)  # per-window mean square error (nan: diverged), an array: not in JSON
    window_ms[ok] = np.mean((res.z[ok] - meas[ok]) ** 2, axis=1)
    if not ok.any():
        return {
            "restarted_rms_percent": float("inf"),
            "restart_window_s": window_s,
            "restart_windows": int(n_win),
            "window_ms": window_ms,
        }
    err = res.z[ok] - meas[ok]
    return {
        "restarted_rms_percent": float(100 * np.sqrt(np.mean(err**2)) / np.sqrt(np.mean(meas[ok] ** 2))),
        "restart_window_s": window_s,
        "restart_windows": int(n_win),
        "restart_diverged": int((~ok).sum()),
        "window_ms": window_ms,
    }


STRUCTURE_WINDOW_S = 0.25
"""A structure's restarted windows [s] (``restarted_structure_runs``; ``identification.WINDOW_S``)."""


def structure_windows(rec: Measurement, place: tuple[int, int], start: int, window_s: float = STRUCTURE_WINDOW_S,
                      between_pulses: bool = False) -> tuple[RestartWindows, np.ndarray, np.ndarray]:  # fmt: skip
    """A structure's restarted windows over the record from sample ``start`` on (``restarted_structure_runs``'), and
    the channels' band-smoothed displacements and velocities (N, T) the runs start from (``channel_states`` of the
    element at ``place``); one ``MeasurementError`` where the part holds no window.
    """
    # each channel's least-error state, as the single DOF's runs start from (``free_run_states``): the band-smoothed
    # states (``channel_states``, NSI's) started the device on its base as a structure of one DOF 2.5x further off
    # its record than its own runs (0.5 s windows of a 30 s rig record: median 1.03 % against 0.42 %; measured)
    zs, v = rec.free_run_states()
    # windows of L + 1 samples, each ending on the next one's start
    windows = restart_windows(rec.n, rec.fs, window_s, start=start, extra=1, min_step=8)
    if between_pulses:
        lead = max(derivative_window(zi, rec.fs, "state", floor=noise_floor(zi, rec.fs))[0] for zi in rec.channels)
        lead = max(lead, rec.channel_states(place)[2][0]) // 2
        busy = np.concatenate([[0], np.cumsum(np.asarray(rec.u) != 0)])
        lo = np.maximum(windows.starts - lead, 0)
        quiet = busy[windows.starts + windows.length] == busy[lo]
        windows = RestartWindows.at(windows.starts[quiet], windows.length)
    if not windows.starts.size:
        if between_pulses:
            raise MeasurementError(f"{rec.source}: the held-out part holds no {window_s} s window between the hammer's "
                                   "pulses")  # fmt: skip
        raise MeasurementError(f"{rec.source}: the held-out part is shorter than one {window_s} s window")
    return windows, zs, v


def structure_window_errors(structures, rec: Measurement, windows: RestartWindows, zs: np.ndarray, v: np.ndarray,
                            offsets=None) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Each of ``structures``' run errors in every window (``structure_windows``), (S, W, N, L + 1) [m] in the
    record's frame (``offsets``: each channel's zero), and which runs diverged (S, W): one batch of S x W runs.
    """
    structures = list(structures)
    o = np.zeros(rec.n_dof) if offsets is None else np.asarray(offsets, float)
    n_s, n_w = len(structures), windows.starts.size
    x0 = windows.start_states(zs - o[:, None], v)
    # the input at every stage time, band-limited as a lab's record's is (``stage_input``), as the single DOF's runs
    # read it (``staged_windows``)
    U, _ = staged_windows(structures[0], rec, windows.starts, windows.measured(rec.u).shape[1], DEFAULT_SUBSTEPS)
    res = simulate_structures(structures, U, rec.dt, np.tile(x0, (n_s, 1)),
                              input_kind=rec.input_name, force_dof=rec.force_dof,
                              input_index=np.tile(np.arange(n_w), n_s),
                              structure_index=np.repeat(np.arange(n_s), n_w), staged=True)  # fmt: skip
    z = res.z.reshape(n_s, n_w, rec.n_dof, -1)
    return z + o[None, None, :, None] - windows.measured(rec.channels)[None], res.diverged.reshape(n_s, n_w)


def channel_scales(rec: Measurement, start: int) -> np.ndarray:
    """Each channel's rms about its mean from sample ``start`` on (N,) [m]: the measure a structure's held-out errors
    are given in (``restarted_structure_runs``, the discrepancy's opinions).
    """
    z_all = rec.channels
    centred = z_all[:, start:] - z_all[:, start:].mean(axis=1, keepdims=True)
    return np.sqrt(np.mean(centred**2, axis=1))


def restarted_structure_runs(structure: Structure, rec: Measurement, start: int, window_s: float = STRUCTURE_WINDOW_S,
                             offsets=None, between_pulses: bool = False,
                             per_window: bool = False) -> dict[str, Any]:  # fmt: skip
    """The restarted windows of a structure of N >= 1 DOFs (a single DOF as ``Structure.single(model)``; the
    estimators' ``free_run_error``): free runs of ``structure`` over the record from sample ``start`` on,
    restarted every ``window_s`` from the record's band-smoothed states: rms error over every DOF in % of the
    responses' rms, and per DOF, with the same measure of the channels' sensor noise alone
    (``noise_floor_percent``: what a perfect model misses). The record's channels are ``offsets`` [m] (each
    channel's zero, default none) above the structure's frame. ``between_pulses``: a hammer's record, its force
    windowed (zero between the pulses, ``record_kind.identification_record``): only the windows whose input is zero
    from half the states' smoothing window before their start to their end, each a free decay from a state no
    pulse smoothed (a pulse of a few samples is not resolved by the runs' input between samples, as the single
    DOF's windows restart after it). ``per_window``: also each window's mean square error in those units
    (``window_ms``, NaN where its run diverged: an array, not for a result's JSON), as the single DOF's ``validate``
    gives them (the refinement's paired comparison, ``refine.refine_stage``).
    """
    o = np.zeros(rec.n_dof) if offsets is None else np.asarray(offsets, float)
    windows, zs, v = structure_windows(rec, structure.place, start, window_s, between_pulses)
    starts = windows.starts
    err, diverged = structure_window_errors([structure], rec, windows, zs, v, o)
    err, ok = err[0], ~diverged[0]
    scale = channel_scales(rec, start)
    noise = rec.channel_noise()
    floor = 100 * float(np.sqrt(np.mean((noise / scale) ** 2)))
    window_ms = np.full(starts.size, np.nan)
    window_ms[ok] = np.mean((err[ok] / scale[None, :, None]) ** 2, axis=(1, 2))
    extra = {"window_ms": window_ms} if per_window else {}
    if not ok.any():
        return {"rms_percent": math.inf, "per_dof_percent": [math.inf] * rec.n_dof, "windows": int(starts.size),
                "diverged": int(starts.size), "window_s": window_s, "noise_floor_percent": floor, **extra}  # fmt: skip
    per = np.sqrt(np.mean(err[ok] ** 2, axis=(0, 2))) / scale
    total = float(np.sqrt(np.mean((err[ok] / scale[None, :, None]) ** 2)))
    return {"rms_percent": 100 * total, "per_dof_percent": (100 * per).tolist(), "windows": int(starts.size),
            "diverged": int((~ok).sum()), "window_s": window_s, "noise_floor_percent": floor, **extra}  # fmt: skip


def residual_psd(rec: Measurement, model: Model, start: int, window_s: float = 2.0):
    """PSD of the restarted free runs' residual over [start, end): (f, P)."""
    zs, v, _, _ = rec.states("state")
    windows = restart_windows(rec.n, rec.fs, window_s, start=start)
    res = simulate_windows(model, rec, windows, zs, v)
    meas = windows.measured(rec.displacement)
    ok = ~res.diverged
    f, p = signal.welch(meas[ok] - res.z[ok], rec.fs, nperseg=min(windows.length, 512), axis=1)
    return f, p.mean(axis=0)


STROKE_MARGIN = 0.5
"""How far beyond the recorded stroke a model's potential must keep confining the motion, as a fraction
of the stroke's span."""
INPUT_MARGIN = 1.2
"""The training input is scaled by this in the boundedness free run (the issue's amplitude margin)."""


def boundedness(system, rec: Measurement, margin: float = STROKE_MARGIN, input_margin: float = INPUT_MARGIN,
                free_run: bool = True, offsets=None) -> dict[str, Any]:  # fmt: skip
    """Whether ``system`` stays bounded where ``rec`` took it, and a little beyond.

    A structure's (``Structure``: ``offsets`` its channels' zeros) is its element's: the stroke is the element's
    relative motion, the force its law, the input's static part that on the element's DOF, and the free run the
    structure's from the record's start state (``element_motion``).

    * ``over_stroke``: beyond the stroke the record visited [z_lo, z_hi], over ``margin`` of its span on
      each side, the effective potential (the restoring force less the input's static part, integrated)
      never falls below its lowest value inside the stroke while the force pushes outward: no model
      term opens an escape just past where the data stopped (a fitted z^4 or negative z^5 does, and a
      free run that strays there never comes back).
    * ``globally``: the restoring force confines at infinity (K -> +inf as z -> +inf, -inf as z -> -inf);
      reported, not required: a polynomial fitted over a stroke need not hold far outside it.
    * ``free_run``: a free run under the record's input scaled by ``input_margin`` from its measured
      start state stays within ten times the record's stroke and speed (``divergence_limits``).

    ``ok`` is ``over_stroke and not diverged``.

    Kept with ``rec`` (a segment is the same object for the same span) for ``system`` (the same object): a fit asks
    it of its final model on its identification part twice (the law's checks or the refinement's judge, then the
    result); a copy is returned.
    """
    key = ("boundedness", id(system), margin, input_margin, free_run,
           None if offsets is None else tuple(np.asarray(offsets, float).tolist()))  # fmt: skip
    hit = rec.derived.get(key)
    if hit is not None and hit[0] is system:
        return copy.deepcopy(hit[1])
    out = _boundedness(system, rec, margin, input_margin, free_run, offsets)
    rec.derived[key] = (system, out)
    return copy.deepcopy(out)


def _boundedness(system, rec: Measurement, margin: float, input_margin: float, free_run: bool,
                 offsets) -> dict[str, Any]:  # fmt: skip
    law, z = element_motion(system, rec, offsets)
    lo, hi = float(np.min(z)), float(np.max(z))
    span = max(hi - lo, 1e-12)
    mass = float(getattr(law, "m", 1.0))
    f_static = float(mass * input_gain_of(rec.input_name, mass) * np.mean(rec.u))
    grid = np.linspace(lo - margin * span, hi + margin * span, 2001)
    k = _force_or_nan(law, grid) - f_static
    inside = (grid >= lo) & (grid <= hi)
    escape = None
    reach = np.isfinite(k)  # a device's rods reach only so far: beyond them nothing escapes
    if not reach[inside].all():
        escape = float(grid[inside & ~reach][0])
    else:
        grid, k, inside = grid[reach], k[reach], inside[reach]
        from scipy.integrate import cumulative_trapezoid

        v = cumulative_trapezoid(k, grid, initial=0.0)
        floor = v[inside].min()
        above = (grid > hi) & (k < 0) & (v < floor)  # pushed outward, lower than anywhere inside
        below = (grid < lo) & (k > 0) & (v < floor)
        hits = grid[above | below]
        if hits.size:
            escape = float(hits[np.argmin(np.abs(hits - 0.5 * (lo + hi)))])
    far = 0.5 * (lo + hi) + np.array([-1.0, 1.0]) * 1e3 * span
    kf = _force_or_nan(law, far) - f_static
    out: dict[str, Any] = {
        "stroke_m": [lo, hi],
        "margin": margin,
        "over_stroke": escape is None,
        "escape_z": escape,
        # a device whose rods cannot reach far out is confined by its geometry
        "globally": bool(np.all(np.isnan(kf)) or (np.all(np.isfinite(kf)) and kf[0] < 0 < kf[1])),
    }
    diverged = False
    if free_run:
        if isinstance(system, Structure):
            o = _offsets(system, offsets)
            zs, vs = rec.free_run_states()
            x0 = np.concatenate([zs[:, 0] - o, vs[:, 0]])[None, :]
            sub = record_substeps(system, rec)  # the step refined for a fast mode, as a single DOF's run is
            res = simulate_structures(system, _scaled_staged(rec, system.element, sub, input_margin)[None], rec.dt, x0,
                                      input_kind=rec.input_name, force_dof=rec.force_dof, substeps=sub, staged=True,
                                      **divergence_limits(rec.channels - o[:, None], vs))  # fmt: skip
        else:
            zs1, vs1, _, _ = rec.states("state")
            limits = divergence_limits(z, vs1)
            if measured_channels(getattr(system, "extra", {})):  # a measured channel's term is not scaled
                scaled = dataclasses.replace(rec, u=input_margin * np.asarray(rec.u, float))
                res = simulate_record(system, scaled, (zs1[0], vs1[0]), **limits)
            else:
                sub = record_substeps(system, rec)
                u = _scaled_staged(rec, system, sub, input_margin)
                res = simulate_record(system, rec, (zs1[0], vs1[0]), substeps=sub, staged_input=u, **limits)
        diverged = bool(res.diverged[0])
        out.update(input_margin=input_margin, diverged_at_margin=diverged)
    out["ok"] = bool(out["over_stroke"] and not diverged)
    if not out["ok"]:
        why = []
        if escape is not None:
            why.append(
                f"its potential opens an escape at z = {escape:.4g} m, just past the stroke [{lo:.4g}, {hi:.4g}] m"
            )
        if diverged:
            why.append(f"it diverges under the record's input scaled by {input_margin:g}")
        out["warning"] = "the model is not bounded where the record went: " + "; ".join(why)
    return out


def _scaled_staged(rec: Measurement, law, substeps: int, factor: float) -> np.ndarray:
    """``rec``'s input scaled by ``factor`` at every Runge-Kutta stage time: the record's own staged input (kept with
    it, ``Measurement.staged``) scaled, the staging being linear (a band-limited resampling), in place of staging the
    scaled input again (32 of a boundedness check's 41 ms on a 240 s record, measured; equal to rounding). ``law``
    with a measured channel's term: the input alone, staged anew.
    """
    if measured_channels(getattr(law, "extra", {})):
        return stage_input(factor * np.asarray(rec.u, float), substeps)
    return factor * rec.staged(law, substeps)


def _offsets(structure: Structure, offsets) -> np.ndarray:
    return np.zeros(structure.n_dof) if offsets is None else np.asarray(offsets, float)


def element_motion(system, rec: Measurement, offsets=None) -> tuple[Any, np.ndarray]:
    """The force law whose stroke bounds ``system`` and the motion it acts on over ``rec``: a single DOF's model
    and z; a structure's element and its relative motion z_J - z_I (the channels less their zeros ``offsets``).
    """
    if isinstance(system, Structure):
        return system.element, relative(rec.channels - _offsets(system, offsets)[:, None], system.place)
    return system, np.asarray(rec.z, float)


def input_gain_of(input_kind: str, mass: float) -> float:
    """W in z'' = ... + w u for one model (``simulator.input_gain`` for a scalar mass)."""
    return float(input_gain(input_kind, np.array([mass]))[0])


def _force_or_nan(system, z: np.ndarray) -> np.ndarray:
    """K(z), nan where the system cannot go (a device's geometric stroke)."""
    with np.errstate(all="ignore"):
        try:
            return np.asarray(system.restoring_force(z), float)
        except ValueError:
            out = np.full(z.shape, np.nan)
            for i, zi in enumerate(z):
                try:
                    out[i] = float(system.restoring_force(zi))
                except ValueError:
                    pass
            return out
