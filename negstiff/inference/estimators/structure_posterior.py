"""The posterior of a structure's nonlinear element (emcee, arviz), the linear structure fixed.

Parameters: the element's k1, k2, k3, c, c_nl (the single-DOF names) and the displacement sensors' noise sigma
(one for every DOF: the same kind of laser); the masses and the linear structure (springs, dampers) are fixed at
a deterministic identification's values (``SINDy(element=...)`` by default, or the ``start`` structure given): the
linear structure is a nuisance well determined by the modes, and fixing it is the approximation this posterior
makes (its intervals are conditional on it; the result says so).

Likelihood: the record cut into windows of ``window_s`` (about a period: short against the cross-well motion's
divergence), each simulated from the record's band-smoothed state at its start (``Measurement.channel_states``) under
the measured input (band-limited between samples), its start state's directions projected off (profiled out: the
smoothed state errs, and chaos grows its error within a window); every DOF's residual Gaussian with sd sigma,
curvature-adjusted by the windows' sandwich covariance (the single-DOF posterior's
``posterior.likelihood.curvature_adjustment``: what is left beside the sensors' white noise is smooth and correlated
within a window, and the spread of the windows' scores says how much the data really carry). Measured over 12 of
the tests' fixture records: rms z-score of the truth 1.48 / 1.20 / 1.14 / 1.33 / 1.24 for k1, k2, k3, c, c_nl,
90 % intervals covering 67-100 % (the likelihood tempered by the residuals' correlation time, before: 2.0-4.4 and
17-67 %); a bias of k1 by -1.4 sd remains. Flat priors on the coefficients (c, c_nl >= 0: the element
dissipates) and on log sigma. Sampling: the package's ensembles
(``posterior.sampling.sample_ensembles``: independent emcee ensembles, DE and snooker moves, run until 50 tau),
started around the least-squares point (Gauss-Newton from the start structure's element) in coordinates scaled by
the adjusted covariance; summaries and R-hat, ESS by arviz (``posterior.diagnostics.summarise``).
"""

from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np

from negstiff.errors import InputError, NegstiffWarning
from negstiff.inference.estimators.posterior.diagnostics import convergence_warnings, summarise
from negstiff.inference.estimators.posterior.likelihood import curvature_adjustment
from negstiff.inference.estimators.posterior.sampling import sample_ensembles
from negstiff.inference.record.measurement import Measurement
from negstiff.models.kernel import KINDS
from negstiff.models.simulator import integrate, stage_input
from negstiff.models.structure import Structure

from .sindy import SINDy
from .structure_id import parse_element

NAMES = ("k1", "k2", "k3", "c", "c_nl")
SUBSTEPS = 2


