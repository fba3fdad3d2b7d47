"""Response sensors as labs have them: the relative displacement z from what was measured.

A lab measures the moving part's response with whichever sensor it has:

* ``z`` [m]: relative displacement (a laser triangulation sensor on the frame, or the reference study's laser
  minus the double-integrated base, already subtracted);
* ``z_dot`` [m/s]: relative velocity (a laser Doppler vibrometer on the moving part, mounted on the
  table, or any velocity sensor relative to the base);
* ``y`` [m] or ``y_dot`` [m/s]: the absolute displacement or velocity (a vibrometer on the ground),
  with the base's motion from ``base_disp`` or from the measured ``base_acc`` (the input); a ``y_dot`` of
  unknown gain (``*?``) has it estimated from the record's dynamics (``absolute_velocity_gain``);
* ``y_acc`` [m/s^2]: the moving part's absolute acceleration (an accelerometer on it).

``derive`` returns z together with a plain account of what was done and the error it carries.
What is lost on the way is said, never hidden:

* From a velocity, z is the integral of the measured signal (a quintic spline's antiderivative:
  a 40 Hz component sampled at 512 Hz is integrated within 1e-5, where the trapezoid rule errs by
  2 %), so its unknowns are the constant (the frame) and, over minutes, a drift (the sensor's zero off
  or wandering). The drift is separated from the device's stays in one well and removed where it
  matters (``velocity_to_z``; the record's physics take off its remnant: ``frame.drift_by_physics``).
  The integrated sensor noise is a random walk; its size over the record, sigma_v sqrt(T dt / 3), is
  reported.
* A base velocity or displacement from the base accelerometer is band-limited (``highpass_hz``): a
  shaker has no DC stroke, and accelerometer noise integrated grows without bound.
* From an acceleration of the moving part, z needs two integrations. A cross-well record keeps its wells
  (the double integral's drift separated from the stays in either well, as a velocity's); an in-well
  record's content below ``highpass_hz`` (which well it sits in) cannot be recovered from the signal and
  is not; the result says so and the frame is pinned by physics as for a velocity.
* The constant is never known from an integral. ``pin_frame`` estimates it from the physics: the
  restoring force at z = 0 (rods horizontal) carries the weight, K(0) = k0 = m g (g per unit mass
  when the mass is unknown). Among the candidate frames, the one whose origin lies between the wells
  is chosen (for a negative-stiffness device the origin is next to the unstable equilibrium).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy import signal
from scipy.interpolate import make_interp_spline

from negstiff.errors import MeasurementError
from negstiff.inference.record import stroke_spline
from negstiff.inference.record.derivatives import noise_floor
from negstiff.inference.record.impacts import find_impacts
from negstiff.models.table import integrate_fft
from negstiff.resources import one_blas_thread

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


DRIFT_CUTOFF_MAX_HZ = 0.05
"""The highest corner [Hz] of the slow part removed from an integrated velocity: the lower end of the field's
0.05-0.1 Hz high-pass of a vibrometer's integral (below any shaker's excitation band). The lower end because a
bistable device's own motion has slow content besides its stays in one well (on the tests' vibrometer record,
z erred by 0.47 mm rms after a 0.05 Hz corner, 0.80 mm after 0.1 Hz; wells 31 mm apart)."""

DRIFT_CUTOFF_FRACTION = 1.0 / 40.0
"""The corner is at most this fraction of the velocity's dominant frequency (its spectrum's peak): a decade
and a half below the dynamics, where a second-order corner changes their amplitude by 0.1 %."""

DRIFT_SPAN_FRACTION = 0.2
"""A slow part of the integral spanning more than this fraction of the record's own 5-95 % range is removed
even when its straight-line trend is not significant (a wander that comes back)."""


def _dominant_hz(v: np.ndarray, fs: float) -> float:
    """The frequency [Hz] of the largest line of a velocity's Welch spectrum (8 s segments), DC excluded."""
    from scipy.signal import welch

    f, p = welch(v - v.mean(), fs, nperseg=min(v.size, int(8 * fs)))
    p[0] = 0.0
    return float(f[int(np.argmax(p))])


