"""The curvature-adjusted multiple-shooting likelihood and the whitened log posterior emcee samples."""

from __future__ import annotations

import math
import threading

import numpy as np

from negstiff.inference.estimators.posterior.parametrisation import Parametrisation
from negstiff.inference.estimators.posterior.windows import Windows
from negstiff.inference.record.derivatives import noise_floor
from negstiff.inference.record.measurement import Measurement


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
    variance factors the adjustment applied, 1 where none).
    """
    H, meat = information_parts(J, r, n_windows, sigma)
    return sandwich(H, meat if adjust else None)


def information_parts(J: np.ndarray, r: np.ndarray, n_windows: int, sigma: float):
    """The model's information H = J^T J / sigma^2 and the windows' score covariance (the sandwich's meat, with the
    small-sample factor W / (W - p); None where there are too few windows to estimate it), ``curvature_adjustment``'s
    two parts. Independent records' parts add: a joint fit's sandwich is ``sandwich(H_1 + H_2, M_1 + M_2)``, not
    the sum of each record's adjusted information (the joint estimate weights the records by H, not by what each
    really carries), which is what a design must predict (``analysis.design``).
    """
    p = J.shape[1]
    H = J.T @ J / sigma**2
    if n_windows <= p + 1:
        return H, None
    scores = np.einsum("wlp,wl->wp", J.reshape(n_windows, -1, p), r.reshape(n_windows, -1)) / sigma**2
    return H, scores.T @ scores * n_windows / (n_windows - p)


def sandwich(H: np.ndarray, meat: np.ndarray | None):
    """The curvature adjustment of ``curvature_adjustment`` from its parts (``information_parts``): (A, V_a,
    inflation); ``meat`` None gives the model's own covariance H^-1 (no adjustment).
    """
    p = H.shape[0]
    lam_h, U_h = np.linalg.eigh(H)
    lam_h = np.maximum(lam_h, 1e-12 * lam_h.max())
    H_half = (U_h * np.sqrt(lam_h)) @ U_h.T
    H_inv_half = (U_h / np.sqrt(lam_h)) @ U_h.T
    if meat is None:
        return np.eye(p), H_inv_half @ H_inv_half, np.ones(p)
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
    Cholesky factor), q = [theta, log sigma] (a joint fit of R records: [theta, log sigma_1 .. log sigma_R], each
    record's sensor noise, ``Windows.groups``).

    ``__call__`` returns one (log posterior, log likelihood) pair per walker (emcee's blob convention
    with ``vectorize=True``).
    """

    def __init__(self, par: Parametrisation, win: Windows, q0: np.ndarray, scale: np.ndarray, adjust=None):
        self.par, self.win, self.q0, self.scale = par, win, q0, scale
        self.adjust = adjust  # (theta_hat, A, free): likelihood at theta_hat + A (theta - theta_hat) on ``free``
        self.calls = 0
        self.n_noise = win.n_groups  # the sigmas at the end of q
        self._lock = threading.Lock()  # the ensembles call from their threads (``sampling.sample_ensembles``)

    def __getstate__(self) -> dict:
        # pickled without its lock (a lock does not pickle; a new one is made on loading)
        return {k: v for k, v in self.__dict__.items() if k != "_lock"}

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._lock = threading.Lock()

    def likelihood_point(self, theta: np.ndarray) -> np.ndarray:
        """The parameters the likelihood is evaluated at: ``theta`` reduced (device: to the reference
        mass, which leaves the likelihood unchanged) and curvature-adjusted about the MAP point.
        """
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

    def split(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The sampled coordinates q split into (theta, log sigma): (B, d) and (B,), or (B, R) for R records."""
        R = getattr(self, "n_noise", 1)  # a LogPosterior pickled before joint fits: one record's
        return (q[:, :-1], q[:, -1]) if R == 1 else (q[:, :-R], q[:, -R:])

    def loglik(self, q: np.ndarray, pointwise: bool = False, lp: np.ndarray | None = None) -> np.ndarray:
        """Log likelihood (-inf outside the prior's support); ``lp``: the log prior, if already known."""
        theta, log_sigma = self.split(q)
        if lp is None:
            lp = self.par.log_prior_sampled(theta, log_sigma)
        out = np.full((q.shape[0], self.win.n_windows) if pointwise else q.shape[0], -np.inf)
        ok = np.isfinite(lp)
        if ok.any():
            params = self.par.to_params(self.likelihood_point(theta[ok]))
            finite = np.all(np.isfinite(params), axis=0)  # a law's table is NaN where its parts are not finite
            if not finite.all():
                ok[ok] = finite
                params = params[:, finite]
            if ok.any():
                zsim, div = self.win.simulate(params, self.par.kind)
                ll = self.win.log_likelihood(zsim, np.exp(2 * log_sigma[ok]))  # (P, W)
                ll[div] = -np.inf
                out[ok] = ll if pointwise else ll.sum(axis=1)
        return out

    def __call__(self, y: np.ndarray):
        """The log posterior at the whitened points ``y`` (one row each): emcee's vectorised callable."""
        with self._lock:
            self.calls += 1
        q = self.unwhiten(y)
        lp = self.par.log_prior_sampled(*self.split(q))
        ll = self.loglik(q, lp=lp)
        post = np.where(np.isfinite(ll), ll + lp, -np.inf)
        return list(zip(post, ll, strict=False))


INPUT_BAND_FILLED = 0.5
"""An input whose spectrum stands above its floor in more than this share of the top fifth of the band fills
the band: its floor is signal, not the sensor's noise, and is not read as noise (``input_noise_rms``)."""


INPUT_NOISE_SHARE = 0.1
"""A white floor holding more than this share of the input's variance is the excitation itself (a
broadband input is flat over the band too), not its sensor's noise (``input_noise_rms``)."""


def input_noise_rms(rec: Measurement) -> tuple[float, str]:
    """The input sensor's white noise rms [input units], read from the input's own spectrum: the white
    plateau above the excitation's band (``derivatives.noise_floor``, the same reading as the displacement's),
    and how it was read. 0 when the excitation fills the band: its spectrum stands above the floor up to the
    Nyquist frequency, or the "floor" holds more than ``INPUT_NOISE_SHARE`` of the input's variance (a flat
    broadband excitation is a plateau too): nothing to read the noise from.
    """
    sigma2, f, S = noise_floor(rec.u, rec.fs)
    top = f > 0.8 * rec.fs / 2
    if not top.any() or np.mean(S[top] > 0) > INPUT_BAND_FILLED or sigma2 > INPUT_NOISE_SHARE * np.var(rec.u):
        return 0.0, "not read: the excitation fills the band (its spectral floor is signal); the input taken as exact"
    return math.sqrt(sigma2), "the input's spectral floor"
