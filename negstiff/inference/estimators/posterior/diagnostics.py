"""The posterior's result: summaries (arviz), convergence warnings, the contract's JSON."""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass
class PosteriorResult:
    """A posterior run. ``idata`` (arviz: posterior, sample stats, observed data and the pointwise
    log likelihood) and ``log_likelihood`` (ensembles, walkers x kept draws, windows; thinned) are built on
    first use: the pointwise log likelihood simulates every kept draw again (4 s of a 30 s run on a
    300 s record, measured), which a run that only reports its summary does not need.
    """

    names: tuple[str, ...]
    samples: np.ndarray  # (ensembles, steps, walkers, d) physical, sigma (not log) last, after burn-in
    summary: dict[str, dict[str, float]]
    tau: np.ndarray  # (ensembles, d) integrated autocorrelation times [steps]
    warnings: list[str]
    settings: dict[str, Any]
    map_point: dict[str, float]
    thin: int = 1
    build_idata: Callable[[], tuple[Any, np.ndarray]] | None = field(default=None, repr=False, compare=False)
    _built: tuple[Any, np.ndarray] | None = field(default=None, init=False, repr=False, compare=False)

    def _idata_and_loglik(self) -> tuple[Any, np.ndarray | None]:
        if self._built is None:
            if self.build_idata is None:
                return None, None
            self._built = self.build_idata()
            self.build_idata = None  # it holds the run's windows and log posterior: let them go
        return self._built

    def __getstate__(self) -> dict[str, Any]:
        """Pickled without the builder (it holds the run's log posterior and its lock): a result pickled
        before its arviz data was asked for has none after unpickling.
        """
        return {**self.__dict__, "build_idata": None}

    @property
    def idata(self):
        """The arviz data of the draws (built once, on first use)."""
        return self._idata_and_loglik()[0]

    @property
    def log_likelihood(self) -> np.ndarray | None:
        """Each draw's log likelihood per window (None when not kept)."""
        return self._idata_and_loglik()[1]


def summarise(samples: np.ndarray, names, tau: np.ndarray, hdi_prob: float) -> dict[str, dict[str, float]]:
    """Posterior summaries of ``samples`` (ensembles, steps, walkers, d): mean, sd, HDI, R-hat across
    the ensembles (each one chain, draws in step order), bulk and tail ESS over all walkers (arviz,
    capped by emcee's N / tau), tau.
    """
    import arviz as az

    E, S, W, d = samples.shape
    across = az.from_dict({"posterior": {n: samples[..., i].reshape(E, S * W) for i, n in enumerate(names)}})
    walkers = az.from_dict(
        {"posterior": {n: np.moveaxis(samples[..., i], 2, 1).reshape(E * W, S) for i, n in enumerate(names)}}
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "more chains than draws" notices for short toy runs
        rhat = az.rhat(across, method="rank")
        ess_b, ess_t = az.ess(walkers, method="bulk"), az.ess(walkers, method="tail")
        hdi = az.hdi(across, prob=hdi_prob)
    out = {}
    for i, n in enumerate(names):
        x = samples[..., i].ravel()
        col = np.asarray(tau, float)[:, i]
        t = float(np.nanmax(col)) if np.isfinite(col).any() else float("nan")
        emcee_ess = E * S * W / max(t, 1.0)
        lo, hi = (float(v) for v in hdi[n].values)
        out[n] = {
            "mean": float(x.mean()),
            "sd": float(x.std(ddof=1)),
            "hdi_low": lo,
            "hdi_high": hi,
            "r_hat": float(rhat[n].values),
            "ess_bulk": float(min(ess_b[n].values, emcee_ess)),
            "ess_tail": float(min(ess_t[n].values, emcee_ess)),
            "tau_steps": t,
        }
    return out


def convergence_warnings(summary: dict[str, dict[str, float]], n_ensembles: int) -> list[str]:
    """A warning per parameter whose R-hat (>= 1.01) or bulk ESS (< 100 per ensemble) says it has not converged."""
    out = []
    for n, s in summary.items():
        if not s["r_hat"] < 1.01:
            out.append(f"{n}: R-hat {s['r_hat']:.4f} >= 1.01 across the {n_ensembles} ensembles")
        if not s["ess_bulk"] > 400:
            out.append(f"{n}: bulk ESS {s['ess_bulk']:.0f} <= 400")
    return out


def result_json(res: PosteriorResult, hdi_prob: float) -> dict[str, Any]:
    """The contract's posterior JSON (plus diagnostics)."""
    params: dict[str, dict[str, float]] = {}
    nuisance: dict[str, dict[str, float]] = {}
    for n, s in res.summary.items():
        key = "alpha_deg" if n == "alpha_deg" else n
        (nuisance if n in ("k0", "g_offset") else params)[key] = s
    return {
        "hdi_prob": hdi_prob,
        "parameters": params,
        "nuisance_parameters": nuisance,
        "map": res.map_point,
        "correlation": _correlation(res),
        "converged": not res.warnings,
        "warnings": res.warnings,
        "settings": res.settings,
    }


def _correlation(res: PosteriorResult) -> dict[str, dict[str, float]]:
    x = res.samples.reshape(-1, res.samples.shape[-1])
    c = np.corrcoef(x.T)
    return {a: {b: float(c[i, j]) for j, b in enumerate(res.names)} for i, a in enumerate(res.names)}
