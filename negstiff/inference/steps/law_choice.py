"""Which law a record asks for: each candidate judged before it is used, then chosen by what it predicts.

Every identification can read any restoring law (``models.laws``). When the law is not given (``law="auto"``),
or the method's default (the reference study's cubic) fails its checks, the candidates are compared the same
way for every method (``identification.Identifier``):

1. **Judged first** (``problems``): a model that has no stable well, whose wells lie outside the stroke the record
   visited, whose potential opens an escape just past the stroke (``validation.boundedness``) or whose damping
   feeds energy in over the record's velocities is never chosen, whatever it predicts.
2. **Scored on what it predicts**: each candidate is estimated on the first part of the identification data and
   its runs restarted from the measured state over the next part (``SELECTION_FRACTION`` of the record, never the
   held-out tail) are compared with the record, in windows no longer than the record stays predictable
   (``validation.predictability``: the discrepancy workflow's horizon; a window longer than it scores chaos).
3. **Weighed**: each candidate's weight is its pseudo-Bayesian-model-averaging weight from the windows'
   Gaussian log predictive densities (Yao, Vehtari, Simpson & Gelman 2018, Bayesian Analysis 13:917, Eq. 8; each
   window's errors scaled by the candidate's own error variance), so a reader sees how decisive the choice was.

The candidate with the least median window error is chosen; its weight says whether another was close.
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
"""A well may lie at most this share of the stroke's span beyond the stroke the record visited."""
MAX_WINDOW_S = 2.0
"""The comparison's windows are the record's predictability horizon, at most half of this [s]."""


def problems(model: Model, rec: Measurement, n: int) -> list[str]:
    """What a physicist would refuse in ``model`` for the first ``n`` samples of ``rec`` (module docstring, 1):
    an empty list when it passes.
    """
    out = []
    z = rec.z[:n]
    lo, hi = (float(q) for q in np.quantile(z, (0.005, 0.995)))
    try:
        eq = model.equilibria()
    except (ValueError, ArithmeticError) as exc:
        return [f"no usable well ({' '.join(str(exc).split())})"]
    margin = STROKE_MARGIN * (hi - lo)
    wells = [w for w in (eq.z_minus, eq.z_plus) if w is not None]
    outside = [w for w in wells if not lo - margin <= w <= hi + margin]
    if outside:
        out.append(f"a well at {1e3 * outside[0]:.3g} mm, outside the stroke [{1e3 * lo:.3g}, {1e3 * hi:.3g}] mm")
    try:
        escape = boundedness(model, rec.segment(0, n), free_run=False)["escape_z"]
    except (ValueError, ArithmeticError):
        escape = None
    if escape is not None:
        out.append(f"its potential opens an escape at {1e3 * escape:.3g} mm, just past the stroke")
    _, v, _, _ = rec.segment(0, n).states("state")
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
    horizon = predictability(ok[0].model, rec, n_fit, MAX_WINDOW_S, z0, v0)  # type: ignore[arg-type]
    windows = restart_windows(n_id, rec.fs, horizon["window_s"], start=n_fit)
    if len(windows) < 2:
        raise ValueError(f"{rec.source}: the selection part holds fewer than two {horizon['window_s']:.3g} s windows")
    meas = windows.measured(rec.displacement)
    scale = float(np.sqrt(np.mean(meas**2)))
    for c in ok:
        res = simulate_windows(c.model, rec, windows, z0, v0)  # type: ignore[arg-type]
        ms = np.full(len(windows), np.inf)
        good = ~res.diverged
        ms[good] = np.mean((res.z[good] - meas[good]) ** 2, axis=1)
        c.window_ms = ms
        c.median_percent = float(100 * np.sqrt(np.median(ms)) / scale) if np.isfinite(np.median(ms)) else math.inf
        if not np.all(good):
            c.problems.append(f"{int((~good).sum())} of its {len(windows)} restarted runs diverged")
    ok = [c for c in ok if c.admissible]
    if ok:
        # pseudo-BMA: each window's Gaussian log density of its errors under the candidate's own error variance
        length = windows.length
        elpd = []
        for c in ok:
            s2 = float(np.mean(c.window_ms))  # type: ignore[arg-type]
            elpd.append(float(np.sum(-0.5 * length * (np.log(2 * np.pi * s2) + c.window_ms / s2))))  # type: ignore[operator]
        e = np.array(elpd)
        w = np.exp(e - e.max())
        for c, wi in zip(ok, w / w.sum(), strict=True):
            c.weight = float(wi)
    return {"horizon_s": horizon["horizon_s"], "window_s": horizon["window_s"], "windows": len(windows),
            "horizon": horizon["method"]}  # fmt: skip


def ranked(candidates: list[Candidate]) -> list[Candidate]:
    """The admissible candidates, the least median window error first."""
    ok = [c for c in candidates if c.admissible and math.isfinite(c.median_percent)]
    return sorted(ok, key=lambda c: c.median_percent)


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


ESTIMATE_ERRORS = (MeasurementError, ValueError, ArithmeticError)
"""What an estimate of a law may raise on a record it cannot explain (said as the candidate's problem)."""


def choose(rec: Measurement, n_id: int, names, estimate: Callable[[Measurement, int, str], Any],
           model_of: Callable[[Any], Model], why: str | None = None) -> Choice:  # fmt: skip
    """The law ``rec`` asks for among ``names`` (module docstring), for any estimator: each law estimated on the
    fitting part (``estimate(part, n, name)``, ``model_of`` its model) and judged there (``problems``), the
    admissible scored on the selection part (``score``), and the best, estimated again on the whole identification
    part [0, ``n_id``), judged again there (where it fails, the next best). Every identification (``Identifier``)
    and the discrepancy workflow's baseline (``Discrepancy(law="auto")``) choose by this one comparison.

    Raises ``InputError`` where the record is too short to compare laws and ``MeasurementError`` where no law
    passes (``why``, the reason the laws were compared, is said in its message).
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
            cand.problems = [" ".join(str(exc).split())]
        candidates.append(cand)
    windows = score(candidates, rec, n_fit, n_id)
    # the best on the selection part, estimated on the whole identification part and judged again there: where it
    # fails, the next best
    for best in ranked(candidates):
        try:
            est = estimate(rec, n_id, best.law)
            failed = problems(model_of(est), rec, n_id)
        except ESTIMATE_ERRORS as exc:
            failed = [" ".join(str(exc).split())]
        if not failed:
            return Choice(est, best, candidates, windows)
        best.problems = [f"on the whole identification part: {failed[0]}"]
    reasons = "; ".join(f"{c.law}: {c.problems[0] if c.problems else 'no estimate'}" for c in candidates)
    raise MeasurementError(f"{rec.source}: no law explains the record{' (' + why + ')' if why else ''}: "
                           f"{reasons}")  # fmt: skip
