"""The hits of a hammer's force channel (``find_impacts``: the method is ``analysis.impact``'s module docstring),
array code the record's loader needs too (an accelerometer's hammer record is integrated from rest, not trimmed:
``sensors.derive``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

MAD_TO_SIGMA = 1.4826
"""The median absolute deviation of Gaussian noise times this is its standard deviation."""

MIN_PEAK_OVER_FLOOR = 30.0
"""A hammer pulse's peak stands at least this many floor deviations above the channel's median (a random or
harmonic force's peaks stand 3-5 deviations high: its median absolute deviation is its own size)."""

PULSE_THRESHOLD = 0.02
"""A pulse is the run of samples above this fraction of its own peak (or 8 floor deviations, the larger): its
rise and fall, not the noise around it."""

MAX_PULSE_SHARE = 0.1
"""Every pulse lasts at most this share of the shortest time between hits (a hammer's contact lasts 0.1-10
ms, its hits seconds apart); a longer 'pulse' is a forcing, not an impact."""

MIN_PRETRIGGER = 8
"""Samples before a pulse (the pre-trigger) needed to read the hit's offset from them; fewer: the block's
quiet end is read instead."""


@dataclass(frozen=True)
class Impacts:
    """The hits of an impact record (``find_impacts``).

    Attributes
    ----------
    starts : numpy.ndarray of int
        Each hit's block start [sample] (a few samples before its pulse rises).
    pulse_ends : numpy.ndarray of int
        Each pulse's end [sample] (exclusive): the force window spans ``starts[k]:pulse_ends[k]``.
    block : int
        The common block length [samples] (the shortest time between hits, or to the record's end).
    peaks : numpy.ndarray
        Each pulse's peak force above its offset [N].
    floor : float
        The force channel's floor deviation (its median absolute deviation as a standard deviation) [N].
    offsets : numpy.ndarray
        Each hit's force offset removed (its pre-trigger median) [N].
    dropped : list of str
        Pulses found but not used, each with why.
    """

    starts: np.ndarray
    pulse_ends: np.ndarray
    block: int
    peaks: np.ndarray
    floor: float
    offsets: np.ndarray
    dropped: list[str] = field(default_factory=list)

    @property
    def count(self) -> int:
        """The number of hits used."""
        return int(self.starts.size)


def _runs(mask: np.ndarray, gap: int) -> list[tuple[int, int]]:
    """Runs [start, stop) of True in ``mask``, runs fewer than ``gap`` samples apart joined."""
    idx = np.flatnonzero(mask)
    if not idx.size:
        return []
    breaks = np.flatnonzero(np.diff(idx) > gap)
    starts = np.r_[idx[0], idx[breaks + 1]]
    stops = np.r_[idx[breaks], idx[-1]] + 1
    return list(zip(starts.tolist(), stops.tolist(), strict=True))


def find_impacts(u: np.ndarray, fs: float) -> Impacts | None:
    """The hammer hits of a force channel, or None when it is not an impact record (module docstring).

    Parameters
    ----------
    u : numpy.ndarray
        The force channel [N], offset and noise included.
    fs : float
        Sampling rate [Hz].

    Returns
    -------
    Impacts or None
        The hits (at least one), or None: no pulse stands ``MIN_PEAK_OVER_FLOOR`` floor deviations high, or a
        pulse lasts longer than ``MAX_PULSE_SHARE`` of the time between hits (a forcing, not an impact).
    """
    u = np.asarray(u, float)
    n = u.size
    if n < 4 * MIN_PRETRIGGER:
        return None
    med = float(np.median(u))
    dev = np.abs(u - med)
    floor = MAD_TO_SIGMA * float(np.median(dev))
    peak = float(dev.max())
    if peak <= 0 or peak < MIN_PEAK_OVER_FLOOR * floor:
        return None
    # the pulses: runs above a threshold set by the highest pulse, joined across a sample or two of ringing
    runs = _runs(dev > max(8 * floor, PULSE_THRESHOLD * peak), gap=max(2, int(1e-3 * fs)))
    runs = [(a, b) for a, b in runs if dev[a:b].max() >= MIN_PEAK_OVER_FLOOR * floor]
    if not runs:
        return None
    starts = np.array([a for a, _ in runs])
    widths = np.array([b - a for a, b in runs])
    spacing = np.diff(np.r_[starts, n])
    if np.any(widths > MAX_PULSE_SHARE * spacing):
        return None
    pre = max(2, int(np.max(widths)) // 2)  # the pulse's foot below the threshold, before it rises
    block_starts = np.maximum(starts - pre, 0)
    ends = np.array([min(b + pre, n) for _, b in runs])
    lengths = np.diff(np.r_[block_starts, n])
    dropped: list[str] = []
    keep = np.ones(starts.size, bool)
    if starts.size > 1 and lengths[-1] < 0.5 * np.min(lengths[:-1]):  # the last hit's ring-down cut by the end
        keep[-1] = False
        dropped.append(f"the hit at {starts[-1] / fs:.4g} s: the record ends {lengths[-1] / fs:.3g} s after it, "
                       f"under half the time between the others")  # fmt: skip
    block = int(np.min(lengths[keep]))
    offsets = []
    for k in np.flatnonzero(keep):
        lo = ends[k - 1] if k else 0
        quiet = u[lo : block_starts[k]]
        if quiet.size < MIN_PRETRIGGER:  # no pre-trigger: the block's quiet end (after the pulse, the force is off)
            quiet = u[ends[k] : block_starts[k] + block][-max(MIN_PRETRIGGER, block // 4) :]
        offsets.append(float(np.median(quiet)))
    offsets_a = np.array(offsets)
    peaks = np.array([float(np.max(np.abs(u[a:b] - o))) for (a, b), o in
                      zip([r for r, k in zip(runs, keep, strict=True) if k], offsets_a, strict=True)])  # fmt: skip
    return Impacts(starts=block_starts[keep], pulse_ends=ends[keep], block=block, peaks=peaks, floor=floor,
                   offsets=offsets_a, dropped=dropped)  # fmt: skip
