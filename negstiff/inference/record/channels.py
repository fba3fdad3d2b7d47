"""A structure's responses, one per DOF, each as its own sensor measured it: ``zK`` (a laser's relative
displacement), or ``zK_dot``, ``yK``, ``yK_dot``, ``yK_acc`` from which the DOF's z is derived exactly as a
single DOF's z is (``sensors.derive``: the integral's drift separated, the base's motion taken out), channel by
channel. Each channel's constant is unknown whatever the sensor (a laser's zero is arbitrary; an integral has
none): a structure's identification estimates it (``offsets_m``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from negstiff.errors import MeasurementError
from negstiff.io.schema import channel_sensor

from . import sensors


def response_channels(source, cols: dict[str, np.ndarray]) -> dict[int, str]:
    """{K: column} of a record's per-DOF response columns, checked: one response per DOF, the DOFs 1 ... N
    consecutive, each a response's name (``sensors.RESPONSES`` with K), and not beside a single DOF's response
    columns; empty for a single DOF's record.
    """
    found: dict[int, str] = {}
    for k in cols:
        cs = channel_sensor(k)
        if cs is None:
            continue
        dof, sensor = cs
        if sensor not in sensors.RESPONSES:
            raise MeasurementError(f"{source}: column {k}: a DOF's response is one of z{dof}, z{dof}_dot, y{dof}, "
                                   f"y{dof}_dot, y{dof}_acc")  # fmt: skip
        if dof in found:
            raise MeasurementError(f"{source}: DOF {dof} has two responses, {found[dof]} and {k}: give one (map the "
                                   "other away with --columns)")  # fmt: skip
        found[dof] = k
    if not found:
        return {}
    if sorted(found) != list(range(1, len(found) + 1)):
        names = ", ".join(found[d] for d in sorted(found))
        raise MeasurementError(f"{source}: responses must be z1 ... zN (one per DOF), consecutive; found {names}")
    single = [k for k in sensors.RESPONSES if k in cols]
    if single:
        raise MeasurementError(f"{source}: a record holds a structure's responses z1 ... zN or a single DOF's "
                               f"response, not both (it has {found[1]} and {single[0]})")  # fmt: skip
    return dict(sorted(found.items()))


def derive_channels(source, cols: dict[str, np.ndarray], found: dict[int, str], input_name: str, fs: float,
                    units_known: bool = True) -> tuple[np.ndarray, dict[str, Any]]:  # fmt: skip
    """The (N, T) responses of a structure's record from its per-DOF columns (``found``, popped from ``cols``),
    each derived as a single DOF's z is (``sensors.derive`` with the record's base channels), and
    ``info["response"]``: each channel's account, and ``trim_s`` (the most any channel's derivation needs cut at
    each end; the caller cuts every channel by it).
    """
    base: dict[str, np.ndarray] = {k: cols[k] for k in ("base_acc", "base_disp", "force") if k in cols}
    rows, accounts = [], []
    for dof, name in found.items():
        sensor = channel_sensor(name)[1]  # type: ignore[index]
        z, info = sensors.derive({sensor: cols.pop(name), **base}, input_name, fs, f"{source}: DOF {dof} ({name})",
                                 units_known=units_known)  # fmt: skip
        rows.append(z)
        accounts.append({"dof": dof, "column": name, **info})
    measured = ", ".join(found.values())
    derived = [a for a in accounts if a.get("derived")]
    out: dict[str, Any] = {
        "measured": measured,
        "derived": None if not derived else "; ".join(f"DOF {a['dof']}: {a['derived']}" for a in derived),
        "z_constant_known": True,
        "offsets": "each channel's zero as measured (a laser's is arbitrary) or left by its integral: a structure's "
                   "identification estimates each channel's constant with the equations of motion",
        "channels": accounts,
    }  # fmt: skip
    trim = max((a.get("trim_s", 0.0) for a in accounts), default=0.0)
    if trim:
        out["trim_s"] = trim
    warnings = [w for a in accounts for w in a.get("warnings", [])]
    if warnings:
        out["warnings"] = warnings
    return np.vstack(rows), out
