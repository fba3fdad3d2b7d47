"""A hybrid model: the physics plus a non-parametric discrepancy force, fitted by output error.

The discrepancy catalogue can only name what it lists. What remains after the best physical model is
quantified here by a smooth regressor of the missing force on the state and the input,

    m z'' + D(z') + K(z) + g(z, z', u) = (input),
    g(z, z', u) = sum_ij W_ij phi_i(z) psi_j(z') + sum_k a_k chi_k(u),

with Gaussian bumps phi, psi, chi on even grids over the range the record visits (a tensor-product
radial-basis network: smooth, local, linear in its weights), kept orthogonal over the visited states to
every force the physics can make (1, z, z^2, z^3, z', z'|z'|), so g carries only what the physics
cannot. The weights are fitted by the simulation error on multiple-shooting windows with the physical
part held (``refine``'s machinery: free start states, fitted first, then Levenberg-Marquardt with the
start states eliminated, ``shooting``), with a ridge penalty that keeps g at zero where the data do not
ask for it; then physics and g are fitted together (the hybrid). How far the physical coefficients
move, in units of their own standard error, says whether the physics-only fit had bent to cover the
missing force.

Why written here: the term must live inside the Runge-Kutta loop of a free run (an output-error fit
simulates it tens of thousands of times); a Gaussian process or scikit-learn regressor would be
called per stage from Python. The kernel reuses the simulator's own physical force (``kernel.force``), so
the physics is exactly the physical model's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import linalg

from negstiff.errors import MeasurementError
from negstiff.inference.record.measurement import Measurement
from negstiff.inference.steps.refine import (
    SystemParameters,
    channel_windows,
    parameter_names,
    parameter_scales,
    spread_windows,
    values_of,
    with_values,
)
from negstiff.inference.steps.shooting import parameter_covariance, shooting_least_squares
from negstiff.inference.steps.validation import divergence_limits, record_substeps, restart_windows, staged_windows
from negstiff.models import Model
from negstiff.models.kernel import grid_constants
from negstiff.models.simulator import simulate_batch, stage_input
from negstiff.models.structure import Structure, relative, simulate_structures


@dataclass(frozen=True)
class Basis:
    """Centres and widths of the bumps: ``nz`` x ``nv`` over the (z, z') range the record visits (its
    0.5-99.5 % quantiles), ``nu`` over the input's; widths equal to the grid spacing.
    """

    zc: np.ndarray
    vc: np.ndarray
    uc: np.ndarray
    wz: float
    wv: float
    wu: float

    @classmethod
    def over(cls, z: np.ndarray, v: np.ndarray, u: np.ndarray, nz: int = 7, nv: int = 5, nu: int = 5) -> Basis:
        """A basis whose centres span the 0.5-99.5 % quantiles of ``z``, ``v`` and ``u`` (``nz`` x ``nv`` + ``nu``)."""

        def grid(x, k):
            lo, hi = np.quantile(x, [0.005, 0.995])
            c = np.linspace(lo, hi, k) if k > 1 else np.array([0.5 * (lo + hi)])[:k]
            return c, float((hi - lo) / max(k - 1, 1)) or 1.0

        zc, wz = grid(z, nz)
        vc, wv = grid(v, nv)
        uc, wu = grid(u, nu) if nu else (np.empty(0), 1.0)
        return cls(zc, vc, uc, wz, wv, wu)

    @property
    def size(self) -> int:
        """The number of basis functions (weights)."""
        return self.zc.size * self.vc.size + self.uc.size

    def split(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The weights as the (z, v) grid's matrix and the input's vector."""
        k = self.zc.size * self.vc.size
        return np.ascontiguousarray(theta[:k].reshape(self.zc.size, self.vc.size)), np.ascontiguousarray(theta[k:])

    @staticmethod
    def _bumps(x, centres: np.ndarray, width: float) -> np.ndarray:
        """The 1-D bumps at the points ``x`` (any shape): shape x.shape + (centres,)."""
        return np.exp(-0.5 * ((np.asarray(x, float)[..., None] - centres) / width) ** 2)

    def features(self, z, v, u) -> np.ndarray:
        """The bumps at the points (n,): an (n, size) matrix, g = features @ theta."""
        bz, bv = self._bumps(z, self.zc, self.wz), self._bumps(v, self.vc, self.wv)
        return np.column_stack(
            [(bz[:, :, None] * bv[:, None, :]).reshape(len(bz), -1), self._bumps(u, self.uc, self.wu)]
        )

    def evaluate(self, theta: np.ndarray, z, v, u=None) -> np.ndarray:
        """G at the points (z, z', u) [N], any shape (u None: the state part alone)."""
        w, _ = self.split(np.asarray(theta, float))
        g = np.einsum("...i,ij,...j->...", self._bumps(z, self.zc, self.wz), w, self._bumps(v, self.vc, self.wv))
        return g if u is None else g + self.input_part(theta, u)

    def input_part(self, theta: np.ndarray, u) -> np.ndarray:
        """The part of g that depends on the input alone, at the inputs ``u`` [N]."""
        _, a = self.split(np.asarray(theta, float))
        return self._bumps(u, self.uc, self.wu) @ a

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> Basis:
        """The basis of a result's ``basis`` entry."""
        return cls(np.array(d["z_centres"]), np.array(d["v_centres"]), np.array(d["u_centres"]), *d["widths"])

    def to_json(self) -> dict[str, Any]:
        """The basis as JSON: its centres and widths."""
        return {"z_centres": self.zc.tolist(), "v_centres": self.vc.tolist(), "u_centres": self.uc.tolist(),
                "widths": [self.wz, self.wv, self.wu]}  # fmt: skip


