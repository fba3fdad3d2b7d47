"""The shape of a law's shaped parts from a record: variable projection on the weak form.

A law whose parts are linear in their coefficients and nonlinear in their shape (``models.shaped``: a magnet's
gap, the rod frame's length and angle, a spline's knots) is fitted by separating the two (Golub & Pereyra 1973,
SIAM J. Numer. Anal. 10:413): at a shape, the coefficients are the weak form's constrained least squares
(``weak.fit_support``: the input's coefficient fixed by physics), and the shape minimises what that least
squares leaves, its relative weak residual. Only the shaped parts' columns depend on the shape, so only they
are projected again at each trial (the others once). A part with one width is searched on a grid across its box
and refined by bounded Brent (Brent 1973); a part with more shape fields (the rod frame's) by Nelder-Mead from a
few starts, in coordinates that keep it inside its box.

A spline's shape is its knots: evenly spaced over the record's stroke (its 0.5 and 99.5 % quantiles), their
number chosen by what the fit predicts: each count is fitted on the first part and scored on the next by its
weak residual in blocks, and the fewest knots whose score is within one standard error (or ``margin``) of the
best are kept (the one-standard-error rule, as SINDy's selection; Hastie, Tibshirani & Friedman 2009, 7.10).

Every method that reads a law takes its shape from here (SINDy's library, NSI's basis, the law comparison, the
record's preparation), so a shape is found once per record and law (kept with the record, ``Measurement.derived``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import optimize

from negstiff.inference.record.measurement import Measurement
from negstiff.inference.steps.selection import block_rows, block_scores, indistinguishable
from negstiff.inference.steps.weak import (
    Library,
    WeakForm,
    WeakFormError,
    WeakSystem,
    fit_support,
    known_input_gain,
    test_function,
    weak_project,
)
from negstiff.models import laws
from negstiff.models.shaped import ShapedLaw, Spline

STROKE_QUANTILES = (0.005, 0.995)
"""The record's stroke: these quantiles of its z (a spline's knots span it; the shapes' search box scales with it)."""
SPLINE_MARGIN = 0.02
"""A spline with more knots must lower the held-out weak residual by more than this fraction (or one standard
error) of the best count's to be kept (the equation error's floor on a lab record: ``selection``)."""


@dataclass(frozen=True)
class ShapeFit:
    """A law's shape on a record: ``shape`` (part -> fields), the relative weak residual it leaves on the fitting
    part, each trial's (``tried``), and how it was chosen (``method``).
    """

    shape: dict[str, dict[str, Any]]
    residual: float
    tried: list[dict[str, Any]] = field(default_factory=list)
    method: str = ""

    def to_json(self) -> dict[str, Any]:
        """The shape and its search, as JSON."""
        return {"shape": {k: {f: list(v) if isinstance(v, tuple) else v for f, v in s.items()}
                          for k, s in self.shape.items()},
                "residual": self.residual, "method": self.method, "tried": self.tried}  # fmt: skip


def stroke(rec: Measurement, n: int | None = None) -> tuple[float, float]:
    """The stroke of ``rec``'s first ``n`` samples: ``STROKE_QUANTILES`` of z [m]."""
    assert rec.z is not None  # a single DOF's record
    z = rec.z[: rec.n if n is None else n]
    lo, hi = np.quantile(z, STROKE_QUANTILES)
    return float(lo), float(hi)


