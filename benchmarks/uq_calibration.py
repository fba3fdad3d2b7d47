"""UQ calibration study (issue 7): whether a 90 % credible interval is right 90 % of the time.

The coefficient posterior is run on N independent rig records (new excitation and sensor noise each,
the same polynomial truth); per parameter, the share of 90 % HDIs that contain the truth, and the rank
of the truth among each posterior's draws (a simulation-based-calibration rank histogram; with the
truth fixed rather than drawn from the prior, a flat histogram is the frequentist calibration under
near-flat priors). Records run as tasks on dask.distributed: a LocalCluster by default,
``--scheduler ADDRESS`` for a real cluster.

    python -m benchmarks.uq_calibration [-o reports/uq_calibration] [--records 20]
        [--duration 10] [--workers 2] [--scheduler tcp://host:8786]
"""

from __future__ import annotations

import argparse
import sys
import time
from typing import Any

import matplotlib.pyplot as plt
import numpy as np

from negstiff.errors import OutputError
from negstiff.files import check_folder
from negstiff.report.document import Report
from negstiff.report.numbers import fmt

PARAMS = ("k1", "k2", "k3", "c", "c_nl")
RANK_DRAWS = 99
"""Posterior draws per record for the rank statistic (ranks 0..99, ten bins of ten)."""


def one_record(seed: int, duration: float, max_steps: int, n_ensembles: int) -> dict[str, Any]:
    """A rig record with seed ``seed`` and its coefficient posterior: HDIs, ranks, diagnostics.
    Runs in a dask worker (one numba thread: the workers are the parallelism).
    """
    from negstiff.inference.estimators.posterior import Posterior, result_json
    from negstiff.inference.record.measurement import from_arrays
    from negstiff.models import SEED_LIKE_CROSS_WELL_RMS, SEED_LIKE_CUBIC
    from negstiff.models.rig import Rig

    truth = SEED_LIKE_CUBIC
    r = Rig(truth, seed=seed).random(duration=duration, rms=SEED_LIKE_CROSS_WELL_RMS)
    rec = from_arrays(r.columns["base_acc"], r.columns["z"], r.fs, mass=float(r.meta["mass"]), source=f"seed {seed}")
    t0 = time.perf_counter()
    pr = Posterior(seed=seed, max_steps=max_steps, n_ensembles=n_ensembles, threads=1).fit(rec).result_
    j = result_json(pr, 0.9)
    flat = pr.samples.reshape(-1, pr.samples.shape[-1])
    pick = np.random.default_rng(seed).choice(flat.shape[0], RANK_DRAWS, replace=False)
    ranks = {n: int(np.sum(flat[pick, pr.names.index(n)] < getattr(truth, n))) for n in PARAMS}
    covered = {
        n: bool(j["parameters"][n]["hdi_low"] <= getattr(truth, n) <= j["parameters"][n]["hdi_high"]) for n in PARAMS
    }
    return {
        "seed": seed,
        "covered": covered,
        "z": {n: (j["parameters"][n]["mean"] - getattr(truth, n)) / j["parameters"][n]["sd"] for n in PARAMS},
        "variance_inflation": j["settings"]["variance_inflation"],
        "windows_dropped": len(j["settings"]["windows_dropped"]),
        "ranks": ranks,
        "parameters": j["parameters"],
        "warnings": j["warnings"],
        "elapsed_s": time.perf_counter() - t0,
    }


def run(records: int, duration: float, max_steps: int, n_ensembles: int, workers: int, scheduler: str | None):
    from dask.distributed import Client, LocalCluster

    cluster = None
    if scheduler:
        client = Client(scheduler)
    else:
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None)
        client = Client(cluster)
    try:
        futures = [
            client.submit(one_record, 1000 + i, duration, max_steps, n_ensembles, pure=False) for i in range(records)
        ]
        out = client.gather(futures)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    return sorted(out, key=lambda r: r["seed"])


def summarise(rows: list[dict[str, Any]]) -> dict[str, Any]:
    cov = {n: float(np.mean([r["covered"][n] for r in rows])) for n in PARAMS}
    ranks = {n: [r["ranks"][n] for r in rows] for n in PARAMS}
    return {
        "records": len(rows),
        "coverage_90": cov,
        "ranks": ranks,
        "rms_z": {n: float(np.sqrt(np.mean([r["z"][n] ** 2 for r in rows]))) for n in PARAMS},
        "mean_z": {n: float(np.mean([r["z"][n] for r in rows])) for n in PARAMS},
        "largest_inflation_median": float(np.median([r["variance_inflation"][0] for r in rows])),
        "windows_dropped": int(sum(r["windows_dropped"] for r in rows)),
        "unconverged_records": [r["seed"] for r in rows if r["warnings"]],
        "mean_elapsed_s": float(np.mean([r["elapsed_s"] for r in rows])),
    }


