"""Characterisation of one harmonically forced record as independent analyses (reference study section 3).

Periodicity (period, amplitudes per branch, Poincare points), regime (in-well or cross-well) and the
largest Lyapunov exponent each give their result, or ``None`` with the ``reason`` it cannot be
determined on this record; one failing does not take the others with it. Only bad input (a record
too short for any cycle count, a forcing frequency beyond Nyquist) fails the whole command.

* Low sampling rates (a lab's 64 Hz, 7 samples per 9 Hz cycle): a record sampled with an
  anti-aliasing filter is band-limited below its Nyquist frequency, so it is first interpolated
  band-limited (polyphase FIR, ``scipy.signal.resample_poly``) to at least ``MIN_SAMPLES_PER_CYCLE``
  samples per forcing cycle; the phase-synchronous spline of ``periodicity`` then sees a smooth
  signal instead of a cubic through 7 points per cycle. The sensor noise that sets the periodicity
  tolerance is then read from the white plateau of the record as acquired
  (``derivatives.noise_floor``: 25.5 um for 28.5 um on a 64 Hz record; a 7-point smoothing
  residual read 1.1 mm there, the response's own curvature).
* The LLE carries an uncertainty: the value is the mean of Wolf's estimates on ``LLE_SEGMENTS``
  consecutive parts of the record, ``sd`` = their spread / sqrt(parts): the value and its sd are what
  the listed segments say (the whole record's estimate and Rosenstein's are reported beside). A record
  is *chaotic* when no period is found and the exponent is significantly positive: above
  ``CHAOS_THRESHOLD`` nats per radian of forcing and ``LLE_SIGMAS`` sd above zero. A record with a
  period never reports a significantly positive exponent: the value is then not determinable, with the
  reason (a periodic orbit's separation is the noise's). Where Wolf and Rosenstein disagree on the
  sign, ``reasons["lle_estimators"]`` says so.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np
from scipy import signal

from negstiff.errors import MeasurementError, RecordWarning, issue
from negstiff.inference.analysis.lyapunov import largest_lyapunov
from negstiff.inference.analysis.periodicity import (
    FREQUENCY_MISLABEL,
    LINE_FRACTION,
    MAX_DECISIVE_TOLERANCE,
    check_forcing_line,
    classify_regime,
    periodicity,
)
from negstiff.inference.record.measurement import Measurement
from negstiff.inference.steps.frame import pin_frame
from negstiff.inference.steps.plausibility import classified
from negstiff.inference.steps.wells import well_guesses

CHAOS_THRESHOLD = 0.05
"""A Wolf exponent counts as significantly positive above this many nats per radian of forcing
(0.05 x 2 pi f: 2.8 1/s at 9 Hz; periodic rig records gave -0.6 to +0.04 1/s, chaotic ones 6.4)."""

LLE_SIGMAS = 3.0
"""... and this many of its standard errors above zero."""

LLE_SEGMENTS = 4
"""Parts of the record whose separate Wolf estimates give the exponent's standard error."""

MIN_SAMPLES_PER_CYCLE = 48
"""Samples per forcing cycle below which a record is first interpolated band-limited."""


def upsampled(rec: Measurement, forcing_hz: float) -> tuple[Measurement, int]:
    """The record interpolated band-limited to >= ``MIN_SAMPLES_PER_CYCLE`` samples per forcing
    cycle (unchanged when it has them), and the factor.
    """
    q = math.ceil(MIN_SAMPLES_PER_CYCLE * forcing_hz / rec.fs)
    if q <= 1:
        return rec, 1
    up = {k: signal.resample_poly(getattr(rec, k), q, 1) for k in ("u", "z")}
    return replace(rec, fs=rec.fs * q, u=up["u"], z=up["z"], z_dot=None, y=None, base_disp=None), q


def _reason(exc: Exception) -> str:
    return " ".join(str(exc).split()) or type(exc).__name__


def significantly_positive(value: float | None, sd: float | None, forcing_hz: float) -> bool:
    """Above ``CHAOS_THRESHOLD`` nats per radian of forcing and (where an sd is known) ``LLE_SIGMAS`` sd."""
    if value is None or not np.isfinite(value):
        return False
    return bool(value > CHAOS_THRESHOLD * 2 * np.pi * forcing_hz and not (sd is not None and np.isfinite(sd)
                                                                          and value <= LLE_SIGMAS * sd))  # fmt: skip


