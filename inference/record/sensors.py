"""Response sensors as labs have them: the relative displacement z from what was measured.

A lab measures the moving part's response with whichever sensor it has:

* ``z`` [m]: relative displacement (a laser triangulation sensor on the frame, or the reference study's laser
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
  2 %), so its only unknown is the constant (the frame). A trend of the integral far beyond its
  batch-means standard error is reported (a sensor's DC offset would make one), not removed. The
  integrated sensor noise is a random walk; its size over the record, sigma_v sqrt(T dt / 3), is
  reported.
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

from negstiff.errors import MeasurementError
from negstiff.inference.steps.derivatives import noise_floor
from negstiff.models.table import integrate_fft

RESPONSES = ("z", "z_dot", "y", "y_dot", "y_acc")
"""Response columns in the order a record's response is taken from (the first present wins)."""

HIGHPASS_HZ = 1.0
"""Low-frequency limit of an integration of an accelerometer [Hz] (as the rig's base; below the
excitation band of a shaker test)."""

TRIM_S = 4.0 / HIGHPASS_HZ
"""Seconds cut from each end of a record whose z needs a band-limited integral of an accelerometer:
the integral's end effects decay over a few periods of the high-pass (measured on a 40 s rig record:
z erred by 7.5 mm rms over the whole record, 0.29 mm beyond 2 s from the ends, 0.06 mm beyond 4 s; the
rig likewise discards 4 s after its records)."""

TREND_SIGMAS = 5.0
"""A ramp in an integrated velocity is reported when its slope exceeds this many standard errors."""


def integrate_exact(x: np.ndarray, fs: float) -> np.ndarray:
    """Antiderivative of a sampled signal (quintic interpolating spline, scipy), zero at the start.

    Chosen over the trapezoid rule because the record's band reaches close to Nyquist: the spline's
    gain error at f is ~(2 pi f dt)^6 / 30240 instead of (2 pi f dt)^2 / 12.
    """
    t = np.arange(x.size) / fs
    spline = make_interp_spline(t, x, k=5 if x.size > 5 else 1)
    return spline.antiderivative()(t) - spline.antiderivative()(0.0)


def _noise_rms(x: np.ndarray, fs: float) -> float:
    """White-noise rms of a signal from the plateau of its spectrum (``derivatives.noise_floor``)."""
    try:
        return float(math.sqrt(noise_floor(x, fs)[0]))
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
    """Z (up to a constant) from a relative velocity, and what the integral carries.

    A vibrometer has no DC offset worth the name (a Doppler shift is zero at rest), and a bistable
    device's z is not stationary over minutes (it may sit in one well for a long stretch: on a 300 s
    rig record the true z's slope was 3.3 batch-means standard errors from zero), so a ramp is not
    removed: one beyond ``TREND_SIGMAS`` standard errors is reported as a warning instead.
    """
    z = integrate_exact(v, fs)
    slope, se = _trend(z, fs)
    sigma_v = _noise_rms(v, fs)
    walk = sigma_v * math.sqrt(z.size / fs / fs / 3) if np.isfinite(sigma_v) else float("nan")
    info: dict[str, Any] = {
        "derived": f"z = integral of {what} (quintic spline antiderivative)",
        "trend_m_s": slope,
        "trend_se_m_s": se,
        "velocity_noise_m_s": sigma_v,
        "integration_error_m": walk,
        "z_constant_known": False,
        "warnings": [],
    }
    if abs(slope) > TREND_SIGMAS * se:
        info["warnings"].append(
            f"z integrated from {what.split()[0]} drifts by {1e3 * slope * z.size / fs:.3g} mm over the record "
            f"({abs(slope) / se:.1f} standard errors): a DC offset of the velocity sensor ({slope:.3g} m/s)? "
            "It is not removed; a long stay in one well looks the same"
        )
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
    ``z_constant_known`` (False when the frame must be pinned by ``pin_frame``); ``trim_s``, where
    present, is the time at each end the caller must cut (an accelerometer's integral is not valid
    there).
    """
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
            return cols["y"], {
                "measured": "y",
                "derived": "z = y (force input: the base does not move)",
                "z_constant_known": True,
            }
        b = integrate_fft(cols["base_acc"], fs, HIGHPASS_HZ, order=2)
        return cols["y"] - b, {
            "measured": "y",
            "derived": f"z = y - b, b the double integral of base_acc above {HIGHPASS_HZ:g} Hz (the paper's route)",
            "trim_s": TRIM_S,
            "z_constant_known": True,
        }
    if measured == "y_dot":
        if base_moves:
            bv = integrate_fft(cols["base_acc"], fs, HIGHPASS_HZ, order=1)
            z, info = velocity_to_z(
                cols["y_dot"] - bv, fs, f"y_dot - base velocity (base_acc integrated above {HIGHPASS_HZ:g} Hz)"
            )
        else:
            z, info = velocity_to_z(cols["y_dot"], fs, "y_dot (force input: the base does not move)")
        return z, {"measured": "y_dot", **info, **({"trim_s": TRIM_S} if base_moves else {})}
    # y_acc: the moving part's absolute acceleration
    a = cols["y_acc"] - cols["base_acc"] if base_moves else cols["y_acc"]
    z = integrate_fft(a, fs, HIGHPASS_HZ, order=2)
    sigma_a = _noise_rms(a, fs)
    return z, {
        "measured": "y_acc",
        "derived": f"z = double integral of {'y_acc - base_acc' if base_moves else 'y_acc'} above {HIGHPASS_HZ:g} Hz",
        "lost": f"z's content below {HIGHPASS_HZ:g} Hz (for a bistable device: which well it sits in) is not in "
        "an acceleration record; only in-well records are fully described",
        "trim_s": TRIM_S,
        "acceleration_noise_m_s2": sigma_a,
        # white noise of rms sigma_a over the band, integrated twice above f_hp:
        # var = sigma_a^2 / (fs/2) * int_{f_hp} df / (2 pi f)^4 = sigma_a^2 (2 / (3 fs)) / ((2 pi)^4 f_hp^3)
        "integration_error_m": sigma_a / (2 * math.pi * HIGHPASS_HZ) ** 2 * math.sqrt(2 * HIGHPASS_HZ / (3 * fs))
        if np.isfinite(sigma_a)
        else float("nan"),
        "z_constant_known": False,
        "warnings": [
            f"z was derived from an accelerometer on the moving part: its content below {HIGHPASS_HZ:g} Hz is lost "
            "(for cross-well motion, which well the device sits in); results hold for in-well records only"
        ],
    }
