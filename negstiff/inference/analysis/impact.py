"""Impact (hammer) tests: the hits found in a force channel, windowed as the field windows them, H1 over hits.

An instrumented hammer's record is a force channel that sits at its floor (the charge amplifier's DC offset and
noise) except for a few short pulses, and a response that rings down after each. A stationary spectral estimate
(Welch's Hann segments, ``frf.estimate``) reads such a record wrongly: the offset is the force's largest
spectral line, the segments cut the ring-downs anywhere, and the noise between hits is averaged as if it were
the excitation. What the field does instead (Ewins, *Modal Testing*, 2nd ed., 3.9 and 4.3; Brandt, *Noise and
Vibration Analysis*, 2011, 13.5-13.6):

* **Hits** (``record.impacts.find_impacts``): samples of the force channel standing far above its floor (its
  median and the median absolute deviation of the whole record: a hammer touches the structure a small fraction of
  the time);
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
from typing import Any

import numpy as np
from scipy import fft as sp_fft

from negstiff.errors import MeasurementError
from negstiff.inference.record.impacts import MIN_PRETRIGGER, Impacts
from negstiff.inference.record.measurement import Measurement

EXPONENTIAL_END = 0.01
"""The windowed response's size at its block's end, relative to its peak: 1 % (-40 dB), the field's usual
choice (Brandt 13.6.2). A ring-down that is already below this needs no exponential window."""

ZERO_PAD = 4
"""Each block is zero-padded to at least this many times its length (the FFT's bins 4x finer than 1/T)."""


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
    F = sp_fft.rfft(fk, nfft, axis=1) / rec.fs
    X = sp_fft.rfft(xk, nfft, axis=1) / rec.fs
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
