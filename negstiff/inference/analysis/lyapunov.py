"""Largest Lyapunov exponent from a measured time series.

* Embedding (``docs/algorithms.md`` B.1): delay tau at the first minimum of the average mutual
  information (Fraser & Swinney 1986), at most a quarter forcing period for a forced oscillator,
  dimension m where the fraction of false nearest neighbours (Kennel, Brown & Abarbanel 1992) falls
  below 2 %.
* Wolf, Swift, Swinney & Vastano (1985, Physica D 16:285), fixed evolution time: follow the nearest
  neighbour of the fiducial trajectory for ``evolv`` samples, accumulate ln(L'/L), and when the pair has
  separated beyond SCALMX replace the neighbour by the candidate (SCALMN < d < SCALMX, outside a
  Theiler window) whose separation vector turns least from the evolved one, relaxing the angle when
  none qualifies. Reported in 1/s (natural log; Wolf's bits/s = this / ln 2).
  Wolf's estimate from one fiducial trajectory carries the noise of its neighbour replacements (on
  500 s of the Lorenz system's x, single trajectories started 1 s apart spread 3-6 %): the value is the
  pooled estimate of ``WOLF_FIDUCIALS`` fiducial trajectories started at different points of the first
  Theiler window (total log stretch over total time), and their spread is reported.
* Rosenstein, Collins & De Luca (1993), written here rather than taken from ``nolds.lyap_r``: nolds
  builds the full N x N distance matrix (20 GB at the 50 000 samples of a 100 s record at 512 Hz) and
  fits its slope over a fixed number of steps; here each point's nearest neighbour outside the Theiler
  window comes from a k-d tree (O(N log N), memory O(N)), the mean log divergence y(k) is followed until
  it saturates, and the slope is fitted where y has risen between ``ROSENSTEIN_FIT`` fractions of the way
  from its start to its saturation level (``ROSENSTEIN_FIT_*``): past the initial alignment with the
  unstable direction, before the separation reaches the attractor's size.
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
    start: int = 0,
) -> dict[str, Any]:
    """Wolf et al. (1985) fixed-evolution-time estimate of the largest Lyapunov exponent [1/s], one
    fiducial trajectory from sample ``start``.

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

    i = start
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
        "stretch": total,
        "time": time_,
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


WOLF_SCALMX_FORCED = 0.1
"""Wolf's replacement threshold for a forced oscillator, a fraction of the embedded vectors' rms radius
(evolution a quarter forcing period): on three chaotic 9 Hz rig records, -6 to -0.5 % of the
variational exponent (-6 to -4 % at 0.3)."""

WOLF_SCALMX_AUTONOMOUS = 0.3
"""... and for an autonomous system (evolution half the embedding delay): each replacement's residual
misalignment biases the estimate upward, and a larger threshold replaces less often. On 500 s of the
Lorenz system's x from five initial states: mean +1 %, at most 4.8 % off 0.906 1/s (at 0.1 and a whole
delay: mean +5 %, up to 9 %)."""

WOLF_FIDUCIALS = 8
"""Fiducial trajectories pooled in a Wolf estimate (started evenly over the first Theiler window)."""


def wolf_pooled(x: np.ndarray, dt: float, m: int, tau: int, evolv: int, theiler: int, fiducials: int = WOLF_FIDUCIALS,
                **kw) -> dict[str, Any]:  # fmt: skip
    """Wolf's estimate pooled over ``fiducials`` trajectories: total log stretch / total evolution time;
    ``spread`` is the standard deviation of the single trajectories' estimates (their neighbour choices
    differ, the data are the same: it measures the algorithm's noise, not the record's).
    """
    n = np.asarray(x).size - (m - 1) * tau
    starts = sorted({int(s) for s in np.linspace(0, min(theiler, max(0, n - 2 * evolv - 1)), fiducials)})
    runs = []
    for s0 in starts:
        try:
            runs.append(wolf(x, dt, m, tau, evolv, theiler=theiler, start=s0, **kw))
        except ValueError:
            continue
    if not runs:
        raise ValueError("no initial neighbour found (series too short or too noisy)")
    first = runs[0]
    total, time_ = sum(r["stretch"] for r in runs), sum(r["time"] for r in runs)
    singles = [r["value"] for r in runs]
    return first | {
        "value": total / time_,
        "fiducials": len(runs),
        "spread": float(np.std(singles, ddof=1)) if len(runs) > 1 else float("nan"),
    }


ROSENSTEIN_FIT_AUTONOMOUS = (0.1, 0.7)
"""The slope is fitted where the mean log divergence has risen between these fractions of the way from
its start to its saturation level. Measured against known exponents: on 500 s of the Lorenz system's x
from five initial states, -3.8 to +3.9 % of 0.906 1/s (mean -0.1 %); a window ending at half the rise
gave +7 % on average (up to +13 %), one from 20 to 70 % -3.8 % (down to -6.9 %)."""

ROSENSTEIN_FIT_FORCED = (0.1, 0.5)
"""... and for a forced oscillator, whose divergence curve bends from its start (the separation spreads
over the forcing cycle's phases of stretching and folding: no straight part): on three chaotic 9 Hz rig
records, -5.5 to -2.8 % of the variational (Benettin) exponent; ending at 70 % of the rise, -23 to -18 %."""


