"""Periodicity analysis and Poincare sections of harmonically forced records (seed section 3;
``shared/docs/algorithms.md`` part C).

* The forcing phase comes from the *measured* input: a least-squares sinusoid at the known forcing
  frequency (not the nominal start time), so records whose sampling rate is not a multiple of the
  forcing frequency are sampled phase-synchronously: z and z' are interpolated (cubic spline of the
  Savitzky-Golay smoothed signal) at t_n = t_phi + n T.
* Period detection: for p in (1, 2, 3, 4, 5, 6, 8, 16), the residual r(p) = rms_n |P_(n+p) - P_n| of
  the Poincare points P = (z / std z, z' / std z') scaled by the whole response's spread; the answer is
  the smallest p with r(p) < tol (and r(2p) < 2 tol when 2p is tested), after removing a slow
  quadratic trend from the points (drift of the integrated base displacement), else ``None`` (chaotic or
  quasi-periodic). The tolerance follows the noise: the sensor noise, estimated from the record, is
  propagated through the smoothing and the derivative to a Poincare point, and tol = max(0.02,
  4 sqrt(2) x that).
* Amplitudes: for period p, the half peak-to-peak of z over each of p consecutive forcing cycles
  (averaged over the record): one amplitude per branch of the bifurcation map.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import signal
from scipy.interpolate import CubicSpline

from negstiff.errors import MeasurementError
from negstiff.inference.record.measurement import Measurement

PERIODS = (1, 2, 3, 4, 5, 6, 8, 16)


def forcing_phase(u: np.ndarray, t: np.ndarray, f_hz: float) -> tuple[float, float]:
    """Amplitude and phase of u ~ A sin(2 pi f t + phi) by linear least squares."""
    w = 2 * np.pi * f_hz
    X = np.column_stack([np.sin(w * t), np.cos(w * t), np.ones_like(t)])
    a, b, _ = np.linalg.lstsq(X, u, rcond=None)[0]
    return float(math.hypot(a, b)), float(math.atan2(b, a))


@dataclass(frozen=True)
class Poincare:
    """Phase-synchronous samples of a record: ``z[k, n]``, ``z_dot[k, n]`` at phase ``phases_deg[k]``
    of forcing cycle n."""

    phases_deg: np.ndarray
    z: np.ndarray
    z_dot: np.ndarray
    forcing_amplitude: float


@dataclass(frozen=True)
class _Synchronous:
    """A record's band-limited z as a cubic spline of time, with the forcing's phase from the input."""

    spline: CubicSpline
    t_first: float
    period: float
    n_cycles: int
    t_end: float
    forcing_amplitude: float


def _synchronous(rec: Measurement, f_hz: float) -> _Synchronous:
    if not (0 < f_hz < rec.fs / 4):
        raise MeasurementError(f"{rec.source}: forcing frequency {f_hz} Hz must lie in (0, fs/4)")
    n_cycles = int(rec.duration * f_hz) - 2
    if n_cycles < 8:
        raise MeasurementError(
            f"{rec.source}: too few samples for a periodicity analysis: {n_cycles + 2} forcing cycles, need at least 10"
        )
    t = rec.t - rec.t0
    amp, phi = forcing_phase(rec.u, t, f_hz)
    period = 1.0 / f_hz
    t_first = (-phi / (2 * np.pi)) % 1.0 * period  # first upward zero crossing of the input's sinusoid
    return _Synchronous(CubicSpline(t, bandlimited(rec.z, rec.fs, f_hz)), t_first, period, n_cycles, t[-1], amp)


def _sections(sync: _Synchronous, phases_deg) -> Poincare:
    zk, vk = [], []
    for ph in phases_deg:
        tn = sync.t_first + (ph / 360.0) * sync.period + sync.period * np.arange(sync.n_cycles)
        tn = tn[tn <= sync.t_end]
        zk.append(sync.spline(tn))
        vk.append(sync.spline(tn, 1))
    n = min(len(a) for a in zk)
    return Poincare(
        np.asarray(phases_deg, float),
        np.array([a[:n] for a in zk]),
        np.array([a[:n] for a in vk]),
        sync.forcing_amplitude,
    )


def poincare(rec: Measurement, f_hz: float, phases_deg=(0.0,)) -> Poincare:
    """Poincare sections at the forcing phases ``phases_deg`` (0 = the input's upward zero crossing)."""
    return _sections(_synchronous(rec, f_hz), phases_deg)


def band_edge(fs: float, f_hz: float) -> float:
    """Upper frequency [Hz] kept for Poincare analysis: 8 forcing harmonics, at most 0.4 fs."""
    return min(0.4 * fs, 8 * f_hz)


def bandlimited(z: np.ndarray, fs: float, f_hz: float) -> np.ndarray:
    """z low-passed (zero-phase, 4th-order Butterworth) at ``band_edge``: the same filter on every
    forcing cycle cannot create or destroy a periodicity, and it keeps broadband sensor noise out of
    the differentiated Poincare coordinate."""
    sos = signal.butter(4, band_edge(fs, f_hz), fs=fs, output="sos")
    return signal.sosfiltfilt(sos, z)


def noise_level(z: np.ndarray, fs: float) -> float:
    """Sensor noise std [same units as z], from the residual of a light smoothing, scaled for the
    part of white noise the smoothing keeps."""
    w = 7
    resid = z - signal.savgol_filter(z, w, 3)
    # a cubic 7-point Savitzky-Golay filter passes sum(h^2) of white noise; the residual keeps 1 - that
    h = signal.savgol_coeffs(w, 3)
    return float(resid.std() / math.sqrt(1 - np.sum(h**2)))


def detect_period(points: np.ndarray, tol: float) -> tuple[int | None, dict[int, float]]:
    """Smallest period p of a sequence of points (N, d), already scaled by the response's spread, with
    r(p) < tol and, where tested, r(2p) < tol."""
    r = {}
    for p in PERIODS:
        if p >= points.shape[0] // 2:
            break
        r[p] = float(np.sqrt(np.mean(np.sum((points[p:] - points[:-p]) ** 2, axis=1))))
    for p, rp in r.items():
        # slow drift left in the points grows with the lag: the consistency check at 2p gets 2 tol
        if rp < tol and (2 * p not in r or r[2 * p] < 2 * tol):
            return p, r
    return None, r


def periodicity(
    rec: Measurement, f_hz: float, wells: tuple | None = None, noise: float | None = None, band_fs: float | None = None
) -> dict[str, Any]:
    """Period, amplitudes per branch and regime of a steady-state harmonically forced record.

    ``wells``: (z_minus, z_0, z_plus) or (z_minus, z_plus) when known (a lab measures the two rest
    positions; z_0 comes from a model), else None. ``noise`` [m] and ``band_fs`` [Hz]: the sensor
    noise and the sampling rate it was acquired at, for a record interpolated from a lower rate
    (default: estimated from ``rec``, at ``rec.fs``).
    """
    sync = _synchronous(rec, f_hz)
    pc = _sections(sync, (0.0,))
    z0, v0 = pc.z[0], pc.z_dot[0]
    zs, vs = sync.spline(rec.t - rec.t0), sync.spline(rec.t - rec.t0, 1)
    # scales: the whole response's spread, so a period-1 orbit (Poincare points equal up to noise)
    # gives r(p) ~ noise / response, not ~ 1
    scale_z, scale_v = max(zs.std(), 1e-15), max(vs.std(), 1e-15)
    pts = np.column_stack([z0 / scale_z, v0 / scale_v])
    # a slow trend (the integrated base displacement drifts) is no periodicity: remove a quadratic in n
    n_idx = np.arange(pts.shape[0])
    for k in range(2):
        pts[:, k] -= np.polyval(np.polyfit(n_idx, pts[:, k], 2), n_idx) - pts[:, k].mean()
    # noise of a Poincare point: white sensor noise through the band limit fc (gain sqrt(2 fc / fs))
    # and its derivative (gain 2 pi fc sqrt(2 fc / (3 fs)))
    noise = noise_level(rec.z, rec.fs) if noise is None else noise
    band_fs = rec.fs if band_fs is None else band_fs
    fc = min(band_edge(rec.fs, f_hz), band_fs / 2)
    gz = math.sqrt(2 * fc / band_fs)
    gv = 2 * math.pi * fc * math.sqrt(2 * fc / (3 * band_fs))
    point_noise = math.hypot(noise * gz / scale_z, noise * gv / scale_v)
    # r(p) of a truly periodic record is sqrt(2) x the point noise; 4x that, and at least 2 %
    tol = max(0.02, 4 * math.sqrt(2) * point_noise)
    period, r = detect_period(pts, tol)
    # amplitude per branch: half peak-to-peak of z over each of p consecutive cycles
    n_per = int(round(rec.fs / f_hz))
    cycles = rec.z[: (rec.n // n_per) * n_per].reshape(-1, n_per)
    p = period or 1
    amps = [float(np.mean(0.5 * (cycles[k::p].max(1) - cycles[k::p].min(1)))) for k in range(p)]
    return {
        "period": period,
        "amplitudes": amps,
        "regime": classify_regime(rec.z, wells),
        "residuals": r,
        "tolerance": tol,
        "noise_std": noise,
        "poincare_z": z0,
        "poincare_z_dot": v0,
        "forcing_amplitude": pc.forcing_amplitude,
    }


def classify_regime(z: np.ndarray, wells: tuple | None) -> str:
    """``in-well-minus``, ``in-well-plus`` or ``cross-well``.

    With the barrier z_0 known (``wells`` = (z_minus, z_0, z_plus), e.g. from a model): cross-well when
    z spends more than 1 % of the record on each side of it. With only the two rest positions (what a
    lab measures): cross-well when z enters both wells' neighbourhoods, within 35 % of the well spacing
    of each (the wells' midpoint is no barrier for an asymmetric device: a large in-well orbit of the
    stiff well passes it). Without wells: the side of the motion's median.
    """
    if wells is None or wells[0] is None or wells[-1] is None:
        return "in-well-plus" if np.median(z) >= 0 else "in-well-minus"
    zm, zp = wells[0], wells[-1]
    if len(wells) == 3 and wells[1] is not None:
        below, above = np.mean(z < wells[1]), np.mean(z > wells[1])
        if below > 0.01 and above > 0.01:
            return "cross-well"
        return "in-well-plus" if above > below else "in-well-minus"
    near = 0.35 * (zp - zm)
    in_minus, in_plus = np.mean(np.abs(z - zm) < near), np.mean(np.abs(z - zp) < near)
    if in_minus > 0.01 and in_plus > 0.01:
        return "cross-well"
    return "in-well-plus" if in_plus > in_minus else "in-well-minus"
