"""The scale of a response channel whose sensitivity is unknown (a column map's ``*?``: a laser
vibrometer's volts, its gain not written down).

In a base-excited record physics fixes the input's coefficient: z'' = -base_acc - (c z' + K(z)) / m. A
response read in its sensor's units, z_read = z / s, obeys z_read'' = -base_acc / s - ..., so the
coefficient the record's own dynamics learn for the input (``weak.input_coefficient``: a quintic
restoring force with viscous and quadratic damping, unconstrained weak-form least squares) is -1 / s.
For a force-driven record it is 1 / (m s): the mass must be known, or scale and mass trade off (``load``
refuses that record). ``calibrate_scale`` estimates s with its standard error (the spread of the
estimates from parts of the record), multiplies the response by it, so that every coefficient found
afterwards is in SI units, and says so in ``info["scale"]`` (a result's ``record.scale``). It is the
first step of ``frame.pin_frame``: every analysis that pins the frame calibrates first.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from negstiff.errors import MeasurementError
from negstiff.inference.record.measurement import Measurement

SCALE_PARTS = 4
"""Parts of the record (at most) whose separate estimates give the scale's standard error."""

SCALE_PART_MIN_S = 20.0
"""... each at least this long where the record allows (two parts at least)."""


def _scale_of(rec: Measurement) -> float:
    from negstiff.inference.steps.weak import input_coefficient, known_input_gain

    c = input_coefficient(rec)
    physical = known_input_gain(rec)
    assert physical is not None  # load refuses a force record of unknown scale without a mass
    if not np.isfinite(c) or c == 0:
        raise MeasurementError(f"{rec.source}: the record's dynamics give the input no weight: its response's scale "
                               "cannot be estimated (does the response follow the input?)")  # fmt: skip
    return physical / c


def calibrate_scale(rec: Measurement) -> Measurement:
    """``rec`` with its response channel of unknown scale multiplied by the scale its dynamics say (the
    value, its standard error and how in ``info["scale"]``); ``rec`` itself when no scale is unknown or it
    was calibrated already. Raises ``MeasurementError`` when the record cannot say.
    """
    info = rec.info.get("scale")
    if not info or info.get("value") is not None:
        return rec
    done = rec.derived.get("calibrated")
    if done is not None:
        return done
    s = _scale_of(rec)
    n_parts = int(np.clip(rec.duration // SCALE_PART_MIN_S, 2, SCALE_PARTS))
    edges = np.linspace(0, rec.n, n_parts + 1).astype(int)
    parts = []
    for a, b in zip(edges[:-1], edges[1:], strict=False):
        try:
            parts.append(_scale_of(rec.segment(a, b)))
        except (MeasurementError, ValueError, np.linalg.LinAlgError):
            continue
    se = float(np.std(parts, ddof=1) / np.sqrt(len(parts))) if len(parts) >= 2 else float("nan")
    channel = info["channel"]
    scaled = {k: getattr(rec, k) * s for k in ("z", "z_dot", "y") if getattr(rec, k) is not None}
    if rec.input_name == "base_acc" and "y" in scaled:  # not SCALABLE: load refuses it; kept out for safety
        scaled.pop("y")
    new_info = {
        **info,
        "value": float(s),
        "se": se,
        "parts": [float(p) for p in parts],
        "status": f"estimated: {channel} in SI = {channel} as read x {s:.6g} (+- {se:.2g}), from the input's "
        "coefficient in the record's own dynamics (physics fixes it); every coefficient is in SI units",
    }
    resp = dict(rec.info.get("response", {}))
    for k in ("velocity_noise_m_s", "integration_error_m", "trend_m_s", "trend_se_m_s"):
        if isinstance(resp.get(k), (int, float)):
            resp[k] = resp[k] * abs(s)
    out = replace(rec, **scaled, info={**rec.info, "scale": new_info, "response": resp})
    rec.derived["calibrated"] = out
    return out
