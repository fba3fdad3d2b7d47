"""Multiple-shooting windows of a record: the batched simulation, start states and the dropping of windows
the model cannot follow (the likelihood's data).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import fft as sp_fft
from scipy.optimize import minimize_scalar

from negstiff.errors import MeasurementError
from negstiff.inference.record.measurement import Measurement
from negstiff.inference.steps.validation import restart_windows
from negstiff.models import simulate_batch

COEFFICIENT_NAMES = ("k1", "k2", "k3", "c", "c_nl", "sigma")
DEVICE_NAMES = ("E", "alpha_deg", "m", "c", "c_nl", "sigma")
DROP_FACTOR = 5.0
"""A window whose residual at the start model exceeds this multiple of the median window's is dropped
(``Windows.drop_unmatched``)."""
DROP_FACTOR_AT_MAP = 3.0
"""The same, at the MAP point, where every window the model follows is matched to the noise."""
NOISE_RANK_TOL = 1e-4
"""An input-noise variance below this share of the sensor's is left out of the likelihood's product
(``Windows.set_input_noise``)."""
SIGMA_BOUNDS = (1e-10, 1e-2)
"""Log-uniform prior on the displacement noise [m] (0.1 nm to 1 cm). A displacement a record derives from a
vibrometer's velocity carries far less white noise than a laser's (the integral's noise falls with frequency): on
the benchmark's 396 s vibrometer record of a bistable harvester (``benchmarks/waits.py``, 0.1 mm/s of velocity
noise at 2048 Hz) the noise the MAP point reads was 45 nm, and a floor at 0.1 um had put the MAP point outside
the prior's support (its posterior refused with no point to start from, measured)."""


class PosteriorError(MeasurementError):
    """The record cannot support a posterior (too short, diverging model at the start point)."""


# ------------------------------------------------------------------------------------------------
# Windows and the batched likelihood
# ------------------------------------------------------------------------------------------------
SUBSTEP_SHIFT_SD = 0.1
"""The forward model's own discretisation error may move the MAP point by at most this share of its
standard deviation (``Windows.resolve_substeps`` doubles the RK4 steps per sample until it does not)."""


def between_pulses(rec: Measurement, index: np.ndarray, window_s: float) -> np.ndarray:
    """Which windows (rows of sample indices ``index``) of a ring-down's record have a zero input throughout: the
    windows between a hammer's pulses (its force windowed, ``record_kind.identification_record``), every window of
    a free decay. One ``PosteriorError`` when fewer than 4 do.
    """
    quiet = ~np.any(np.asarray(rec.u)[index] != 0.0, axis=1)
    if int(quiet.sum()) < 4:
        raise PosteriorError(
            f"{rec.source}: {int(quiet.sum())} of the {len(index)} windows of {window_s:g} s lie between the "
            "hammer's pulses: a ring-down's posterior needs 4 at least"
        )
    return quiet


def _profiled_sigma2(y2: np.ndarray, lam: np.ndarray, s0: float) -> float:
    """The sensor variance [m^2] maximising the likelihood of squared residuals ``y2`` along directions whose
    input-noise variances are ``lam`` (each direction's variance lam + sigma^2); ``s0``, the residuals' mean square,
    brackets the search (12 decades below it to e above).
    """

    def nll(log_s2):
        v = lam + np.exp(log_s2)
        return float(np.sum(np.log(v) + y2 / v))

    sol = minimize_scalar(nll, bounds=(np.log(s0) - 12.0, np.log(s0) + 1.0), method="bounded")
    return float(np.exp(sol.x))


