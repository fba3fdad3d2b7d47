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

from negstiff.models.constants import G
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
    gain error at f is ~(2 pi f dt)^6 / 30240 instead of (2 pi f dt)^2 / 12."""
    t = np.arange(x.size) / fs
    spline = make_interp_spline(t, x, k=5 if x.size > 5 else 1)
    return spline.antiderivative()(t) - spline.antiderivative()(0.0)


def _noise_rms(x: np.ndarray, fs: float) -> float:
    """White-noise rms of a signal from the plateau of its spectrum (``derivatives.noise_floor``)."""
    from negstiff.inference.derivatives import noise_floor

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
    """z (up to a constant) from a relative velocity, and what the integral carries.

    A vibrometer has no DC offset worth the name (a Doppler shift is zero at rest), and a bistable
    device's z is not stationary over minutes (it may sit in one well for a long stretch: on a 300 s
    rig record the true z's slope was 3.3 batch-means standard errors from zero), so a ramp is not
    removed: one beyond ``TREND_SIGMAS`` standard errors is reported as a warning instead."""
    z = integrate_exact(v, fs)
    slope, se = _trend(z, fs)
    sigma_v = _noise_rms(v, fs)
    walk = sigma_v * math.sqrt(z.size / fs / fs / 3) if np.isfinite(sigma_v) else float("nan")
    info = {
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
            return cols["y"], {
                "measured": "y",
                "derived": "z = y (force input: the base does not move)",
                "z_constant_known": True,
            }
        b = integrate_fft(cols["base_acc"], fs, HIGHPASS_HZ, order=2)
        return cols["y"] - b, {
            "measured": "y",
            "derived": f"z = y - b, b the double integral of base_acc above {HIGHPASS_HZ:g} Hz (the seed's route)",
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


PIN_TERMS = ("1", "z", "z^2", "z^3", "z^4", "z^5", "v", "v|v|")
"""Library of the frame fit: a quintic restoring force follows the exact device's K near its origin
(the cubic's K(0) errs there: 0.7-1.7 mm of frame on as-built records, measured; 0.15-0.2 mm with
the quintic)."""


def _crossings(x: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Zeros of a sampled function, by linear interpolation between the samples that bracket them."""
    i = np.flatnonzero(np.diff(np.sign(f)) != 0)
    return x[i] - f[i] * (x[i + 1] - x[i]) / (f[i + 1] - f[i])


