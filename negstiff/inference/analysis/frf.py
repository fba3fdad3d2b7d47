"""Frequency response functions of a low-level test around one well, with a modal fit of each peak.

Before any nonlinear test a lab measures the FRF around each stable well (random or swept excitation
at a level that keeps the motion small): its resonance is the well's underlying-linear frequency,
an independent check of what NSI, SINDy and a refined model say (reference study Eq. 4).

* Estimation (Bendat & Piersol, *Random Data*, 4th ed., sections 9.1-9.2): H1 = G_xy / G_xx (noise
  on the response averages out), H2 = G_yy / G_yx (noise on the input averages out), coherence
  gamma^2 = |G_xy|^2 / (G_xx G_yy), from Welch-averaged (cross-)spectra of scipy.signal (Hann window,
  50 % overlap). scipy is used rather than pyFRF: pyFRF averages over repeated impact measurements,
  a stationary random record is one long Welch average, and scipy.signal is already a dependency.
* Modal fit of each peak: the single-degree-of-freedom receptance of the equation of motion,
  H(w) = A / (w_n^2 - w^2 + 2 i zeta w_n w) + R (R: a complex residual of the other modes and of
  the nonlinearity's distortion), fitted to H1 by least squares on its real and imaginary parts over
  the half-power band widened 3x (``scipy.optimize.least_squares``), started from peak picking and
  the half-power bandwidth (Ewins, *Modal Testing*, 2nd ed., 4.3). For base excitation A = -1 (z per
  table acceleration) and for a force A = 1/m: the fit's A is reported, and for a force it gives m.
* Impact (hammer) records, a force channel of short pulses far above its floor, are not stationary: their hits
  are found, offset, windowed (force and exponential windows) and averaged (``impact``), and each fitted
  mode's damping has the exponential window's share taken off (``result["impacts"]`` says what was done).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy import fft as sp_fft
from scipy import optimize, signal

from negstiff.errors import MeasurementError, issue
from negstiff.files import read_json
from negstiff.inference.analysis.impact import correct_exponential, impact_band, impact_spectra
from negstiff.inference.record.impacts import Impacts, find_impacts
from negstiff.inference.record.measurement import Measurement
from negstiff.inference.steps.plausibility import classified

SEGMENT_S = 16.0
"""Welch segment length [s]: 1/16 Hz bins, at least 8 averages on a 72 s record (fewer on shorter
ones, said by ``averages``)."""


PERIODIC_CORRELATION = 0.999
"""An input whose autocorrelation at one lag (0.25 s or more, a third of the record at most) is this close to 1
is periodic (a multisine, a periodic chirp): its spectrum is lines 1/period apart."""


MIN_SEGMENT_SAMPLES = 64
"""The shortest averaging segment [samples] an FRF is estimated on (a record gives two at least)."""


def input_period(rec: Measurement) -> int | None:
    """The period [samples] of a periodic input (``PERIODIC_CORRELATION``), else None."""
    u = rec.u - rec.u.mean()
    n = u.size
    if n < 64 or not np.any(u):
        return None
    spec = sp_fft.rfft(u, 2 * n)
    acf = sp_fft.irfft(np.abs(spec) ** 2)[: n // 3 + 1]
    acf = acf / acf[0] * n / (n - np.arange(acf.size))  # unbiased: each lag over the samples it has
    lo = max(1, int(0.25 * rec.fs))
    if acf.size <= lo + 1:
        return None
    above = np.flatnonzero(acf[lo:] >= PERIODIC_CORRELATION)
    if not above.size:
        return None
    run_end = above[0] + int(np.argmax(np.diff(np.r_[above, above[-1] + 2]) > 1))  # the first lags that repeat
    return lo + above[0] + int(np.argmax(acf[lo + above[0] : lo + run_end + 1]))  # the period, not a multiple


def estimate(rec: Measurement, segment_s: float = SEGMENT_S, period: int | None = None) -> dict[str, np.ndarray]:
    """H1, H2 and the coherence of z over the input: (f [Hz], H1, H2, coherence, averages). A periodic input
    (``period`` samples: a multisine) is averaged over whole periods without a window: every bin is one of its
    lines, none leaks (Welch's Hann segments of a random input would split its lines and fit noise between).
    """
    if rec.z is None:
        raise MeasurementError(f"{rec.source}: an FRF needs a response column")
    if period is not None and rec.n >= 2 * period:
        kw = {"fs": rec.fs, "nperseg": period, "window": "boxcar", "noverlap": 0, "detrend": "constant"}
        nper = period
    else:
        nper = int(min(rec.n // 2, round(segment_s * rec.fs)))
        kw = {"fs": rec.fs, "nperseg": nper, "window": "hann", "noverlap": nper // 2, "detrend": "constant"}
    if nper < MIN_SEGMENT_SAMPLES:
        raise MeasurementError(
            f"{rec.source}: too few samples for an FRF ({rec.n}); need at least {2 * MIN_SEGMENT_SAMPLES}"
        )
    f, gxx = signal.welch(rec.u, **kw)
    _, gyy = signal.welch(rec.z, **kw)
    _, gxy = signal.csd(rec.u, rec.z, **kw)  # conj(X) Y: H1 = G_xy / G_xx
    with np.errstate(divide="ignore", invalid="ignore"):
        h1 = gxy / gxx
        h2 = gyy / np.conj(gxy)
        coh = np.abs(gxy) ** 2 / (gxx * gyy)
    averages = rec.n // nper if kw["window"] == "boxcar" else 2 * rec.n // nper - 1
    return {"f": f, "H1": h1, "H2": h2, "coherence": np.nan_to_num(coh), "Gxx": gxx, "averages": averages,
            "window": kw["window"]}  # fmt: skip


COHERENT = 0.8
"""A peak whose coherence reaches this is the input's response (at most a quarter as much uncorrelated output power,
drift or noise, as input-driven, Bendat & Piersol 9.2.3): the dominant peak is the strongest of these. A drift's
bump at the bottom of a swept test reaches 0.5-0.65 (measured: a 1-20 Hz sweep, drift 0.1-2 Hz) where a
resonance stands above 0.9."""


def _height(f: np.ndarray, h1: np.ndarray, p: dict[str, Any]) -> float:
    """|H1| at a peak's bin."""
    return float(np.abs(h1[np.argmin(np.abs(f - p["peak_bin_hz"]))]))


