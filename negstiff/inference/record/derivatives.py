"""Derivatives of a measured displacement for equation-error regression and for measured states.

Savitzky-Golay filters whose (window, order) is chosen from the record's own spectra: the sensor's
white-noise floor (the top fifth of the band, where the response has died out) and the signal's PSD
above it. The filter's error on the signal (bias) and the noise it passes are both predicted, and the
choice weighs them for the purpose (``derivative_window``); spectral differentiation is the fallback
when the band leaves no room for smoothing (e.g. the Silverbox, sampled at 3x its band).

Every velocity and start state of negstiff comes from this module: ``state_derivatives`` (the
weak form, SINDy, the discrepancy workflow, validation, refinement, the posterior's windows; purpose
"regression" or "state"; "band", ``smooth_and_differentiate``, is NSI's: a window fitted to keep the
response's band flat to 0.1 %, the gain its frequency-domain fit needs). A record computes each once
(``Measurement.states``). A start state for a
free run is ``state_derivatives(..., purpose="state")`` everywhere (``validation.start_state``
refines it by the system's own free run).
"""

from __future__ import annotations

import functools
import math

import numpy as np
from scipy import fft as sp_fft
from scipy import signal

WELCH_SEGMENT = 4096
"""The samples of the Welch PSD's segments (Hann, overlapping by half) that ``noise_floor`` reads a record with
(the whole record when shorter): ``weak.noise_excursion`` counts its averages from it."""