def _slow_part(x: np.ndarray, fs: float, cutoff_hz: float, order: int = 2) -> np.ndarray:
    """The part of ``x`` below ``cutoff_hz``: block means over an eighth of the corner's period, low-passed
    forward and backward (Butterworth of ``order``: zero phase, scipy) and interpolated back to every sample.
    Averaging first keeps the filter well conditioned (a corner at 5e-5 of the sampling rate) and cheap.
    """
    from scipy.signal import butter, sosfiltfilt

    block = max(1, int(fs / (8 * cutoff_hz)))
    nb = x.size // block
    if nb < 16:  # shorter than two corner periods: only a constant and a ramp are seen as slow
        n = np.arange(x.size)
        return np.polyval(np.polyfit(n, x, 1), n)
    # a polynomial of the filter's order is taken off first and given back after: the drift's trend (a
    # sensor's offset integrated once or twice) passes whole, and the filter's ends see no ramp to pad
    t = np.arange(x.size) / x.size
    trend = np.polynomial.Polynomial.fit(t, x, order)
    x = x - trend(t)
    means = x[: nb * block].reshape(nb, block).mean(axis=1)
    centres = (np.arange(nb) + 0.5) * block - 0.5
    sos = butter(order, cutoff_hz, "lowpass", fs=fs / block, output="sos")
    slow = sosfiltfilt(sos, means, padtype="odd", padlen=min(nb - 1, 3 * int(fs / block / cutoff_hz)))
    return np.interp(np.arange(x.size), centres, slow) + trend(t)


def _occupancy(y: np.ndarray) -> np.ndarray:
    """Each sample's cluster centre among two (1-D two-means from the 10 % and 90 % quantiles): for a
    cross-well record, the well it is in, so a long stay in one well is a step, not a slow drift; for an
    in-well record, a square wave at the response's own frequency, whose slow part is nil.
    """
    c = np.quantile(y, [0.1, 0.9])
    for _ in range(20):
        split = 0.5 * (c[0] + c[1])
        low = y < split
        if low.all() or not low.any():
            return np.full_like(y, y.mean())
        new = np.array([y[low].mean(), y[~low].mean()])
        if np.allclose(new, c, rtol=0, atol=1e-12 * (abs(c).max() + 1e-300)):
            break
        c = new
    return np.where(y < 0.5 * (c[0] + c[1]), c[0], c[1])


def separate_drift(z: np.ndarray, fs: float, cutoff_hz: float, order: int = 2) -> np.ndarray:
    """The integral's drift: the slow part of ``z`` that is not the device moving between wells.

    A plain high-pass of a bistable record also removes a long stay in one well (it is slow too). Here the
    occupancy (which of two levels each sample is at, ``_occupancy``) is taken off before the slow part is
    taken, and the two are re-estimated in turn (three passes): a hop between wells is a step the drift does
    not follow, a sensor's offset or wander is a smooth curve it does. ``order``: the low-pass's (2 for a
    velocity's integral, a random walk's 1/f^2 spectrum; 4 for a double integral's 1/f^4, which a second
    order's complement would leak through).
    """
    drift = _slow_part(z, fs, cutoff_hz, order)
    for _ in range(3):
        drift = _slow_part(z - _occupancy(z - drift), fs, cutoff_hz, order)
    return drift - drift.mean()


def integral_warnings(info: dict[str, Any], units: str = "mm", scale: float = 1e3) -> list[str]:
    """What an integrated velocity's account (``velocity_to_z``'s info) calls for, in the record's units:
    ``units`` and ``scale`` (per metre) for a calibrated record, the column's own ("units as read") else.
    """
    out = []
    what, slope, se, n_s = info["integrated_from"], info["trend_m_s"], info["trend_se_m_s"], info["duration_s"]
    drift = info.get("drift")
    if drift is not None:
        out.append(
            f"z integrated from {what} drifted by {scale * drift['span_m']:.3g} {units} over the record "
            f"(a trend of {scale * slope * n_s:.3g} {units}, {abs(slope) / se:.1f} standard errors); its slow part "
            f"below {drift['cutoff_hz']:.3g} Hz that is not a stay in one well was removed ({drift['cutoff_from']}): "
            f"z's 5-95 % range {scale * drift['range_before_m']:.3g} -> {scale * drift['range_after_m']:.3g} {units}, "
            f"{drift['modes_after']} mode(s) of its histogram (was {drift['modes_before']})"
            + (
                f"; then a further {scale * drift['physics_span_m']:.3g} {units} by the record's physics (the "
                "restoring force's slow shift)"
                if "physics_span_m" in drift
                else ""
            )
        )
    elif abs(slope) > TREND_SIGMAS * se:
        out.append(
            f"z integrated from {what} drifts by {scale * slope * n_s:.3g} {units} over the record "
            f"({abs(slope) / se:.1f} standard errors): a DC offset of the velocity sensor ({slope:.3g} "
            f"{units.replace('mm', 'm')}/s)? It is not removed; a long stay in one well looks the same"
        )
    return out


