"""Bayesian inference with emcee: posteriors over the coefficients (k1, k2, k3, c, c_nl) or the device
(E, alpha, m, c, c_nl), with the exact forward model inside a multiple-shooting output-error likelihood.

Likelihood. z is measured with noise; z' and z'' are not measured. The record is cut into windows of
``window_s`` seconds; each is simulated from the measured state at its start (Savitzky-Golay z, z'
of least predicted velocity error, ``derivatives``) under the measured input, all windows of all
walkers in one batched simulator call (emcee ``vectorize=True``). Short windows keep cross-well
chaos from amplifying differences (device-model.md); one long free run could not be matched.
The measured start state is uncertain (z' to ~1 % rms), and a wrong start leaves a decaying free
oscillation in the window's residual: each window's start state is a nuisance parameter, profiled
out to first order by projecting the residual off the window's two initial-state sensitivities
(computed by finite differences at the maximum a posteriori point; they depend on the parameters
only weakly). With i.i.d. Gaussian sensor noise sigma (sampled, log-uniform prior):

    log L = -(N - 2 W)/2 log(2 pi sigma^2) - sum_w |P_w (z_w - z_sim,w(theta*))|^2 / (2 sigma^2)

Windows are 0.125 s: with 0.25 s windows the cross-well chaos roughens the likelihood and the
point estimate scattered 1.2-1.3x wider than its curvature said even with white noise alone
(measured: 40 records of 8 s, accelerometer noise off; 0.9-1.05x with 0.125 s windows). A window
that starts near the saddle and cannot be followed from any nearby start state is dropped
(``Windows.drop_unmatched``; listed in the result). The i.i.d. Gaussian noise model is wrong in a
known way (the accelerometer's noise enters through the model's input and through z's double
integration, both correlated within a window): theta* = theta_hat + A (theta - theta_hat) is the
curvature adjustment by the windows' sandwich covariance (``curvature_adjustment``), which widens
the posterior where the windows' scatter says the data carry less information than the model
claims. The device's likelihood depends on E/m, c/m, c_nl/m only: it is evaluated at the reference
mass, and the sampler works in (E, c, c_nl at the reference mass, m, ...), where the E-m ridge is a
cylinder whose length is the mass prior's (``device_parametrisation``).

Sampler. emcee's differential-evolution moves (80 % DE, 20 % snooker; ecosystem.md 2) in coordinates
scaled by a Laplace approximation at the MAP point (scipy ``least_squares`` on the same residual),
walkers started from that Gaussian. Independent ensembles (default 4, seeds seed..seed+3) run until
every parameter's integrated autocorrelation time tau satisfies steps >= ``tau_multiple`` tau (the
emcee docs' rule) or ``max_steps`` is reached (then a loud warning). R-hat (rank-normalised, split)
is computed across ensembles, each ensemble one chain (walkers of one ensemble are not independent);
ESS bulk and tail across all walkers, and capped by the emcee estimate N / tau.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np
from scipy import optimize

from negstiff.models import Model, simulate_batch
from negstiff.models.device import NOMINAL, Device
from negstiff.models.simulator import P_C, P_CNL, P_M

from .derivatives import state_derivatives
from .measurement import Measurement, MeasurementError

COEFFICIENT_NAMES = ("k1", "k2", "k3", "c", "c_nl", "sigma")
DEVICE_NAMES = ("E", "alpha_deg", "m", "c", "c_nl", "sigma")
DROP_FACTOR = 5.0
"""A window whose residual at the start model exceeds this multiple of the median window's is dropped
(``Windows.drop_unmatched``)."""
DROP_FACTOR_AT_MAP = 3.0
"""The same, at the MAP point, where every window the model follows is matched to the noise."""
SIGMA_BOUNDS = (1e-7, 1e-2)
"""Log-uniform prior on the displacement noise [m] (0.1 um to 1 cm)."""


class PosteriorError(MeasurementError):
    """The record cannot support a posterior (too short, diverging model at the start point)."""


# ------------------------------------------------------------------------------------------------
# Windows and the batched likelihood
# ------------------------------------------------------------------------------------------------
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

    @property
    def n_windows(self) -> int:
        return self.z.shape[0]

    @property
    def length(self) -> int:
        return self.z.shape[1]

    @classmethod
    def cut(cls, rec: Measurement, window_s: float, max_windows: int | None = None, oversample: int = 1) -> "Windows":
        L = int(round(window_s * rec.fs))
        if L < 8:
            raise PosteriorError(f"{rec.source}: window of {window_s} s holds fewer than 8 samples")
        n_win = rec.n // L
        if n_win < 4:
            raise MeasurementError(
                f"{rec.source}: too few samples for a posterior: {rec.n} ({rec.duration:.3g} s), need at least "
                f"{4 * L} (4 windows of {window_s:g} s)"
            )
        picks = np.arange(n_win)
        if max_windows is not None and n_win > max_windows:
            # evenly spread over the whole record (not its first part): every regime it visits is seen
            picks = np.unique(np.round(np.linspace(0, n_win - 1, max_windows)).astype(int))
        zs, v, _, _ = state_derivatives(rec.z, rec.fs, purpose="state")
        starts = L * picks
        idx = starts[:, None] + np.arange(L)[None, :]
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
            u = np.fft.irfft(np.fft.rfft(rec.u) * gain, rec.n)[idx]
        else:
            from scipy import signal

            # band-limited (FFT) interpolation of the input: the acquisition's anti-aliasing filter made
            # it band-limited; a polyphase FIR interpolator (resample_poly's Kaiser window) biased c by
            # 0.06 % and k2 by 1.3 % on exact data (measured), the FFT interpolation by < 1e-5
            u_fine = signal.resample(rec.u, q * rec.n)
            u = u_fine[q * starts[:, None] + np.arange(q * L)[None, :]]
        return cls(
            rec.dt, rec.input_name, u, rec.z[idx], np.column_stack([zs[starts], v[starts]]), oversample=q, starts=starts
        )

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
        (windows that pass near the saddle, whose response the start state changes a lot)."""
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

    def drop_unmatched(self, params: np.ndarray, kind: str, factor: float = DROP_FACTOR) -> int:
        """Drop the windows the model cannot follow from any nearby start state: those whose residual
        (after ``refine_states``) is above ``factor`` times the median window's rms. Such a window starts
        near the saddle: the measured start state's error sends the simulation into the other well, the
        response is not a smooth function of the start state there, and its millimetre residual would
        dominate the fit (measured: on 4 of 40 8-s records one such window pulled the MAP point 5-70
        standard deviations off the truth). With noise alone no window's rms exceeds the median's by
        more than ~25 % (64 samples), so ``factor`` = 5 drops nothing a correct model matches.
        Returns the number dropped; ``dropped`` records where and how large."""
        zsim, div = self.simulate(params[:, None], kind)
        rms = np.sqrt(np.mean((self.z - zsim[0]) ** 2, axis=1))
        rms = np.where(np.isfinite(rms), rms, np.inf)
        bad = rms > factor * np.median(rms)
        if bad.all() or not bad.any():
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
        if self.starts is not None:
            self.starts = self.starts[keep]
        self.proj = None
        return int(bad.sum())

    def set_sensitivities(self, params: np.ndarray, kind: str) -> None:
        """Orthonormal bases of each window's start-state sensitivities (finite differences)."""
        _, S = self._state_sensitivities(params, kind)
        self.proj = np.linalg.qr(S)[0]

    def residuals(self, zsim: np.ndarray) -> np.ndarray:
        """Residuals with the start-state directions projected out: (P, W, L)."""
        r = self.z[None] - zsim
        if self.proj is None:
            return r
        rw = r.transpose(1, 0, 2)  # (W, P, L): one small matrix product per window (BLAS, not einsum)
        coef = rw @ self.proj  # (W, P, 2)
        return (rw - coef @ self.proj.transpose(0, 2, 1)).transpose(1, 0, 2)

    @property
    def dof(self) -> int:
        return self.n_windows * (self.length - (0 if self.proj is None else self.proj.shape[-1]))