def _sdof(p, w):
    a_re, a_im, wn, zeta, r_re, r_im = p
    return (a_re + 1j * a_im) / (wn**2 - w**2 + 2j * zeta * wn * w) + (r_re + 1j * r_im)


ZETA_BOUNDS = (1e-5, 1.0)
"""The damping ratios a peak's fit may take: a fit at either bound found no resonance there."""


def fit_peak(f: np.ndarray, h: np.ndarray, k: int) -> dict[str, Any]:
    """SDOF receptance fit around the peak at bin ``k`` (module docstring)."""
    mag = np.abs(h)
    half = mag[k] / math.sqrt(2)
    lo = k
    while lo > 0 and mag[lo] > half:
        lo -= 1
    hi = k
    while hi < f.size - 1 and mag[hi] > half:
        hi += 1
    bw = max(f[hi] - f[lo], 2 * (f[1] - f[0]))
    zeta0 = min(max(bw / (2 * f[k]), 1e-5), 0.99)  # a broad low-frequency hump would start beyond the bounds
    sel = (f > f[k] - 1.5 * bw) & (f < f[k] + 1.5 * bw)
    if sel.sum() < 6:  # a sharp peak: at least 3 bins either side
        sel = (np.arange(f.size) >= k - 3) & (np.arange(f.size) <= k + 3)
    w = 2 * np.pi * f[sel]
    wn0 = 2 * np.pi * f[k]
    a0 = h[k] * (2j * zeta0 * wn0**2)

    def resid(p):
        d = _sdof(p, w) - h[sel]
        return np.concatenate([d.real, d.imag]) / mag[k]

    p0 = [a0.real, a0.imag, wn0, zeta0, 0.0, 0.0]
    lb = [-np.inf, -np.inf, 0.5 * wn0, ZETA_BOUNDS[0], -np.inf, -np.inf]
    ub = [np.inf, np.inf, 1.5 * wn0, ZETA_BOUNDS[1], np.inf, np.inf]
    sol = optimize.least_squares(resid, p0, bounds=(lb, ub), x_scale="jac")
    a_re, a_im, wn, zeta, r_re, r_im = sol.x
    return {
        "f_hz": float(wn / (2 * np.pi)),
        "zeta": float(zeta),
        "modal_constant": [float(a_re), float(a_im)],
        "peak_bin_hz": float(f[k]),
        "half_power_zeta": float(zeta0),
        "fit_rms_relative": float(np.sqrt(np.mean(resid(sol.x) ** 2))),
        "band_hz": [float(f[sel][0]), float(f[sel][-1])],
    }