def _modes(y: np.ndarray) -> int:
    """How many modes the histogram of ``y`` has (40 bins over its 1-99 % range, smoothed over three, a mode a
    local maximum holding at least 2 % of the samples' density peak and a dip of 20 % to its neighbour).
    """
    lo, hi = np.quantile(y, [0.01, 0.99])
    if not hi > lo:
        return 1
    h, _ = np.histogram(y, bins=40, range=(lo, hi))
    h = np.convolve(h, np.ones(3) / 3, mode="same")
    peaks = [i for i in range(1, h.size - 1) if h[i] >= h[i - 1] and h[i] > h[i + 1] and h[i] > 0.02 * h.max()]
    kept = peaks[:1]
    for p in peaks[1:]:
        if h[kept[-1] : p + 1].min() < 0.8 * min(h[kept[-1]], h[p]):
            kept.append(p)
        elif h[p] > h[kept[-1]]:
            kept[-1] = p
    return max(1, len(kept))


STAYS_OVER_ERROR = 5.0
"""A double integral's two-mode histogram is read as stays in two wells only when its well level's rms (``well_level``)
is this many times what the acceleration's noise alone leaves in it (``_double_integral_error`` above the drift's
corner): a cross-well device on the bench record 16.5; a stiffening structure's quiet accelerometers (0.01 % noise)
0.9-2.2, whose histogram after the drift's separation had two modes by the integral's leftover wander, and read as
cross-well their z erred by 0.1-0.25 mm."""


def well_level(z: np.ndarray, fs: float, dominant_hz: float) -> np.ndarray:
    """``z``'s part below a quarter of the motion's dominant frequency (zero-phase, 2nd-order Butterworth), about its
    mean: which well a cross-well motion sits in, apart from its oscillation in the well (zero where the cut is
    outside the record's band).
    """
    cut = 0.25 * dominant_hz
    if not 0 < cut < 0.45 * fs:
        return np.zeros_like(z)
    return signal.sosfiltfilt(signal.butter(2, cut, fs=fs, output="sos"), z - np.mean(z))


CROSSING_OSCILLATION = 1.0 / 3.0
"""Stays in two wells: the oscillation about the well (``z`` less its ``well_level``) has an rms at least this share of
the well level's. To leave a well a motion oscillates up to the barrier, about half the wells' separation away, which
is about the well level's rms (stays in both wells), and an oscillation's peaks are about three times its rms.
Measured: cross-well chaos read by an accelerometer 0.48-1.02 (six DOP853 records at 8 and 12 m/s^2 rms; the bench
harvester's 1.02); the real F-16 ground vibration test's wing and payload integrals 0.19 and 0.17, whose slow part is
their low-frequency error's wander, five times the structure's motion in the force's band (the wing's histogram had
two modes, and was read as a cross-well device's)."""


def oscillation_share(z: np.ndarray, level: np.ndarray) -> float:
    """The rms of ``z``'s oscillation about its well level (``well_level``) over the well level's rms
    (``CROSSING_OSCILLATION``; inf where the well level is zero).
    """
    spread = float(np.std(level))
    return float(np.std(z - np.mean(z) - level)) / spread if spread > 0 else math.inf