# ------------------------------------------------------------------------------------------------
# Parametrisations: physical parameters -> simulator kernel parameters, priors
# ------------------------------------------------------------------------------------------------
@dataclass
class Parametrisation:
    """What is sampled: names, kernel kind, the map to kernel parameters and the prior."""

    names: tuple[str, ...]  # physical parameters except sigma (sigma is always last)
    kind: str
    to_params: Callable[[np.ndarray], np.ndarray]  # (P, d) -> (17, P)
    lower: np.ndarray
    upper: np.ndarray
    gaussian: dict[int, tuple[float, float]] = field(default_factory=dict)  # index -> (mean, sd)
    description: list[str] = field(default_factory=list)
    # parameters the likelihood does not see, held at the start value by the point estimate, and the
    # sampler's scale for each (from its prior)
    fixed_sd: dict[int, float] = field(default_factory=dict)
    # sampled coordinates phi (default: theta itself): the maps both ways, the log |d theta / d phi|, and
    # phi -> the phi the likelihood is evaluated at (the fixed ones at the start value; the same likelihood)
    to_physical: Callable[[np.ndarray], np.ndarray] | None = None
    to_sampled: Callable[[np.ndarray], np.ndarray] | None = None
    log_jacobian: Callable[[np.ndarray], np.ndarray] | None = None
    reduce: Callable[[np.ndarray], np.ndarray] | None = None

    def __post_init__(self):
        # a Gaussian prior enters the sampler's posterior, not the point estimate's least squares: it is
        # for parameters the likelihood does not see (the weighed mass)
        if not set(self.gaussian) <= set(self.fixed_sd):
            raise ValueError("a Gaussian prior is supported only on a parameter held by the point estimate")

    def free(self) -> np.ndarray:
        """Mask of the parameters the likelihood sees (estimated by the point estimate)."""
        mask = np.ones(len(self.names), bool)
        mask[list(self.fixed_sd)] = False
        return mask

    def physical(self, phi: np.ndarray) -> np.ndarray:
        return phi if self.to_physical is None else self.to_physical(phi)

    def log_prior_sampled(self, phi: np.ndarray, log_sigma: np.ndarray) -> np.ndarray:
        """Log prior density of the sampled coordinates: the physical prior times the Jacobian."""
        lp = self.log_prior(self.physical(phi), log_sigma)
        return lp if self.log_jacobian is None else lp + self.log_jacobian(phi)

    def log_prior(self, theta: np.ndarray, log_sigma: np.ndarray) -> np.ndarray:
        ok = np.all((theta > self.lower) & (theta < self.upper), axis=1)
        ok &= (log_sigma > math.log(SIGMA_BOUNDS[0])) & (log_sigma < math.log(SIGMA_BOUNDS[1]))
        lp = np.where(ok, 0.0, -np.inf)
        for i, (mu, sd) in self.gaussian.items():
            lp = lp - 0.5 * ((theta[:, i] - mu) / sd) ** 2
        return lp