class _Problem:
    """The weak-form least squares of a law over samples [lo, hi) of a record, its shape-free columns projected
    once: ``residual(shape)`` projects only the shaped parts' columns.
    """

    def __init__(self, rec: Measurement, restoring: laws.Law, damping: laws.Law, lo: int, hi: int,
                 aux: tuple[str, ...] = (), scoring: bool = False):  # fmt: skip
        self.rec, self.restoring, self.damping, self.lo, self.hi, self.aux = rec, restoring, damping, lo, hi, aux
        self.scoring = scoring  # a part that scores fits made elsewhere: a column it never reaches is zeros there
        self.form = WeakForm.of(rec)
        self.gain = known_input_gain(rec)
        self.shaped = restoring.shaped()
        self.zs = self.form.zs[lo:hi]

    def library(self, shape) -> Library:
        return Library.of_laws(self.restoring, self.damping, shape, self.aux)

    def system(self, shape):
        return self.form.system(self.rec, self.lo, self.hi, library=self.library(shape), scoring=self.scoring)

    def residual(self, shape) -> float:
        """The relative weak residual ||y - W theta||^2 / ||y||^2 of the constrained least squares at ``shape``
        (inf where the shape cannot be evaluated: the rods cannot reach the stroke). The shape-free columns, the
        target and the input are projected at the first call and kept; each later call projects the shaped parts'
        columns alone (a shape search's trials: 30 ms each with every column, measured, against a few).
        """
        with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
            try:
                if "_fixed" not in vars(self):
                    first = self.system(shape)
                    labels = self.library(shape).labels()
                    shaped = np.array([lab.split("[")[0] in self.shaped for lab in labels] + [False])
                    seg = self.rec.segment(self.lo, self.hi)
                    self._fixed = (first.W_physical, first.y_physical, shaped, test_function(self.form.half, seg.dt)[0],
                                   seg.dt, first.col)  # fmt: skip
                W, y, shaped, phi, dt, col = self._fixed
                if shaped.any():
                    cols = [c for name in self.shaped for c in self.shaped[name].columns(shape[name], self.zs)]
                    W = W.copy()
                    W[:, shaped] = weak_project(np.column_stack([np.broadcast_to(c, self.zs.shape) for c in cols]),
                                                phi, self.form.stride, dt)  # fmt: skip
                if not np.all(np.isfinite(W)):
                    return math.inf
                col = col.copy()  # the shape-free columns' scales as the system made them (a constant's: its mean)
                col[shaped] = W[:, shaped].std(axis=0)
                col[col == 0] = 1.0
                phys = fit_support(WeakSystem(W / col, y / y.std(), col, float(y.std())), self.gain)
            except (WeakFormError, ValueError, np.linalg.LinAlgError):
                return math.inf
        r = y - W @ phys
        return float(np.mean(r**2) / np.mean(y**2))


def _box_search(problem: _Problem, name: str, law: ShapedLaw, rng_stroke, others) -> tuple[dict, float, list]:
    """One shaped part's shape by bounded minimisation of the weak residual from each of its guesses (the other
    parts' shapes held at ``others``), in coordinates that map the part's box onto the real line.
    """
    bounds = law.shape_bounds(rng_stroke)
    keys = list(bounds)
    if len(keys) == 1:
        return _width_search(problem, name, keys[0], *bounds[keys[0]], others)
    lo = np.array([bounds[k][0] for k in keys])
    hi = np.array([bounds[k][1] for k in keys])

    def unpack(x):
        # a logistic map of each coordinate into its box: the search is unconstrained and never leaves it
        return {k: float(a + (b - a) / (1 + math.exp(-xi))) for k, a, b, xi in zip(keys, lo, hi, x, strict=True)}

    def pack(shape):
        f = np.clip((np.array([shape[k] for k in keys]) - lo) / (hi - lo), 1e-6, 1 - 1e-6)
        return np.log(f / (1 - f))

    def objective(x):
        return problem.residual({**others, name: unpack(x)})

    tried, best, best_r = [], None, math.inf
    for guess in law.shape_guesses(rng_stroke):
        x0 = pack(guess)
        sol = optimize.minimize(objective, x0, method="Nelder-Mead",
                                options={"xatol": 1e-4, "fatol": 1e-9, "maxfev": 60 * len(keys)})  # fmt: skip
        shape, r = unpack(sol.x), float(sol.fun)
        tried.append({"start": guess, "shape": shape, "residual": r})
        if r < best_r:
            best, best_r = shape, r
    if best is None or not math.isfinite(best_r):
        raise WeakFormError(f"{problem.rec.source}: no shape of the {name} part explains the record (every trial "
                            "failed: is the stroke inside the part's reach?)")  # fmt: skip
    return best, best_r, tried