def report(rep: Report, results: dict[str, Any], rows: list[dict[str, Any]], settings: dict[str, Any]) -> None:
    s = summarise(rows)
    results["uq_calibration"] = {"summary": s, "records": rows, "settings": settings}
    n = s["records"]
    rep.heading("UQ calibration: coverage of the 90 % credible intervals")
    # the binomial sd of a coverage share at 0.9 over n records
    sd = np.sqrt(0.9 * 0.1 / n)
    rep.text(
        f"{n} independent {settings['duration']:g} s cross-well rig records (polynomial truth, default sensor noise, "
        f"new excitation and noise each), one coefficient posterior each ({settings['ensembles']} ensembles), run as "
        f"dask tasks ({settings['where']}). A calibrated 90 % interval holds the truth in 90 % of the records, "
        f"+- {fmt(100 * sd, 2)} % (binomial sd over {n} records)."
    )
    rep.table(
        ["parameter", "coverage of the 90 % HDI", "rms (mean - truth) / sd", "mean (mean - truth) / sd", "records"],
        [[p, s["coverage_90"][p], fmt(s["rms_z"][p], 3), fmt(s["mean_z"][p], 2), n] for p in PARAMS],
    )
    inside = [p for p in PARAMS if 0.75 <= s["coverage_90"][p] <= 0.98]
    rep.text(
        f"The rms of the truth's z-score is the sharper measure: 1 for a calibrated posterior, +- "
        f"{fmt(1 / np.sqrt(2 * n), 2)} (sd over {n} records); above 1 the intervals are too narrow. "
        f"{len(inside)} of {len(PARAMS)} coverages lie in the accepted band 0.75-0.98"
        + ("." if len(inside) == len(PARAMS) else f" (outside: {', '.join(p for p in PARAMS if p not in inside)}).")
        + f" Each posterior's likelihood is curvature-adjusted by its windows' sandwich covariance (the i.i.d. noise "
        f"model ignores the accelerometer's noise in the input and in z); the largest variance inflation it applied "
        f"has median {fmt(s['largest_inflation_median'], 3)} over the records. Windows dropped (not matched from any "
        f"nearby start state): {s['windows_dropped']} in all."
    )
    if s["unconverged_records"]:
        rep.warning(f"records whose posterior did not converge: {s['unconverged_records']}")
    fig, axes = plt.subplots(1, len(PARAMS), figsize=(12, 2.6), sharey=True)
    for ax, p in zip(axes, PARAMS, strict=False):
        ax.hist(s["ranks"][p], bins=np.linspace(0, RANK_DRAWS + 1, 11), color="C0", edgecolor="k")
        ax.axhline(n / 10, color="r", lw=1)
        ax.set(title=p, xlabel="rank of the truth")
    axes[0].set_ylabel("records")
    rep.figure(
        "uq_rank_histograms",
        fig,
        f"Rank of the truth among {RANK_DRAWS} posterior draws per record (red: the flat histogram of a calibrated "
        "posterior).",
    )


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("-o", "--out", default="reports/uq_calibration")
    ap.add_argument("--records", type=int, default=20)
    ap.add_argument("--duration", type=float, default=10.0, help="record length [s]")
    ap.add_argument("--max-steps", type=int, default=4000)
    ap.add_argument("--ensembles", type=int, default=4)
    ap.add_argument("--workers", type=int, default=2, help="LocalCluster worker processes")
    ap.add_argument("--scheduler", help="address of a running dask scheduler (default: a LocalCluster)")
    a = ap.parse_args(argv)
    try:
        check_folder(a.out, "--out")  # before the study: a folder holding a user's file is refused
    except OutputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    t0 = time.perf_counter()
    rows = run(a.records, a.duration, a.max_steps, a.ensembles, a.workers, a.scheduler)
    settings = {
        "duration": a.duration,
        "ensembles": a.ensembles,
        "max_steps": a.max_steps,
        "where": a.scheduler or f"LocalCluster, {a.workers} workers",
        "elapsed_s": time.perf_counter() - t0,
    }
    rep = Report("negstiff: calibration of the Bayesian uncertainty")
    results: dict[str, Any] = {}
    report(rep, results, rows, settings)
    rep.text(f"Run time: {settings['elapsed_s']:.0f} s.")
    rep.write(a.out, results)
    print(f"wrote {a.out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