def lyapunov(rec: Measurement, forcing_hz: float, noise: float | None) -> dict[str, Any]:
    """Wolf's exponent as the mean of its estimates on ``LLE_SEGMENTS`` consecutive parts of the record
    (``segments``), ``sd`` their standard error: the value and its uncertainty are what the listed
    segments say. Beside it: the segments' estimates pooled (``segments_pooled``: their total log stretch
    over their total time) and Rosenstein's
    (``rosenstein``, None with ``rosenstein_error`` where no divergence can be followed), and whether the
    two estimators agree on the exponent's sign (``estimators_agree``: both significantly positive, or
    neither).
    """
    w = largest_lyapunov(rec.displacement, rec.dt, forcing_hz=forcing_hz, noise=noise, segments=LLE_SEGMENTS)
    parts = w["segments"]
    if len(parts) >= 2:
        value = float(np.mean(parts))
        sd = float(np.std(parts, ddof=1) / math.sqrt(len(parts)))
        source = f"mean of {len(parts)} segments"
    else:  # too short to split further: the one segment Wolf could follow, without an uncertainty
        value, sd, source = float(w["value"]), float("nan"), f"{len(parts)} segment (too short for more)"
    wolf_positive = significantly_positive(value, sd, forcing_hz)
    rs = w.get("rosenstein")
    rosenstein_positive = significantly_positive(rs, None, forcing_hz)
    out = {
        "value": value,
        "sd": sd,
        "units": "1/s",
        "method": "wolf",
        "value_from": source,
        "segments": parts,
        "segments_pooled": float(w["value"]),
        "rosenstein": rs,
        "estimators_agree": wolf_positive == rosenstein_positive,
        "embedding": {"m": w["m"], "tau_samples": w["tau"] * w["sample_step"]},
        "evolv_samples": w["evolv"] * w["sample_step"],
    }
    if "rosenstein_error" in w:
        out["rosenstein_error"] = w["rosenstein_error"]
    return out


def check_harmonic(rec: Measurement, forcing_hz: float) -> None:
    """Refuse (``MeasurementError``, one line) a harmonic record no characterisation can use: a structure's
    record whose one response is not named (``response_for``), a forcing at or above the Nyquist frequency, fewer
    than 10 forcing cycles, a response or an input that does not move (the forcing's phase is read from the
    input), a stated forcing frequency that is not the input's (``periodicity.check_forcing_line``: its line
    carries under 10 % of the input's rms while another line dominates).
    """
    rec = response_for(rec)
    if not 0 < forcing_hz < rec.fs / 2:
        raise MeasurementError(
            f"{rec.source}: forcing frequency {forcing_hz:g} Hz must lie below the Nyquist frequency {rec.fs / 2:g} Hz"
        )
    if rec.duration * forcing_hz < 10:
        raise MeasurementError(
            f"{rec.source}: too few samples for a characterisation: {rec.duration * forcing_hz:.3g} forcing cycles, "
            "need at least 10"
        )
    rec.require_motion("a characterisation")
    rec.require_excitation("a characterisation (the forcing's phase is read from the input)")
    check_forcing_line(rec, forcing_hz)


def response_for(rec: Measurement, element: str | tuple[int, int] | None = None, dof: int | None = None) -> Measurement:
    """The one response a characterisation reads, as a single DOF's record: a single DOF's as it is; a structure's
    (N > 1), the element's relative displacement z_J - z_I (the motion whose wells the regime is of: ``element``,
    else the record's ``# element: I-J``; its rests the header's ``element_minus_rest``, ``element_plus_rest``) or
    DOF ``dof``'s channel, under the record's input. One
    ``MeasurementError`` where a structure's record names neither (the z of N channels had crashed the regime's
    indexing, or asked a least squares of 42 GiB).
    """
    from negstiff.inference.estimators.base import parse_element
    from negstiff.models.structure import relative

    if rec.n_dof == 1 and dof in (None, 1) and (element is None or parse_element(element, 1) == (0, 1)):
        return rec  # a single DOF's record (its element on the base): its z and its rests as they are
    if dof is not None:
        if isinstance(dof, bool) or not isinstance(dof, (int, np.integer)) or not 1 <= dof <= rec.n_dof:
            raise MeasurementError(f"{rec.source}: a characterisation's channel is one of DOFs 1..{rec.n_dof}, "
                                   f"got {dof!r}")  # fmt: skip
        signal_, what = rec.channels[dof - 1], f"z{dof}"
    else:
        text = element if element is not None else rec.meta.get("element")
        if text is None:
            raise MeasurementError(
                f"{rec.source}: a structure's record of {rec.n_dof} DOFs (z1 ... z{rec.n_dof}): a characterisation "
                "reads one response: name the element (--element I-J, or '# element: I-J' in the header), whose "
                "relative motion it reads, or a channel (--dof K)"
            )
        i, j = parse_element(text, rec.n_dof)
        signal_ = relative(rec.channels, (i, j))
        what = f"the element's relative displacement z{j}" + (f" - z{i}" if i else "")
    meta = {k: v for k, v in rec.meta.items() if not k.endswith("_rest")}  # a structure's rests are its DOFs'
    if dof is None:  # the element's relative rests, where the header states them, are the response's
        meta |= {f"z_{w}_rest": rec.meta[f"element_{w}_rest"] for w in ("minus", "plus")
                 if f"element_{w}_rest" in rec.meta}  # fmt: skip
    return replace(rec, z=np.ascontiguousarray(signal_, float), z_dot=None, y=None, masses=None, force_dof=None,
                   meta=meta, source=f"{rec.source} ({what})")  # fmt: skip