WIDTH_GRID = 13
"""Widths a one-width part's search scores first, evenly in log across its box (then Brent between the best one's
neighbours)."""


def _width_search(problem: _Problem, name: str, key: str, lo, hi, others) -> tuple[dict, float, list]:
    """A part with one width (the magnets' gap, the springs' half-span): its weak residual on ``WIDTH_GRID`` widths
    evenly in log across [lo, hi], then scipy's bounded Brent between the best width's neighbours. Nelder-Mead from
    three starts took up to 180 residuals (each a projection of the part's columns) and stopped at its budget on
    most records; this takes ~25 and sees the whole box before it refines.
    """
    lo, hi = float(lo), float(hi)
    grid = np.geomspace(lo, hi, WIDTH_GRID) if lo > 0 else np.linspace(lo, hi, WIDTH_GRID)

    def residual(width: float) -> float:
        return problem.residual({**others, name: {key: float(width)}})

    scores = np.array([residual(w) for w in grid])
    if not np.isfinite(scores).any():
        raise WeakFormError(f"{problem.rec.source}: no shape of the {name} part explains the record (every width "
                            "failed: is the stroke inside the part's reach?)")  # fmt: skip
    k = int(np.nanargmin(np.where(np.isfinite(scores), scores, np.nan)))
    a, b = grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)]
    sol = optimize.minimize_scalar(residual, bounds=(a, b), method="bounded", options={"xatol": 1e-6 * (b - a)})
    width, r = (float(sol.x), float(sol.fun)) if sol.fun <= scores[k] else (float(grid[k]), float(scores[k]))
    tried = [{"start": {key: float(w)}, "shape": {key: float(w)}, "residual": float(x)}
             for w, x in zip(grid, scores, strict=True)]  # fmt: skip
    tried.append({"start": {key: float(grid[k])}, "shape": {key: width}, "residual": r})
    return {key: width}, r, tried


def _spline_knots(problem: _Problem, n_fit: int, name: str, law: Spline, rng_stroke, others,
                  window_s: float) -> tuple[dict, float, list]:  # fmt: skip
    """A spline's knots: each count of ``law.shape_guesses`` fitted on the weak form's rows whose test functions lie
    before ``n_fit`` and scored by its weak residual, in blocks, on the rows after it (one system over the whole
    identification part: a ring-down's later part, whose motion no longer reaches the outer knots, still scores);
    the fewest knots within one standard error (or ``SPLINE_MARGIN``) of the best (module docstring).
    """
    rec = problem.rec
    form = problem.form
    rows = block_rows(window_s, rec.fs, form.stride)
    trials = []
    for guess in law.shape_guesses(rng_stroke):
        shape = {**others, name: guess}
        try:
            system = problem.system(shape)
        except (WeakFormError, ValueError, np.linalg.LinAlgError):
            continue
        centre = form.centre(rec.dt) + form.stride * np.arange(system.W.shape[0])
        fit, sel = centre + 4 * form.half < n_fit, centre - 4 * form.half >= n_fit  # whole test functions either side
        if fit.sum() < 4 * system.W.shape[1] or sel.sum() < 2:
            continue
        W, y = system.W_physical, system.y_physical
        sub = type(system)(system.W[fit], system.y[fit], system.col, system.s_y)
        phys = fit_support(sub, problem.gain)
        r2 = (y[sel] - W[sel] @ phys) ** 2
        blocks = block_scores(r2, rows, y[sel].var()) if sel.sum() >= 2 * rows else np.array([r2.mean() / y[sel].var()])
        trials.append((guess, blocks, float(np.mean((y[fit] - W[fit] @ phys) ** 2) / np.mean(y[fit] ** 2))))
    if not trials:
        raise WeakFormError(f"{rec.source}: no spline over the stroke could be fitted (too little motion?)")
    best = min(trials, key=lambda t: t[1].mean())
    for guess, blocks, r in trials:  # the fewest knots first
        if indistinguishable(blocks, best[1], SPLINE_MARGIN):
            tried = [{"shape": {"knots": list(g["knots"])}, "heldout_residual": float(b.mean()), "residual": rr}
                     for g, b, rr in trials]  # fmt: skip
            return guess, r, tried
    raise AssertionError("the best count always qualifies")  # pragma: no cover