RESOLUTION_RATIO = 0.1
"""The Hann window's resolution bandwidth (1.5 / T) kept below this fraction of the dominant peak's
half-power bandwidth (2 zeta f): window leakage widens a peak and biases zeta upwards (measured on a
2 % mode at 10 Hz: +15 % with 8 s segments, +4 % with 16 s, +2 % with 32 s)."""


def check_frf(rec: Measurement, band: tuple[float, float] | None = None) -> None:
    """Refuse (``MeasurementError``, one line) what no FRF can be estimated from: an input or a response
    that does not move, a band beyond the Nyquist frequency.
    """
    rec.require(2 * MIN_SEGMENT_SAMPLES, "an FRF")  # two averaging segments at least
    rec.require_excitation("an FRF")
    rec.require_motion("an FRF")
    if band is not None and not (0 <= band[0] < band[1] <= rec.fs / 2):
        raise MeasurementError(f"{rec.source}: FRF band {band[0]:g}:{band[1]:g} Hz must lie within 0:{rec.fs / 2:g} Hz")


def frf(rec: Measurement, band: tuple[float, float] | None = None, segment_s: float | None = None) -> dict[str, Any]:
    """Frequency response functions (H1, H2, coherence) with every resonance peak fitted; a structure's record
    (N DOFs): every DOF's, the modes merged (``frf_structure``).

    Peaks are local maxima of ``|H1|`` standing 6 dB above the band's median level at coherence above
    0.5, each fitted with a single-degree-of-freedom receptance (``docs/methods/frf.md``). The dominant peak
    is the strongest whose coherence reaches ``COHERENT`` (a drift's bump the input does not explain never wins
    over a resonance; a stronger peak passed over is warned about), else the strongest. A response of
    unknown scale (``*?``) is calibrated first: the FRF is in SI units.

    Parameters
    ----------
    rec : Measurement
        A record with broadband input (a low-level random or swept test around one well).
    band : (float, float), optional
        The frequency band [Hz] searched for peaks (default: the input's band).
    segment_s : float, optional
        Welch segment length [s] (default: lengthened until the resolution resolves the dominant peak).

    Returns
    -------
    dict
        The contract's frf result: ``f_hz``, ``zeta``, ``coherence`` (the dominant peak's), ``band``, ``peaks``
        (each fitted peak, the dominant first), ``well`` (the rest position nearest the record's mean z),
        ``record``, ``warnings``, and the spectra in ``_curves`` (arrays, for a figure; not JSON).

    Examples
    --------
    >>> from negstiff import Measurement, Rig, frf
    >>> from negstiff.models import SEED_LIKE_CUBIC
    >>> rec = Measurement.from_rig(Rig(SEED_LIKE_CUBIC, seed=7).random(duration=60.0, rms=0.5, start="minus"))
    >>> r = frf(rec)
    >>> abs(r["f_hz"] / SEED_LIKE_CUBIC.uls("minus").f_hz - 1) < 0.01   # the well's own frequency
    True
    """
    from negstiff.inference.steps.frame import calibrate_scale

    check_frf(rec, band)
    if rec.n_dof > 1:  # each DOF's response read as a single DOF's (``frf_structure``), the modes merged
        return frf_structure(rec, band=band, segment_s=segment_s)
    rec = calibrate_scale(rec)
    hits = find_impacts(rec.u, rec.fs) if rec.input_name == "force" else None
    period = input_period(rec) if segment_s is None and hits is None else None
    if hits is not None:  # a hammer's record: its hits, windowed
        r = _impact_frf(rec, band, hits)
    elif period is not None:  # a multisine: whole periods, its lines
        r = _frf(rec, band, period / rec.fs, period)
    elif segment_s is None:
        r = _frf(rec, band, SEGMENT_S)
        if r["f_hz"] is not None:
            need = 1.5 / (RESOLUTION_RATIO * 2 * r["zeta"] * r["f_hz"])
            seg = min(need, rec.duration / 4)
            r = r if seg <= SEGMENT_S * 1.05 else _frf(rec, band, seg)
    else:
        r = _frf(rec, band, segment_s)
    rest = rec.rest_positions
    z = rec.z
    r["well"] = min(rest, key=lambda w: abs(rest[w] - float(np.mean(z)))) if rest and z is not None else None
    notes = r.pop("_notes")
    lines = classified(rec, None, ([r["reason"]] if r["reason"] else []) + notes)
    issue(lines)
    return r | {"record": dict(rec.info), "warnings": [text for _, text in lines]}