def velocity_to_z(
    v: np.ndarray,
    fs: float,
    what: str,
    units_known: bool = True,
    drift_cutoff_hz: float | None = None,
    always: bool = False,
) -> tuple[np.ndarray, dict[str, Any]]:
    """Z (up to a constant) from a relative velocity, and what the integral carries.

    A vibrometer's integral drifts over minutes (its zero is not exact and wanders), and a bistable device's
    z is not stationary either (it may sit in one well for a long stretch). The drift is separated from the
    stays (``separate_drift``: a hop between wells is a step, a drift a smooth curve) and removed below a
    corner chosen from the record's own spectrum (``DRIFT_CUTOFF_FRACTION`` of its dominant frequency, at most
    ``DRIFT_CUTOFF_MAX_HZ``) when it matters: a straight-line trend beyond ``TREND_SIGMAS`` batch-means
    standard errors, or a slow part spanning over ``DRIFT_SPAN_FRACTION`` of z's range. What was removed, and
    its effect on z's range and histogram, is in the account (``drift``) and a warning. ``drift_cutoff_hz``
    fixes the corner (0: never remove); ``always`` removes the drift whatever its size (a double integral's).
    """
    z = integrate_exact(v, fs)
    slope, se = _trend(z, fs)
    sigma_v = _noise_rms(v, fs)
    walk = sigma_v * math.sqrt(z.size / fs / fs / 3) if np.isfinite(sigma_v) else float("nan")
    info: dict[str, Any] = {
        "derived": f"z = integral of {what} (quintic spline antiderivative)",
        "trend_m_s": slope,
        "trend_se_m_s": se,
        "duration_s": z.size / fs,
        "integrated_from": what.split()[0],
        "velocity_noise_m_s": sigma_v,
        "integration_error_m": walk,
        "z_constant_known": False,
    }
    if drift_cutoff_hz != 0.0 and z.size >= 64:
        dominant = _dominant_hz(v, fs)
        if drift_cutoff_hz is None:
            cutoff = min(DRIFT_CUTOFF_MAX_HZ, DRIFT_CUTOFF_FRACTION * dominant)
            source = f"{DRIFT_CUTOFF_FRACTION:.3g} of the velocity's dominant {cutoff / DRIFT_CUTOFF_FRACTION:.3g} Hz"
            if cutoff >= DRIFT_CUTOFF_MAX_HZ:
                source = f"the field's {DRIFT_CUTOFF_MAX_HZ:g} Hz, below the velocity's dominant frequency"
        else:
            cutoff, source = float(drift_cutoff_hz), "as given"
        if cutoff * z.size / fs >= 2.0:  # at least two corner periods in the record, else a drift is a trend
            drift = separate_drift(z, fs, cutoff, 4 if always else 2)
            q = np.quantile(z, [0.05, 0.95])
            corrected = z - drift
            qc = np.quantile(corrected, [0.05, 0.95])
            if always or abs(slope) > TREND_SIGMAS * se or np.ptp(drift) > DRIFT_SPAN_FRACTION * (qc[1] - qc[0]):
                info["drift"] = {
                    "cutoff_hz": cutoff,
                    "dominant_hz": dominant,
                    "cutoff_from": source,
                    "span_m": float(np.ptp(drift)),
                    "rms_m": float(np.std(drift)),
                    "range_before_m": float(q[1] - q[0]),
                    "range_after_m": float(qc[1] - qc[0]),
                    "modes_before": _modes(z),
                    "modes_after": _modes(corrected),
                }
                z = corrected
    info["warnings"] = integral_warnings(info, *(("mm", 1e3) if units_known else ("(units as read)", 1.0)))
    return z, info


GAIN_SEARCH_DECADES = (-1.5, 2.5)
"""Where the gain of an absolute velocity read in its sensor's units is searched: these decades about the ratio
of the base's velocity rms to the channel's (a response moving a thirtieth to 300 times as much as the base)."""

GAIN_FIT_ROWS = 200_000
"""Rows of the gain's equation-error fit at most (every k-th sample beyond: a 400 s record at 2048 Hz in 0.1 s)."""

GAIN_SHARPNESS = 1.02
"""The residual at 0.8 and 1.25 times the estimated gain must exceed the minimum by this factor, else the base's
motion is too small beside the response for the record to say the gain (refused)."""


