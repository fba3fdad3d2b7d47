"""The discrepancy workflow's Bayesian second opinions: ``arviz.compare``'s PSIS-LOO over restarted windows with
and without an effect, beside the paired rule that keeps it.
"""

from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np

from negstiff.inference.estimators.identification import WINDOW_S
from negstiff.inference.estimators.results import Identification
from negstiff.inference.record.measurement import Measurement
from negstiff.inference.steps.validation import RestartWindows
from negstiff.models import Model
from negstiff.models.structure import Structure

from ._candidates import _admissible_sizes, _with_size, _without
from ._runs import Runs


def _loo_compare(ms_with: np.ndarray, ms_without: np.ndarray, residual_rows, length: int,
                 rng: np.random.Generator) -> dict[str, Any]:  # fmt: skip
    """``arviz.compare`` (PSIS-LOO) of two models by windows: ``ms_*`` each window's mean-square run error per draw
    (draws, windows). Each window's log density is Gaussian with ``n_eff`` independent samples (``length`` over the
    errors' integrated autocorrelation time, from ``residual_rows``) and a noise variance drawn per draw from its
    scaled inverse chi-square posterior (so that each model's draws differ, as LOO needs).
    """
    import arviz as az

    # the integrated autocorrelation time (samples), summed to the first negative lag: a window of ``length``
    # correlated samples carries length / tau independent ones (numpy's correlate: arviz's autocorrelation works
    # on chains, not on these residual windows)
    taus = []
    for row in residual_rows:
        if not np.all(np.isfinite(row)) or not np.any(row):
            continue
        x = row - row.mean()
        ac = np.correlate(x, x, "full")[x.size - 1 :] / np.dot(x, x)
        neg = np.flatnonzero(ac < 0)
        taus.append(1 + 2 * np.sum(ac[1 : neg[0] if neg.size else ac.size]))
    tau = float(np.median(taus)) if taus else float(length)
    n_eff = max(1.0, length / max(tau, 1.0))
    draws, windows = ms_with.shape

    def loglik(ms: np.ndarray) -> np.ndarray:
        nu = n_eff * ms.shape[1]
        s2 = np.mean(ms, axis=1)  # each draw's pooled variance
        sig2 = nu * s2 / rng.chisquare(nu, size=s2.size)
        return -0.5 * n_eff * (np.log(2 * np.pi * sig2)[:, None] + ms / sig2[:, None])

    data = {name: az.from_dict({"posterior": {"draw_index": np.arange(draws, dtype=float)[None, :]},
                                "log_likelihood": {"windows": loglik(ms)[None]}})
            for name, ms in (("with", ms_with), ("without", ms_without))}  # fmt: skip
    # arviz's own warnings (PSIS's Pareto k over 0.7 for a window that dominates; the stacking weights' overflow
    # when the two models' densities lie far apart) said in the result, not printed to the user's terminal mid-run
    with warnings.catch_warnings(record=True) as said, np.errstate(all="ignore"):
        warnings.simplefilter("always")
        try:
            table = az.compare(data, round_to="none")
        except ValueError as err:  # arviz cannot score these windows
            return {"windows": int(windows), "error": str(err)}
    pareto = any("Pareto" in str(w.message) for w in said) or bool("warning" in table and np.any(table["warning"]))
    weight = float(table.loc["with", "weight"])
    diff = float(table.loc["with", "elpd"] - table.loc["without", "elpd"])
    dse = float(max(table.loc["with", "dse"], table.loc["without", "dse"]))
    return {
        "elpd_with": float(table.loc["with", "elpd"]),
        "elpd_without": float(table.loc["without", "elpd"]),
        "elpd_diff": diff,  # with minus without: > 0 favours naming it
        "dse": dse,
        "weight_with": weight if math.isfinite(weight) else None,  # the stacking weights overflow far apart
        "prefers": "with" if diff > 0 else "without",
        "beyond_two_se": bool(abs(diff) > 2 * dse),
        "windows": int(windows),
        "effective_samples_per_window": n_eff,
        "pareto_k_high": pareto,  # PSIS-LOO's own check: a window its importance sampling cannot stand in for
    }


