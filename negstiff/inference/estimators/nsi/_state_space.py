"""NSI on a structure read through its sensors, its masses unknown and its modes more than its sensors.

A lab's record of a structure (a shaker's measured force at one sensed point, a few sensors, two of them either side
of a nonlinear joint) holds more modes than channels, and nothing gives the masses. Its linear part is then a
state-space model (``models.state_space``) whose order the record shows: the stabilisation diagram (the poles of
the PO-MOESP model of every even order from one LQ factor, ``subspace.poles_by_order``), a pole stable when the
next two orders hold one within ``F_TOL`` in frequency and ``ZETA_TOL`` in damping; the model's order is the
lowest that holds every mode stable at some order (Peeters & De Roeck 2001; the stabilisation of
Marchesiello, Fasana & Garibaldi 2016).

The element's basis functions of the relative motion r = y_J - y_I about its mean r* (low-passed at 1.5 times the
force's band top, ``element_motion``) are the model's feedback inputs beside the force
(Marchesiello & Garibaldi 2008), and the element's coefficients come from the extended FRF: the input column of
basis function j is mu_j G l (G the structure's compliance, l its place) and the force's is G e_p (p the sensor the
force acts at), so by reciprocity (G symmetric) its row p is mu_j (l . G e_p) = mu_j times the relative motion's
FRF to the force. mu_j is the least-squares ratio of the two over the modes' band (weighted by |l . G e_p|^2, so
an antiresonance of the relative motion weighs nothing), in newtons per unit of its basis function with no mass
known: the driving point, measured, sets the scale (Noel & Kerschen 2013 extract the coefficients from the extended
FRF alike). |Im/Re| of the ratio is the quality index; the standard errors are batch means over ``BLOCKS`` blocks.

The subspace step reads the record at about ``SAMPLES_PER_CUT`` samples per cycle of the basis's band top: every
input and output low-passed there (the basis's own filter) and decimated. A ground vibration test sampled at 400 Hz
for modes of 3-16 Hz puts its poles in a sliver of the unit circle by 1 (the F-16 benchmark's record: every order
from 16 to 40 had a pole outside it at 400 Hz and at 100 Hz; at 57 Hz none). Where every sensor is an
accelerometer the outputs are the accelerations themselves with a feedthrough (``StateSpaceStructure``'s
``output``): on their double integrals the same record's diagram held two of its six modes, on the accelerations
all of them within 1 % of its FRF's peaks.

The model is judged on the held-out tail: windows restarted every ``window_s`` from the state the model's own
least squares reads off the measured stretch before each (``StateSpaceStructure.initial_state``), run free under
the measured force, beside the underlying-linear part alone and the best linear model of the same order (the
force its only input, fitted by the same subspace step on the same channels: it takes in the element's equivalent
stiffness and damping, so it is the linear model a lab would fit instead) under the same protocol.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from typing import Any

import numpy as np
from scipy import fft as sp_fft
from scipy import signal, stats

from negstiff.errors import InputError, issue
from negstiff.errors import NegstiffWarning as _Warning
from negstiff.inference.estimators import subspace
from negstiff.inference.estimators.results import Bunch, Identification
from negstiff.inference.record.derivatives import band_limited, basis_band_hz, smooth_and_differentiate
from negstiff.inference.record.measurement import Measurement
from negstiff.models import laws
from negstiff.models.state_space import StateSpaceStructure, element_basis, feedback_inputs
from negstiff.models.structure import Mode, coupling, relative

F_TOL = 0.01
"""A pole is stable when the next order holds one within this share of its frequency ..."""
ZETA_TOL = 0.2
"""... and within this share of its damping ratio (or ``ZETA_ABS`` absolute, for lightly damped modes whose
estimate scatters by more than a share)."""
ZETA_ABS = 0.002
STABLE_RUN = 3
"""A mode is physical when it is stable at this many consecutive orders."""
MAX_ZETA = 0.3
"""Poles damped above this are left out of the diagram (the noise's)."""
PHYSICAL_ZETA = 0.1
"""A stable pole is a mode when damped below this: a ground vibration test's modes are damped below a few percent
(a bolted joint's up to about 5 %), the noise's stable-looking poles above 10 %."""
MAX_ORDER = 40
BLOCKS = 4
"""Batch means' blocks of the identification part, for the element's standard errors."""
FORCE_POWER_SHARE = 0.99
"""The share of the force's power below the band's top (``force_band_top``)."""
UNSEEN_WARNING = 0.5
"""The held-out tail's force power share outside the identification part's band (``unseen_share``) above which
the held-out error is said not to measure the model."""
BASIS_BAND_FACTOR = 1.5
"""The element's motion is low-passed at this many times the force's band top (``element_motion``): the joint's
harmonics reach beyond the force's band (a cubic's to three times it) and the sensors' noise is everywhere. Measured:
at 1x a 3-DOF chain's k3 came out +0.33 % with lasers of 2 um, at 1.5x -0.09 %, at 2x and 3x -0.1 %; on the 5-mode
chain with 1 % sensor noise the modes were within 0.05 % at 1x and 1.5x, 0.08 % at 2x, 0.21 % at 3x (unfiltered,
the noise in the basis biases them low)."""
BAND_CHOICES = (2 / 3, 4 / 3)
"""The basis bands (times the chosen one: on a random test 1x and 2x the force's band top) whose fits' spread
about the chosen band's is the band's part of the element's standard error."""
QUALITY_WARNING = 0.3
"""|Im/Re| of an element coefficient's ratio above which it is said to be poorly determined."""
SLOW_BIN_HZ = 0.5
"""The bins [Hz] over which ``quasi_static_motion`` compares its law's residual with the double integral's noise."""
SLOW_RESIDUAL_RATIO = 2.0
"""The quasi-static law replaces the accelerometers' relative motion up to the first bin where its residual
against the double integral exceeds this many times the integral's own noise power (``quasi_static_motion``)."""
SLOW_ITERATIONS = 10
"""Fixed-point iterations of ``quasi_static_motion`` (its basis functions are of the motion it corrects)."""
SAMPLES_PER_CUT = 2.4
"""The subspace step's record is decimated to at least this many samples per cycle of the basis's band top (its
Nyquist 1.2 times it or more; ``decimation``). The empty band between the band top and Nyquist is what the subspace
step cannot place poles in; measured, as the Nyquist's ratio to the band top: the F-16 benchmark's record (400 Hz,
the band top 22.5 Hz) reads its 7 modes at 1.11 and 1.27 (decimated 8x, 7x), loses two at 1.78 (5x), and at 2.2
(4x) and 8.9 (none) every order has an unstable pole; a 3-DOF chain read by accelerometers, right at 1.40, five
modes for three and its held-out runs lost at 2.8; a hammer test read by accelerometers, the lowest mode's damping
within 5 % at 1.24, 3x high at 2.47 (k3 -0.57 against -0.97 %)."""


class StateSpaceIdentificationError(InputError):
    """The record does not allow a state-space structure's identification (a refusal, exit 2 at the CLI)."""


def check_record(rec: Measurement, at: tuple[int, int], block_rows: int) -> int:
    """The refusals that need no work: a force input at a sensed point the record names (the coefficients' scale
    without masses), a record long enough. Returns the driving point's sensor (1-based).
    """
    if rec.input_name != "force":
        raise StateSpaceIdentificationError(
            f"{rec.source}: without the masses a structure's element is sized by a measured force at a sensed point "
            f"(the driving point); this record's input is {rec.input_name}: give the masses ('# masses:', --masses)"
        )
    if rec.force_dof is None:
        # not guessed: the element's coefficients are the ratio of two rows of the extended FRF at the driving point,
        # and at another sensor they are another number (the F-16 benchmark's force acts at sensor 1, beside neither
        # of the joint's sensors)
        raise StateSpaceIdentificationError(
            f"{rec.source}: without the masses a structure's element is sized through the sensor the force acts at "
            f"(the driving point), which the record does not name: give it ('# force_dof: K' in the header, "
            f"--force-dof K, load(..., force_dof=K)), 1..{rec.n_dof}"
        )
    rec.require(max(2000, 40 * block_rows), "NSI")
    return int(rec.force_dof)


def force_band_top(u: np.ndarray, fs: float, share: float = FORCE_POWER_SHARE) -> float:
    """The frequency below which ``share`` of the force's power lies (Welch), at most 0.45 fs: the band where the
    record tells the structure's response from noise (a pole above it models the sensors' noise: a 260 Hz pole at
    4 % stable over orders on a chain forced to 150 Hz, with 1 % sensor noise).
    """
    freqs, pxx = signal.welch(u - np.mean(u), fs, nperseg=min(u.size, int(4 * fs)))
    cum = np.cumsum(pxx)
    top = float(freqs[min(int(np.searchsorted(cum, share * cum[-1])), freqs.size - 1)])
    return min(top, 0.45 * fs)


def unseen_share(u_ident: np.ndarray, u_tail: np.ndarray, fs: float) -> float:
    """The share of the held-out tail's force power at frequencies where the identification part's force has less
    than 1 % of its peak power (Welch): near 0 for a random test, near 1 for a sine sweep's tail, which drives the
    structure in a band (and at modes) the identification never saw.
    """
    n = min(u_ident.size, u_tail.size, int(4 * fs))
    _, p_id = signal.welch(u_ident - np.mean(u_ident), fs, nperseg=n)
    _, p_tail = signal.welch(u_tail - np.mean(u_tail), fs, nperseg=n)
    return float(p_tail[p_id < 0.01 * p_id.max()].sum() / max(p_tail.sum(), 1e-300))


def _stable(pole: tuple[float, float], others: list[tuple[float, float]]) -> bool:
    f, z = pole
    return any(abs(f / g - 1) < F_TOL and abs(z - y) < max(ZETA_TOL * abs(y), ZETA_ABS) for g, y in others)


def stabilisation(w: np.ndarray, y: np.ndarray, dt: float, block_rows: int, f_max: float,
                  max_order: int = MAX_ORDER) -> tuple[list[dict[str, Any]], list[float], int]:  # fmt: skip
    """The stabilisation diagram's rows (order, poles with ``stable``), the physical modes' frequencies and the
    lowest order holding them all (module docstring).
    """
    orders = list(range(2, min(max_order, block_rows * y.shape[1]) + 1, 2))
    lam = subspace.poles_by_order(w, y, dt, block_rows, orders)
    poles = {n: sorted((float(abs(q) / (2 * math.pi)), float(-q.real / abs(q))) for q in p
                       if q.imag > 0 and 0 < -q.real / abs(q) < MAX_ZETA and abs(q) / (2 * math.pi) < f_max)
             for n, p in lam.items()}  # fmt: skip
    ns = sorted(poles)
    rows, run = [], {}
    for k, n in enumerate(ns):
        later = [poles[m] for m in ns[k + 1 : k + STABLE_RUN]]
        marks = [len(later) == STABLE_RUN - 1 and all(_stable(p, q) for q in later) for p in poles[n]]
        rows.append({"order": n, "poles": [{"f_hz": f, "zeta": z, "stable": s} for (f, z), s in
                                           zip(poles[n], marks, strict=True)]})  # fmt: skip
        run[n] = [p for p, s in zip(poles[n], marks, strict=True) if s]
    # a mode is physical when it is marked stable at STABLE_RUN orders or more with a damping ratio a structure's mode
    # has (below PHYSICAL_ZETA): the noise's poles, heavily damped, also meet the next orders' now and then (a chain
    # record with 1 % sensor noise: a 145 Hz pole at 11 % marked at 3 orders; noise-free, 288 Hz at 37 % at one),
    # while a lightly damped mode seen weakly by the sensors may lose its mark at some orders (27.9 Hz at 3 % noise:
    # marked at 6 of 13 orders)
    clusters: list[list[tuple[float, float]]] = []
    for n in ns:
        for f, z in run[n]:
            home = next((c for c in clusters if abs(f / c[0][0] - 1) < F_TOL), None)
            if home is None:
                clusters.append([(f, z)])
            else:
                home.append((f, z))
    physical = sorted(float(np.median([f for f, _ in c])) for c in clusters
                      if len(c) >= STABLE_RUN and np.median([z for _, z in c]) < PHYSICAL_ZETA)  # fmt: skip
    if not physical:
        raise StateSpaceIdentificationError("no mode is stable over the stabilisation diagram's orders")
    chosen = next((n for n in ns if all(any(abs(f / g - 1) < F_TOL for g, _ in poles[n]) for f in physical)), ns[-1])
    return rows, physical, chosen


def element_motion(rec: Measurement, at: tuple[int, int], cut_hz: float,
                   r: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """The element's relative motion r and r' for its basis: the sensors' difference (or ``r``, the same motion
    with its slow part from ``quasi_static_motion``) low-passed without phase at ``cut_hz`` (``BASIS_BAND_FACTOR``
    times the force's band top; ``derivatives.band_limited``) and differentiated spectrally (exact on a band-limited
    signal). The sensor noise a basis function carries is an error in an input, which biases the subspace step: on
    the 5-mode chain with 1 % noise the modes came out 0.08-0.21 % low with the record's Savitzky-Golay states (its
    window allowed no smoothing), 0.02-0.05 % with this.
    """
    r = relative(rec.channels, at) if r is None else r
    return smooth_and_differentiate(band_limited(r, rec.fs, cut_hz), rec.fs, (0, 0))


def sensor_channels(rec: Measurement) -> dict[int, dict[str, Any]]:
    """Each sensor's channel as the loader derived it (``rec.info["response"]["channels"]``), by its number."""
    return {c["dof"]: c for c in (rec.info.get("response") or {}).get("channels") or [] if "dof" in c}


def output_kind(rec: Measurement) -> str:
    """The model's outputs: "acceleration" where every sensor is an accelerometer (what they measured), else
    "displacement".
    """
    chans = sensor_channels(rec)
    every = all(chans.get(k, {}).get("measured") == "y_acc" for k in range(1, rec.n_dof + 1))
    return "acceleration" if every else "displacement"


def decimation(fs: float, cut_hz: float) -> int:
    """The decimation factor that leaves ``SAMPLES_PER_CUT`` samples or more per cycle of ``cut_hz`` (module
    docstring), at least 1.
    """
    return max(1, int(fs // (SAMPLES_PER_CUT * cut_hz)))


def sensor_outputs(rec: Measurement, kind: str) -> np.ndarray:
    """The model's outputs (T, sensors): the channels, or for accelerometers their accelerations, the channels'
    second derivative (each a double integral above its corner, this is the measured acceleration there). By
    the five-point stencil (``scipy.signal.savgol_filter``, a quartic through five samples: error (2 pi f dt)^4 / 90,
    5e-5 at a tenth of the rate; its ends by the same quartic): on the F-16 benchmark's record 0.15-0.25 % of the
    low-passed rms from the file's own accelerations, all of it their content below the integral's 1 Hz corner. A
    spectral derivative is exact inside but rings at a record's ends (there 70 times the rms).
    """
    if kind == "displacement":
        return rec.channels.T
    return signal.savgol_filter(rec.channels, 5, 4, deriv=2, delta=rec.dt, axis=1, mode="interp").T


def accelerometer_noise(rec: Measurement, at: tuple[int, int]) -> tuple[float, float] | None:
    """When the element's motion comes from accelerometers whose double integrals were high-passed: their
    acceleration noise together (the root sum of squares) [m/s^2] and the corner [Hz] above which the integrals are
    exact; else None (I = 0, the ground, has no sensor; a cross-well integral's slow part, its stays in the wells, is
    kept by the loader, not high-passed).
    """
    chans = sensor_channels(rec)
    sensed = [chans.get(k) or {} for k in at if k]
    if not sensed or any(c.get("measured") != "y_acc" or c.get("highpass_hz") is None for c in sensed):
        return None
    noise = [float(c.get("acceleration_noise_m_s2") or 0.0) for c in sensed]
    if not all(x > 0 for x in noise):
        return None
    return float(math.sqrt(sum(x * x for x in noise))), max(float(c["highpass_hz"]) for c in sensed)


def quasi_static_motion(r: np.ndarray, u: np.ndarray, fs: float, basis: laws.FeedbackBasis, cut_hz: float,
                        corner_hz: float, top_hz: float, noise: float, below_hz: float | None = None
                        ) -> tuple[np.ndarray, dict[str, Any]]:  # fmt: skip
    """The relative motion of two accelerometers ``r`` with its slow part from the structure's quasi-static law.

    A double integral is exact above its corner only, has nothing below it, and its error, white acceleration noise
    ``noise`` [m/s^2] over (2 pi f)^2, is largest just above it; the element's law mixes that slow error into the
    band (3 k3 r^2 dr for a cubic). On a 3-DOF chain read by two accelerometers (0.1 % noise) the joint's k3 came
    out 14 % low with an error of 30 um below 2 Hz in r's 0.75 mm; the same record with the true r gave it within
    0.3 %, with the true r's content below 1 Hz taken off 24 % low: the slow part is needed, and the integral's is
    wrong. It is the structure's answer to the element's own slow force (the law's intermodulation) and to the
    force's slow content, quasi-static below the lowest mode (``top_hz``, half of it): there r's spectrum is
    R = (a + b f^2) F + sum_j (c_j + d_j f^2) G_j, F the force's and G_j the element's basis functions' of r itself.
    The law's real coefficients are fitted by least squares over the bins of [``corner_hz``, ``top_hz``], where the
    integral is exact and the form holds, and the law replaces r below the crossover: the first ``SLOW_BIN_HZ`` bin
    whose residual exceeds ``SLOW_RESIDUAL_RATIO`` times the integral's expected noise power (below it the
    integral's noise is the larger error, above it the law's), or ``below_hz`` where given. Iterated to its fixed
    point (G is of r). Returns the motion and what was done.
    """
    n = r.size
    fq = np.fft.rfftfreq(n, 1 / fs)
    measured = sp_fft.rfft(r - r.mean())
    force = sp_fft.rfft(u - u.mean())
    fit = (fq >= corner_hz) & (fq <= top_hz)
    noise_power = n * noise**2 / np.maximum(2 * np.pi * fq, 1e-300) ** 4  # E|FFT|^2 of the integral's error per bin

    def solve(cross: float) -> tuple[np.ndarray, np.ndarray]:
        est, law = r, measured
        for _ in range(SLOW_ITERATIONS):
            x = band_limited(est, fs, cut_hz)
            g = sp_fft.rfft(-basis.displacement(x - np.mean(x), float(np.mean(x))), axis=0)
            X = np.column_stack([force, fq**2 * force, g, fq[:, None] ** 2 * g])
            coef = np.linalg.lstsq(np.vstack([X[fit].real, X[fit].imag]),
                                   np.concatenate([measured[fit].real, measured[fit].imag]), rcond=None)[0]  # fmt: skip
            law = X @ coef
            spec = measured.copy()
            spec[fq < cross] = law[fq < cross]
            spec[0] = 0.0
            est = sp_fft.irfft(spec, n) + r.mean()
        return est, np.abs(measured - law) ** 2

    def done(out: np.ndarray, cross: float, ratios: list[float]) -> tuple[np.ndarray, dict[str, Any]]:
        return out, {"below_hz": float(cross), "law_fitted_hz": [float(corner_hz), float(top_hz)],
                     "residual_over_noise": [round(q, 3) for q in ratios], "bin_hz": SLOW_BIN_HZ}  # fmt: skip

    if below_hz is not None:
        return done(solve(below_hz)[0], below_hz, [])
    whole, residual = solve(top_hz)  # the law over its whole band: its residual against the integral, bin by bin
    edges = np.arange(corner_hz, top_hz, SLOW_BIN_HZ)
    ratios = []
    for a in edges:
        b = (fq >= a) & (fq < a + SLOW_BIN_HZ)
        ratios.append(float(residual[b].mean() / noise_power[b].mean()) if b.any() else math.nan)
    cross = next((float(a) for a, q in zip(edges, ratios, strict=True) if q > SLOW_RESIDUAL_RATIO), float(top_hz))
    return done(whole if cross == top_hz else solve(cross)[0], cross, ratios)  # no bin passed: the whole band's


@dataclasses.dataclass(frozen=True)
class Sampling:
    """How the subspace step reads a record: its outputs (``output_kind``), the record's rate [Hz], the basis's
    band top [Hz] and the decimation factor (``decimation``; module docstring).
    """

    output: str
    fs: float
    cut_hz: float
    q: int

    @classmethod
    def of(cls, rec: Measurement, cut_hz: float) -> Sampling:
        return cls(output_kind(rec), rec.fs, cut_hz, decimation(rec.fs, cut_hz))

    @property
    def dt(self) -> float:
        """The model's sampling interval [s]."""
        return self.q / self.fs

    def apply(self, x: np.ndarray) -> np.ndarray:
        """``x`` (T, ...) low-passed at the band top and decimated (itself where the factor is 1)."""
        return x if self.q == 1 else band_limited(x.T, self.fs, self.cut_hz).T[:: self.q]


def _channels(rec: Measurement, at: tuple[int, int], sampling: Sampling, basis: laws.FeedbackBasis,
              r_ref: float | None = None, r: np.ndarray | None = None):  # fmt: skip
    """The extended input [f, -basis] and the model's outputs of ``rec``, unscaled, as ``sampling`` reads them, and
    r* (``r``: the element's motion given, ``element_motion``).
    """
    r, vr = element_motion(rec, at, sampling.cut_hz, r)
    r_ref = float(np.mean(r)) if r_ref is None else r_ref
    w = np.column_stack([rec.u, feedback_inputs(basis, r, vr, r_ref)])
    return sampling.apply(w), sampling.apply(sensor_outputs(rec, sampling.output)), r_ref


def coefficient_names(basis: laws.FeedbackBasis) -> list[tuple[str, str]]:
    """Each basis function's coefficient name and units: a power x^n's is k{n}, about r* (``k{n}_tilde``) but for
    the law's highest power, which the shift leaves alone; r'|r'|'s is c_nl; any other keeps its basis name.
    """
    names = basis.names()
    top = max((int(n[1:]) for n in names if n[:1] == "x" and n[1:].isdigit()), default=0)
    out = []
    for n in names:
        if n[:1] == "x" and n[1:].isdigit():
            k = int(n[1:])
            out.append((f"k{k}" if k == top else f"k{k}_tilde", f"N/m^{k}"))
        elif n == "vabsv":
            out.append(("c_nl", "N s^2/m^2"))
        elif n.startswith("v^") and n[2:].isdigit():
            out.append((n, f"N s^{n[2:]}/m^{n[2:]}"))
        else:
            out.append((n, "N per unit of its basis function"))
    return out


def _standardised(w: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, tuple[np.ndarray, ...]]:
    """The extended input and the outputs made zero-mean and unit-variance per channel, and their (means,
    standard deviations); one refusal where a channel is constant.
    """
    wm, ws = w.mean(axis=0), w.std(axis=0)
    ym, ys = y.mean(axis=0), y.std(axis=0)
    if np.any(ws == 0) or np.any(ys == 0):
        raise StateSpaceIdentificationError("the force, a basis function or a sensor is constant")
    return (w - wm) / ws, (y - ym) / ys, (wm, ws, ym, ys)


def _fit(w: np.ndarray, y: np.ndarray, sampling: Sampling, order: int, block_rows: int):
    """The state-space fit at ``order`` on standardised channels, back in SI units: (A, B, C, D, means), D None for
    displacement outputs (they have no feedthrough).
    """
    wn, yn, (wm, ws, ym, ys) = _standardised(w, y)
    ss = subspace.identify(wn, yn, sampling.dt, order, block_rows)
    assert ss.Ad is not None and ss.Bd is not None
    D = ys[:, None] * ss.D / ws[None, :] if sampling.output == "acceleration" else None
    return ss.Ad, ss.Bd / ws[None, :], ys[:, None] * ss.C, D, wm, ym


def _refitted(model: StateSpaceStructure, rec: Measurement, sampling: Sampling, basis: laws.FeedbackBasis,
              block_rows: int, r: np.ndarray | None = None) -> StateSpaceStructure:  # fmt: skip
    """``model``'s identification again on ``rec`` (a block of the record, or another basis band in
    ``sampling``), at its order and about its r* (``r``: the element's motion over ``rec``, as ``_channels``): the
    batch means' and the band's fits.
    """
    w, y, _ = _channels(rec, model.at, sampling, basis, model.r_ref, r)
    A, B, C, D, wm, ym = _fit(w, y, sampling, model.order, block_rows)
    return dataclasses.replace(model, A=A, B=B, C=C, D=D, input_mean=wm, output_mean=ym)


def _coefficients(model: StateSpaceStructure, p: int, band: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    """mu_j and |Im/Re| from the extended FRF's row p against the relative motion's FRF to the force."""
    he = model.extended_frf(np.linspace(band[0], band[1], 512))  # (F, sensors, inputs)
    a = he[:, :, 0] @ coupling(model.n_sensors, model.at)
    b = he[:, p - 1, 1:]
    mu = (np.conj(a)[:, None] * b).sum(axis=0) / (np.abs(a) ** 2).sum()
    return mu.real, np.abs(mu.imag) / np.maximum(np.abs(mu.real), 1e-300)


def best_linear(w: np.ndarray, y: np.ndarray, sampling: Sampling, order: int, block_rows: int,
                like: StateSpaceStructure) -> StateSpaceStructure:  # fmt: skip
    """The best linear model of ``order`` on the identification's channels (``_channels``' w and y): the same
    subspace step with the force (w's first column) its only input. As a ``StateSpaceStructure`` like ``like`` whose
    element's input columns are zero, so it runs and reads its start states as any (``element`` makes no difference).
    """
    A, B, C, D, wm, ym = _fit(w[:, :1], y, sampling, order, block_rows)
    nb = w.shape[1] - 1
    D = None if D is None else np.hstack([D, np.zeros((D.shape[0], nb))])
    return dataclasses.replace(like, A=A, B=np.hstack([B, np.zeros((order, nb))]), C=C, D=D,
                               input_mean=np.concatenate([wm, np.zeros(nb)]), output_mean=ym)  # fmt: skip


def read_record(rec: Measurement, at: tuple[int, int], sampling: Sampling, r: np.ndarray | None = None):
    """The force, the model's outputs (sensors, T), the element's r and r' of ``rec`` as ``sampling`` reads them
    (``r``: the element's motion given, ``element_motion``).
    """
    r, vr = element_motion(rec, at, sampling.cut_hz, r)
    y = sampling.apply(sensor_outputs(rec, sampling.output)).T
    return sampling.apply(rec.u), y, r[:: sampling.q], vr[:: sampling.q]


def window_plan(model: StateSpaceStructure, n: int, fs: float, window_s: float, start: int = 0) -> tuple[int, range]:
    """The restarted windows over samples [start, n) of a record read at ``fs`` (the model's rate): their length
    (``window_s``, at least four times the model's order) and their starts, the first a window in (the stretch
    before each is where its start state is read, ``window_run``).
    """
    n_win = max(int(round(window_s * fs)), 4 * model.order)
    return n_win, range(max(start, n_win), n - n_win + 1, n_win)


def window_run(model: StateSpaceStructure, element: bool, u, y, r, vr, s0: int, n_win: int):
    """The model's free run over the window [s0, s0 + n_win) from the state its least squares reads off the stretch
    of the same length before it (``StateSpaceStructure.initial_state``): (outputs, diverged).
    """
    lead = slice(s0 - n_win, s0)
    x0 = model.initial_state(u[lead], y[:, lead], r[lead], vr[lead], element)
    return model.run(u[s0 : s0 + n_win], x0, element)


def _held_out(model: StateSpaceStructure, rec: Measurement, start: int, window_s: float, sampling: Sampling,
              r: np.ndarray | None = None, linear: StateSpaceStructure | None = None) -> dict[str, Any]:  # fmt: skip
    """The held-out windows (module docstring): the model's error, its linear part's and the best linear model's
    (``linear``, ``best_linear``; None: not judged), % of the sensors' rms (of the model's outputs as ``sampling``
    reads them), each window's start state read by the model run in it from the stretch before.
    """
    u, y, r, vr = read_record(rec, model.at, sampling, r)
    fs = rec.fs / sampling.q
    n_win, starts = window_plan(model, u.size, fs, window_s, -(-start // sampling.q))
    out: dict[str, Any] = {"window_s": n_win / fs, "starts_s": []}
    runs = {"": (model, True), "linear_": (model, False)}
    if linear is not None:
        runs["best_linear_"] = (linear, False)
    errs: dict[str, list[float]] = {key: [] for key in runs}
    scale = []
    diverged = dict.fromkeys(runs, 0)
    for s0 in starts:
        out["starts_s"].append(s0 / fs)
        seg = y[:, s0 : s0 + n_win]
        scale.append(((seg - seg.mean(axis=1, keepdims=True)) ** 2).sum())
        for key, (m, element) in runs.items():
            run, gone = window_run(m, element, u, y, r, vr, s0, n_win)
            diverged[key] += gone
            errs[key].append(np.inf if gone else float(((run - seg) ** 2).sum()))
    if not scale:
        raise StateSpaceIdentificationError(f"{rec.source}: the held-out tail is shorter than one window")
    total = float(np.sum(scale))
    for key in runs:
        e = np.asarray(errs[key])
        out[f"{key}rms_percent"] = float(100 * math.sqrt(e.sum() / total)) if np.all(np.isfinite(e)) else math.inf
        out[f"{key}median_window_percent"] = float(np.median(100 * np.sqrt(e / np.asarray(scale))))
        out[f"{key}diverged_windows"] = diverged[key]
    out["windows"] = len(scale)
    return out


def driving_point_misses(model: StateSpaceStructure, modes: list[Mode]) -> dict[int, list[float]]:
    """Each sensor's (1-based) modes [Hz] at which its FRF to the force does not read as a driving point's: a
    structure's compliance at the point the force acts on has a negative imaginary part at every mode (its residues
    phi_p^2 / (2 j m_r w_r), one sign), another point's changes sign with the modes' shapes; a driving point's list
    is empty. On the F-16 benchmark's record with the force at sensor 1, sensor 1's alone (the joint's sensors flip
    at 12.3 Hz); on the five-mass chain, sensor 1's alone.
    """
    f = np.array([m.f_hz for m in modes])
    H = model.frf(f)  # (modes, sensors)
    return {k + 1: f[~(H[:, k].imag < 0)].tolist() for k in range(H.shape[1])}


def _nearest(modes: list[Mode], f_hz: float) -> Mode | None:
    """The mode of ``modes`` within ``F_TOL`` of ``f_hz`` (the nearest), or None."""
    near = [m for m in modes if abs(m.f_hz / f_hz - 1) < F_TOL]
    return min(near, key=lambda m: abs(m.f_hz - f_hz)) if near else None


CANDIDATE_LAWS = ("cubic", "quintic", "septic")
"""The restoring laws ``law="auto"`` compares on a structure read through its sensors: the polynomials, linear in
their parameters (a shaped law's shape is fitted on a single DOF's record only)."""


def choose_state_space_law(est, rec: Measurement, at: tuple[int, int]) -> Identification:
    """``NSI(law="auto")`` on a structure without masses: each of ``CANDIDATE_LAWS`` (with the estimator's damping
    law) identified on the identification part less its last ``law_choice.SELECTION_FRACTION`` of the record, and
    its restarted windows over that selection part (the held-out protocol, never the held-out tail) scored; a
    candidate whose selection runs diverge, or whose element predicts no better than its linear part, is not
    chosen. The least median window error wins; the chosen law is identified again on the whole identification part
    and judged on the tail. The comparison is ``settings["law_choice"]``.
    """
    from types import SimpleNamespace

    from negstiff.inference.steps.law_choice import SELECTION_FRACTION

    n_id = int(round(rec.n * (1 - est.validation_fraction)))
    n_sel = int(round(SELECTION_FRACTION * rec.n))
    if n_id - n_sel < n_id // 2:
        raise InputError(f"{rec.source}: too short to compare laws (the selection part would exceed the fit)")
    ident = rec.segment(0, n_id)
    rows = []
    for law in CANDIDATE_LAWS:
        part = SimpleNamespace(block_rows=est.block_rows, validation_fraction=n_sel / n_id, law=law,
                               damping=est.damping)  # fmt: skip
        row: dict[str, Any] = {"law": law, "damping": est.damping}
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # each candidate's notes; the chosen one's are said again
                v = identify_state_space(part, ident, at).validation
        except (InputError, ValueError, np.linalg.LinAlgError) as exc:
            rows.append({**row, "problems": [" ".join(str(exc).split())]})
            continue
        problems = [f"{v['diverged_windows']} of its selection windows diverged"] if v["diverged_windows"] else []
        if not v["rms_percent"] < v["linear_rms_percent"]:
            problems.append("its element predicts the selection part no better than its linear part")
        rows.append({**row, "median_window_percent": v["median_window_percent"], "rms_percent": v["rms_percent"],
                     "windows": v["windows"], "problems": problems})  # fmt: skip
    admissible = [r for r in rows if not r["problems"]]
    if not admissible:
        raise StateSpaceIdentificationError(
            f"{rec.source}: no law passes on the selection part ("
            + "; ".join(f"{r['law']}: {r['problems'][0]}" for r in rows)
            + ")"
        )
    best = min(admissible, key=lambda r: (r["median_window_percent"], r["rms_percent"]))
    chosen = SimpleNamespace(block_rows=est.block_rows, validation_fraction=est.validation_fraction, law=best["law"],
                             damping=est.damping)  # fmt: skip
    result = identify_state_space(chosen, rec, at)
    choice = {"chosen": best["law"], "candidates": rows,
              "selection": f"samples {n_id - n_sel}-{n_id} (the identification part's last "
                           f"{100 * SELECTION_FRACTION:.0f} % of the record), each candidate fitted before it",
              "criterion": "the least median window error over the selection part's restarted windows"}  # fmt: skip
    return dataclasses.replace(result, settings={**result.settings, "law_choice": choice})


def identify_state_space(est, rec: Measurement, at: tuple[int, int]) -> Identification:
    """NSI on ``rec`` (N sensors, no masses, a measured force at a sensed point) with the element at ``at``
    (module docstring).
    """
    p = check_record(rec, at, est.block_rows)
    n_id = int(round(rec.n * (1 - est.validation_fraction)))
    ident = rec.segment(0, n_id)
    f_max = force_band_top(ident.u, rec.fs)
    # the basis's band: 1.5x the force's band top, but no wider than the response stands above the sensors' noise
    # (``derivatives.basis_band_hz``, the ring-downs' rule): a hammer's pulse spreads the force to 425 Hz while the
    # chain's response leaves its noise at 220 Hz, and the noise in the basis put k3 2.4 % low (0.4 % with this)
    cut = min(BASIS_BAND_FACTOR * f_max, basis_band_hz(relative(ident.channels, at), rec.fs), 0.45 * rec.fs)
    basis = element_basis(est.law or laws.DEFAULT_RESTORING, est.damping)
    sampling = Sampling.of(rec, cut)
    w, y, r_ref = _channels(ident, at, sampling, basis)
    wn, yn, _ = _standardised(w, y)
    rows, physical, order = stabilisation(wn, yn, sampling.dt, est.block_rows, f_max)
    # accelerometers across the element: its motion's slow part from the structure's quasi-static law below the
    # lowest mode (``quasi_static_motion``), and the diagram again on the basis of that motion
    r_el, slow = None, None
    acc = accelerometer_noise(rec, at)
    if acc is not None and physical[0] / 2 >= acc[1] + 2 * SLOW_BIN_HZ:
        r_el, slow = quasi_static_motion(relative(rec.channels, at), rec.u, rec.fs, basis, cut, acc[1],
                                         physical[0] / 2, acc[0])  # fmt: skip
        w, y, r_ref = _channels(ident, at, sampling, basis, r=r_el[:n_id])
        wn, yn, _ = _standardised(w, y)
        rows, physical, order = stabilisation(wn, yn, sampling.dt, est.block_rows, f_max)
    fitted, errors = None, []
    for n in range(order, min(MAX_ORDER, est.block_rows * y.shape[1]) + 1, 2):
        try:
            fitted = _fit(w, y, sampling, n, est.block_rows)
            order = n
            break
        except (ValueError, np.linalg.LinAlgError) as exc:
            errors.append(f"order {n}: {exc}")
    if fitted is None:
        raise StateSpaceIdentificationError(f"{rec.source}: no state-space model from order {order} up ({errors[-1]})")
    A, B, C, D, wm, ym = fitted
    model = StateSpaceStructure(A, B, C, sampling.dt, at, r_ref, wm, ym, basis.restoring.name, basis.damping.name,
                                sampling.output, D, cut)  # fmt: skip
    modes = [m for m in model.modes() if any(abs(m.f_hz / f - 1) < F_TOL for f in physical)]
    if not modes:
        raise StateSpaceIdentificationError(f"{rec.source}: the order-{order} model holds none of the stable modes")
    band = (0.5 * modes[0].f_hz, min(1.5 * modes[-1].f_hz, f_max))
    mu, quality = _coefficients(model, p, band)
    misses = driving_point_misses(model, modes)
    looks_driven = [k for k, off in misses.items() if not off]
    # batch means: each block's own fit at the chosen order, about the same r*
    edges = np.linspace(0, n_id, BLOCKS + 1).round().astype(int)
    per_block: list[np.ndarray] = []
    block_modes: list[list[Mode | None]] = []
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        try:
            r_block = None if r_el is None else r_el[int(a) : int(b)]
            block = _refitted(model, ident.segment(int(a), int(b)), sampling, basis, est.block_rows, r_block)
            per_block.append(_coefficients(block, p, band)[0])
            block_modes.append([_nearest(block.modes(), m.f_hz) for m in modes])
        except (ValueError, np.linalg.LinAlgError, InputError):
            continue
    se_blocks = (np.std(per_block, axis=0, ddof=1) / math.sqrt(len(per_block)) if len(per_block) >= 2
                 else np.full(mu.size, np.nan))  # fmt: skip
    # the basis's band is a choice the data do not pin (its harmonics against the sensors' noise): the same fit with
    # the band at BAND_CHOICES' ends, half their spread an error of its own, added in quadrature. On a 3-DOF chain
    # with lasers of 2 um the blocks' standard error of k3 was 0.024 % and its error 0.12 %; the band's spread 0.2 %
    by_band = []
    for factor in BAND_CHOICES:
        try:
            r_ident = None if r_el is None else r_el[:n_id]
            band_cut = min(factor * cut, 0.45 * rec.fs / sampling.q)  # within the model's own Nyquist
            other = _refitted(model, ident, dataclasses.replace(sampling, cut_hz=band_cut), basis, est.block_rows,
                              r_ident)  # fmt: skip
            by_band.append(_coefficients(other, p, band)[0])
        except (ValueError, np.linalg.LinAlgError, InputError):
            continue
    se_band = 0.5 * np.ptp(np.vstack([mu, *by_band]), axis=0) if by_band else np.zeros(mu.size)
    # the accelerometers' slow part: its crossover is a choice too (the bin where the law's residual passes the
    # integral's noise): the fits with it a bin lower and a bin higher, half their spread an error of its own
    by_slow = []
    if slow is not None and acc is not None:
        for other_hz in (slow["below_hz"] - SLOW_BIN_HZ, slow["below_hz"] + SLOW_BIN_HZ):
            if not acc[1] <= other_hz <= slow["law_fitted_hz"][1]:
                continue
            r_other, _ = quasi_static_motion(relative(rec.channels, at), rec.u, rec.fs, basis, cut, acc[1],
                                             slow["law_fitted_hz"][1], acc[0], other_hz)  # fmt: skip
            try:
                other = _refitted(model, ident, sampling, basis, est.block_rows, r_other[:n_id])
                by_slow.append(_coefficients(other, p, band)[0])
            except (ValueError, np.linalg.LinAlgError, InputError):
                continue
    se_slow = 0.5 * np.ptp(np.vstack([mu, *by_slow]), axis=0) if by_slow else np.zeros(mu.size)
    se = np.sqrt(se_blocks**2 + se_band**2 + se_slow**2)
    modes_se = []
    for k in range(len(modes)):
        seen = [bm[k] for bm in block_modes if bm[k] is not None]
        modes_se.append({key: float(np.std([getattr(m, key) for m in seen], ddof=1) / math.sqrt(len(seen)))
                         if len(seen) >= 2 else None for key in ("f_hz", "zeta")})  # fmt: skip
    named = coefficient_names(basis)
    names = [n for n, _ in named]
    # the 90 % interval from the blocks' Student t (len(per_block) - 1 degrees of freedom: four blocks give
    # +-2.35 standard errors), on the standard error with the band's part
    t90 = float(stats.t.ppf(0.95, len(per_block) - 1)) if len(per_block) >= 2 else math.nan
    element: dict[str, Any] = {
        n: {"value": float(mu[j]), "se": float(se[j]), "se_blocks": float(se_blocks[j]), "se_band": float(se_band[j]),
            "se_slow_part": float(se_slow[j]),
            "interval_90": [float(mu[j] - t90 * se[j]), float(mu[j] + t90 * se[j])],
            "quality_im_over_re": float(quality[j])}
        for j, n in enumerate(names)
    }  # fmt: skip

    element["r_ref_m"] = r_ref
    element["units"] = dict(named)
    element["laws"] = {"restoring": basis.restoring.name, "damping": basis.damping.name}
    window_s = max(0.25, 4.0 / modes[0].f_hz)
    try:
        linear = best_linear(w, y, sampling, order, est.block_rows, model)
    except (ValueError, np.linalg.LinAlgError):
        linear = None  # no linear model of this order on these channels: the tail judges the model and its part
    validation = _held_out(model, rec, n_id, window_s, sampling, r_el, linear)
    validation["best_linear_order"] = order if linear is not None else None
    validation["tail_unseen_band_share"] = unseen = unseen_share(ident.u, rec.u[n_id:], rec.fs)
    freqs = np.linspace(band[0], band[1], 256)
    H = model.frf(freqs)
    lines = [f"{rec.source}: the element's {n} is poorly determined (|Im/Re| {quality[j]:.2g} of its FRF ratio)"
             for j, n in enumerate(names) if quality[j] > QUALITY_WARNING and abs(mu[j]) > 2 * se[j]]  # fmt: skip
    if misses[p]:
        off = [f"{f:.3g}" for f in misses[p]]
        there = f"; sensor {', '.join(map(str, looks_driven))}'s does: is the force there?" if looks_driven else ""
        lines.append(
            f"{rec.source}: the force is said to act at sensor {p}, but its FRF does not read as a driving point's "
            f"(its imaginary part is positive at {', '.join(off)} Hz, where a driving point's compliance is negative "
            f"at every mode){there or '.'} The element's coefficients are sized through sensor {p}"
        )
    acc_sensors = [k for k, c in sensor_channels(rec).items() if c.get("measured") == "y_acc"]
    if slow is None and any(k in at for k in acc_sensors):
        why = ("the record has no band between their double integral's exact band and the lowest mode "
               f"({physical[0]:.3g} Hz) to fit its slow part on" if acc is not None else
               "its slow part is not from the structure's quasi-static law (that needs both of the element's sensors "
               "accelerometers whose integrals were high-passed, their noise measured)")  # fmt: skip
        lines.append(
            f"{rec.source}: the element's relative motion comes from accelerometers and {why}: its slow error is mixed "
            "into the band by the element's law (on a test chain at 0.1 % noise the joint's k3 was lost while the "
            "modes held within 0.2 %): read the modes, and size the joint from displacement sensors"
        )
    elif sampling.output == "displacement" and [k for k in acc_sensors if k not in at]:
        # (where every sensor is an accelerometer the outputs are their accelerations, which hold no slow error)
        lines.append(
            f"{rec.source}: sensor(s) {', '.join(str(k) for k in acc_sensors if k not in at)} are accelerometers "
            "away from the element: their double integrals keep their slow error in the outputs (on a test chain "
            "whose driving point was read by one, the joint's k3 came out 40 % low while the modes held within "
            "0.2 %): read the modes, and size the joint from displacement sensors there"
        )
    if unseen > UNSEEN_WARNING:
        lines.append(
            f"{rec.source}: {100 * unseen:.0f} % of the held-out tail's force lies where the identification part's "
            "has none (a sine sweep's tail?): its modes there are not in the model, and the held-out error says so, "
            "not how good the model is where it was fitted; validate on another record"
        )
    if not validation["rms_percent"] < validation["linear_rms_percent"]:
        lines.append(f"{rec.source}: the element's terms do not improve the held-out prediction "
                     f"({validation['rms_percent']:.3g} % against the linear part's "
                     f"{validation['linear_rms_percent']:.3g} %)")  # fmt: skip
    elif linear is not None and not validation["rms_percent"] < validation["best_linear_rms_percent"]:
        lines.append(f"{rec.source}: the model predicts the held-out tail no better than the best linear model of "
                     f"its order ({validation['rms_percent']:.3g} % against {validation['best_linear_rms_percent']:.3g}"
                     " %): the element's law is not what the record shows beyond its equivalent linear stiffness "
                     "and damping")  # fmt: skip
    issue([(_Warning, x) for x in lines])
    return Identification(
        method="nsi", system=model, linear_part="state_space", modal={"linear": modes}, element_estimate=element,
        validation=Bunch(validation),
        stabilisation=rows, warnings=tuple(lines),
        frf={"f_hz": freqs.tolist(), "real": H.real.T.tolist(), "imag": H.imag.T.tolist(), "units": "m/N",
             "input": f"force at sensor {p}"},
        settings={"block_rows": est.block_rows, "order": order, "order_from": "stabilisation diagram",
                  "physical_modes_hz": physical, "modes_se": modes_se, "driving_point": p,
                  "driving_point_like": looks_driven,
                  "identification_samples": n_id,
                  "element_slow_part": slow,
                  "basis": list(basis.names()),
                  "element_motion": f"the sensors' difference low-passed at {cut:.4g} Hz (the force's band top "
                                    f"{f_max:.4g} Hz), its derivative spectral",
                  "outputs": sampling.output, "model_fs_hz": rec.fs / sampling.q,
                  "sampling": f"the sensors' {sampling.output}s" + (
                      f", every input and output low-passed at {cut:.4g} Hz and decimated {sampling.q}x"
                      if sampling.q > 1 else ""),
                  "standard_error": f"batch means over {len(per_block)} blocks of the identification part, and half "
                                    "the spread of the fits with the basis's band at 2/3 and 4/3 of its own, and "
                                    "through accelerometers half the spread of the fits with the slow part's "
                                    "crossover a bin lower and higher (in quadrature)"},
    )  # fmt: skip
