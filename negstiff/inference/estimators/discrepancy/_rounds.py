"""The discrepancy workflow's rounds on a structure (N > 1 DOFs): the element's base law with the linear structure
is the baseline; each registered effect with a column of its own is added as a term of the element and scored like
SINDy's supports, on held-out blocks of the structure's weak form (``equations``). An effect is named when it lowers
the held-out weak residual by more than max(one standard error of the paired block differences, ``margin``)
(``selection.compare``, the single DOF's rule); among those, the largest gain. The named one joins the base and the
rest are offered again. Each round's effect is kept only if the structure with it predicts the held-out windows
where it acts better than without it beyond one standard error, and the rest not worse (``verdict_of``: the single
DOF's rule; where fewer than three tail windows hold it, the record's windows where it acts in cross-validated
blocks, ``fold_evidence``; else the pooled rule); then where the gap
lay (``_locating.locate``), each named effect's interval (``_intervals.effect_intervals``) and its Bayesian second
opinion (``_opinions.bayesian_opinions``).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from negstiff.inference.analysis.record_kind import ring_down
from negstiff.inference.estimators.identification import (
    REFINEMENT_SETTING,
    WINDOW_S,
    held_out_runs,
    refined,
    structure_result,
)
from negstiff.inference.estimators.results import Bunch, Identification
from negstiff.inference.record.measurement import Measurement
from negstiff.inference.steps.equations import _assemble, _block_scores, _lstsq, _systems, physical_frame, unknown_zeros
from negstiff.inference.steps.selection import compare
from negstiff.inference.steps.validation import (
    RestartWindows,
    channel_scales,
    structure_window_errors,
    structure_windows,
)
from negstiff.models import effects
from negstiff.models.structure import relative

from ._intervals import effect_intervals
from ._judging import paired_windows
from ._locating import locate, where_words
from ._opinions import bayesian_opinions
from ._runs import acting_mask, rows_clear_of


def structure_rounds(est, rec: Measurement, at: tuple[int, int]) -> Identification:
    """The discrepancy workflow on a record of N > 1 DOFs (module docstring): the element's base law with the
    linear structure, each registered effect added in turn, named by the paired block rule; the named one joins the
    base and the rest are offered again, until none is named (at most ``max_effects`` rounds: ``iterations``).
    """
    ident_states: dict[str, Any] = {}

    def v_noise_of(vr: np.ndarray) -> float:
        # the smoothed sign's velocity scale: the relative velocity's noise, read as its rough part (first differences
        # of a white-noise-dominated tail), never below 1e-4 of its spread
        return max(float(np.std(np.diff(vr)) / math.sqrt(2)), 1e-4 * float(vr.std()))

    terms = [t for t in effects.library_terms() if t.field not in ("k0", "k1", "k2", "k3", "c", "c_nl")]

    def extras(zs, v):
        r, vr = relative(zs, at), relative(v, at)
        ident_states["v_noise"] = v_noise_of(vr)
        return [(t.field, t.law.column(r, vr, ident_states["v_noise"])) for t in terms]

    fit, sel, whole, rows, window, form, (n_id, _), states = _systems(
        est, rec, at, ring_down(rec), ring_down(rec, ("decay",)), extras
    )
    (yf, Xf_all, names_all, _), (ys, Xs_all, _, per_sel) = fit[:4], sel[:4]
    n_base = len(names_all) - len(terms)
    masses = rec.dof_masses

    def scored(cols: list[int]) -> tuple[np.ndarray, np.ndarray]:
        theta = _lstsq(Xf_all[:, cols], yf)
        return theta, _block_scores(ys - Xs_all[:, cols] @ theta, ys, per_sel, rec.n_dof, rows)

    fields = [t.field for t in terms]
    base_cols = list(range(n_base))
    named_all: list[str] = []
    iterations: list[dict[str, Any]] = []
    y, X = whole[0], whole[1]
    hits = ring_down(rec, ("impact",))  # a hammer's record: the windows between its pulses

    def fitted(cols: list[int], names: list[str], keep: np.ndarray | None = None):
        # the structure with the base terms and the named effects ``names`` (columns ``cols``) from the whole
        # identification part's weak form (its rows ``keep``: a fold's), in its physical frame, with each channel's
        # zero and its coefficients
        theta = _lstsq(X[:, cols], y) if keep is None else _lstsq(X[keep][:, cols], y[keep])
        extra = {name: float(theta[n_base + i]) for i, name in enumerate(names)}
        s, b = _assemble(theta[:n_base], rec.n_dof, at, masses, extra)
        return (*physical_frame(s, b, rec.gravity, unknown_zeros(rec)), theta)

    judgement: list[dict[str, Any]] = []
    # the structure the rounds have reached (the baseline first), and its held-out windows' errors once judged
    current = base_fit = fitted(base_cols, [])
    held: HeldOut | None = None
    current_ms: np.ndarray | None = None
    # as the single DOF's workflow: each round adds the effect that lowers the held-out score most, beyond the margin
    # rule, to the base the next round scores against; until no effect passes (at most ``max_effects``)
    for _ in range(est.max_effects):
        _, base_blocks = scored(base_cols)
        ranking: list[dict[str, Any]] = [{"effect": "none", "score": float(100 * np.sqrt(base_blocks.mean()))}]
        named, best_gain = None, 0.0
        candidates: dict[str, dict[str, float]] = {}
        for k, t in enumerate(terms):
            if t.field in named_all:
                continue
            theta, blocks = scored(base_cols + [n_base + k])
            value = float(theta[-1])
            cmp = compare(base_blocks, blocks, est.margin, base_blocks)
            physical = not (effects.get(t.field).dissipative and value < 0)  # a feed of energy is no candidate
            candidates[t.field] = {"value": value, "score": float(100 * np.sqrt(blocks.mean())), "gain": cmp.gain,
                                   "se": cmp.se, "physical": physical}  # fmt: skip
            ranking.append({"effect": t.field, "score": candidates[t.field]["score"]})
            if physical and cmp.significant and cmp.gain > best_gain:
                named, best_gain = t.field, cmp.gain
        ranking.sort(key=lambda e: e["score"])
        iterations.append({"named": named or "none", "ranking": ranking, "candidates": candidates})
        if named is None:
            break
        # kept only if it predicts better where it acts, as a single DOF's round's effect (``verdict_of``)
        trial_cols = base_cols + [n_base + fields.index(named)]
        trial = fitted(trial_cols, [*named_all, named])
        if held is None:  # the held-out windows read once, where a round first names an effect
            held = HeldOut(rec, at, n_id, hits)
        if current_ms is None:
            current_ms = held.errors(*current[:2])
        trial_ms = held.errors(*trial[:2])
        # where it acts: the effect's force in the structure with it, at the record's measured relative motion
        r, vr = (relative(x, at) for x in (held.zs - np.asarray(trial[1], float)[:, None], held.v))
        force = float(trial[2][-1]) * terms[fields.index(named)].law.column(r, vr, ident_states["v_noise"])
        acting = acting_mask(force)  # by its force over the record: a quiet tail is not where it acts
        regime = acting_evidence(held, current_ms, trial_ms, acting[n_id:])
        folds = None
        if regime["windows"] < 3:  # the tail barely reaches it: the record's windows where it acts, cross-validated
            folds = fold_evidence(held, acting, fitted, (base_cols, list(named_all)), (trial_cols, [*named_all, named]),
                                  form, whole[3])  # fmt: skip
        verdict = verdict_of(current_ms, trial_ms, [named], regime, folds)
        judgement.append({"effect": named, **verdict})
        iterations[-1].update(kept=verdict["kept"], verdict=verdict["text"])
        if not verdict["kept"]:  # named by the equation error, not helping the prediction: said, and left out
            iterations[-1]["named"] = "none"
            break
        named_all.append(named)
        base_cols, current, current_ms = trial_cols, trial, trial_ms
    if not iterations:  # max_effects = 0: the base law's own score, nothing offered
        score = float(100 * np.sqrt(scored(base_cols)[1].mean()))
        iterations.append({"named": "none", "ranking": [{"effect": "none", "score": score}], "candidates": {}})
    first = iterations[0]
    baseline, base_offsets, theta_base = base_fit
    located = {"before": locate(y - X[:, :n_base] @ theta_base, y, whole[3], form, states, at, baseline, base_offsets)}
    structure, offsets, theta = current  # the baseline where no effect was kept
    if not named_all:
        located["after"] = located["before"]
    else:
        located["after"] = locate(y - X[:, base_cols] @ theta, y, whole[3], form, states, at, structure, offsets)
    # refined as the single DOF's workflow refines (a hammer's record only when asked): the baseline here, the
    # final structure by ``structure_result``, so the gap before and after the effects is measured on refined
    # models alike
    refine = est.refine is True or (est.refine is None and not hits)
    gap_before = held_out_runs(baseline, rec, n_id, base_offsets, hits, paired=refine)  # the refinement's too
    if refine:
        baseline, base_offsets, gap_before, account = refined(baseline, base_offsets, rec, n_id, gap_before, hits)
        if not named_all:  # the baseline is the result, refined once
            structure, offsets = baseline, base_offsets
    est.effects_ = named_all or ["none"]
    est.baseline_structure_ = baseline
    out = structure_result("discrepancy", rec, structure, offsets, n_id, None, [], {
        "effect": first["named"], "effects": named_all or ["none"], "ranking": first["ranking"],
        "candidates": first["candidates"], "iterations": iterations,
        "gap_before_percent": gap_before["rms_percent"],
        "where": where_words(located["before"]), "regimes_before": located["before"],
        "regimes_after": located["after"],
        "velocity_noise_for_sign": ident_states.get("v_noise"), "judgement": judgement,
    }, {"velocity": f"Savitzky-Golay (window, order) = {window}",
        "score": f"held-out weak residual in blocks of {est.window_s:g} s; named only above max(1 SE, "
                 f"{100 * est.margin:g} %)"}, refine=refine and bool(named_all))  # fmt: skip
    if refine and not named_all:
        out = dataclasses.replace(out, refinement=Bunch(account),
                                  settings={**out.settings, "refinement": REFINEMENT_SETTING})  # fmt: skip
    gap_after = {k: v for k, v in out.validation.items() if k != "floor_percent"}
    out.details["gap_after_percent"] = gap_after["rms_percent"]
    out.details["effect_interval"] = effect_intervals(out, named_all)
    out.details["bayesian"] = bayesian_opinions(out, rec, n_id, named_all, hits)
    if est.unnamed:
        out.details["unnamed"] = unnamed_term(out, rec, n_id, hits)
    est.gap_before_, est.gap_after_ = gap_before, gap_after
    return out


def unnamed_term(result, rec: Measurement, n_id: int, hits: bool) -> dict[str, Any]:
    """What no registered effect names in the structure's element (``Discrepancy(unnamed=True)``): the hybrid term
    g(r, r', u) fitted on the identification part with the final structure held, then jointly with the structure
    (``hybrid.fit_element_term``), its size against the element's restoring force, and the held-out tail's restarted
    windows with and without it (the
    median window in % of the record's channels' rms, the runs from the free-run states under the staged input: not
    the measure of ``gap_after_percent``). Not on a hammer's record (as a single DOF's: its windows would cross the
    pulses).
    """
    from negstiff.inference.estimators.hybrid import fit_element_term

    if hits:
        return {"reason": "not fitted on a hammer's record: the non-parametric force is fitted and judged by output "
                "error on windows that would cross the pulses"}  # fmt: skip
    structure, offsets = result.structure, np.asarray(result.offsets_m, float)
    ident = rec.segment(0, n_id)  # one segment: the states the fit derives are kept with it
    term = fit_element_term(structure, offsets, ident)
    zs, vs = ident.free_run_states()
    r, rv = relative(zs - offsets[:, None], structure.place), relative(vs, structure.place)
    g = term.term(r, rv, ident.driving(structure.element))
    force = structure.element.restoring_force(r)
    return {
        "term_rms": float(np.sqrt(np.mean(g**2))),
        "term_percent_of_restoring_force": float(100 * np.sqrt(np.mean(g**2) / np.mean(force**2))),
        "gap": term.restarted_gap(rec, n_id, WINDOW_S),
        **term.to_json(),
    }


class HeldOut:
    """A structure's restarted windows over the held-out tail, read once with their start states and the channels'
    scales (``hits``: a hammer's record, its windows between the pulses): each window's mean-square error over every
    channel (each in its rms; infinite where the run diverged) of a ``(structure, offsets)`` (``errors``).
    """

    def __init__(self, rec: Measurement, at: tuple[int, int], n_id: int, hits: bool):
        self.rec, self.at, self.n_id, self.hits = rec, at, n_id, hits
        self.windows, self.zs, self.v = structure_windows(rec, at, n_id, WINDOW_S, hits)
        self.scale = channel_scales(rec, n_id)

    def record_windows(self) -> RestartWindows:
        """The same windows over the whole record (the folds' where the tail barely reaches an effect)."""
        return structure_windows(self.rec, self.at, 0, WINDOW_S, self.hits)[0]

    def errors(self, structure, offsets, windows: RestartWindows | None = None,
               scale: np.ndarray | None = None) -> np.ndarray:  # fmt: skip
        """Each window's mean-square error over every channel, in each channel's rms (``windows``: by default the
        tail's; ``scale``: the channels' rms they are given in, by default the tail's).
        """
        w = self.windows if windows is None else windows
        s = self.scale if scale is None else scale
        err, diverged = structure_window_errors([structure], self.rec, w, self.zs, self.v, offsets)
        with np.errstate(invalid="ignore", over="ignore"):
            ms = np.mean((err[0] / s[None, :, None]) ** 2, axis=(1, 2))
        return np.where(diverged[0], np.inf, ms)


def acting_evidence(held: HeldOut, before_ms: np.ndarray, after_ms: np.ndarray, acting: np.ndarray) -> dict[str, Any]:
    """The held-out windows where an effect acts, judged on their own as a single DOF's are (``_judging._regime``):
    the tail's windows that hold a sample where the effect acts (``acting`` over the tail: ``_runs.acting_mask`` of its
    force over the record, so that a quiet tail is not where it acts, as a single DOF's),
    the structure's errors without and with it (``before_ms``, ``after_ms``: ``HeldOut.errors``) paired (``acting``),
    and the windows that hold none (``rest``). The gaps are the median window's rms error in % of the channels' rms.
    A single DOF's windows are restarted before each episode, no longer than the motion there stays predictable (its
    tail's are 2 s long); a structure's tail windows are short (``WINDOW_S``, 0.25 s), each episode in one is within
    that of its restart, so they are the tail's own: an effect acting in most of the tail (a friction, at every
    speed but the turning points) is judged on most of its windows, not on fewer placed anew.
    """
    holds = held.windows.measured(np.concatenate([np.zeros(held.n_id, bool), acting])).any(axis=1)
    out: dict[str, Any] = {"window_s": WINDOW_S, "windows": int(holds.sum()),
                           "acting_share_of_tail": float(np.mean(acting))}  # fmt: skip
    if holds.sum() >= 2:
        b, a = before_ms[holds], after_ms[holds]
        out["gap_before_percent"], out["gap_after_percent"] = _median_percent(b), _median_percent(a)
        out["acting"] = paired_windows(b, a, worst=1.0)
    if (~holds).sum() >= 2:
        out["rest"] = paired_windows(before_ms[~holds], after_ms[~holds], worst=1.0)
    return out


def fold_evidence(held: HeldOut, acting: np.ndarray, fitted, without: tuple[list[int], list[str]],
                  with_it: tuple[list[int], list[str]], form, per_dof: int,
                  folds: int = 5) -> dict[str, Any]:  # fmt: skip
    """The windows where an effect acts anywhere in the record, judged by blocked cross-validation as a single DOF's
    are (``_judging._regime_folds``): the record's windows (``HeldOut.record_windows``) that hold a sample where it
    acts (``acting``, over the record), split into ``folds`` contiguous blocks in time; for each block the structure
    without and with the effect (``fitted(columns, names, keep)`` of ``without`` and ``with_it``: each a
    ``(structure, offsets, theta)``) fitted on the identification part's weak rows (``per_dof`` a DOF, ``form``'s
    test functions) whose test function touches none of the block's samples (its windows, and where the effect acts
    between them), and run from the block's windows. Every window is thus predicted by fits that never saw it.
    Returns the windows, the gaps (the median window's rms error in % of the channels' rms over the record), the
    paired comparison ``acting`` and each fold's span.
    """
    windows = held.record_windows()
    holds = windows.measured(acting).any(axis=1)
    starts = windows.starts[holds]
    out: dict[str, Any] = {"windows": int(starts.size), "window_s": WINDOW_S,
                           "acting_share_of_record": float(np.mean(acting))}  # fmt: skip
    if starts.size < 3:
        return out
    n_id, length = held.n_id, windows.length
    # the errors in the record's channels' rms: the folds run where the tail is quiet, whose rms would inflate the
    # gaps and shrink a diverged window's count (an error the size of the signal) below a loud block's ordinary one
    scale = channel_scales(held.rec, 0)
    row_lo = np.arange(per_dof) * form.stride  # row k's test function spans [row_lo, row_lo + phi.size)
    before_ms, after_ms, spans = [], [], []
    for idx in np.array_split(starts, min(folds, starts.size)):
        block = RestartWindows.at(idx, length)
        keep = np.tile(rows_clear_of(block, acting, row_lo, form.phi.size, n_id), held.rec.n_dof)
        b_fit, a_fit = fitted(*without, keep), fitted(*with_it, keep)
        before_ms.append(held.errors(b_fit[0], b_fit[1], block, scale))
        after_ms.append(held.errors(a_fit[0], a_fit[1], block, scale))
        spans.append({"from_s": float(idx[0] / held.rec.fs), "to_s": float((idx[-1] + length) / held.rec.fs),
                      "windows": int(idx.size), "size": float(a_fit[2][-1])})  # fmt: skip
    b, a = np.concatenate(before_ms), np.concatenate(after_ms)
    out["gap_before_percent"], out["gap_after_percent"] = _median_percent(b), _median_percent(a)
    out["acting"] = paired_windows(b, a, worst=1.0)
    out["folds"] = spans
    return out


def _median_percent(ms: np.ndarray) -> float:
    """The median window's rms error in % of the channels' rms (``HeldOut.errors``' units), a diverged window's
    counted as an error the size of the signal.
    """
    return float(100 * np.sqrt(np.median(np.where(np.isfinite(ms), ms, 1.0))))


def judged(rec: Measurement, at: tuple[int, int], n_id: int, hits: bool, before, after, named: list[str],
           force: np.ndarray | None = None) -> dict[str, Any]:  # fmt: skip
    """Whether a round's named effects are kept (``verdict_of``): the structure's restarted windows over the held-out
    tail run from the same states by the structure without and with them (each ``(structure, offsets)``, the
    equation-error fits; ``HeldOut``) compared paired by their logs, pooled and, given the effect's ``force`` over
    the record, where it acts (``acting_evidence``). ``hits``: a hammer's record, its windows between the pulses.
    """
    held = HeldOut(rec, at, n_id, hits)
    b, a = held.errors(*before[:2]), held.errors(*after[:2])
    return verdict_of(b, a, named, None if force is None else acting_evidence(held, b, a, acting_mask(force)[n_id:]))


def _change(c: dict[str, Any]) -> str:
    gain, (lo, hi) = c["gain_percent"], c["gain_interval_percent"]
    return (f"fell {gain:.3g} % (one standard error: {lo:.3g} to {hi:.3g} %, geometric mean)" if gain >= 0 else
            f"rose {1 - gain / 100:.3g}x (geometric mean)")  # fmt: skip


def verdict_of(before_ms: np.ndarray, after_ms: np.ndarray, named: list[str], regime: dict[str, Any] | None = None,
               folds: dict[str, Any] | None = None) -> dict[str, Any]:  # fmt: skip
    """The single DOF's rule on two structures' held-out window errors (``HeldOut.errors``), and what it says: with
    three or more held-out windows where the effect acts (``regime``, ``acting_evidence``), kept when it predicts
    them better beyond one standard error and the rest of the tail not worse beyond theirs; with fewer, the windows
    where it acts anywhere in the record predicted by fits without them (``folds``, ``fold_evidence``) where three or
    more; else the pooled rule, kept when the tail's windows' error falls beyond one standard error.
    """
    pooled = paired_windows(before_ms, after_ms, worst=1.0)  # a diverged window: an error the size of the signal
    what = ", ".join(named)
    out: dict[str, Any] = {"pooled": pooled}
    if regime is not None:
        out["regime"], out["folds"] = regime, folds  # folds None: the tail's windows decided
    judged_on = None
    if regime is not None and regime.get("windows", 0) >= 3 and regime.get("acting") is not None:
        judged_on = regime, "held-out windows"
    elif folds is not None and folds.get("windows", 0) >= 3 and folds.get("acting") is not None:
        judged_on = folds, (f"windows of the record (in {len(folds['folds'])} blocks, each predicted by fits "
                            "without it)")  # fmt: skip
    if judged_on is not None:
        acts, rest = judged_on[0]["acting"], (regime or {}).get("rest")
        worse = rest is not None and rest["gain_percent"] < 0 and rest["significant"]
        kept = bool(acts["significant"] and acts["gain_percent"] > 0 and not worse)
        where = f"the {judged_on[0]['windows']} {judged_on[1]} where it acts: rms error {_change(acts)}"
        why = ("the rest predicted worse" if worse else
               "not a fall beyond its uncertainty" if acts["gain_percent"] >= 0 else "a worse prediction")  # fmt: skip
        rest_text = "the rest not worse" if rest is not None else "too few windows where it does not act to judge"
        text = (f"{what}: kept: {where}; {rest_text}" if kept else
                f"{what}: named by the equation error but not kept: {where}: {why}")  # fmt: skip
        return {"kept": kept, **out, "text": text}
    if pooled is None:
        return {"kept": False, **out,
                "text": f"{what}: not kept: the held-out tail has too few windows to tell if it helps"}  # fmt: skip
    kept = bool(pooled["significant"] and pooled["gain_percent"] > 0)
    change = _change(pooled)
    text = (f"{what}: kept: the held-out windows' rms error {change}" if kept else
            f"{what}: named by the equation error but not kept: with it the held-out windows' rms error {change}, "
            + ("not beyond its uncertainty" if pooled["gain_percent"] >= 0 else "a worse prediction"))  # fmt: skip
    return {"kept": kept, **out, "text": text}