def _normal_least_squares(A: np.ndarray, scale: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The least-squares solution of A x = y through the normal equations of A's columns divided by ``scale`` (their
    spread: the Gram matrix's condition is then modest; the scaled matrix itself is never formed), solved by SVD in
    the small space (rank-deficient columns get the minimum-norm answer, as ``lstsq``'s): a tall A of 40 columns
    costs one matrix product, where LAPACK's tall least squares (SVD or QR) took ten times longer (measured on a
    41k-row gain fit).
    """
    with one_blas_thread():  # a 40-column product: a second thread does not pay (and waits on a busy machine)
        G = (A.T @ A) / np.outer(scale, scale)
        return np.linalg.lstsq(G, (A.T @ y) / scale, rcond=None)[0] / scale


def absolute_velocity_gain(
    v_read: np.ndarray, base_acc: np.ndarray, fs: float, source: str = "record"
) -> tuple[float, dict[str, Any]]:
    """The gain ``g`` [m/s per unit as read] of an absolute velocity read in its sensor's units (a vibrometer on
    the ground, its sensitivity not written down), from the record's own dynamics.

    z' = g v_read - b' (b' the base's velocity from its accelerometer): the base enters z at its known scale, so
    a wrong g leaves a multiple of the base's motion in z that no restoring force of z explains. For each trial g,
    z'' = g v_read' - b'' is fitted by least squares on a restoring force with no formula, a cubic B-spline over
    z's stroke (``stroke_spline``: any smooth device's force; the read channel's drift separated as
    ``velocity_to_z`` does, scaled by g; a ramp's first order in the fit, t K'(z)), viscous and quadratic damping
    and the base's acceleration, that acceleration's coefficient free (the measured point's participation in the
    input: 1 at the moving mass, less inboard on a beam; it is left to the response's scale,
    ``frame.calibrate_scale``). The force must be one the device can have: with a quintic, whose misfit of a
    magnet harvester's force a wrong gain partly took up, the gain of ``tests/law_records.py``'s chaotic magnet
    record came out 6.6 % high (0.01 % with the spline, measured).
    ``g`` minimises the fit's residual relative to g v_read': a log grid over ``GAIN_SEARCH_DECADES`` (twice: the
    drift found at the first one's gain), then Brent's method. Refused (``MeasurementError``) when the minimum
    lies at the grid's edge or is not sharper than ``GAIN_SHARPNESS``. Returns g and an account (the relative
    residual, the coefficient of the base's acceleration, the residual's rise at 0.8 g and 1.25 g).
    """
    from scipy.optimize import minimize_scalar
    from scipy.signal import butter, sosfiltfilt

    bv = integrate_fft(base_acc, fs, HIGHPASS_HZ, order=1)
    dominant = _dominant_hz(v_read, fs)
    corner = max(8.0 * dominant, 20.0)
    step = max(1, int(fs / (5.0 * corner)))  # the fit on a low-passed copy at 5 samples a corner period (speed)
    if step > 1:
        sos = butter(4, corner, "lowpass", fs=fs, output="sos")
        v_read, bv, base_acc = (sosfiltfilt(sos, x)[::step] for x in (v_read, bv, base_acc))
        fs = fs / step
    # z'' from a five-point derivative (its error at a fifth of the rate: 0.1 %)
    dv = np.gradient(v_read, 1.0 / fs)
    dv[2:-2] = (v_read[:-4] - 8 * v_read[1:-3] + 8 * v_read[3:-1] - v_read[4:]) * fs / 12.0
    vs, bs, ab = v_read, bv, base_acc
    z_read, z_base = integrate_exact(v_read, fs), integrate_exact(bv, fs)
    cutoff = min(DRIFT_CUTOFF_MAX_HZ, DRIFT_CUTOFF_FRACTION * dominant)
    trim = min(int(TRIM_S * fs), v_read.size // 10)
    rows = np.arange(trim, v_read.size - trim, max(1, (v_read.size - 2 * trim) // GAIN_FIT_ROWS))
    spread = float(np.sum((dv[rows] - dv[rows].mean()) ** 2))
    t_rows = rows / fs - 0.5 * v_read.size / fs

    def drift_of(z: np.ndarray) -> np.ndarray | float:
        """The integral's drift where ``velocity_to_z`` would remove it (a significant trend or a wide slow part)."""
        if cutoff * z.size / fs < 2.0:
            return 0.0
        drift = separate_drift(z, fs, cutoff)
        slope, se = _trend(z, fs)
        qc = np.quantile(z - drift, [0.05, 0.95])
        wide = np.ptp(drift) > DRIFT_SPAN_FRACTION * (qc[1] - qc[0])
        return drift if abs(slope) > TREND_SIGMAS * se or wide else 0.0

    # the drift is the read channel's (its zero off or wandering; the base's band-limited integral has none): it enters
    # z as g times itself. Found in z at the gain of a first search without it, then the search repeated
    per_gain: np.ndarray | float = 0.0

    def fit(g: float) -> tuple[float, float]:
        z = g * (z_read - per_gain) - z_base
        zc = z[rows] - np.median(z[rows])
        zc = zc / (np.std(zc) or 1.0)
        vz = g * vs[rows] - bs[rows]
        acc = g * dv[rows] - ab[rows]
        # the restoring force a spline over z's stroke (``stroke_spline``: any smooth device's); a ramp d = o t left
        # in z (the read channel's zero off) shifts it by -d K'(z): its first order, the spline's slopes times t
        # (they sum to zero: one left out)
        knots = stroke_spline.knots(zc)
        basis = stroke_spline.basis(zc, knots)
        n = basis.shape[1]
        # the columns written into one column-major matrix (each column contiguous: its spread and the products
        # below read it in one pass; stacked row-major they took half of each trial's time, measured)
        A = np.empty((zc.size, 2 * n + 2), order="F")
        A[:, :n] = basis
        np.multiply(t_rows[:, None], stroke_spline.slopes(zc, knots)[:, 1:], out=A[:, n : 2 * n - 1])
        A[:, -3] = vz
        np.multiply(vz, np.abs(vz), out=A[:, -2])
        A[:, -1] = ab[rows]
        scale = A.std(axis=0)
        scale[scale == 0] = 1.0
        theta = _normal_least_squares(A, scale, acc)
        r = acc - A @ theta
        # relative to the measured channel's own part (g v_read'): a small g's z is the base's motion, which the
        # base acceleration's free coefficient fits exactly, so the residual relative to z'' would favour it
        return float(r @ r / (g * g * spread)), float(theta[-1])

    g0 = float(np.std(bv) / (np.std(v_read) or 1.0))
    grid = g0 * 10.0 ** np.linspace(*GAIN_SEARCH_DECADES, 17)
    for _ in range(2):
        res = np.array([fit(g)[0] for g in grid])
        i = int(np.nanargmin(res))
        if i in (0, grid.size - 1):
            raise MeasurementError(
                f"{source}: y_dot's gain (*?) cannot be estimated: the record's dynamics fit best at the edge of the "
                f"searched range ({grid[0]:.3g}-{grid[-1]:.3g} m/s per unit as read); give the sensor's sensitivity"
            )
        per_gain = drift_of(grid[i] * z_read - z_base) / grid[i]
    opt = minimize_scalar(lambda lg: fit(math.exp(lg))[0], method="bounded",
                          bounds=(math.log(grid[i - 1]), math.log(grid[i + 1])), options={"xatol": 1e-3})  # fmt: skip
    g = float(math.exp(opt.x))
    best, coef = fit(g)
    rise = [fit(g * f)[0] / best for f in (0.8, 1.25)]
    if min(rise) < GAIN_SHARPNESS:
        raise MeasurementError(
            f"{source}: y_dot's gain (*?) cannot be estimated: the record's dynamics fit it as well at 0.8 and 1.25 "
            f"times (residual x{min(rise):.3f}): the base moves too little beside the response; give the "
            "sensor's sensitivity"
        )
    return g, {
        "gain": g,
        "residual_fraction": best,
        "input_coefficient": coef,
        "residual_rise": rise,
        "how": "the gain at which z = integral of (g y_dot - base velocity) obeys a restoring force with no formula "
        f"(a cubic spline over z's stroke, {stroke_spline.STROKE_INTERVALS} intervals) with viscous and quadratic "
        "damping best (equation error, the base acceleration's coefficient free)",
    }


