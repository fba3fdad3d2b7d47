"""The record schema: the contract's columns, their dimensions and SI units, the magnitudes no shaker-table
record exceeds, the sampling rates a record may have, the column maps that name a foreign file's
columns, and the channel units a label may state (one table, read by every reader and writer).

Channel units: what a lab file's label says a channel is in, and its factor to the contract's SI units.

A CSV header's ``z [mm]`` or a lab format's channel unit arrives as ``unit:<channel>`` metadata; a
contract column under its own name is converted by it, or refused where the label is not a unit of the
column's dimension (``in_si``). Written here, not with pint or astropy.units: they read a lab's 'g' as
the gram (standard gravity is pint's 'g0'), and the labels exports write are a dozen, in a few spellings.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np

from negstiff.constants import STANDARD_GRAVITY
from negstiff.errors import MeasurementError

INPUTS = ("base_acc", "force")
OPTIONAL = ("z_dot", "y", "base_disp")
RESPONSE_ONLY = ("y_dot", "y_acc")
"""Response columns a record may hold instead of z (``sensors.RESPONSES``): z is derived from them."""
KNOWN = ("t", *INPUTS, "z", *OPTIONAL, *RESPONSE_ONLY)

UNITS = {
    "time": {"s": 1.0, "ms": 1e-3, "us": 1e-6},
    "length": {"m": 1.0, "cm": 1e-2, "mm": 1e-3, "um": 1e-6, "in": 0.0254},
    "velocity": {"m/s": 1.0, "cm/s": 1e-2, "mm/s": 1e-3, "um/s": 1e-6, "in/s": 0.0254},
    "acceleration": {"m/s^2": 1.0, "mm/s^2": 1e-3, "g": STANDARD_GRAVITY, "in/s^2": 0.0254},
    "force": {"N": 1.0, "kN": 1e3, "mN": 1e-3, "lbf": 4.4482216152605},
}
"""The units a channel's label may state, by dimension, and each one's factor to SI."""
DIMENSIONS = {
    "t": "time",
    "base_acc": "acceleration",
    "y_acc": "acceleration",
    "force": "force",
    "z": "length",
    "y": "length",
    "base_disp": "length",
    "z_dot": "velocity",
    "y_dot": "velocity",
}
"""The dimension of each contract column."""

RESPONSE_CHANNEL = re.compile(r"^z([1-9][0-9]*)$")
"""A structure's response channel ``z1 ... zN`` (each DOF's displacement relative to the base [m])."""

CHANNEL_SENSOR = re.compile(r"^(z|y)([1-9][0-9]*)(_dot|_acc)?$")
"""A structure's DOF response as its sensor measured it: ``zK`` (relative displacement), ``zK_dot`` (relative
velocity), ``yK``, ``yK_dot``, ``yK_acc`` (absolute displacement, velocity, acceleration): the single DOF's
response columns with the DOF's number K (``sensors.RESPONSES``)."""


def channel_sensor(column: str) -> tuple[int, str] | None:
    """(K, the single DOF's column name) of a structure's response column (``z2_dot`` -> (2, "z_dot")), else
    None. The name may be one no response has (``z2_acc``): the reader refuses it.
    """
    m = CHANNEL_SENSOR.match(column)
    return None if m is None else (int(m.group(2)), m.group(1) + (m.group(3) or ""))


def dimension(column: str) -> str | None:
    """The dimension of a contract column (``DIMENSIONS``; a structure's ``z1 ... zN`` are lengths, its ``zK_dot``
    velocities, and so on), else None.
    """
    sensor = channel_sensor(column)
    return DIMENSIONS.get(sensor[1] if sensor is not None else column)


SI_UNITS = {dim: next(iter(units)) for dim, units in UNITS.items()}
"""The SI unit of each dimension (the first of ``UNITS``)."""


def si_unit(column: str) -> str:
    """The unit a column is written in: SI by its dimension, or g for an acceleration written as ``<name>_g``."""
    if column.endswith("_g") and DIMENSIONS.get(column[:-2]) == "acceleration":
        return "g"
    dim = dimension(column)
    return SI_UNITS[dim] if dim is not None else ""


