"""Universal Files (``.uff``, ``.unv``), dataset type 58 (function at nodal DOF), through **pyuff** (SDyPy,
MIT): each type-58 record whose function type is a time response (1) is one channel, named by its ID line 1
(``id1``) as the front end wrote it, else ``node+direction``. A file is read whole or refused (pyuff drops
an incomplete last dataset silently). Written as ASCII type-58 records, one per channel (pyuff's binary
58b of this version did not read back its own output).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from negstiff.errors import MeasurementError

from .base import check_memory, common_step, equal_lengths, unique_names
from .schema import si_unit

SUFFIXES = (".uff", ".unv")

UFF_TIME_RESPONSE = 1
"""UFF dataset 58 function type of a time response (2: auto-spectrum, 4: FRF, ...)."""

UFF_FUNCTION_TYPES = {0: "general", 1: "time response", 2: "auto spectrum", 3: "cross spectrum",
                      4: "frequency response function", 5: "transmissibility", 6: "coherence",
                      7: "auto correlation", 8: "cross correlation", 9: "power spectral density",
                      12: "spectrum"}  # fmt: skip

UFF_INCREMENT_PRECISION = 5e-6
"""Relative precision of a UFF 58 abscissa increment as printed (E13.5: six significant digits)."""

LAB_PARSE_BYTES_PER_BYTE = 24
"""Memory [bytes] a lab format's reader may hold per byte of its file (the text and its values)."""


def read(path: Path):
    """Type-58 time-series channels of a Universal File (pyuff)."""
    import pyuff

    check_memory(path, LAB_PARSE_BYTES_PER_BYTE * path.stat().st_size)
    try:
        sets = pyuff.UFF(str(path)).read_sets()
    except Exception as exc:
        raise MeasurementError(
            f"{path}: unreadable Universal File ({type(exc).__name__}: {exc})".splitlines()[0]
        ) from None
    sets = [sets] if isinstance(sets, dict) else list(sets)
    _check_uff_complete(path, len(sets))
    cols: dict[str, np.ndarray] = {}
    meta: dict[str, str] = {}
    steps: dict[str, float] = {}
    found = [(i, s) for i, s in enumerate(sets) if s.get("type") == 58]
    names = [str(s.get("id1") or "").strip() or f"{s.get('rsp_node')}{s.get('rsp_dir')}" for _, s in found]
    names, aside = unique_names(names, [str(i + 1) for i, _ in found], "records")
    meta.update(aside)
    for (i, s), name in zip(found, names, strict=True):
        ft = int(s.get("func_type", -1))
        if ft != UFF_TIME_RESPONSE:
            raise MeasurementError(
                f"{path}: record {i + 1} ({name}) holds a {UFF_FUNCTION_TYPES.get(ft, 'function')} (UFF 58 function "
                f"type {ft}), not a time series (type 1)"
            )
        data = np.asarray(s["data"])
        if np.iscomplexobj(data):
            raise MeasurementError(f"{path}: record {i + 1} ({name}) is complex, not a time series")
        _check_point_count(path, i, name, s.get("num_pts"), data.size)
        cols[name] = data.astype(float)
        x = np.asarray(s.get("x", []), float)
        steps[name] = float(s.get("abscissa_inc") or (x[1] - x[0] if x.size > 1 else 0.0))
        unit = str(s.get("ordinate_axis_units_lab") or "").strip()
        if unit:
            meta[f"unit:{name}"] = unit
    if not found:
        raise MeasurementError(f"{path}: no UFF 58 (function at nodal DOF) records in the file")
    equal_lengths(path, cols)
    step = common_step(path, steps)
    if step:
        fs = 1.0 / step
        # the increment is printed with 6 significant digits (E13.5): 1/512 s reads back as 512.0013 Hz;
        # an integer rate within that precision is the acquisition's
        if abs(fs - round(fs)) <= UFF_INCREMENT_PRECISION * fs:
            fs = float(round(fs))
        meta["fs"] = repr(fs)
    return cols, meta


def _check_point_count(path: Path, i: int, name: str, header, read: int) -> None:
    """A type-58 record holds the points its header (record 7, ``num_pts``) says: pyuff reads every value
    up to the closing ``-1`` whatever the header says, so lines lost in copying (or two datasets spliced
    into one where their delimiters were lost) would otherwise read as a shorter or longer record.
    """
    try:
        said = int(header)
    except (TypeError, ValueError):
        raise MeasurementError(f"{path}: record {i + 1} ({name}): no point count in its header") from None
    if said != read:
        raise MeasurementError(
            f"{path}: record {i + 1} ({name}): its header says {said} points, {read} were read: lines lost or "
            "added in copying? negstiff reads a file whole or not at all"
        )


def _check_uff_complete(path: Path, n_read: int) -> None:
    """A Universal File read whole: every dataset opens and closes with a ``-1`` line, and pyuff returned
    them all (it drops an incomplete last dataset silently; the record would then lose a channel, or its
    end, and negstiff would derive z from another channel).
    """
    delimiters = sum(1 for line in path.read_bytes().splitlines() if line.strip() == b"-1")
    if delimiters % 2 or delimiters // 2 != n_read:
        raise MeasurementError(
            f"{path}: the Universal File is incomplete ({delimiters // 2 + delimiters % 2} datasets begin, "
            f"{n_read} read whole): truncated in copying? negstiff reads a file whole or not at all"
        )


def write(path: Path, cols: dict[str, np.ndarray], fs: float, meta: dict) -> None:
    """One ASCII type-58 time response per channel (the time column is not a channel: the time step is)."""
    chans = {k: v for k, v in cols.items() if k != "t"}
    import pyuff

    x = np.arange(next(iter(chans.values())).size) / fs
    uff = pyuff.UFF(str(path))
    for i, (k, v) in enumerate(chans.items()):
        zero = {
            f"{a}_{b}": 0
            for a in ("orddenom", "z_axis")
            for b in ("spec_data_type", "len_unit_exp", "force_unit_exp", "temp_unit_exp")
        }
        ds = pyuff.prepare_58(
            binary=0, id1=k, id2=str(meta.get("source", "")), func_type=1, rsp_node=i + 1, rsp_dir=3, ref_node=0,
            ref_dir=0, data=np.asarray(v, float), x=x, ord_data_type=4, num_pts=x.size, abscissa_spacing=1,
            abscissa_min=0.0, abscissa_inc=1.0 / fs, abscissa_spec_data_type=17, abscissa_len_unit_exp=0,
            abscissa_force_unit_exp=0, abscissa_temp_unit_exp=0, abscissa_axis_units_lab="s",
            ordinate_spec_data_type=0, ordinate_len_unit_exp=0, ordinate_force_unit_exp=0, ordinate_temp_unit_exp=0,
            ordinate_axis_units_lab=si_unit(k), orddenom_axis_units_lab="", z_axis_axis_units_lab="", z_axis_value=0.0,
            **zero,
        )  # fmt: skip
        uff.write_sets(ds, mode="overwrite" if i == 0 else "add")