class StructurePosterior:
    """Posterior of a structure's element coefficients (module docstring).

    Parameters
    ----------
    element : "I-J" or (I, J)
        The element's place (J moved, I attached to; 0: the base).
    start : Structure, optional
        The structure whose linear part is fixed and whose element starts the sampler (default: ``SINDy``
        on the record).
    window_s : float, default 0.1
        Length of the likelihood's windows [s].
    max_windows : int, default 80
        Windows used at most (spread over the record's identification part, the first 80 %).
    n_walkers, n_ensembles : int
        emcee walkers per ensemble, independent ensembles (R-hat across them).
    max_steps : int, default 3000
        Steps per ensemble at most.
    hdi_prob : float, default 0.9
        Credible interval's probability.
    seed : int, default 0
        Every random draw's root.

    Attributes
    ----------
    parameters_ : dict
        Per parameter: mean, sd, hdi_low, hdi_high, r_hat, ess_bulk (and the least-squares point ``map``).
    structure_ : Structure
        The structure with the posterior mean's element.
    warnings_ : list of str
        Convergence and record warnings (also issued as ``NegstiffWarning``).
    settings_ : dict
        The windows, the sampler's settings and what was held fixed.

    Examples
    --------
    >>> from negstiff import StructurePosterior, load
    >>> from negstiff.models import SEED_LIKE_CUBIC
    >>> from negstiff.models.structure_rig import StructureRig
    >>> rec = load(StructureRig.device_on_fixture(seed=1).random(duration=40.0).write("fixture.csv"))
    >>> post = StructurePosterior(element="1-2", n_walkers=12, max_windows=24, seed=1).fit(rec)
    >>> k3 = post.parameters_["k3"]
    >>> abs(k3["mean"] / SEED_LIKE_CUBIC.k3 - 1) < 0.05
    True
    """

    def __init__(self, *, element=None, start: Structure | None = None, window_s: float = 0.1,
                 max_windows: int = 80, n_walkers: int = 16, n_ensembles: int = 2, max_steps: int = 3000,
                 hdi_prob: float = 0.9, seed: int = 0):  # fmt: skip
        self.element, self.start, self.window_s, self.max_windows = element, start, window_s, max_windows
        self.n_walkers, self.n_ensembles, self.max_steps, self.hdi_prob, self.seed = (
            n_walkers, n_ensembles, max_steps, hdi_prob, seed)  # fmt: skip

    def _check(self, rec: Measurement) -> tuple[int, int]:
        if not isinstance(rec, Measurement):
            raise InputError("a structure's posterior needs a Measurement (load, from_arrays)")
        if not (0 < self.window_s <= 5 and self.max_windows >= 4 and self.n_walkers >= 12 and 0 < self.hdi_prob < 1):
            raise InputError(
                f"window_s in (0, 5], max_windows >= 4, n_walkers >= 12, hdi_prob in (0, 1); got {self.window_s}, "
                f"{self.max_windows}, {self.n_walkers}, {self.hdi_prob}"
            )
        if self.element is None and self.start is None:
            raise InputError(f"{rec.source}: the element's place is needed (element='I-J')")
        if self.element is not None:
            return parse_element(self.element, rec.n_dof)
        assert self.start is not None
        return self.start.place

    def fit(self, rec: Measurement) -> StructurePosterior:
        """Sample the element's posterior on ``rec``; returns self."""
        at = self._check(rec)
        start = self.start if self.start is not None else SINDy(element=at).fit(rec).structure_
        if start.place != at or start.n_dof != rec.n_dof:
            raise InputError(f"{rec.source}: the start structure's element {start.place} is not the record's {at}")
        n_id = int(0.8 * rec.n)
        L = max(8, int(round(self.window_s * rec.fs)))
        starts = np.arange(0, n_id - L, L)
        if starts.size < 4:
            raise InputError(f"{rec.source}: too short for {self.window_s} s windows (4 needed)")
        starts = starts[np.linspace(0, starts.size - 1, min(self.max_windows, starts.size)).round().astype(int)]
        zs, v, _ = rec.channel_states(at)
        idx = starts[:, None] + np.arange(L + 1)[None, :]
        data = np.transpose(rec.channels[:, idx], (1, 0, 2))  # (W, N, L+1)
        sim = _WindowSimulator(start, rec, idx, np.hstack([zs[:, starts].T, v[:, starts].T]))
        theta0 = np.array([getattr(start.element, k) for k in NAMES])
        sim.start_sensitivity(theta0)
        n_obs = data.size - sim.W * 2 * rec.n_dof  # the start states profiled out
        theta, cov, sigma, J, r0 = _gauss_newton(sim, data, theta0, n_obs)
        # the single-DOF posterior's curvature adjustment by the windows' sandwich covariance: what is left in the
        # residual beside the sensors' white noise is smooth and correlated within a window, and the windows'
        # scores scatter by what the data really carry (``posterior.likelihood.curvature_adjustment``)
        s_gn = np.sqrt(np.diag(cov))
        A, V_a, inflation = curvature_adjustment(J * s_gn[None, :], r0, sim.W, sigma)
        tau_res = _correlation_time(r0.reshape(sim.W, rec.n_dof, -1))
        scale = np.r_[s_gn * np.sqrt(np.diag(V_a)), 1.0 / math.sqrt(2 * n_obs)]
        centre = np.r_[theta, math.log(sigma)]

        def log_prob(xs: np.ndarray):
            pts = centre[None, :] + xs * scale[None, :]
            out = [(-math.inf, 0.0)] * len(pts)
            ok = (pts[:, 3] >= 0) & (pts[:, 4] >= 0)
            if ok.any():
                adjusted = theta + ((pts[ok, :5] - theta) / s_gn) @ A.T * s_gn  # the likelihood's point
                res = sim.residuals(adjusted, data)  # (B, n_obs)
                s2 = np.exp(2 * pts[ok, 5])
                lp = -0.5 * np.sum(res**2, axis=1) / s2 - n_obs * pts[ok, 5]
                for k, i in enumerate(np.flatnonzero(ok)):
                    out[i] = (float(lp[k]) if np.isfinite(lp[k]) else -math.inf, 0.0)
            return out

        run = sample_ensembles(log_prob, 6, n_walkers=self.n_walkers, n_ensembles=self.n_ensembles, seed=self.seed,
                               max_steps=self.max_steps, min_steps=500, p0_scale=1.0)  # fmt: skip
        S = min(c.shape[0] for c in run["chains"])
        chains = np.stack([c[-S:] for c in run["chains"]])  # (E, S, W, d) scaled
        phys = centre + chains * scale
        phys[..., 5] = np.exp(phys[..., 5])
        tau = np.array(run["tau"]) * 1.0
        summary = summarise(phys, (*NAMES, "sigma"), tau, self.hdi_prob)
        for i, k in enumerate((*NAMES, "sigma")):
            summary[k]["map"] = float(theta[i]) if i < 5 else sigma
        self.parameters_ = summary
        mean = {k: summary[k]["mean"] for k in NAMES}
        self.structure_ = start.with_element(start.element.__class__(**{**start.element.to_dict(), **mean}))
        self.warnings_ = list(run["warnings"]) + convergence_warnings(summary, self.n_ensembles)
        for w in self.warnings_:
            warnings.warn(w, NegstiffWarning, stacklevel=2)
        self.settings_ = {"windows": int(starts.size), "window_s": L / rec.fs, "n_walkers": self.n_walkers,
                          "n_ensembles": self.n_ensembles, "steps_kept": int(S), "hdi_prob": self.hdi_prob,
                          "residual_correlation_time": tau_res,
                          "curvature_adjustment": [float(x) for x in inflation],
                          "fixed": "masses and the linear structure (springs, dampers) at the start structure's",
                          "start": start.to_dict()}  # fmt: skip
        return self

    def result(self) -> dict[str, Any]:
        """The contract's posterior JSON for a structure's element."""
        return {"hdi_prob": self.hdi_prob, "parameters": self.parameters_, "structure": self.structure_.to_dict(),
                "settings": self.settings_, "warnings": self.warnings_}  # fmt: skip