def _double_integral_error(sigma_a: float, corner: float, fs: float) -> float:
    """The rms error [m] of white acceleration noise ``sigma_a`` integrated twice above ``corner`` [Hz]:
    var = sigma_a^2 / (fs/2) * int_{corner} df / (2 pi f)^4 = sigma_a^2 (2 / (3 fs)) / ((2 pi)^4 corner^3).
    """
    if not np.isfinite(sigma_a):
        return math.nan
    return sigma_a / (2 * math.pi * corner) ** 2 * math.sqrt(2 * corner / (3 * fs))


def _ring_down_integral(a: np.ndarray, fs: float, sigma_a: float, first_hit: int,
                        end: float) -> tuple[np.ndarray, dict]:  # fmt: skip
    """Z of an accelerometer's hammer record, no sample lost: at rest before its first hit (the pre-trigger, or the
    hit at its first sample) and after its ring-down (``end``: its last tenth's share, ``hammer_end_ratio``), so
    the acceleration is padded with that rest by four periods of the high-pass on each side and integrated twice
    above a corner a tenth of the displacement's dominant frequency (at least ``HIGHPASS_HZ``). Between two rests
    the velocity does not change: the acceleration's mean is the sensor's zero. The trim of a stationary record's
    integral (``TRIM_S``) would cut a hit at the record's start and leave an analyser's 1-4 s block nothing. What no
    integral holds is the content below the corner: an asymmetric well's mean shift with the amplitude (it follows
    the decay's envelope), which well the device rests in; a warning says so, as the stationary route's.
    """
    x = a - a.mean()
    f, p = signal.welch(x, fs, nperseg=min(4096, x.size))
    floor = float(np.median(p[f > 0.8 * f[-1]]))
    strong = (f >= HIGHPASS_HZ) & (p > 100 * floor)
    # the displacement's dominant frequency (p / f^4): an acceleration's PSD weights a light high mode by w^4
    f_dom = float(f[strong][np.argmax(p[strong] / f[strong] ** 4)]) if strong.any() else 10 * HIGHPASS_HZ
    corner = max(HIGHPASS_HZ, 0.1 * f_dom)
    pad = int(round(4.0 / corner * fs))
    z = integrate_fft(np.r_[np.zeros(pad), x, np.zeros(pad)], fs, corner, order=2)[pad : pad + x.size]
    return z, {
        "measured": "y_acc",
        "derived": f"z = double integral of y_acc above {corner:.3g} Hz (a tenth of the displacement's dominant "
        f"frequency), a hammer's record integrated from rest (before its first hit at sample {first_hit}, after its "
        f"ring-down): padded with {4.0 / corner:.3g} s of rest at each end, no sample cut, the acceleration's mean "
        "taken as the accelerometer's zero",
        "lost": f"z's constant and its content below {corner:.3g} Hz",
        "highpass_hz": corner,
        "acceleration_noise_m_s2": sigma_a,
        "integration_error_m": _double_integral_error(sigma_a, corner, fs),
        "z_constant_known": False,
        "warnings": [
            f"z was derived from an accelerometer's hammer record: its content below {corner:.3g} Hz is lost (an "
            "asymmetric well's mean shift with the amplitude, which well the device rests in); a quadratic stiffness "
            "k2 read from it is not reliable (a seed-like double well's z erred by a quarter, measured)",
            *(
                [
                    f"the hammer record ends still ringing ({100 * end:.0f} % of its loudest tenth's rms): its z, "
                    "integrated to a rest after the record, errs most over its last part"
                ]
                if end > RING_DOWN_WARN
                else []
            ),
        ],
    }


