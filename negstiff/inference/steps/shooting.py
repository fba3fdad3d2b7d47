"""Least squares for multiple shooting: Levenberg-Marquardt with the windows' start states eliminated.

A multiple-shooting fit (``refine``; Bock & Plitt 1984) has p model parameters q that move every
residual and, per window i, a start state x_i (s components: z0, z0' of each of a structure's N DOFs, s = 2N) that
moves only that window's L residuals r_i. Its Jacobian is [A | B] with B block-diagonal (one L x s block B_i per
window). The damped
Gauss-Newton (Levenberg-Marquardt) step solves

    (J^T J + lam D) d = -J^T r,   D = diag(J^T J) (Marquardt's scaling, floored),

and with B block-diagonal the start states are eliminated window by window (the Schur complement, as
in bundle adjustment: Triggs et al. 2000, section 6.1): with U = sum A_i^T A_i + lam D_q,
W_i = A_i^T B_i, V_i = B_i^T B_i + lam D_i (s x s),

    (U - sum W_i V_i^-1 W_i^T) dq = -(g_q - sum W_i V_i^-1 g_i),   dx_i = -V_i^-1 (g_i + W_i^T dq),

with g_q = sum A_i^T r_i, g_i = B_i^T r_i: a p x p solve and n s x s ones, exact at every step. The
step's damping follows Nielsen (1999): lam *= max(1/3, 1 - (2 rho - 1)^3) on success, doubling growth on
failure, rho the actual over the predicted reduction.

Why it is written here: ``scipy.optimize.least_squares`` takes the Jacobian's sparsity (and groups
the start-state columns, so a Jacobian costs p + s simulations too), but its trust-region solver on a
sparse Jacobian takes inexact LSMR steps that crawl along the weakly determined directions of the
model: on a 300 s rig record's 240 windows it stopped at its 60-evaluation budget with c_nl still
0.4 % from the optimum it reached after 174 (measured). No maintained Python package (scipy, lmfit,
pymoo) solves the block-eliminated normal equations; the elimination is the textbook one.

The residuals come from one callable evaluating a batch of points at once, so the p + s perturbed
points of a Jacobian are one batched simulator call. A ridge on the parameters (``penalty``: rows
w_j q_j appended to the residuals, as a penalised fit writes them) adds w^2 to U's diagonal and w^2 q to
g_q: it touches no start state, so the elimination is unchanged.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

Residuals = Callable[[np.ndarray, np.ndarray], np.ndarray]
"""fun(Q, X) -> R: Q (k, p) parameter points, X (k, n, s) start states, R (k, n, L) residuals."""


@dataclass(frozen=True)
class ShootingFit:
    """The solution: parameters ``q`` (p,), start states ``x`` (n, s), residuals ``fun`` (n, L), the
    residual evaluations (``nfev``, Jacobians not counted, as scipy counts them), the Jacobians
    (``njev``), and why it stopped (``status``: "ftol", "xtol", "max_nfev" or "nonfinite").
    """

    q: np.ndarray
    x: np.ndarray
    fun: np.ndarray
    nfev: int
    njev: int
    status: str
    robust_covariance: np.ndarray | None = None
    """The parameters' covariance at the last Jacobian the fit evaluated, robust over windows
    (``_robust_covariance``: a sandwich whose meat is the windows' scores, the start states eliminated; each window
    one cluster, its samples' errors correlated as a chaotic or smoothed record's are), in the parameters' units: no
    residual variance to multiply by. None where there was no Jacobian, or it is singular."""

    @property
    def cost(self) -> float:
        """Half the sum of squared residuals at the solution."""
        return 0.5 * float(np.sum(self.fun**2))


def _steps(values: np.ndarray, rel: float) -> np.ndarray:
    """Forward-difference steps as scipy's 2-point rule takes them: rel sign(v) max(1, |v|)."""
    return rel * np.where(values >= 0, 1.0, -1.0) * np.maximum(1.0, np.abs(values))


