"""Independent emcee ensembles run until the autocorrelation rule holds (emcee docs)."""

from __future__ import annotations

import math
import threading
import warnings
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np

from negstiff.inference.estimators.posterior.windows import PosteriorError
from negstiff.models.simulator import cores


def sample_ensembles(
    log_prob,
    nd: int,
    *,
    n_walkers: int,
    n_ensembles: int,
    seed: int,
    tau_multiple: float = 50.0,
    min_steps: int = 500,
    max_steps: int = 6000,
    chunk: int = 250,
    progress: bool = False,
    p0_scale: float = 1.0,
    workers: int | None = None,
) -> dict[str, Any]:
    """Independent emcee ensembles (DE 80 % / snooker 20 %) of a vectorised ``log_prob`` over scaled
    coordinates (walkers start from N(0, p0_scale^2)). Each runs in chunks until its kept steps (after a
    burn-in of 2 tau, at least one chunk) reach ``tau_multiple`` x the largest autocorrelation time, or
    ``max_steps``; a run that stops short is reported in ``warnings``. Seeds: the walkers' start from
    ``seed + e``, the moves from ``seed + 1000 + e``: the same seed gives the same chains, whatever
    ``workers`` (threads running ensembles at once; None: one per core).
    """
    import emcee

    pbar = _progress_bar(progress, n_ensembles * max_steps)
    lock = threading.Lock()  # the progress bar and the warnings filters are shared by the threads

    def run(e: int):
        # each ensemble its own moves: emcee's DEMove keeps per-run state (g0) set up at every step
        moves = [(emcee.moves.DEMove(), 0.8), (emcee.moves.DESnookerMove(), 0.2)]
        rs = np.random.RandomState(seed + e)
        p0 = p0_scale * rs.standard_normal((n_walkers, nd))
        # every walker must start where the posterior is positive (emcee's moves compare log probabilities)
        for _ in range(50):
            bad = ~np.isfinite(np.array([lp for lp, _ in log_prob(p0)]))
            if not bad.any():
                break
            p0[bad] = 0.5 * p0_scale * rs.standard_normal((int(bad.sum()), nd))
        else:
            raise PosteriorError("no start point of positive posterior density near the MAP point")
        sampler = emcee.EnsembleSampler(n_walkers, nd, log_prob, vectorize=True, moves=moves)
        sampler.random_state = np.random.RandomState(seed + 1000 + e).get_state()
        state, steps, tau, burn = p0, 0, np.full(nd, np.inf), 0
        while steps < max_steps:
            with np.errstate(invalid="ignore", divide="ignore"):
                state = sampler.run_mcmc(state, min(chunk, max_steps - steps), progress=False)
            done, steps = steps, sampler.iteration
            # catch_warnings saves and restores the process's filters: one thread at a time
            with lock, np.errstate(invalid="ignore", divide="ignore"), warnings.catch_warnings():
                warnings.simplefilter("ignore")
                tau = sampler.get_autocorr_time(tol=0, quiet=True)
                if pbar is not None:
                    pbar.update(steps - done)
            t_max = float(np.max(tau)) if np.all(np.isfinite(tau)) else math.inf
            burn = int(min(steps // 2, max(2 * t_max, chunk)))
            if steps >= min_steps and steps - burn >= tau_multiple * t_max:
                break
        warn = []
        if not steps - burn >= tau_multiple * t_max:
            warn.append(
                f"ensemble {e}: not converged after {steps} steps: {steps - burn} kept steps < "
                f"{tau_multiple:g} x tau = {tau_multiple * t_max:.0f} (emcee's rule); the numbers are not reliable"
            )
        acc = float(np.mean(sampler.acceptance_fraction))
        if acc < 0.05:
            warn.append(f"ensemble {e}: acceptance fraction {acc:.3f} (stuck walkers)")
        return sampler.get_chain(discard=burn), sampler.get_blobs(discard=burn), tau, warn

    # The ensembles are independent (own seeds, own sampler): they run on the machine's cores at once,
    # each in a thread (the compiled simulator releases the GIL; a step's batch is too small to split
    # further). Results are gathered in ensemble order, so the numbers are those of a serial run.
    workers = max(1, min(n_ensembles, cores())) if workers is None else max(1, int(workers))
    try:
        if workers == 1:
            runs = [run(e) for e in range(n_ensembles)]
        else:
            with ThreadPoolExecutor(max_workers=workers) as pool:
                runs = list(pool.map(run, range(n_ensembles)))
    finally:
        if pbar is not None:
            pbar.close()
    return {
        "chains": [r[0] for r in runs],
        "tau": [r[2] for r in runs],
        "warnings": [w for r in runs for w in r[3]],
        "blobs": [r[1] for r in runs],
    }


def _progress_bar(on: bool, total: int):
    if not on:
        return None
    from tqdm import tqdm

    return tqdm(total=total, desc="emcee steps", unit="step", leave=False)