def _frf(rec: Measurement, band: tuple[float, float] | None, segment_s: float, period: int | None = None
         ) -> dict[str, Any]:  # fmt: skip
    """``frf`` with a given Welch segment [s] (or the input's period [samples])."""
    est = estimate(rec, segment_s, period)
    f = est["f"]
    nyq = rec.fs / 2
    if band is None:  # the excited band: where the input's spectrum is within 20 dB of its peak
        gxx = est["Gxx"]
        on = np.flatnonzero((gxx >= 0.01 * gxx[1:].max()) & (f > 0))
        band = (float(f[on[0]]), float(min(f[on[-1]], 0.8 * nyq))) if on.size else (float(f[1]), 0.8 * nyq)
    r = _peaks(rec, est, band)
    return r | {
        "estimator": (
            f"H1 = Gxy/Gxx (H2 beside), the periodic input's {est['averages']} whole periods of "
            f"{segment_s:.4g} s, no window; peaks: SDOF receptance fit"
            if est["window"] == "boxcar"
            else f"H1 = Gxy/Gxx (H2 beside), Welch: Hann, {est['averages']} averages of "
            f"{segment_s:.3g} s, 50 % overlap; peaks: SDOF receptance fit"
        ),  # fmt: skip
        "segment_s": float(segment_s),
    }


IMPACT_PEAKS = 12
"""The most prominent local maxima of an impact FRF that are fitted as candidate modes."""


IMPACT_FIT_RMS = 0.05
"""An impact FRF's local maximum is a mode when one SDOF receptance fits it within this share of its peak (rms over
the fitted band): a resonance above the noise is fitted within 0.3-1 %, the noise's maxima err by 7-27 %."""


