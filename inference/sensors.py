"""Response sensors as labs have them: the relative displacement z from what was measured.

A lab measures the moving part's response with whichever sensor it has:

* ``z`` [m]: relative displacement (a laser triangulation sensor on the frame, or the seed's laser
  minus the double-integrated base, already subtracted);
* ``z_dot`` [m/s]: relative velocity (a laser Doppler vibrometer on the moving part, mounted on the
  table, or any velocity sensor relative to the base);
* ``y`` [m] or ``y_dot`` [m/s]: the absolute displacement or velocity (a vibrometer on the ground),
  with the base's motion from ``base_disp`` or from the measured ``base_acc`` (the input);
* ``y_acc`` [m/s^2]: the moving part's absolute acceleration (an accelerometer on it).

``derive`` returns z together with a plain account of what was done and the error it carries.
What is lost on the way is said, never hidden:

* From a velocity, z is the integral of the measured signal (a quintic spline's antiderivative:
  a 40 Hz component sampled at 512 Hz is integrated within 1e-5, where the trapezoid rule errs by
  2 %), so its only unknowns are the constant (the frame) and, if the sensor has a DC offset, a
  ramp. The ramp is removed only where the record shows one: a stationary response has no trend,
  so the least-squares slope of the integral is compared with its batch-means standard error and
  removed when it exceeds 3 of them. The integrated sensor noise is a random walk; its size over the
  record, sigma_v sqrt(T dt / 3), is reported.
* A base velocity or displacement from the base accelerometer is band-limited (``highpass_hz``): a
  shaker has no DC stroke, and accelerometer noise integrated grows without bound.
* From an acceleration of the moving part, z needs two integrations: its content below
  ``highpass_hz`` (for a bistable device, which well it sits in) cannot be recovered from the signal
  and is not; the result says so and the frame is pinned by physics as for a velocity.
* The constant is never known from an integral. ``pin_frame`` estimates it from the physics: the
  restoring force at z = 0 (rods horizontal) carries the weight, K(0) = k0 = m g (g per unit mass
  when the mass is unknown). Among the candidate frames, the one whose origin lies between the wells
  is chosen (for a negative-stiffness device the origin is next to the unstable equilibrium).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy.interpolate import make_interp_spline

from negstiff.models.constants import G
from negstiff.models.rig import integrate_fft

RESPONSES = ("z", "z_dot", "y", "y_dot", "y_acc")
"""Response columns in the order a record's response is taken from (the first present wins)."""

HIGHPASS_HZ = 1.0
"""Low-frequency limit of an integration of an accelerometer [Hz] (as the rig's base; below the
excitation band of a shaker test)."""

TREND_SIGMAS = 3.0
"""A ramp in an integrated velocity is removed when its slope exceeds this many standard errors."""


def integrate_exact(x: np.ndarray, fs: float) -> np.ndarray:
    """Antiderivative of a sampled signal (quintic interpolating spline, scipy), zero at the start.

    Chosen over the trapezoid rule because the record's band reaches close to Nyquist: the spline's
    gain error at f is ~(2 pi f dt)^6 / 30240 instead of (2 pi f dt)^2 / 12."""
    t = np.arange(x.size) / fs
    spline = make_interp_spline(t, x, k=5 if x.size > 5 else 1)
    return spline.antiderivative()(t) - spline.antiderivative()(0.0)


def _noise_rms(x: np.ndarray, fs: float) -> float:
    """White-noise rms of a signal from the plateau of its spectrum (``derivatives.noise_floor``)."""
    from negstiff.inference.derivatives import noise_floor

    try:
        return float(noise_floor(x, fs)[0])
    except Exception:  # too short or too clean for a plateau: no estimate
        return float("nan")


def _trend(z: np.ndarray, fs: float, n_blocks: int = 10) -> tuple[float, float]:
    """Least-squares slope of ``z`` over time [units/s] and its batch-means standard error."""
    n = z.size
    t = np.arange(n) / fs
    if n < 4 * n_blocks:
        return 0.0, float("inf")
    idx = np.array_split(np.arange(n), n_blocks)
    tc = np.array([t[i].mean() for i in idx])
    zm = np.array([z[i].mean() for i in idx])
    slope, icpt = np.polyfit(tc, zm, 1)
    resid = zm - (slope * tc + icpt)
    se = math.sqrt(resid @ resid / (n_blocks - 2) / np.sum((tc - tc.mean()) ** 2))
    return float(slope), se


def velocity_to_z(v: np.ndarray, fs: float, what: str) -> tuple[np.ndarray, dict[str, Any]]:
    """z (up to a constant) from a relative velocity; the ramp of a DC offset removed if significant."""
    z = integrate_exact(v, fs)
    slope, se = _trend(z, fs)
    t = np.arange(z.size) / fs
    removed = bool(abs(slope) > TREND_SIGMAS * se)
    if removed:
        z = z - slope * (t - t.mean())
    sigma_v = _noise_rms(v, fs)
    walk = sigma_v * math.sqrt(z.size / fs / fs / 3) if np.isfinite(sigma_v) else float("nan")
    info = {
        "derived": f"z = integral of {what} (quintic spline antiderivative)",
        "velocity_offset_m_s": slope if removed else 0.0,
        "velocity_offset_se_m_s": se,
        "velocity_offset_removed": removed,
        "velocity_noise_m_s": sigma_v,
        "integration_error_m": walk,
        "z_constant_known": False,
    }
    return z, info