def _jacobian(fun: Residuals, q: np.ndarray, x: np.ndarray, r: np.ndarray, rel: float):
    """A (n, L, p) and B (n, L, s) by forward differences, from one batch of p + s points: one per
    parameter, and one per start-state component moved in every window at once (the windows are
    independent, so each window's residual answers its own start state).
    """
    p, s = q.size, x.shape[1]
    hq = _steps(q, rel)
    hx = _steps(x, rel)  # (n, s)
    Q = np.repeat(q[None], p + s, axis=0)
    Q[np.arange(p), np.arange(p)] += hq
    X = np.repeat(x[None], p + s, axis=0)
    for j in range(s):
        X[p + j, :, j] += hx[:, j]
    R = fun(Q, X) - r[None]
    A = np.moveaxis(R[:p], 0, -1) / hq
    B = np.stack([R[p + j] / hx[:, j, None] for j in range(s)], axis=-1)
    return A, B


def _inverses(V: np.ndarray) -> np.ndarray:
    """Inverses of a stack of symmetric positive definite s x s matrices (n, s, s): by LAPACK, but 2 x 2 blocks (a
    single DOF's start state) by their adjugate, the solver's arithmetic before it took structures: LAPACK's inverse
    moved a refined k2 by 2e-9 relative on a 60 s rig record (measured), which ``reproduce``'s results would show.
    """
    if V.shape[1] == 2:
        a, b, d = V[:, 0, 0], V[:, 0, 1], V[:, 1, 1]
        det = a * d - b * b
        return np.stack([np.stack([d, -b], -1), np.stack([-b, a], -1)], -2) / det[:, None, None]
    return np.linalg.inv(V)


def _diagonal(V: np.ndarray) -> np.ndarray:
    """(n, s) the diagonals of a stack of s x s matrices (a view)."""
    return np.einsum("nii->ni", V)


@dataclass(frozen=True)
class _Normal:
    """The undamped normal equations' blocks at one Jacobian (module docstring): U (p, p), W (n, p, s),
    V (n, s, s), g_q (p,), g_x (n, s), and the diagonal of J^T J's floor for the damping.
    """

    U: np.ndarray
    W: np.ndarray
    V: np.ndarray
    gq: np.ndarray
    gx: np.ndarray
    floor: float

    @classmethod
    def of(cls, A: np.ndarray, B: np.ndarray, r: np.ndarray, w2: np.ndarray, q: np.ndarray) -> _Normal:
        # by BLAS's matrix products, not einsum's loops: 11x faster on a 300 s record's 240 one-second windows
        # (1.3 against 14.5 ms a Jacobian, measured), the sums in another order (1e-14 relative)
        p = A.shape[2]
        flat = A.reshape(A.shape[0] * A.shape[1], p)
        U = flat.T @ flat
        U[np.diag_indices_from(U)] += w2
        Bt = B.transpose(0, 2, 1)
        V = Bt @ B
        top = max(float(np.max(np.diag(U), initial=0.0)), float(_diagonal(V).max()), 1e-300)
        return cls(U, A.transpose(0, 2, 1) @ B, V, flat.T @ r.reshape(-1) + w2 * q, (Bt @ r[:, :, None])[:, :, 0],
                   1e-12 * top)  # fmt: skip


def _step(A, B, ne: _Normal, lam: float, w2: np.ndarray):
    """The damped Gauss-Newton step (dq, dx) with the start states eliminated (module docstring), and
    the linear model's predicted fall of the cost, -(g.d) - |J d|^2 / 2 (computed directly, not as a
    difference of two nearly equal costs).
    """
    Vd = ne.V.copy()
    _diagonal(Vd)[...] += lam * np.maximum(_diagonal(ne.V), ne.floor)
    Vi = _inverses(Vd)
    if A.shape[2]:
        S = ne.U.copy()
        S[np.diag_indices_from(S)] += lam * np.maximum(np.diag(ne.U), ne.floor)
        S -= np.einsum("npk,nkj,nqj->pq", ne.W, Vi, ne.W)
        rhs = -(ne.gq - np.einsum("npk,nkj,nj->p", ne.W, Vi, ne.gx))
        try:
            dq = np.linalg.solve(S, rhs)
        except np.linalg.LinAlgError:
            dq = np.linalg.lstsq(S, rhs, rcond=None)[0]
    else:
        dq = np.zeros(0)
    dx = -np.einsum("nkj,nj->nk", Vi, ne.gx + np.einsum("npk,p->nk", ne.W, dq))
    Jd = np.einsum("nlp,p->nl", A, dq) + np.einsum("nlk,nk->nl", B, dx)
    predicted = -(float(ne.gq @ dq) + float(np.sum(ne.gx * dx))) - 0.5 * float(np.sum(Jd**2) + np.sum(w2 * dq**2))
    return dq, dx, predicted


