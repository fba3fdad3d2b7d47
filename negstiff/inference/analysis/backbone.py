"""Backbone curves of a free decay: the instantaneous frequency and damping ratio against amplitude, measured and
predicted by a model.

A lightly damped nonlinear oscillator ringing down passes slowly through its family of periodic orbits, so
its frequency at each amplitude traces the backbone of its conservative part, and the decay rate of its
amplitude gives the damping at that amplitude (Feldman, *Hilbert Transform Applications in Mechanical
Vibration*, 2011, ch. 6, FREEVIB; the same curves SSMLearn and FrID draw from decays).

* **The decay** (``decay_start``): the record after its input's last activity (a release, a hammer's last
  hit, a shaker switched off): the input stands at its floor (its tail's median and median absolute deviation)
  from there on; an input identically zero is a decay from the first sample.
* **Hilbert** (``hilbert_backbone``): the response about its final rest, band-passed around the fundamental
  (zero-phase Butterworth, ``scipy.signal.sosfiltfilt``: its DC, which moves with amplitude in an asymmetric well,
  and its harmonics off), the analytic signal (``scipy.signal.hilbert``) gives the envelope a(t) (divided by the
  filter's gain at the instantaneous frequency) and the phase; both are averaged over one period (the ripple the
  remaining harmonics leave), the frequency is the phase's slope and the damping ratio
  zeta = sigma / sqrt(sigma^2 + w_d^2), sigma = -d ln a / dt. The amplitude is the fundamental harmonic's.
* **Peaks** (``peak_backbone``, the cross-check): each cycle between two upward crossings of the rest level
  (linear interpolation): frequency 1 / period, amplitude half the peak-to-peak (parabolic peaks), damping from
  the logarithmic decrement of successive cycles. The amplitude is the orbit's half peak-to-peak.
* **Predicted** (``predict_backbone``): the model's free decay from the record's state at the decay's start
  (``negstiff.models.simulate``, zero input), measured by the same estimator, so both curves carry that
  estimator's bias; with a posterior's draws (a list of models), the band the draws' curves span.
* **Conservative** (``conservative_backbone``): the model's exact backbone without damping, by quadrature over
  each orbit of energy E in a well (period T(E) = 2 int dz / sqrt(2 (E - V(z)) / m), substituted z =
  z_lo + (z_hi - z_lo)(1 - cos theta) / 2 so the turning points are regular), with both amplitudes (half the
  peak-to-peak, and the fundamental harmonic's, the Hilbert estimator's); its damping ratio is the slow flow's
  for viscous damping, dE/dt = -c <v^2> over the orbit (first order in c: the averaging method's, exact as
  c -> 0). It holds where the damping is light (a few per cent).
* **Forced response** (``forced_response``): the periodic responses the model predicts under a harmonic force
  (``negstiff.models.continuation.nfrc``, in frequency at fixed force levels, with Floquet stability), at the
  levels whose resonance reaches a quarter, half and nine tenths of the decay's largest amplitude (the model's
  damping over a harmonic orbit balanced by the force's work), drawn
  with the backbones as SSMLearn and FrID draw them. For light damping each curve's peak lies at the model's
  backbone frequency times sqrt(1 - 2 zeta^2) (a linear oscillator's displacement resonance: -0.0225 % at
  zeta = 1.5 %): the distance is reported, a check of the model against itself.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy import fft as sp_fft
from scipy import optimize, signal

from negstiff.errors import MeasurementError
from negstiff.inference.record.impacts import MAD_TO_SIGMA
from negstiff.inference.record.measurement import Measurement
from negstiff.models.structure import Structure, as_structure, simulate_structures

QUIET_DEVIATIONS = 10.0
"""The input is active where it stands more than this many floor deviations from its tail's median."""

MIN_CYCLES = 6
"""A decay shorter than this many periods of its response is refused: the band-pass and the period averages need
three periods at each end."""

EDGE_CYCLES = 3
"""Periods left out at each end of the band-passed decay (the zero-phase filter's and the Hilbert transform's
end effects)."""

NOISE_MARGIN = 100.0
"""The backbone stops where the envelope falls below this many times the band's noise rms (the band-passed
sensor noise): the phase's noise, about noise / amplitude radians, then moves a period's frequency by under
0.2 %; below, by several per cent."""

DAMPING_EDGE_CYCLES = EDGE_CYCLES + 2
"""Periods at each end of the band-passed decay whose log-envelope the decay rate's fit does not read: the end
effects reach further into a slope over ``DAMPING_CYCLES`` periods than into a period's frequency (measured on linear
decays to their ends: every period's damping within 5 % at 0.5 %, within 7 % at 0.1 %)."""

SMOOTH_CYCLES = 3
"""The phase and the log-envelope are smoothed by local quadratics over this many periods."""

DAMPING_CYCLES = 8
"""The decay rate is the slope of a local quadratic of the log-envelope over this many periods (over three, the
filter's and the harmonics' ripple moved a noise-free linear decay's damping by +-15 %; over eight, by +-3 %)."""


