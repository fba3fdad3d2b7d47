"""Whether a named effect is kept: the same restarted runs before and after it, compared pooled over the held-out
tail, where it acts, and cross-validated over the record where the tail barely reaches it.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from negstiff.inference.record.measurement import Measurement
from negstiff.inference.steps.selection import compare
from negstiff.inference.steps.validation import RestartWindows
from negstiff.inference.steps.weak import test_function
from negstiff.models import Model, effects

from ._candidates import Candidate, _positional, _size_of, law_of
from ._opinions import Opinions
from ._runs import rows_clear_of


class Judging(Opinions):
    """Whether an effect helps the prediction (a layer of ``Discrepancy``)."""

    def _helps(self, rec: Measurement, before: dict[str, Any], after: dict[str, Any], effect: str,
               model_before: Model, model_after: Model, spec_before: Candidate | None = None,
               best: Candidate | None = None) -> tuple[bool, str, dict[str, Any]]:  # fmt: skip
        """Whether the effect is kept, and why.

        Judged on the held-out tail twice, the same restarted free runs before and after (paired), each
        comparison by the windows' log mean-square errors (log: a window whose run parts near the barrier,
        chaos, carries an error 100x the others' and would decide a plain mean alone; a
        window whose run diverges counts as an error the size of the signal):

        * **pooled**: every ``window_s`` window of the tail;
        * **where it acts** (``_regime``): windows starting just before each episode where the effect's force
          is large, scored on their own, beside the tail's windows where it never acts (the rest).

        * **where it acts, cross-validated** (``_regime_folds``), when the tail holds fewer than three such
          windows (an effect the tail barely reaches): the windows where it acts anywhere in the record, in
          blocks, each predicted by fits made without its block's data.

        Kept when the model with it predicts the windows where it acts better by more than one standard error
        of their paired differences and does not predict the rest of the tail worse beyond theirs; with fewer
        than three such windows in the tail, the cross-validated windows decide, and with fewer than three of
        those too, the pooled rule. An effect the equation error named that does not help the prediction is
        said, and left out.
        """
        pooled = self._paired(rec, before.get("window_ms"), after.get("window_ms"))
        regime = self._regime(rec, before, after, effect, model_before, model_after)
        evidence: dict[str, Any] = {"pooled": pooled, "regime": regime,
                                    "bayesian": self._held_out_opinion(rec, model_before, model_after)}  # fmt: skip
        change = "{:.3g} % (one standard error: {:.3g} to {:.3g} %, geometric mean)"
        judged, where = regime, "held-out windows"
        if regime.get("windows", 0) < 3 and spec_before is not None and best is not None:
            evidence["folds"] = self._regime_folds(rec, effect, spec_before, best, model_after, model_before)
            self._folds_evidence[effect] = evidence["folds"]
            if evidence["folds"].get("windows", 0) >= 3 and evidence["folds"].get("acting") is not None:
                judged = {**evidence["folds"], "rest": regime.get("rest")}
                where = f"windows of the record (in {len(judged['folds'])} blocks, each predicted by fits without it)"
        # a measured channel's term the equation error named (beyond twice its standard error) is kept unless it
        # predicts worse beyond its uncertainty: the catalogue's rule (better beyond it) dropped a piezo's coupling
        # whose windows' error fell 30 % within a wide one (measured)
        measured = effect.startswith(effects.AUX_PREFIX)

        def not_worse(c: dict[str, Any] | None) -> bool:
            return c is not None and not (c["gain_percent"] < 0 and c["significant"])

        if judged.get("windows", 0) >= 3 and judged.get("acting") is not None:
            acts, rest = judged["acting"], judged.get("rest")
            worse = rest is not None and rest["gain_percent"] < 0 and rest["significant"]
            what = (f"the {judged['windows']} {where} where it acts: rms error fell "
                    + change.format(acts["gain_percent"], *acts["gain_interval_percent"]))  # fmt: skip
            if acts["significant"] and acts["gain_percent"] > 0 and not worse:
                return True, f"{effect}: kept: {what}; the rest not worse", evidence
            if measured and not_worse(acts) and not worse:
                return True, f"{effect}: kept: a measured channel, not worse: {what}; the rest not worse", evidence
            why = "the rest predicted worse" if worse else "not a fall beyond its uncertainty"
            return False, f"{effect}: named by the equation error but not kept: {what}: {why}", evidence
        if pooled is None:
            return False, f"{effect}: not kept: the held-out tail has too few windows to tell if it helps", evidence
        txt = change.format(pooled["gain_percent"], *pooled["gain_interval_percent"])
        if pooled["significant"] and pooled["gain_percent"] > 0:
            return True, f"{effect}: kept: the held-out windows' rms error fell {txt}", evidence
        if measured and not_worse(pooled):
            return True, (f"{effect}: kept: a measured channel the equation error names, not predicting the held-out "
                          f"windows worse: their rms error fell {txt}"), evidence  # fmt: skip
        return False, (f"{effect}: named by the equation error but not kept: with it the held-out windows' rms error "
                       f"fell {txt}, not beyond its uncertainty"), evidence  # fmt: skip

    def _paired(self, rec: Measurement, a, b, worst: float | None = None) -> dict[str, Any] | None:
        """``paired_windows`` of two models' per-window mean-square errors, a diverged run counting as an error the
        size of the held-out tail's signal unless ``worst`` says otherwise.
        """
        if worst is None:
            worst = float(np.mean(rec.displacement[self.n_id_ :] ** 2))
        return paired_windows(a, b, worst)

    def _effect_force(self, model: Model, effect: str, z: np.ndarray, v: np.ndarray) -> np.ndarray | None:
        """The named effect's force [N] in ``model`` at the states (z, v); None for a measured channel's term and
        for a law (it replaces the restoring force at every state: it acts wherever the motion goes).
        """
        if law_of(effect) is not None:
            return None
        e = effects.get(effect)
        if isinstance(e.law, effects.MeasuredChannel):
            return None
        value = model.to_dict()[e.folds_into] if e.folds_into else model.extra.get(effect)
        if value is None:
            return None
        return np.asarray(e.law.force(value, z, v), float)

    def _regime(self, rec: Measurement, before: dict[str, Any], after: dict[str, Any], effect: str,
                model_before: Model, model_after: Model) -> dict[str, Any]:  # fmt: skip
        """The held-out windows where ``effect`` acts, scored on their own: free runs restarted a quarter window
        before each episode of the tail where the effect's force (the model's with it, at the measured states)
        exceeds a quarter of its rms over the record's samples where it acts at all (a quiet tail is not where it
        acts), no longer than the motion there stays predictable by either model (``_episode_windows``:
        ``window_s / 2`` at most); and the tail's ``window_s`` windows that hold no such sample (the rest). Gaps in %
        of the windows' rms z, before and after, and the paired comparisons.
        """
        force = self._effect_force(model_after, effect, self._z0, self._v0)  # over the record (``_episodes``)
        if force is None:
            return {"windows": 0, "reason": "a law replaces the restoring force at every state: judged on every "
                    "held-out window" if law_of(effect) is not None else "a measured channel's term acts wherever "
                    "the channel does"}  # fmt: skip
        if not np.any(np.abs(force[self.n_id_ :]) > 0):
            return {"windows": 0, "reason": "the effect does not act in the held-out tail"}
        acting, windows, horizon = self._episode_windows(rec, force, self.n_id_, (model_before, model_after))
        out: dict[str, Any] = {"window_s": windows.length / rec.fs, "windows": len(windows),
                               "record_window_s": horizon["record_s"],
                               "acting_share_of_tail": float(np.mean(acting))}  # fmt: skip
        if len(windows) < 2:
            return out
        ms_b, ms_a = (self._runs_at(m, rec, windows) for m in (model_before, model_after))
        meas = windows.measured(rec.displacement)
        ref = float(np.sqrt(np.mean(meas**2)))
        worst = float(np.mean(meas**2))
        # the median window's rms error, % of those windows' rms z (the headline gap's measure: one run that
        # parts near the barrier, chaos, cannot decide it)
        out["gap_before_percent"], out["gap_after_percent"] = (
            float(100 * np.sqrt(np.median(np.where(np.isfinite(m), m, worst))) / ref) for m in (ms_b, ms_a)
        )
        out["acting"] = self._paired(rec, ms_b, ms_a)
        a, b = before.get("window_ms"), after.get("window_ms")
        if a is not None and b is not None:
            # the tail's windows (``restarted_free_runs``' own) that hold no sample where it acts
            tail = self._tail_windows(rec)
            clear = ~tail.measured(np.concatenate([np.zeros(self.n_id_, bool), acting])).any(axis=1)
            if clear.sum() >= 2:
                out["rest"] = self._paired(rec, np.asarray(a)[clear], np.asarray(b)[clear])
        return out

    def _regime_folds(self, rec: Measurement, effect: str, before: Candidate, best: Candidate,
                      model_after: Model, model_before: Model | None = None,
                      folds: int = 5) -> dict[str, Any]:  # fmt: skip
        """The windows where ``effect`` acts anywhere in the record, judged by blocked cross-validation: the
        episodes where its force (``model_after``'s, at the measured states) is large, their restarted windows
        split into ``folds`` contiguous blocks in time; for each block the model without the effect (``before``'s
        terms) and with it (``best``'s, an end stop's onset searched again) are fitted by weak least squares on
        the identification part without the block's data (the weak rows whose test function touches one of its
        windows or any sample between them where the effect acts) and run from the block's windows. Every
        window is thus predicted by fits that never saw it: the honest judgement where the held-out tail barely
        reaches the effect. Returns the windows, the gaps before and after (the median window's rms error, % of
        those windows' rms z), the paired comparison ``acting`` and each fold's fitted size.
        """
        force = self._effect_force(model_after, effect, self._z0, self._v0)
        if force is None or not np.any(np.abs(force) > 0):
            return {"windows": 0}
        compared = (model_after,) if model_before is None else (model_before, model_after)
        acting, windows, horizon = self._episode_windows(rec, force, 0, compared)
        length = windows.length
        out: dict[str, Any] = {"windows": len(windows), "window_s": length / rec.fs,
                               "record_window_s": horizon["record_s"],
                               "acting_share_of_record": float(np.mean(acting))}  # fmt: skip
        if len(windows) < 3:
            return out
        form = self._form
        n_rows = self._design(rec, 0, self.n_id_, None, before.aux, before.law)[0].shape[0]
        support = test_function(form.half, rec.dt)[0].size
        row_lo = np.arange(n_rows) * form.stride  # row k's test function spans [row_lo, row_lo + support)
        groups = np.array_split(windows.starts, min(folds, len(windows)))
        ms_b, ms_a, sizes = [], [], []
        pos = _positional()
        for idx in groups:
            block = RestartWindows.at(idx, length)
            keep = rows_clear_of(block, acting, row_lo, support, self.n_id_)  # its windows and contacts between
            models = []
            for cand in (before, best):
                stop = cand.stop
                if pos is not None and cand.effect == pos.name:
                    stop = self._fit_stop(rec, cand.terms, cand.aux, upto=self.n_id_, keep=keep, law=cand.law)
                W, y = self._design(rec, 0, self.n_id_, stop, cand.aux, cand.law)
                coef = self._fit(W[keep], y[keep], cand.terms, stop is not None, len(cand.aux), cand.law)
                models.append(self._model(coef, rec, stop, cand.aux, cand.law))
            ms_b.append(self._runs_at(models[0], rec, block))
            ms_a.append(self._runs_at(models[1], rec, block))
            folds_size = _size_of(models[1], effect)
            sizes.append({"from_s": float(idx[0] / rec.fs), "to_s": float((idx[-1] + length) / rec.fs),
                          "windows": int(len(idx)), "size": folds_size})  # fmt: skip
        b, a = np.concatenate(ms_b), np.concatenate(ms_a)
        meas = windows.measured(rec.displacement)
        ref = float(np.sqrt(np.mean(meas**2)))
        worst = float(np.mean(meas**2))
        out["gap_before_percent"], out["gap_after_percent"] = (
            float(100 * np.sqrt(np.median(np.where(np.isfinite(m), m, worst))) / ref) for m in (b, a)
        )
        out["acting"] = self._paired(rec, b, a, worst)
        out["folds"] = sizes
        return out


def paired_windows(a, b, worst: float) -> dict[str, Any] | None:
    """Paired comparison of two models' per-window mean-square errors (the same windows) by their logs: the rms
    error's fall in % (geometric mean), its standard error, whether it exceeds one standard error (None for fewer
    than two windows). A diverged run's (not finite) counts as ``worst``. A single DOF's judging and a structure's
    (``_rounds``) read it alike.
    """
    if a is None or b is None or len(a) != len(b) or len(a) < 2:
        return None
    a, b = (np.log(np.maximum(np.where(np.isfinite(x), x, worst), 1e-300)) for x in (a, b))
    gain = compare(a, b, 0.0, a)
    return {
        "windows": int(len(a)),
        "gain_percent": float(100 * (1 - math.exp(-gain.gain / 2))),  # the windows' rms error, geometric mean
        "gain_interval_percent": [float(100 * (1 - math.exp(-(gain.gain + k * gain.se) / 2))) for k in (-1, 1)],
        "significant": bool(gain.significant),
    }