def wells_for(rec: Measurement, wells="auto") -> tuple[float | None, ...] | None:
    """The wells a regime is judged against: those given (z_minus, z_plus or z_minus, z_0, z_plus [m],
    increasing; None: none, the regime is the side of the median), else (``"auto"``) the rest positions of
    the record's metadata, else the stable roots of a cubic fitted to the record (``steps.wells.well_guesses``).
    """
    if wells is None:
        return None
    if not isinstance(wells, str):
        wells = tuple(float(w) for w in wells)
        if len(wells) not in (2, 3) or not all(math.isfinite(w) for w in wells) or any(np.diff(wells) <= 0):
            raise MeasurementError(f"wells {wells}: give z_minus, z_plus (or z_minus, z_0, z_plus) in m, increasing")
        return wells
    rest = rec.rest_positions
    if len(rest) == 2:
        return rest["minus"], rest["plus"]
    try:
        return well_guesses(rec)
    except ValueError:
        return None


def characterise(
    rec: Measurement, forcing_hz: float, wells="auto", lle: bool = True, poincare: bool = False,
    element: str | tuple[int, int] | None = None, dof: int | None = None,
) -> dict[str, Any]:  # fmt: skip
    """Period, regime, amplitudes and the largest Lyapunov exponent of one harmonic-forced record.

    Parameters
    ----------
    rec : Measurement
        A steady-state response to a harmonic input; a structure's, its element's relative displacement (``element``,
        else the record's ``# element: I-J``) or one channel (``dof``).
    forcing_hz : float
        The forcing frequency [Hz].
    wells : "auto" or (float, float), default "auto"
        The stable wells [m] the regime is judged against (``"auto"``: the metadata's rest positions,
        else the record's own).
    lle : bool, default True
        Estimate the largest Lyapunov exponent (Wolf, with Rosenstein beside it).
    poincare : bool, default False
        Also return the Poincare z of every forcing cycle.
    element : str or (int, int), optional
        A structure's element ``"I-J"`` whose relative displacement is read (default: the record's
        ``# element:``; ``response_for``).
    dof : int, optional
        A structure's channel read instead (1-based).

    Returns
    -------
    dict
        The contract's keys (``period``, ``regime``, ``chaotic``, ``amplitudes``, ``lle``), each
        analysis's ``reasons`` where it could not be determined, ``wells_used``, ``record``,
        ``warnings`` (also issued as ``NegstiffWarning``), and ``poincare_z`` with ``poincare``.

    Raises
    ------
    MeasurementError
        Input no analysis can use (too few forcing cycles, a forcing above the Nyquist frequency).

    Examples
    --------
    >>> from negstiff import Measurement, Rig, characterise
    >>> from negstiff.models import SEED_LIKE_CUBIC
    >>> rec = Measurement.from_rig(Rig(SEED_LIKE_CUBIC, seed=6).harmonic(freq=9.0, amplitude=5.0))
    >>> c = characterise(rec, forcing_hz=9.0, lle=False)
    >>> c["period"], c["regime"]
    (1, 'in-well-plus')
    """
    rec = response_for(rec, element, dof)  # built once: the checks and the analyses read the same record
    check_harmonic(rec, forcing_hz)
    rec = pin_frame(rec)  # the regime is judged against wells in the physical frame
    wells = wells_for(rec, wells)
    out: dict[str, Any] = {"reasons": {}}
    work, q = upsampled(rec, forcing_hz)
    out["interpolation"] = None if q == 1 else f"band-limited (polyphase FIR) x{q} to {work.fs:g} Hz"
    per: dict[str, Any] | None = None
    try:
        if q == 1:
            per = periodicity(work, forcing_hz, wells)
        else:  # the noise of the acquisition, from the white plateau of the record as measured
            noise = math.sqrt(rec.noise_floor()[0])
            per = periodicity(work, forcing_hz, wells, noise=noise, band_fs=rec.fs)
    except (MeasurementError, ValueError, np.linalg.LinAlgError) as exc:
        out["reasons"]["period"] = _reason(exc)
    if per is not None:
        keys = ("period", "decided_by", "steady_from_s", "amplitudes", "tolerance", "tolerances", "residuals",
                "noise_std", "forcing", "spectrum")  # fmt: skip
        out |= {k: per[k] for k in keys}
        out["poincare_z"] = per["poincare_z"]
        line_share = (f"the spectrum's lines at multiples of f/{per['spectrum']['period']} carry "
                 f"{100 * per['spectrum']['line_fraction']:.3g} % of the response's power "
                 f"(a periodic response's: {100 * LINE_FRACTION:g} % or more)")  # fmt: skip
        loose = per["tolerance"] >= MAX_DECISIVE_TOLERANCE
        points = (
            f"the Poincare points cannot tell: their tolerance ({per['tolerance']:.3g} of the response's spread, "
            f"from a noise of {per['noise_std']:.3g} m read from the record) rejects almost nothing"
        )
        if per["period"] is None and per["decided_by"] == "spectrum":
            out["reasons"]["period"] = f"no period: {points if loose else 'the Poincare points nearly repeat'}, " + (
                f"and {line_share}: chaotic or quasi-periodic"
            )
        elif per["period"] is None:
            p_best = min(per["residuals"], key=lambda p: per["residuals"][p] / per["tolerances"][p])
            out["reasons"]["period"] = (
                f"no period up to 16 forcing cycles repeats within the noise and the input's own variation (closest: "
                f"period {p_best}, residual {per['residuals'][p_best]:.3g} against a tolerance of "
                f"{per['tolerances'][p_best]:.3g}): chaotic or quasi-periodic"
            )
        elif per["decided_by"] == "spectrum":
            p = per["period"]
            why = points if loose else (
                f"the Poincare points repeat every {p} cycle(s) only within "
                f"{per['residuals'][p] / per['tolerances'][p]:.2g}x their tolerance "
                f"(residual {per['residuals'][p]:.3g}, tolerance {per['tolerances'][p]:.3g})"
            )  # fmt: skip
            out["reasons"]["period_spectrum"] = f"decided by the spectrum: {why}; {line_share}"
        elif per["spectrum"]["agrees"] is False:
            out["reasons"]["period_spectrum"] = (
                f"the Poincare points repeat every {per['period']} cycle(s), but the spectrum's sub-harmonic lines "
                f"imply {per['spectrum']['period']}"
            )
    else:
        out |= {"period": None, "amplitudes": None, "poincare_z": np.array([])}
    steady = rec.t - rec.t0 >= out.get("steady_from_s", 0.0)  # the regime of the steady state
    out["regime"] = classify_regime(rec.displacement[steady], wells)
    significant = None
    if lle:
        try:
            out["lle"] = lyapunov(work, forcing_hz, out.get("noise_std"))
            significant = significantly_positive(out["lle"]["value"], out["lle"]["sd"], forcing_hz)
        except (ValueError, MeasurementError) as exc:
            out["lle"] = {"value": None, "sd": None, "units": "1/s", "method": "wolf"}
            out["reasons"]["lle"] = (
                f"{_reason(exc)}: a trajectory that returns onto itself within the noise (a periodic orbit) leaves "
                "no separation to follow"
                if "neighbour" in str(exc)
                else _reason(exc)
            )
        if significant and out["period"] is not None:
            # a record that repeats every p cycles within the noise has no positive exponent: what Wolf
            # followed was the noise's separation, not the dynamics'. Never report both.
            lle_ = out["lle"]
            out["lle"] = lle_ | {"value": None, "sd": None, "estimate_discarded": [lle_["value"], lle_["sd"]]}
            out["reasons"]["lle"] = (
                f"not determinable: the record repeats every {out['period']} forcing cycle(s) within the noise, "
                f"yet Wolf's estimate is {lle_['value']:.3g} +- {lle_['sd']:.2g} 1/s; on a periodic orbit the "
                "separation it follows is the sensor noise's, not the dynamics'"
            )
            significant = False
        if out["lle"].get("estimators_agree") is False:
            rs = out["lle"]["rosenstein"]
            out["reasons"]["lle_estimators"] = (
                f"Wolf ({out['lle']['value'] if out['lle']['value'] is not None else 'not determinable'}) and "
                f"Rosenstein ({'none' if rs is None else f'{rs:.3g} 1/s'}) disagree on whether the exponent is "
                "significantly positive"
            )
    if out["period"] is not None:
        out["chaotic"] = False
    elif significant is not None:
        out["chaotic"] = significant
    elif not lle:
        out["chaotic"] = per is not None  # the bifurcation map's rule without the exponent: no period
    else:
        out["chaotic"] = False
        out["reasons"]["chaotic"] = "no period, but no Lyapunov exponent to show sensitivity either"
    if not poincare:
        out.pop("poincare_z", None)
    lines = classified(rec)
    if "forcing" in out and abs(out["forcing"]["measured_hz"] / forcing_hz - 1) > FREQUENCY_MISLABEL:
        lines.append((RecordWarning, (
            f"{rec.source}: the input's forcing line is at {out['forcing']['measured_hz']:.4g} Hz, the stated "
            f"{forcing_hz:g} Hz: the measured frequency was used"
        )))  # fmt: skip
    issue(lines)
    return out | {"wells_used": list(wells) if wells is not None else None, "record": dict(rec.info),
                  "warnings": [text for _, text in lines]}  # fmt: skip


