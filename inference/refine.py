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
* ``scipy.optimize.least_squares`` (trust-region reflective) with a finite-difference Jacobian whose
  sparsity (a window's start state moves only that window's residual) lets scipy group the start-state
  columns: a Jacobian costs the model's parameters plus two batched simulations, not two per window.

The result keeps the start model (``initial_model``) beside the refined one, with the simulation
error of each stage.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import optimize, sparse

from negstiff.models import Model, simulate_batch

from .derivatives import state_derivatives
from .measurement import Measurement, MeasurementError

SCALAR_EFFECTS = ("coulomb_friction", "cubic_damping", "quadratic_stiffness", "cubic_stiffness",
                  "quartic_stiffness", "quintic_stiffness")  # fmt: skip
"""Named extra effects with one scalar coefficient, refined with the base coefficients."""


@dataclass(frozen=True)
class Refinement:
    """What ``refine`` found: the refined model, the start model, the names refined and, per stage,
    the window length, count and the rms simulation error (m) at its start and end."""

    model: Model
    initial_model: Model
    parameters: tuple[str, ...]
    stages: list[dict[str, Any]] = field(default_factory=list)

    def to_json(self) -> dict[str, Any]:
        return {
            "parameters": list(self.parameters),
            "stages": self.stages,
            "initial_model": self.initial_model.to_dict(),
        }


def _names(model: Model, free_mass: bool) -> tuple[str, ...]:
    base = ["k0", "k1", "k2", "k3", "c", "c_nl"]
    base += [e for e in SCALAR_EFFECTS if e in model.extra]
    return tuple(base + (["m"] if free_mass else []))


def _with(model: Model, names, values) -> Model:
    d = model.to_dict()
    extra = dict(d.pop("extra"))
    for n, v in zip(names, values):
        if n in SCALAR_EFFECTS:
            extra[n] = v
        else:
            d[n] = v
    return Model.from_dict({**d, "extra": extra})


EFFECT_POWERS = {"coulomb_friction": ("v", 0), "cubic_damping": ("v", 3), "quadratic_stiffness": ("z", 2),
                 "cubic_stiffness": ("z", 3), "quartic_stiffness": ("z", 4), "quintic_stiffness": ("z", 5)}  # fmt: skip


def _scales(model: Model, names, z_rms: float, v_rms: float) -> np.ndarray:
    """Each parameter's scale: the coefficient that makes its force, at the record's rms state, the
    size of the linear restoring force there (|k1| z_rms); the start value where that is larger. A
    term that starts at zero (an effect to be tried) then moves as readily as the others."""
    d = {**model.to_dict(), **dict(model.extra)}
    force = max(abs(model.k1) * z_rms, abs(model.c) * v_rms, 1e-300)
    basis = {"k0": 1.0, "k1": z_rms, "k2": z_rms**2, "k3": z_rms**3, "c": v_rms, "c_nl": v_rms**2, "m": None}
    basis |= {e: (v_rms if var == "v" else z_rms) ** k for e, (var, k) in EFFECT_POWERS.items()}
    out = []
    for n in names:
        b = basis.get(n)
        natural = model.m if b is None else force / max(b, 1e-300)
        out.append(max(abs(float(d.get(n, 0.0))), 1e-3 * natural))
    return np.asarray(out, float)