class _WindowSimulator:
    """The record's windows simulated for many element coefficient sets in one kernel call."""

    def __init__(self, structure: Structure, rec: Measurement, idx: np.ndarray, x0: np.ndarray):
        self.structure, self.rec = structure, rec
        # the input at every Runge-Kutta stage time (band-limited interpolation of the whole record, ``stage_input``):
        # a record's input is band-limited, and over cross-well chaos the linear convention's small error grows
        # (measured on the tests' fixture record, the truth's 0.1 s windows: 31 um rms linear, 0.9 um staged)
        staged = stage_input(rec.u, SUBSTEPS)
        r = 2 * SUBSTEPS
        self.u = np.ascontiguousarray(staged[r * idx[:, 0][:, None] + np.arange(r * (idx.shape[1] - 1) + 1)[None, :]])
        self.x0 = x0
        self.Q: np.ndarray | None = None
        self.W = idx.shape[0]
        self.T = idx.shape[1]
        p, minv, K, C, gain = structure.arrays(rec.input_name, rec.force_dof)
        self.p, self.minv, self.K, self.C, self.gain = p, minv, K, C, gain
        from negstiff.models.effects import POLYNOMIAL_ROWS, ROWS

        self.rows = [POLYNOMIAL_ROWS["k1"], POLYNOMIAL_ROWS["k2"], POLYNOMIAL_ROWS["k3"], ROWS["c"], ROWS["c_nl"]]

    def simulate(self, thetas: np.ndarray) -> np.ndarray:
        """(B, W, N, T) responses for B coefficient sets (k1, k2, k3, c, c_nl)."""
        B, W, nd = thetas.shape[0], self.W, self.structure.n_dof
        nb = B * W
        p = np.repeat(self.p[:, None], nb, axis=1)
        for j, row in enumerate(self.rows):
            p[row] = np.repeat(thetas[:, j], W)
        tile = lambda a: np.ascontiguousarray(np.repeat(a[..., None], nb, axis=-1))  # noqa: E731
        z0 = np.tile(self.x0[:, :nd].T, B)
        v0 = np.tile(self.x0[:, nd:].T, B)
        oz, _, status, _ = integrate(
            KINDS[self.structure.element.kind], np.ascontiguousarray(p), tile(self.minv), tile(self.K), tile(self.C),
            tile(self.gain), self.u, np.tile(np.arange(W), B), self.T, self.rec.dt, SUBSTEPS, z0, v0,
            place=self.structure.place, z_limit=1.0, v_limit=100.0, threads=1,
        )  # fmt: skip
        z = np.transpose(oz, (2, 1, 0)).reshape(B, W, nd, self.T)
        z[status.reshape(B, W) != 0] = np.nan
        return z

    def start_sensitivity(self, theta: np.ndarray) -> None:
        """Each window's response to its start state, d z / d x0 (central differences at ``theta``), kept as an
        orthonormal basis ``Q`` (W, N T, 2N): ``residuals`` projects it out. The windows' start states come from
        the smoothed record (a fixture's velocity off by ~1 %), and over cross-well chaos their error grows into
        the residual within a window; projecting the start-state directions off profiles them out (as the
        single-DOF posterior does), at the cost of 2N degrees of freedom per window.
        """
        nd = self.structure.n_dof
        x0 = self.x0.copy()
        h = np.r_[np.full(nd, 1e-7), np.full(nd, 1e-5)]
        cols = []
        for k in range(2 * nd):
            self.x0 = x0.copy()
            self.x0[:, k] += h[k]
            up = self.simulate(theta[None])[0]
            self.x0[:, k] -= 2 * h[k]
            down = self.simulate(theta[None])[0]
            cols.append(((up - down) / (2 * h[k])).reshape(self.W, -1))
        self.x0 = x0
        G = np.stack(cols, axis=-1)  # (W, N T, 2N)
        self.Q = np.linalg.qr(G)[0]

    def residuals(self, thetas: np.ndarray, data: np.ndarray) -> np.ndarray:
        """(B, n_obs) residuals (simulated - measured) with the start states' directions projected off (when
        ``start_sensitivity`` has run), NaN where a window diverged.
        """
        r = (self.simulate(thetas) - data[None]).reshape(thetas.shape[0], self.W, -1)
        if self.Q is not None:
            r = r - np.einsum("wik,bwk->bwi", self.Q, np.einsum("wik,bwi->bwk", self.Q, r))
        return r.reshape(thetas.shape[0], -1)


