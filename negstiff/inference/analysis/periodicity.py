"""Periodicity analysis and Poincare sections of harmonically forced records (reference study section 3;
``docs/algorithms.md`` part C).

* The forcing phase comes from the *measured* input: a least-squares sinusoid at the known forcing
  frequency (not the nominal start time), so records whose sampling rate is not a multiple of the
  forcing frequency are sampled phase-synchronously: z and z' are interpolated (cubic spline of the
  band-limited signal) at t_n = t_phi + n T. The first and last ``EDGE_CYCLES`` cycles (and the
  acquisition's ``EDGE_SAMPLES``) are not compared: the filters' edge transients live there.
* The stated frequency is checked against the input's own spectrum first (``check_forcing_line``): a
  stated line that carries under ``STATED_LINE_FRACTION`` of the input's rms while another line
  dominates is refused (an analysis at the wrong frequency is meaningless); the measured line near the
  stated one is used, and a difference beyond ``FREQUENCY_MISLABEL`` is said (``forcing_mismatch``).
* Steady state: a record may begin with a transient, a jump between wells (a campaign's every step
  does). For each candidate lag p the differences |P_(n+p) - P_n| of the Poincare points are compared
  with their own level at the record's end: the steady state for p starts after the last cycle whose
  difference exceeds ``TRANSIENT_FACTOR`` x that level (and the tolerance), so a transient is cut off
  whatever it looked like (``steady_from_s``: where the steady state of the reported period begins).
* Period detection: for p in (1, 2, 3, 4, 5, 6, 8, 16), the residual r(p) = rms_n |P_(n+p) - P_n| over
  the steady state of the Poincare points P = (z / std z, z' / std z') scaled by the steady response's
  spread; the answer is the smallest p with r(p) < tol (and r(2p) < 2 tol when 2p is tested), after
  removing a slow quadratic trend from the points (drift of the integrated base displacement). The
  tolerance follows the noise: the sensor noise, estimated from the record, is propagated through the
  smoothing and the derivative to a Poincare point, and tol = max(0.02, 4 sqrt(2) x that); to it is
  added what the input's own cycle-to-cycle variation and the interpolation explain of the differences.
  The interpolation's error: any linear, shift-invariant interpolation of samples of a period-T signal
  (harmonics folded back or not) errs at t_n by a function of the forcing phase's offset between two
  samples, phi_n = frac(t_n fs), alone; a Fourier series in phi_n (``SAMPLING_HARMONICS``) on each
  branch takes it up, less what as many regressors explain of any sequence by chance (on a record
  acquired with under ``SAMPLING_REGRESSORS_BELOW`` samples a cycle; above, the error is negligible).
* Which verdict decides (``decided_by``): the time domain's, unless it cannot decide: no lag repeats
  within its tolerance but one within ``UNDECIDED_RATIO`` x it, or the tolerance itself rejects almost
  nothing (``MAX_DECISIVE_TOLERANCE``: a noise read from a coarse chaotic record's own broadband floor).
  The spectrum's sub-harmonic lines then name the period q, provided the folded lines k f / q carry
  ``LINE_FRACTION`` of the response's power (``spectrum.line_fraction``; a chaotic response's broadband
  spectrum does not) and the time residual of q is within that band; else (and far beyond the band: a
  chaotic or quasi-periodic record) the answer is ``None``.
* Amplitudes: for period p, the half peak-to-peak of z over each of p consecutive forcing cycles
  (averaged over the steady state): one amplitude per branch of the bifurcation map.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import fft as sp_fft
from scipy import ndimage, optimize, signal
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


def refine_frequency(u: np.ndarray, t: np.ndarray, f0: float, halfwidth: float) -> float:
    """The frequency [Hz] within ``f0`` +- ``halfwidth`` whose least-squares sinusoid (with a constant)
    leaves the least residual in u (a periodogram's peak, refined between its bins).
    """

    def misfit(f: float) -> float:  # the least-squares residual (not the amplitude: over a non-integer number
        w = 2 * np.pi * f  # of cycles sin and cos are not orthogonal, and the amplitude peaks off the line)
        X = np.column_stack([np.sin(w * t), np.cos(w * t), np.ones_like(t)])
        return float(np.sum((u - X @ np.linalg.lstsq(X, u, rcond=None)[0]) ** 2))

    res = optimize.minimize_scalar(misfit, bounds=(f0 - halfwidth, f0 + halfwidth), method="bounded",
                                   options={"xatol": 1e-7 * f0})  # fmt: skip
    return float(res.x)


FREQUENCY_SEARCH = 0.05
"""The measured forcing frequency is searched within this fraction of the stated one (a shaker
controller's error is a fraction of a percent); a line outside it is refused as another frequency."""


def measured_forcing(rec: Measurement, f_hz: float) -> dict[str, float]:
    """The forcing as the input channel says it is: its frequency near the stated ``f_hz`` (the
    strongest periodogram line within ``FREQUENCY_SEARCH``, refined by least squares), amplitude and
    phase (u ~ A sin(2 pi f (t - t0) + phi)). Raises ``MeasurementError`` when the input has no line there.
    """
    u, t = rec.u - rec.u.mean(), rec.t - rec.t0
    pad = 8 * rec.n
    spec = np.abs(sp_fft.rfft(u * np.hanning(rec.n), pad))
    freqs = np.fft.rfftfreq(pad, rec.dt)
    band = np.flatnonzero(np.abs(freqs - f_hz) <= FREQUENCY_SEARCH * f_hz)
    if band.size < 3:
        raise MeasurementError(f"{rec.source}: the record is too short to resolve its forcing near {f_hz:g} Hz")
    k = band[int(np.argmax(spec[band]))]
    if k in (band[0], band[-1]):
        raise MeasurementError(
            f"{rec.source}: the input has no spectral line within {100 * FREQUENCY_SEARCH:g} % of the stated forcing "
            f"{f_hz:g} Hz (its strongest there is at the band's edge, {freqs[k]:.4g} Hz): check the frequency"
        )
    f = refine_frequency(u, t, float(freqs[k]), 1.0 / rec.duration)
    amp, phi = forcing_phase(u, t, f)
    return {"stated_hz": float(f_hz), "measured_hz": f, "amplitude": amp, "phase_rad": phi}


STATED_LINE_FRACTION = 0.10
"""A stated forcing whose line carries under this fraction of the input's rms, while another line
dominates the input, is refused: the analysis would be of the wrong frequency."""

DOMINANT_LINE_FRACTION = 0.5
"""A line dominates the input when it carries over this fraction of the input's rms (a harmonic input:
1/sqrt(2) of its amplitude is its rms, all of it)."""

FREQUENCY_MISLABEL = 0.002
"""A measured forcing frequency further than this fraction from the stated one is used and said in a
warning (a shaker controller's error is a fraction of a per mille)."""


def _line_rms(u: np.ndarray, t: np.ndarray, f_hz: float) -> float:
    amp, _ = forcing_phase(u, t, f_hz)
    return amp / math.sqrt(2)


def check_forcing_line(rec: Measurement, f_hz: float) -> dict[str, float]:
    """The stated forcing frequency against the input's own spectrum, before any analysis.

    The input's dominant line (the Hann periodogram's highest above a few bins from 0 Hz, refined by
    least squares) and the line near the stated ``f_hz`` (``measured_forcing``'s band) are measured with
    the rms each carries. Raises ``MeasurementError`` (an ``InputError``, one line naming both
    frequencies) when the stated line carries under ``STATED_LINE_FRACTION`` of the input's rms while
    the dominant line, elsewhere, carries over ``DOMINANT_LINE_FRACTION``. Returns ``{"stated_hz",
    "dominant_hz", "stated_line_rms", "dominant_line_rms", "input_rms"}`` [Hz, input units].
    """
    u, t = rec.u - rec.u.mean(), rec.t - rec.t0
    u_rms = float(u.std())
    pad = 8 * rec.n
    spec = np.abs(sp_fft.rfft(u * np.hanning(rec.n), pad))
    freqs = np.fft.rfftfreq(pad, rec.dt)
    above = freqs > max(4.0 / rec.duration, 0.05 * f_hz)  # not the accelerometer's bias or drift
    if not above.any() or u_rms == 0:
        return {"stated_hz": float(f_hz), "dominant_hz": float("nan"), "stated_line_rms": 0.0,
                "dominant_line_rms": 0.0, "input_rms": u_rms}  # fmt: skip
    k = int(np.flatnonzero(above)[np.argmax(spec[above])])
    f_dom = refine_frequency(u, t, float(freqs[k]), 1.0 / rec.duration)
    band = np.abs(freqs - f_hz) <= FREQUENCY_SEARCH * f_hz
    k_stated = int(np.flatnonzero(band)[np.argmax(spec[band])]) if band.any() else int(np.argmin(np.abs(freqs - f_hz)))
    f_near = refine_frequency(u, t, float(freqs[k_stated]), 1.0 / rec.duration)
    out = {"stated_hz": float(f_hz), "dominant_hz": f_dom, "stated_line_rms": _line_rms(u, t, f_near),
           "dominant_line_rms": _line_rms(u, t, f_dom), "input_rms": u_rms}  # fmt: skip
    elsewhere = abs(f_dom - f_hz) > FREQUENCY_SEARCH * f_hz
    if (elsewhere and out["stated_line_rms"] < STATED_LINE_FRACTION * u_rms
            and out["dominant_line_rms"] > DOMINANT_LINE_FRACTION * u_rms):  # fmt: skip
        units = "m/s^2" if rec.input_name == "base_acc" else "N"
        raise MeasurementError(
            f"{rec.source}: the stated forcing {f_hz:g} Hz is not the input's: its line there carries "
            f"{out['stated_line_rms']:.2g} {units} rms of the input's {u_rms:.3g} "
            f"({100 * out['stated_line_rms'] / u_rms:.2g} %), its dominant line is at {f_dom:.4g} Hz "
            f"({out['dominant_line_rms']:.3g} {units} rms): check the forcing frequency"
        )
    return out


@dataclass(frozen=True)
class Poincare:
    """Phase-synchronous samples of a record: ``z[k, n]``, ``z_dot[k, n]`` at phase ``phases_deg[k]``
    of forcing cycle n.
    """

    phases_deg: np.ndarray
    z: np.ndarray
    z_dot: np.ndarray
    forcing_amplitude: float


@dataclass(frozen=True)
class _Synchronous:
    """A record's band-limited z as a cubic spline of time, and the times its input's phase passes
    zero (``starts``: one per forcing cycle, drift of the input's phase followed), with the input's
    amplitude and phase on each cycle (``cycle_amplitude``, ``cycle_phase``).
    """

    spline: CubicSpline
    starts: np.ndarray
    period: float
    t_end: float
    forcing: dict
    cycle_amplitude: np.ndarray
    cycle_phase: np.ndarray

    @property
    def forcing_amplitude(self) -> float:
        return self.forcing["amplitude"]


PHASE_SMOOTHING_CYCLES = 9
"""The input's phase is followed over this many forcing cycles (a running mean): a shaker's slow phase
drift moves the sampling instants with it, the input's noise does not jitter them."""


def _cycles(u: np.ndarray, t: np.ndarray, f_hz: float, t_first: float, n_cycles: int):
    """Amplitude and phase of u on each forcing cycle [t_first + n T, t_first + (n + 1) T), by least
    squares on sin, cos and a constant (sums over each cycle's samples).
    """
    w, period = 2 * np.pi * f_hz, 1.0 / f_hz
    idx = np.floor((t - t_first) / period).astype(int)
    keep = (idx >= 0) & (idx < n_cycles)
    idx, tt, uu = idx[keep], t[keep], u[keep]
    s, c = np.sin(w * tt), np.cos(w * tt)
    cols = (s, c, np.ones_like(s))
    G = np.empty((n_cycles, 3, 3))
    r = np.empty((n_cycles, 3))
    for i in range(3):
        r[:, i] = np.bincount(idx, cols[i] * uu, n_cycles)
        for j in range(i, 3):
            G[:, i, j] = G[:, j, i] = np.bincount(idx, cols[i] * cols[j], n_cycles)
    coef = np.linalg.solve(G, r[..., None])[..., 0]
    return np.hypot(coef[:, 0], coef[:, 1]), np.arctan2(coef[:, 1], coef[:, 0])


def _synchronous(rec: Measurement, f_hz: float) -> _Synchronous:
    if not (0 < f_hz < rec.fs / 4):
        raise MeasurementError(f"{rec.source}: forcing frequency {f_hz} Hz must lie in (0, fs/4)")
    n_cycles = int(rec.duration * f_hz) - 2
    if n_cycles < 8:
        raise MeasurementError(
            f"{rec.source}: too few samples for a periodicity analysis: {n_cycles + 2} forcing cycles, need at least 10"
        )
    t = rec.t - rec.t0
    forcing = measured_forcing(rec, f_hz)
    f, phi = forcing["measured_hz"], forcing["phase_rad"]
    period = 1.0 / f
    t_first = (-phi / (2 * np.pi)) % 1.0 * period  # first upward zero crossing of the input's sinusoid
    n_cycles = int((t[-1] - t_first) / period) - 1
    amp_n, phi_n = _cycles(rec.u, t, f, t_first, n_cycles)
    # the phase's drift relative to the fitted sinusoid, unwrapped around phi and followed slowly
    drift = np.unwrap(phi_n) - phi
    drift -= 2 * np.pi * np.round(np.median(drift) / (2 * np.pi))
    k = min(PHASE_SMOOTHING_CYCLES, n_cycles)
    slow = ndimage.uniform_filter1d(drift, k, mode="nearest")
    starts = t_first + period * np.arange(n_cycles) - slow / (2 * np.pi * f)
    spline = CubicSpline(t, bandlimited(rec.displacement, rec.fs, f))
    return _Synchronous(spline, starts, period, t[-1], forcing, amp_n, phi_n)


def _sections(sync: _Synchronous, phases_deg) -> Poincare:
    zk, vk = [], []
    for ph in phases_deg:
        tn = sync.starts + (ph / 360.0) * sync.period
        tn = tn[(tn >= 0) & (tn <= sync.t_end)]
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
    """Z low-passed (zero-phase, 4th-order Butterworth) at ``band_edge``: the same filter on every
    forcing cycle cannot create or destroy a periodicity, and it keeps broadband sensor noise out of
    the differentiated Poincare coordinate.
    """
    sos = signal.butter(4, band_edge(fs, f_hz), fs=fs, output="sos")
    return signal.sosfiltfilt(sos, z)


def noise_level(z: np.ndarray, fs: float) -> float:
    """Sensor noise std [same units as z], from the residual of a light smoothing, scaled for the
    part of white noise the smoothing keeps.
    """
    w = 7
    resid = z - signal.savgol_filter(z, w, 3)
    # a cubic 7-point Savitzky-Golay filter passes sum(h^2) of white noise; the residual keeps 1 - that
    h = signal.savgol_coeffs(w, 3)
    return float(resid.std() / math.sqrt(1 - np.sum(h**2)))


EDGE_CYCLES = 1
"""Forcing cycles at each end of a record that are not compared: the band-limited interpolation's and
the zero-phase filter's edge transients live there (plus ``EDGE_SAMPLES`` of the acquisition)."""

EDGE_SAMPLES = 12
"""Samples of the acquisition at each end beyond ``EDGE_CYCLES`` (a polyphase FIR's half length is 10)."""

SAMPLING_HARMONICS = 3
"""Harmonics of the sampling offset phi_n = frac(t_n fs) that take up the interpolation's error."""

TRANSIENT_FACTOR = 5.0
"""A cycle whose difference |P_(n+p) - P_n| exceeds this many times the steady level (the median of the
record's last half) and the tolerance belongs to a transient (Gaussian noise alone: a 5.9 sigma
excursion, probability 3e-8 a cycle)."""

MIN_STEADY_FRACTION = 0.25
"""The steady state judged is at least this fraction of the record's cycles (and ``MIN_STEADY_CYCLES``):
a transient longer than the rest leaves the record's end to be judged, and it fails."""

MIN_STEADY_CYCLES = 16

UNDECIDED_RATIO = 3.0
"""No lag within its tolerance but one within this many times it: the time domain cannot decide, the
spectrum does."""

MAX_DECISIVE_TOLERANCE = 0.5
"""A tolerance this large (of the steady response's spread; independent points differ by 2) rejects
almost nothing: a noise read from a coarse record's broadband floor (a chaotic response's own, at 7
samples a cycle) is no sensor's, and the time domain's "periodic" is then the spectrum's to confirm."""

SAMPLING_REGRESSORS_BELOW = 24.0
"""Samples a forcing cycle (as acquired) below which the interpolation's error is allowed for: above,
a spline of the band-limited signal errs by far less than any noise, and the regressors would only
take up chance."""

LINE_FRACTION = 0.9
"""The spectrum calls a response periodic with period q when the folded lines k f / q (k f / q below
``HARMONICS_COUNTED`` f) carry at least this fraction of its power (above f / 4q: a drift is not
counted); a chaotic response's broadband spectrum does not."""

HARMONICS_COUNTED = 24


def sampling_regressors(times: np.ndarray, fs: float, harmonics: int = SAMPLING_HARMONICS) -> np.ndarray:
    """(N, 2 ``harmonics``) sin and cos of 2 pi j phi_n, phi_n = frac(t_n fs): where each Poincare time falls
    between two samples acquired at ``fs``. A linear, shift-invariant interpolation of samples of a
    T-periodic signal s(t) = sum_k c_k exp(2 pi i k t / T) gives at t_n = t_0 + n T the value
    sum_k c_k exp(2 pi i k t_0 / T) G_k(phi_n), each G_k periodic in t with period 1 / fs: its error is a
    function of phi_n alone, folded harmonics included (ideal band-limited interpolation: the harmonics
    folded m times err by exp(-2 pi i m phi_n) - 1, a Fourier series in phi_n).
    """
    phi = np.mod(times * fs, 1.0)
    j = np.arange(1, harmonics + 1)
    arg = 2 * np.pi * phi[:, None] * j[None, :]
    return np.column_stack([np.sin(arg), np.cos(arg)])


def _explained(d: np.ndarray, x: np.ndarray | None, p: int, per_branch: bool = False) -> float:
    """The rms of what the regressors ``x`` (N, k) explain of the differences ``d`` (N, dim) at lag p, by
    least squares (``per_branch``: on each branch n mod p, unless the branches are short), less what as
    many regressors explain of any sequence by chance (k / (N - k) of the rest).
    """
    if x is None or x.size == 0:
        return 0.0
    sd = x.std(axis=0)
    x = x[:, sd > 1e-12] / sd[sd > 1e-12]
    n, k = x.shape
    if k == 0:
        return 0.0
    groups = p if per_branch and n // p >= 10 * k else 1
    fit = np.zeros_like(d)
    for b in range(groups):
        rows = slice(b, None, groups)
        fit[rows] = x[rows] @ np.linalg.lstsq(x[rows], d[rows], rcond=None)[0]
    k_all = k * groups
    chance = k_all / max(n - k_all, 1) * np.mean(np.sum((d - fit) ** 2, axis=1))
    return math.sqrt(max(0.0, float(np.mean(np.sum(fit**2, axis=1))) - chance))


def _detrended(points: np.ndarray) -> np.ndarray:
    """The points less a quadratic in the cycle index (a slow drift is no periodicity), their mean kept."""
    n_idx = np.arange(points.shape[0])
    out = points.copy()
    if points.shape[0] > 3:
        for k in range(points.shape[1]):
            out[:, k] -= np.polyval(np.polyfit(n_idx, out[:, k], 2), n_idx) - out[:, k].mean()
    return out


def steady_start(points: np.ndarray, p: int, tol: float, latest: int | None = None) -> int:
    """The first cycle of the steady state for lag p: after the last n before ``latest`` (default: the
    record's end) whose difference |P_(n+p) - P_n| exceeds ``TRANSIENT_FACTOR`` x its median over the
    record's last half and ``tol`` (a transient, a jump between wells), 0 when none does. Differences at
    or after ``latest`` are no transient (a transient is at the start: an excursion in the last cycles is
    the sensor chain's filter edge or an event the steady state's residual then carries).
    """
    d = np.sqrt(np.sum((points[p:] - points[:-p]) ** 2, axis=1))
    if d.size < 4:
        return 0
    threshold = max(TRANSIENT_FACTOR * float(np.median(d[d.size // 2 :])), tol)
    out = np.flatnonzero(d[:latest] > threshold)
    return int(out[-1] + 1) if out.size else 0


def _lag(
    points: np.ndarray, p: int, tol: float, regressors: np.ndarray | None, per_branch: bool = False
) -> tuple[float, float]:
    d = points[p:] - points[:-p]
    r = float(np.sqrt(np.mean(np.sum(d**2, axis=1))))
    x = None if regressors is None else regressors[p:] - regressors[:-p]
    return r, math.hypot(tol, _explained(d, x, p, per_branch))


def detect_period(
    points: np.ndarray, tol: float, inputs: np.ndarray | None = None
) -> tuple[int | None, dict[int, float], dict[int, float]]:
    """Smallest period p of a sequence of points (N, d), already scaled by the response's spread, whose
    residual r(p) = rms_n |P_(n+p) - P_n| over its steady state lies below its tolerance (and, where
    tested, r(2p) below twice its own: slow drift left in the points grows with the lag). See
    ``steady_period``, which also returns where each lag's steady state starts; ``inputs`` (N, k) are
    the per-cycle regressors (input amplitude and phase, sampling offset). Returns (period, residuals,
    tolerances).
    """
    found = steady_period(points, tol, inputs)
    return found["period"], found["residuals"], found["tolerances"]


def steady_period(
    points: np.ndarray, tol: float, regressors: np.ndarray | None = None, per_branch: bool = False
) -> dict[str, Any]:
    """For each lag p of ``PERIODS``: the steady state's first cycle (``steady_start``, at most the last
    ``MIN_STEADY_FRACTION`` of the cycles), the residual r(p) = rms |P_(n+p) - P_n| over it (the points
    detrended there) and its tolerance: ``tol`` (the noise's) combined with what the per-cycle
    ``regressors`` (N, k) explain of the differences. The tolerance takes what the shaker's own
    cycle-to-cycle variation (amplitude, phase) and the interpolation (the sampling offset) explain: a
    periodic response to a shaker whose amplitude breathes changes with it, an interpolated one errs
    by where its instants fall between samples (differently on each branch: ``per_branch``).

    Returns ``{"period", "residuals", "tolerances", "starts"}``: the smallest p with r(p) below its
    tolerance and, where tested on the same steady state, r(2p) below twice its own (None without).
    """
    n = points.shape[0]
    min_len = min(n, max(MIN_STEADY_CYCLES, math.ceil(MIN_STEADY_FRACTION * n)))
    r, tols, starts, doubled = {}, {}, {}, {}
    for p in PERIODS:
        if p >= n // 2:
            break
        s0 = steady_start(points, p, tol, latest=n - min_len)
        tail = _detrended(points[s0:])
        reg = None if regressors is None else regressors[s0:]
        if p >= tail.shape[0] // 2:
            break
        starts[p] = s0
        r[p], tols[p] = _lag(tail, p, tol, reg, per_branch)
        if 2 * p in PERIODS and 2 * p < tail.shape[0] // 2:
            doubled[p] = _lag(tail, 2 * p, tol, reg, per_branch)
    period = None
    for p, rp in r.items():
        if rp < tols[p] and (p not in doubled or doubled[p][0] < 2 * doubled[p][1]):
            period = p
            break
    return {"period": period, "residuals": r, "tolerances": tols, "starts": starts}


def line_fraction(z: np.ndarray, fs: float, f_hz: float, q: int, acquired_fs: float | None = None) -> float:
    """The fraction of z's power (Hann periodogram above f / 4q) within two bins of the lines k f / q,
    k < ``HARMONICS_COUNTED`` q, each folded about the acquisition's Nyquist frequency (``acquired_fs``,
    default ``fs``: a record interpolated from a coarser acquisition keeps its folded lines where the
    acquisition put them).
    """
    acquired_fs = fs if acquired_fs is None else acquired_fs
    x = (z - z.mean()) * np.hanning(z.size)
    spec = np.abs(sp_fft.rfft(x)) ** 2
    freqs = np.fft.rfftfreq(z.size, 1.0 / fs)
    counted = freqs >= f_hz / (4 * q)
    total = float(spec[counted].sum())
    if total <= 0:
        return 0.0
    lines = np.arange(1, HARMONICS_COUNTED * q) * f_hz / q
    folded = np.abs((lines + acquired_fs / 2) % acquired_fs - acquired_fs / 2)
    df = fs / z.size
    on = np.zeros(freqs.size, bool)
    for g in folded:
        c = int(round(g / df))
        on[max(c - 2, 0) : c + 3] = True
    return float(spec[counted & on].sum() / total)


SPECTRAL_LINE_RATIO = 100.0
"""A sub-harmonic line counts when its power exceeds this many times the spectrum's median around it
(20 dB: a periodogram of noise alone exceeds it with probability e^-69 per bin)."""


def subharmonic_lines(z: np.ndarray, fs: float, f_hz: float) -> dict[str, Any]:
    """The spectral cross-check of a period: for each candidate period q > 1, the strongest line at k f / q
    (k < 2 q, k not a multiple of q's divisors' lines: gcd(k, q) = 1) over the median of the spectrum
    around it (+- f / (4 q), the line's own bins left out), and the period the significant lines imply
    (the least common multiple of their q; 1 with none). A chaotic record's broadband spectrum has no
    such lines to speak of; the check is the periodicity's, not chaos's.
    """
    x = (z - z.mean()) * np.hanning(z.size)
    spec = np.abs(sp_fft.rfft(x)) ** 2
    df = fs / z.size
    ratios = {}
    for q in PERIODS[1:]:
        half = f_hz / (4 * q)
        if half < 8 * df:  # the record does not resolve lines this close
            break
        best = 0.0
        for k in range(1, 2 * q):
            if math.gcd(k, q) != 1:
                continue
            c = int(round(k * f_hz / q / df))
            w = int(half / df)
            near = spec[max(c - w, 0) : c + w + 1]
            around = np.concatenate([spec[max(c - w, 0) : max(c - 2, 0)], spec[c + 3 : c + w + 1]])
            if around.size == 0 or near.size == 0:
                continue
            # a Hann-windowed line peaks within a bin of its frequency (the forcing is measured to far less)
            best = max(best, float(spec[max(c - 1, 0) : c + 2].max() / max(np.median(around), 1e-300)))
        ratios[q] = best
    significant = [q for q, v in ratios.items() if v > SPECTRAL_LINE_RATIO]
    return {
        "line_ratio_db": {f"1/{q}": float(10 * np.log10(max(v, 1e-30))) for q, v in ratios.items()},
        "period": math.lcm(*significant) if significant else 1,
    }


def _spectral_shorter_period(
    zs: np.ndarray,
    t_rel: np.ndarray,
    tn: np.ndarray,
    starts: dict[int, int],
    ratios: dict[int, float],
    period: int,
    fs: float,
    f_hz: float,
    band_fs: float,
) -> tuple[int, dict[str, Any]] | None:
    """The spectrum's shorter period q for a time-domain period p = m q (m > 1), with the spectrum it read,
    or None: lag q within ``UNDECIDED_RATIO`` x its tolerance, and the lines of z over lag q's steady state
    (``starts[q]`` on) imply period q, carry ``LINE_FRACTION`` of its power, and were resolved out to 1/p
    (a record too short to resolve the lines of p leaves the time domain's verdict standing).
    """
    for q in sorted(ratios):
        if q >= period or period % q or ratios[q] > UNDECIDED_RATIO or q not in starts:
            continue
        wide = zs[t_rel >= float(tn[starts[q]])]
        lines = subharmonic_lines(wide, fs, f_hz)
        if lines["period"] != q or f"1/{period}" not in lines["line_ratio_db"]:
            continue
        lines["line_fraction"] = line_fraction(wide, fs, f_hz, q, band_fs)
        if lines["line_fraction"] >= LINE_FRACTION:
            return q, lines
    return None


def periodicity(
    rec: Measurement, f_hz: float, wells: tuple | None = None, noise: float | None = None, band_fs: float | None = None
) -> dict[str, Any]:
    """Period, amplitudes per branch and regime of a steady-state harmonically forced record.

    ``wells``: (z_minus, z_0, z_plus) or (z_minus, z_plus) when known (a lab measures the two rest
    positions; z_0 comes from a model), else None. ``noise`` [m] and ``band_fs`` [Hz]: the sensor
    noise and the sampling rate it was acquired at, for a record interpolated from a lower rate
    (default: estimated from ``rec``, at ``rec.fs``).

    The forcing's frequency and phase are the input's (``forcing``: stated and measured), the response
    is sampled where the input's phase passes zero on each cycle, and each candidate period's residual
    is reported beside its tolerance (``residuals``, ``tolerances``), with the spectrum's sub-harmonic
    lines as a cross-check (``spectrum``: their ratios over the floor and the period they imply).
    Both are judged on the steady state: ``steady_from_s`` [s from the record's start] is where it begins
    (a transient, a jump between wells before it), ``decided_by`` says which verdict gave the period
    (``"time"``: the Poincare points; ``"spectrum"``: the sub-harmonic lines, where the points repeat
    only within ``UNDECIDED_RATIO`` x their tolerance).
    """
    sync = _synchronous(rec, f_hz)
    band_fs = rec.fs if band_fs is None else band_fs
    t_rel = rec.t - rec.t0
    # the filters' edge transients: the first and last cycles (and a polyphase FIR's length) not compared
    edge = EDGE_CYCLES * sync.period + EDGE_SAMPLES / band_fs
    inside = (sync.starts >= edge) & (sync.starts <= sync.t_end - edge)
    if inside.sum() < 8:
        raise MeasurementError(
            f"{rec.source}: too few forcing cycles inside the record's edges for a periodicity analysis"
        )
    tn = sync.starts[inside]
    z0, v0 = sync.spline(tn), sync.spline(tn, 1)
    zs, vs = sync.spline(t_rel), sync.spline(t_rel, 1)
    # scales: the steady response's spread (the record's second half: transients are at the start), so a
    # period-1 orbit (Poincare points equal up to noise) gives r(p) ~ noise / response, not ~ 1
    late = (t_rel >= 0.5 * sync.t_end) & (t_rel <= sync.t_end - edge)
    scale_z, scale_v = max(zs[late].std(), 1e-15), max(vs[late].std(), 1e-15)
    pts = np.column_stack([z0 / scale_z, v0 / scale_v])
    # the input's own cycle-to-cycle variation: relative amplitude, and the phase the sampling did not follow
    slow = ndimage.uniform_filter1d(np.unwrap(sync.cycle_phase), min(PHASE_SMOOTHING_CYCLES, sync.starts.size),
                                    mode="nearest")  # fmt: skip
    inputs = np.column_stack([sync.cycle_amplitude / sync.cycle_amplitude.mean() - 1,
                              np.unwrap(sync.cycle_phase) - slow])[inside]  # fmt: skip
    # where each Poincare instant falls between the acquisition's samples: the interpolation's error
    coarse = band_fs / f_hz < SAMPLING_REGRESSORS_BELOW
    regressors = np.column_stack([inputs, sampling_regressors(tn, band_fs)]) if coarse else inputs
    # noise of a Poincare point: white sensor noise through the band limit fc (gain sqrt(2 fc / fs))
    # and its derivative (gain 2 pi fc sqrt(2 fc / (3 fs)))
    noise = noise_level(rec.displacement, rec.fs) if noise is None else noise
    fc = min(band_edge(rec.fs, f_hz), band_fs / 2)
    gz = math.sqrt(2 * fc / band_fs)
    gv = 2 * math.pi * fc * math.sqrt(2 * fc / (3 * band_fs))
    point_noise = math.hypot(noise * gz / scale_z, noise * gv / scale_v)
    # r(p) of a truly periodic record is sqrt(2) x the point noise; 4x that, and at least 2 %
    tol = max(0.02, 4 * math.sqrt(2) * point_noise)
    found = steady_period(pts, tol, regressors, per_branch=coarse)
    period, r, tols, starts = found["period"], found["residuals"], found["tolerances"], found["starts"]
    ratios = {p: r[p] / tols[p] for p in r}
    p_best = min(ratios, key=ratios.__getitem__) if ratios else None
    start = starts.get(period or p_best, 0) if ratios else 0
    steady_from = float(tn[start])
    f_meas = sync.forcing["measured_hz"]
    steady = t_rel >= steady_from
    spectrum = subharmonic_lines(zs[steady], rec.fs, f_meas)
    q = spectrum["period"]
    spectrum["line_fraction"] = line_fraction(zs[steady], rec.fs, f_meas, q, band_fs)
    spectral = q if spectrum["line_fraction"] >= LINE_FRACTION and q in r else None
    decided_by = "time"
    if period is not None and tol >= MAX_DECISIVE_TOLERANCE:
        # a tolerance that rejects nothing: the points' "periodic" is the spectrum's to confirm
        period, decided_by = spectral, "spectrum"
    elif period is None and ratios and ratios[p_best] <= UNDECIDED_RATIO and ratios.get(q, math.inf) <= UNDECIDED_RATIO:
        # the points nearly repeat, too little beyond their tolerance to call it chaos: the lines decide
        period, decided_by = spectral, "spectrum"
    elif period is not None and period > 1:
        # the points repeat only at a multiple p of a shorter lag q that nearly passes: a slow wander of z
        # that is no dynamics (a derived z's double-integrated base, high-passed near 0.5 Hz, wanders with a
        # period of some 18 forcing cycles: lag 16 cancels most of it, lag 4 little) or a true period p. The
        # lines decide, over the longest steady part lag q allows, where the record resolves the lines of p
        shorter = _spectral_shorter_period(zs, t_rel, tn, starts, ratios, period, rec.fs, f_meas, band_fs)
        if shorter is not None:
            period, spectrum = shorter
            decided_by = "spectrum"
    if decided_by == "time" and period is not None and spectral is not None and spectral > period:
        # the points repeat at p within their tolerance, and significant sub-harmonic lines (20 dB over the
        # floor) say p is m p: a period doubling whose split is below the points' noise allowance (a true
        # period 8 read as 4 with the split at a third of the tolerance); lag m p passes as well
        if spectral % period == 0 and ratios.get(spectral, math.inf) < 1.0:
            period, decided_by = spectral, "spectrum"
    if period is not None:
        start = starts[period]
        steady_from = float(tn[start])
    spectrum["agrees"] = spectrum["period"] == period if period is not None else None
    # amplitude per branch: half peak-to-peak of the band-limited z over each of p consecutive steady cycles
    p = period or 1
    grid = tn[start:][:-1, None] + sync.period * np.linspace(0, 1, 64, endpoint=False)
    per_cycle = sync.spline(grid)
    half_pp = 0.5 * (per_cycle.max(axis=1) - per_cycle.min(axis=1))
    amps = [float(np.mean(half_pp[k::p])) for k in range(p)]
    return {
        "period": period,
        "decided_by": decided_by,
        "steady_from_s": steady_from,
        "amplitudes": amps,
        "regime": classify_regime(rec.displacement[rec.t - rec.t0 >= steady_from], wells),
        "residuals": r,
        "tolerance": tol,
        "tolerances": tols,
        "noise_std": noise,
        "poincare_z": z0,
        "poincare_z_dot": v0,
        "forcing_amplitude": sync.forcing_amplitude,
        "forcing": sync.forcing,
        "spectrum": spectrum,
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


HARMONIC_SHARE = 0.9
"""A record whose input puts this share of its power in one spectral line (and its two neighbouring bins) is
harmonic: a shaker at one frequency. A random, swept or multisine input spreads it."""


def harmonic_frequency(rec) -> float | None:
    """The forcing frequency [Hz] of a harmonic record (``HARMONIC_SHARE`` of the input's power in one line,
    refined by least squares), else None.
    """
    u = rec.u - rec.u.mean()
    spec = np.abs(sp_fft.rfft(u * np.hanning(u.size))) ** 2
    if spec.sum() <= 0:
        return None
    k = int(np.argmax(spec[1:])) + 1
    if spec[max(k - 2, 0) : k + 3].sum() < HARMONIC_SHARE * spec.sum():
        return None
    return refine_frequency(u, rec.t - rec.t0, k * rec.fs / u.size, rec.fs / u.size)


ORBIT_DISTORTION = 0.1
"""A periodic response whose harmonics (2nd to 6th; a period-n orbit's subharmonics too) reach less than this
fraction of its fundamental's amplitude is nearly one sinusoid (``steady_orbit``). Measured on 24 s rig records of
the polynomial truth: in-well orbits at 9 Hz and 3, 8, 12 m/s^2 (harmonics 2.7, 5.5, 6.5 %) gave SINDy and NSI
coefficients that are not the device's (k1 -1.6e6, -1730, -230 N/m for 439; negative c); orbits across both wells at
5.5 Hz and 40, 60 m/s^2 (26, 33 %) and a 9 Hz run that crossed before it settled (12 %) gave SINDy's k1 within
0.01-2 %. On the device on a sprung fixture (1 kg, 25 Hz) at 9 Hz, the element's relative motion's period-1 orbits at
3 and 4 m/s^2 (harmonics 3.4, 4.8 %) gave SINDy's k2 13 and 21 % off (c 0 at 4 m/s^2) and NSI no model; its period-2
orbit at 8 m/s^2 (harmonics 8.9 %, and its subharmonics) gave SINDy's within 0.6 % (measured)."""


def _harmonic_share(rec: Measurement, f_hz: float, start_s: float, period: int = 1) -> float:
    """The amplitude of z's lines other than ``f_hz`` up to its 6th harmonic, on the orbit's own base frequency
    ``f_hz / period`` (root sum square: a period-1 orbit's 2nd to 6th harmonics; a period-n orbit's subharmonics too,
    which a linear system under this input does not make), over the fundamental's, by least squares on the record
    from ``start_s``.
    """
    t = rec.t - rec.t0
    keep = t >= start_s
    w = 2 * np.pi * f_hz / period * t[keep]
    cols = [np.ones(w.size)] + [fn(k * w) for k in range(1, 6 * period + 1) for fn in (np.cos, np.sin)]
    coef = np.linalg.lstsq(np.column_stack(cols), rec.displacement[keep], rcond=None)[0]
    amp = np.hypot(coef[1::2], coef[2::2])
    fundamental = amp[period - 1]
    return float(np.sqrt(np.sum(amp**2) - fundamental**2) / max(fundamental, 1e-300))


def steady_orbit(rec: Measurement) -> str | None:
    """What makes ``rec`` one nearly sinusoidal orbit at one frequency, or None: a harmonic record
    (``harmonic_frequency``) whose response is periodic (``periodicity``: period n, Poincare points and
    sub-harmonic lines) with harmonics under ``ORBIT_DISTORTION`` of its fundamental. Along such an orbit the
    restoring force's nonlinear terms show only through those small harmonics, and the fits' coefficients are not
    the device's (``ORBIT_DISTORTION``'s measurements). A chaotic or transient response, and a strongly nonlinear
    orbit (across both wells), pass. About 20 ms on a 24 s record at 512 Hz.
    """
    f_hz = harmonic_frequency(rec)
    if f_hz is None:
        return None
    try:
        # a check's only output is its refusal: the analysis's own warnings (and scipy 1.16's sosfiltfilt's
        # DeprecationWarning under numpy 2.5) are the characterisation's to say, not the identification's
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            found = periodicity(rec, f_hz)
    except MeasurementError:  # too few cycles to tell: not judged here
        return None
    if found["period"] is None:
        return None
    period, regime = found["period"], found["regime"]
    share = _harmonic_share(rec, f_hz, float(found.get("steady_from_s") or 0.0), int(period))
    if share >= ORBIT_DISTORTION:
        return None
    lines = "harmonics" if period == 1 else "harmonics and subharmonics"
    return (f"a harmonic record at {f_hz:.4g} Hz whose response is one nearly sinusoidal orbit (period {period}, "
            f"{regime}; its {lines} {100 * share:.2g} % of its fundamental)")  # fmt: skip