def _impact_frf(rec: Measurement, band: tuple[float, float] | None, hits: Impacts) -> dict[str, Any]:
    """``frf`` of an impact record (``impact``): H1 over its hits, force and exponential windows, each fitted
    mode's damping corrected for the exponential window.
    """
    est = impact_spectra(rec, hits)
    if band is None:
        band = impact_band(est, rec.fs)
    # one hit's coherence is 1 by construction: it judges nothing, so no peak is passed over for it
    r = _peaks(rec, est, band, min_coherence=0.5 if hits.count > 1 else 0.0, most=IMPACT_PEAKS, stationary=False)
    tau = est["tau_s"]
    # a fit at its damping bounds (a broad hump near 0 Hz, the noise beyond the hammer's band) is no mode: the
    # lab's silent "0.3 Hz, zeta 100 %"; nor is a local maximum of the noise that one SDOF receptance does not fit
    # (a single hit has no coherence to tell it: its fit's residual does)
    off = [p for p in r["peaks"] if not (ZETA_BOUNDS[0] * 1.5 < p["zeta"] < ZETA_BOUNDS[1] / 2)
           or p["fit_rms_relative"] > IMPACT_FIT_RMS]  # fmt: skip
    r["peaks"] = [p for p in r["peaks"] if p not in off]
    r["set_aside_hz"] = sorted(float(p["f_hz"]) for p in off)
    if off:
        r["_notes"].append(
            f"{len(off)} local maxima set aside (their fits ran to a damping bound, or erred by over "
            f"{100 * IMPACT_FIT_RMS:g} % of the peak: no resonance), "
            f"at {', '.join(f'{p["f_hz"]:.4g}' for p in off[:4])}{' ...' if len(off) > 4 else ''} Hz"
        )
    for p in r["peaks"]:
        p["windowed"] = {"f_hz": p["f_hz"], "zeta": p["zeta"]}
        p["f_hz"], p["zeta"] = correct_exponential(p["f_hz"], p["zeta"], tau)
        p["window_zeta"] = p["windowed"]["zeta"] - p["zeta"]
    top = r["peaks"][0] if r["peaks"] else None
    r |= {"f_hz": top and top["f_hz"], "zeta": top and top["zeta"], "coherence": top and top["coherence"]}
    if top is None:
        r["reason"] = "no resonance peak in the hammer's band"
    if hits.count == 1:
        r["_notes"].append("a single hit: its coherence is 1 by construction and says nothing of the noise; "
                           "several hits in one record give H1 averaged over them and a coherence")  # fmt: skip
    r["_notes"] += [f"impact: {d} (set aside)" for d in hits.dropped]
    r["impacts"] = {
        "hits": hits.count,
        "times_s": [float(rec.t0 + a / rec.fs) for a in hits.starts],
        "peak_force_n": hits.peaks.tolist(),
        "offset_n": hits.offsets.tolist(),
        "floor_n": hits.floor,
        "block_s": est["block_s"],
        "windows": est["window"],
        "exponential_tau_s": None if not np.isfinite(tau) else float(tau),
        "response": est["response"],
        "coherence": "over hits" if hits.count > 1 else "one hit: 1 by construction",
        "set_aside": list(hits.dropped),
    }
    return r | {
        "estimator": (
            f"impact: H1 = sum conj(F) X / sum |F|^2 over {hits.count} hit(s) of {est['block_s']:.4g} s, "
            f"each offset by its pre-trigger median, zero-padded to {est['nfft']} points; {est['window']}; "
            "peaks: SDOF receptance fit"
        ),  # fmt: skip
        "segment_s": float(est["block_s"]),
    }


PEAK_RANDOM_ERRORS = 6.0
"""A stationary FRF's local maximum is a resonance only where it stands above its surroundings (its prominence) by
more than this many random errors of |H1| at its bin, eps = sqrt(1 - gamma^2) / (|gamma| sqrt(2 n_d)) (Bendat &
Piersol, *Random Data*, eq. 9.65): a ground test's sweep at 10 % response noise showed its two modes 12-1900 random
errors high and dozens of maxima of the noise (one inside the anti-resonance, where the coherence dips) 2-7."""


Peaks = list[dict[str, Any]]