MAGNITUDE_LIMITS = {"time": 1e9, "length": 1e3, "velocity": 1e4, "acceleration": 1e7, "force": 1e9}
"""Beyond these magnitudes (s, m, m/s, m/s^2, N) no shaker-table record is in SI units: a value there is
refused, never fed to the numerics (a 1e300-scale column overflows every product an identification forms)."""
AUX_MAGNITUDE_LIMIT = 1e15
"""Beyond this magnitude (in its own units, whatever they are) no lab instrument's channel reads: a 24-bit
converter counts to 8.4e6, a pressure in Pa or a frequency in Hz stays below 1e12. An auxiliary channel there
is refused (a 1e300 channel overflows every product a fit forms with it)."""
TIME_STEP_RESOLUTION = 0.01
"""A time column's magnitude does not matter (a DAQ stamping Unix time: 1.7e9 s), its steps do: float64's
spacing at the column's largest value must stay within this fraction of its step (1.7e9 s: 2.4e-7 s)."""
USABLE_BAND_FRACTION = 0.4
"""The band [fraction of the sampling rate] an acquisition's anti-aliasing filter passes: a forcing above
0.4 fs (fewer than 2.5 samples a period) lies in the filter's roll-off, where no phase can be read."""
MASS_RANGE_KG = (1e-9, 1e9)
"""Moving masses [kg] a record may state: a microgram MEMS proof mass to a building's storey."""

SAMPLING_RATE_RANGE_HZ = (1e-3, 1e7)
"""Sampling rates [Hz] a record may have: an acquisition slower than one sample in 1000 s, or faster than
10 MHz, is a misread time column or a mistyped rate."""
RAW_UNITS = ("V", "mV")
"""A sensor's output before its sensitivity: no unit of the column's dimension."""


_UNIT_WORDS = {"meter": "m", "metre": "m", "millimeter": "mm", "millimetre": "mm", "second": "s", "sec": "s",
               "newton": "N"}  # fmt: skip
"""Units written out, as some exports do (singular or plural)."""


def _unit(label: str) -> str:
    """A unit label in ``UNITS``' spelling: 'µm' and 'μm' -> 'um', 'm/s²', 'm/s2', 'm/s/s' and 'm s^-2' ->
    'm/s^2', 'm s^-1' -> 'm/s', 'meters' -> 'm', 'm/sec' -> 'm/s'.
    """
    u = label.strip().replace("µ", "u").replace("μ", "u").replace("²", "^2").replace(" ", "").replace("*", "")
    u = re.sub(r"[A-Za-z]{3,}", lambda w: _UNIT_WORDS.get(w.group(0).lower().rstrip("s"), w.group(0)), u)
    u = re.sub(r"(/s/s|/s2|s\^?-2)$", "/s^2", u)
    return re.sub(r"s\^?-1$", "/s", u)


def si_factor(label: str, column: str) -> float | None:
    """The factor that turns ``column``'s values labelled ``label`` into SI, or None where the label is not
    a unit of the column's dimension in ``UNITS``.
    """
    dim = dimension(column)
    return UNITS[dim].get(_unit(label)) if dim is not None else None