def coefficient_parametrisation(start: Model) -> Parametrisation:
    """k1, k2, k3, c, c_nl (and k0 as a nuisance: the record's static offset) around ``start``."""
    names = ("k1", "k2", "k3", "c", "c_nl", "k0")
    x = np.array([getattr(start, n) for n in names])
    span = 10 * np.maximum(np.abs(x), 1e-3 * np.max(np.abs(x)))
    lower, upper = x - span, x + span
    lower[2] = 0.0  # k3 > 0: a hardening spring, a bounded potential
    lower[3] = lower[4] = 0.0  # dissipative damping
    template = start.kernel_params()

    def to_params(theta: np.ndarray) -> np.ndarray:
        p = np.repeat(template[:, None], theta.shape[0], axis=1)
        p[1], p[2], p[3], p[4] = theta[:, 5], theta[:, 0], theta[:, 1], theta[:, 2]
        p[P_C], p[P_CNL] = theta[:, 3], theta[:, 4]
        return p

    desc = [
        "k1, k2, k0: uniform within 10x the magnitude of the deterministic start point on either side "
        "(k0, the static offset m g plus any accelerometer bias, is a nuisance parameter)",
        "k3: uniform on (0, 11 k3_start): a hardening spring (bounded potential)",
        "c, c_nl: uniform on (0, 11 x start): dissipative damping",
        f"sigma: log-uniform on ({SIGMA_BOUNDS[0]:g}, {SIGMA_BOUNDS[1]:g}) m",
        f"mass fixed at m = {start.m:g} kg" + (" (per unit mass)" if start.m == 1.0 else " (weighed)"),
    ]
    return Parametrisation(names, "polynomial", to_params, lower, upper, {}, desc)


def device_parametrisation(start: Device, mass_prior: tuple[float, float] | None) -> Parametrisation:
    """E, alpha, m, c, c_nl of the device with its exact geometric restoring force."""
    names = ("E", "alpha_deg", "m", "c", "c_nl", "g_offset")
    lower = np.array([100e9, 2.0, 0.05, 0.0, 0.0, -0.5])
    upper = np.array([320e9, 14.0, 0.6, 50.0, 20.0, 0.5])
    template = start.kernel_params()
    kf_per_E = start.k_f / start.E

    def to_params(theta: np.ndarray) -> np.ndarray:
        p = np.repeat(template[:, None], theta.shape[0], axis=1)
        p[1] = kf_per_E * theta[:, 0]
        p[3] = np.radians(theta[:, 1])
        p[P_M], p[P_C], p[P_CNL] = theta[:, 2], theta[:, 3], theta[:, 4]
        p[5] = template[5] + theta[:, 5]  # the static load's acceleration: g plus the nuisance offset
        return p

    gauss = {} if mass_prior is None else {2: mass_prior}
    m_ref = float(start.m)

    # m z'' + c z' + c_nl z'|z'| + K(z; E, alpha) = -m (b'' + g'): only E/m, c/m, c_nl/m, alpha, g' matter.
    # The sampler works in phi = (E, alpha, m, c, c_nl, g') with E, c, c_nl taken to the reference mass
    # (E m_ref / m, ...): the likelihood is a function of phi without m, and the posterior along the
    # ridge (a cone in E, m, c, c_nl, its width growing with m) becomes a cylinder the DE moves cross
    # in a few steps. The prior stays the physical one, times the Jacobian (m / m_ref)^3.
    scaled = [0, 3, 4]

    def to_physical(phi: np.ndarray) -> np.ndarray:
        out = phi.copy()
        out[:, scaled] *= (phi[:, 2] / m_ref)[:, None]
        return out

    def to_sampled(theta: np.ndarray) -> np.ndarray:
        out = theta.copy()
        out[:, scaled] *= (m_ref / theta[:, 2])[:, None]
        return out

    def log_jacobian(phi: np.ndarray) -> np.ndarray:
        return 3.0 * np.log(phi[:, 2] / m_ref)

    def reduce(phi: np.ndarray) -> np.ndarray:
        out = phi.copy()
        out[:, 2] = m_ref
        return out

    if mass_prior is None:
        # uniform m, cut by E's bounds along the ridge: log m spans at most log(320/100)
        s_m = m_ref * min(math.log(upper[2] / lower[2]), math.log(upper[0] / lower[0])) / math.sqrt(12)
    else:
        s_m = mass_prior[1]

    desc = [
        "E: uniform on (100, 320) GPa (any steel or spring alloy, generously)",
        "alpha: uniform on (2, 14) deg (the design's 8 deg +- 6 deg of frame tolerance)",
        "m: uniform on (0.05, 0.6) kg"
        + ("" if mass_prior is None else f" times the scale's N({mass_prior[0]:g}, {mass_prior[1]:.2g}) kg (weighed)"),
        "c, c_nl: uniform on (0, 50) N s/m and (0, 20) N s^2/m^2 (dissipative)",
        f"sigma: log-uniform on ({SIGMA_BOUNDS[0]:g}, {SIGMA_BOUNDS[1]:g}) m",
        "g_offset: uniform on (-0.5, 0.5) m/s^2, a nuisance: the static load's apparent acceleration differs from g "
        "by the accelerometer's bias (without it alpha took the bias up, 0.05 deg off at 0.02 m/s^2, measured)",
        "geometry (L, l, b, h, D0) fixed at the drawings' values",
    ]
    return Parametrisation(
        names,
        "device",
        to_params,
        lower,
        upper,
        gauss,
        desc,
        {2: s_m},
        to_physical,
        to_sampled,
        log_jacobian,
        reduce,
    )