def _resonances(f: np.ndarray, h1: np.ndarray, coh: np.ndarray, averages: int, cand: np.ndarray,
                prominence: np.ndarray, peaks: Peaks) -> tuple[Peaks, Peaks]:  # fmt: skip
    """``peaks`` (fitted at ``cand``'s bins, of ``prominence``) split into resonances and the local maxima of a
    stationary estimate's random error: those within ``PEAK_RANDOM_ERRORS`` of their surroundings, those whose fit
    ran to a damping bound, and those narrower than a frequency bin (a resolved resonance seen through the Hann
    window is a few bins wide; a one-bin spike is the estimate's noise).
    """
    df = float(f[1] - f[0])
    keep: Peaks = []
    off: Peaks = []
    for p in peaks:
        k = int(np.argmin(np.abs(f - p["peak_bin_hz"])))
        i = np.flatnonzero(cand == k)
        g = min(max(float(coh[k]), 1e-12), 1.0)
        eps = math.sqrt(1 - g) / (math.sqrt(g) * math.sqrt(2 * max(averages, 1)))
        rise = float(prominence[i[0]]) / max(float(np.abs(h1[k])), 1e-300) if i.size else math.inf
        bounded = not ZETA_BOUNDS[0] * 1.5 < p["zeta"] < ZETA_BOUNDS[1] / 2
        (off if rise <= PEAK_RANDOM_ERRORS * eps or bounded or 2 * p["zeta"] * p["f_hz"] < df else keep).append(p)
    return keep, off


def _peaks(rec: Measurement, est: dict[str, Any], band: tuple[float, float], min_coherence: float = 0.5,
           most: int | None = None, stationary: bool = True) -> dict[str, Any]:  # fmt: skip
    """The peaks of ``est``'s H1 in ``band``, each fitted, the dominant first (``frf``); ``most``: only the
    candidates of the largest prominence fitted (a zero-padded spectrum's noise holds thousands of local maxima);
    ``stationary`` (a Welch or periodic average): the local maxima of the estimate's random error set aside
    (``_resonances``; an impact record's are judged by its own rules).
    """
    f, h1, coh = est["f"], est["H1"], est["coherence"]
    nyq = rec.fs / 2
    if not (0 <= band[0] < band[1] <= nyq):
        raise MeasurementError(f"{rec.source}: FRF band {band[0]:g}:{band[1]:g} Hz must lie within 0:{nyq:g} Hz")
    inb = (f >= band[0]) & (f <= band[1])
    if inb.sum() < 8:
        raise MeasurementError(
            f"{rec.source}: the FRF band {band[0]:g}:{band[1]:g} Hz holds fewer than 8 frequency bins"
        )
    idx = np.flatnonzero(inb)
    mag = np.abs(h1[idx])
    cand, props = signal.find_peaks(mag, prominence=np.median(mag))
    if most is not None and cand.size > most:
        cand = np.sort(cand[np.argsort(props["prominences"])[::-1][:most]])
    peaks = []
    for c in cand:
        k = idx[c]
        if mag[c] < 2 * np.median(mag) or coh[k] < min_coherence:
            continue
        p = fit_peak(f, h1, k)
        p["coherence"] = float(coh[k])
        p["h1_over_h2"] = float(np.abs(h1[k]) / np.abs(est["H2"][k]))
        peaks.append(p)
    notes: list[str] = []
    off: list[dict[str, Any]] = []
    if stationary and peaks:  # the result's ``set_aside_hz``: the estimate's noise is no news to warn about
        peaks, off = _resonances(f, h1, coh, int(est.get("averages", 1)), idx[cand], props["prominences"], peaks)
    # the dominant peak is the strongest coherent one: a peak the input does not explain (a drift's bump at the
    # bottom of a sweep, where few segments hold the input and a slow drift lifts |H1|) is never a resonance
    # while a coherent peak stands in the band; only without one is the strongest of the rest reported
    peaks.sort(key=lambda p: (p["coherence"] < COHERENT, -_height(f, h1, p)))
    # one mode, one peak: a noisy |H1| can hold two local maxima on one resonance (the Silverbox's, 0.6 Hz
    # apart), whose fits return the same mode; a peak whose fitted frequency lies within half the half-power
    # bandwidth (zeta f) of a stronger one's is that mode again (two modes so close cannot be resolved)
    kept: list[dict[str, Any]] = []
    for p in peaks:
        if not any(abs(p["f_hz"] - q["f_hz"]) <= q["zeta"] * q["f_hz"] for q in kept):
            kept.append(p)
    peaks = kept
    top = peaks[0] if peaks else None
    louder = [p for p in peaks[1:] if top is not None and top["coherence"] >= COHERENT
              and p["coherence"] < COHERENT and _height(f, h1, p) > _height(f, h1, top)]  # fmt: skip
    notes += [f"a higher peak at {p['f_hz']:.3g} Hz (coherence {p['coherence']:.2f}) passed over for the coherent one "
              f"at {top['f_hz']:.4g} Hz (coherence {top['coherence']:.2f}): the input explains little of the response "
              "there (drift or noise?); --band F1:F2 limits the search" for p in louder if top is not None]  # fmt: skip
    if top is not None and top["coherence"] < COHERENT:
        notes.append(f"no peak in the band has coherence above {COHERENT:g}: the dominant peak at {top['f_hz']:.4g} Hz "
                     f"(coherence {top['coherence']:.2f}) may be drift or noise rather than a resonance")  # fmt: skip
    return {
        "f_hz": top["f_hz"] if top else None,
        "zeta": top["zeta"] if top else None,
        "coherence": top["coherence"] if top else None,
        "band": [float(band[0]), float(band[1])],
        "peaks": peaks,
        "set_aside_hz": sorted(float(p["f_hz"]) for p in off),
        "response_per_input": "m per m/s^2 (z / base_acc)" if rec.input_name == "base_acc" else "m per N (z / force)",
        "reason": None if top else f"no resonance peak with coherence above {min_coherence:g} in the band",
        "_notes": notes,
        "_curves": est,
    }


