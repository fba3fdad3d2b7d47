"""Output-error refinement: the prediction-error method as the last stage of an identification.

NSI and SINDy fit derivatives of noisy, band-limited data (equation error); a user judges a model by
what it predicts, its simulation error. ``refine`` starts from a method's estimate and minimises the
simulation error of the model over the identification part of a record (Ljung, *System
Identification*, 2nd ed., 7.3, the output-error model; multiple shooting after Bock & Plitt 1984):

* The part is cut into windows; each window is simulated from its own start state (z0, z0'), a free
  parameter started at the measured state (``derivatives.state_derivatives``), under the measured
  input, all windows in one batched simulator call. Short windows keep a poor start model (and a
  chaotic cross-well response) from running away; the schedule then widens them (``windows_s``), each
  stage started from the last, so the final fit matches long free runs where the dynamics allow.
  The first stage is short (0.05 s): from a start 5 % off in k1-k3 on a cross-well record, 0.25 s
  windows already crossed wells (4 mm rms) and the fit wandered off (k2 +2400 %); 0.05 s windows
  brought it to the truth within 0.02 % (measured).
* The parameters are those of the physical model: k0 (the constant force: gravity, a static load or
  the force's offset), k1, k2, k3, c, c_nl and the named extra effects, each scaled by its start
  value; for a force input without a known mass the mass too (the input's gain 1/m).
* Levenberg-Marquardt with the windows' start states eliminated (``shooting``: a window's start state
  moves only that window's residuals, so the normal equations reduce to a p x p solve), with a
  finite-difference Jacobian that costs the model's p parameters plus two simulations, all in one
  batched simulator call. ``scipy.optimize.least_squares`` given the same sparsity (the solver before)
  took inexact steps that stopped short of the optimum within its evaluation budget (``shooting``).

The system refined is a structure of N DOFs (``models.structure``): its element's parameters (as above) and each
nonzero entry of its linear structure's stiffness and damping matrices, every DOF's channel in the residuals and
every DOF's z0, z0' a window's start state. The single-DOF ``Model`` is the structure of one DOF on the base (no
linear entries, one channel): the same code, the same numbers.

The result keeps the start model (``initial_model``) beside the refined one, with the simulation
error of each stage.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import optimize, sparse

from negstiff.errors import MeasurementError
from negstiff.inference.record.measurement import Measurement
from negstiff.inference.steps.shooting import ShootingFit, parameter_covariance, shooting_least_squares
from negstiff.inference.steps.validation import (
    boundedness,
    divergence_limits,
    record_substeps,
    validate,
)
from negstiff.models import Model, effects
from negstiff.models.structure import Structure, as_structure, simulate_structures

PREDICTABLE_GROWTH = 5.0
"""A stage of longer windows is fitted only while its error at the current model stays within this
factor of the shorter windows' fitted error. Beyond it the response is not predictable over the window
(cross-well chaos parts nearby states exponentially, or the model's form cannot follow it), and a fit
would trade the physics for diverging trajectories. Measured: on a 300 s cross-well record of the
as-built device the 0.25 s windows started 33x above the 0.05 s windows' error, and fitting 1 s windows
moved k0 from 1.4 N to -0.8 N and k2 tenfold; on the Silverbox the growth was 2.8x and 1.7x."""


def scalar_effects() -> tuple[str, ...]:
    """Named extra effects with one scalar coefficient (the registry's), refined with the base coefficients."""
    return tuple(e.name for e in effects.REGISTRY if e.scalar)


@dataclass(frozen=True)
class Refinement:
    """What ``refine`` found: the refined system (a ``Model`` or a ``Structure``, as given), the start one, the
    names refined and, per stage, the window length, count and the rms simulation error (m) at its start and end.
    """

    model: Any
    initial_model: Any
    parameters: tuple[str, ...]
    stages: list[dict[str, Any]] = field(default_factory=list)
    offsets: np.ndarray | None = None
    """A structure's channels' zeros as refined [m] (None: a single DOF's z frame, not refined)."""
    standard_errors: dict[str, float] | None = None
    """Each refined parameter's local standard error (``_standard_errors``), in its own unit."""

    def to_json(self) -> dict[str, Any]:
        """The refinement's account as JSON: parameters, stages, held-out errors and why it was kept."""
        out = {
            "parameters": list(self.parameters),
            "stages": self.stages,
            "initial_model": self.initial_model.to_dict(),
        }
        if self.offsets is not None:
            out["offsets_m"] = self.offsets.tolist()
        if self.standard_errors is not None:
            out["standard_errors"] = self.standard_errors
        return out


def field_effects(model: Model) -> tuple[str, ...]:
    """The model's named effects with several values (``effects.Effect.scalar`` false: an end stop's
    ``{"k", "z"}``, a magnet's ``{"A", "d"}``, a spline's coefficients ``c0``, ``c1``, ...), each refined under
    the name ``EFFECT.PARAMETER`` (the law's ``parameters``).
    """
    named = [e for e in effects.REGISTRY if not e.scalar and e.name in model.extra]
    return tuple(f"{e.name}.{f}" for e in named for f in _fielded(e.name).parameters(model.extra[e.name]))


def _fielded(name: str) -> effects.OneSidedStop | effects.ShapedLaw:
    """The law of an effect with several values (its ``parameters`` and ``with_parameters``)."""
    law = effects.get(name).law
    assert isinstance(law, effects.OneSidedStop | effects.ShapedLaw)
    return law


def parameter_names(model: Model, free_mass: bool, held=()) -> tuple[str, ...]:
    """The parameters refined: the base fields (but those ``held``), the model's named scalar effects, the
    values of its named effects with several (``EFFECT.FIELD``: an end stop's stiffness and onset, refined
    like the others) and the mass when free. A named effect that folds into a base field
    (``effects.Effect.folds_into``) is refined and that field is not (the two are the same term; refining
    both leaves a redundant direction).
    """
    named = [e for e in scalar_effects() if e in model.extra]
    out = {effects.get(e).folds_into for e in named} | set(held)
    base = [n for n in ("k0", "k1", "k2", "k3", "c", "c_nl") if n not in out]
    base += named + list(field_effects(model))
    return tuple(base + (["m"] if free_mass else []))


def values_of(model: Model, names) -> np.ndarray:
    """The current values of the parameters ``names`` (``parameter_names``)."""
    d = {**model.to_dict(), **dict(model.extra)}
    out = []
    for n in names:
        effect, _, fld = n.partition(".")
        out.append(_fielded(effect).parameters(d[effect])[fld] if fld else float(d[n]))
    return np.asarray(out, float)


def with_values(model: Model, names, values) -> Model:
    """``model`` with the parameters ``names`` set to ``values``."""
    d = model.to_dict()
    extra = effects.plain(d.pop("extra"))  # fresh dicts: an effect's own values are set in place below
    scalar = scalar_effects()
    for n, v in zip(names, values, strict=False):
        effect, _, fld = n.partition(".")
        if fld:
            extra[effect] = _fielded(effect).with_parameters(extra[effect], {fld: v})
        elif n in scalar:
            extra[n] = v
        else:
            d[n] = v
    return Model.from_dict({**d, "extra": extra})


def parameter_scales(model: Model, names, z_rms: float, v_rms: float) -> np.ndarray:
    """Each parameter's scale: the coefficient that makes its force, at the record's rms state, the
    size of the linear restoring force there (|k1| z_rms); the start value where that is larger. A
    term that starts at zero (an effect to be tried) then moves as readily as the others.
    """
    force = max(abs(model.k1) * z_rms, abs(model.c) * v_rms, 1e-300)
    basis: dict[str, float | None] = {"k0": 1.0, "k1": z_rms, "k2": z_rms**2, "k3": z_rms**3, "c": v_rms,
                                      "c_nl": v_rms**2, "m": None}  # fmt: skip
    basis |= {e.name: e.law.scale(z_rms, v_rms) for e in effects.REGISTRY
              if e.scalar and isinstance(e.law, effects.Monomial | effects.SmoothSign)}  # fmt: skip
    out = []
    for n, value in zip(names, values_of(model, names), strict=False):
        if "." in n:  # an effect's own value (a stop's stiffness or onset): scaled by itself, never zero
            out.append(abs(value) if value else z_rms)
            continue
        b = basis.get(n)
        natural = model.m if b is None else force / max(b, 1e-300)
        out.append(max(abs(value), 1e-3 * natural))
    return np.asarray(out, float)


LINEAR_MATRICES = ("K", "C")
"""A structure's linear matrices ``refine`` moves, by the names of its parameters (``K[i,j]``, ``C[i,j]``)."""


@dataclass(frozen=True)
class SystemParameters:
    """The parameters ``refine`` moves in a system of N DOFs: its element's (``parameter_names``: the base fields
    but those held, its named effects, the mass when free), then each nonzero entry of its linear structure's
    stiffness and damping matrices on and above the diagonal, named ``K[i,j]`` and ``C[i,j]`` (the matrices stay
    symmetric; a zero entry, no spring or damper there, stays zero). A single-DOF ``Model`` is the structure of one
    DOF on the base: no linear entries, and the system built is a ``Model`` again.
    """

    system: Any
    element_names: tuple[str, ...]
    linear: tuple[tuple[str, int, int], ...]
    base: Structure
    """``system`` as a structure (``as_structure``), made once."""

    @classmethod
    def of(cls, system: Model | Structure, free_mass: bool = False, held=()) -> SystemParameters:
        """The parameters of ``system``: the mass too when ``free_mass``, none of those named in ``held``."""
        structure = as_structure(system)
        entries = tuple((name, int(i), int(j)) for name in LINEAR_MATRICES
                        for i, j in zip(*np.triu_indices(structure.n_dof), strict=True)
                        if getattr(structure, name)[i, j] != 0 and f"{name}[{i + 1},{j + 1}]" not in held)  # fmt: skip
        return cls(system, parameter_names(structure.element, free_mass, held), entries, structure)

    @property
    def names(self) -> tuple[str, ...]:
        """Every parameter's name, in the order of ``values``."""
        return self.element_names + tuple(f"{name}[{i + 1},{j + 1}]" for name, i, j in self.linear)

    def values(self) -> np.ndarray:
        """The parameters' current values."""
        structure = self.base
        linear = [getattr(structure, name)[i, j] for name, i, j in self.linear]
        return np.concatenate([values_of(structure.element, self.element_names), np.asarray(linear, float)])

    def scales(self, z_rms: float, v_rms: float) -> np.ndarray:
        """The element's ``parameter_scales``, and each linear entry's own size (nonzero by construction)."""
        element = parameter_scales(self.base.element, self.element_names, z_rms, v_rms)
        return np.concatenate([element, np.abs(self.values()[element.size :])])

    def structure(self, values) -> Structure:
        """The system with these values as a structure (``Structure.unchecked``: ``system`` was checked, and the
        values keep its matrices symmetric and its masses).
        """
        values = np.asarray(values, float)
        p = len(self.element_names)
        s = self.base
        element = with_values(s.element, self.element_names, values[:p])
        matrices = {name: np.array(getattr(s, name), float) for name in LINEAR_MATRICES}
        for (name, i, j), v in zip(self.linear, values[p:], strict=True):
            matrices[name][i, j] = matrices[name][j, i] = v
        masses = (element.m,) if isinstance(self.system, Model) else s.masses
        return Structure.unchecked(masses, element, matrices["K"], matrices["C"], s.place)

    def build(self, values) -> Any:
        """The system with these values (a ``Model`` for a ``Model``; a structure checked as a user's is)."""
        if isinstance(self.system, Model):
            return with_values(self.system, self.element_names, np.asarray(values, float))
        s = self.structure(values)
        return Structure(s.masses, s.element, s.K, s.C, s.place)


def shooting_sparsity(n_win: int, length: int, dense: int, penalty: tuple[int, int] | None = None,
                      states: int = 2) -> sparse.csr_matrix:  # fmt: skip
    """The Jacobian's sparsity for multiple shooting: ``dense`` leading parameter columns touch every
    residual, each window's ``states`` start-state columns only its own ``length`` residuals; ``penalty``
    (first column, count) appends one ridge row per penalised column. Built from blocks (a row-wise
    ``lil_matrix`` cost 1.3 s per refinement of a 150 s record, measured).
    """
    rows = n_win * length
    states = sparse.kron(sparse.identity(n_win, dtype=np.int8, format="csr"), np.ones((length, states), np.int8))
    out = sparse.hstack([sparse.csr_matrix(np.ones((rows, dense), dtype=np.int8)), states], format="csr")
    if penalty is not None:
        first, count = penalty
        ridge = sparse.hstack([sparse.csr_matrix((count, first), dtype=np.int8), sparse.identity(count, np.int8),
                               sparse.csr_matrix((count, out.shape[1] - first - count), dtype=np.int8)])  # fmt: skip
        out = sparse.vstack([out, ridge], format="csr")
    return out


SOLVERS = ("schur", "scipy", "scipy-dense")
"""``refine``'s least-squares solvers: Levenberg-Marquardt with the start states eliminated
(``shooting``, the default), and the benchmarks' baselines, ``scipy.optimize.least_squares`` (trust
region) given the Jacobian's sparsity or not."""


def refine(
    model: Model | Structure,
    rec: Measurement,
    windows_s: tuple[float, ...] = (0.05, 0.25, 1.0),
    max_windows: int = 240,
    free_mass: bool = False,
    max_nfev: int = 60,
    solver: str = "schur",
    held: tuple[str, ...] = (),
    offsets=None,
) -> Refinement:
    """Minimise the simulation error of ``model`` on ``rec`` (the identification part: pass a segment).

    Parameters
    ----------
    model : the start system (a method's equation-error estimate): a single DOF's ``Model`` (z frame) or a
        ``Structure`` of N DOFs (its physical frame, ``offsets`` the record's channels' zeros)
    rec : the record to fit (its held-out part excluded by the caller)
    windows_s : the schedule of window lengths [s]; a length of at least the record's gives one free run
    max_windows : windows per stage at most, spread evenly over the record; a structure's N channels share them
        (max_windows / N windows: the residuals a single DOF's hold; on the tests' fixture record 120 windows
        of two channels gave the element as 240 did, to 3 digits, in 0.63 against 0.82 s on a 3-DOF chain)
    free_mass : refine the mass too (a force input without a weighed mass: the input's gain)
    max_nfev : residual evaluations per stage at most
    held : parameters held at their start value (a sparse method's unselected terms stay zero; a structure's
        element constant, pinned by its frame: ``k0``)
    solver : one of ``SOLVERS``
    offsets : each channel's zero [m] (measured = physical + offset), refined with the system where given (a
        structure's frame: a zero off by 25 um moved the seed-like element's k2 by 5 % through its cubic re-expanded
        about it, 3 k3 dz, measured with the zeros held); default none, a single DOF's z frame (pinned before, its
        constant force k0 refined)

    Every channel's error counts in the units of the element's DOF's motion (divided by its channel's rms over
    the element's channel's): a stiff fixture's channel, moving a tenth of the device's, weighs as much.
    """
    if rec.z is None:
        raise MeasurementError(f"{rec.source}: refinement needs a response")
    if solver not in SOLVERS:
        raise ValueError(f"solver must be one of {SOLVERS}, got {solver!r}")
    params = SystemParameters.of(model, free_mass, held)
    structure = params.base
    nd = structure.n_dof
    n_off = 0 if offsets is None else nd  # the channels' zeros refined where the caller has them
    names = params.names + tuple(f"offset[{i + 1}]" for i in range(n_off))
    p_sys = len(params.names)
    o = np.zeros(nd) if offsets is None else np.asarray(offsets, float)
    raw = rec.channels
    z_all = raw - o[:, None]
    zs, vs = rec.free_run_states()
    zs = zs - o[:, None]
    j = structure.place[1] - 1
    rms = np.sqrt(np.mean((z_all - z_all.mean(axis=1, keepdims=True)) ** 2, axis=1))
    scale = np.concatenate([params.scales(float(np.std(z_all[j])), float(np.std(vs[j]))),
                            np.maximum(rms[:n_off], 1e-12)])  # fmt: skip
    weight = (rms[j] / np.where(rms > 0, rms, rms[j]))[:, None]  # (N, 1); a single DOF's is 1.0 exactly
    weighted = bool(np.any(weight != 1.0))
    q = np.concatenate([params.values(), o[:n_off]]) / scale
    limits = divergence_limits(z_all, vs)
    sub = record_substeps(model, rec)
    u_staged = rec.staged(structure.element, sub)  # a measured channel's term held at its start value
    x_scale = np.concatenate([np.maximum(np.abs(z_all).max(axis=1), 1e-12), np.maximum(np.abs(vs).max(axis=1), 1e-12)])
    start_model, current = model, model
    stages: list[dict[str, Any]] = []
    last = None
    for w_s in windows_s:
        length, starts = spread_windows(rec, w_s, max_windows, nd)
        n_win = starts.size
        meas, u, x0 = channel_windows(rec, u_staged, zs, vs, starts, length, sub)
        x0 = x0 / x_scale
        penalty = 10 * np.abs(meas).max()

        def residuals(Q, X, meas=meas, u=u, n_win=n_win, length=length):  # this stage's windows, kept by the fit
            """(k, n_win, N length) simulation errors of k parameter points and start states, one batch."""
            k = Q.shape[0]
            points = [params.structure(qq[:p_sys] * scale[:p_sys]) for qq in Q]
            zeros = np.zeros((k, nd))
            zeros[:, :n_off] = Q[:, p_sys:] * scale[p_sys:]
            res = simulate_structures(
                points, u, rec.dt, (X * x_scale).reshape(-1, 2 * nd), input_kind=rec.input_name,
                force_dof=rec.force_dof, input_index=np.tile(np.arange(n_win), k),
                structure_index=np.repeat(np.arange(k), n_win), substeps=sub, staged=True, **limits,
            )  # fmt: skip
            z = res.z.reshape(k, n_win, nd, length)
            out = (z + zeros[:, None, :, None] if n_off else z) - meas  # (adding 0 and weighing by 1: skipped)
            if weighted:
                out *= weight
            out[res.diverged.reshape(k, n_win)] = penalty  # a diverging window: a large, finite penalty
            return out.reshape(k, n_win, nd * length)

        if stages:
            # the start states alone first, the model held: the windows' best error at the current model
            # is what the predictability test compares (measured start states carry the smoothing's error)
            x0 = _solve(residuals, q, x0, 10, solver, nd * length, states_only=True)[1]
        r0 = residuals(q[None], x0[None])[0]
        rms0 = float(np.sqrt(np.mean(r0**2)))
        if stages and rms0 > PREDICTABLE_GROWTH * stages[-1]["rms_end_m"]:
            growth = rms0 / stages[-1]["rms_end_m"]
            reason = f"not predictable over this window (error grew {growth:.3g}x): kept the shorter windows' fit"
            stages.append({"window_s": length / rec.fs, "windows": int(n_win), "rms_start_m": rms0, "skipped": reason})
            break
        q, x_fit, fun, nfev, cov = _solve(residuals, q, x0, max_nfev, solver, nd * length)
        last = (residuals, q, x_fit, fun, cov)
        current = params.build(q[:p_sys] * scale[:p_sys])
        o = q[p_sys:] * scale[p_sys:] if n_off else o
        stages.append(
            {
                "window_s": length / rec.fs,
                "windows": int(n_win),
                "rms_start_m": rms0,
                "rms_end_m": float(np.sqrt(np.mean(fun**2))),
                "evaluations": int(nfev),
            }
        )
    se = None if last is None else _standard_errors(*last) * scale
    return Refinement(current, start_model, names, stages, None if offsets is None else np.asarray(o, float),
                      None if se is None else dict(zip(names, se.tolist(), strict=True)))  # fmt: skip


def spread_windows(rec: Measurement, window_s: float, max_windows: int, n_dof: int) -> tuple[int, np.ndarray]:
    """A structure's multiple-shooting windows over ``rec``: their samples (``window_s``, at least 8) and starts, at
    most ``max_windows`` / N of them spread evenly (the N channels share the residuals a single DOF's hold).
    """
    length = min(rec.n, max(8, int(round(window_s * rec.fs))))
    n_win = min(max(1, max_windows // n_dof), max(1, rec.n // length))
    return length, np.linspace(0, rec.n - length, n_win).astype(int)


def channel_windows(rec: Measurement, u_staged: np.ndarray, zs: np.ndarray, vs: np.ndarray, starts: np.ndarray,
                    length: int, substeps: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """The windows of ``length`` samples at ``starts``: the channels as measured (W, N, L), each window's staged
    input rows (``u_staged``'s, ``substeps`` a sample) and the start states (W, 2N) from ``zs``, ``vs`` (N, T). The
    refinement's and the element's unnamed term's (``hybrid.fit_element_term``, ``ElementTerm.window_errors``).
    """
    r = 2 * substeps
    meas = np.stack([rec.channels[:, s : s + length] for s in starts])  # (W, N, L), as measured
    u = np.stack([u_staged[r * s : r * (s + length - 1) + 1] for s in starts])
    return meas, u, np.hstack([zs[:, starts].T, vs[:, starts].T])


def _standard_errors(residuals, q: np.ndarray, x: np.ndarray, fun: np.ndarray, robust=None) -> np.ndarray:
    """The last stage's standard errors of the scaled parameters: ``robust``, the fit's own window-robust
    covariance at its last Jacobian (``shooting._robust_covariance``: each window one cluster, its samples' errors
    correlated as a chaotic record's are, the start states eliminated); else (the scipy solvers, the benchmarks'
    baselines) the Gauss-Newton covariance (``shooting.parameter_covariance``, one more Jacobian) times the
    residuals' variance, which treats the samples as independent and so is a lower bound. Local and conditional on
    the windows and on the model's form and simulation: on the tests' 2-DOF fixture record (120 s, 1 um lasers,
    written by a fixed-step RK4 elsewhere) the truth's z-scores were within 3.3 for the element's k1, k2, k3, c_nl
    and the zeros, but 7 for NSI's c and 6-25 for the fixture's spring and damper, whose errors (1e-5 and 2e-4
    relative) are the two integrators' difference, not the noise's (measured).
    """
    if not q.size:
        return np.full(q.size, np.nan)
    if robust is not None:
        return np.sqrt(np.clip(np.diag(robust), 0.0, None))
    dof = fun.size - q.size - x.size
    if dof <= 0:
        return np.full(q.size, np.nan)
    try:
        cov = parameter_covariance(residuals, ShootingFit(q, x, fun, 0, 0, "solved"))
    except np.linalg.LinAlgError:
        return np.full(q.size, np.nan)
    return np.sqrt(np.clip(np.diag(cov), 0.0, None) * float(np.sum(fun**2)) / dof)


SETTLE_SE = 0.01
"""A stage's fit stops once a step moves every parameter by less than this fraction of its standard error (the
start states alone: each by less than this fraction of its own; ``shooting_least_squares``' ``settle``). On the
benchmark's 300 s record of the polynomial truth (240 windows a stage) the last stage's ``ftol`` took 16 residual
evaluations, its last ten moving no parameter by more than 0.008 of its standard error (measured)."""


def _solve(residuals, q, x0, max_nfev: int, solver: str, length: int, states_only: bool = False):
    """One stage's least squares over (q, x0), or x0 alone: (q, x, residuals, evaluations, the parameters'
    unscaled covariance where the solver gives it).
    """
    if solver == "schur":
        if states_only:
            held = lambda Q, X: residuals(np.repeat(q[None], len(X), 0), X)  # noqa: E731 (the model held)
            fit = shooting_least_squares(held, np.zeros(0), x0, max_nfev)
            return q, fit.x, fit.fun, fit.nfev, None
        fit = shooting_least_squares(residuals, q, x0, max_nfev, settle=SETTLE_SE)
        return fit.q, fit.x, fit.fun, fit.nfev, fit.robust_covariance
    p, (n_win, n_state) = (0 if states_only else q.size), x0.shape

    def flat(theta):
        qq = q if states_only else theta[:p]
        return residuals(qq[None], theta[p:].reshape(1, n_win, n_state))[0].ravel()

    pattern = shooting_sparsity(n_win, length, p, states=n_state) if solver == "scipy" else None
    theta0 = x0.ravel() if states_only else np.concatenate([q, x0.ravel()])
    sol = optimize.least_squares(flat, theta0, jac="2-point", jac_sparsity=pattern, method="trf", x_scale=1.0,
                                 max_nfev=max_nfev, diff_step=1e-7)  # fmt: skip
    qq = q if states_only else sol.x[:p]
    return qq, sol.x[p:].reshape(n_win, n_state), sol.fun.reshape(n_win, -1), sol.nfev, None


def stroke_quantiles(z: np.ndarray, n: int = 41) -> np.ndarray:
    """Quantiles (0.5 % to 99.5 %) of the z a record visited: the stroke and how often each part of it
    was visited, which model updating needs to compare a device with an identified polynomial over the
    same states (``updating.targets_from``).
    """
    return np.quantile(np.asarray(z, float), np.linspace(0.005, 0.995, n))


ACCEPT_TOLERANCE = 0.02
"""The refined model replaces the start model unless it predicts the held-out part worse by more than
this fraction (restarted free-run error): at the noise floor both predict alike, and the simulation-
error estimate, the maximum-likelihood one under sensor noise, is then preferred."""


PAIRED_SE = 2.0
"""A refined model predicting the held-out windows worse than ``ACCEPT_TOLERANCE`` allows is still kept when the
windows do not tell it apart: its windows' mean square errors exceed the start model's, window by window, by less
than this many standard errors of their mean difference (a paired comparison over the same windows, where the judge
offers them: ``paired_window_ms``, a structure's judge). Near the floor the windows' own scatter is wider than 2 %:
on a 120 s fixture record with a quintic and friction named, the element's equation-error estimate missed the
held-out windows by 0.786 %, its refinement by 0.827 % and the truth by 0.819 % (measured). The single DOF's judge
keeps the 2 % rule alone: on the tests' clean record the paired rule kept a refinement that moved SINDy's c_nl by
6e-4 of itself (beyond the test's 5e-4), not yet studied."""


PAIRED_CAP = 0.10
"""The paired comparison (``PAIRED_SE``) keeps a refinement at most this much worse on the held-out windows: few or
heavy-tailed windows make its standard error wide. Tried on the single DOF's 2 s windows of the reference study's
records (not applied there), it would have kept NSI's refinement of the polynomial truth at 1.27 % against its
start's 0.579 % (measured)."""


def worse_beyond_noise(before_ms, after_ms) -> bool:
    """Whether the per-window mean square errors ``after_ms`` exceed ``before_ms`` (the same windows) by more than
    ``PAIRED_SE`` standard errors of their mean difference; a window only the second diverges in (NaN) is worse
    beyond doubt, and fewer than 8 windows both ran tell nothing apart (True: the relative rule alone decides).
    """
    a, b = np.asarray(before_ms, float), np.asarray(after_ms, float)
    if a.shape != b.shape or np.any(np.isnan(b) & np.isfinite(a)):
        return True
    both = np.isfinite(a) & np.isfinite(b)
    if both.sum() < 8:
        return True
    d = b[both] - a[both]
    return bool(d.mean() > PAIRED_SE * d.std(ddof=1) / math.sqrt(d.size))


def _heldout_error(validation: dict[str, Any]) -> float:
    e = validation.get("restarted_rms_percent")
    if e is None or not np.isfinite(e):
        e = validation.get("rms_percent", math.inf)
    return float(e) if e is not None else math.inf


def refine_stage(
    model: Model | Structure,
    rec: Measurement,
    n_id: int,
    validation: dict[str, Any],
    held: tuple[str, ...] = (),
    offsets=None,
    judge: Callable[[Any, Any], dict[str, Any]] | None = None,
) -> tuple[Any, dict[str, Any], dict[str, Any]]:
    """Output-error refinement as the last stage of an identification (NSI, SINDy, the discrepancy
    workflow): ``model`` (a single DOF's ``Model`` or a ``Structure``) refined on the identification part
    ``[0, n_id)`` of ``rec``, validated on the held-out tail like the start model was (``validation``, by
    ``judge(system, offsets)``: a system's held-out validation, default ``validate`` from ``n_id``). The mass is
    refined when the input is a force and no mass was given (the input's gain is then unknown). Returns the system
    to keep, its validation and the stage's account for the result JSON (``refinement``): what was refined, each
    stage's simulation error, the held-out errors of both models and whether the refined one was kept.
    ``held``: parameters that stay at their start value (the terms a sparse method did not select; a structure's
    element constant, pinned by its frame); ``offsets``: a structure's channels' zeros, refined with it (the
    account's ``offsets_m``).
    """
    start = time.perf_counter()
    if judge is None:
        judge = lambda system, _offsets: validate(system, rec, n_id)  # noqa: E731
    # a force without a weighed mass: the input's gain; a free decay (no input) cannot weigh it (per unit mass)
    free_mass = rec.input_name == "force" and rec.mass is None and rec.masses is None and bool(np.any(rec.u))
    info: dict[str, Any] = {"applied": False, "initial_model": model.to_dict()}
    try:
        r = refine(model, rec.segment(0, n_id), free_mass=free_mass, held=held, offsets=offsets)
        new_validation = judge(r.model, r.offsets)
    except (ValueError, MeasurementError) as exc:
        info["reason"] = f"refinement failed, the equation-error model is kept: {exc}"
        return model, validation, info
    before, after = _heldout_error(validation), _heldout_error(new_validation)
    within = after <= before * (1 + ACCEPT_TOLERANCE)
    paired = "paired_window_ms" in validation and "paired_window_ms" in new_validation
    keep = within or (
        paired
        and after <= before * (1 + PAIRED_CAP)
        and not worse_beyond_noise(validation["paired_window_ms"], new_validation["paired_window_ms"])
    )
    ident = rec.segment(0, n_id)
    bounded = boundedness(r.model, ident, offsets=r.offsets)
    if keep and not bounded["ok"] and boundedness(model, ident, offsets=offsets)["ok"]:
        keep = False
        verdict = f"rejected: {bounded['warning'].replace('the model', 'the refined model')}"
    elif keep and not within:
        verdict = (
            f"kept: it misses the held-out part by {after:.3g} % against {before:.3g} %, a difference its windows "
            f"do not tell apart (within {PAIRED_SE:g} standard errors, window by window)"
        )
    elif keep:
        verdict = "kept: it predicts the held-out part at least as well"
    else:
        verdict = f"rejected: the held-out free-run error grew from {before:.3g} % to {after:.3g} %"
    plain = {k: v for k, v in new_validation.items() if not isinstance(v, np.ndarray)}
    old = {k: v for k, v in validation.items() if not isinstance(v, np.ndarray)}
    info.update(
        applied=bool(keep),
        reason=verdict,
        refined_model=r.model.to_dict(),
        **r.to_json() | {"initial_model": model.to_dict()},
        heldout={
            "initial": {k: old.get(k) for k in ("rms_percent", "restarted_rms_percent", "diverged")},
            "refined": {k: plain.get(k) for k in ("rms_percent", "restarted_rms_percent", "diverged")},
        },
        free_mass=free_mass,
        seconds=time.perf_counter() - start,
    )
    return (r.model, new_validation, info) if keep else (model, validation, info)