def decay_start(rec: Measurement) -> tuple[int, str]:
    """The first sample of the record's free decay, and how it was found (module docstring)."""
    if rec.info.get("decay"):
        return 0, "named a free decay by the caller (decay=True, --decay): from the first sample"
    u = np.asarray(rec.u, float)
    tail = u[-max(16, u.size // 5) :]
    offset = float(np.median(tail))
    floor = MAD_TO_SIGMA * float(np.median(np.abs(tail - offset)))
    dev = np.abs(u - offset)
    if dev.max() <= max(QUIET_DEVIATIONS * floor, 1e-12 * max(1.0, abs(offset))):
        return 0, f"the input ({rec.input_name}) stays at its floor throughout: a decay from the first sample"
    last = int(np.flatnonzero(dev > QUIET_DEVIATIONS * floor)[-1])
    start = min(last + 1 + max(2, int(0.002 * rec.fs)), rec.n)
    return start, (f"after the input's last activity at {rec.t0 + last / rec.fs:.4g} s ({rec.input_name} beyond "
                   f"{QUIET_DEVIATIONS:g} deviations of its floor, {floor:.3g}, about its tail's "
                   f"{offset:.3g})")  # fmt: skip


def _crossings(x: np.ndarray, fs: float) -> np.ndarray:
    """Times [s] of the upward zero crossings of ``x``, linearly interpolated."""
    i = np.flatnonzero((x[:-1] < 0) & (x[1:] >= 0))
    return (i + x[i] / (x[i] - x[i + 1])) / fs


def _parabolic(x: np.ndarray, k: int) -> float:
    """The extreme of the parabola through x[k-1], x[k], x[k+1]."""
    if k <= 0 or k >= x.size - 1:
        return float(x[k])
    a, b, c = x[k - 1], x[k], x[k + 1]
    den = a - 2 * b + c
    return float(b - 0.125 * (a - c) ** 2 / den) if den else float(b)


def _zeta(sigma: np.ndarray, w_d: np.ndarray) -> np.ndarray:
    return sigma / np.sqrt(sigma**2 + w_d**2)


def peak_backbone(x: np.ndarray, fs: float, floor: float = 0.0) -> dict[str, np.ndarray]:
    """Per cycle of ``x`` (a decay about its rest, rest = 0): time [s], half peak-to-peak amplitude, frequency
    [Hz] (1 / the period between upward crossings) and damping ratio (log decrement of successive cycles); the
    cycles until the amplitude first falls below ``floor`` [m] (the sensor's noise crosses zero at random).
    """
    tc = _crossings(x, fs)
    if tc.size < 3:
        return {k: np.array([]) for k in ("t_s", "amplitude_m", "f_hz", "zeta")}
    amp, mids = [], []
    for a, b in zip(tc[:-1], tc[1:], strict=True):
        i0, i1 = int(math.ceil(a * fs)), int(math.floor(b * fs)) + 1
        seg = x[i0:i1]
        hi, lo = int(np.argmax(seg)) + i0, int(np.argmin(seg)) + i0
        amp.append(0.5 * (_parabolic(x, hi) - _parabolic(x, lo)))
        mids.append(0.5 * (a + b))
    amp_a, period = np.array(amp), np.diff(tc)
    low = np.flatnonzero(amp_a < floor)
    if low.size:
        amp_a, period, mids = amp_a[: low[0]], period[: low[0]], mids[: low[0]]
    w_d = 2 * np.pi / period
    # the decrement between neighbouring cycles, centred on each (ends: one-sided)
    sigma = -np.gradient(np.log(np.maximum(amp_a, 1e-300)), np.array(mids)) if amp_a.size > 1 \
        else np.full(amp_a.size, np.nan)  # fmt: skip
    return {"t_s": np.array(mids), "amplitude_m": amp_a, "f_hz": w_d / (2 * np.pi), "zeta": _zeta(sigma, w_d)}


def _band(x: np.ndarray, fs: float, noise_rms: float) -> tuple[float, float]:
    """The band-pass around the fundamental: from the frequencies of the cycles above the noise (``peak_backbone``),
    0.6 of the lowest to 1.5 of the highest, below 1.9 of the lowest (the second harmonic out).
    """
    f = peak_backbone(x, fs, floor=NOISE_MARGIN * noise_rms)["f_hz"]
    if f.size < MIN_CYCLES:
        raise MeasurementError(f"the decay holds {f.size} cycles about its rest above {NOISE_MARGIN:g} times the "
                               f"sensor's noise; a backbone needs {MIN_CYCLES} at least")  # fmt: skip
    lo, hi = float(np.min(f)), float(np.max(f))
    return 0.6 * lo, min(1.5 * hi, 1.9 * lo, 0.45 * fs)


def hilbert_backbone(x: np.ndarray, fs: float, band: tuple[float, float] | None = None,
                     noise_rms: float = 0.0) -> dict[str, Any]:  # fmt: skip
    """Per period of ``x`` (a decay about its rest): time [s], the fundamental's amplitude [m], frequency [Hz]
    and damping ratio by the Hilbert transform of the band-passed decay (module docstring); ``noise_rms``: the
    sensor's white noise [m] (the backbone stops at ``NOISE_MARGIN`` times its band-passed share).
    """
    band = _band(x, fs, noise_rms) if band is None else band
    sos = signal.butter(4, band, btype="bandpass", fs=fs, output="sos")
    y = signal.sosfiltfilt(sos, x)
    # zero-padded to twice its length: the FFT's wrap-around would put the decay's large start beside its small end,
    # and the Hilbert kernel's 1/t tail would carry it there (measured: the last periods' damping doubled)
    z = signal.hilbert(y, N=2 * y.size)[: y.size]
    f_mean = math.sqrt(band[0] * band[1]) / 0.95  # the band's centre: 0.6 f_lo to 1.5 f_hi
    per = max(3, int(round(fs / f_mean)))
    # phase and log-envelope, each a local quadratic over SMOOTH_CYCLES periods (Savitzky-Golay): its slope is the
    # frequency and the decay rate, the ripple the remaining harmonics leave averaged out
    win = 2 * (SMOOTH_CYCLES * per // 2) + 1
    phase = np.unwrap(np.angle(z))
    w_s = signal.savgol_filter(phase, win, 2, deriv=1) * fs
    ln_raw = np.log(np.maximum(np.abs(z), 1e-300))
    gain = np.abs(signal.sosfreqz(sos, worN=np.clip(w_s / (2 * np.pi), 1e-9, None), fs=fs)[1]) ** 2  # filtfilt: |H|^2
    ln_a = signal.savgol_filter(ln_raw, win, 2) - np.log(np.maximum(gain, 1e-12))
    # the decay rate: the slope of a local quadratic of the log-envelope over DAMPING_CYCLES periods, each window clear
    # of the envelope's end effects (``DAMPING_EDGE_CYCLES``); within half a window of them, the nearest clear
    # window's: the nearest window from the record's ends reached into them, and a 0.5 % decay's first and last
    # periods read 0.13 % and 2.5 % (measured)
    cut = DAMPING_EDGE_CYCLES * per
    clear = slice(min(cut, x.size // 4), max(x.size - cut, x.size - x.size // 4))
    n_clear = clear.stop - clear.start
    win_d = min(2 * (DAMPING_CYCLES * per // 2) + 1, 2 * ((n_clear - 1) // 2) + 1)
    sigma_all = np.empty(x.size)
    sigma_all[clear] = -signal.savgol_filter(ln_raw[clear], win_d, 2, deriv=1) * fs
    first, last = clear.start + win_d // 2, clear.stop - 1 - win_d // 2
    sigma_all[:first], sigma_all[last + 1 :] = sigma_all[first], sigma_all[last]
    edge = EDGE_CYCLES * per
    idx = np.arange(edge, x.size - edge, per)
    if idx.size < 2:
        raise MeasurementError(f"the decay is too short for a Hilbert backbone: {x.size / fs:.3g} s at {f_mean:.3g} "
                               f"Hz (needs {2 * EDGE_CYCLES + 2} periods)")  # fmt: skip
    sigma = sigma_all[idx]
    amp = np.exp(ln_a[idx])
    noise_band = noise_rms * math.sqrt(2 * (band[1] - band[0]) / fs)
    f_idx = w_s[idx] / (2 * np.pi)
    keep = (amp > NOISE_MARGIN * noise_band * math.sqrt(2)) & (f_idx > band[0]) & (f_idx < band[1])
    if keep.sum() < 2:
        raise MeasurementError(f"the decay's envelope stands above {NOISE_MARGIN:g} times the band's noise for "
                               "under two periods: no backbone")  # fmt: skip
    last = int(np.flatnonzero(keep)[-1]) + 1 if keep.all() else int(np.argmin(keep))
    sl = slice(0, max(last, 2))
    w_d = w_s[idx][sl]
    return {"t_s": idx[sl] / fs, "amplitude_m": amp[sl], "f_hz": w_d / (2 * np.pi), "zeta": _zeta(sigma[sl], w_d),
            "band_hz": [float(band[0]), float(band[1])]}  # fmt: skip


def _decay_part(rec: Measurement) -> tuple[np.ndarray, int, np.ndarray, str]:
    """(every channel's decay about its rest (N, T) [m], its first sample, each channel's rest (N,) [m], how the
    start was found).
    """
    start, how = decay_start(rec)
    z = np.asarray(rec.channels, float)[:, start:]
    if z.shape[1] < 16:
        raise MeasurementError(f"{rec.source}: no free decay after the input's last activity ({how})")
    rest = np.median(z[:, -max(8, z.shape[1] // 10) :], axis=1)
    return z - rest[:, None], start, rest, how


NEIGHBOUR_MARGIN = 1.25
"""On a side where another mode rings, a mode's band reaches this factor beyond the frequencies its cycles span (not
the single DOF's 1.5, nor midway to the neighbour): the zero-phase band-pass's gain there is 0.86 (divided out), and
a neighbour twice as far off is 50 times down. With the edge midway (1.49 times it off), the tests' fixture's 25.7 Hz
mode leaked 4 % of itself into the 11.7 Hz mode's band, whose small-amplitude frequency read 0.18 % low (11.640 Hz
for the truth's 11.662; with this margin 11.661), and the other way 0.16 % high (measured)."""


def decay_modes(x: np.ndarray, fs: float, count: int) -> np.ndarray:
    """The frequencies [Hz] of the ``count`` strongest resonances of the decays ``x`` (N, T) about their rests, by
    frequency: the local maxima of the channels' summed periodograms (Hann window, each channel's normalised to
    its own power, so a stiff DOF's small motion counts as much as the device's), the strongest ``count`` of them
    (a structure of N DOFs rings in N modes at most; beyond them a nonlinear decay's peaks are its harmonics).
    """
    w = signal.windows.hann(x.shape[1])
    p = np.abs(sp_fft.rfft(x * w, axis=1)) ** 2
    p = (p / np.maximum(p.sum(axis=1, keepdims=True), 1e-300)).sum(axis=0)
    f = np.fft.rfftfreq(x.shape[1], 1.0 / fs)
    peaks, _ = signal.find_peaks(p[1:])  # the rest's residual at 0 Hz is no resonance
    peaks = peaks + 1
    top = peaks[np.argsort(p[peaks])[::-1][:count]]
    return np.sort(f[top])


def mode_band(x: np.ndarray, fs: float, noise_rms: float, modes_hz: np.ndarray) -> tuple[float, float]:
    """The band-pass of the backbone of the mode that dominates ``x`` (one channel's decay about its rest), among
    the decay's resonances ``modes_hz`` (``decay_modes``): ``_band`` of the cycles of ``x`` band-passed between
    the geometric means of that mode's frequency and its neighbours', kept inside them and, on a neighbour's side,
    within ``NEIGHBOUR_MARGIN`` of the cycles' frequencies. With one resonance (a single DOF's decay) there is no
    neighbour: ``_band`` of ``x`` itself. One ``MeasurementError`` where no band is left (modes near Nyquist).
    """
    if modes_hz.size < 2:
        return _band(x, fs, noise_rms)
    spec = np.abs(sp_fft.rfft(x * signal.windows.hann(x.size)))
    f = np.fft.rfftfreq(x.size, 1.0 / fs)
    k = int(np.argmax([spec[int(np.argmin(np.abs(f - fm)))] for fm in modes_hz]))
    lo = math.sqrt(modes_hz[k - 1] * modes_hz[k]) if k > 0 else 0.0
    hi = math.sqrt(modes_hz[k] * modes_hz[k + 1]) if k + 1 < modes_hz.size else 0.45 * fs
    if not lo < hi:
        raise MeasurementError(f"the decay's mode at {modes_hz[k]:.4g} Hz lies too near the Nyquist frequency "
                               f"({fs / 2:g} Hz) for its band (give --band)")  # fmt: skip
    sos = signal.butter(4, [lo, hi] if lo > 0 else hi, btype="bandpass" if lo > 0 else "lowpass", fs=fs,
                        output="sos")  # fmt: skip
    xf = signal.sosfiltfilt(sos, x)
    b_lo, b_hi = _band(xf, fs, noise_rms)
    f = peak_backbone(xf, fs, floor=NOISE_MARGIN * noise_rms)["f_hz"]
    if k > 0:
        b_lo = max(b_lo, lo, float(np.min(f)) / NEIGHBOUR_MARGIN)
    if k + 1 < modes_hz.size:
        b_hi = min(b_hi, hi, float(np.max(f)) * NEIGHBOUR_MARGIN)
    if not b_lo < b_hi:
        raise MeasurementError(f"no band is left for the decay's mode at {modes_hz[k]:.4g} Hz between its neighbours "
                               "(give --band)")  # fmt: skip
    return b_lo, b_hi


def _mode_cycles(x: np.ndarray, fs: float, band, several: bool) -> np.ndarray:
    """The cycles the peak-to-peak estimator reads: ``x`` itself where the decay rings in one mode; among
    ``several`` modes, ``x`` band-passed to the mode's ``band`` (zero-phase Butterworth, as ``hilbert_backbone``'s).
    """
    if not several:
        return x
    return signal.sosfiltfilt(signal.butter(4, band, "bandpass", fs=fs, output="sos"), x)


def _curves(d: dict[str, Any]) -> dict[str, Any]:
    return {k: (np.asarray(v).tolist() if isinstance(v, np.ndarray) else v) for k, v in d.items()}


def measure_backbone(rec: Measurement, dof: int | None = None,
                     band: tuple[float, float] | None = None) -> dict[str, Any]:  # fmt: skip
    """The measured backbones of a free-decay record (Hilbert, and peaks as a cross-check), arrays: of DOF ``dof``'s
    channel (1-based; default: the channel whose decay moves most), in the band of the mode that dominates it
    (``mode_band``; or ``band`` [Hz] as given: another mode's). A single DOF's decay rings in one mode; a
    structure's in up to N, each read where it dominates: after the higher modes' faster decay, a band-passed
    mode rings as a single DOF on its own backbone (the modes well apart and lightly damped).

    Returns
    -------
    dict
        ``hilbert`` and ``peaks`` (each ``t_s``, ``amplitude_m``, ``f_hz``, ``zeta`` arrays; the peaks' cut to the
        Hilbert's amplitude range), ``decay`` (its start [s], how it was found, the channel's rest [m] and initial
        state, every channel's in ``rests_m``, ``z0s_m``, ``v0s_m_s``), ``dof``, ``modes_hz`` (the decay's
        resonances, ``decay_modes``).
    """
    xs, start, rests, how = _decay_part(rec)
    n_dof = xs.shape[0]
    if dof is None:
        dof = int(np.argmax(np.std(xs, axis=1))) + 1
    elif isinstance(dof, bool) or not isinstance(dof, (int, np.integer)) or not 1 <= dof <= n_dof:
        raise MeasurementError(f"{rec.source}: the backbone's DOF is one of 1..{n_dof}, got {dof!r}")
    x = xs[dof - 1]
    noise = float(rec.channel_noise()[dof - 1]) if rec.n >= 256 else 0.0
    modes_hz = decay_modes(xs, rec.fs, n_dof)
    if band is not None and not (0 < band[0] < band[1] < 0.5 * rec.fs):
        raise MeasurementError(f"{rec.source}: a backbone's band is 0 < low < high < {0.5 * rec.fs:g} Hz (the "
                               f"record's Nyquist frequency), got {band[0]:g}-{band[1]:g}")  # fmt: skip
    band = mode_band(x, rec.fs, noise, modes_hz) if band is None else (float(band[0]), float(band[1]))
    hil = hilbert_backbone(x, rec.fs, band=band, noise_rms=noise)
    pk = peak_backbone(_mode_cycles(x, rec.fs, band, modes_hz.size > 1), rec.fs, floor=NOISE_MARGIN * noise)
    lo, hi = float(np.min(hil["amplitude_m"])), float(np.max(hil["amplitude_m"]))
    inside = (pk["t_s"] >= hil["t_s"][0]) & (pk["t_s"] <= hil["t_s"][-1])
    pk = {k: v[inside] for k, v in pk.items()}
    z_s, v_s = rec.free_run_states()
    return {
        "hilbert": hil,
        "peaks": pk,
        "decay": {
            "start_s": rec.t0 + start / rec.fs,
            "found": how,
            "duration_s": x.size / rec.fs,
            "rest_m": float(rests[dof - 1]),
            "z0_m": float(rec.channels[dof - 1, start]),
            "v0_m_s": float(v_s[dof - 1, start]),
            "noise_m": noise,
            "rests_m": rests.tolist(),
            "z0s_m": rec.channels[:, start].tolist(),
            "v0s_m_s": v_s[:, start].tolist(),
        },  # fmt: skip
        "amplitude_range_m": [lo, hi],
        "dof": dof,
        "modes_hz": modes_hz.tolist(),
    }


def _model_decay(model, x0: np.ndarray, fs: float, n: int, dof: int) -> np.ndarray:
    """DOF ``dof``'s channel of the model's free decay from the state ``x0`` (2N,), n samples at fs (zero force)."""
    res = simulate_structures(as_structure(model), np.zeros(n), 1.0 / fs, x0, input_kind="force")
    if res.diverged[0]:
        raise MeasurementError(f"the model's free decay from z0 = {x0[dof - 1]:.4g} m diverged "
                               f"({res.describe_failures()})")  # fmt: skip
    return np.asarray(res.z[0, dof - 1], float)


def _model_start(model, measured: dict[str, Any], rec: Measurement, offsets=None) -> tuple[np.ndarray, str]:
    """The model's initial state [z_1..z_N, z_1'..z_N'] for the record's decay: the record's, less each channel's
    zero (``offsets``: measured = physical + offset, a structure's identification's ``offsets_``), when its z is in
    the model's frame (a measured z); a derived z's constant unknown, the record's rests put on the model's static
    positions at the well of the nearest frequency.
    """
    d = measured["decay"]
    z0, v0 = np.asarray(d["z0s_m"]), np.asarray(d["v0s_m_s"])
    if _z_constant_known(rec):
        o = np.zeros(z0.size) if offsets is None else np.asarray(offsets, float)
        how = "the record's state at the decay's start" + (", less each channel's zero" if np.any(o) else "")
        return np.r_[z0 - o, v0], how
    s = as_structure(model)
    static = s.static_positions(s.element_equilibria().well(_rest_well(model, measured, rec)))
    return (
        np.r_[static + z0 - np.asarray(d["rests_m"]), v0],
        "the record's z (its constant unknown) about its rest, put on the model's well of the nearest frequency",
    )


def _check_dofs(model, rec: Measurement) -> None:
    n_model = as_structure(model).n_dof
    if n_model != rec.n_dof:
        raise MeasurementError(f"{rec.source}: the model has {n_model} DOF(s) and the record {rec.n_dof}")


def predict_backbone(model, rec: Measurement, measured: dict[str, Any] | None = None,
                     offsets=None) -> dict[str, Any]:  # fmt: skip
    """The backbone ``model`` (a ``Model``, or a ``Structure`` on a structure's record, ``offsets`` its channels'
    zeros) predicts for ``rec``'s decay: its free decay from the record's initial state, the same DOF's channel
    measured by the same estimators (``hilbert``, ``peaks``) and the same band-pass as the record's.
    """
    _check_dofs(model, rec)
    measured = measure_backbone(rec) if measured is None else measured
    dof = measured["dof"]
    n_model = as_structure(model).n_dof
    x0, how = _model_start(model, measured, rec, offsets)
    n = int(round(measured["decay"]["duration_s"] * rec.fs))
    z = _model_decay(model, x0, rec.fs, n, dof)
    x = z - float(np.median(z[-max(8, n // 10) :]))
    band = tuple(measured["hilbert"]["band_hz"])
    hil = hilbert_backbone(x, rec.fs, band=band)
    cycles = _mode_cycles(x, rec.fs, band, len(measured["modes_hz"]) > 1)
    return {"hilbert": hil, "peaks": peak_backbone(cycles, rec.fs),
            "initial": {"z0_m": float(x0[dof - 1]), "v0_m_s": float(x0[n_model + dof - 1]), "from": how}}  # fmt: skip


def on_amplitudes(curve: dict[str, Any], amplitudes: np.ndarray, key: str = "f_hz") -> np.ndarray:
    """A backbone's ``key`` interpolated at ``amplitudes`` [m] (NaN outside its range): a decay's, while its
    amplitude falls (where it stops falling, its end is the rest's and the noise's), or any curve's in order of
    amplitude.
    """
    a, v = np.asarray(curve["amplitude_m"]), np.asarray(curve[key])
    if a.size > 1 and a[0] > a[1]:
        rising = np.flatnonzero(np.diff(a) >= 0)
        stop = int(rising[0]) + 1 if rising.size else a.size
        a, v = a[:stop], v[:stop]
    order = np.argsort(a)
    return np.interp(amplitudes, a[order], v[order], left=np.nan, right=np.nan)


def conservative_backbone(model, well: str, amplitude_max: float, n: int = 40, nodes: int = 400) -> dict[str, Any]:
    """The exact backbone of ``model``'s conservative part in ``well`` up to the half peak-to-peak
    ``amplitude_max`` [m] (module docstring): ``peak_amplitude_m`` (half peak-to-peak), ``amplitude_m`` (the
    fundamental harmonic's), ``f_hz`` and ``zeta`` (viscous c's slow flow, first order), arrays of ``n`` orbits.
    """
    eq = model.equilibria()
    zs = eq.well(well)
    m = model.m

    def v(z):
        return model.potential(z) - model.potential(zs)

    barrier = eq.z_0
    lo_lim = barrier if (barrier is not None and barrier < zs) else zs - 1.0
    hi_lim = barrier if (barrier is not None and barrier > zs) else zs + 1.0
    e_max = float(min(v(min(zs + amplitude_max, hi_lim)), v(max(zs - amplitude_max, lo_lim))))
    if barrier is not None:  # the orbits of the well: below its barrier
        e_max = min(e_max, 0.999 * float(v(barrier)))
    th = (np.arange(nodes) + 0.5) * np.pi / nodes  # midpoints: the turning points' regular integrand
    out: dict[str, list[float]] = {"peak_amplitude_m": [], "amplitude_m": [], "f_hz": [], "zeta": [], "energy_j": []}
    for e in e_max * np.geomspace(1e-6, 1.0, n):
        z_lo = optimize.brentq(lambda z, e=e: v(z) - e, lo_lim, zs)
        z_hi = optimize.brentq(lambda z, e=e: v(z) - e, zs, hi_lim)
        half = 0.5 * (z_hi - z_lo)
        z = z_lo + half * (1 - np.cos(th))
        speed = np.sqrt(np.maximum(2 * (e - v(z)) / m, 1e-300))
        dt = half * np.sin(th) / speed * (np.pi / nodes)
        period = 2 * dt.sum()
        t = np.cumsum(dt) - dt / 2
        w = 2 * np.pi / period
        c1 = 4 / period * np.sum(z * np.cos(w * t) * dt)  # the fundamental of the even orbit z(t) = z(-t)
        out["peak_amplitude_m"].append(half)
        out["amplitude_m"].append(abs(c1))
        out["f_hz"].append(1 / period)
        out["energy_j"].append(e)
        out["zeta"].append(2 * np.sum(speed**2 * dt) / period)  # <v^2> over the orbit, turned into zeta below
    res: dict[str, Any] = {k: np.array(val) for k, val in out.items()}
    # slow flow: dE/dt = -c <v^2>; d ln a / dt = (d ln a / dE) dE/dt; zeta = -(d ln a/dt) / w (first order in c)
    dlna_de = np.gradient(np.log(res["amplitude_m"]), np.log(res["energy_j"])) / res["energy_j"]
    res["zeta"] = model.c * res["zeta"] * dlna_de / (2 * np.pi * res["f_hz"])
    res["well"] = well
    return res


FORCED_LEVELS = (0.25, 0.5, 0.9)
"""The forced responses' levels: the force whose resonance reaches these fractions of the decay's largest amplitude
(``_resonant_force``)."""

FORCED_SPAN = (0.8, 1.2)
"""The forced responses' frequency range: these factors times the lowest and the highest frequency the model's
backbone or the decay reaches."""


def _z_constant_known(rec: Measurement) -> bool:
    """Whether the record's z is in the model's frame (a measured z), not a derived one with its constant unknown."""
    return (rec.info.get("response") or {}).get("z_constant_known", True)


def _rest_well(model, measured: dict[str, Any], rec: Measurement, offsets=None) -> str:
    """The model's well the record's decay rests in: the one whose static positions are nearest the record's rests
    (less each channel's zero, ``offsets``) where z is in the model's frame, else the one with a linear frequency
    nearest the decay's at its smallest amplitude.
    """
    s = as_structure(model)
    eq = s.element_equilibria()
    wells = {n: w for n, w in (("minus", eq.z_minus), ("plus", eq.z_plus)) if w is not None}
    if _z_constant_known(rec):
        rests = np.asarray(measured["decay"]["rests_m"]) - (0.0 if offsets is None else np.asarray(offsets, float))
        return min(wells, key=lambda n: float(np.linalg.norm(s.static_positions(wells[n]) - rests)))
    f_small = measured["hilbert"]["f_hz"][-1]

    def distance(well: str) -> float:
        K, _ = s.linear(well)
        w2 = np.linalg.eigvals(np.linalg.solve(np.diag(s.masses), K)).real
        return float(np.min(np.abs(np.sqrt(np.maximum(w2, 0.0)) / (2 * np.pi) - f_small)))

    return min(wells, key=distance)


def _resonant_force(model, z_well: float, amplitude: float, cons: dict[str, Any], nodes: int = 256) -> float | None:
    """The harmonic force [N] whose resonance reaches ``amplitude`` [m] (half the peak-to-peak) about ``z_well``:
    the energy the model's damping (every velocity-dependent force, its effects' too) takes from the harmonic orbit
    z = z_well + a cos(w t) at the backbone's frequency there, per cycle, over pi a (at resonance the force's work
    meets it: F pi a = E). None where the backbone does not reach the amplitude. With viscous damping alone it is
    the linear F = 2 zeta k a; a quadratic damping's grows with the amplitude (on a measured magneto-mechanical
    decay NSI's c_nl put the top curve's peak at a quarter of its linear target, measured).
    """
    f = np.interp(amplitude, cons["peak_amplitude_m"], cons["f_hz"], left=np.nan, right=np.nan)
    if not np.isfinite(f):
        return None
    w = 2 * np.pi * f
    th = 2 * np.pi * (np.arange(nodes) + 0.5) / nodes
    z = z_well + amplitude * np.cos(th)
    v = -amplitude * w * np.sin(th)
    dissipative = np.asarray(model.total_force(z, v)) - np.asarray(model.total_force(z, 0.0 * v))
    energy = float(np.sum(dissipative * v) * (2 * np.pi / w) / nodes)  # over one period
    return energy / (np.pi * amplitude) if energy > 0 else None


def forced_response(model, well: str, amplitude_max: float, f_range: tuple[float, float],
                    levels: Sequence[float] = FORCED_LEVELS, force_unit: str = "N") -> dict[str, Any]:  # fmt: skip
    """The periodic responses of ``model`` about ``well`` under f = F sin(2 pi f t), continued in frequency over
    ``f_range`` [Hz] at the forces whose resonance reaches ``levels`` times ``amplitude_max`` [m] (``_resonant_force``:
    the model's damping over a harmonic orbit at its backbone's frequency).

    Returns
    -------
    dict
        ``curves``: per level ``force_n``, ``f_hz``, ``amplitude_m`` (half the peak-to-peak, the peaks backbone's
        amplitude), ``stable`` lists, ``peak`` (``f_hz``, ``amplitude_m``) and ``peak_off_backbone_percent`` (the
        peak's frequency against the model's conservative backbone at the peak's amplitude); ``well``;
        ``warnings`` (a level not drawn: beyond the well's orbits, no dissipation, not followed; a peak more than
        20 % from its target); ``force_unit``: ``force_unit``, the forces' unit (``"N/kg"`` for a model per unit
        mass: its force is the device's per kilogram of moving mass, ``force_unit_of``).
    """
    from negstiff.models.continuation import ContinuationError, nfrc

    eq = model.equilibria()
    z_well = eq.well(well)
    unit = force_unit
    out: dict[str, Any] = {"well": well, "f_range_hz": list(f_range), "curves": [], "warnings": [],
                           "force_unit": unit}  # fmt: skip
    if not float(model.stiffness(z_well)) > 0:
        out["warnings"].append(f"no forced response drawn: the model's {well} well is not stable (K' <= 0)")
        return out
    cons = conservative_backbone(model, well, amplitude_max * 1.5, n=80)
    reach = float(np.max(cons["peak_amplitude_m"]))
    for level in levels:
        target = level * amplitude_max
        # the force whose work meets the model's damping over the orbit (every velocity-dependent term: a negative
        # c with a positive c_nl can still dissipate); none where the well's backbone does not reach the target
        # (beyond its barrier) or the orbit gains energy: said, not replaced by a linear guess
        force = _resonant_force(model, z_well, target, cons) if target <= reach else None
        if force is None:
            why = (f"beyond the {well} well's orbits (they reach {1e3 * reach:.3g} mm)" if target > reach
                   else "the model's damping does not dissipate over that orbit")  # fmt: skip
            out["warnings"].append(f"no forced response at {1e3 * target:.3g} mm: {why}")
            continue
        try:
            res = nfrc(model, freq=tuple(f_range), amplitude=force, well=well, input_kind="force", max_period=1)
        except ContinuationError as exc:
            out["warnings"].append(f"the forced response at {force:.3g} {unit} was not followed: {exc}")
            continue
        pts = [p for b in res["branches"] if b["period"] == 1 for p in b["points"]]
        if not pts:
            out["warnings"].append(f"the forced response at {force:.3g} {unit} has no periodic branch")
            continue
        amp = np.array([(p["max_z"] - p["min_z"]) / 2 for p in pts])
        f = np.array([p["f_hz"] for p in pts])
        top = int(np.argmax(amp))
        f_top, a_top = float(f[top]), float(amp[top])
        if 0 < top < amp.size - 1:  # the peak between the continuation's points: quadratics in the point index
            a_, b_, c_ = amp[top - 1 : top + 2]
            s_top = 0.5 * (a_ - c_) / (a_ - 2 * b_ + c_) if a_ - 2 * b_ + c_ < 0 else 0.0
            qa, qf = np.polyfit([-1, 0, 1], amp[top - 1 : top + 2], 2), np.polyfit([-1, 0, 1], f[top - 1 : top + 2], 2)
            f_top, a_top = float(np.polyval(qf, s_top)), float(np.polyval(qa, s_top))
        f_bb = np.interp(a_top, cons["peak_amplitude_m"], cons["f_hz"], left=np.nan, right=np.nan)
        if abs(a_top / target - 1) > 0.2:  # the orbit is not the cosine the force was sized on (near a barrier)
            out["warnings"].append(f"the forced response at {force:.3g} {unit} peaks at {1e3 * a_top:.3g} mm, not the "
                                   f"{1e3 * target:.3g} mm it was sized for (the orbit far from a cosine)")  # fmt: skip
        out["curves"].append({
            "force_n": float(force), "f_hz": f.tolist(), "amplitude_m": amp.tolist(),
            "stable": [bool(p["stable"]) for p in pts],
            "peak": {"f_hz": f_top, "amplitude_m": a_top},
            "peak_off_backbone_percent": float(100 * (f_top / f_bb - 1)) if np.isfinite(f_bb) else None,
        })  # fmt: skip
    return out


def force_unit_of(model, rec: Measurement) -> str:
    """The unit of ``model``'s forces on ``rec``: ``"N/kg"`` for a model per unit mass (m = 1 identified from a
    record without a mass: every force the device's divided by its moving mass), else ``"N"``.
    """
    return "N/kg" if rec.mass is None and float(model.m) == 1.0 else "N"


def credible_band(curves: Sequence[dict[str, Any]], amplitudes: np.ndarray, prob: float = 0.9) -> dict[str, Any]:
    """The band the draws' backbones span at ``amplitudes`` [m]: the central ``prob`` interval of each's
    frequency and damping ratio (draws whose curve does not reach an amplitude left out there).
    """
    f = np.array([on_amplitudes(c, amplitudes, "f_hz") for c in curves])
    z = np.array([on_amplitudes(c, amplitudes, "zeta") for c in curves])
    q = [(1 - prob) / 2, (1 + prob) / 2]
    with np.errstate(all="ignore"):
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # an amplitude no draw reaches: NaN
            fq, zq = np.nanquantile(f, q, axis=0), np.nanquantile(z, q, axis=0)
    return {"prob": prob, "amplitude_m": amplitudes.tolist(), "f_hz_low": fq[0].tolist(), "f_hz_high": fq[1].tolist(),
            "zeta_low": zq[0].tolist(), "zeta_high": zq[1].tolist(), "draws": len(curves)}  # fmt: skip


def backbone(rec: Measurement, model=None, draws: Sequence | None = None, prob: float = 0.9,
             forced: bool = True, dof: int | None = None, band: tuple[float, float] | None = None,
             offsets=None) -> dict[str, Any]:  # fmt: skip
    """Backbone curves of a free-decay record, measured and (with ``model``, ``draws``) predicted.

    Parameters
    ----------
    rec : Measurement
        A record whose input is at its floor after a release (``decay_start``): a free decay, the ring-down after a
        hammer's last hit or a shaker switched off; a single DOF's, or a structure's of N DOFs (the backbone of the
        mode that dominates channel ``dof``, ``measure_backbone``).
    model : negstiff.models.Model or Structure, optional
        A model whose free decay from the record's initial state is measured alike (``predict_backbone``): a
        structure of the record's DOFs on a structure's record.
    draws : sequence of Model, optional
        A posterior's draws: the predicted backbone's credible band (``prob``).
    prob : float, default 0.9
        The credible band's probability.
    forced : bool, default True
        With a single DOF's model, also its forced responses about the well the decay rests in
        (``forced_response``; a structure's are not drawn: their force levels are sized on a single DOF's
        conservative backbone, and a warning says so).
    dof : int, optional
        The channel whose backbone is measured (1-based; default: the one whose decay moves most).
    band : (float, float), optional
        The band-pass [Hz] (default: around the mode that dominates the channel, ``mode_band``): another mode's.
    offsets : sequence of float, optional
        A structure's channels' zeros [m] (measured = physical + offset: its identification's ``offsets_``): the
        model's decay starts from the record's state less them.

    Returns
    -------
    dict
        ``measured`` (``hilbert`` and ``peaks``: ``amplitude_m``, ``f_hz``, ``zeta``, ``t_s`` lists), ``decay``,
        ``amplitude_range_m``, ``linear`` (the Hilbert backbone at its smallest amplitude: ``f_hz``, ``zeta``),
        ``band_hz``, ``dof`` (the channel read), ``modes_hz`` (the decay's resonances); with a model ``predicted``
        (the same, and ``difference_percent``: the largest ``|f_predicted / f_measured - 1|`` over the measured range,
        Hilbert) and ``forced`` (``forced_response``), with draws ``credible``; ``warnings``.

    Examples
    --------
    >>> import numpy as np
    >>> from negstiff import backbone, from_arrays
    >>> t = np.arange(8192) / 1024.0
    >>> z = 1e-3 * np.exp(-0.6 * t) * np.cos(2 * np.pi * 10 * t)   # a linear 10 Hz, ~1 % decay
    >>> r = backbone(from_arrays(np.zeros_like(t), z, 1024.0, input_name="force"))
    >>> round(r["linear"]["f_hz"], 2), round(100 * r["linear"]["zeta"], 2)   # 0.6 / (2 pi 10) = 0.955 %
    (10.0, 0.96)
    """
    if model is not None:
        _check_dofs(model, rec)
    measured = measure_backbone(rec, dof=dof, band=band)
    hil = measured["hilbert"]
    small = np.argsort(hil["amplitude_m"])[: max(3, hil["amplitude_m"].size // 5)]
    out: dict[str, Any] = {
        "measured": {
            "hilbert": _curves({k: v for k, v in hil.items() if k != "band_hz"}),
            "peaks": _curves(measured["peaks"]),
        },  # fmt: skip
        "decay": measured["decay"],
        "amplitude_range_m": measured["amplitude_range_m"],
        "band_hz": hil["band_hz"],
        "dof": measured["dof"],
        "modes_hz": measured["modes_hz"],
        "linear": {
            "f_hz": float(np.median(hil["f_hz"][small])),
            "zeta": float(np.median(hil["zeta"][small])),
            "amplitude_m": [float(hil["amplitude_m"][small].min()), float(hil["amplitude_m"][small].max())],
            "from": "the median of the Hilbert backbone's smallest fifth of amplitudes",
        },  # fmt: skip
        "estimator": "Hilbert transform of the band-passed decay (scipy.signal.hilbert; zero-phase Butterworth "
        f"{hil['band_hz'][0]:.3g}-{hil['band_hz'][1]:.3g} Hz), one point per period; peaks: half peak-to-peak, period "
        "between upward crossings of the rest, log decrement",
        "warnings": [],
    }
    if model is not None:
        pred = predict_backbone(model, rec, measured, offsets)
        f_pred = on_amplitudes(pred["hilbert"], np.asarray(hil["amplitude_m"]))
        diff = np.abs(f_pred / np.asarray(hil["f_hz"]) - 1)
        out["predicted"] = {"hilbert": _curves({k: v for k, v in pred["hilbert"].items() if k != "band_hz"}),
                            "peaks": _curves(pred["peaks"]), "initial": pred["initial"],
                            "difference_percent": float(100 * np.nanmax(diff)) if np.any(np.isfinite(diff)) else None,
                            "covered_share": float(np.mean(np.isfinite(diff)))}  # fmt: skip
        if out["predicted"]["covered_share"] < 0.8:
            out["warnings"].append(f"the model's decay covers {100 * out['predicted']['covered_share']:.0f} % of the "
                                   "measured amplitude range")  # fmt: skip
        if forced and isinstance(model, Structure):
            out["warnings"].append("no forced response drawn for a structure: its force levels are sized on a single "
                                   "DOF's conservative backbone")  # fmt: skip
        elif forced:
            well = _rest_well(model, measured, rec, offsets)
            f_all = np.concatenate([hil["f_hz"], pred["hilbert"]["f_hz"]])
            f_range = (FORCED_SPAN[0] * float(np.min(f_all)), FORCED_SPAN[1] * float(np.max(f_all)))
            a_max = float(np.max(measured["peaks"]["amplitude_m"], initial=measured["amplitude_range_m"][1]))
            out["forced"] = forced_response(model, well, a_max, f_range, force_unit=force_unit_of(model, rec))
            out["warnings"] += out["forced"]["warnings"]
    if draws:
        # a structure's posterior draws its element's coefficients: each draw is the structure with that element
        systems = [model.with_element(d) if isinstance(model, Structure) and not isinstance(d, Structure) else d
                   for d in draws]  # fmt: skip
        curves = [predict_backbone(d, rec, measured, offsets)["hilbert"] for d in systems]
        lo, hi = measured["amplitude_range_m"]
        grid = np.geomspace(lo, hi, 40)
        out["credible"] = credible_band(curves, grid, prob)
    return out
