"""A study over many records: every estimator fitted on every record, serially or as dask tasks, the
fitted estimators returned, and (with the records' truths) how often each posterior's credible interval
holds the truth.

Each (estimator, record) pair is one task: a fresh copy of the estimator (its parameters, unfitted) fitted
on the record, returned whole (fitted estimators pickle: ``persistence``), so the caller keeps, compares
and saves them. On a dask cluster (``scheduler``: a ``distributed.Client``, a scheduler's address, or
``"local"`` for a ``LocalCluster`` of ``workers`` processes) the tasks run where the workers are; dask is the
optional extra ``negstiff[dask]``, imported only then. Per-record failures (a record a method refuses) are
kept as text beside the fits, never lost in a worker's log.

Coverage (truths given): for each posterior and parameter, the share of records whose credible interval
(``hdi_prob``, negstiff's 90 % highest-density interval) holds the truth, with its binomial standard error:
a calibrated posterior's share is ``hdi_prob`` within about two standard errors.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from negstiff.errors import InputError, MeasurementError


def fresh(estimator):
    """An unfitted copy of ``estimator`` with the same parameters (scikit-learn's ``clone``)."""
    return type(estimator)(**estimator.get_params(deep=False))


def fit_one(estimator, record) -> tuple[Any, str | None]:
    """``estimator``'s fresh copy fitted on ``record``: (the fitted estimator, None), or (None, the reason) when
    the record is refused (a ``MeasurementError``/``InputError``: that record's failure, not the study's).
    """
    import warnings

    est = fresh(estimator)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # each fit keeps its warnings in its result
            return est.fit(record), None
    except (MeasurementError, InputError) as exc:
        return None, f"{type(exc).__name__}: {exc}"


@dataclass
class ManyFits:
    """What ``fit_many`` returns.

    Attributes
    ----------
    names : list of str
        The estimators' names (the keys of ``fits``).
    fits : dict
        ``{name: [fitted estimator or None, ...]}``, one per record, in the records' order.
    errors : dict
        ``{name: [None or the reason the record was refused, ...]}``.
    coverage : dict
        With truths: ``{name: {PARAMETER: {"hits", "records", "share", "share_se", "hdi_prob"}}}`` for each
        posterior (an estimator whose result has ``parameters`` with ``hdi_low``/``hdi_high``).
    """

    names: list[str]
    fits: dict[str, list[Any]]
    errors: dict[str, list[str | None]]
    coverage: dict[str, dict[str, dict[str, float]]] = field(default_factory=dict)

    def results(self) -> dict[str, list[dict[str, Any] | None]]:
        """Each fit's ``result()`` (None where the record was refused)."""
        return {n: [None if e is None else e.result() for e in fits] for n, fits in self.fits.items()}


def _client(scheduler, workers: int):
    """A dask ``Client`` for ``scheduler`` (a Client, an address, or "local"), and whether it was made here."""
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise InputError("fit_many on a dask cluster needs dask's distributed: pip install 'negstiff[dask]'") from None
    if isinstance(scheduler, Client):
        return scheduler, False
    if scheduler == "local":
        return Client(LocalCluster(n_workers=workers, threads_per_worker=1, processes=True)), True
    return Client(scheduler), True


def fit_many(
    estimators: Mapping[str, Any] | Sequence[Any],
    records: Sequence[Any],
    *,
    truths: Sequence[Mapping[str, float]] | None = None,
    scheduler: Any = None,
    workers: int = 2,
) -> ManyFits:
    """Fit every estimator on every record (module docstring).

    Parameters
    ----------
    estimators : dict or sequence of Estimator
        Configured (unfitted) estimators, by name (a sequence: named by class, ``NSI``, ``SINDy``, ...).
        Each record gets a fresh copy.
    records : sequence of Measurement or path
        The records (a path is read where the task runs: on a cluster, a path every worker can read).
    truths : sequence of dict, optional
        Each record's true parameter values (``{"k3": ..., "c": ...}``): the posteriors' coverage.
    scheduler : None, "local", str or distributed.Client
        None: serial, in this process. "local": a dask ``LocalCluster`` of ``workers`` processes (closed
        after). An address (``"tcp://host:8786"``) or a ``Client``: that cluster.
    workers : int, default 2
        The local cluster's worker processes.

    Returns
    -------
    ManyFits
        The fitted estimators, the refused records' reasons, and the coverage.

    Examples
    --------
    >>> from negstiff import NSI, Measurement, Rig, fit_many
    >>> from negstiff.models import SEED_LIKE_CUBIC
    >>> recs = [Measurement.from_rig(Rig(SEED_LIKE_CUBIC, seed=s).random(duration=30.0, rms=20.0)) for s in (1, 2)]
    >>> many = fit_many({"nsi": NSI(refine=False)}, recs)      # serially, here; scheduler="local": on dask
    >>> [fit.modal_["plus"]["f_hz"] > 0 for fit in many.fits["nsi"]], many.errors["nsi"]
    ([True, True], [None, None])
    """
    named = dict(estimators) if isinstance(estimators, Mapping) else {type(e).__name__: e for e in estimators}
    if not named or not records:
        raise InputError("fit_many needs at least one estimator and one record")
    if len(named) != (len(estimators) if not isinstance(estimators, Mapping) else len(named)):
        raise InputError("fit_many: two estimators of one class need names (pass a dict)")
    if truths is not None and len(truths) != len(records):
        raise InputError(f"fit_many: {len(truths)} truths for {len(records)} records")
    if not (isinstance(workers, int) and workers >= 1):
        raise InputError(f"fit_many(workers={workers!r}): one worker at least")
    pairs = [(n, i) for n in named for i in range(len(records))]
    if scheduler is None:
        done = [fit_one(named[n], records[i]) for n, i in pairs]
    else:
        client, own = _client(scheduler, workers)
        try:
            futures = [client.submit(fit_one, named[n], records[i], pure=False) for n, i in pairs]
            done = client.gather(futures)
        finally:
            if own:
                cluster = getattr(client, "cluster", None)
                client.close()
                if cluster is not None:
                    cluster.close()
    out = ManyFits(list(named), {n: [None] * len(records) for n in named}, {n: [None] * len(records) for n in named})
    for (n, i), (est, err) in zip(pairs, done, strict=True):
        out.fits[n][i], out.errors[n][i] = est, err
    if truths is not None:
        out.coverage = coverage(out, truths)
    return out


def coverage(fits: ManyFits, truths: Sequence[Mapping[str, float]]) -> dict[str, dict[str, dict[str, float]]]:
    """For each posterior among ``fits`` and each parameter with a truth: how many of its credible intervals
    hold the truth, their share and its binomial standard error sqrt(p (1 - p) / n) at p = ``hdi_prob``.
    """
    out: dict[str, dict[str, dict[str, float]]] = {}
    for name, ests in fits.fits.items():
        per: dict[str, list[bool]] = {}
        prob = None
        for est, truth in zip(ests, truths, strict=True):
            if est is None:
                continue
            res = est.result()
            params = res.get("parameters")
            if not isinstance(params, Mapping) or "hdi_prob" not in res:
                break  # not a posterior
            prob = float(res["hdi_prob"])
            for p, value in truth.items():
                s = params.get(p)
                if s is not None:
                    per.setdefault(p, []).append(bool(s["hdi_low"] <= value <= s["hdi_high"]))
        if per and prob is not None:
            out[name] = {
                p: {
                    "hits": sum(h),
                    "records": len(h),
                    "share": sum(h) / len(h),
                    "hdi_prob": prob,
                    "share_se": math.sqrt(prob * (1 - prob) / len(h)),
                }  # fmt: skip
                for p, h in per.items()
            }
    return out