def shooting_least_squares(
    fun: Residuals,
    q0: np.ndarray,
    x0: np.ndarray,
    max_nfev: int = 60,
    diff_step: float = 1e-7,
    ftol: float = 1e-8,
    xtol: float = 1e-8,
    penalty: np.ndarray | None = None,
    settle: float | None = None,
) -> ShootingFit:
    """Minimise 0.5 |r(q, x)|^2 (+ 0.5 |w q|^2 with a ``penalty`` w) over the parameters q and the
    windows' start states x.

    Parameters
    ----------
    fun : residuals of a batch of points (``Residuals``); q and x in scaled units (order one)
    q0 : (p,) start parameters (p may be 0: the start states alone)
    x0 : (n, s) start states
    max_nfev : residual evaluations at most (the Jacobians' batches not counted)
    diff_step : relative forward-difference step (scipy's ``diff_step``)
    ftol, xtol : scipy's ``least_squares`` tolerances, with its meanings: the cost's relative fall on
        an accepted step, the step's norm relative to the point's (no gradient test: the gradient's size
        depends on the residuals' units). Where no step lowers the cost any more, the damping grows until
        the step vanishes ("xtol"); a non-finite residual or Jacobian ends the fit ("nonfinite"), a trial
        point ``fun`` refuses (ValueError) counts as a failed step
    penalty : (p,) ridge weights w >= 0 on the parameters (the rows w q added to the residuals; ``fun``
        and the returned ``fun`` hold the windows' residuals alone)
    settle : stop ("settled") after an accepted step that lowered the cost by less than one unit of chi-square (the
        residuals' variance, 2 cost / their number) and moved every parameter by less than this fraction of its
        standard error (the window-robust one at the step's Jacobian, ``_robust_covariance``); with no parameter,
        every window's start state by less than this fraction of its own (the Gauss-Newton one, the residuals'
        variance pooled). A fit is then as good as the data can tell: the steps left would move it by a few
        hundredths of its uncertainty at most (they shrink geometrically), while ``ftol`` on a long record's sum of
        squares asks for digits its noise does not hold. None (default): ``ftol`` and ``xtol`` alone
    """
    q, x = np.array(q0, float), np.array(x0, float)
    w2 = np.zeros(q.size) if penalty is None else np.asarray(penalty, float) ** 2
    if w2.shape != q.shape or np.any(~np.isfinite(w2)):
        raise ValueError(f"penalty must be {q.size} finite weights, got {penalty!r}")
    r = fun(q[None], x[None])[0]
    nfev, njev, cost = 1, 0, 0.5 * float(np.sum(r**2) + np.sum(w2 * q**2))
    if not np.isfinite(cost):
        return ShootingFit(q, x, r, nfev, njev, "nonfinite")
    lam, nu, status = 1e-3, 2.0, "max_nfev"
    last = None
    while nfev < max_nfev and status == "max_nfev":
        A, B = _jacobian(fun, q, x, r, diff_step)
        njev += 1
        if not (np.all(np.isfinite(A)) and np.all(np.isfinite(B))):
            status = "nonfinite"
            break
        ne = _Normal.of(A, B, r, w2, q)
        last = (ne, A, r)
        sd_q, sd_x = (None, None) if settle is None else _standard_deviations(ne, A, r, cost)
        while nfev < max_nfev:
            dq, dx, predicted = _step(A, B, ne, lam, w2)
            r_new, new_cost = None, np.inf
            if predicted > 0 and np.all(np.isfinite(dq)) and np.all(np.isfinite(dx)):
                try:
                    r_new = fun((q + dq)[None], (x + dx)[None])[0]
                    new_cost = 0.5 * float(np.sum(r_new**2) + np.sum(w2 * (q + dq) ** 2))
                except ValueError:  # a trial point outside the model's domain (e.g. a mass <= 0)
                    pass
                nfev += 1
            rho = (cost - new_cost) / predicted if predicted > 0 and np.isfinite(new_cost) else -1.0
            if rho > 0:
                fall = cost - new_cost
                step_norm = np.sqrt(np.sum(dq**2) + np.sum(dx**2))
                point_norm = np.sqrt(np.sum(q**2) + np.sum(x**2))
                q, x, r, cost = q + dq, x + dx, r_new, new_cost
                lam *= max(1 / 3, 1 - (2 * rho - 1) ** 3)
                nu = 2.0
                if fall < ftol * cost and rho > 0.25:
                    status = "ftol"
                elif (
                    settle is not None
                    and sd_q is not None
                    and sd_x is not None
                    and fall < 2 * cost / (A.shape[0] * A.shape[1])  # under one unit of the noise's chi-square
                    and np.all(np.abs(dq) < settle * sd_q)
                    and (q.size or np.all(np.abs(dx) < settle * sd_x))
                ):
                    status = "settled"
                elif step_norm < xtol * (xtol + point_norm):
                    status = "xtol"
                break
            # no fall, a fall the linear model did not predict, or a trial that failed: a shorter step
            lam *= nu
            nu *= 2
            if lam > 1e16:  # steps shrunk to nothing and none lowers the cost: at the minimum to rounding
                status = "xtol"
                break
    return ShootingFit(q, x, r, nfev, njev, status, None if last is None else _robust_covariance(*last))