def refine(
    model: Model,
    rec: Measurement,
    windows_s: tuple[float, ...] = (0.05, 0.25, 1.0),
    max_windows: int = 240,
    free_mass: bool = False,
    max_nfev: int = 60,
) -> Refinement:
    """Minimise the simulation error of ``model`` on ``rec`` (the identification part: pass a segment).

    Parameters
    ----------
    model : the start model (a method's equation-error estimate), z frame
    rec : the record to fit (its held-out part excluded by the caller)
    windows_s : the schedule of window lengths [s]; a length of at least the record's gives one free run
    max_windows : windows per stage at most, spread evenly over the record
    free_mass : refine the mass too (a force input without a weighed mass: the input's gain)
    max_nfev : function evaluations per stage at most (``least_squares``)
    """
    if rec.z is None:
        raise MeasurementError(f"{rec.source}: refinement needs a response")
    names = _names(model, free_mass)
    zs, vs, _, _ = state_derivatives(rec.z, rec.fs, purpose="state")
    scale = _scales(model, names, float(np.std(rec.z)), float(np.std(vs)))
    d = {**model.to_dict(), **dict(model.extra)}
    q = np.array([float(d[n]) for n in names]) / scale
    limits = divergence_limits(rec.z, vs)
    start_model, stages, current = model, [], model
    for w_s in windows_s:
        length = min(rec.n, max(8, int(round(w_s * rec.fs))))
        n_win = min(max_windows, max(1, rec.n // length))
        starts = np.linspace(0, rec.n - length, n_win).astype(int)
        meas = np.stack([rec.z[s : s + length] for s in starts])
        u = np.stack([rec.u[s : s + length] for s in starts])
        x0 = np.column_stack([zs[starts], vs[starts]])
        x_scale = np.array([max(np.abs(rec.z).max(), 1e-12), max(np.abs(vs).max(), 1e-12)])
        p = len(names)

        def residual(theta):
            m = _with(model, names, theta[:p] * scale)
            xs = theta[p:].reshape(-1, 2) * x_scale
            res = simulate_batch(
                np.repeat(m.kernel_params()[:, None], n_win, axis=1), m.kind, u, rec.dt, xs,
                input_kind=rec.input_name, input_index=np.arange(n_win), **limits,
            )  # fmt: skip
            r = res.z - meas
            r[res.diverged] = 10 * np.abs(meas).max()  # a diverging window: a large, finite penalty
            return r.ravel()

        theta0 = np.concatenate([q, (x0 / x_scale).ravel()])
        pattern = sparse.lil_matrix((n_win * length, p + 2 * n_win), dtype=int)
        pattern[:, :p] = 1
        for w in range(n_win):
            pattern[w * length : (w + 1) * length, p + 2 * w : p + 2 * w + 2] = 1
        r0 = residual(theta0)
        sol = optimize.least_squares(
            residual, theta0, jac="2-point", jac_sparsity=pattern.tocsr(), method="trf", x_scale=1.0,
            max_nfev=max_nfev, diff_step=1e-7,
        )  # fmt: skip
        q = sol.x[:p]
        current = _with(model, names, q * scale)
        stages.append(
            {
                "window_s": length / rec.fs,
                "windows": int(n_win),
                "rms_start_m": float(np.sqrt(np.mean(r0**2))),
                "rms_end_m": float(np.sqrt(np.mean(sol.fun**2))),
                "evaluations": int(sol.nfev),
            }
        )
    return Refinement(current, start_model, names, stages)


def divergence_limits(z: np.ndarray, v: np.ndarray) -> dict[str, float]:
    """|z| and |z'| a simulation may reach before it counts as diverged: ten times the record's (the
    simulator's defaults, 1 m and 100 m/s, are a shaker device's; an electronic benchmark's volts per
    second exceed them)."""
    return {"z_limit": 10 * float(np.abs(z).max()) + 1e-12, "v_limit": 10 * float(np.abs(v).max()) + 1e-12}


def free_run_rms(model: Model, rec: Measurement, skip: int = 0, x0=None) -> float:
    """rms of the free-run simulation error over ``rec`` (started at its measured state, or ``x0``),
    the first ``skip`` samples not scored (the benchmarks' transient)."""
    zs, vs, _, _ = state_derivatives(rec.z, rec.fs, purpose="state")
    if x0 is None:
        x0 = (zs[0], vs[0])
    res = simulate_batch(model.kernel_params(), model.kind, rec.u, rec.dt, np.asarray(x0, float),
                         input_kind=rec.input_name, **divergence_limits(rec.z, vs))  # fmt: skip
    if res.diverged[0]:
        return math.inf
    return float(np.sqrt(np.mean((res.z[0, skip:] - rec.z[skip:]) ** 2)))