def fit_shape(rec: Measurement, restoring, damping, *, n_fit: int | None = None, n_id: int | None = None,
              window_s: float = 2.0, aux: tuple[str, ...] = ()) -> ShapeFit:  # fmt: skip
    """The shape of ``restoring``'s shaped parts on ``rec`` (module docstring): found on samples [0, n_fit), a
    spline's knot count scored on [n_fit, n_id) in ``window_s`` blocks (default: the first 60 % and the next 20 %
    of the record). A law without shaped parts has the empty shape. Kept with the record.

    Parameters
    ----------
    rec : Measurement
        The record (its z in the physical frame: ``pin_frame``).
    restoring, damping : str or Law
        The laws (``models.laws``).
    n_fit, n_id : int, optional
        The fitting part's and the identification part's ends (samples).
    window_s : float
        The blocks' length [s] that score a spline's knot counts.
    aux : tuple of str
        Measured auxiliary channels whose terms join the fit.

    Returns
    -------
    ShapeFit
    """
    restoring, damping = laws.get(restoring, "restoring"), laws.get(damping, "damping")
    n_id = int(round(0.8 * rec.n)) if n_id is None else n_id
    n_fit = int(round(0.6 * rec.n)) if n_fit is None else n_fit
    key = ("shape", restoring.name, damping.name, n_fit, n_id, float(window_s), tuple(aux))
    hit = rec.derived.get(key)
    if hit is not None:
        return hit
    shaped = restoring.shaped()
    fitting = _Problem(rec, restoring, damping, 0, n_fit, tuple(aux))
    if not shaped:
        out = ShapeFit({}, fitting.residual({}), method="no shaped part")
        rec.derived[key] = out
        return out
    rng = stroke(rec, n_id)
    shape: dict[str, dict[str, Any]] = {n: law.shape_guesses(rng)[0] for n, law in shaped.items()}
    tried: list[dict[str, Any]] = []
    methods = []
    residual = math.inf
    for name, law in shaped.items():  # one part at a time (the laws have one shaped part each)
        others = {k: v for k, v in shape.items() if k != name}
        if isinstance(law, Spline):
            whole = _Problem(rec, restoring, damping, 0, n_id, tuple(aux))
            best, residual, t = _spline_knots(whole, n_fit, name, law, rng, others, window_s)
            methods.append(f"{name}: {len(best['knots']) - 1} intervals over the stroke "
                           f"[{1e3 * rng[0]:.3g}, {1e3 * rng[1]:.3g}] mm, the fewest whose held-out weak residual is "
                           f"within one standard error (or {100 * SPLINE_MARGIN:g} %) of the best")  # fmt: skip
        else:
            best, residual, t = _box_search(fitting, name, law, rng, others)
            how = (f"{WIDTH_GRID} widths across the part's box, then bounded Brent" if len(best) == 1 else
                   f"Nelder-Mead over the part's box from {len(t)} starts")  # fmt: skip
            methods.append(f"{name}: " + ", ".join(f"{k} = {v:.4g}" for k, v in best.items())
                           + f" by variable projection ({how}, the weak form's least squares inside)")  # fmt: skip
        shape[name] = best
        tried += [{"part": name, **x} for x in t]
    out = ShapeFit(shape, residual, tried, "; ".join(methods))
    rec.derived[key] = out
    return out
