"""Which law a record asks for: each candidate judged before it is used, then chosen by what it predicts.

Every identification can read any restoring law (``models.laws``). When the law is not given (``law="auto"``),
or the method's default (the reference study's cubic) fails its checks, the candidates are compared the same
way for every method (``identification.Identifier``):

1. **Judged first** (``problems``): a model that has no stable well, no well inside the stroke the record visited,
   whose potential opens an escape just past the stroke or whose free run under the record's input, 1.2 times as
   large, leaves for good (``validation.boundedness``), or whose damping
   feeds energy in over the record's velocities is never chosen, whatever it predicts.
2. **Scored on what it predicts**: each candidate is estimated on the first part of the identification data and
   its runs restarted from the measured state over the next part (``SELECTION_FRACTION`` of the record, never the
   held-out tail) are compared with the record, in windows no longer than the record stays predictable
   (``validation.predictability``: the discrepancy workflow's horizon; a window longer than it scores chaos).
3. **Weighed**: each candidate's weight is its pseudo-BMA+ weight from the windows' Gaussian log predictive
   densities (Yao, Vehtari, Simpson & Gelman 2018, Bayesian Analysis 13:917, section 3.3: the log scores summed
   over windows re-weighted by a Bayesian bootstrap; each window's errors scaled by the candidate's own error
   variance), so a reader sees how decisive the choice was.

The candidate of the greatest weight is chosen (ties: the least median window error); each candidate's median
window error is said beside it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from negstiff.errors import InputError, MeasurementError
from negstiff.inference.record.measurement import Measurement
from negstiff.inference.steps.validation import (
    boundedness,
    predictability,
    restart_windows,
    simulate_windows,
)
from negstiff.models import Model

SELECTION_FRACTION = 0.2
"""The share of the record (before the held-out tail) over which the candidate laws are scored."""
STROKE_MARGIN = 0.25
"""One well at least must lie within the stroke the record visited, widened by this share of its span on either
side (a well the record did not visit, an in-well record's other well, lies where the model puts it)."""
BOOTSTRAP_DRAWS = 1000
"""Bayesian-bootstrap draws of the windows' weights behind each candidate's pseudo-BMA+ weight."""
MAX_WINDOW_S = 2.0
"""The comparison's windows are the record's predictability horizon, at most half of this [s]."""


def problems(model: Model, rec: Measurement, n: int) -> list[str]:
    """What a physicist would refuse in ``model`` for the first ``n`` samples of ``rec`` (module docstring, 1):
    an empty list when it passes.
    """
    out = []
    assert rec.z is not None  # a single DOF's record
    z = rec.z[:n]
    lo, hi = (float(q) for q in np.quantile(z, (0.005, 0.995)))
    try:
        eq = model.equilibria()
    except (ValueError, ArithmeticError) as exc:
        return [f"no usable well ({' '.join(str(exc).split())})"]
    margin = STROKE_MARGIN * (hi - lo)
    wells = [w for w in (eq.z_minus, eq.z_plus) if w is not None]
    if not any(lo - margin <= w <= hi + margin for w in wells):  # the record rests nowhere the model does
        out.append(f"no well inside the stroke [{1e3 * lo:.3g}, {1e3 * hi:.3g}] mm (wells at "
                   + ", ".join(f"{1e3 * w:.3g}" for w in wells) + " mm)")  # fmt: skip
    seg = rec.segment(0, n)  # one segment for both checks: what it derives is kept with it
    try:
        bounded = boundedness(model, seg)
    except (ValueError, ArithmeticError):
        bounded = {"escape_z": None, "ok": True}
    if bounded["escape_z"] is not None:
        out.append(f"its potential opens an escape at {1e3 * bounded['escape_z']:.3g} mm, just past the stroke")
    elif not bounded["ok"]:  # its free run under the record's input, a little larger, leaves for good
        out.append(bounded.get("warning") or "it is not bounded where the record went")
    _, v, _, _ = seg.states("state")
    with np.errstate(all="ignore"):  # the damping's force at the record's states, and its power
        d = model.total_force(z, v) - model.total_force(z, np.zeros_like(v))
    power = float(np.mean(v * d))
    if not power > 0:
        out.append(f"its damping feeds energy in over the record's velocities (mean power {power:.3g} W)")
    return out


@dataclass
class Candidate:
    """One law as the comparison saw it: its estimate on the fitting part (or why there was none), what it failed,
    its windows' errors over the selection part.
    """

    law: str
    model: Model | None = None
    problems: list[str] = field(default_factory=list)
    window_ms: np.ndarray | None = None
    median_percent: float = math.inf
    weight: float = 0.0

    @property
    def admissible(self) -> bool:
        """Estimated, and passed every check."""
        return self.model is not None and not self.problems

    def to_json(self) -> dict[str, Any]:
        """The candidate's row of the comparison (the contract's ``laws.candidates``)."""
        return {
            "law": self.law,
            "heldout_median_window_percent": self.median_percent if math.isfinite(self.median_percent) else None,
            "weight": self.weight,
            "problems": list(self.problems),
            "model": None if self.model is None else self.model.to_dict(),
        }


def score(candidates: list[Candidate], rec: Measurement, n_fit: int, n_id: int) -> dict[str, Any]:
    """Score the admissible candidates on samples [n_fit, n_id) of ``rec`` (module docstring, 2 and 3), in place;
    returns the windows' account (``horizon``, ``window_s``, ``windows``).
    """
    ok = [c for c in candidates if c.admissible]
    if not ok:
        return {}
    z0, v0, _, _ = rec.states("state")
    horizon = predictability(ok[0].model, rec, n_fit, MAX_WINDOW_S, z0, v0)
    # at most a quarter of the selection part each (a short record's, a ring-down's: four windows at least)
    window_s = max(8 / rec.fs, min(horizon["window_s"], (n_id - n_fit) / rec.fs / 4))
    windows = restart_windows(n_id, rec.fs, window_s, start=n_fit)
    if len(windows) < 2:
        raise MeasurementError(f"{rec.source}: too short to compare laws: the selection part holds fewer than two "
                               f"{window_s:.3g} s windows")  # fmt: skip
    meas = windows.measured(rec.displacement)
    scale = float(np.sqrt(np.mean(meas**2)))
    for c in ok:
        res = simulate_windows(c.model, rec, windows, z0, v0)
        ms = np.full(len(windows), np.inf)
        good = ~res.diverged
        ms[good] = np.mean((res.z[good] - meas[good]) ** 2, axis=1)
        c.window_ms = ms
        c.median_percent = float(100 * np.sqrt(np.median(ms)) / scale) if np.isfinite(np.median(ms)) else math.inf
        if not np.all(good):
            c.problems.append(f"{int((~good).sum())} of its {len(windows)} restarted runs diverged")
    ok = [c for c in ok if c.admissible]
    if ok:
        # pseudo-BMA+ (Yao et al. 2018, section 3.3): each window's Gaussian log density of its errors under the
        # candidate's own error variance, summed over windows re-weighted by a Bayesian bootstrap (Dirichlet(1)
        # weights, seeded), each draw's softmax averaged
        length = windows.length
        elpd = []
        for c in ok:
            ms = np.asarray(c.window_ms, float)
            s2 = float(np.mean(ms))
            elpd.append(-0.5 * length * (np.log(2 * np.pi * s2) + ms / s2))
        e = np.array(elpd)  # (candidates, windows)
        alpha = np.random.default_rng(0).dirichlet(np.ones(e.shape[1]), BOOTSTRAP_DRAWS)  # (draws, windows)
        z = e.shape[1] * alpha @ e.T  # (draws, candidates)
        w = np.exp(z - z.max(axis=1, keepdims=True))
        w = (w / w.sum(axis=1, keepdims=True)).mean(axis=0)
        for c, wi in zip(ok, w, strict=True):
            c.weight = float(wi)
    return {"horizon_s": horizon["horizon_s"], "window_s": window_s, "windows": len(windows),
            "horizon": horizon["method"]}  # fmt: skip


def ranked(candidates: list[Candidate]) -> list[Candidate]:
    """The admissible candidates, the greatest weight first (ties: the least median window error)."""
    ok = [c for c in candidates if c.admissible and math.isfinite(c.median_percent)]
    return sorted(ok, key=lambda c: (-c.weight, c.median_percent))


@dataclass
class Choice:
    """What ``choose`` found: the chosen law's ``estimate`` over the whole identification part (whatever the
    caller's estimator returns), its ``best`` candidate, every ``candidate`` as the comparison saw it and the
    windows' account (``score``'s).
    """

    estimate: Any
    best: Candidate
    candidates: list[Candidate]
    windows: dict[str, Any]


class NoLawError(MeasurementError):
    """No law passes its checks (``choose``): the comparison is kept with the refusal (``candidates``, ``windows``)
    so a caller that has a model of its own (an identification's default) can keep it and say why.
    """

    def __init__(self, message: str, candidates: list[Candidate], windows: dict[str, Any]):
        super().__init__(message)
        self.candidates, self.windows = candidates, windows

    @property
    def reasons(self) -> str:
        """Each candidate's first problem, in one line."""
        return "; ".join(f"{c.law}: {c.problems[0] if c.problems else 'no estimate'}" for c in self.candidates)


ESTIMATE_ERRORS = (MeasurementError, ValueError, ArithmeticError)
"""What an estimate of a law may raise on a record it cannot explain (said as the candidate's problem)."""


def said(exc: Exception) -> str:
    """What a law's failed estimate tells a reader: its error on one line; a linear-algebra failure named as the
    fit's (numpy's "SVD did not converge" alone read as negstiff's own fault).
    """
    text = " ".join(str(exc).split())
    if isinstance(exc, np.linalg.LinAlgError):
        return f"its least-squares fit failed on this record ({text}: its columns are degenerate or not finite here)"
    return text


def choose(rec: Measurement, n_id: int, names, estimate: Callable[[Measurement, int, str], Any],
           model_of: Callable[[Any], Model], why: str | None = None) -> Choice:  # fmt: skip
    """The law ``rec`` asks for among ``names`` (module docstring), for any estimator: each law estimated on the
    fitting part (``estimate(part, n, name)``, ``model_of`` its model) and judged there (``problems``), the
    admissible scored on the selection part (``score``), and the best, estimated again on the whole identification
    part [0, ``n_id``), judged again there (where it fails, the next best). Every identification (``Identifier``)
    and the discrepancy workflow's baseline (``Discrepancy(law="auto")``) choose by this one comparison.

    Raises ``InputError`` where the record is too short to compare laws and ``NoLawError`` (a ``MeasurementError``
    holding the comparison) where no law passes (``why``, the reason the laws were compared, is said in its
    message).
    """
    n_fit = n_id - int(round(SELECTION_FRACTION * rec.n))
    if n_fit < n_id // 2:
        raise InputError(f"{rec.source}: too short to compare laws (the selection part would exceed the fit)")
    fitting = rec.segment(0, n_fit)
    candidates = []
    for name in names:
        cand = Candidate(name)
        try:
            cand.model = model_of(estimate(fitting, n_fit, name))
            cand.problems = problems(cand.model, rec, n_fit)
        except ESTIMATE_ERRORS as exc:
            cand.problems = [said(exc)]
        candidates.append(cand)
    windows = score(candidates, rec, n_fit, n_id)
    # the best on the selection part, estimated on the whole identification part and judged again there: where it
    # fails, the next best
    for best in ranked(candidates):
        try:
            est = estimate(rec, n_id, best.law)
            failed = problems(model_of(est), rec, n_id)
        except ESTIMATE_ERRORS as exc:
            failed = [said(exc)]
        if not failed:
            return Choice(est, best, candidates, windows)
        best.problems = [f"on the whole identification part: {failed[0]}"]
    reasons = "; ".join(f"{c.law}: {c.problems[0] if c.problems else 'no estimate'}" for c in candidates)
    raise NoLawError(f"{rec.source}: no law explains the record{' (' + why + ')' if why else ''}: {reasons}",
                     candidates, windows)  # fmt: skip