class Opinions(Runs):
    """The Bayesian second opinions (a layer of ``Discrepancy``)."""

    def _held_out_opinion(self, rec: Measurement, model_before: Model, model_after: Model,
                          draws: int = 64) -> dict[str, Any]:  # fmt: skip
        """A round's Bayesian second opinion: the held-out tail's ``window_s`` restarted runs' predictive
        densities with the effect (``model_after``) and without it (``model_before``), compared by
        ``arviz.compare`` (PSIS-LOO over the windows; the noise variance drawn, the models' parameters held).
        """
        windows = self._tail_windows(rec)  # the tail's gap windows
        if len(windows) < 2:
            return {"windows": len(windows), "error": "too few held-out windows"}
        rb, ra = (self._residuals_at(m, rec, windows) for m in (model_before, model_after))
        worst = float(np.mean(rec.displacement[self.n_id_ :] ** 2))
        ms_b, ms_a = (np.where(np.isfinite(m), m, worst) for m in (np.mean(rb**2, axis=1), np.mean(ra**2, axis=1)))
        rng = np.random.default_rng(0)
        out = _loo_compare(np.repeat(ms_a[None], draws, 0), np.repeat(ms_b[None], draws, 0), [*ra, *rb],
                           windows.length, rng)  # fmt: skip
        out["method"] = (f"arviz.compare (PSIS-LOO) over the held-out tail's {len(windows)} restarted "
                         f"{self.window_s_:g} s runs, {draws} draws of the noise variance")  # fmt: skip
        return out

    def _bayesian_opinion(self, rec: Measurement, effect: str, windows: RestartWindows, theta: np.ndarray,
                          cov: np.ndarray, keys: list, where: str, draws: int = 64) -> dict[str, Any]:  # fmt: skip
        """A Bayesian second opinion on naming ``effect``: the windows' predictive densities of the final model
        with it (its size drawn from the Laplace approximation) and without it (the rest held), compared by
        ``arviz.compare`` (PSIS-LOO over the windows). Each window's log density is Gaussian in its run's error
        with ``n_eff`` independent samples (the window's length over the errors' integrated autocorrelation
        time) and a noise variance drawn from its scaled inverse chi-square posterior (so that each model's
        draws differ, as LOO needs).
        """
        rng = np.random.default_rng(0)
        length = windows.length
        worst = float(np.mean(windows.measured(rec.displacement) ** 2))

        def window_ms(model: Model) -> tuple[np.ndarray, np.ndarray]:
            r = self._residuals_at(model, rec, windows)
            ms = np.nanmean(r**2, axis=1)
            return np.where(np.isfinite(ms), ms, worst), r

        with_ms = []
        for size in _admissible_sizes(self.model_, effect, keys, rng.multivariate_normal, theta, cov, draws):
            with_ms.append(window_ms(_with_size(self.model_, effect, size))[0])
        ms_with = np.stack(with_ms)  # (draws, windows)
        ms_without, r_without = window_ms(_without(self.model_, effect))
        out = _loo_compare(ms_with, np.repeat(ms_without[None, :], len(ms_with), axis=0),
                           [*self._residuals_at(self.model_, rec, windows), *r_without], length, rng)  # fmt: skip
        out["method"] = (
            f"arviz.compare (PSIS-LOO) over {where} ({length / rec.fs:g} s restarted runs), {draws} "
            "draws of the effect's size from its Laplace approximation and of the noise variance"
        )
        return out


# --- a structure's -------------------------------------------------------------------------------------------------
def bayesian_opinions(result: Identification, rec: Measurement, n_id: int, named: list[str],
                      between_pulses: bool = False, draws: int = 64) -> dict[str, Any]:  # fmt: skip
    """A Bayesian second opinion on each named effect, beside the paired rule that named it (the single DOF's
    ``_loo_compare``): the held-out tail's restarted windows (``free_run_error``'s) predicted by the final structure
    with the effect (its size drawn ``draws`` times from the refinement's standard error where one was kept, else at
    its value) and without it (the rest held), compared by ``arviz.compare`` (PSIS-LOO over the windows). A window's
    mean-square error is every DOF's divided by that channel's held-out variance (the validation's measure); a
    diverged run's is the measured motion's own.
    """
    from negstiff.inference.steps.validation import channel_scales, structure_window_errors, structure_windows

    from ._candidates import _admissible_sizes, _with_size, _without

    if not named:
        return {}
    structure, offsets = result.system, np.asarray(result.offsets_m, float)
    assert isinstance(structure, Structure)  # the discrepancy workflow reads a structure with its masses
    windows, zs, v = structure_windows(rec, structure.place, n_id, WINDOW_S, between_pulses)
    scale = channel_scales(rec, n_id)[None, None, :, None]
    worst = float(np.mean((windows.measured(rec.channels) / scale[0]) ** 2))
    account: dict[str, Any] = dict(result.refinement or {})
    se_all = (account.get("standard_errors") or {}) if account.get("applied") else {}
    element = structure.element
    out: dict[str, Any] = {}
    for e in named:
        rng = np.random.default_rng(0)
        raw = element.extra.get(e)
        if not isinstance(raw, (int, float)):  # an effect of several values (none in a structure's catalogue yet)
            out[e] = {"error": "not one coefficient: no opinion drawn"}
            continue
        value, se = float(raw), float(se_all.get(e) or math.nan)
        drawn = math.isfinite(se) and se > 0
        sizes = (_admissible_sizes(element, e, [None], rng.multivariate_normal, np.array([value]),
                                   np.array([[se**2]]), draws) if drawn else [])  # fmt: skip
        systems = [structure.with_element(_with_size(element, e, size)) for size in sizes]
        systems += [structure, structure.with_element(_without(element, e))]  # at its value; without it
        err, diverged = structure_window_errors(systems, rec, windows, zs, v, offsets)
        norm = err / scale
        ms = np.where(diverged, worst, np.mean(norm**2, axis=(2, 3)))
        rows = [r for k in (-2, -1) for r in norm[k].reshape(-1, norm.shape[-1])]
        ms_with = ms[:-2] if drawn else np.repeat(ms[-2:-1], draws, axis=0)  # at its value: its one run, each draw's
        opinion = _loo_compare(ms_with, np.repeat(ms[-1][None], draws, axis=0), rows, windows.length, rng)
        opinion["method"] = (
            f"arviz.compare (PSIS-LOO) over the held-out tail's {windows.starts.size} restarted {WINDOW_S:g} s runs of "
            f"every DOF, {draws} draws of the noise variance"
            + (" and of the effect's size from the refinement's standard error" if drawn else
               " (the effect at its value: no refinement's standard error was kept)")
        )  # fmt: skip
        out[e] = opinion
    return out