def simulate_hybrid(
    model: Model, basis: Basis, theta, u_staged: np.ndarray, dt: float, x0: np.ndarray, substeps: int,
    input_kind: str, z_limit: float, v_limit: float,
) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Free runs of physics + g from the start states ``x0`` (B, 2) under staged input rows (B, S);
    returns z and z' (N, B), NaN after a divergence.
    """
    u2 = np.atleast_2d(np.asarray(u_staged, float))
    x0 = np.atleast_2d(np.asarray(x0, float))
    nb = x0.shape[0]
    # the simulator's own Runge-Kutta loop, with g as its extra force (``kernel.extra_term``)
    res = simulate_batch(
        np.repeat(model.kernel_params()[:, None], nb, axis=1), model.kind, u2, dt, x0, input_kind=input_kind,
        input_index=np.arange(nb), substeps=substeps, store_velocity=True, z_limit=z_limit, v_limit=v_limit,
        threads=1, staged=True, hook=_hook(basis, theta),
    )  # fmt: skip
    assert res.z_dot is not None
    return res.z.T, res.z_dot.T


@dataclass
class Hybrid:
    """A fitted hybrid: the physical model, the discrepancy term's basis and weights [N], and the fit's
    record (stages, the joint refit's coefficient shifts in standard errors).
    """

    model: Model
    basis: Basis
    theta: np.ndarray
    info: dict[str, Any] = field(default_factory=dict)

    def held(self) -> Hybrid:
        """The held fit: the physical model as it was given (its coefficients unchanged) plus the term
        fitted with it held. It cannot undo a bend of the physics (the term is orthogonal to the
        physics' own forces), so where the physics-only fit had bent a coefficient it predicts worse than
        the joint fit; where term and physics trade (the Silverbox's cubic) it keeps the physics' own
        estimate and, with the bumps vanishing beyond the training range, extrapolates as the physics.
        """
        held = self.info["held"]
        return Hybrid(Model.from_dict(held["model"]), self.basis, np.asarray(held["weights_N"], float),
                      {"fit": "physics held", "joint": self.info.get("joint")})  # fmt: skip

    def term(self, z, v, u=None) -> np.ndarray:
        """The non-parametric force g(z, v, u) [N] at the given states."""
        return self.basis.evaluate(self.theta, z, v, u)

    def free_run(self, rec: Measurement, x0) -> np.ndarray:
        """Z of a free run over ``rec`` from ``x0`` (NaN after a divergence)."""
        sub = record_substeps(self.model, rec)
        zs, vs, _, _ = rec.states("state")
        us = rec.staged(self.model, sub)[None]  # with any measured channel's term (its u)
        x = np.asarray(x0, float)[None]
        oz, _ = simulate_hybrid(self.model, self.basis, self.theta, us, rec.dt, x, sub, rec.input_name,
                                **divergence_limits(rec.displacement, vs))  # fmt: skip
        return oz[:, 0]

    def restarted_gap(self, rec: Measurement, start: int, window_s: float, zs, vs) -> dict[str, float]:
        """The median restarted window's rms error over [start, N) (``validation.restart_windows``: the single
        DOF's validation windows, and the measured start states), % of rms(z), for the hybrid and for its physics
        alone (the same windows with the term's weights at zero).
        """
        windows = restart_windows(rec.n, rec.fs, window_s, start=start)
        if len(windows) < 1:
            return {}
        U, sub = staged_windows(self.model, rec, windows.starts, windows.length)
        meas = windows.measured(rec.displacement)
        x0 = windows.start_states(zs, vs)
        scale = float(np.sqrt(np.mean(rec.displacement[start:] ** 2)))
        limits = divergence_limits(rec.displacement, vs)
        out = {}
        for name, theta in (("physics", np.zeros_like(self.theta)), ("hybrid", self.theta)):
            oz, _ = simulate_hybrid(self.model, self.basis, theta, U, rec.dt, x0, sub, rec.input_name, **limits)
            ms = np.mean((oz.T - meas) ** 2, axis=1)
            ok = np.isfinite(ms)
            out[f"{name}_median_window_percent"] = (
                float(100 * np.sqrt(np.median(ms[ok])) / scale) if ok.any() else math.inf
            )
        return out

    def to_json(self) -> dict[str, Any]:
        """The hybrid model as JSON: the physics, the basis and its weights [N]."""
        return {"model": self.model.to_dict(), "basis": self.basis.to_json(), "weights_N": self.theta.tolist(),
                **self.info}  # fmt: skip


def _correlation_time(e: np.ndarray) -> float:
    """Integrated autocorrelation time [samples] of window residuals ``e`` (windows, samples), pooled
    over the windows: 1 + 2 sum of the autocorrelation over lags up to its first non-positive value
    (Geyer's initial positive sequence, as emcee's and arviz's ESS do for chains; written here because
    theirs take chains, not many short residual windows).
    """
    e = e - e.mean(axis=1, keepdims=True)
    var = float(np.mean(e**2))
    if var <= 0:
        return 1.0
    tau = 1.0
    for k in range(1, e.shape[1] // 2):
        rho = float(np.mean(e[:, k:] * e[:, :-k])) / var
        if rho <= 0:
            break
        tau += 2 * rho
    return tau


def _orthogonal_weights(basis: Basis, zs: np.ndarray, vs: np.ndarray, u: np.ndarray) -> np.ndarray:
    """An orthonormal basis N of the bump weights whose term is orthogonal, over the states the record
    visits, to every force the physics can make (1, z, z^2, z^3, z', z'|z'|).
    """
    pick = slice(None, None, max(1, zs.size // 20000))
    zp, vp, up = zs[pick], vs[pick], u[pick]
    F = np.column_stack([np.ones_like(zp), zp, zp**2, zp**3, vp, vp * np.abs(vp)])
    Phi = basis.features(zp, vp, up)
    N = linalg.null_space((F / np.linalg.norm(F, axis=0)).T @ (Phi / np.linalg.norm(Phi, axis=0)))
    N = N / np.linalg.norm(Phi, axis=0)[:, None]
    return np.linalg.qr(N)[0]


def _coefficient_shifts(sol, cov_unit: np.ndarray, names, q0: np.ndarray, pscale: np.ndarray) -> tuple[dict, float]:
    """How far the joint refit moved each physical coefficient, in its standard errors: (J^T J)^-1 at the
    solution with the start states marginalised (``cov_unit``: ``shooting.parameter_covariance``) times
    the residual variance, inflated by the residual's correlation time (coloured residuals: tau samples
    carry one sample's information).
    """
    p = len(names)
    n_res = sol.fun.size
    dof = max(1, n_res - sol.q.size - sol.x.size)
    s2 = float(np.sum(sol.fun**2) / dof)
    tau = _correlation_time(sol.fun)
    diag = np.diag(cov_unit)[:p] if np.all(np.isfinite(cov_unit)) else np.full(p, np.nan)
    se = np.sqrt(np.clip(s2 * diag, 0, None)) * pscale
    moved = (sol.q[:p] - q0) * pscale
    se_white = se
    se = se * math.sqrt(tau)
    shifts = {
        n: {"held": float(q0[i] * pscale[i]), "joint": float(sol.q[i] * pscale[i]), "se": float(se[i]),
            "se_white": float(se_white[i]), "shift_in_se": float(moved[i] / se[i]) if se[i] > 0 else None}
        for i, n in enumerate(names)
    }  # fmt: skip
    return shifts, tau


def fit_hybrid(
    model: Model,
    rec: Measurement,
    windows_s: tuple[float, ...] = (1.0,),
    max_windows: int = 60,
    ridge: float = 1e-2,
    shape: tuple[int, int, int] = (6, 4, 3),
    max_nfev: int = 20,
) -> Hybrid:
    """Fit the discrepancy term to ``rec`` (the identification part) with ``model``'s physics held, then
    refit physics and term together and report how far each physical coefficient moved.

    ``ridge``: the penalty on the weights, as a fraction of the residual a weight of the physical force's
    size (|k1| z_rms) would cost on one window sample; ``shape``: bumps over z, z' and u.
    """
    if rec.z is None:
        raise MeasurementError(f"{rec.source}: a hybrid model needs a response")
    zs, vs, _, _ = rec.states("state")
    drive = rec.driving(model)  # the input, plus a measured channel's term the physics holds (the term's u)
    basis = Basis.over(zs, vs, drive, *shape)
    limits = divergence_limits(rec.z, vs)
    sub = record_substeps(model, rec)
    us = stage_input(drive, sub)
    r = 2 * sub
    z_rms, v_rms = float(np.std(rec.z)), float(np.std(vs))
    force = max(abs(model.k1) * z_rms, abs(model.c) * v_rms, 1e-300)
    x_scale = np.array([max(np.abs(rec.z).max(), 1e-12), max(np.abs(vs).max(), 1e-12)])
    names = parameter_names(model, free_mass=False)
    pscale = parameter_scales(model, names, z_rms, v_rms)
    q0 = values_of(model, names) / pscale
    # the term is kept orthogonal, over the states the record visits, to every force the physics can
    # make (1, z, z^2, z^3, z', z'|z'|): it can carry only what the physics cannot, so it cannot trade
    # against a physical coefficient (measured on the Silverbox without this: the joint refit moved k3
    # by 6 and k1 by 5 standard errors). Weights theta = N phi, N an orthonormal null-space basis.
    N = _orthogonal_weights(basis, zs, vs, drive)
    P = N.shape[1]
    theta = np.zeros(basis.size)
    stages = []

    def windows(w_s):
        length = min(rec.n, max(8, int(round(w_s * rec.fs))))
        n_win = min(max_windows, max(1, rec.n // length))
        starts = np.linspace(0, rec.n - length, n_win).astype(int)
        meas = np.stack([rec.z[s : s + length] for s in starts])
        u = np.stack([us[r * s : r * (s + length - 1) + 1] for s in starts])
        return length, n_win, meas, u, np.column_stack([zs[starts], vs[starts]]) / x_scale

    def sim(phys: Model, th, u, xs):
        oz, _ = simulate_hybrid(phys, basis, th, u, rec.dt, xs * x_scale, sub, rec.input_name, **limits)
        return oz.T

    pen = math.sqrt(ridge) * z_rms  # a weight of size `force` costs ridge * z_rms^2 in the sum of squares

    def residuals(length, meas, u, phys_of):
        """The batched residuals (``shooting.Residuals``) of points (q, X): q's physics (``phys_of``) and
        term weights, every window's free run from its start states (scaled) X.
        """
        big = 10 * np.abs(meas).max()

        def fun(Q, X):
            out = np.empty((Q.shape[0], *meas.shape))
            for k, (q, xs) in enumerate(zip(Q, X, strict=False)):
                phys, t = phys_of(q)
                z = sim(phys, N @ t * force, u, xs)
                out[k] = np.where(np.isfinite(z), z - meas, big)  # a diverging window: large, finite
            return out

        return fun

    for w_s in windows_s:
        length, n_win, meas, u, x0 = windows(w_s)
        held_fun = residuals(length, meas, u, lambda q: (model, q))
        t0 = N.T @ theta / force
        # the start states first, the term held (the measured states carry the smoothing's error)
        st = shooting_least_squares(lambda Q, X: held_fun(np.repeat(t0[None], len(X), 0), X), np.zeros(0), x0, 10)
        rms0 = float(np.sqrt(np.mean(st.fun**2)))
        sol = shooting_least_squares(held_fun, t0, st.x, max_nfev, penalty=np.full(P, pen))
        theta, states = N @ sol.q * force, sol.x
        stages.append({"window_s": length / rec.fs, "windows": int(n_win), "rms_start_m": rms0,
                       "rms_end_m": float(np.sqrt(np.mean(sol.fun**2))), "evaluations": int(sol.nfev),
                       "jacobians": int(sol.njev), "stop": sol.status})  # fmt: skip

    # the joint refit: physics and term together, from the held fit, on the last stage's windows
    p = len(names)
    joint_fun = residuals(length, meas, u, lambda q: (with_values(model, names, q[:p] * pscale), q[p:]))
    penalty = np.concatenate([np.zeros(p), np.full(P, pen)])
    sol = shooting_least_squares(joint_fun, np.concatenate([q0, N.T @ theta / force]), states, max_nfev,
                                 penalty=penalty)  # fmt: skip
    shifts, tau = _coefficient_shifts(sol, parameter_covariance(joint_fun, sol, penalty), names, q0, pscale)
    # the hybrid is the joint fit: with the term orthogonal to the physics' own forces, the physics
    # must move where its output-error fit had bent to cover the missing force (that bend is the shift)
    joint_model, weights = with_values(model, names, sol.q[:p] * pscale), N @ sol.q[p:] * force
    joint_info = {"rms_end_m": float(np.sqrt(np.mean(sol.fun**2))), "evaluations": int(sol.nfev),
                  "jacobians": int(sol.njev), "stop": sol.status,
                  "residual_correlation_samples": tau, "coefficients": shifts, "model": joint_model.to_dict(),
                  "weights_N": weights.tolist()}  # fmt: skip
    held = {"model": model.to_dict(), "weights_N": theta.tolist(), "stages": stages}
    return Hybrid(joint_model, basis, weights, {"ridge": ridge, "joint": joint_info, "held": held})


# --- a structure's: the element's term ------------------------------------------------------------------------------
def _hook(basis: Basis, theta: np.ndarray) -> tuple:
    """The kernel's extra force hook (``kernel.extra_term``'s arguments) of ``basis`` at weights ``theta`` [N]."""
    w, a = basis.split(np.asarray(theta, float))
    return (np.ascontiguousarray(w), np.ascontiguousarray(a), basis.zc, basis.vc, basis.uc,
            grid_constants(basis.zc, basis.wz), grid_constants(basis.vc, basis.wv),
            grid_constants(basis.uc, basis.wu))  # fmt: skip


@dataclass
class ElementTerm:
    """A structure's hybrid term: the element's non-parametric force g(r, r', u) [N] over its relative motion r (in
    the structure's physical frame, the channels' ``offsets`` off) and the input, added to the element's force (on
    DOF J, opposite on DOF I), fitted by output error with the structure (``fit_element_term``: jointly with the
    structure's parameters; ``held()``, with the structure held).
    """

    structure: Structure
    offsets: np.ndarray
    basis: Basis
    theta: np.ndarray
    info: dict[str, Any] = field(default_factory=dict)

    def held(self) -> ElementTerm:
        """The held fit: the structure as it was given plus the term fitted with it held (``fit_hybrid``'s
        ``Hybrid.held``).
        """
        h = self.info["held"]
        return ElementTerm(Structure.from_dict(h["structure"]), self.offsets, self.basis,
                           np.asarray(h["weights_N"], float), {"fit": "structure held"})  # fmt: skip

    def term(self, r, rv, u=None) -> np.ndarray:
        """g(r, r', u) [N] at the given relative states (and input)."""
        return self.basis.evaluate(self.theta, r, rv, u)

    def window_errors(self, rec: Measurement, starts: np.ndarray, length: int, theta=None) -> np.ndarray:
        """Each window's mean-square error over every channel, each in its rms over the record (W,), the structure
        with the term at weights ``theta`` (default its own; zeros: the physics alone) run from the measured state
        at each start under the staged input; infinite where the run diverged.
        """
        s, o = self.structure, np.asarray(self.offsets, float)
        sub = record_substeps(s, rec)
        zs, vs = rec.free_run_states()
        zs = zs - o[:, None]
        meas, U, x0 = channel_windows(rec, rec.staged(s.element, sub), zs, vs, starts, length, sub)
        res = simulate_structures(s, U, rec.dt, x0, input_kind=rec.input_name, force_dof=rec.force_dof,
                                  input_index=np.arange(len(starts)), substeps=sub, staged=True,
                                  hook=_hook(self.basis, self.theta if theta is None else theta),
                                  **divergence_limits(rec.channels - o[:, None], vs))  # fmt: skip
        raw = rec.channels
        scale = np.sqrt(np.mean((raw - raw.mean(axis=1, keepdims=True)) ** 2, axis=1))
        with np.errstate(invalid="ignore", over="ignore"):
            ms = np.mean(((res.z + o[None, :, None] - meas) / scale[None, :, None]) ** 2, axis=(1, 2))
        return np.where(res.diverged, np.inf, ms)

    def restarted_gap(self, rec: Measurement, start: int, window_s: float) -> dict[str, Any]:
        """The median restarted window's rms error over [start, N) in % of the channels' rms (windows of ``window_s``
        restarted from the measured states, the input staged): the structure as it was given alone (``physics``),
        with the term fitted with it held (``held``), and the joint fit (``hybrid``); each fit's paired comparison
        with the structure alone (``paired_held``, ``paired``: ``_judging.paired_windows``).
        """
        from negstiff.inference.estimators.discrepancy._judging import paired_windows

        windows = restart_windows(rec.n, rec.fs, window_s, start=start, min_step=8)
        if len(windows) < 2:
            return {}
        base = self.held() if "held" in self.info else self
        runs = {"physics": base.window_errors(rec, windows.starts, windows.length, np.zeros_like(self.theta)),
                "held": base.window_errors(rec, windows.starts, windows.length),
                "hybrid": self.window_errors(rec, windows.starts, windows.length)}  # fmt: skip
        out: dict[str, Any] = {"windows": len(windows), "window_s": windows.length / rec.fs}
        for name, ms in runs.items():
            ok = np.isfinite(ms)
            out[f"{name}_median_window_percent"] = float(100 * np.sqrt(np.median(ms[ok]))) if ok.any() else math.inf
        out["paired"] = paired_windows(runs["physics"], runs["hybrid"], worst=1.0)
        out["paired_held"] = paired_windows(runs["physics"], runs["held"], worst=1.0)
        return out

    def to_json(self) -> dict[str, Any]:
        """The term as JSON: its basis and weights [N], and the fit's account."""
        return {"basis": self.basis.to_json(), "weights_N": self.theta.tolist(), **self.info}


def fit_element_term(structure: Structure, offsets, rec: Measurement, window_s: float = 0.25, max_windows: int = 120,
                     ridge: float = 1e-2, shape: tuple[int, int, int] = (6, 4, 3),
                     max_nfev: int = 20) -> ElementTerm:  # fmt: skip
    """The single DOF's hybrid term (``fit_hybrid``'s held fit) on a structure's element: bumps over the element's
    relative displacement and velocity and the input (its driving input, ``Measurement.driving``), kept orthogonal
    over the states the record visits to the cubic law's forces (1, r, r^2, r^3, r', r'|r'|, as the single DOF's),
    their weights fitted by the simulation error of
    every channel (each weighed to the element's channel's rms, as the structure's refinement weighs them) on
    ``window_s`` windows over ``rec`` (the identification part: pass a segment), their start states fitted first,
    with the structure held and the ridge penalty of ``fit_hybrid``; then, as ``fit_hybrid``'s second stage, the
    structure's parameters and the term together from there (the joint fit, returned; ``held()`` the first). The
    term is a force pair across the element: what
    the held structure misses elsewhere (a fixture's spring, a mass) it takes in where that projects onto the
    element's relative motion and the input, so calling it the element's is an attribution the fit assumes.
    """
    nd, at = structure.n_dof, structure.place
    o = np.asarray(offsets, float)
    zs, vs = rec.free_run_states()
    zs = zs - o[:, None]
    r, rv = relative(zs, at), relative(vs, at)
    el = structure.element
    drive = np.asarray(rec.driving(el), float)  # what the hook reads, staged (``Measurement.staged``)
    basis = Basis.over(r, rv, drive, *shape)
    N = _orthogonal_weights(basis, r, rv, drive)
    P = N.shape[1]
    raw = rec.channels
    z_all = raw - o[:, None]
    rms = np.sqrt(np.mean((z_all - z_all.mean(axis=1, keepdims=True)) ** 2, axis=1))
    j = at[1] - 1
    weight = (rms[j] / np.where(rms > 0, rms, rms[j]))[:, None]
    force = max(abs(el.k1) * float(np.std(r)), abs(el.c) * float(np.std(rv)), 1e-300)
    sub = record_substeps(structure, rec)
    limits = divergence_limits(z_all, vs)
    x_scale = np.concatenate([np.maximum(np.abs(z_all).max(axis=1), 1e-12), np.maximum(np.abs(vs).max(axis=1), 1e-12)])
    length, starts = spread_windows(rec, window_s, max_windows, nd)
    n_win = starts.size
    meas, u, x0 = channel_windows(rec, rec.staged(el, sub), zs, vs, starts, length, sub)
    x0 = x0 / x_scale
    big = 10 * float(np.abs(meas).max())
    pen = math.sqrt(ridge) * float(rms[j])  # a weight of size ``force`` costs ridge * rms^2 in the sum of squares

    def residuals(system_of):
        """The batched residuals (``shooting.Residuals``) of points (q, X): q's structure and term weights
        (``system_of``), every window's run of every channel from its start states (scaled) X.
        """

        def fun(Q, X):
            out = np.empty((Q.shape[0], n_win, nd * length))
            for k, (q, xs) in enumerate(zip(Q, X, strict=True)):
                s, t = system_of(q)
                res = simulate_structures(s, u, rec.dt, xs * x_scale, input_kind=rec.input_name,
                                          force_dof=rec.force_dof, input_index=np.arange(n_win), substeps=sub,
                                          staged=True, hook=_hook(basis, N @ t * force), **limits)  # fmt: skip
                e = (res.z + o[None, :, None] - meas) * weight
                e[res.diverged] = big  # a diverging window: large, finite
                out[k] = e.reshape(n_win, -1)
            return out

        return fun

    held_fun = residuals(lambda q: (structure, q))
    t0 = np.zeros(P)
    st = shooting_least_squares(lambda Q, X: held_fun(np.repeat(t0[None], len(X), 0), X), np.zeros(0), x0, 10)
    rms0 = float(np.sqrt(np.mean(st.fun**2)))
    sol = shooting_least_squares(held_fun, t0, st.x, max_nfev, penalty=np.full(P, pen))
    held_theta = N @ sol.q * force
    held = {"structure": structure.to_dict(), "weights_N": held_theta.tolist(), "rms_start_m": rms0,
            "rms_end_m": float(np.sqrt(np.mean(sol.fun**2))), "evaluations": int(sol.nfev),
            "stop": sol.status}  # fmt: skip
    # the joint refit, as the single DOF's: the structure's parameters (its element's, its linear entries; the
    # element's constant held at the weight its frame pins, the channels' zeros held) and the term together, from
    # the held fit, on the same windows; how far each parameter moved in its standard errors says whether the
    # structure had bent to cover the missing force
    params = SystemParameters.of(structure, held=("k0",))
    names = params.names
    p = len(names)
    pscale = params.scales(float(np.std(z_all[j])), float(np.std(vs[j])))
    q0 = params.values() / pscale
    joint_fun = residuals(lambda q: (params.structure(q[:p] * pscale), q[p:]))
    penalty = np.concatenate([np.zeros(p), np.full(P, pen)])
    solj = shooting_least_squares(joint_fun, np.concatenate([q0, sol.q]), sol.x, max_nfev, penalty=penalty)
    shifts, tau = _coefficient_shifts(solj, parameter_covariance(joint_fun, solj, penalty), names, q0, pscale)
    joint_structure, weights = params.structure(solj.q[:p] * pscale), N @ solj.q[p:] * force
    joint = {"rms_end_m": float(np.sqrt(np.mean(solj.fun**2))), "evaluations": int(solj.nfev), "stop": solj.status,
             "residual_correlation_samples": tau, "coefficients": shifts, "structure": joint_structure.to_dict(),
             "weights_N": weights.tolist()}  # fmt: skip
    info = {"ridge": ridge, "window_s": length / rec.fs, "windows": int(n_win), "joint": joint, "held": held}
    return ElementTerm(joint_structure, o, basis, weights, info)
