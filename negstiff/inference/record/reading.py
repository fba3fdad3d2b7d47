"""``load``: a measurement file read through ``negstiff.io``, its columns mapped (``force=V1,z=V2``, a scale
per entry, ``*?`` for an unknown one), converted to SI, its time base made uniform, its response derived from what
the lab measured (``sensors``, ``channels``) and checked (``checks``), into a ``Measurement``. Input files are only
read.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from negstiff import io as record_io
from negstiff.errors import MeasurementError, RecordWarning, issue
from negstiff.io.base import RESOLUTION, SET_ASIDE
from negstiff.io.schema import INPUTS, KNOWN, channel_sensor, header_name, in_si, parse_column_map
from negstiff.resources import on_fit_threads

from . import channels, sensors
from .checks import (
    TIME_JITTER_FRACTION,
    aux_channels,
    check_sampling_rate,
    check_values,
    checked_force_dof,
    checked_gravity,
    checked_masses,
    checked_unknown_scale,
    time_base,
)
from .measurement import Measurement


@on_fit_threads  # the same numbers from a script and the command (``resources.on_fit_threads``)
def load(
    path: str | Path,
    columns: str | dict | None = None,
    fs: float | None = None,
    mass: float | None = None,
    response: bool = True,
    gravity: float | None = None,
    aux: Sequence[str] | str | None = None,
    masses: Sequence[float] | str | None = None,
    decay: bool = False,
    force_dof: int | None = None,
) -> Measurement:
    """Read a measurement file, checked as the command line checks it.

    The response is z, or z derived from z_dot, y (with the base's motion), y_dot or y_acc
    (``sensors.derive``); what was done is in ``info["response"]``. A derived z's constant is unknown:
    the analyses that need z's frame pin it (``pin_frame``); ``load`` fits nothing.

    Parameters
    ----------
    path : str or pathlib.Path
        A .csv, .npz, .mat, .uff/.unv, .tdms or .lvm file.
    columns : str or dict, optional
        Column map for foreign files (``"force=V1,z=V2"``, ``"base_acc=ACC*9.81,z_dot=LDV*?"``, or its
        parsed dict); ``*?`` marks a response of unknown sensitivity.
    fs : float, optional
        Sampling rate [Hz]; replaces the time column when given (the column then only sets t0).
    mass : float, optional
        Moving mass [kg] (overrides the metadata's ``mass``).
    response : bool, default True
        False for an input-only record (``negstiff simulate``): no response column needed.
    gravity : float, optional
        The gravity along the motion [m/s^2] (overrides the metadata's ``gravity``; 0 for a horizontal
        device).
    aux : str or sequence of str, optional
        Measured auxiliary channels to keep, by the file's column names (``"voltage"``): candidate terms
        of the discrepancy workflow and SINDy (``aux:NAME``).
    masses : sequence of float or str, optional
        A structure's DOF masses m1 ... mN [kg] (overrides the metadata's ``masses``); its responses are the
        file's (or the map's) ``z1 ... zN``.
    decay : bool, default False
        The record is a free decay whatever its input column holds (a force channel left connected that reads only
        its noise): the analyses read it as one (``record_kind``; ``info["decay"]``). A constant input is a decay
        without saying so.
    force_dof : int, optional
        A structure's DOF (sensor) the measured force acts on, 1..N (overrides the metadata's ``force_dof``): NSI
        sizes the element of a structure read without masses through that driving point.

    Returns
    -------
    Measurement
        The record in SI units, with how it was read in ``info``.

    Raises
    ------
    MeasurementError
        A file, column, unit or number that cannot be read as a record: one line naming the file, the
        column or row, and the problem.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> from negstiff import Rig, load
    >>> path = Rig(seed=1).random(duration=10.0).write(pathlib.Path(tempfile.mkdtemp()) / "rec.csv")
    >>> rec = load(path)
    >>> rec.fs, rec.input_name, rec.n
    (512.0, 'base_acc', 5120)
    """
    path = Path(path)
    mass_given = mass is not None
    raw, meta = record_io.read(path)
    resolution = raw.pop(RESOLUTION, None)
    cmap = parse_column_map(columns) if isinstance(columns, (str, type(None))) else dict(columns)
    cmap = {name: (header_name(src, raw), scale) for name, (src, scale) in cmap.items()}
    _refuse_set_aside(path, meta, [src for src, _ in cmap.values()] if cmap else [k for k in KNOWN if k not in raw])
    cols, channel_info = in_si(path, _mapped_columns(path, raw, cmap), meta, cmap)
    if any(name == "t" and (src != "t" or scale != 1.0) for name, (src, scale) in cmap.items()):
        resolution = None  # the printed precision was read for a column named t only
    if resolution is not None:  # a time column in ms: its printed precision in s too
        resolution = resolution * channel_info.get("channels", {}).get("t", {}).get("to_si", 1.0)
    input_name, n = _checked_input(path, raw, cols)
    fs, t0, time_info = _time_base(path, cols, meta, fs, resolution)
    if mass is None and "mass" in meta:
        try:
            mass = float(meta["mass"])
        except ValueError:
            raise MeasurementError(f"{path}: metadata mass = {meta['mass']!r} is not a number") from None
    if "gravity" in meta:
        meta = {**meta, "gravity": repr(checked_gravity(f"{path}: metadata", meta["gravity"]))}
    unknown = [name for name, (_, scale) in cmap.items() if scale is None]
    if len(unknown) > 1:
        raise MeasurementError(f"{path}: scales of {' and '.join(unknown)} marked unknown (*?): one channel at most")
    scale_info = checked_unknown_scale(path, unknown[0] if unknown else None, input_name, mass, cols)
    aux_names = [a for a in (aux.split(",") if isinstance(aux, str) else aux or ()) if str(a).strip()]
    _refuse_set_aside(path, meta, aux_names)
    aux_cols = aux_channels(path, raw, aux_names, n)
    dofs = channels.response_channels(path, cols)
    if len(dofs) == 1:  # one DOF: a single DOF's response (z1 its z, z1_dot its z_dot, ...)
        cols[channel_sensor(dofs[1])[1]] = cols.pop(dofs[1])  # type: ignore[index]
    masses = masses if masses is not None else meta.get("masses")
    dof_masses = None if masses is None else checked_masses(path, masses, max(1, len(dofs)))
    if len(dofs) <= 1 and dof_masses is not None and mass is None:
        mass = dof_masses[0]
    force_dof = checked_force_dof(path, force_dof if force_dof is not None else meta.get("force_dof"),
                                  max(1, len(dofs)))  # fmt: skip
    z: np.ndarray | None = None
    resp: dict[str, Any] = {"measured": None}
    if len(dofs) > 1:
        if mass_given:
            raise MeasurementError(f"{path}: a record of {len(dofs)} DOFs (z1 ... z{len(dofs)}) takes its DOFs' "
                                   "masses (masses=, --masses, '# masses:'), not one mass")  # fmt: skip
        z, resp = channels.derive_channels(path, cols, dofs, input_name, fs, units_known=not unknown)
        mass = None  # a structure's are its masses
    elif response or any(k in cols for k in sensors.RESPONSES):
        z, resp = sensors.derive(cols, input_name, fs, str(path), units_known=not unknown)
    k = int(round(resp.get("trim_s", 0.0) * fs))
    if k and z is not None:
        if n <= 4 * k:
            raise MeasurementError(
                f"{path}: too few samples ({n}) to derive z from {resp['measured']}: the integral of an "
                f"accelerometer loses {resp['trim_s']:g} s at each end"
            )
        cols = {c: v[k:-k] for c, v in cols.items()}
        aux_cols = {c: v[k:-k] for c, v in aux_cols.items()}
        z, t0 = z[..., k:-k], t0 + k / fs
        resp["derived"] += f"; {resp['trim_s']:g} s cut at each end (the integral's end effects)"
    aside = {k[len(SET_ASIDE) :]: v for k, v in meta.items() if k.startswith(SET_ASIDE)}
    rec = Measurement(
        fs=fs,
        input_name=input_name,
        u=cols[input_name],
        z=z,
        z_dot=cols.get("z_dot"),
        y=cols.get("y"),
        base_disp=cols.get("base_disp"),
        meta=meta,
        source=str(path),
        t0=t0,
        info={
            "time": time_info,
            "response": resp,
            **channel_info,
            **({"scale": scale_info} if scale_info else {}),
            **({"set_aside": aside} if aside else {}),  # channels of other rates, each with why
            **({"decay": True} if decay else {}),
        },
        aux=aux_cols,
        masses=dof_masses if len(dofs) > 1 else None,
        force_dof=force_dof,
    )
    return _warned(rec.with_mass(mass).with_gravity(gravity))


def _warned(rec: Measurement) -> Measurement:
    """The record with what looks wrong in it alone (units: mm read as m, an acceleration in mm/s^2; the
    sensor's derivation) in ``info["warnings"]``, each issued as a ``RecordWarning`` at once: a user learns
    it when loading, whatever comes next (``Measurement.unit_warnings``).
    """
    new = [w for w in rec.unit_warnings() if w not in rec.info.get("warnings", [])]
    lines = [*rec.info.get("warnings", []), *rec.info.get("response", {}).get("warnings", []), *new]
    issue([(RecordWarning, w) for w in lines])
    return replace(rec, info={**rec.info, "warnings": [*rec.info.get("warnings", []), *new]}) if new else rec


def _refuse_set_aside(path: Path, meta: dict[str, str], wanted) -> None:
    """One ``MeasurementError`` line for a wanted channel the reader set aside (``SET_ASIDE``: another rate than
    the record's), naming it and why (the others are listed in the record's ``info["set_aside"]``).
    """
    for name in wanted:
        why = meta.get(SET_ASIDE + str(name))
        if why is not None:
            raise MeasurementError(f"{path}: channel {name!r} {why}")


def _mapped_columns(path: Path, raw: dict[str, np.ndarray], cmap: dict) -> dict[str, np.ndarray]:
    """The contract's columns: mapped (and scaled) from the file's, plus unmapped contract names."""
    if not cmap:
        return {k: v for k, v in raw.items() if k in KNOWN or channel_sensor(k) is not None}
    cols: dict[str, np.ndarray] = {}
    for name, (src, scale) in cmap.items():
        if src not in raw:
            raise MeasurementError(
                f"{path}: column map refers to {src!r}, which is not in the file (columns: {', '.join(raw) or 'none'})"
            )
        cols[name] = raw[src] * (1.0 if scale is None else scale)  # an unknown scale (*?): as read
    for name in [*KNOWN, *(k for k in raw if channel_sensor(k) is not None)]:  # unmapped contract columns count
        if name in raw and name not in cols and all(src != name for src, _ in cmap.values()):
            cols[name] = raw[name]
    return cols


def _checked_input(path: Path, raw: dict, cols: dict[str, np.ndarray]) -> tuple[str, int]:
    """The one input column's name and the record's length; equal lengths, finite values."""
    inputs = [k for k in INPUTS if k in cols]
    if len(inputs) != 1:
        what = "no input column" if not inputs else "two input columns"
        raise MeasurementError(
            f"{path}: {what}; exactly one of base_acc, force is needed "
            f"(columns: {', '.join(raw) or 'none'}; map foreign names with --columns)"
        )
    n = cols[inputs[0]].size
    if n < 2:
        raise MeasurementError(f"{path}: too few samples ({n}) for a record")
    for k, v in cols.items():
        if v.size != n:
            raise MeasurementError(f"{path}: column {k} has {v.size} samples, {inputs[0]} has {n}")
    check_values(path, cols)
    return inputs[0], n


def _time_base(path: Path, cols: dict, meta: dict, fs: float | None, resolution) -> tuple[float, float, dict]:
    """(fs [Hz], t0 [s], how it was found): the caller's fs (replacing any column t), else column t
    (``time_base``: uniform within its printed precision), else the metadata's fs.
    """
    if fs is not None:
        fs = check_sampling_rate(path, fs, "given by the caller")
        source = f"fs = {fs:g} Hz given by the caller" + (" (replaces column t)" if "t" in cols else "")
        return float(fs), float(cols["t"][0]) if "t" in cols else 0.0, {"source": source}
    fs_meta = meta.get("fs")
    if fs_meta is not None:
        try:
            fs = float(fs_meta)
        except ValueError:
            raise MeasurementError(f"{path}: metadata fs = {fs_meta!r} is not a number") from None
        fs = check_sampling_rate(path, fs, "the metadata's fs")
    if "t" in cols:
        dt, jitter, res = time_base(cols["t"], resolution, path)
        check_sampling_rate(path, 1.0 / dt if dt > 0 else math.inf, "from column t")
        if fs is not None and abs(fs * dt - 1) > TIME_JITTER_FRACTION:
            raise MeasurementError(
                f"{path}: fs = {fs:g} Hz disagrees with column t (1/dt = {1 / dt:.6g} Hz); "
                "--fs replaces the time column"
            )
        return (
            1.0 / dt,
            float(cols["t"][0]),
            {"source": "column t (mean step)", "jitter_s": jitter, "resolution_s": res},
        )
    if fs is None:
        raise MeasurementError(f"{path}: no time base: give a column t, '# fs: ...' metadata or --fs")
    return fs, 0.0, {"source": "metadata fs"}