def coherence(u: np.ndarray, z: np.ndarray, fs: float, nperseg: int) -> tuple[np.ndarray, np.ndarray]:
    """``scipy.signal.coherence(u, z, fs=fs, nperseg=nperseg)`` with its defaults (Hann segments overlapping by
    half, each segment's mean removed), the segments transformed as one matrix: (f [Hz], coherence). The same
    numbers to 1e-14; scipy's own detrends and transforms segment by segment in Python (2,883 calls on a 300 s record
    at 512 Hz: 40 ms against 7 ms here, measured; 121 against 55 ms on 396 s at 2048 Hz), and every record's check
    of its response (``Measurement.require_response``) reads one.
    """
    step = nperseg - nperseg // 2
    window = signal.get_window("hann", nperseg)

    def spectra(x: np.ndarray) -> np.ndarray:
        seg = np.lib.stride_tricks.sliding_window_view(np.asarray(x, float), nperseg)[::step]
        return sp_fft.rfft((seg - seg.mean(axis=1, keepdims=True)) * window, axis=1)

    X, Z = spectra(u), spectra(z)
    pxz = np.mean(np.conj(X) * Z, axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        coh = np.abs(pxz) ** 2 / (np.mean(np.abs(X) ** 2, axis=0) * np.mean(np.abs(Z) ** 2, axis=0))
    return sp_fft.rfftfreq(nperseg, 1 / fs), coh


def noise_floor(z: np.ndarray, fs: float) -> tuple[float, np.ndarray, np.ndarray]:
    """White sensor-noise variance of ``z`` and the signal's own PSD: (sigma^2, f, S).

    The floor is the white plateau of the Welch PSD above the response's band: the longest run (at
    least 3) of consecutive bands (5 % of the Nyquist frequency each, from 30 % up) whose medians stay
    within a factor 1.5 of the run's median. The acquisition's anti-aliasing filter rolls the noise
    off near the Nyquist frequency, so the top of the band alone would read the floor far too low
    (measured: 400x on rig records with a flat delta-sigma filter). Without a plateau (the response
    fills the band, as in the Silverbox), the median over the top fifth is taken. S is the measured
    PSD minus the floor where it stands clearly (4x) above it: noise bins fluctuate about the floor,
    and weighted by omega^2 their positive excursions would be read as a broadband signal.
    """
    f, p = signal.welch(z - z.mean(), fs, nperseg=min(WELCH_SEGMENT, z.size))
    edges = np.arange(0.30, 1.0001, 0.05) * fs / 2
    med = np.array([np.median(p[(f >= a) & (f < b)]) for a, b in zip(edges[:-1], edges[1:], strict=False)])
    best: tuple[int, int] | None = None
    for i in range(med.size):
        for j in range(i + 3, med.size + 1):
            run = med[i:j]
            ref = np.median(run)
            if ref > 0 and np.all((run < 1.5 * ref) & (run > ref / 1.5)):
                if best is None or j - i > best[1] - best[0]:
                    best = (i, j)
    if best is not None:
        floor = float(np.median(p[(f >= edges[best[0]]) & (f < edges[best[1]])]))
    else:
        floor = float(np.median(p[f > 0.8 * fs / 2]))
    return floor * fs / 2, f, np.where(p > 4 * floor, p - floor, 0.0)


def _filter_response(w: int, order: int, d: int, fs: float, nf: int, df: float) -> tuple[np.ndarray, float]:
    """Frequency response of the Savitzky-Golay d-th derivative filter (window w, order) on the Welch
    grid f = k df, k < nf (centred), and the sum of its squared taps. Not cached itself: ``_filter_errors``
    keeps what the search reads of every candidate's response, per rate and grid (the responses depend on them
    only; 3456 freqz calls a fit of NSI and SINDy on one record had taken 2 s of its 17, measured).
    """
    f = np.arange(nf) * df
    h = signal.savgol_coeffs(w, order, deriv=d, delta=1.0 / fs, use="conv")
    # H(f_k) = sum_n h_n exp(-2 pi i f_k n / fs): on the grid f_k = k fs / N that is the N-point DFT of
    # h (freqz's polynomial evaluation at nf points took 2/3 of this function's time)
    n_dft = int(round(fs / df))
    if n_dft >= w and abs(n_dft * df - fs) <= 1e-9 * fs:
        H = sp_fft.rfft(h, n_dft)[:nf] * np.exp(1j * 2 * np.pi * f * (w // 2) / fs)
    else:
        H = signal.freqz(h, worN=f, fs=fs)[1] * np.exp(1j * 2 * np.pi * f * (w // 2) / fs)
    return H, float(np.sum(h**2))


@functools.lru_cache(maxsize=16)
def _filter_errors(
    orders: tuple[int, ...], max_window: int, fs: float, nf: int, df: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Every candidate (window, order) of ``derivative_window`` in its search order, the squared error of each
    one's first and second derivative filters against i w and (i w)^2 on the Welch grid (rows: candidates), and
    each first-derivative filter's sum of squared taps. Kept per rate and grid: the search is then two
    matrix-vector products (a loop over the 150 candidates took 4-5 ms a record, a tenth of a posterior window's
    preparation, measured).
    """
    combos = [(w, order) for order in orders for w in range(order + 2 + (order % 2 == 0), max_window + 1, 2)]
    jw = 2j * np.pi * np.arange(nf) * df
    err = {d: np.empty((len(combos), nf)) for d in (1, 2)}
    h2 = np.empty(len(combos))
    for i, (w, order) in enumerate(combos):
        for d in (1, 2):
            H, taps = _filter_response(w, order, d, fs, nf, df)
            err[d][i] = np.abs(H - jw**d) ** 2
            if d == 1:
                h2[i] = taps
    table = np.array(combos, dtype=int).reshape(-1, 2)
    for a in (table, err[1], err[2], h2):
        a.setflags(write=False)
    return table, err[1], err[2], h2


def derivative_window(
    z: np.ndarray,
    fs: float,
    purpose: str = "regression",
    orders=(3, 5, 7),
    max_window: int = 101,
    floor: tuple[float, np.ndarray, np.ndarray] | None = None,
) -> tuple[int, int, dict]:
    """Savitzky-Golay (window, order) for equation-error regression, from the record's own spectra
    (``noise_floor``): the one of least predicted coefficient bias b_a + b_v + e_v^2, where b_a, b_v are
    the filters' relative rms errors on the signal's spectrum, sum |H_d(f) - (2 pi i f)^d|^2 S(f) df
    (d = 2: the target z'', d = 1: the regressor z'), and e_v the relative rms sensor noise they pass
    into z', sigma^2 sum h_k^2. A target's filter error biases least squares to first order, a
    regressor's noise only to second order (attenuation); the target's noise does not bias it at all.
    A window fitted to the velocity's error alone (bias^2 + noise^2) is twice as wide and made k2 12 %
    and c_nl 6 % low on the rig's default record (measured). (0, 0): spectral differentiation
    predicts less.

    ``purpose="state"``: the window of least predicted velocity error b_v^2 + e_v^2, for the measured
    state a free run starts from (there the noise counts as much as the bias). ``floor``: ``noise_floor(z, fs)``
    when the caller has it (a record keeps its own: ``Measurement.noise_floor``).
    """
    sigma2, f, S = noise_floor(z, fs) if floor is None else floor
    df = f[1] - f[0]
    jw = 2j * np.pi * f
    power = {d: float(np.sum(np.abs(jw**d) ** 2 * S) * df) for d in (1, 2)}
    if power[1] == 0:
        return (
            0,
            0,
            {
                "noise_std": math.sqrt(sigma2),
                "acceleration_bias": 0.0,
                "velocity_noise": math.inf,
                "velocity_noise_std": math.inf,
            },
        )
    spectral_ev = math.sqrt(sigma2 * (2 * np.pi) ** 2 * (fs / 2) ** 2 / 3 / power[1])
    best = (spectral_ev**2, 0, 0, 0.0, spectral_ev)
    table, err1, err2, h2 = _filter_errors(tuple(orders), int(max_window), float(fs), f.size, float(df))
    if table.size:
        b_v = np.sqrt(err1 @ S * df / power[1])  # each candidate's relative rms bias of z'
        b_a = np.sqrt(err2 @ S * df / power[2])  # and of z''
        e_v = np.sqrt(sigma2 * h2 / power[1])  # the sensor noise it passes into z'
        cost = b_a + b_v + e_v**2 if purpose == "regression" else b_v**2 + e_v**2
        i = int(np.argmin(cost))  # the first of equal costs, as the candidates' order
        if cost[i] < best[0]:
            best = (float(cost[i]), int(table[i, 0]), int(table[i, 1]), float(b_a[i]), float(e_v[i]))
    return (
        best[1],
        best[2],
        {
            "noise_std": math.sqrt(sigma2),
            "acceleration_bias": best[3],
            "velocity_noise": best[4],
            "velocity_noise_std": best[4] * math.sqrt(power[1]),
        },
    )


def state_derivatives(
    z: np.ndarray, fs: float, purpose: str = "regression", floor: tuple[float, np.ndarray, np.ndarray] | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    """Smoothed z, z', z'' and what was done (``derivative_window``'s predictions, and "method"). A record
    computes them once and keeps them (``Measurement.states``), with its noise floor (``floor``).
    ``purpose="band"``: NSI's (``smooth_and_differentiate``: the window keeps the response's band flat, the
    gain a frequency-domain fit needs), its (window, order) in ``info["window"]``.
    """
    z = np.asarray(z, dtype=float)
    fs = float(fs)
    if purpose == "band":
        w, order = velocity_window(z, fs)
        zs, v = smooth_and_differentiate(z, fs, (w, order))
        a = signal.savgol_filter(z, w, order, deriv=2, delta=1.0 / fs) if w else np.gradient(v, 1.0 / fs)
        how = f"Savitzky-Golay, window {w}, order {order}" if w else "spectral differentiation"
        return zs, v, a, {"window": (w, order), "method": f"{how} (the response's band kept flat to 0.1 %)"}
    w, order, info = derivative_window(z, fs, purpose, floor=floor)
    if w:
        dt = 1.0 / fs
        info["method"] = (
            f"Savitzky-Golay, window {w}, order {order} (predicted: z'' filter bias "
            f"{100 * info['acceleration_bias']:.2f} %, z' noise {100 * info['velocity_noise']:.2f} % rms; "
            f"sensor noise {info['noise_std']:.3g} m)"
        )
        return (
            signal.savgol_filter(z, w, order),
            signal.savgol_filter(z, w, order, deriv=1, delta=dt),
            signal.savgol_filter(z, w, order, deriv=2, delta=dt),
            info,
        )
    # spectral differentiation of the even extension (periodic and continuous: no jump at the ends)
    n = z.size
    ext = np.concatenate([z, z[::-1]]) - z.mean()
    jw = 2j * np.pi * np.fft.rfftfreq(2 * n, 1 / fs)
    spec = sp_fft.rfft(ext)
    info["method"] = "spectral differentiation (the band leaves no room for smoothing)"
    return z.copy(), sp_fft.irfft(jw * spec, 2 * n)[:n], sp_fft.irfft(jw**2 * spec, 2 * n)[:n], info


def response_band_hz(z: np.ndarray, fs: float) -> float:
    """The response's band [Hz]: twice the frequency below which 99.9 % of the displacement's power lies (Welch),
    at most 0.45 fs (the displacement's, not the velocity's: differencing whitens the sensor noise).
    """
    f, p = signal.welch(z - z.mean(), fs, nperseg=min(WELCH_SEGMENT, z.size))
    cum = np.cumsum(p) / np.sum(p)
    return float(min(2 * f[np.searchsorted(cum, 0.999)], 0.45 * fs))


BASIS_SNR = 1000.0
"""A nonlinear basis (NSI's x^2, x^3, x'|x'|) is built from z and z' low-passed where the displacement's PSD falls
below this many times its white sensor noise's (30 dB), never below ``BASIS_BAND`` times the response's band
(``basis_band_hz``). Above it the channels hold mostly noise, which, in the nonlinear channels and in the output at
once, biases the subspace step's coefficients (errors in variables): on a Duffing's hammer record at 5 um (1 kHz;
the band states' window 5 samples) NSI's k3 came out -9 to -11 % over four seeds, and -0.6 to +0.7 % with the basis
low-passed (measured)."""

BASIS_BAND = 2.0
"""The basis's low-pass corner is at least this many times the response's band (``response_band_hz``), where the
4th-order zero-phase Butterworth's gain is 0.996: the response itself is not bent (at one band, its corner, -6 dB
run forward and back, the 2-DOF rig's k2 moved 2.4 % noise-free; at two, 0.04 %)."""


def basis_band_hz(z: np.ndarray, fs: float, floor: tuple[float, np.ndarray, np.ndarray] | None = None) -> float:
    """The corner [Hz] a nonlinear basis is low-passed at (``BASIS_SNR``): the highest frequency where the measured
    displacement ``z``'s PSD stands ``BASIS_SNR`` times above its white noise floor (``noise_floor``, or ``floor``
    where the caller has it), or ``BASIS_BAND`` times the response's band if higher. At or above 0.45 fs (a record
    whose noise lies far below its response everywhere) ``band_limited`` takes nothing off.
    """
    var, f, s = noise_floor(z, fs) if floor is None else floor
    above = np.flatnonzero(s > BASIS_SNR * var / (fs / 2))
    return max(BASIS_BAND * response_band_hz(z, fs), float(f[above[-1]]) if above.size else 0.0)


def band_limited(x: np.ndarray, fs: float, cut_hz: float) -> np.ndarray:
    """``x`` low-passed at ``cut_hz`` without phase (4th-order Butterworth, ``scipy.signal.sosfiltfilt``), or
    ``x`` itself where the cut is at 0.45 fs or above (nothing to take off).
    """
    if cut_hz >= 0.45 * fs:
        return x
    return signal.sosfiltfilt(signal.butter(4, cut_hz, fs=fs, output="sos"), x, axis=-1)


def velocity_window(z: np.ndarray, fs: float) -> tuple[int, int]:
    """Savitzky-Golay (window, polynomial order) fitted to the data: the widest window whose gain
    stays within 0.1 % of 1 up to twice the frequency below which 99.9 % of the displacement's power
    lies (the displacement's, not the velocity's: differencing whitens the sensor noise, which would
    fake a wide band exactly when smoothing is needed),
    trying cubic fits first, then quintic, then septic. Wide enough to average sensor noise, narrow
    enough not to bend the response (a fixed fs/70 window cut the Silverbox's response by several %).
    (0, 0) means no window passes: no smoothing, and the velocity by spectral differentiation.
    """
    f_band = response_band_hz(z, fs)
    for order in (3, 5, 7):
        best = None
        for w in range(order + 2, 53, 2):  # odd windows (order is odd)
            h = np.abs(signal.freqz(signal.savgol_coeffs(w, order), worN=[f_band], fs=fs)[1][0])
            if abs(h - 1) > 1e-3:
                break
            best = w
        if best is not None:
            return best, order
    return 0, 0


def smooth_and_differentiate(
    z: np.ndarray, fs: float, window: tuple[int, int] | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Savitzky-Golay smoothed displacement and velocity (``velocity_window``, or ``window`` when the caller
    has it), or, when the data's band leaves no room for smoothing, z itself and its spectral derivative.
    A record keeps them (``Measurement.states("band")``).
    """
    w, order = velocity_window(z, fs) if window is None else window
    if w:
        return (signal.savgol_filter(z, w, order), signal.savgol_filter(z, w, order, deriv=1, delta=1.0 / fs))
    zm = z.mean()
    spec = sp_fft.rfft(z - zm)
    v = sp_fft.irfft(2j * np.pi * np.fft.rfftfreq(z.size, 1 / fs) * spec, z.size)
    return z.copy(), v
