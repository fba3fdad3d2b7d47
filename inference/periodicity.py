"""Periodicity analysis and Poincare sections of harmonically forced records (seed section 3;
``shared/docs/algorithms.md`` part C).

* The forcing phase comes from the *measured* input: a least-squares sinusoid at the known forcing
  frequency (not the nominal start time), so records whose sampling rate is not a multiple of the
  forcing frequency are sampled phase-synchronously: z and z' are interpolated (cubic spline of the
  Savitzky-Golay smoothed signal) at t_n = t_phi + n T.
* Period detection: for p in (1, 2, 3, 4, 5, 6, 8, 16), the residual r(p) = rms_n |P_(n+p) - P_n| of
  the Poincare points P = (z / std z, z' / std z') scaled by the whole response's spread; the answer is
  the smallest p with r(p) < tol (and r(2p) < tol when 2p is tested), else ``None`` (chaotic or
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

from .measurement import Measurement, MeasurementError

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


def poincare(rec: Measurement, f_hz: float, phases_deg=(0.0,)) -> Poincare:
    """Poincare sections at the forcing phases ``phases_deg`` (0 = the input's upward zero crossing)."""
    if not (0 < f_hz < rec.fs / 4):
        raise MeasurementError(f"{rec.source}: forcing frequency {f_hz} Hz must lie in (0, fs/4)")
    period = 1.0 / f_hz
    n_cycles = int(rec.duration * f_hz) - 2
    if n_cycles < 8:
        raise MeasurementError(
            f"{rec.source}: too few samples for a periodicity analysis: {n_cycles + 2} forcing cycles, need at least 10"
        )
    t = rec.t - rec.t0
    amp, phi = forcing_phase(rec.u, t, f_hz)
    from .nsi import smooth_and_differentiate

    zs, _ = smooth_and_differentiate(rec.z, rec.fs)
    spline = CubicSpline(t, zs)
    t_first = (-phi / (2 * np.pi)) % 1.0 * period  # first upward zero crossing of the input's sinusoid
    zk, vk = [], []
    for ph in phases_deg:
        tn = t_first + (ph / 360.0) * period + period * np.arange(n_cycles)
        tn = tn[tn <= t[-1]]
        zk.append(spline(tn))
        vk.append(spline(tn, 1))
    n = min(len(a) for a in zk)
    return Poincare(np.asarray(phases_deg, float), np.array([a[:n] for a in zk]), np.array([a[:n] for a in vk]), amp)


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
        if rp < tol and (2 * p not in r or r[2 * p] < tol):
            return p, r
    return None, r


def periodicity(rec: Measurement, f_hz: float, wells: tuple | None = None) -> dict[str, Any]:
    """Period, amplitudes per branch and regime of a steady-state harmonically forced record.

    ``wells``: (z_minus, z_0, z_plus) or (z_minus, z_plus) when known (a lab measures the two rest
    positions; z_0 comes from a model), else None.
    """
    from .nsi import smooth_and_differentiate, velocity_window

    pc = poincare(rec, f_hz, (0.0,))
    z0, v0 = pc.z[0], pc.z_dot[0]
    zs, vs = smooth_and_differentiate(rec.z, rec.fs)
    # scales: the whole response's spread, so a period-1 orbit (Poincare points equal up to noise)
    # gives r(p) ~ noise / response, not ~ 1
    scale_z, scale_v = max(zs.std(), 1e-15), max(vs.std(), 1e-15)
    pts = np.column_stack([z0 / scale_z, v0 / scale_v])
    # noise of a Poincare point, propagated through the smoothing and the derivative
    noise = noise_level(rec.z, rec.fs)
    w, order = velocity_window(rec.z, rec.fs)
    if w:
        gz = math.sqrt(np.sum(signal.savgol_coeffs(w, order) ** 2))
        gv = math.sqrt(np.sum(signal.savgol_coeffs(w, order, deriv=1, delta=1 / rec.fs) ** 2))
    else:
        gz, gv = 1.0, math.pi * rec.fs / math.sqrt(3)  # spectral derivative of white noise
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
    """``in-well-minus``, ``in-well-plus`` or ``cross-well``: cross-well when z spends more than 1 % of
    the record on each side of the barrier, z_0 if known, else the wells' midpoint; without wells, the
    side of the motion's median."""
    if wells is None or wells[0] is None or wells[-1] is None:
        return "in-well-plus" if np.median(z) >= 0 else "in-well-minus"
    zm, zp = wells[0], wells[-1]
    mid = wells[1] if len(wells) == 3 and wells[1] is not None else 0.5 * (zm + zp)
    below, above = np.mean(z < mid), np.mean(z > mid)
    if below > 0.01 and above > 0.01:
        return "cross-well"
    return "in-well-plus" if above > below else "in-well-minus"