def curvature_adjustment(J: np.ndarray, r: np.ndarray, n_windows: int, sigma: float, adjust: bool = True):
    """Curvature adjustment of a misspecified likelihood by the windows' sandwich covariance.

    ``J``, ``r``: the projected residuals' Jacobian (in the point estimate's scaled coordinates x) and
    residuals at the MAP point, window after window. The Gaussian likelihood with i.i.d. noise is
    wrong in a known way: the accelerometer's noise enters twice, through the model's input (a
    response filtered by the device) and through z = y - b_est (the lab's double integration), both
    correlated within a window. The windows are nearly independent of each other, so the spread of
    their score vectors s_w = J_w^T r_w / sigma^2 measures the information the data really carry
    (Godambe's sandwich V_s = H^-1 (sum_w s_w s_w^T) H^-1, H = J^T J / sigma^2, with the small-sample
    factor W / (W - p)). The adjusted covariance V_a takes the sandwich's variance wherever it is
    larger than the model's and never less (eigenvalues of H^1/2 V_s H^1/2 clipped at 1: below 1 is
    the estimate's own noise), and the likelihood is evaluated at theta_hat + A (theta - theta_hat)
    with A^T H A = V_a^-1 (Ribatet, Cooley & Davison 2012, "curvature adjustment"): the posterior's
    spread becomes V_a, its shape elsewhere is the model's.

    Measured (Laplace approximation, 40 records of 8 s, 0.125 s windows): rms z-score of the truth
    1.33 / 1.16 / 1.28 / 1.29 / 1.27 for k1, k2, k3, c, c_nl unadjusted, 1.06 / 0.93 / 1.02 / 1.04 /
    1.04 adjusted. (Whitening by the residuals' estimated autocorrelation instead made it worse,
    1.7-1.9: the fitted start states remove the residual's slow part, and the estimate misses it.)

    Returns (A, V_a, inflation): A and V_a in x coordinates, inflation the clipped eigenvalues (the
    variance factors the adjustment applied, 1 where none)."""
    p = J.shape[1]
    H = J.T @ J / sigma**2
    lam_h, U_h = np.linalg.eigh(H)
    lam_h = np.maximum(lam_h, 1e-12 * lam_h.max())
    H_half = (U_h * np.sqrt(lam_h)) @ U_h.T
    H_inv_half = (U_h / np.sqrt(lam_h)) @ U_h.T
    if not adjust or n_windows <= p + 1:
        return np.eye(p), H_inv_half @ H_inv_half, np.ones(p)
    scores = np.einsum("wlp,wl->wp", J.reshape(n_windows, -1, p), r.reshape(n_windows, -1)) / sigma**2
    meat = scores.T @ scores * n_windows / (n_windows - p)
    lam, U = np.linalg.eigh(H_inv_half @ meat @ H_inv_half)  # = H^1/2 V_s H^1/2
    lam = np.maximum(lam, 1.0)
    V = H_inv_half @ (U * lam) @ U.T @ H_inv_half
    A = H_inv_half @ (U / np.sqrt(lam)) @ U.T @ H_half
    return A, V, np.sort(lam)[::-1]


# ------------------------------------------------------------------------------------------------
# The posterior
# ------------------------------------------------------------------------------------------------
class LogPosterior:
    """Vectorised log posterior in whitened coordinates y, q = q0 + C y (C: the Laplace approximation's
    Cholesky factor), q = [theta, log sigma].

    ``__call__`` returns one (log posterior, log likelihood) pair per walker (emcee's blob convention
    with ``vectorize=True``)."""

    def __init__(self, par: Parametrisation, win: Windows, q0: np.ndarray, scale: np.ndarray, adjust=None):
        self.par, self.win, self.q0, self.scale = par, win, q0, scale
        self.adjust = adjust  # (theta_hat, A, free): likelihood at theta_hat + A (theta - theta_hat) on ``free``
        self.calls = 0

    def likelihood_point(self, theta: np.ndarray) -> np.ndarray:
        """The parameters the likelihood is evaluated at: ``theta`` reduced (device: to the reference
        mass, which leaves the likelihood unchanged) and curvature-adjusted about the MAP point."""
        if self.par.reduce is not None:
            theta = self.par.reduce(theta)
        if self.adjust is None:
            return theta
        th_hat, A, free = self.adjust
        out = theta.copy()
        out[:, free] = th_hat[free] + (theta[:, free] - th_hat[free]) @ A.T
        return out

    def unwhiten(self, y: np.ndarray) -> np.ndarray:
        """Whitened coordinates y -> the sampled coordinates q = [phi, log sigma]."""
        return self.q0 + np.atleast_2d(y) @ self.scale.T

    def loglik(self, q: np.ndarray, pointwise: bool = False, lp: np.ndarray | None = None) -> np.ndarray:
        """Log likelihood (-inf outside the prior's support); ``lp``: the log prior, if already known."""
        theta, log_sigma = q[:, :-1], q[:, -1]
        if lp is None:
            lp = self.par.log_prior_sampled(theta, log_sigma)
        out = np.full((q.shape[0], self.win.n_windows) if pointwise else q.shape[0], -np.inf)
        ok = np.isfinite(lp)
        if ok.any():
            zsim, div = self.win.simulate(self.par.to_params(self.likelihood_point(theta[ok])), self.par.kind)
            r = self.win.residuals(zsim)
            ss = np.sum(r**2, axis=2)  # (P, W)
            sig2 = np.exp(2 * log_sigma[ok])[:, None]
            n_w = self.win.dof // self.win.n_windows
            ll = -0.5 * n_w * np.log(2 * np.pi * sig2) - ss / (2 * sig2)
            ll[div] = -np.inf
            out[ok] = ll if pointwise else ll.sum(axis=1)
        return out

    def __call__(self, y: np.ndarray):
        self.calls += 1
        q = self.unwhiten(y)
        lp = self.par.log_prior_sampled(q[:, :-1], q[:, -1])
        ll = self.loglik(q, lp=lp)
        post = np.where(np.isfinite(ll), ll + lp, -np.inf)
        return list(zip(post, ll))


