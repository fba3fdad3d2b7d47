"""Model selection by blocked held-out residuals: the one rule SINDy's sparsity path (a single DOF's and a
structure's, ``choose``) and the discrepancy catalogue share.

A candidate is fitted on one part of the record and scored on the following part in blocks of a few
seconds (``block_scores``): the block means are nearly independent where the record decorrelates
within a block, so the paired per-block differences of two candidates give the standard error of
their difference. A candidate beats another only if its gain exceeds

    max(one standard error of the paired per-block differences, margin x the reference's score),

the one-standard-error rule (Hastie, Tibshirani & Friedman, *Elements of Statistical Learning*,
7.10) plus a practical margin: on a lab record even the true model's weak residual has a consistency
floor (anti-aliasing filters, the input's interpolation between samples), and a term that buys back
a few per cent of that floor is systematic, hence statistically significant, but not physical
(measured on rig truth: a z^5 term gained 3-5 % of the floor).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


def block_rows(window_s: float, fs: float, stride: int) -> int:
    """Rows of a weak system (test functions every ``stride`` samples) in a block of ``window_s``."""
    return max(1, int(round(window_s * fs / max(1, stride))))


def block_scores(r2: np.ndarray, rows: int, scale: float) -> np.ndarray:
    """Mean squared residual per block of ``rows`` (whole blocks only), divided by ``scale`` (the
    target's variance: dimensionless scores).
    """
    n = r2.size // rows
    return r2[: n * rows].reshape(n, rows).mean(axis=1) / scale


@dataclass(frozen=True)
class Comparison:
    """How much better ``better`` scores than ``worse`` over the same blocks."""

    gain: float  # mean of the paired per-block differences (worse - better)
    se: float  # its standard error
    threshold: float  # the practical margin, in the scores' units

    @property
    def significant(self) -> bool:
        """The gain exceeds max(one standard error, the margin)."""
        return self.gain > max(self.se, self.threshold)


def compare(worse: np.ndarray, better: np.ndarray, margin: float, reference: np.ndarray) -> Comparison:
    """Paired comparison of two candidates' block scores; the margin is a fraction of ``reference``'s
    mean score.
    """
    d = np.asarray(worse) - np.asarray(better)
    return Comparison(float(d.mean()), float(d.std(ddof=1) / math.sqrt(d.size)), margin * float(np.mean(reference)))


def indistinguishable(candidate: np.ndarray, best: np.ndarray, margin: float) -> bool:
    """Whether ``candidate`` scores within max(1 SE, margin x best) of ``best`` (not significantly worse)."""
    return not compare(candidate, best, margin, best).significant


def choose(path: list[dict], margin: float, admissible) -> dict:
    """The sparsest candidate of ``path`` (sorted by number of terms, then held-out residual) whose block scores
    (``block_ms``) are within max(one standard error, ``margin`` x the best's) of the best candidate's, among the
    ``admissible`` ones (a predicate: a model whose free runs stay bounded and whose potential opens no escape just
    past the stroke; every candidate where none is): a term that buys equation error at the price of an unbounded
    model is not selected, for a single DOF as for a structure.
    """
    allowed = [p for p in path if admissible(p)] or path
    best = min(allowed, key=lambda p: p["heldout_residual_percent"])
    return next(p for p in allowed if indistinguishable(p["block_ms"], best["block_ms"], margin))
