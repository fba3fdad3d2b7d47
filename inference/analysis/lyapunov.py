"""Largest Lyapunov exponent from a measured time series.

* Embedding (``shared/docs/algorithms.md`` B.1): delay tau at the first minimum of the average mutual
  information (Fraser & Swinney 1986), at most a quarter forcing period for a forced oscillator,
  dimension m where the fraction of false nearest neighbours (Kennel, Brown & Abarbanel 1992) falls
  below 2 %.
* Wolf, Swift, Swinney & Vastano (1985, Physica D 16:285), fixed evolution time: follow the nearest
  neighbour of the fiducial trajectory for ``evolv`` samples, accumulate ln(L'/L), and when the pair has
  separated beyond SCALMX replace the neighbour by the candidate (SCALMN < d < SCALMX, outside a
  Theiler window) whose separation vector turns least from the evolved one, relaxing the angle when
  none qualifies. Reported in 1/s (natural log; Wolf's bits/s = this / ln 2).
* Rosenstein, Collins & De Luca (1993) through ``nolds.lyap_r``, as the cross-check.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy.spatial import cKDTree


def embed(x: np.ndarray, m: int, tau: int) -> np.ndarray:
    """Delay vectors [x_k, x_(k+tau), ..., x_(k+(m-1)tau)], shape (N - (m-1) tau, m)."""
    n = x.size - (m - 1) * tau
    if n < 10:
        raise ValueError(f"series too short for embedding m = {m}, tau = {tau}")
    return np.stack([x[i * tau : i * tau + n] for i in range(m)], axis=1)


def mutual_information_delay(x: np.ndarray, max_lag: int, bins: int = 32) -> int:
    """First minimum of the average mutual information I(x_k; x_(k+lag)) (Fraser & Swinney 1986)."""
    edges = np.quantile(x, np.linspace(0, 1, bins + 1))
    xi = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, bins - 1)
    ami = []
    for lag in range(1, max_lag + 1):
        joint = np.zeros((bins, bins))
        np.add.at(joint, (xi[:-lag], xi[lag:]), 1)
        pxy = joint / joint.sum()
        px, py = pxy.sum(1), pxy.sum(0)
        nz = pxy > 0
        ami.append(float(np.sum(pxy[nz] * np.log(pxy[nz] / np.outer(px, py)[nz]))))
        if len(ami) >= 3 and ami[-2] < ami[-3] and ami[-2] <= ami[-1]:
            return lag - 1
    return int(np.argmin(ami)) + 1


def false_nearest_neighbours(
    x: np.ndarray,
    tau: int,
    max_dim: int = 8,
    rtol: float = 15.0,
    atol: float = 2.0,
    threshold: float = 0.02,
    max_points: int = 20000,
) -> tuple[int, list[float]]:
    """Embedding dimension by false nearest neighbours (Kennel et al. 1992)."""
    step = max(1, x.size // max_points)
    sd = x.std()
    fractions = []
    for m in range(1, max_dim + 1):
        Y = embed(x, m + 1, tau)[::step]
        Ym = Y[:, :m]
        d, idx = cKDTree(Ym).query(Ym, k=2)
        d, j = d[:, 1], idx[:, 1]
        extra = np.abs(Y[:, m] - Y[j, m])
        ok = d > 0
        false = (extra[ok] / d[ok] > rtol) | (np.sqrt(d[ok] ** 2 + extra[ok] ** 2) / sd > atol)
        fractions.append(float(false.mean()))
        if fractions[-1] < threshold:
            return m, fractions
    return max_dim, fractions


def wolf(
    x: np.ndarray,
    dt: float,
    m: int,
    tau: int,
    evolv: int,
    theiler: int | None = None,
    scalmx: float | None = None,
    scalmn: float | None = None,
    anglmx: float = 0.3,
) -> dict[str, Any]:
    """Wolf et al. (1985) fixed-evolution-time estimate of the largest Lyapunov exponent [1/s].

    ``scalmx`` defaults to 10 % of the attractor's extent (the embedded vectors' rms radius),
    ``scalmn`` to 0.1 % of it (set it to the noise level for measured data), ``theiler`` to ``evolv``.
    """
    Y = embed(np.asarray(x, float), m, tau)
    n = Y.shape[0]
    extent = float(np.sqrt(np.mean(np.sum((Y - Y.mean(0)) ** 2, axis=1))))
    scalmx = 0.1 * extent if scalmx is None else scalmx
    scalmn = 1e-3 * extent if scalmn is None else scalmn
    theiler = evolv if theiler is None else theiler
    tree = cKDTree(Y)

    def neighbour(i: int, ref_vec: np.ndarray | None) -> int | None:
        for radius, angle in ((scalmx, anglmx), (scalmx, 2 * anglmx), (2 * scalmx, 2 * anglmx), (4 * scalmx, np.pi)):
            cand = np.array(tree.query_ball_point(Y[i], radius), dtype=int)
            if cand.size == 0:
                continue
            cand = cand[(np.abs(cand - i) > theiler) & (cand + evolv < n)]
            if cand.size == 0:
                continue
            sep = Y[cand] - Y[i]
            dist = np.linalg.norm(sep, axis=1)
            keep = dist > scalmn
            cand, sep, dist = cand[keep], sep[keep], dist[keep]
            if cand.size == 0:
                continue
            if ref_vec is None:
                return int(cand[np.argmin(dist)])
            cosang = sep @ ref_vec / (dist * np.linalg.norm(ref_vec) + 1e-300)
            ang = np.arccos(np.clip(cosang, -1, 1))
            ok = ang < angle
            if ok.any():
                c, a, d_ = cand[ok], ang[ok], dist[ok]
                return int(c[np.argmin(a + d_ / radius)])  # small angle first, then short distance
        return None

    i = 0
    j = neighbour(i, None)
    if j is None:
        raise ValueError("no initial neighbour found (series too short or too noisy)")
    total, time_, running, t_run = 0.0, 0.0, [], []
    while i + evolv < n and j + evolv < n:
        d0 = np.linalg.norm(Y[j] - Y[i])
        i2, j2 = i + evolv, j + evolv
        d1 = np.linalg.norm(Y[j2] - Y[i2])
        if d0 > 0 and d1 > 0:
            total += math.log(d1 / d0)
            time_ += evolv * dt
            running.append(total / time_)
            t_run.append(time_)
        i = i2
        if d1 > scalmx or d1 <= scalmn:
            jn = neighbour(i, Y[j2] - Y[i2])
            if jn is None:
                break
            j = jn
        else:
            j = j2
    if time_ == 0:
        raise ValueError("the Wolf iteration made no step")
    return {
        "value": total / time_,
        "t": np.array(t_run),
        "running": np.array(running),
        "units": "1/s",
        "method": "wolf",
        "m": m,
        "tau": tau,
        "evolv": evolv,
        "scalmx": scalmx,
        "scalmn": scalmn,
    }


ROSENSTEIN_MAX_POINTS = 4000
"""nolds.lyap_r builds the full N x N distance matrix (27 GB at N = 58 000): it sees at most this many
contiguous samples (128 MB)."""


def rosenstein(x: np.ndarray, dt: float, m: int, tau: int, theiler: int, trajectory_len: int = 20) -> float:
    """Rosenstein et al. (1993) via nolds.lyap_r [1/s] (slope of the mean log divergence, polyfit),
    on the first ``ROSENSTEIN_MAX_POINTS`` samples."""
    import nolds

    x = np.asarray(x, float)[:ROSENSTEIN_MAX_POINTS]
    return float(
        nolds.lyap_r(x, emb_dim=m, lag=tau, min_tsep=theiler, tau=dt, trajectory_len=trajectory_len, fit="poly")
    )


def largest_lyapunov(
    x: np.ndarray, dt: float, *, forcing_hz: float | None = None, noise: float | None = None, max_points: int = 40000
) -> dict[str, Any]:
    """Embedding from the data, Wolf's estimate and Rosenstein's cross-check, both in 1/s.

    For a forced oscillator the evolution time is a quarter forcing period and the Theiler window one
    forcing period; otherwise both are the embedding delay times m.
    """
    x = np.asarray(x, float)
    step = max(1, x.size // max_points)
    xs, dts = x[::step], dt * step
    max_lag = int(round(1.0 / forcing_hz / dts)) if forcing_hz else max(10, xs.size // 100)
    tau = mutual_information_delay(xs, max_lag)
    if forcing_hz:
        # cap at a quarter forcing period (algorithms.md B.1): on six chaotic 9 Hz rig records the
        # mutual-information minimum fell near a whole period (46-50 samples) and Wolf erred -19..+41 %
        # against the variational truth; at T/4 (14 samples) -7..+9 %
        tau = min(tau, max(1, int(round(0.25 / forcing_hz / dts))))
    m, fnn = false_nearest_neighbours(xs, tau)
    m = max(m, 3)
    if forcing_hz:
        evolv = max(1, int(round(0.25 / forcing_hz / dts)))
        theiler = max(evolv, int(round(1.0 / forcing_hz / dts)))
    else:
        evolv = max(1, tau)
        theiler = m * tau
    extent = xs.std() * math.sqrt(m)
    scalmn = max(1e-3 * extent, 3 * noise * math.sqrt(m)) if noise else None
    w = wolf(xs, dts, m, tau, evolv, theiler=theiler, scalmn=scalmn)
    try:
        rs = rosenstein(xs, dts, m, tau, theiler, trajectory_len=max(20, theiler))
    except Exception as exc:  # nolds refuses some short series; the cross-check is then missing, said so
        rs = float("nan")
        w["rosenstein_error"] = str(exc).splitlines()[0]
    w.update(rosenstein=rs, fnn_fractions=fnn, sample_step=step)
    return w