def _frame_anchors(rec) -> tuple[float, dict[str, float]]:
    """In the record's own frame: the origin (where a quintic fitted to ``rec`` carries m g, between
    its wells) and the stable wells, all searched over the stroke the record visited."""
    from negstiff.inference.weak import weak_least_squares

    model = weak_least_squares(rec, PIN_TERMS)
    x = np.linspace(rec.z.min(), rec.z.max(), 4001)
    K = model.restoring_force(x)
    eq = _crossings(x, K)
    stable = [e for e in eq if np.interp(e, x, np.gradient(K, x)) > 0]
    if len(stable) == 1:  # an in-well record: one well, and no origin between wells to find
        return float("nan"), {"one": stable[0]}
    wells = {"minus": stable[0], "plus": stable[-1]} if len(stable) >= 2 else {}
    roots = _crossings(x, K - model.m * G)
    if not roots.size:
        raise ValueError("the fitted restoring force never carries the weight over the visited stroke")
    mid = eq[len(eq) // 2] if eq.size else float(np.median(rec.z))
    origin = float(roots[np.argmin(np.abs(roots - mid))])
    if wells and not wells["minus"] < origin < wells["plus"]:
        wells = {}  # a fit whose weight-carrying point is not between its wells pins nothing well
    return origin, wells


def frame_offset(rec, spread: bool = True) -> dict[str, Any]:
    """The frame constant C that makes a record's z physical (z_true = z + C).

    Two anchors, the better one used:

    * rest positions (``# z_minus_rest`` / ``# z_plus_rest`` metadata [m], measured statically
      before the test; ``# z_rest`` for the one well an in-well record stays in): C = z_rest -
      x_well, with x_well the fitted model's wells in the record's frame (well positions are what a
      record determines best); an in-well record can only be pinned this way;
    * gravity: the restoring force at z = 0 (rods horizontal) carries the weight, K(0) = m g (g per
      unit mass). A quintic restoring force with viscous and quadratic damping is fitted by weak-form
      least squares (``weak.weak_least_squares``) in the record's frame, where K_rec(x) =
      K_true(x + C); the origin solves K_rec(x) = m g between the fitted wells (a negative-stiffness
      device's origin is next to its unstable equilibrium). A force-driven record carries no weight
      in its equation (k0 is the force's offset): there the frame is not pinned.

    The uncertainty ``offset_se_m`` is the spread of the estimates from ``FRAME_PARTS`` parts of the
    record, scaled to the whole (sd / sqrt(parts)); ``spread=False`` skips the parts (``offset_se_m`` NaN:
    the plausibility check asks for it only when it warns). Returns a dict with ``offset_m`` (None when
    not pinned), ``offset_se_m``, ``method``.
    """
    rest = {w: rec.meta.get(f"z_{w}_rest") for w in ("minus", "plus")}
    try:
        rest = {w: float(v) for w, v in rest.items() if v is not None}
        if "z_rest" in rec.meta:  # the rest position of the one well an in-well record stays in
            rest["one"] = float(rec.meta["z_rest"])
    except ValueError:
        rest = {}
    if rec.input_name != "base_acc" and not rest:
        return {"offset_m": None, "method": "not pinned: a force-driven record carries no weight (k0 unknown)"}
    try:
        x, wells = _frame_anchors(rec)
        n_parts = int(np.clip(rec.duration // FRAME_PART_MIN_S, 2, FRAME_PARTS))
        edges = np.linspace(0, rec.n, n_parts + 1).astype(int) if spread else np.zeros(1, int)
        parts = []
        for a, b in zip(edges[:-1], edges[1:]):
            try:
                part = _frame_anchors(rec.segment(a, b))
            except Exception:
                continue
            if part[1]:  # only parts that visited both wells say where the origin between them is
                parts.append(part)
    except Exception as exc:  # a record too short or too poor for the fit: said, not pinned
        return {"offset_m": None, "method": f"not pinned: {' '.join(str(exc).split())}"}
    if "one" in wells:
        if "one" not in rest and len(rest) == 1:
            rest["one"] = next(iter(rest.values()))
        if "one" not in rest:
            return {
                "offset_m": None,
                "one_well": True,
                "method": "not pinned: the record stays in one well (no origin between wells to find); give that "
                "well's rest position as '# z_rest: VALUE' metadata [m]",
            }
    anchored = [w for w in rest if w in wells]
    if anchored:

        def offset(ws):
            return float(np.mean([rest[w] - ws[w] for w in anchored]))

        return {
            "offset_m": offset(wells),
            "offset_se_m": _se([offset(p[1]) for p in parts if all(w in p[1] for w in anchored)]),
            "method": "the fitted wells put at the rest positions of the file's metadata ("
            + ", ".join(f"z_{w}_rest = {rest[w]:g} m" for w in anchored)
            + ")",
        }
    if rec.input_name != "base_acc":
        return {"offset_m": None, "method": "not pinned: a force-driven record carries no weight (k0 unknown)"}
    return {
        "offset_m": -x,
        "offset_se_m": _se([-p[0] for p in parts]),
        "method": "K(0) = m g: the frame in which a quintic restoring force fitted to the record carries the "
        "weight at z = 0, between the wells",
    }


FRAME_SE_WARN_M = 2e-5
"""A frame standard error above this [m] is warned about: on the seed's cubic (k2 / 3 k3 = 0.5 mm) 20 um moves
k2 by 4 %."""

FRAME_PARTS = 4
"""Parts of the record (at most) whose separate frame estimates give the frame's standard error."""

FRAME_PART_MIN_S = 30.0
"""... each at least this long where the record allows (two parts at least): a 10 s part of a
cross-well record may visit one well only, and its frame estimate is then off by millimetres."""


def _se(estimates: list[float]) -> float:
    """Standard error of the whole record's estimate from its parts' (NaN with fewer than two)."""
    if len(estimates) < 2:
        return float("nan")
    return float(np.std(estimates, ddof=1) / np.sqrt(len(estimates)))


def pin_frame(rec):
    """``rec`` with z in the physical frame when its constant was unknown (``frame_offset``), and the
    offset, its uncertainty and the anchor in ``info["response"]``; otherwise ``rec`` itself."""
    from dataclasses import replace

    resp = rec.info.get("response", {})
    if rec.z is None or resp.get("z_constant_known", True):
        return rec
    fo = frame_offset(rec)
    resp = {**resp, "frame_offset_m": fo["offset_m"], "frame_offset_se_m": fo.get("offset_se_m"), "frame": fo["method"]}
    se = fo.get("offset_se_m")
    se = 0.0 if se is None else se
    if fo["offset_m"] is not None and not np.isfinite(se):
        resp["warnings"] = [
            *resp.get("warnings", []),
            "z's frame uncertainty could not be estimated (no two "
            "parts of the record visit both wells); k2 and k1 inherit the frame's error "
            "(dk2 = 3 k3 dC)",
        ]
    elif fo["offset_m"] is None:
        resp["warnings"] = [
            *resp.get("warnings", []),
            f"z's frame is unknown ({fo['method']}); the coefficients k0-k2 are in the record's own frame",
        ]
    elif se > FRAME_SE_WARN_M:
        resp["warnings"] = [
            *resp.get("warnings", []),
            f"z's frame is uncertain: offset {1e3 * fo['offset_m']:.3f} "
            f"+- {1e3 * se:.3f} mm (the record visits one well little?); k2 and k1 inherit it "
            "(dk2 = 3 k3 dC)",
        ]
    z = rec.z if fo["offset_m"] is None else rec.z + fo["offset_m"]
    return replace(rec, z=z, info={**rec.info, "response": resp})