QUIET_BEFORE = 0.05
"""A hammer record's acceleration is at rest before its first hit when its pre-trigger's rms is under this share of
its loudest tenth's."""

RING_DOWN_END = 0.3
"""A hammer record's acceleration has rung down enough to be integrated from rest at its end when its last tenth's
rms is under this share of its loudest tenth's: the padding's rest then errs where the record ends (a Duffing hit
four times, its last tenth at 28 %: z within 6.3 % rms, 15 % over its last second; at 62 %: 22 %, measured);
above ``RING_DOWN_WARN`` a warning says so."""

RING_DOWN_WARN = 0.1
"""Above this share the integral's last part errs by a few per cent (``RING_DOWN_END``): said in a warning."""


def hammer_end_ratio(a: np.ndarray, first_hit: int) -> float | None:
    """The rms of a hammer record's acceleration over its last tenth against its loudest tenth's, or None when it
    is not at rest before its first hit (``first_hit`` [sample]: the pre-trigger's rms over ``QUIET_BEFORE`` of the
    loudest tenth's; a hit at the record's first samples has no pre-trigger and is taken at rest) or too short.
    """
    n = a.size // 10
    if n < 8:
        return None
    x = np.asarray(a, float) - float(np.mean(a))
    rms = np.sqrt(np.mean(x[: 10 * n].reshape(10, n) ** 2, axis=1))
    before = x[:first_hit]
    if before.size >= 8 and float(np.sqrt(np.mean(before**2))) >= QUIET_BEFORE * rms.max():
        return None
    return float(rms[-1] / rms.max())