def _correlation_time(res: np.ndarray) -> float:
    """Integrated autocorrelation time [samples] of residuals (W, N, T) within their windows: 1 + 2 sum rho_k over
    the lags before rho first falls below 0.05 (1 for white noise).
    """
    r = res - res.mean(axis=-1, keepdims=True)
    var = float(np.mean(r**2))
    if not var > 0:
        return 1.0
    tau = 1.0
    for k in range(1, r.shape[-1] // 2):
        rho = float(np.mean(r[..., k:] * r[..., :-k])) / var
        if rho < 0.05:
            break
        tau += 2 * rho
    return tau


def _gauss_newton(sim: _WindowSimulator, data: np.ndarray, theta: np.ndarray, n_obs: int, iterations: int = 6):
    """Least squares of the windows' residuals from ``theta`` (central-difference Jacobian, one batched call per
    iteration): the point, its covariance sigma^2 (J^T J)^-1, sigma, the last Jacobian and the point's residuals.
    """
    theta = theta.astype(float).copy()
    for _ in range(iterations):
        h = 1e-4 * np.maximum(np.abs(theta), 1e-3)
        pts = np.vstack([theta, theta + np.diag(h), theta - np.diag(h)])
        res = sim.residuals(pts, data)
        if not np.all(np.isfinite(res[0])):
            raise InputError("the start structure's element does not survive the record's windows")
        J = ((res[1:6] - res[6:11]) / (2 * h[:, None])).T
        step = np.linalg.lstsq(J, -res[0], rcond=None)[0]
        theta = theta + step
        if np.all(np.abs(step) < 1e-6 * np.maximum(np.abs(theta), 1e-9)):
            break
    h = 1e-4 * np.maximum(np.abs(theta), 1e-3)  # the Jacobian at the point itself (the scores pair it with r0)
    res = sim.residuals(np.vstack([theta, theta + np.diag(h), theta - np.diag(h)]), data)
    J = ((res[1:6] - res[6:11]) / (2 * h[:, None])).T
    r0 = res[0]
    sigma = float(np.sqrt(np.sum(r0**2) / n_obs))
    cov = sigma**2 * np.linalg.inv(J.T @ J)
    return theta, cov, sigma, J, r0