def _standard_deviations(ne: _Normal, A: np.ndarray, r: np.ndarray, cost: float) -> tuple[np.ndarray, np.ndarray]:
    """The standard errors ``settle`` compares a step with, at one Jacobian: the parameters' window-robust ones
    (``_robust_covariance``; zero where it is singular or not finite, so that ``settle`` never stops a fit whose
    uncertainty it cannot size: ``ftol`` and ``xtol`` do) and each window's start state's by Gauss-Newton,
    sigma^2 diag(V_i^-1) with sigma^2 the residuals' pooled variance.
    """
    n, length, p = A.shape
    cov = _robust_covariance(ne, A, r) if p else None
    sd_q = np.zeros(p) if cov is None else np.sqrt(np.clip(np.nan_to_num(np.diag(cov), nan=0.0), 0.0, None))
    s = ne.V.shape[1]
    sigma2 = 2.0 * cost / max(n * length - p - n * s, 1)
    sd_x = np.sqrt(np.clip(sigma2 * _diagonal(_inverses(ne.V)), 0.0, None))
    return sd_q, sd_x


def _robust_covariance(ne: _Normal, A: np.ndarray, r: np.ndarray) -> np.ndarray | None:
    """At one Jacobian, the window-robust covariance S^-1 (sum_i s_i s_i^T) S^-1 n / (n - p): S = U - sum W_i V_i^-1
    W_i^T the undamped Schur complement, s_i = A_i^T r_i - W_i V_i^-1 B_i^T r_i window i's score with its start state
    eliminated (a sandwich with each window one cluster, as ``discrepancy``'s effect intervals and the posterior's
    curvature adjustment read windows). None: singular, or no parameter.
    """
    n, p = A.shape[0], A.shape[2]
    if not p:
        return None
    Vi = _inverses(ne.V)
    try:
        bread = np.linalg.inv(ne.U - np.einsum("npk,nkj,nqj->pq", ne.W, Vi, ne.W))
    except np.linalg.LinAlgError:
        return None
    scores = (A.transpose(0, 2, 1) @ r[:, :, None])[:, :, 0] - np.einsum("npk,nkj,nj->np", ne.W, Vi, ne.gx)
    return bread @ (scores.T @ scores) @ bread * n / max(n - p, 1)


def parameter_covariance(fun: Residuals, fit: ShootingFit, penalty: np.ndarray | None = None,
                         diff_step: float = 1e-7) -> np.ndarray:  # fmt: skip
    """(J^T J)^-1's parameter block at ``fit``'s solution, the start states marginalised (the inverse of
    the Schur complement U - sum W_i V_i^-1 W_i^T), with the ``penalty`` rows in J; multiply by the
    residual variance for the parameters' covariance. One more Jacobian (p + s simulations).
    """
    q = fit.q
    w2 = np.zeros(q.size) if penalty is None else np.asarray(penalty, float) ** 2
    A, B = _jacobian(fun, q, fit.x, fit.fun, diff_step)
    ne = _Normal.of(A, B, fit.fun, w2, q)
    S = ne.U - np.einsum("npk,nkj,nqj->pq", ne.W, _inverses(ne.V), ne.W)
    return np.linalg.inv(S)
