"""What kind of test a record is (a single DOF's or a structure's), and the input an identification reads from it.

Three kinds of test are common in a structural-dynamics lab (issue "Hammer and decay tests"):

- ``"base"``: base-excited (a shaker under the device; the input is the base's acceleration);
- ``"force"`` and ``"impact"``: a force on the device, a shaker's or a hammer's (short pulses far above the
  channel's floor: ``record.impacts.find_impacts``);
- ``"decay"``: no input, a free decay from the record's own initial state (a release): the input column is
  constant (a zero written for it), or the caller says so. A channel of noise alone is not told from a random
  input by its own statistics (a Gaussian input of 60 000 samples stays within 5 of its deviations, which
  ``backbone.decay_start`` reads as quiet), so a decay whose input column holds a sensor's noise is named.

A hammer's force channel carries an offset and a floor of noise between the hits. Read as it is, that noise
is an input the response never saw (errors in the input variable): NSI's pole came out 27 % too damped on a
Duffing record with a 0.5 N offset and 0.05 N of noise (measured, 4 hits). ``impact_input`` is the field's
force window: each hit's pre-trigger offset removed and the channel zeroed outside its pulses.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from negstiff.errors import MeasurementError
from negstiff.inference.record.impacts import Impacts, find_impacts
from negstiff.inference.record.measurement import Measurement

KINDS = ("base", "force", "impact", "decay")
"""The record kinds, as the results and the report name them."""


@dataclass(frozen=True)
class RecordKind:
    """A record's kind (``KINDS``), how it was decided, and the hammer's hits where it is an impact record."""

    kind: str
    how: str
    impacts: Impacts | None = None


def record_kind(rec: Measurement, decay: bool | None = None) -> RecordKind:
    """The kind of test ``rec`` is (module docstring).

    Parameters
    ----------
    rec : Measurement
        A single DOF's record or a structure's (its force on one DOF, ``force_dof``).
    decay : bool, optional
        True: the record is a free decay whatever its input column holds (its input is not used); False: it is
        not one; None: decided from the input column (a decay when it stays at its floor throughout).

    Returns
    -------
    RecordKind
    """
    if decay or (decay is None and rec.info.get("decay")):
        return RecordKind("decay", "named a free decay by the caller (decay=True, --decay): the input column is not "
                                   "used")  # fmt: skip
    if decay is None and is_constant(rec.u):
        return RecordKind("decay", f"the input ({rec.input_name}) is constant throughout: a free decay")
    if rec.input_name == "base_acc":
        return RecordKind("base", "base acceleration")
    hits = find_impacts(rec.u, rec.fs)
    if hits is None:
        return RecordKind("force", "a force that is no hammer's (no short pulses far above its floor)")
    return RecordKind("impact", f"{hits.count} hammer hit(s) in the force channel (floor {hits.floor:.3g} N)", hits)


RING_DOWN_KINDS = ("impact", "decay")
"""The kinds read as ring-downs: their windows free decays between a hammer's pulses (a decay's: all of it)."""
RING_DOWN = 10.0
"""A free decay's response must ring down: its first tenth's rms about the rest (the last tenth's median) at
least this many times the last tenth's (a record at rest with a constant input is no decay: a dead input)."""


RINGING_FACTOR = 3.0
"""A decay's channel still rings in a 0.25 s window while its rms about the rest exceeds this many times the
channel's white sensor noise (``Measurement.channel_noise``): below it, the window holds the sensor's noise."""


def _about_rest(rec: Measurement) -> tuple[np.ndarray, int]:
    """Each channel of a decay about its rest, (N, T), the rest its last tenth's median; and that tenth's length."""
    z = np.asarray(rec.channels, float)
    tenth = max(8, z.shape[1] // 10)
    return z - np.median(z[:, -tenth:], axis=1, keepdims=True), tenth


def ring_down(rec: Measurement, kinds: tuple[str, ...] | None = None) -> bool:
    """Whether ``rec`` is a hammer's record or a free decay (``record_kind``; ``kinds``: of those): a response that
    rings down.
    """
    return record_kind(rec).kind in (RING_DOWN_KINDS if kinds is None else kinds)


def rings_until(rec: Measurement, window_s: float = 0.25) -> int:
    """The sample where a decay has rung down into its sensors' noise: the end of the last ``window_s`` window in
    which a channel's rms about its rest exceeds ``RINGING_FACTOR`` times its white noise (0: none does).
    """
    x, _ = _about_rest(rec)
    win = max(8, int(round(window_s * rec.fs)))
    count = x.shape[1] // win
    rms = np.sqrt(np.mean(x[:, : count * win].reshape(x.shape[0], count, win) ** 2, axis=2))
    ringing = np.any(rms > RINGING_FACTOR * rec.channel_noise()[:, None], axis=0)
    return (int(np.flatnonzero(ringing).max(initial=-1)) + 1) * win


def check_decay(rec: Measurement, what: str) -> None:
    """Raise ``MeasurementError`` when a free decay's response does not ring down (``RING_DOWN``); a structure's
    when none of its channels does (each channel's ratio, the largest read).
    """
    x, tenth = _about_rest(rec)
    starts, ends = np.std(x[:, :tenth], axis=1), np.std(x[:, -tenth:], axis=1)
    best = int(np.argmax(starts / np.maximum(ends, 1e-300)))
    start, end = float(starts[best]), float(ends[best])
    if not start > RING_DOWN * end and rec.info.get("decay"):
        raise MeasurementError(f"{rec.source}: named a free decay, but the response does not ring down (its first "
                               f"tenth's rms {start:.3g} m about the rest, the last tenth's {end:.3g} m): nothing for "
                               f"{what} to read")  # fmt: skip
    if not start > RING_DOWN * end:
        raise MeasurementError(
            f"{rec.source}: the input {rec.input_name} is constant ({rec.u[0]:.6g} over {rec.n} samples) and the "
            f"response does not ring down (its first tenth's rms {start:.3g} m about the rest, the last tenth's "
            f"{end:.3g} m): no excitation and no free decay for {what}"
        )


def is_constant(u: np.ndarray) -> bool:
    """Whether a channel holds one value throughout (to its rounding)."""
    u = np.asarray(u, float)
    return bool(np.ptp(u) <= 1e-12 * max(1.0, float(np.max(np.abs(u)))))


def impact_input(rec: Measurement, hits: Impacts) -> np.ndarray:
    """The hammer's force as an identification reads it: each hit's pulse less its pre-trigger offset, zero
    elsewhere (the force window). After the last hit's block (a hit set aside as cut by the record's end) the
    channel is kept, less the last offset.
    """
    u = np.zeros(rec.n)
    for a, b, off in zip(hits.starts, hits.pulse_ends, hits.offsets, strict=True):
        u[a:b] = rec.u[a:b] - off
    end = int(hits.starts[-1]) + hits.block
    if end < rec.n:
        u[end:] = rec.u[end:] - hits.offsets[-1]
        u[end:][np.abs(u[end:]) < 8 * hits.floor] = 0.0
    return u


def identification_record(rec: Measurement, kind: RecordKind) -> Measurement:
    """The record an identification reads: an impact record with its force windowed (``impact_input``); a decay
    with a zero input from the decay's start (its first sample after the input's last activity); else ``rec``.
    """
    if kind.kind == "impact" and kind.impacts is not None:
        return replace(rec, u=impact_input(rec, kind.impacts))
    if kind.kind == "decay":
        return replace(rec, u=np.zeros(rec.n))
    return rec
