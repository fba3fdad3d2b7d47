"""Restarted free runs of the discrepancy workflow: the held-out gap, the windows where an effect acts (no longer
than the motion there stays predictable), a hammer's windows restarted after its pulses.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from negstiff.inference.record.measurement import Measurement
from negstiff.inference.steps.validation import (
    RestartWindows,
    parting_sample,
    predictability,
    restart_windows,
    restarted_free_runs,
    simulate_windows,
)
from negstiff.models import Model

from ._candidates import LOCAL_DRAWS
from ._scoring import Scoring


class Runs(Scoring):
    """Restarted free runs, their windows and gaps (a layer of ``Discrepancy``)."""

    def _gap(self, rec: Measurement, model: Model) -> dict[str, Any]:
        """Restarted free runs over the held-out tail (and their residual PSD)."""
        fr = self._tail_runs(model, rec)
        out = {k: v for k, v in fr.items() if not isinstance(v, np.ndarray)}
        ms = fr.get("window_ms")
        out["window_ms"] = ms  # per window, for the paired comparison (``_helps``); not in the result JSON
        if ms is not None:
            ok = np.isfinite(ms)
            # the median window: a single window that diverges near the barrier (chaos) cannot dominate
            out["median_window_rms_um"] = float(1e6 * np.sqrt(np.median(ms[ok]))) if ok.any() else math.inf
            tail = rec.displacement[self.n_id_ :]
            out["median_window_percent"] = (
                float(100 * np.sqrt(np.median(ms[ok])) / np.sqrt(np.mean(tail**2))) if ok.any() else math.inf
            )
        return out

    def _tail_windows(self, rec: Measurement) -> RestartWindows:
        """The held-out tail's gap windows: ``window_s`` windows from the split (``restart_windows``), on a hammer's
        record restarted after its pulses (``_after_pulses``).
        """
        return self._after_pulses(rec, restart_windows(rec.n, rec.fs, self.window_s_, start=self.n_id_))

    def _tail_runs(self, model: Model, rec: Measurement) -> dict[str, Any]:
        """The held-out tail's restarted free runs (``validation.restarted_free_runs``' keys) over ``_tail_windows``:
        ``restarted_free_runs`` itself where they are its windows (any record but a hammer's).
        """
        if vars(self).get("record_kind_") is None or self.record_kind_.kind != "impact":
            return restarted_free_runs(model, rec, self.n_id_, self.window_s_, self._z0, self._v0)
        windows = self._tail_windows(rec)
        if not len(windows):
            return {}
        err = self._residuals_at(model, rec, windows)
        meas = windows.measured(rec.displacement)
        ok = np.isfinite(err).all(axis=1)
        window_ms = np.where(ok, np.mean(np.where(ok[:, None], err, 0.0) ** 2, axis=1), np.nan)
        out: dict[str, Any] = {"restart_window_s": windows.length / rec.fs, "restart_windows": len(windows),
                               "restart_diverged": int((~ok).sum()), "window_ms": window_ms,
                               "restarted_after_pulses": True}  # fmt: skip
        out["restarted_rms_percent"] = (float(100 * np.sqrt(np.mean(err[ok] ** 2)) / np.sqrt(np.mean(meas[ok] ** 2)))
                                        if ok.any() else math.inf)  # fmt: skip
        return out

    def _after_pulses(self, rec: Measurement, windows: RestartWindows) -> RestartWindows:
        """On a hammer's record (its force windowed: zero between the pulses, ``record_kind``), each window that
        holds a pulse restarted after it (the hit sets its start state), once the start state's smoothing window
        (``derivatives.derivative_window``, the free runs' states) is clear of it; those that then run past the
        record's end are left out; on any other record ``windows`` as they are. A pulse lasts a few samples (4 ms
        at 1 kHz: four), which the sampled force does not resolve for the simulator: the true model's run through
        a hit missed its record by 0.9-2 mm; restarted on the pulse's last sample by 100-200 um (the smoothing
        window across the hit), half a smoothing window after it by 1-160 um, the velocity's noise (the seed-like
        double well hit by 40 N, 1 um of noise; measured), as the posterior found (``Windows.free_windows``).
        """
        kind = vars(self).get("record_kind_")
        if kind is None or kind.kind != "impact" or not len(windows):
            return windows
        from negstiff.inference.record.derivatives import derivative_window

        cached = vars(self).get("_state_window")
        if cached is None or cached[0] is not rec:  # the states' own window (``Measurement.states("state")``)
            width = derivative_window(rec.displacement, rec.fs, "state", floor=rec.noise_floor())[0]
            cached = self._state_window = (rec, width)
        clear = cached[1] // 2 + 1
        busy = np.asarray(rec.u) != 0
        starts = []
        for s in windows.starts.tolist():
            for _ in range(4):  # a window moved past one pulse into the next is moved again
                held = np.flatnonzero(busy[max(0, s - clear + 1) : s + windows.length])
                if not held.size:
                    break
                s = max(0, s - clear + 1) + int(held[-1]) + clear
            if s + windows.length <= rec.n and not busy[max(0, s - clear + 1) : s + windows.length].any():
                starts.append(s)
        return RestartWindows.at(starts, windows.length)

    def _runs_at(self, model: Model, rec: Measurement, windows: RestartWindows) -> np.ndarray:
        """Mean-square error of free runs over ``windows``, each restarted from the measured state at its start
        (nan: diverged).
        """
        return np.mean(self._residuals_at(model, rec, windows) ** 2, axis=1)

    def _residuals_at(self, model: Model, rec: Measurement, windows: RestartWindows) -> np.ndarray:
        """Free runs' errors over ``windows`` (run minus measured z, one row per window; nan rows: diverged):
        ``validation.simulate_windows`` from the states the gap's runs start from.
        """
        res = simulate_windows(model, rec, windows, self._z0, self._v0)
        meas = windows.measured(rec.displacement)
        out = np.full(meas.shape, np.nan)
        ok = ~res.diverged
        out[ok] = res.z[ok] - meas[ok]
        return out

    def _predictability(self, rec: Measurement, model: Model) -> dict[str, Any]:
        """How long ``model``'s runs restarted from the record's states stay predictable (``validation.predictability``
        over the identification part, at most ``window_s / 2`` of the fit's own window, ``window_s_``).
        """
        return predictability(model, rec, self.n_id_, self.window_s_, self._z0, self._v0)

    def _parting_sample(self, rec: Measurement, model: Model, windows: RestartWindows, draws: int,
                        min_pairs: int) -> int | None:  # fmt: skip
        """``validation.parting_sample`` of ``model``'s runs over ``windows`` (the identification part's amplitude)."""
        return parting_sample(model, rec, windows, self._z0, self._v0, self.n_id_, draws, min_pairs)

    def _window_length(self, rec: Measurement) -> int:
        """Samples of the regime's and the interval's windows: the record's predictability horizon
        (``predictability_``), at most ``window_s / 2``.
        """
        return max(8, int(round(self.predictability_["window_s"] * rec.fs)))

    def _episodes(self, rec: Measurement, force: np.ndarray, lo: int,
                  length: int | None = None) -> tuple[np.ndarray, RestartWindows]:  # fmt: skip
        """Where a force acts (above a quarter of its rms over the samples where it acts at all) and windows of
        ``length`` samples (by default the record's predictable span, ``_window_length``: ``window_s / 2`` at
        most) restarted a quarter window before each episode from sample ``lo`` on (no two overlapping); ``force``
        is given over the whole record, so that where it acts is read against its size over the record (a quiet
        held-out tail is not where it acts, as a structure's, ``_rounds.acting_evidence``). Returns (acting mask from
        ``lo`` on, the windows).
        """
        acting = acting_mask(force)[lo:]
        length = self._window_length(rec) if length is None else length
        lead = length // 4
        starts: list[int] = []
        edges = np.flatnonzero(np.diff(np.concatenate([[0], acting.astype(np.int8)])) == 1)  # episodes' first samples
        for e in edges:
            s0 = lo + max(0, int(e) - lead)
            if s0 + length <= rec.n and (not starts or s0 >= starts[-1] + length):
                starts.append(s0)
        return acting, self._after_pulses(rec, RestartWindows.at(starts, length))

    def _episode_windows(self, rec: Measurement, force: np.ndarray, lo: int,
                         models: tuple[Model, ...]) -> tuple[np.ndarray, RestartWindows, dict[str, Any]]:  # fmt: skip
        """``_episodes``' windows no longer than the motion there stays predictable by the models compared on them:
        each model's runs from the windows' start states and from those states moved by draws of their noise
        (``LOCAL_DRAWS`` per window, seeded), the first time their rms separation, pooled over windows and draws,
        exceeds ``PREDICTABILITY_FRACTION`` of the identification part's amplitude (``motion_amplitude``); the
        shorter of the models' (and of the record's span, ``_window_length``). Measured before any run is compared
        with the record, the same for every model. Where an effect acts the motion can be far less predictable than
        the record's average (an end stop's bounce next to the barrier: 0.17 s against 0.9 s, measured), which the
        baseline, without the effect, does not show. Returns (acting mask, the windows, ``{"horizon_s", "record_s"}``).
        """
        acting, windows = self._episodes(rec, force, lo)
        length = windows.length
        info = {"record_s": length / rec.fs, "horizon_s": length / rec.fs}
        if len(windows) < 1:
            return acting, windows, info
        for model in models:
            parted = self._parting_sample(rec, model, windows, draws=LOCAL_DRAWS, min_pairs=1)
            if parted is not None:
                length = min(length, max(8, parted))
        if length < windows.length:
            acting, windows = self._episodes(rec, force, lo, length)
            info["horizon_s"] = length / rec.fs
        return acting, windows, info


def acting_mask(force: np.ndarray) -> np.ndarray:
    """Where a force acts: the samples where it exceeds a quarter of its rms over those where it acts at all (a single
    DOF's episodes, ``Runs._episodes``; a structure's windows where an effect acts, ``_rounds.acting_evidence``).
    """
    nz = np.abs(force) > 0
    return np.abs(force) > 0.25 * np.sqrt(np.mean(force[nz] ** 2)) if nz.any() else nz


def rows_clear_of(block: RestartWindows, acting: np.ndarray, row_lo: np.ndarray, support: int, n_id: int) -> np.ndarray:
    """The weak rows of the identification part [0, ``n_id``) (row k's test function over samples [``row_lo[k]``,
    ``row_lo[k]`` + ``support``)) that touch none of a cross-validation block's samples: its windows and, between its
    first and its last, where the effect acts (``acting``, over the record). A single DOF's folds
    (``Judging._regime_folds``) and a structure's (``_rounds.fold_evidence``, each DOF's rows alike).
    """
    mask = np.zeros(acting.size, bool)
    mask[block.index] = True
    span = slice(int(block.starts[0]), int(block.starts[-1]) + block.length)
    mask[span] |= acting[span]
    cum = np.concatenate([[0], np.cumsum(mask[:n_id])])
    hi = np.minimum(row_lo + support, n_id)
    return (cum[hi] - cum[np.minimum(row_lo, n_id)]) == 0