@dataclass
class Windows:
    """Multiple-shooting windows of a record."""

    dt: float
    input_kind: str
    u: np.ndarray  # (W, L) input of each window
    z: np.ndarray  # (W, L) measured z
    x0: np.ndarray  # (W, 2) measured start states
    proj: np.ndarray | None = None  # (W, L, 2) orthonormal basis of the start-state sensitivities
    substeps: int = 1  # RK4 steps per (oversampled) interval
    oversample: int = 1  # the input is interpolated band-limited to oversample x fs before simulation
    threads: int | None = None  # simulator threads (None: the machine's cores)
    starts: np.ndarray | None = None  # (W,) first sample of each window in the record
    dropped: list[tuple[float, float]] = field(default_factory=list)  # (start [s], rms residual [m]) of dropped windows
    noise_basis: np.ndarray | None = None  # (W, L - 2, L): each window's input-noise eigenbasis (``set_input_noise``)
    noise_var: np.ndarray | None = None  # (W, L - 2): the input noise's variance [m^2] along it
    noise_rank: int = 0  # the directions (the last of ``noise_basis``) whose input-noise variance counts
    _basis_t: np.ndarray | None = field(default=None, repr=False)  # their basis, transposed and contiguous
    groups: np.ndarray | None = None  # (W,) the record each window is of (``joined``: several records); None: one

    @classmethod
    def joined(cls, parts: list[Windows]) -> Windows:
        """The windows of several records of one device as one set (a lab's runs fitted together): each record's
        windows cut as its own (its input, start states and dropped windows), ``groups`` naming the record of each,
        so that each record keeps its own sensor noise (``n_groups`` sigmas in the likelihood). The records share
        the sampling step, window length, kind of input and oversampling (``Posterior.check`` refuses others).
        """
        first = parts[0]
        starts = [p.starts if p.starts is not None else np.zeros(p.n_windows, int) for p in parts]
        return cls(
            first.dt, first.input_kind, np.concatenate([p.u for p in parts]), np.concatenate([p.z for p in parts]),
            np.concatenate([p.x0 for p in parts]), oversample=first.oversample, threads=first.threads,
            starts=np.concatenate(starts),
            groups=np.concatenate([np.full(p.n_windows, g) for g, p in enumerate(parts)]),
        )  # fmt: skip

    @property
    def n_groups(self) -> int:
        """The records the windows are of (each its own sensor noise): 1 for one record's."""
        return 1 if self.groups is None else int(self.groups.max()) + 1

    def per_window(self, values) -> np.ndarray:
        """Per-record values (a scalar, (R,), or (P, R) for P parameter sets) spread to the windows: (W,) or
        (P, W); a scalar or a single record's stays as it is (broadcast).
        """
        v = np.asarray(values, float)
        if self.groups is None or v.ndim == 0 or v.shape[-1] == 1:
            return v
        return v[..., self.groups]

    def dof_groups(self) -> np.ndarray:
        """Each record's degrees of freedom (``dof`` split over ``groups``): (R,)."""
        per = self.length - (0 if self.proj is None else self.proj.shape[-1])
        if self.groups is None:
            return np.array([self.n_windows * per])
        return np.bincount(self.groups, minlength=self.n_groups) * per

    @property
    def n_windows(self) -> int:
        """The number of windows."""
        return self.z.shape[0]

    @property
    def length(self) -> int:
        """The samples per window."""
        return self.z.shape[1]

    @staticmethod
    def check(rec: Measurement, window_s: float) -> tuple[int, int]:
        """(samples per window, windows in the record), or a ``PosteriorError`` where there are too few."""
        L = int(round(window_s * rec.fs))
        if L < 8:
            raise PosteriorError(f"{rec.source}: window of {window_s} s holds fewer than 8 samples")
        n_win = rec.n // L
        if n_win < 4:
            raise PosteriorError(
                f"{rec.source}: too few samples for a posterior: {rec.n} ({rec.duration:.3g} s), need at least "
                f"{4 * L} (4 windows of {window_s:g} s)"
            )
        return L, n_win

    @classmethod
    def cut(cls, rec: Measurement, window_s: float, max_windows: int | None = None, oversample: int = 1,
            free: bool = False) -> Windows:  # fmt: skip
        """The record's windows of ``window_s`` seconds (at most ``max_windows``, evenly picked).

        ``free``: a ring-down's record (a free decay, or a hammer's with its force windowed: zero between the
        pulses, ``record_kind.identification_record``): only the windows whose input is zero throughout, each a free
        decay from its start state (``free_windows``).
        """
        L, _ = cls.check(rec, window_s)
        # the record's restarted windows (``validation.restart_windows``), at most ``max_windows`` evenly spread over
        # the whole record (not its first part): every regime it visits is seen
        windows = restart_windows(rec.n, rec.fs, window_s, max_windows=max_windows)
        zs, v, _, _ = rec.states("state")
        if free:
            return cls.free_windows(rec, windows, zs, v, window_s)
        starts, idx = windows.starts, windows.index
        q = int(oversample)
        if q == 1:
            # RK4 with the simulator's linearly interpolated input averages the input over a step like
            # the trapezoid rule; a band-limited input's right average is Simpson's. Their ratio for
            # exp(i w t) is (2 + cos(w h/2)) / (3 cos(w h/2)): the input is pre-emphasised by it (below
            # 0.4 fs). Measured on noise-free records: the same parameter errors (<= 0.008 %) as a 4x
            # band-limited oversampled simulation, at a quarter of its cost; without it c is 0.2 % low.
            f = np.fft.rfftfreq(rec.n, rec.dt)
            x = np.pi * f * rec.dt
            gain = np.where(f < 0.4 * rec.fs, (2 + np.cos(x)) / (3 * np.cos(x)), 1.0)
            u = sp_fft.irfft(sp_fft.rfft(rec.u) * gain, rec.n)[idx]
        else:
            from scipy import signal

            # band-limited (FFT) interpolation of the input: the acquisition's anti-aliasing filter made
            # it band-limited; a polyphase FIR interpolator (resample_poly's Kaiser window) biased c by
            # 0.06 % and k2 by 1.3 % on exact data (measured), the FFT interpolation by < 1e-5
            u_fine = signal.resample(rec.u, q * rec.n)
            u = u_fine[q * starts[:, None] + np.arange(q * L)[None, :]]
        return cls(
            rec.dt,
            rec.input_name,
            u,
            windows.measured(rec.displacement),
            windows.start_states(zs, v),
            oversample=q,
            starts=starts,
        )

    @classmethod
    def free_windows(cls, rec: Measurement, windows, zs: np.ndarray, v: np.ndarray, window_s: float) -> Windows:
        """A ring-down's windows (``cut`` with ``free``): those whose input is zero throughout, each a free decay
        from its start state (a nuisance parameter, as every window's), the input zero in the simulation.

        A hammer's pulse lasts a few samples (4 ms at 1 kHz: four), which the sampled force does not resolve for
        the simulator's interpolated input: with the true model a window holding a hit missed its record by 50x the
        others' rms (1.5e-4 against 3e-6 m, a Duffing at 1 um, measured), so the windows with a pulse are left out
        (``drop_unmatched`` left a crash in the step-size check). Between the pulses the likelihood is exact: the
        hits set the start states, the windows read the ring-down. The band-limiting pre-emphasis of ``cut`` is
        not applied: on the windowed force it rings (5 mN between 40 N pulses, 4 um of static response).
        """
        quiet = between_pulses(rec, windows.index, window_s)
        z = windows.measured(rec.displacement)[quiet]
        return cls(rec.dt, rec.input_name, np.zeros_like(z), z, windows.start_states(zs, v)[quiet],
                   starts=windows.starts[quiet])  # fmt: skip

    def simulate(self, params: np.ndarray, kind: str, x0: np.ndarray | None = None):
        """Every window under every parameter column: (P, W, L) z and (P,) diverged."""
        P = params.shape[1]
        W = self.n_windows
        cols = np.repeat(params, W, axis=1)
        x0 = np.tile(self.x0 if x0 is None else x0, (P, 1))
        res = simulate_batch(
            cols,
            kind,
            self.u,
            self.dt / self.oversample,
            x0,
            input_kind=self.input_kind,
            input_index=np.tile(np.arange(W), P),
            substeps=self.substeps,
            threads=self.threads,
        )
        z = res.z[:, :: self.oversample]
        return z.reshape(P, W, self.length), res.diverged.reshape(P, W).any(axis=1)

    def _state_sensitivities(self, params: np.ndarray, kind: str, dz: float = 1e-6, dv: float = 1e-4):
        base, _ = self.simulate(params[:, None], kind)
        sz, _ = self.simulate(params[:, None], kind, self.x0 + [dz, 0.0])
        sv, _ = self.simulate(params[:, None], kind, self.x0 + [0.0, dv])
        return base[0], np.stack([(sz[0] - base[0]) / dz, (sv[0] - base[0]) / dv], axis=-1)  # (W, L), (W, L, 2)

    def refine_states(self, params: np.ndarray, kind: str, iterations: int = 3) -> None:
        """Gauss-Newton on each window's start state (all windows at once) for the parameters ``params``:
        the profile over the nuisance states, where the first-order projection alone is not enough
        (windows that pass near the saddle, whose response the start state changes a lot).
        """
        for _ in range(iterations):
            base, S = self._state_sensitivities(params, kind)
            r = self.z - base
            ok = np.isfinite(S).all(axis=(1, 2)) & np.isfinite(r).all(axis=1)
            step = np.zeros_like(self.x0)
            for w in np.flatnonzero(ok):
                step[w] = np.linalg.lstsq(S[w], r[w], rcond=None)[0]
            trial = self.x0 + step
            new, _ = self.simulate(params[:, None], kind, trial)
            better = ok & (np.sum((self.z - new[0]) ** 2, axis=1) < np.sum(r**2, axis=1))
            self.x0 = np.where(better[:, None], trial, self.x0)
        self.clear_input_noise()

    def drop_unmatched(self, params: np.ndarray, kind: str, factor: float = DROP_FACTOR) -> int:
        """Drop the windows the model cannot follow from any nearby start state: those whose residual
        (after ``refine_states``) is above ``factor`` times the median window's rms. Such a window starts
        near the saddle: the measured start state's error sends the simulation into the other well, the
        response is not a smooth function of the start state there, and its millimetre residual would
        dominate the fit (measured: on 4 of 40 8-s records one such window pulled the MAP point 5-70
        standard deviations off the truth). With noise alone no window's rms exceeds the median's by
        more than ~25 % (64 samples), so ``factor`` = 5 drops nothing a correct model matches.
        Returns the number dropped; ``dropped`` records where and how large.
        """
        zsim, div = self.simulate(params[:, None], kind)
        rms = np.sqrt(np.mean((self.z - zsim[0]) ** 2, axis=1))
        rms = np.where(np.isfinite(rms), rms, np.inf)
        groups = np.zeros(self.n_windows, int) if self.groups is None else self.groups
        # each record's windows against its own median (a joint fit's records have their own noise)
        median = np.array([np.median(rms[groups == g]) for g in range(self.n_groups)])[groups]
        bad = rms > factor * median
        if not bad.any() or any(bad[groups == g].all() for g in range(self.n_groups)):
            return 0
        if bad.sum() > self.n_windows // 4:
            raise PosteriorError(
                f"{bad.sum()} of {self.n_windows} windows are not matched by the start model (residual above "
                f"{factor:g}x the median window's): the model or the record is far off"
            )
        keep = ~bad
        t0 = (self.starts if self.starts is not None else np.zeros(self.n_windows)) * self.dt
        self.dropped += [(float(t0[w]), float(rms[w])) for w in np.flatnonzero(bad)]
        self.u, self.z, self.x0 = self.u[keep], self.z[keep], self.x0[keep]
        if self.groups is not None:
            self.groups = self.groups[keep]
        if self.starts is not None:
            self.starts = self.starts[keep]
        self.proj = None
        self.clear_input_noise()
        return int(bad.sum())

    def resolve_substeps(self, params: np.ndarray, kind: str, jac: np.ndarray, tol: float = SUBSTEP_SHIFT_SD,
                         most: int = 16) -> bool:  # fmt: skip
        """Double the RK4 steps per interval until the forward model's own discretisation error moves the
        MAP point by less than ``tol`` of its Laplace standard deviation. The error of s steps is estimated
        by the difference of s and 2 s (Richardson: RK4's error falls 16-fold), projected off the start
        states like the residuals, and carried to the parameters by the least-squares Jacobian ``jac``
        (the point estimate's, its scaled coordinates: the ratio to the sd is scale free). A record's
        noise sets how precise the posterior is, so it sets the step too: on a 3 um record of a lightly
        damped cross-well device one step per sample biased k3 by 1.5 sd (measured); noisier records keep
        the one step. Returns whether the steps changed.
        """
        J = np.asarray(jac)
        norms = np.linalg.norm(J, axis=0)
        J = J[:, norms > 1e-6 * norms.max()]  # a direction the windows do not see (a parameter the likelihood
        # holds: its column ~0) has no sd to measure a shift in (it had 1e4 "sd" from a 1e-12 difference)
        r0 = self.residuals(self.simulate(params, kind)[0])[0]
        sigma = np.sqrt(np.sum(r0**2) / self.dof)
        sd = sigma * np.sqrt(np.diag(np.linalg.pinv(J.T @ J)))
        start = self.substeps
        while self.substeps < most:
            s = self.substeps
            self.substeps = 2 * s
            r1 = self.residuals(self.simulate(params, kind)[0])[0]
            shift = np.linalg.lstsq(J, (r1 - r0).ravel(), rcond=None)[0]
            if not np.max(np.abs(shift) / sd) > tol:
                self.substeps = s
                break
            r0 = r1
        if self.substeps != start:
            self.clear_input_noise()
        return self.substeps != start

    def set_sensitivities(self, params: np.ndarray, kind: str) -> None:
        """Orthonormal bases of each window's start-state sensitivities (finite differences)."""
        _, S = self._state_sensitivities(params, kind)
        self.proj = np.linalg.qr(S)[0]
        self.clear_input_noise()  # made for the old basis: ``set_input_noise`` again

    def clear_input_noise(self) -> None:
        """Forget the input-noise term (the likelihood is then the sensor's i.i.d. noise alone): what changes
        the windows (start states, steps, basis, dropped windows) makes it stale.
        """
        self.noise_basis = self.noise_var = self._basis_t = None
        self.noise_rank = 0

    def input_sensitivities(self, params: np.ndarray, kind: str) -> np.ndarray:
        """Each window's response to its own input samples, (W, L, L): G[w, i, j] = dz_i / du_j, by finite
        differences of the batched simulator (one simulation per input sample: W L runs of L samples). With
        ``oversample`` q > 1 a raw sample's perturbation reaches the fine input as a hat of width 2q (linear
        interpolation: the band-limited interpolant's main lobe).
        """
        W, L, q = self.n_windows, self.length, self.oversample
        base, _ = self.simulate(params[:, None], kind)
        scale = float(np.std(self.u)) or 1.0
        du = 1e-3 * scale
        pulse = np.zeros((L, q * L))
        hat = 1.0 - np.abs(np.arange(-q + 1, q)) / q
        for j in range(L):
            lo = q * j - q + 1
            idx = np.arange(lo, lo + hat.size)
            ok = (idx >= 0) & (idx < q * L)
            pulse[j, idx[ok]] = hat[ok]
        u = (self.u[:, None, :] + du * pulse[None]).reshape(W * L, q * L)
        res = simulate_batch(
            np.repeat(params[:, None], W * L, axis=1), kind, u, self.dt / q, np.repeat(self.x0, L, axis=0),
            input_kind=self.input_kind, input_index=np.arange(W * L), substeps=self.substeps, threads=self.threads,
        )  # fmt: skip
        z = res.z[:, ::q].reshape(W, L, L)  # (window, perturbed sample j, response sample i)
        G = ((z - base[0][:, None, :]) / du).transpose(0, 2, 1)
        return np.where(np.isfinite(G), G, 0.0)  # a run that diverges has no linear response: no term there

    def set_input_noise(self, params: np.ndarray, kind: str, variance: float | np.ndarray,
                        sigma2: float | np.ndarray | None = None) -> None:  # fmt: skip
        """The input sensor's white noise (``variance`` per sample, in the input's units squared) in the
        likelihood: a window's residual is then e = n_z - G n_u (G: ``input_sensitivities``, the model's
        response to its input samples, linearised at ``params``), with covariance sigma^2 I + s_u^2 G G^T.
        Projected off the start states (``proj``), that covariance is diagonalised once per window:
        ``noise_basis`` (its eigenvectors, the rows of a basis of the projected space) and ``noise_var``
        (its eigenvalues less sigma^2), so the likelihood costs one small product per window
        (``log_likelihood``). The device filters the input's noise into its band: a few directions carry it.
        Those whose variance is below ``NOISE_RANK_TOL`` of ``sigma2`` (the residuals' mean square: the
        sensor's variance or a little more) are taken as the sensor's alone (each changes a window's log
        likelihood by about that fraction of a nat: 7e-4 nats per window at most, measured on a 0.02 m/s^2
        table), and the likelihood projects on the others only (``noise_rank``: 27 of 62 there). G is the
        response to the simulator's own input samples (pre-emphasised or interpolated, ``cut``): the
        raw samples' noise passes those filters with a gain within 1 % of 1 in the device's band (below
        0.1 fs), where the response to it lives. ``variance`` 0 removes the term.
        """
        var = self.per_window(variance)  # a joint fit: each record's input sensor (W,)
        if not np.any(var > 0):
            self.clear_input_noise()
            return
        if self.proj is None:
            self.set_sensitivities(params, kind)
        assert self.proj is not None
        G = self.input_sensitivities(params, kind)
        Q = np.linalg.qr(self.proj, mode="complete")[0][:, :, self.proj.shape[-1] :]  # (W, L, L - 2)
        var_w = var if var.ndim == 0 else var[:, None, None]
        M = var_w * (Q.transpose(0, 2, 1) @ G) @ (G.transpose(0, 2, 1) @ Q)
        lam, V = np.linalg.eigh(M)  # ascending: the directions that carry the input's noise come last
        lam = np.maximum(lam, 0.0)
        if sigma2 is not None:
            s2 = self.per_window(sigma2)
            lam = np.where(lam > NOISE_RANK_TOL * (s2 if s2.ndim == 0 else s2[:, None]), lam, 0.0)
        self.noise_rank = max(1, int((lam > 0).sum(axis=1).max()))
        self.noise_var = lam
        self.noise_basis = (Q @ V).transpose(0, 2, 1)
        self._basis_t = None

    def log_likelihood(self, zsim: np.ndarray, sigma2: np.ndarray) -> np.ndarray:
        """Each window's Gaussian log likelihood, (P, W), of the simulations ``zsim`` (P, W, L) with sensor
        noise ``sigma2`` (P,) [m^2] (a joint fit: (P, R), each record's), on the projected residuals: i.i.d. noise
        alone, or with the input's noise (``set_input_noise``) through each window's eigenbasis.
        """
        s2 = np.asarray(sigma2, float)
        s2 = s2[:, None] if s2.ndim == 1 else self.per_window(s2)  # (P, 1), or (P, W) for several records
        n_w = self.dof // self.n_windows
        if self.noise_basis is None:
            ss = self.sum_squares(zsim)
            return -0.5 * n_w * np.log(2 * np.pi * s2) - ss / (2 * s2)
        assert self.noise_var is not None
        k = self.noise_rank
        if self._basis_t is None or self._basis_t.shape[-1] != k:  # (W, L, k): the directions the noise reaches
            self._basis_t = np.ascontiguousarray(self.noise_basis[:, -k:].transpose(0, 2, 1))
        r = np.ascontiguousarray((self.z[None] - zsim).transpose(1, 0, 2))  # (W, P, L): contiguous, one GEMM each
        y2 = (r @ self._basis_t) ** 2  # (W, P, k)
        var = self.noise_var[:, None, -k:] + s2.T[:, :, None]  # (W, P, k)
        quad = (y2 / var).sum(axis=-1).T  # (P, W)
        logdet = np.log(var).sum(axis=-1).T
        rest = self.sum_squares(zsim) - y2.sum(axis=-1).T  # the other directions: the sensor's noise alone
        return -0.5 * (n_w * np.log(2 * np.pi) + (n_w - k) * np.log(s2) + rest / s2 + logdet + quad)

    def whitened_residuals(self, zsim: np.ndarray, sigma2: float) -> np.ndarray:
        """One simulation's residuals (``zsim``: (W, L)) whitened by the noise model at ``sigma2``: the
        residual vector whose squared norm is the likelihood's quadratic form (W (L - 2),), for least squares.
        """
        r = self.residuals(zsim[None])[0]
        s2 = self.per_window(sigma2)  # a joint fit: each record's (W,)
        s2 = s2 if s2.ndim == 0 else s2.reshape(-1, 1)
        if self.noise_basis is None:
            return (r / np.sqrt(s2)).ravel()
        assert self.noise_var is not None
        return ((self.noise_basis @ r[:, :, None])[:, :, 0] / np.sqrt(self.noise_var + s2)).ravel()

    def mean_square(self, r: np.ndarray):
        """The projected residuals' (``r``: (W L,)) mean square per degree of freedom: a float for one record's
        windows, each record's (R,) for several.
        """
        if self.groups is None:
            return float(np.sum(r**2) / self.dof)
        rows = np.sum(np.asarray(r).reshape(self.n_windows, -1) ** 2, axis=1)
        return np.bincount(self.groups, weights=rows, minlength=self.n_groups) / self.dof_groups()

    def noise_sigma2(self, r: np.ndarray) -> float:
        """The sensor noise variance [m^2] that maximises the likelihood of the projected residuals ``r``
        (W L,) under the noise model (the residuals' mean square without the input's noise).
        """
        if self.noise_basis is None:
            return float(np.sum(r**2) / self.dof)
        assert self.noise_var is not None
        return _profiled_sigma2(self._noise_y2(r), self.noise_var, float(np.sum(r**2) / self.dof))

    def noise_sigma2_groups(self, r: np.ndarray) -> np.ndarray:
        """``noise_sigma2`` of each record's windows (a joint fit): (R,)."""
        ms = np.atleast_1d(self.mean_square(r))
        if self.noise_basis is None:
            return ms
        assert self.noise_var is not None
        y2 = self._noise_y2(r)
        groups = np.zeros(self.n_windows, int) if self.groups is None else self.groups
        return np.array([_profiled_sigma2(y2[groups == g], self.noise_var[groups == g], float(ms[g]))
                         for g in range(self.n_groups)])  # fmt: skip

    def _noise_y2(self, r: np.ndarray) -> np.ndarray:
        """The squared residuals along each window's input-noise eigenbasis: (W, L - 2)."""
        assert self.noise_basis is not None
        return ((self.noise_basis @ r.reshape(self.n_windows, self.length, 1))[:, :, 0]) ** 2

    def residuals(self, zsim: np.ndarray) -> np.ndarray:
        """Residuals with the start-state directions projected out: (P, W, L)."""
        r = self.z[None] - zsim
        if self.proj is None:
            return r
        rw = r.transpose(1, 0, 2)  # (W, P, L): one small matrix product per window (BLAS, not einsum)
        coef = rw @ self.proj  # (W, P, 2)
        return (rw - coef @ self.proj.transpose(0, 2, 1)).transpose(1, 0, 2)

    def sum_squares(self, zsim: np.ndarray) -> np.ndarray:
        """The squared norm of each window's projected residual, (P, W): |r|^2 - |Q^T r|^2 with Q the
        window's orthonormal start-state basis (``residuals`` without forming the projected residual:
        the likelihood needs only its norm; measured, a third of the sampler's time went into the
        projection).
        """
        r = self.z[None] - zsim
        ss = np.einsum("pwl,pwl->pw", r, r)
        if self.proj is None:
            return ss
        coef = r.transpose(1, 0, 2) @ self.proj  # (W, P, 2)
        return ss - np.einsum("wpk,wpk->pw", coef, coef)

    @property
    def dof(self) -> int:
        """The residuals' degrees of freedom: samples less the start states projected out."""
        return self.n_windows * (self.length - (0 if self.proj is None else self.proj.shape[-1]))