@dataclass
class PosteriorResult:
    names: tuple[str, ...]
    samples: np.ndarray  # (ensembles, steps, walkers, d) physical, sigma (not log) last, after burn-in
    summary: dict[str, dict[str, float]]
    tau: np.ndarray  # (ensembles, d) integrated autocorrelation times [steps]
    warnings: list[str]
    settings: dict[str, Any]
    map_point: dict[str, float]
    log_likelihood: np.ndarray | None = None  # (ensembles*walkers, kept draws, windows), thinned
    thin: int = 1
    idata: Any = None


class Posterior:
    """emcee posterior of a record (module docstring).

    Parameters
    ----------
    model : ``"coefficients"`` (k1-k3, c, c_nl, sigma; mass fixed) or ``"device"`` (E, alpha, m, c,
        c_nl, sigma with the exact geometric K(z))
    mass_prior : device model only: ``"free"`` or ``"weighed"`` (N(m_weighed, 2 %))
    window_s : multiple-shooting window length [s]
    max_windows : at most this many windows, evenly spread over the record (240 x 0.125 s = 30 s of
        data: a 300 s record's posterior would take five times as long and be no less biased by the
        model's floor; None: every window)
    n_walkers, n_ensembles : walkers per ensemble, independent ensembles
    tau_multiple, min_steps, max_steps, chunk : run length control (emcee docs' rule)
    hdi_prob : credible-interval probability
    adjust : curvature adjustment of the likelihood by the windows' sandwich covariance (module
        docstring; default True); False: the Gaussian likelihood as it stands
    oversample : 1 (default): the input is pre-emphasised for the simulator's linear interpolation
        (``Windows.cut``); q > 1: interpolated (FFT, band-limited) to q x fs instead, q times the cost
    start : coefficient posterior only: the model the MAP search starts from (an ``identify`` result's
        refined model); default: weak-form least squares of the record, refined by simulation error
        (``refine_start``)
    refine_start : without ``start``, refine the weak-form estimate by output error over the record
        (``refine.refine``, the last stage of ``identify``) before the MAP search: the posterior then
        starts from the same refined point an identification reports (default True)
    """

    def __init__(
        self,
        model: str = "coefficients",
        mass_prior: str = "weighed",
        window_s: float = 0.125,
        max_windows: int | None = 240,
        n_walkers: int = 16,
        n_ensembles: int = 4,
        tau_multiple: float = 50.0,
        min_steps: int = 500,
        max_steps: int = 6000,
        chunk: int = 250,
        hdi_prob: float = 0.9,
        oversample: int = 1,
        adjust: bool = True,
        threads: int | None = None,
        seed: int = 0,
        progress: bool = False,
        start: Model | None = None,
        refine_start: bool = True,
    ):
        if model not in ("coefficients", "device"):
            raise ValueError(f"model must be 'coefficients' or 'device', got {model!r}")
        if mass_prior not in ("free", "weighed"):
            raise ValueError(f"mass_prior must be 'free' or 'weighed', got {mass_prior!r}")
        self.model = model
        self.mass_prior = mass_prior
        self.window_s = window_s
        self.max_windows = max_windows
        self.n_walkers = n_walkers
        self.n_ensembles = n_ensembles
        self.tau_multiple = tau_multiple
        self.min_steps = min_steps
        self.max_steps = max_steps
        self.chunk = chunk
        self.hdi_prob = hdi_prob
        self.oversample = oversample
        self.adjust = adjust
        self.threads = threads
        self.seed = seed
        self.progress = progress
        if start is not None and (model != "coefficients" or not isinstance(start, Model)):
            raise ValueError("a start model is a polynomial model, for the coefficient posterior")
        self.start = start
        self.refine_start = refine_start
        self.start_info_: dict[str, Any] = {}

    # --- start point -------------------------------------------------------------------------------
    def _start(self, rec: Measurement, win: Windows) -> tuple[Parametrisation, np.ndarray]:
        if self.model == "coefficients":
            from .weak import weak_least_squares

            if self.start is not None:  # an identified (output-error refined) model: the MAP search starts there
                if rec.mass is not None and abs(self.start.m / rec.mass - 1) > 1e-6:
                    raise PosteriorError(
                        f"{rec.source}: the start model's mass ({self.start.m:g} kg) is not the record's "
                        f"({rec.mass:g} kg)"
                    )
                start = self.start
                self.start_info_ = {"source": "given", "model": start.to_dict()}
            else:
                start = self._refined_start(rec, weak_least_squares(rec, ("1", "z", "z^2", "z^3", "v", "v|v|")))
            par = coefficient_parametrisation(start)
            theta = np.array([getattr(start, n) for n in par.names])
        else:
            if rec.mass is None and self.mass_prior == "weighed":
                raise PosteriorError(f"{rec.source}: the device posterior with a weighed mass needs --mass or metadata")
            m0 = rec.mass if rec.mass is not None else NOMINAL.m
            prior = (m0, 0.02 * m0) if self.mass_prior == "weighed" else None
            start = NOMINAL.with_(m=m0, c=1.0, c_nl=0.1)
            par = device_parametrisation(start, prior)
            theta = np.array([start.E, start.alpha_deg, start.m, start.c, start.c_nl, 0.0])
        return par, theta

    def _refined_start(self, rec: Measurement, weak: Model) -> Model:
        """The weak-form estimate refined by simulation error over the record (``refine.refine``; the mass
        held: the coefficient posterior holds it too), kept only if it is bounded and predicts the record
        at least as well; ``start_info_`` says which start was used and why."""
        from .refine import refine
        from .validation import boundedness

        info: dict[str, Any] = {"source": "weak-form least squares", "initial_model": weak.to_dict()}
        self.start_info_ = info
        if not self.refine_start:
            info["reason"] = "refinement switched off"
            return weak
        t0 = time.perf_counter()
        try:
            r = refine(weak, rec)
        except (ValueError, MeasurementError) as exc:
            info["reason"] = f"refinement failed, the weak-form estimate is the start: {exc}"
            return weak
        info["refinement"] = r.to_json()
        info["seconds"] = time.perf_counter() - t0
        bounded = boundedness(r.model, rec)
        if not bounded["ok"]:
            info["reason"] = f"refined model rejected: {bounded['warning']}"
            return weak
        stages = [s for s in r.stages if "rms_end_m" in s]
        if stages and not stages[-1]["rms_end_m"] <= stages[-1]["rms_start_m"]:
            info["reason"] = "refined model rejected: its simulation error did not fall"
            return weak
        info.update(source="output-error refinement of the weak-form estimate", model=r.model.to_dict())
        return r.model

    def _map(self, par: Parametrisation, win: Windows, theta: np.ndarray):
        """MAP point of theta (sigma profiled) by least squares on the projected residuals, with the
        parameters the likelihood does not see held; returns (theta, the least-squares solution)."""
        x_scale = np.maximum(np.abs(theta), 1e-6)
        free = par.free()
        n_rows = win.n_windows * win.length

        def resid(x):
            th = theta.copy()
            th[free] = x * x_scale[free]
            if np.any(th <= par.lower) or np.any(th >= par.upper):
                return np.full(n_rows, 1.0)
            zsim, div = win.simulate(par.to_params(th[None]), par.kind)
            if div[0]:
                return np.full(n_rows, 1.0)
            return win.residuals(zsim)[0].ravel()

        x0 = theta[free] / x_scale[free]
        sol = optimize.least_squares(resid, x0, method="lm", x_scale="jac", max_nfev=400)
        th = theta.copy()
        th[free] = sol.x * x_scale[free]
        return th, sol

    def point_estimate(self, rec: Measurement):
        """Windows, MAP point and noise model of a record: (parametrisation, windows, theta, the least
        squares solution, sigma). The MAP point and the windows' start states are found alternately, each
        a profile over the other. The device's mass is held at its start (weighed) value: the
        likelihood depends on E/m, c/m, c_nl/m only (device-model.md), so the MAP point along the E-m
        ridge is the prior's."""
        win = Windows.cut(rec, self.window_s, self.max_windows, oversample=self.oversample)
        win.threads = self.threads
        par, theta = self._start(rec, win)
        zsim, div = win.simulate(par.to_params(theta[None]), par.kind)
        if div[0]:
            raise PosteriorError(f"{rec.source}: the start model diverges on the record's windows")
        for it in range(3):
            p_ = par.to_params(theta[None])[:, 0]
            win.refine_states(p_, par.kind)
            win.drop_unmatched(p_, par.kind)
            win.set_sensitivities(p_, par.kind)
            theta, sol = self._map(par, win, theta)
        # at the MAP point the model matches every window it can follow to the noise (rms within ~10 % of
        # the median window's): a window 3x above the median is not followed (it turns back near the
        # saddle); measured on the as-built device, one such window held 90 % of the score's variance.
        # The least squares solution is then recomputed on the windows kept (the curvature adjustment
        # reads its Jacobian window by window).
        p_ = par.to_params(theta[None])[:, 0]
        win.refine_states(p_, par.kind)
        win.drop_unmatched(p_, par.kind, factor=DROP_FACTOR_AT_MAP)
        win.set_sensitivities(p_, par.kind)
        theta, sol = self._map(par, win, theta)
        sigma = float(np.sqrt(np.sum(sol.fun**2) / win.dof))  # sol.fun: the projected residuals at theta
        return par, win, theta, sol, sigma

    # --- the run --------------------------------------------------------------------------------
    def fit(self, rec: Measurement) -> PosteriorResult:

        t_start = time.perf_counter()
        par, win, theta, sol, sigma = self.point_estimate(rec)
        # Laplace approximation at the MAP point, curvature-adjusted (``curvature_adjustment``): the sampler
        # works in coordinates whitened by its Cholesky factor, where the posterior is close to N(0, I)
        # (DE moves then decorrelate in ~10 steps). Along the device's E-m ridge, which the data do not
        # see, the scale is the mass prior's.
        free = par.free()
        x_scale = np.maximum(np.abs(theta), 1e-6)
        A_x, V_x, inflation = curvature_adjustment(sol.jac, sol.fun, win.n_windows, sigma, adjust=self.adjust)
        cov = np.zeros((theta.size, theta.size))
        cov[np.ix_(free, free)] = V_x * np.outer(x_scale[free], x_scale[free])
        for i, sd in par.fixed_sd.items():  # the likelihood does not see them: the prior's scale
            cov[i, i] = sd**2
        for i in np.flatnonzero(~(np.diag(cov) > 0)):
            cov[i, i] = (1e-3 * x_scale[i]) ** 2
        try:
            chol = np.linalg.cholesky(cov)
        except np.linalg.LinAlgError:
            chol = np.diag(np.sqrt(np.diag(cov)))
        q0 = np.concatenate([theta, [math.log(sigma)]])
        scale = np.zeros((q0.size, q0.size))
        scale[:-1, :-1] = chol
        scale[-1, -1] = 1.0 / math.sqrt(2 * win.dof)  # the sd of log sigma
        A_theta = A_x * np.outer(x_scale[free], 1.0 / x_scale[free])
        logpost = LogPosterior(par, win, q0, scale, (theta, A_theta, free) if self.adjust else None)

        nd = q0.size
        run = sample_ensembles(
            logpost,
            nd,
            n_walkers=self.n_walkers,
            n_ensembles=self.n_ensembles,
            seed=self.seed,
            tau_multiple=self.tau_multiple,
            min_steps=self.min_steps,
            max_steps=self.max_steps,
            chunk=self.chunk,
            progress=self.progress,
        )
        chains, taus, warn = run["chains"], run["tau"], run["warnings"]
        n_keep = min(c.shape[0] for c in chains)
        y = np.stack([c[-n_keep:] for c in chains])  # (E, S, W, nd)
        q = logpost.unwhiten(y.reshape(-1, nd))
        q[:, :-1] = par.physical(q[:, :-1])
        q = q.reshape(y.shape)
        q[..., -1] = np.exp(q[..., -1])
        names = tuple(par.names) + ("sigma",)
        tau_arr = np.array(taus)
        res = PosteriorResult(
            names=names,
            samples=q,
            summary={},
            tau=tau_arr,
            warnings=warn,
            settings={},
            map_point={n: float(v) for n, v in zip(names, np.concatenate([theta, [sigma]]))},
        )
        res.summary = summarise(res.samples, names, tau_arr, self.hdi_prob)
        warn += convergence_warnings(res.summary, self.n_ensembles)
        res.settings = {
            "model": self.model,
            "mass_prior": self.mass_prior if self.model == "device" else None,
            "mass": rec.mass,
            "window_s": self.window_s,
            "windows": win.n_windows,
            "curvature_adjustment": self.adjust,
            "variance_inflation": [round(float(v), 3) for v in inflation],
            "windows_dropped": [{"start_s": t, "rms_m": r} for t, r in win.dropped],
            "samples_used": int(win.n_windows * win.length),
            "walkers": self.n_walkers,
            "ensembles": self.n_ensembles,
            "kept_steps_per_ensemble": int(n_keep),
            "tau_max_steps": float(np.nanmax(tau_arr)) if np.isfinite(tau_arr).any() else None,
            "likelihood_calls": logpost.calls,
            "priors": par.description,
            "seed": self.seed,
            "elapsed_s": time.perf_counter() - t_start,
            "moves": "DEMove 0.8, DESnookerMove 0.2",
            "start": self.start_info_ or {"source": "the device's nominal values"},
        }
        self.logpost_, self.par_, self.windows_ = logpost, par, win
        tau_max = np.nanmax(tau_arr) if np.isfinite(tau_arr).any() else np.nan  # too short a chain: no tau
        res.thin = max(1, int(np.ceil(tau_max / 2))) if np.isfinite(tau_max) else 1
        res.idata = self._idata(res, y, rec)
        return res

    def _idata(self, res: PosteriorResult, y: np.ndarray, rec: Measurement):
        """arviz DataTree: posterior (thinned; chain = ensemble x walker), sample stats, observed
        data and pointwise (per-window) log likelihood."""
        import arviz as az

        E, S, W, d = res.samples.shape
        th = res.thin
        post = res.samples[:, ::th]  # (E, S', W, d)
        Sp = post.shape[1]
        chains = np.moveaxis(post, 2, 1).reshape(E * W, Sp, d)
        q = np.moveaxis(y[:, ::th], 2, 1).reshape(E * W * Sp, d)
        ll = np.concatenate(
            [
                self.logpost_.loglik(self.logpost_.unwhiten(q[i : i + 2048]), pointwise=True)
                for i in range(0, q.shape[0], 2048)
            ]
        ).reshape(E * W, Sp, -1)
        res.log_likelihood = ll
        data = {
            "posterior": {n: chains[..., i] for i, n in enumerate(res.names)},
            "sample_stats": {"lp": ll.sum(axis=2)},
            "log_likelihood": {"z": ll},
            "observed_data": {"z": self.windows_.z},
            "constant_data": {"window_start_state": self.windows_.x0, "u": self.windows_.u},
        }
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "more chains than draws": the walkers of all ensembles
            return az.from_dict(data)


