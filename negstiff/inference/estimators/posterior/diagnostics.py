"""The posterior's result: summaries (arviz), convergence warnings, the contract's JSON."""

from __future__ import annotations

import json
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

    ``samples`` is ``(ensemble, step, walker, parameter)``: an ensemble is one independent emcee run (an
    arviz chain), a step one move of all its walkers, the walkers of one ensemble not independent of each
    other (each move draws on the others); the parameters in ``names`` order, sigma (not its log) last.
    In ``idata`` each ensemble is a ``chain`` and its ``draw`` runs walker by walker, each walker's
    steps in order (``chain, draw``, arviz's order): stacking steps before walkers would put the walkers'
    near-copies side by side and inflate arviz's ESS (6-36x, measured).

    Kept three ways: pickled whole (the builder of ``idata`` travels with it, so the arviz data is there
    after unpickling whether it was asked for before or not); as NetCDF (``to_netcdf``/``from_netcdf``: the
    arviz data, the draws in the order above and the run's provenance, a full round trip); and as the
    contract's JSON (``from_json``: the summary only, no draws: ``samples`` of no step).
    """

    names: tuple[str, ...]
    samples: np.ndarray  # (ensemble, step, walker, parameter) physical, sigma (not log) last, after burn-in
    summary: dict[str, dict[str, float]]
    tau: np.ndarray  # (ensembles, d) integrated autocorrelation times [steps]
    warnings: list[str]
    settings: dict[str, Any]
    map_point: dict[str, float]
    thin: int = 1
    build_idata: Callable[[], tuple[Any, np.ndarray]] | None = field(default=None, repr=False, compare=False)
    provenance: dict[str, Any] = field(default_factory=dict)
    """The record's source, the settings and the software's versions (``persistence.provenance``)."""
    correlation: dict[str, dict[str, float]] | None = field(default=None, repr=False)
    """The parameters' correlation when there are no samples (a result rebuilt from its JSON)."""
    force_band: dict[str, Any] | None = field(default=None, repr=False)
    """A law's posterior: the restoring force's credible band over the record's stroke (``core.force_band``)."""
    _built: tuple[Any, np.ndarray] | None = field(default=None, init=False, repr=False, compare=False)

    def _idata_and_loglik(self) -> tuple[Any, np.ndarray | None]:
        if self._built is None:
            if self.build_idata is None:
                return None, None
            self._built = self.build_idata()
            self.build_idata = None  # it holds the run's windows and log posterior: let them go
        return self._built

    @property
    def idata(self):
        """The arviz data of the draws (an ``xarray.DataTree``, built once, on first use; its ``attrs`` the
        run's provenance).
        """
        return self._idata_and_loglik()[0]

    @property
    def log_likelihood(self) -> np.ndarray | None:
        """Each draw's log likelihood per window (None when not kept)."""
        return self._idata_and_loglik()[1]

    def arviz_summary(self, hdi_prob: float = 0.9):
        """``arviz.summary`` of ``idata`` at negstiff's interval: the ``hdi_prob`` highest-density interval
        (arviz's own default is an 89 % equal-tailed one). Passed as arguments, not set in ``az.rcParams``,
        so the user's session keeps its own defaults.
        """
        import arviz as az

        return az.summary(self.idata, ci_prob=hdi_prob, ci_kind="hdi")

    # --- NetCDF: the arviz data with the run's draws and provenance ------------------------------------
    def to_netcdf(self, path) -> None:
        """Write the arviz data (``idata``) as NetCDF (h5netcdf), with a ``negstiff_run`` group holding the
        draws ``(ensemble, step, walker, parameter)``, the autocorrelation times, the summary, settings,
        warnings and MAP point, and the run's provenance in the root's attributes; written atomically.
        ``from_netcdf`` reads it back whole.
        """
        import xarray as xr

        from negstiff.files import atomic_path

        if self.samples.size == 0 or self.idata is None:
            raise ValueError("a posterior rebuilt from its JSON has no draws to write (its NetCDF has them)")
        tree = self.idata.copy()
        run = xr.Dataset(
            {
                "samples": (("ensemble", "step", "walker", "parameter"), np.asarray(self.samples)),
                "tau": (("ensemble", "parameter"), np.asarray(self.tau, float)),
            },
            coords={"parameter": list(self.names)},
            attrs={
                "summary_json": json.dumps(self.summary),
                "warnings_json": json.dumps(list(self.warnings)),
                "settings_json": json.dumps(self.settings, default=_plain),
                "map_json": json.dumps(self.map_point),
                "thin": int(self.thin),
                **({} if self.force_band is None else {"force_band_json": json.dumps(self.force_band)}),
            },
        )
        tree["negstiff_run"] = run
        tree.attrs.update({k: v for k, v in self.provenance.items() if isinstance(v, (str, int, float))})
        with atomic_path(path) as tmp:
            tree.to_netcdf(tmp, engine="h5netcdf")

    @classmethod
    def from_netcdf(cls, path) -> PosteriorResult:
        """The posterior ``to_netcdf`` wrote, whole (its ``idata`` the file's arviz groups)."""
        import xarray as xr

        with xr.open_datatree(path, engine="h5netcdf") as opened:
            tree = opened.load()
        run = tree["negstiff_run"].dataset
        names = tuple(str(n) for n in run.coords["parameter"].values)
        res = cls(
            names=names,
            samples=np.asarray(run["samples"].values),
            summary=json.loads(run.attrs["summary_json"]),
            tau=np.asarray(run["tau"].values),
            warnings=list(json.loads(run.attrs["warnings_json"])),
            settings=json.loads(run.attrs["settings_json"]),
            map_point=json.loads(run.attrs["map_json"]),
            thin=int(run.attrs["thin"]),
            provenance={str(k): v for k, v in tree.attrs.items()},
            force_band=json.loads(run.attrs["force_band_json"]) if "force_band_json" in run.attrs else None,
        )
        del tree["negstiff_run"]
        ll = tree["log_likelihood"].dataset["z"].values if "log_likelihood" in tree.children else None
        res._built = (tree, ll)  # type: ignore[assignment]
        return res

    @classmethod
    def from_json(cls, data) -> PosteriorResult:
        """The summary a posterior result JSON holds (``result_json``; a dict, its text or a path), without
        draws (``samples`` of no step: the draws are the NetCDF's, ``from_netcdf``).
        """
        from negstiff.inference.estimators.persistence import json_source

        d = json_source(data, "posterior result JSON")
        params = {**d.get("parameters", {}), **d.get("nuisance_parameters", {})}
        names = tuple(d.get("correlation") or params)
        return cls(
            names=names,
            samples=np.empty((0, 0, 0, len(names))),
            summary={n: dict(params[n]) for n in names if n in params},
            tau=np.empty((0, len(names))),
            warnings=[] if d.get("converged", True) else list(d.get("warnings", [])),
            settings=dict(d.get("settings", {})),
            map_point=dict(d.get("map", {})),
            correlation=d.get("correlation"),
            force_band=d.get("force_band"),
        )


def _plain(o: Any) -> Any:
    """A numpy value as a JSON number (``json.dumps``'s ``default``)."""
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    return str(o)


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


def noise_names(n_records: int) -> tuple[str, ...]:
    """The sensor noise's parameter names: ``sigma`` for one record, ``sigma_1`` .. ``sigma_R`` for a joint fit's R
    records (in the order given).
    """
    return ("sigma",) if n_records == 1 else tuple(f"sigma_{i + 1}" for i in range(n_records))


def is_noise(name: str) -> bool:
    """Whether a posterior's parameter is a record's sensor noise (``noise_names``)."""
    return name == "sigma" or (name.startswith("sigma_") and name[6:].isdigit())


def result_json(res: PosteriorResult, hdi_prob: float) -> dict[str, Any]:
    """The contract's posterior JSON (plus diagnostics; a law's posterior adds its ``force_band``)."""
    params: dict[str, dict[str, float]] = {}
    nuisance: dict[str, dict[str, float]] = {}
    for n, s in res.summary.items():
        key = "alpha_deg" if n == "alpha_deg" else n
        nuisance_name = n in ("k0", "g_offset", "z_shift") or n.startswith(("offset_", "spring_", "damper_"))
        (nuisance if nuisance_name else params)[key] = s
    return {
        "hdi_prob": hdi_prob,
        "parameters": params,
        "nuisance_parameters": nuisance,
        "map": res.map_point,
        "correlation": _correlation(res),
        "converged": not res.warnings,
        "warnings": res.warnings,
        "settings": res.settings,
        **({} if res.force_band is None else {"force_band": res.force_band}),
    }


def _correlation(res: PosteriorResult) -> dict[str, dict[str, float]]:
    if res.samples.size == 0:
        return dict(res.correlation or {})
    x = res.samples.reshape(-1, res.samples.shape[-1])
    c = np.corrcoef(x.T)
    return {a: {b: float(c[i, j]) for j, b in enumerate(res.names)} for i, a in enumerate(res.names)}
