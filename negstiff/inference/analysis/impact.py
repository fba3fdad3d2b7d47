"""Impact (hammer) tests: the hits found in a force channel, windowed as the field windows them, H1 over hits.

An instrumented hammer's record is a force channel that sits at its floor (the charge amplifier's DC offset and
noise) except for a few short pulses, and a response that rings down after each. A stationary spectral estimate
(Welch's Hann segments, ``frf.estimate``) reads such a record wrongly: the offset is the force's largest
spectral line, the segments cut the ring-downs anywhere, and the noise between hits is averaged as if it were
the excitation. What the field does instead (Ewins, *Modal Testing*, 2nd ed., 3.9 and 4.3; Brandt, *Noise and
Vibration Analysis*, 2011, 13.5-13.6):

* **Hits** (``find_impacts``): samples of the force channel standing far above its floor (its median and the
  median absolute deviation of the whole record: a hammer touches the structure a small fraction of the time);
  contiguous runs a few samples apart are one pulse; a record is an impact test when every pulse is short (a
  small share of the time between hits) and its peak stands ``MIN_PEAK_OVER_FLOOR`` floor deviations high.
* **Offset**: each hit's force (and response) has the median of its pre-trigger samples (the quiet stretch
  before the pulse) subtracted: the hammer's DC offset, which would otherwise be the largest line of its
  spectrum.
* **Windows**: the force by a rectangular (force) window around the pulse, zero elsewhere (what lies outside
  is the channel's noise); the response by an exponential window exp(-t / tau) from the block's start, chosen so
  the windowed ring-down has fallen to ``EXPONENTIAL_END`` of its peak at the block's end (no window where it
  already has: leakage-free without it). The exponential window adds 1 / tau to every mode's decay rate: a
  pole s = -zeta w_n + i w_d is seen at s - 1/tau, which ``correct_exponential`` takes off the fitted pole
  (Ewins 3.9; Brandt 13.6.2), the damped frequency w_d unchanged.
* **Averaging**: H1 = sum_k conj(F_k) X_k / sum_k |F_k|^2 over the hits k (one block each, all of one length),
  H2 = sum |X_k|^2 / sum X_k conj(F_k), and the coherence over hits |sum conj(F) X|^2 / (sum |F|^2 sum |X|^2)
  (1 by construction for a single hit: said in the result). The blocks are zero-padded (the windowed signals
  are zero at their end, so padding interpolates the spectrum without adding leakage).
* A velocity or acceleration response gives a mobility or accelerance; it is divided by i w (or -w^2) to a
  receptance, which is what ``frf.fit_peak`` fits.

Why scipy/numpy rather than pyFRF or pyEMA (both installable with pip: pyFRF 1.5.0, pyEMA 0.31.0): pyFRF
averages hits it is handed one by one, already triggered and cut; it neither finds the hits nor removes the
hammer's offset, and its exponential window is applied without the damping correction, which is the step
that put the lab's damping 3-4x off. pyEMA fits poles to an FRF (LSCF), which ``frf.fit_peak`` already does
per peak. What is left is an FFT and a few sums.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from negstiff.errors import MeasurementError
from negstiff.inference.record.measurement import Measurement

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

EXPONENTIAL_END = 0.01
"""The windowed response's size at its block's end, relative to its peak: 1 % (-40 dB), the field's usual
choice (Brandt 13.6.2). A ring-down that is already below this needs no exponential window."""

ZERO_PAD = 4
"""Each block is zero-padded to at least this many times its length (the FFT's bins 4x finer than 1/T)."""


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


RESPONSE_KINDS = {"z": 0, "y": 0, "z_dot": 1, "y_dot": 1, "y_acc": 2}
"""Each response column's order of derivative of displacement."""


def response_signal(rec: Measurement) -> tuple[np.ndarray, int, str]:
    """The response as the lab measured it, where the record keeps it: (signal, derivative order, name).

    A velocity (``z_dot``) is taken as measured (its integral's drift and constant are no part of an impact's
    ring-down); a displacement as it is; an acceleration's record keeps only z, its double integral above 1 Hz,
    which is used then.
    """
    measured = (rec.info.get("response") or {}).get("measured") or "z"
    if measured == "z_dot" and rec.z_dot is not None:
        return np.asarray(rec.z_dot, float), 1, "z_dot"
    return np.asarray(rec.displacement, float), 0, "z" if measured in ("z", None) else f"z (from {measured})"


def _pretrigger_median(x: np.ndarray, lo: int, start: int, block: int) -> float:
    quiet = x[lo:start]
    if quiet.size < MIN_PRETRIGGER:
        quiet = x[start : start + block][-max(MIN_PRETRIGGER, block // 10) :]
    return float(np.median(quiet))


def impact_spectra(rec: Measurement, hits: Impacts) -> dict[str, Any]:
    """H1, H2 and the coherence over the hits (module docstring), as receptance [m/N].

    Returns
    -------
    dict
        ``f`` [Hz], ``H1``, ``H2`` (receptance, complex), ``coherence`` (over hits), ``Gxx`` (the windowed
        force's auto-spectrum, summed over hits), ``tau_s`` (the exponential window's time constant; inf:
        none), ``window`` (a plain account), ``response`` (the column used), ``block_s``, ``nfft``.
    """
    x, order, name = response_signal(rec)
    u = rec.u
    n, block = rec.n, hits.block
    nfft = 1 << int(math.ceil(math.log2(ZERO_PAD * block)))
    forces, responses = [], []
    for k, (a, e) in enumerate(zip(hits.starts, hits.pulse_ends, strict=True)):
        f_k = np.zeros(block)
        f_k[: e - a] = u[a:e] - hits.offsets[k]  # force window: the pulse only, its offset off
        lo = hits.pulse_ends[k - 1] if k else 0
        x_k = x[a : min(a + block, n)] - _pretrigger_median(x, lo, a, block)
        forces.append(f_k)
        responses.append(np.r_[x_k, np.zeros(block - x_k.size)])
    fk, xk = np.array(forces), np.array(responses)
    # the exponential window: the ring-down at the block's end (its last tenth) against its peak, worst hit
    tail = max(1, block // 10)
    ratio = float(np.max(np.max(np.abs(xk[:, -tail:]), axis=1) / np.maximum(np.max(np.abs(xk), axis=1), 1e-300)))
    t = np.arange(block) / rec.fs
    if ratio > EXPONENTIAL_END:
        tau = (block / rec.fs) / math.log(ratio / EXPONENTIAL_END)
        xk = xk * np.exp(-t / tau)
        window = (f"response: exponential, tau {tau:.4g} s (its end {np.exp(-block / rec.fs / tau):.3g}: the "
                  f"ring-down at the block's end was {100 * ratio:.3g} % of its peak), its added decay rate 1/tau "
                  "taken off each fitted mode's damping")  # fmt: skip
    else:
        tau = math.inf
        window = f"response: none (rectangular; its ring-down is {100 * ratio:.2g} % of its peak at the block's end)"
    window = f"force: rectangular over each pulse ({(hits.pulse_ends - hits.starts).max() / rec.fs * 1e3:.3g} ms), " \
        + window  # fmt: skip
    F = np.fft.rfft(fk, nfft, axis=1) / rec.fs
    X = np.fft.rfft(xk, nfft, axis=1) / rec.fs
    f = np.fft.rfftfreq(nfft, 1 / rec.fs)
    gxx = np.sum(np.abs(F) ** 2, axis=0)
    gyy = np.sum(np.abs(X) ** 2, axis=0)
    gxy = np.sum(np.conj(F) * X, axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        h1 = gxy / gxx
        h2 = gyy / np.conj(gxy)
        coh = np.abs(gxy) ** 2 / (gxx * gyy)
        iw = 2j * np.pi * f
        h1, h2 = h1 / iw**order, h2 / iw**order  # mobility or accelerance to receptance
    if order:  # no receptance at 0 Hz from a velocity or an acceleration
        h1[0] = h2[0] = 0.0
    return {"f": f, "H1": np.nan_to_num(h1), "H2": np.nan_to_num(h2), "coherence": np.nan_to_num(coh), "Gxx": gxx,
            "tau_s": tau, "window": window, "response": name, "block_s": block / rec.fs, "nfft": nfft,
            "averages": hits.count}  # fmt: skip


def correct_exponential(f_hz: float, zeta: float, tau: float) -> tuple[float, float]:
    """The mode under the exponential window exp(-t / tau) taken back to the structure's: (f_n [Hz], zeta).

    The window moves the pole s = -zeta w_n + i w_d to s - 1/tau (Ewins 3.9, Brandt 13.6.2): the decay rate
    sigma = zeta w_n loses 1/tau, the damped frequency w_d stays. A fitted decay rate below 1/tau (a fit that
    saw less damping than the window added) gives zeta 0.
    """
    if not math.isfinite(tau):
        return f_hz, zeta
    wn = 2 * math.pi * f_hz
    sigma = zeta * wn - 1.0 / tau
    wd = wn * math.sqrt(max(1.0 - zeta**2, 0.0))
    sigma = max(sigma, 0.0)
    wn_true = math.hypot(sigma, wd)
    return wn_true / (2 * math.pi), sigma / wn_true


def impact_band(spectra: dict[str, Any], fs: float) -> tuple[float, float]:
    """The band the hammer excites: where the windowed force's spectrum is within 20 dB of its largest, from
    two blocks' bins above 0 Hz (below, the window's own width) to 0.8 of the Nyquist frequency at most.
    """
    f, gxx = spectra["f"], spectra["Gxx"]
    lo = 2.0 / spectra["block_s"]
    on = np.flatnonzero((gxx >= 0.01 * gxx.max()) & (f >= lo))
    hi = float(min(f[on[-1]], 0.8 * fs / 2)) if on.size else 0.8 * fs / 2
    if hi <= lo:
        raise MeasurementError(f"the hammer's band ends at {hi:g} Hz, below the blocks' resolution ({lo:g} Hz)")
    return float(lo), hi