def derive(cols: dict[str, np.ndarray], input_name: str, fs: float, source: str) -> tuple[np.ndarray, dict]:
    """The relative displacement z from the record's response columns, and what was done.

    Parameters
    ----------
    cols : the record's columns (contract names, SI units)
    input_name : ``"base_acc"`` or ``"force"`` (a force-driven rig's base does not move)
    fs : sampling rate [Hz]
    source : the file, for messages

    Returns
    -------
    z [m] and an info dict: ``measured`` (the column used), ``derived`` (how), the estimated error and
    ``z_constant_known`` (False when the frame must be pinned by ``pin_frame``).
    """
    from negstiff.inference.measurement import MeasurementError

    measured = next((k for k in RESPONSES if k in cols), None)
    if measured is None:
        raise MeasurementError(
            f"{source}: missing column z (or another response: {', '.join(RESPONSES[1:])}; "
            f"columns: {', '.join(cols) or 'none'}; map foreign names with --columns)"
        )
    base_moves = input_name == "base_acc"
    if measured == "z":
        return cols["z"], {"measured": "z", "derived": None, "z_constant_known": True}
    if measured == "z_dot":
        z, info = velocity_to_z(cols["z_dot"], fs, "z_dot")
        return z, {"measured": "z_dot", **info}
    if measured == "y":
        if "base_disp" in cols:
            return cols["y"] - cols["base_disp"], {
                "measured": "y",
                "derived": "z = y - base_disp",
                "z_constant_known": True,
            }
        if not base_moves:
            return cols["y"], {"measured": "y", "derived": "z = y (force input: the base does not move)",
                               "z_constant_known": True}
        b = integrate_fft(cols["base_acc"], fs, HIGHPASS_HZ, order=2)
        return cols["y"] - b, {
            "measured": "y",
            "derived": f"z = y - b, b the double integral of base_acc above {HIGHPASS_HZ:g} Hz (the seed's route)",
            "z_constant_known": True,
        }
    if measured == "y_dot":
        if base_moves:
            bv = integrate_fft(cols["base_acc"], fs, HIGHPASS_HZ, order=1)
            z, info = velocity_to_z(cols["y_dot"] - bv, fs, f"y_dot - base velocity (base_acc integrated above "
                                    f"{HIGHPASS_HZ:g} Hz)")
        else:
            z, info = velocity_to_z(cols["y_dot"], fs, "y_dot (force input: the base does not move)")
        return z, {"measured": "y_dot", **info}
    # y_acc: the moving part's absolute acceleration
    a = cols["y_acc"] - cols["base_acc"] if base_moves else cols["y_acc"]
    z = integrate_fft(a, fs, HIGHPASS_HZ, order=2)
    sigma_a = _noise_rms(a, fs)
    return z, {
        "measured": "y_acc",
        "derived": f"z = double integral of {'y_acc - base_acc' if base_moves else 'y_acc'} above {HIGHPASS_HZ:g} Hz",
        "lost": f"z's content below {HIGHPASS_HZ:g} Hz (for a bistable device: which well it sits in) is not in "
        "an acceleration record; only in-well records are fully described",
        "acceleration_noise_m_s2": sigma_a,
        "integration_error_m": sigma_a / (2 * math.pi * HIGHPASS_HZ) ** 2 * math.sqrt(2 * HIGHPASS_HZ / fs)
        if np.isfinite(sigma_a)
        else float("nan"),
        "z_constant_known": False,
    }


def frame_offset(rec) -> dict[str, Any]:
    """The frame constant C that makes the record's z physical (z_true = z + C), from K(0) = m g.

    A cubic restoring force and viscous plus quadratic damping are fitted by weak-form least squares
    (``sindy.weak_least_squares``) in the record's own frame; its K_rec(x) = K_true(x + C), so the
    physical origin x = -C solves K_rec(x) = k0 with k0 = m g (g per unit mass). A force-driven record
    carries no weight in its equation (k0 is the force's offset): there the frame is not pinned.

    Returns a dict with ``offset_m`` (C, or None), ``candidates_m`` (every real solution) and ``method``.
    """
    from negstiff.inference.sindy import weak_least_squares

    if rec.input_name != "base_acc":
        return {"offset_m": None, "method": "not pinned: a force-driven record carries no weight (k0 unknown)"}
    model = weak_least_squares(rec, ("1", "z", "z^2", "z^3", "v", "v|v|"))
    k0 = model.m * G
    # K_rec(x) - k0 = k3 x^3 + k2 x^2 - k1 x + (k0_rec - k0)
    roots = np.roots([model.k3, model.k2, -model.k1, model.k0 - k0])
    real = np.sort(roots[np.abs(roots.imag) <= 1e-9 * np.abs(roots).max(initial=1.0)].real)
    if real.size == 0:
        return {"offset_m": None, "method": "not pinned: the fitted restoring force never carries the weight"}
    x = real[len(real) // 2] if real.size == 3 else real[np.argmin(np.abs(real - np.median(rec.z)))]
    return {
        "offset_m": float(-x),
        "candidates_m": [float(-r) for r in real],
        "method": "K(0) = m g: the frame in which the fitted cubic restoring force carries the weight at z = 0"
        + (" (of three candidate origins, the one between the wells)" if real.size == 3 else ""),
    }
