"""The lab's own file formats, read through the field's maintained libraries.

* Universal Files (``.uff``, ``.unv``), dataset type 58 (function at nodal DOF), through **pyuff**
  (ladisk, MIT): each type-58 record whose function type is a time response (1) is one channel,
  named by its ID line 1 (``id1``) as the front end wrote it, else ``node+direction``.
* LabVIEW TDMS (``.tdms``) through **npTDMS** (LGPL-3.0, used as a library): every channel of every
  group, named by the channel's name (``group/channel`` where two groups share a name); the time
  step from the waveform property ``wf_increment``.
* LabVIEW measurement files (``.lvm``) through **lvm_read** (ladisk, MIT), called without its pickle
  cache (by default it writes a ``.pkl`` beside the input and trusts one found there: negstiff never
  writes beside an input); channels by the header's names, the time step from ``Delta_X``.

Why these: each is the reader the structural-dynamics Python community maintains for the format
(pyuff and lvm_read by the SDyPy group, npTDMS the reference TDMS reader), installs from a wheel
with numpy as its only dependency, and was checked against files written by the library itself.

Every reader returns the channels as columns, the metadata (``fs`` from the file's time step when
all channels share it) and each channel's unit and sensitivity where the file holds them
(``unit:<channel>`` and ``sensitivity:<channel>`` metadata, reported in the result). A missing
channel lists the channels there are (``measurement.load``); unequal lengths or rates, and a UFF
function type that is not a time series, raise ``MeasurementError`` naming the file and the channel
or record.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

UFF_TIME_RESPONSE = 1
"""UFF dataset 58 function type of a time response (2: auto-spectrum, 4: FRF, ...)."""

UFF_FUNCTION_TYPES = {0: "general", 1: "time response", 2: "auto spectrum", 3: "cross spectrum",
                      4: "frequency response function", 5: "transmissibility", 6: "coherence",
                      7: "auto correlation", 8: "cross correlation", 9: "power spectral density",
                      12: "spectrum"}  # fmt: skip


def _error(msg: str):
    from .measurement import MeasurementError

    return MeasurementError(msg)


def _common_step(path: Path, steps: dict[str, float]) -> float | None:
    """The one sampling step all channels share (relative 1e-6), or a MeasurementError naming two."""
    named = {k: v for k, v in steps.items() if v and np.isfinite(v) and v > 0}
    if not named:
        return None
    ref_name, ref = next(iter(named.items()))
    for k, v in named.items():
        if abs(v / ref - 1) > 1e-6:
            raise _error(
                f"{path}: channels {ref_name} and {k} have different sampling rates ({1 / ref:.6g} Hz, {1 / v:.6g} Hz)"
            )
    return ref


def _equal_lengths(path: Path, cols: dict[str, np.ndarray]) -> None:
    if not cols:
        raise _error(f"{path}: no channels in the file")
    ref_name, ref = next(iter(cols.items()))
    for k, v in cols.items():
        if v.size != ref.size:
            raise _error(f"{path}: channels {ref_name} and {k} have different lengths ({ref.size}, {v.size} samples)")


def read_uff(path: Path):
    """Type-58 time-series channels of a Universal File (pyuff)."""
    import pyuff

    _check_memory(path)
    try:
        sets = pyuff.UFF(str(path)).read_sets()
    except Exception as exc:
        raise _error(f"{path}: unreadable Universal File ({type(exc).__name__}: {exc})".splitlines()[0]) from None
    sets = [sets] if isinstance(sets, dict) else list(sets)
    _check_uff_complete(path, len(sets))
    cols: dict[str, np.ndarray] = {}
    meta: dict[str, str] = {}
    steps: dict[str, float] = {}
    n58 = 0
    for i, s in enumerate(sets):
        if s.get("type") != 58:
            continue
        n58 += 1
        name = str(s.get("id1") or "").strip() or f"{s.get('rsp_node')}{s.get('rsp_dir')}"
        ft = int(s.get("func_type", -1))
        if ft != UFF_TIME_RESPONSE:
            raise _error(
                f"{path}: record {i + 1} ({name}) holds a {UFF_FUNCTION_TYPES.get(ft, 'function')} (UFF 58 function "
                f"type {ft}), not a time series (type 1)"
            )
        if name in cols:
            name = f"{name}#{i + 1}"
        data = np.asarray(s["data"])
        if np.iscomplexobj(data):
            raise _error(f"{path}: record {i + 1} ({name}) is complex, not a time series")
        cols[name] = data.astype(float)
        x = np.asarray(s.get("x", []), float)
        steps[name] = float(s.get("abscissa_inc") or (x[1] - x[0] if x.size > 1 else 0.0))
        unit = str(s.get("ordinate_axis_units_lab") or "").strip()
        if unit:
            meta[f"unit:{name}"] = unit
    if not n58:
        raise _error(f"{path}: no UFF 58 (function at nodal DOF) records in the file")
    _equal_lengths(path, cols)
    step = _common_step(path, steps)
    if step:
        fs = 1.0 / step
        # the increment is printed with 6 significant digits (E13.5): 1/512 s reads back as 512.0013 Hz;
        # an integer rate within that precision is the acquisition's
        if abs(fs - round(fs)) <= UFF_INCREMENT_PRECISION * fs:
            fs = float(round(fs))
        meta["fs"] = repr(fs)
    return cols, meta


def _check_uff_complete(path: Path, n_read: int) -> None:
    """A Universal File read whole: every dataset opens and closes with a ``-1`` line, and pyuff returned
    them all (it drops an incomplete last dataset silently; the record would then lose a channel, or its
    end, and negstiff would derive z from another channel)."""
    delimiters = sum(1 for line in path.read_bytes().splitlines() if line.strip() == b"-1")
    if delimiters % 2 or delimiters // 2 != n_read:
        raise _error(
            f"{path}: the Universal File is incomplete ({delimiters // 2 + delimiters % 2} datasets begin, "
            f"{n_read} read whole): truncated in copying? negstiff reads a file whole or not at all"
        )


def _check_memory(path: Path) -> None:
    """Refuse a lab file whose parse would not fit in memory, before its reader starts."""
    from negstiff.errors import InputError
    from negstiff.resources import require_memory

    try:
        require_memory(LAB_PARSE_BYTES_PER_BYTE * path.stat().st_size, f"reading {path}")
    except InputError as exc:
        raise _error(str(exc)) from None


LAB_PARSE_BYTES_PER_BYTE = 24
"""Memory [bytes] a lab format's reader may hold per byte of its file (as for a CSV: the text and its values)."""