def read_frf_results(paths: Sequence[str] | None) -> list[tuple[str, float, str | None, int]]:
    """(path, peak frequency [Hz], well, the FRF's DOFs) of each ``frf`` result file, checked (one
    ``MeasurementError``): a single DOF's FRF its peak (and the well its record rested in, where it says); a
    structure's (``frf_structure``) each of its modes.
    """
    out = []
    for p in paths or []:
        try:
            r = read_json(p)
            structure = "modes" in r and "dofs" in r
            peaks = [(m["f_hz"], None) for m in r["modes"]] if structure else [(r["f_hz"], r.get("well"))]
            n_dofs = len(r["dofs"]) if structure else 1
        except (ValueError, KeyError, TypeError, AttributeError):
            raise MeasurementError(f"--frf {p}: not an frf result (needs f_hz, or a structure's modes)") from None
        if not peaks:
            raise MeasurementError(f"--frf {p}: the FRFs found no mode to compare with")
        for f_frf, well in peaks:
            if not isinstance(f_frf, (int, float)) or isinstance(f_frf, bool):
                raise MeasurementError(f"--frf {p}: the FRF found no peak to compare with (f_hz is {f_frf!r})")
            out.append((p, float(f_frf), well, n_dofs))
    return out


def compare_with_frf(modal: dict, frfs: list[tuple[str, float, str | None, int]]) -> list[dict]:
    """Each low-level FRF peak (``read_frf_results``; ``identify --frf``) beside the identified underlying-linear
    frequency nearest it (an identification's ``modal``: a single DOF's ``{well: {"f_hz", ...}}``, a structure's
    ``{well: [{"f_hz", ...}, ...]}``, whose ``mode`` is then named, 1 the lowest): within the FRF's well where its
    record's rest positions say which; a structure's FRF file, one low-level test, within the one well whose modes
    lie nearest its modes altogether. A structure's FRF given to a single DOF's identification is one
    ``MeasurementError``.
    """
    found: list[tuple[str, int | None, float]] = []  # (well, mode or None, f)
    for w, m in modal.items():
        if isinstance(m, dict):
            if m.get("f_hz"):
                found.append((w, None, float(m["f_hz"])))
        else:
            found += [(w, i + 1, float(x["f_hz"])) for i, x in enumerate(m) if x.get("f_hz")]
    single = all(isinstance(m, dict) for m in modal.values())
    by_file: dict[str, list[tuple[float, str | None, int]]] = {}
    for p, f_frf, well, n_dofs in frfs:
        if single and n_dofs > 1:
            raise MeasurementError(f"--frf {p}: a structure's FRFs ({n_dofs} DOFs) beside a single DOF's "
                                   "identification")  # fmt: skip
        by_file.setdefault(str(p), []).append((f_frf, well, n_dofs))

    def nearest(pool, f_frf):
        return min(pool, key=lambda c: abs(c[2] - f_frf)) if pool else (None, None, None)

    out = []
    for p, rows in by_file.items():
        well_of_file = None
        if rows[0][2] > 1 and found:  # one test: the well whose modes lie nearest its modes altogether
            wells = sorted({c[0] for c in found})
            well_of_file = min(wells, key=lambda w: sum(abs(nearest([c for c in found if c[0] == w], f)[2] - f)
                                                         for f, _, _ in rows))  # fmt: skip
        for f_frf, well, _ in rows:
            target = well_of_file or well
            best = nearest([c for c in found if c[0] == target] or found, f_frf)
            diff = None if best[2] is None else 100 * (best[2] / f_frf - 1)
            row: dict[str, Any] = {"frf": p, "well": best[0], "frf_f_hz": f_frf, "identified_f_hz": best[2],
                                   "difference_percent": diff}  # fmt: skip
            if best[1] is not None:
                row["mode"] = best[1]
            out.append(row)
    return out


