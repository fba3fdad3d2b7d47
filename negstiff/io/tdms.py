"""LabVIEW TDMS (``.tdms``) through **npTDMS** (LGPL-3.0, used as a library): every channel of every group,
named by the channel's name (``group/channel`` where two groups share a name); the time step from the
waveform property ``wf_increment``. A truncated file (npTDMS logs it, then reads what is there) is refused.
Written as one group of waveform channels with the record's metadata as file properties.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from negstiff.errors import MeasurementError

from .base import check_memory, common_step, equal_lengths
from .schema import si_unit
from .uff import LAB_PARSE_BYTES_PER_BYTE

SUFFIXES = (".tdms",)


def read(path: Path):
    """Every channel of a TDMS file (npTDMS), with wf_increment, unit and sensitivity properties."""
    from nptdms import TdmsFile
    from nptdms.log import log_manager

    check_memory(path, LAB_PARSE_BYTES_PER_BYTE * path.stat().st_size)
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
        raise MeasurementError(f"{path}: unreadable TDMS file ({type(exc).__name__}: {exc})".splitlines()[0]) from None
    finally:
        console.setLevel(level)
        log.removeHandler(notes)
        log.propagate = propagate
    if notes.lines:
        raise MeasurementError(f"{path}: the TDMS file is incomplete (npTDMS: {notes.lines[0]}): truncated in copying? "
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
    equal_lengths(path, cols)
    step = common_step(path, steps)
    if step:
        meta["fs"] = repr(1.0 / step)
    return cols, meta


class _Notes(logging.Handler):
    """A log handler that keeps the warnings a reader logs (npTDMS's word that a file is truncated)."""

    def __init__(self) -> None:
        super().__init__(logging.WARNING)
        self.lines: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.lines.append(record.getMessage())


def write(path: Path, cols: dict[str, np.ndarray], fs: float, meta: dict) -> None:
    """One group of waveform channels (the time column is not a channel: ``wf_increment`` is)."""
    chans = {k: v for k, v in cols.items() if k != "t"}
    from nptdms import ChannelObject, GroupObject, RootObject, TdmsWriter

    with TdmsWriter(str(path)) as w:
        objs = [RootObject(properties={k: str(v) for k, v in meta.items()}), GroupObject("negstiff")]
        objs += [
            ChannelObject("negstiff", k, np.asarray(v, float), properties={"wf_increment": 1.0 / fs,
                          "wf_start_offset": 0.0, "unit_string": si_unit(k)})
            for k, v in chans.items()
        ]  # fmt: skip
        w.write_segment(objs)