UFF_INCREMENT_PRECISION = 5e-6
"""Relative precision of a UFF 58 abscissa increment as printed (E13.5: six significant digits)."""


def read_tdms(path: Path):
    """Every channel of a TDMS file (npTDMS), with wf_increment, unit and sensitivity properties."""
    from nptdms import TdmsFile
    from nptdms.log import log_manager

    _check_memory(path)
    # npTDMS says a file is truncated in log lines on stderr (its own handler on each module's logger) and
    # reads what is there: the lines are collected here (they reach the package's logger), not printed
    log, notes, console = logging.getLogger("nptdms"), _Notes(), log_manager.console_handler
    log.addHandler(notes)
    propagate, log.propagate = log.propagate, False
    level = console.level
    console.setLevel(logging.CRITICAL + 1)
    try:
        f = TdmsFile.read(str(path))
    except Exception as exc:
        raise _error(f"{path}: unreadable TDMS file ({type(exc).__name__}: {exc})".splitlines()[0]) from None
    finally:
        console.setLevel(level)
        log.removeHandler(notes)
        log.propagate = propagate
    if notes.lines:
        raise _error(f"{path}: the TDMS file is incomplete (npTDMS: {notes.lines[0]}): truncated in copying? "
                     "negstiff reads a file whole or not at all")  # fmt: skip
    chans = [(g.name, c) for g in f.groups() for c in g.channels()]
    names = [c.name for _, c in chans]
    cols: dict[str, np.ndarray] = {}
    meta: dict[str, str] = {str(k): str(v) for k, v in f.properties.items() if isinstance(v, (str, int, float))}
    steps: dict[str, float] = {}
    for group, c in chans:
        name = c.name if names.count(c.name) == 1 else f"{group}/{c.name}"
        data = np.asarray(c[:])
        if data.dtype.kind not in "fiu":
            continue  # timestamps, strings: not a measured channel
        cols[name] = data.astype(float)
        props = c.properties
        steps[name] = float(props.get("wf_increment", 0.0) or 0.0)
        unit = props.get("unit_string") or props.get("NI_UnitDescription")
        if unit:
            meta[f"unit:{name}"] = str(unit)
        for key in ("sensitivity", "Sensitivity", "NI_Scale[1]_Linear_Slope"):
            if key in props:
                meta[f"sensitivity:{name}"] = str(props[key])
                break
    _equal_lengths(path, cols)
    step = _common_step(path, steps)
    if step:
        meta["fs"] = repr(1.0 / step)
    return cols, meta


class _Notes(logging.Handler):
    """A log handler that keeps the warnings a reader logs (npTDMS's word that a file is truncated)."""

    def __init__(self):
        super().__init__(logging.WARNING)
        self.lines: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.lines.append(record.getMessage())


def read_lvm(path: Path):
    """The first segment of a LabVIEW measurement file (lvm_read, no pickle cache)."""
    import lvm_read

    _check_memory(path)
    try:
        d = lvm_read.read(str(path), read_from_pickle=False, dump_file=False)
        seg = d[0]
        data = np.asarray(seg["data"], float)
        names = [str(n).strip() for n in seg["Channel names"]]
    except Exception as exc:
        raise _error(f"{path}: unreadable LVM file ({type(exc).__name__}: {exc})".splitlines()[0]) from None
    if data.ndim != 2 or data.shape[1] < len(names):
        raise _error(f"{path}: the LVM data block does not match its {len(names)} channel names")
    cols: dict[str, np.ndarray] = {}
    meta: dict[str, str] = {}
    units = seg.get("Y_Unit_Label") or []
    dx = seg.get("Delta_X") or []
    steps: dict[str, float] = {}
    has_x = names and names[0] == "X_Value"
    for j, name in enumerate(names):
        if name in ("Comment", ""):
            continue
        if name == "X_Value":
            cols["t"] = data[:, j]
            continue
        cols[name] = data[:, j]
        k = j - 1 if has_x else j  # the per-channel header fields do not count the X column
        if 0 <= k < len(units) and str(units[k]).strip():
            meta[f"unit:{name}"] = str(units[k]).strip()
        if 0 <= k < len(dx):
            steps[name] = float(dx[k]) if np.isfinite(dx[k]) else 0.0
    _equal_lengths(path, cols)
    step = _common_step(path, steps)
    if step and "t" not in cols:
        meta["fs"] = repr(1.0 / step)
    return cols, meta


READERS = {".uff": read_uff, ".unv": read_uff, ".tdms": read_tdms, ".lvm": read_lvm}