def frf_structure(rec, band: tuple[float, float] | None = None, segment_s: float | None = None) -> dict[str, Any]:
    """The FRFs of a structure's record (``StructureRecord``): from the input to every DOF's response, each as
    ``frf`` makes it (H1, H2, coherence, fitted peaks), and ``modes``: the peaks found on any DOF, those within 2 %
    in frequency merged (their mean frequency and damping, and the DOFs that show them). ``_curves``: each DOF's
    spectra (arrays, for a figure; not JSON).
    """
    from negstiff.inference.record.measurement import from_arrays

    dofs, curves, warnings_ = [], [], []
    for i, zi in enumerate(rec.z):
        one = from_arrays(rec.u, zi, rec.fs, input_name=rec.input_name, source=f"{rec.source} (z{i + 1})")
        r = frf(one, band=band, segment_s=segment_s)
        curves.append(r.pop("_curves"))
        warnings_ += r.pop("warnings")
        r.pop("record", None)
        r.pop("well", None)
        dofs.append({"dof": i + 1, **r})
    found = sorted((p["f_hz"], p["zeta"], d["dof"]) for d in dofs for p in d["peaks"])
    modes: list[dict[str, Any]] = []
    for f, z, d in found:
        if modes and abs(f / modes[-1]["f_hz"] - 1) < 0.02:
            m = modes[-1]
            m["_all"].append((f, z))
            m["f_hz"] = float(np.mean([a for a, _ in m["_all"]]))
            m["zeta"] = float(np.mean([b for _, b in m["_all"]]))
            m["seen_on"] = sorted(set(m["seen_on"]) | {d})
        else:
            modes.append({"f_hz": f, "zeta": z, "seen_on": [d], "_all": [(f, z)]})
    for m in modes:
        m.pop("_all")
    return {"dofs": dofs, "modes": modes, "warnings": warnings_, "_curves": curves}