def rosenstein(
    x: np.ndarray,
    dt: float,
    m: int,
    tau: int,
    theiler: int,
    horizon: int,
    fit: tuple = ROSENSTEIN_FIT_AUTONOMOUS,
    min_span: int = 3,
) -> dict[str, Any]:
    """Rosenstein et al. (1993) [1/s]: the slope of the mean log distance between each delay vector's
    nearest neighbour (outside ``theiler`` samples) and it, followed ``horizon`` samples ahead.

    Returns ``value``, the divergence curve (``t``, ``divergence``) and the fitted window (``fit_t``).
    Raises ``ValueError`` when the separation does not grow beyond a tenth of the orbit's size (a
    periodic orbit within the noise), when the window to fit spans fewer than ``min_span`` samples, or
    for a series too short.
    """
    Y = embed(np.asarray(x, float), m, tau)
    n = Y.shape[0] - horizon
    if n < 10 * (theiler + 1):
        raise ValueError(f"series too short for Rosenstein's estimate: {Y.shape[0]} vectors, horizon {horizon}")
    tree = cKDTree(Y[:n])
    nn = np.full(n, -1)
    todo, k = np.arange(n), 8
    while todo.size and k <= 4096:  # widen the query until a neighbour outside the Theiler window turns up
        d, idx = tree.query(Y[todo], k=min(k, n))
        ok = (np.abs(idx - todo[:, None]) > theiler) & (d > 0)
        has = ok.any(axis=1)
        nn[todo[has]] = idx[has, np.argmax(ok[has], axis=1)]
        todo, k = todo[~has], 4 * k
    i = np.flatnonzero(nn >= 0)
    j = nn[i]
    if i.size < 10:
        raise ValueError("no nearest neighbours outside the Theiler window (series too short)")
    y = np.empty(horizon + 1)
    for kk in range(horizon + 1):
        dist = np.linalg.norm(Y[i + kk] - Y[j + kk], axis=1)
        y[kk] = np.mean(np.log(dist[dist > 0]))
    t = np.arange(horizon + 1) * dt
    sat = float(np.mean(y[-max(2, horizon // 4) :]))
    rise = sat - y[0]
    size = float(np.sqrt(np.mean(np.sum((Y - Y.mean(0)) ** 2, axis=1))))
    if not rise > 0.5 or math.exp(sat) < 0.1 * size:
        # a periodic orbit: neighbours chosen closest within the noise drift apart to the noise's typical
        # distance within a few samples and stay there, far below the orbit's size
        raise ValueError(
            f"the neighbours' separation saturates at {100 * math.exp(sat) / size:.2g} % of the orbit's size "
            f"(rising {rise:.2g} nats): no divergence beyond the noise to follow"
        )
    lo, hi = (y[0] + f * rise for f in fit)
    a = int(np.argmax(y > lo))
    b = int(np.argmax(y > hi))
    if b - a < max(3, min_span):
        raise ValueError(
            f"the divergence curve rises within {b - a} samples: too fast for a slope (at least {max(3, min_span)})"
        )
    slope = float(np.polyfit(t[a:b], y[a:b], 1)[0])
    return {"value": slope, "t": t, "divergence": y, "fit_t": [float(t[a]), float(t[b])], "pairs": int(i.size)}


def largest_lyapunov(
    x: np.ndarray,
    dt: float,
    *,
    forcing_hz: float | None = None,
    noise: float | None = None,
    max_points: int = 40000,
    segments: int = 1,
) -> dict[str, Any]:
    """Embedding from the data, Wolf's estimate (pooled over ``WOLF_FIDUCIALS`` trajectories) and
    Rosenstein's cross-check, both in 1/s (``rosenstein`` None with ``rosenstein_error`` saying why when
    it cannot be made).

    With ``segments`` > 1, Wolf's estimate is also made on that many consecutive parts of the series
    with the whole series' embedding (``segments``: their values; parts too short are left out) and
    ``value`` pools them (their total log stretch over their total time).

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
    extent = xs.std() * math.sqrt(m)
    if forcing_hz:
        evolv = max(1, int(round(0.25 / forcing_hz / dts)))
        theiler = max(evolv, int(round(1.0 / forcing_hz / dts)))
        scalmx = WOLF_SCALMX_FORCED * extent
    else:
        evolv = max(1, tau // 2)
        theiler = m * tau
        scalmx = WOLF_SCALMX_AUTONOMOUS * extent
    scalmn = max(1e-3 * extent, 3 * noise * math.sqrt(m)) if noise else None
    if segments > 1:
        runs = []
        edges = np.linspace(0, xs.size, segments + 1).astype(int)
        for a, b in zip(edges[:-1], edges[1:], strict=False):
            try:
                runs.append(wolf_pooled(xs[a:b], dts, m, tau, evolv, theiler, scalmx=scalmx, scalmn=scalmn))
            except ValueError:
                continue
        if not runs:
            raise ValueError("no initial neighbour found in any segment (series too short or too noisy)")
        w = runs[0] | {
            "value": sum(r["value"] * r["time"] for r in runs) / sum(r["time"] for r in runs),
            "segments": [r["value"] for r in runs],
        }
    else:
        w = wolf_pooled(xs, dts, m, tau, evolv, theiler, scalmx=scalmx, scalmn=scalmn)
    horizon = min(16 * theiler, xs.size // 5)
    try:
        fit = ROSENSTEIN_FIT_FORCED if forcing_hz else ROSENSTEIN_FIT_AUTONOMOUS
        r = rosenstein(xs, dts, m, tau, theiler, horizon, fit, min_span=evolv)
        w.update(rosenstein=r["value"], rosenstein_fit_t=r["fit_t"])
    except ValueError as exc:  # a periodic orbit gives no divergence to fit: the cross-check says why
        w.update(rosenstein=None, rosenstein_error=" ".join(str(exc).split()))
    w.update(fnn_fractions=fnn, sample_step=step)
    return w