def sample_ensembles(
    log_prob,
    nd: int,
    *,
    n_walkers: int,
    n_ensembles: int,
    seed: int,
    tau_multiple: float = 50.0,
    min_steps: int = 500,
    max_steps: int = 6000,
    chunk: int = 250,
    progress: bool = False,
    p0_scale: float = 1.0,
) -> dict[str, Any]:
    """Independent emcee ensembles (DE 80 % / snooker 20 %) of a vectorised ``log_prob`` over scaled
    coordinates (walkers start from N(0, p0_scale^2)). Each runs in chunks until its kept steps (after a
    burn-in of 2 tau, at least one chunk) reach ``tau_multiple`` x the largest autocorrelation time, or
    ``max_steps``; a run that stops short is reported in ``warnings``. Seeds: the walkers' start from
    ``seed + e``, the moves from ``seed + 1000 + e``: the same seed gives the same chains."""
    import emcee

    moves = [(emcee.moves.DEMove(), 0.8), (emcee.moves.DESnookerMove(), 0.2)]
    chains, taus, warn, blobs = [], [], [], []
    pbar = _progress_bar(progress, n_ensembles * max_steps)
    for e in range(n_ensembles):
        rs = np.random.RandomState(seed + e)
        p0 = p0_scale * rs.standard_normal((n_walkers, nd))
        # every walker must start where the posterior is positive (emcee's moves compare log probabilities)
        for _ in range(50):
            bad = ~np.isfinite(np.array([lp for lp, _ in log_prob(p0)]))
            if not bad.any():
                break
            p0[bad] = 0.5 * p0_scale * rs.standard_normal((int(bad.sum()), nd))
        else:
            raise PosteriorError("no start point of positive posterior density near the MAP point")
        sampler = emcee.EnsembleSampler(n_walkers, nd, log_prob, vectorize=True, moves=moves)
        sampler.random_state = np.random.RandomState(seed + 1000 + e).get_state()
        state, steps, tau, burn = p0, 0, np.full(nd, np.inf), 0
        while steps < max_steps:
            with np.errstate(invalid="ignore", divide="ignore"):
                state = sampler.run_mcmc(state, min(chunk, max_steps - steps), progress=False)
            steps = sampler.iteration
            if pbar is not None:
                pbar.update(min(chunk, max_steps))
            with np.errstate(invalid="ignore", divide="ignore"), warnings.catch_warnings():
                warnings.simplefilter("ignore")
                tau = sampler.get_autocorr_time(tol=0, quiet=True)
            t_max = float(np.max(tau)) if np.all(np.isfinite(tau)) else math.inf
            burn = int(min(steps // 2, max(2 * t_max, chunk)))
            if steps >= min_steps and steps - burn >= tau_multiple * t_max:
                break
        if not steps - burn >= tau_multiple * t_max:
            warn.append(
                f"ensemble {e}: not converged after {steps} steps: {steps - burn} kept steps < "
                f"{tau_multiple:g} x tau = {tau_multiple * t_max:.0f} (emcee's rule); the numbers are not reliable"
            )
        acc = float(np.mean(sampler.acceptance_fraction))
        if acc < 0.05:
            warn.append(f"ensemble {e}: acceptance fraction {acc:.3f} (stuck walkers)")
        chains.append(sampler.get_chain(discard=burn))
        blobs.append(sampler.get_blobs(discard=burn))
        taus.append(tau)
    if pbar is not None:
        pbar.close()
    return {"chains": chains, "tau": taus, "warnings": warn, "blobs": blobs}


def summarise(samples: np.ndarray, names, tau: np.ndarray, hdi_prob: float) -> dict[str, dict[str, float]]:
    """Posterior summaries of ``samples`` (ensembles, steps, walkers, d): mean, sd, HDI, R-hat across
    the ensembles (each one chain, draws in step order), bulk and tail ESS over all walkers (arviz,
    capped by emcee's N / tau), tau."""
    import arviz as az

    E, S, W, d = samples.shape
    across = az.from_dict({"posterior": {n: samples[..., i].reshape(E, S * W) for i, n in enumerate(names)}})
    walkers = az.from_dict(
        {"posterior": {n: np.moveaxis(samples[..., i], 2, 1).reshape(E * W, S) for i, n in enumerate(names)}}
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "more chains than draws" notices for short toy runs
        rhat = az.rhat(across, method="rank")
        ess_b, ess_t = az.ess(walkers, method="bulk"), az.ess(walkers, method="tail")
        hdi = az.hdi(across, prob=hdi_prob)
    out = {}
    for i, n in enumerate(names):
        x = samples[..., i].ravel()
        col = np.asarray(tau, float)[:, i]
        t = float(np.nanmax(col)) if np.isfinite(col).any() else float("nan")
        emcee_ess = E * S * W / max(t, 1.0)
        lo, hi = (float(v) for v in hdi[n].values)
        out[n] = {
            "mean": float(x.mean()),
            "sd": float(x.std(ddof=1)),
            "hdi_low": lo,
            "hdi_high": hi,
            "r_hat": float(rhat[n].values),
            "ess_bulk": float(min(ess_b[n].values, emcee_ess)),
            "ess_tail": float(min(ess_t[n].values, emcee_ess)),
            "tau_steps": t,
        }
    return out


def convergence_warnings(summary: dict[str, dict[str, float]], n_ensembles: int) -> list[str]:
    out = []
    for n, s in summary.items():
        if not s["r_hat"] < 1.01:
            out.append(f"{n}: R-hat {s['r_hat']:.4f} >= 1.01 across the {n_ensembles} ensembles")
        if not s["ess_bulk"] > 400:
            out.append(f"{n}: bulk ESS {s['ess_bulk']:.0f} <= 400")
    return out


def _progress_bar(on: bool, total: int):
    if not on:
        return None
    from tqdm import tqdm

    return tqdm(total=total, desc="emcee steps", unit="step", leave=False)


def result_json(res: PosteriorResult, hdi_prob: float) -> dict[str, Any]:
    """The contract's posterior JSON (plus diagnostics)."""
    params = {}
    nuisance = {}
    for n, s in res.summary.items():
        key = "alpha_deg" if n == "alpha_deg" else n
        (nuisance if n in ("k0", "g_offset") else params)[key] = s
    return {
        "hdi_prob": hdi_prob,
        "parameters": params,
        "nuisance_parameters": nuisance,
        "map": res.map_point,
        "correlation": _correlation(res),
        "converged": not res.warnings,
        "warnings": res.warnings,
        "settings": res.settings,
    }


def _correlation(res: PosteriorResult) -> dict[str, dict[str, float]]:
    x = res.samples.reshape(-1, res.samples.shape[-1])
    c = np.corrcoef(x.T)
    return {a: {b: float(c[i, j]) for j, b in enumerate(res.names)} for i, a in enumerate(res.names)}