characterize = characterise
"""The first spelling of ``characterise`` (the contract's command kept it), the same function."""


MAP_POINCARE_POINTS = 32
"""Poincare points kept per record of a bifurcation map (the last ones: the steadiest)."""


def map_point(rec: Measurement, forcing_hz: float, wells=None) -> dict[str, Any]:
    """One record of a stepped harmonic campaign as a point of the bifurcation map (reference study Figure 4): the
    forcing's amplitude measured from the input (its harmonic at the measured frequency near ``forcing_hz``
    by least squares: m/s^2
    for base excitation, N for a force), the period, regime, branch amplitudes and the last
    ``MAP_POINCARE_POINTS`` Poincare z (phase 0); no Lyapunov exponent (a map's records are many).
    """
    from negstiff.inference.analysis.periodicity import forcing_phase

    c = characterise(rec, forcing_hz, wells, lle=False, poincare=True)
    if "forcing" in c:  # the input's amplitude at its measured frequency
        amplitude = c["forcing"]["amplitude"]
    else:  # no periodicity analysis could be made: at the stated frequency
        amplitude, _ = forcing_phase(rec.u, rec.t - rec.t0, forcing_hz)
    return {
        "amplitude": amplitude,
        "period": c["period"],
        "regime": c["regime"],
        "chaotic": c["chaotic"],
        "amplitudes": c["amplitudes"],
        "poincare_z": [float(v) for v in np.asarray(c["poincare_z"])[-MAP_POINCARE_POINTS:]],
        "reason": c["reasons"].get("period"),
    }