def derive(
    cols: dict[str, np.ndarray], input_name: str, fs: float, source: str, units_known: bool = True
) -> tuple[np.ndarray, dict]:
    """The relative displacement z from the record's response columns, and what was done.

    Parameters
    ----------
    cols : the record's columns (contract names, SI units)
    input_name : ``"base_acc"`` or ``"force"`` (a force-driven rig's base does not move)
    fs : sampling rate [Hz]
    source : the file, for messages
    units_known : False when the response's scale is unknown (``*?``): warnings then speak its units as read

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
        z, info = velocity_to_z(cols["z_dot"], fs, "z_dot", units_known)
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
            gain: dict[str, Any] = {}
            y_dot = cols["y_dot"]
            if not units_known:  # y_dot's gain unknown (*?): the base's known motion in z says it
                g, gain = absolute_velocity_gain(y_dot, cols["base_acc"], fs, source)
                y_dot = g * y_dot
            z, info = velocity_to_z(
                y_dot - bv,
                fs,
                f"y_dot - base velocity (base_acc integrated above {HIGHPASS_HZ:g} Hz)",
                units_known,
            )
            if gain:
                info["gain"] = gain
                info["derived"] += f", g = {gain['gain']:.6g} m/s per unit as read (estimated: {gain['how']})"
        else:
            z, info = velocity_to_z(cols["y_dot"], fs, "y_dot (force input: the base does not move)", units_known)
        return z, {"measured": "y_dot", **info, **({"trim_s": TRIM_S} if base_moves else {})}
    # y_acc: the moving part's absolute acceleration
    a = cols["y_acc"] - cols["base_acc"] if base_moves else cols["y_acc"]
    wander = ""  # why a double integral with two modes in its histogram was not read as stays in two wells
    sigma_a = _noise_rms(a, fs)
    whole = "y_acc - base_acc" if base_moves else "y_acc"
    if a.size / fs * DRIFT_CUTOFF_MAX_HZ >= 2.0:
        # a cross-well record keeps its wells: integrated twice whole (the sensor's constant offset off), the
        # double integral's drift separated from the stays in either well as a vibrometer's is
        zc, vinfo = velocity_to_z(integrate_exact(a - a.mean(), fs), fs, f"{whole} (twice)", units_known, always=True)
        drift = vinfo.get("drift") or {}
        level = well_level(zc, fs, drift["dominant_hz"]) if drift.get("modes_after") == 2 else None
        two = level is not None and float(np.std(level)) >= STAYS_OVER_ERROR * (
            _double_integral_error(sigma_a, drift["cutoff_hz"], fs))  # fmt: skip
        share = oscillation_share(zc, level) if two and level is not None else math.nan
        stays = two and share >= CROSSING_OSCILLATION
        if two and not stays:  # two modes, but an oscillation too small to cross a barrier: the integral's wander
            wander = (f"{whole}'s double integral has two modes in its histogram, but its oscillation about them is "
                      f"{share:.2g} of their spread (a cross-well motion's is at least {CROSSING_OSCILLATION:.2g}): "
                      "read as the integral's slow error, not as stays in two wells")  # fmt: skip
        if stays:
            cut = drift["cutoff_hz"]
            return zc, {
                **vinfo,
                "measured": "y_acc",
                "derived": f"z = double integral of {whole} (quintic spline antiderivatives), its drift below "
                f"{cut:.3g} Hz separated from the stays in either well (two modes of its histogram: cross-well)",
                "acceleration_noise_m_s2": sigma_a,
                "integration_error_m": _double_integral_error(sigma_a, cut, fs),  # the separation's corner
            }
    force = cols.get("force")
    hits = find_impacts(force, fs) if (force is not None and not base_moves) else None
    first = None if hits is None else int(hits.starts[0])
    end = None if first is None else hammer_end_ratio(a, first)
    if first is not None and end is not None and end < RING_DOWN_END:
        return _ring_down_integral(a, fs, sigma_a, first, end)
    if first is not None and a.size <= 4 * TRIM_S * fs:  # too short for the stationary route's trim: say why here
        why = ("it is not at rest before its first hit" if end is None else
               f"it still rings at its end ({100 * end:.0f} % of its loudest tenth's rms)")  # fmt: skip
        raise MeasurementError(
            f"{source}: an accelerometer's hammer record is integrated from rest before its first hit to rest after "
            f"its ring-down, and {why}: record the whole ring-down (or measure z or z_dot)"
        )
    z = integrate_fft(a, fs, HIGHPASS_HZ, order=2)
    return z, {
        "measured": "y_acc",
        "derived": f"z = double integral of {'y_acc - base_acc' if base_moves else 'y_acc'} above {HIGHPASS_HZ:g} Hz",
        "lost": f"z's content below {HIGHPASS_HZ:g} Hz (for a bistable device: which well it sits in) is not in "
        "an acceleration record; only in-well records are fully described",
        "trim_s": TRIM_S,
        "acceleration_noise_m_s2": sigma_a,
        "integration_error_m": _double_integral_error(sigma_a, HIGHPASS_HZ, fs),
        "highpass_hz": HIGHPASS_HZ,
        "z_constant_known": False,
        "warnings": [
            f"z was derived from an accelerometer on the moving part: its content below {HIGHPASS_HZ:g} Hz is lost "
            "(for cross-well motion, which well the device sits in); results hold for in-well records only",
            *([wander] if wander else []),
        ],
    }