def in_si(path: Path, cols: dict[str, np.ndarray], meta: dict[str, str], cmap: dict):
    """The contract's columns in SI, by the units the file states for them (``unit:<channel>`` metadata: a
    CSV header's ``z [mm]``, a lab format's channel unit), and what was done: ``(cols, info)``.

    A column under its own name (not mapped) is converted by its stated unit; a unit that is not one of
    the column's dimension is an error (one line), never a silent SI reading. A mapped column is the
    user's: its map's scale stands, and a non-SI unit the map does not scale is a warning.
    """
    channels: dict[str, dict[str, Any]] = {}
    for k in meta:
        if k.startswith(("unit:", "sensitivity:")):
            c = k.split(":", 1)[1]
            channels[c] = {"unit": meta.get(f"unit:{c}"), "sensitivity": meta.get(f"sensitivity:{c}")}
    warns: list[str] = []
    out = dict(cols)
    for name in cols:
        src, scale = cmap.get(name, (name, 1.0))
        label = meta.get(f"unit:{src}")
        dim = dimension(name)
        if label is None or dim is None:
            continue
        f = si_factor(label, name)
        if name in cmap:  # the user's map decides
            if scale is UNKNOWN_SCALE:  # the dynamics will say: the file's label is moot
                continue
            if scale == 1.0 and (label in RAW_UNITS or (f is not None and f != 1.0)):
                fix = f" (scale it: --columns {name}={src}*{f:.6g})" if f else " (scale it by the sensor's sensitivity)"
                warns.append(f"channel {src} ({name}) is labelled {label!r} in the file, not SI{fix}")
            continue
        if f is None:
            hint = (
                "a sensor's raw output: scale it to SI with its sensitivity"
                if label in RAW_UNITS
                else f"a {dim} is expected, in {', '.join(UNITS[dim])}"
            )
            raise MeasurementError(
                f"{path}: column {name} is labelled {label!r}: {hint} (or map and scale it: "
                f"--columns {name}={name}*FACTOR)"
            )
        if f != 1.0:
            out[name] = cols[name] * f
            channels.setdefault(src, {"unit": label, "sensitivity": None})["to_si"] = f
    info: dict[str, Any] = {"channels": channels} if channels else {}
    return out, info | ({"warnings": warns} if warns else {})


GRAVITY_RANGE = (0.0, 30.0)
"""The gravity along a device's motion [m/s^2] (metadata ``gravity``, ``--gravity``): 0 (horizontal) to 9.81
(vertical); beyond 30 it is not m/s^2."""


_MAP_ENTRY = re.compile(r"^\s*(\w+)\s*=\s*([^*]+?)\s*(?:\*\s*([-+0-9.eE]+|\?))?\s*$")

UNKNOWN_SCALE = None
"""A column map's scale for a channel whose sensitivity is unknown (``z_dot=ldv*?``): the record's own
dynamics estimate it (``negstiff.inference.steps.frame``)."""


def parse_column_map(text: str | None) -> dict[str, tuple[str, float | None]]:
    """Parse ``name=SOURCE[*scale],...`` into ``{name: (SOURCE, scale)}``; ``*?`` marks a scale unknown
    (``UNKNOWN_SCALE``: a response channel whose sensitivity the record's dynamics are to estimate).
    """
    if not text:
        return {}
    out: dict[str, tuple[str, float | None]] = {}  # None: the scale is unknown (``*?``)
    for entry in text.split(","):
        m = _MAP_ENTRY.match(entry)
        if not m:
            raise MeasurementError(
                f"column map entry {entry!r} is not of the form name=COLUMN, name=COLUMN*scale or name=COLUMN*? "
                "(scale unknown)"
            )
        name, src, scale = m.group(1), m.group(2).strip().strip('"'), m.group(3)
        if name not in KNOWN and channel_sensor(name) is None:
            raise MeasurementError(
                f"column map names {name!r}, which is not a measurement column ({', '.join(KNOWN)}, z1 ... zN, "
                "or a DOF's z1_dot, y1, y1_dot, y1_acc)"
            )
        try:
            factor = 1.0 if scale is None else UNKNOWN_SCALE if scale == "?" else float(scale)
        except ValueError:
            raise MeasurementError(f"column map entry {entry!r}: scale {scale!r} is not a number") from None
        if name in out:
            raise MeasurementError(
                f"column map names {name!r} twice ({out[name][0]!r} and {src!r}): which one is meant?"
            )
        out[name] = (src, factor)
    return out


UNIT_IN_NAME = re.compile(r"^(?P<name>.*?)\s*(?:\[(?P<square>[^\]]*)\]|\((?P<round>[^)]*)\))\s*$")
"""A header entry with its unit: ``z [mm]`` or ``z (mm)``."""


def header_name(src: str, raw: dict[str, np.ndarray]) -> str:
    """A column map's source as the file's column name: the header's whole text ('Time [s]') names the
    column its unit was split from ('Time').
    """
    m = UNIT_IN_NAME.match(src)
    return m.group("name").strip() if src not in raw and m and m.group("name").strip() in raw else src