def map_sequence(points: list[dict[str, Any]], key: str = "amplitude") -> list[list]:
    """A sweep's regimes in its order: [label, first, last value of ``key``] runs, the label ``P<n>`` for
    period n or ``chaos`` where no period was found.
    """
    seq: list[list] = []
    for p in points:
        label = "chaos" if p["period"] is None else f"P{p['period']}"
        if not seq or seq[-1][0] != label:
            seq.append([label, p[key], p[key]])
        else:
            seq[-1][2] = p[key]
    return seq


def first_period_2(points: list[dict[str, Any]]) -> float | None:
    """The first amplitude of a sweep whose response has a period of 2 or more forcing cycles."""
    return next((float(p["amplitude"]) for p in points if p["period"] is not None and p["period"] >= 2), None)


def jump(points: list[dict[str, Any]]) -> float | None:
    """Where a stepped-sine sweep's response jumps: the midpoint of the two consecutive steps whose
    response amplitudes (half peak-to-peak, largest branch) differ most; None for fewer than two steps.
    """
    amp = np.array([max(p["amplitudes"]) if p["amplitudes"] else np.nan for p in points])
    diffs = np.abs(np.diff(amp))
    if not np.isfinite(diffs).any():  # fewer than two steps, or no amplitudes to compare
        return None
    k = int(np.nanargmax(diffs))
    return 0.5 * (points[k]["f_hz"] + points[k + 1]["f_hz"])
