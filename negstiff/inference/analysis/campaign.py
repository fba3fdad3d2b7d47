"""A stepped harmonic campaign and its bifurcation map (reference study Figure 4; ``negstiff map``): the records (files
in order, or a folder with ``index.json`` as ``negstiff rig campaign`` writes it, else its files by name),
each one's forcing frequency, the ``negstiff nfrc`` results drawn over the map, and the map itself: each
record's period, regime, Poincare z and forcing amplitude measured from its input (``characterise.map_point``),
each sweep's sequence and first period 2 (or where a stepped sine jumps), each continuation's first doubling
or folds beside the map's.

``Campaign.read`` reads and checks everything (the files, the frequencies, the continuations, the wells)
before any analysis; ``Campaign.map`` analyses.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from negstiff.errors import MeasurementError
from negstiff.files import read_json
from negstiff.inference.analysis.characterise import (
    check_harmonic,
    first_period_2,
    jump,
    map_point,
    map_sequence,
    response_for,
)
from negstiff.inference.record.measurement import Measurement
from negstiff.inference.record.reading import load

MEASUREMENT_SUFFIXES = (".csv", ".txt", ".npz", ".mat", ".uff", ".unv", ".tdms", ".lvm")


def campaign_records(data: Sequence[str]) -> list[dict[str, Any]]:
    """The records of a stepped campaign, each ``{"file", "start", "direction", "forcing_hz"}`` (None where
    not known yet): the files in the order given, or one folder: its ``index.json`` (``negstiff rig
    campaign``'s: file, start_well, direction, forcing_hz), else its measurement files by name.
    """
    folder = Path(data[0]) if len(data) == 1 and Path(data[0]).is_dir() else None
    if folder is None:
        return [{"file": d, "start": None, "direction": None, "forcing_hz": None} for d in data]
    index = folder / "index.json"
    if not index.is_file():
        files = sorted((p for p in folder.iterdir() if p.suffix.lower() in MEASUREMENT_SUFFIXES), key=_natural)
        if not files:
            raise MeasurementError(
                f"{folder}: no measurement files ({', '.join(MEASUREMENT_SUFFIXES)}) and no index.json"
            )
        return [{"file": str(p), "start": None, "direction": None, "forcing_hz": None} for p in files]
    try:
        return [
            {"file": str(folder / r["file"]), "start": r.get("start_well"), "direction": r.get("direction"),
             "forcing_hz": float(r["forcing_hz"]) if "forcing_hz" in r else None}
            for r in read_json(index)["records"]
        ]  # fmt: skip
    except (ValueError, KeyError, TypeError, AttributeError):
        raise MeasurementError(
            f"{index}: not a campaign index (records: file, start_well, direction, forcing_hz)"
        ) from None


def campaign_files(data: Sequence[str] | None) -> list[Path]:
    """Every file ``map`` reads for ``data``: the records (a folder's, by its index or its names) and the
    folder's index; checked against the outputs before any work.
    """
    if not data:
        return []
    files = [Path(e["file"]) for e in campaign_records(data)]
    folder = Path(data[0]) if len(data) == 1 and Path(data[0]).is_dir() else None
    if folder is not None and (folder / "index.json").is_file():
        files.append(folder / "index.json")
    return files


def _natural(path: Path) -> list:
    """A file name's sort key with its numbers as numbers: step2 before step10, 4.5 before 10."""
    return [(0, float(t), "") if t[:1].isdigit() else (1, 0.0, t) for t in re.findall(r"\d+(?:\.\d+)?|\D+", path.name)]


def forcing_frequencies(entries: list[dict[str, Any]], recs, given: float | None) -> list[float]:
    """Each record's forcing frequency [Hz]: the index's, else its metadata's ``forcing_hz``, else
    ``given`` (--forcing-hz); a given one that disagrees with the file's is refused.
    """
    out = []
    for e, rec in zip(entries, recs, strict=False):
        stated = e["forcing_hz"]
        if stated is None and "forcing_hz" in rec.meta:
            try:
                stated = float(rec.meta["forcing_hz"])
            except ValueError:
                raise MeasurementError(
                    f"{e['file']}: metadata forcing_hz = {rec.meta['forcing_hz']!r} is not a number"
                ) from None
        if stated is not None and not (stated > 0 and math.isfinite(stated)):
            raise MeasurementError(f"{e['file']}: its forcing frequency {stated:g} Hz is not a positive number")
        if given is not None and stated is not None and abs(given / stated - 1) > 1e-9:
            raise MeasurementError(f"--forcing-hz {given:g} disagrees with {e['file']} ({stated:g} Hz)")
        if stated is None and given is None:
            raise MeasurementError(
                f"{e['file']}: no forcing frequency (no index or metadata forcing_hz): give --forcing-hz"
            )
        value = stated if stated is not None else given
        assert value is not None  # refused above
        out.append(float(value))
    return out


def read_nfrc_results(paths: Sequence[str] | None, axis: str, forcing_hz: float) -> list[dict[str, Any]]:
    """Each ``--nfrc`` result, checked before any analysis: a continuation along the map's ``axis``
    (``amplitude``: at ``forcing_hz``; ``f_hz``: its amplitude is compared with the records' afterwards).
    """
    out = []
    for p in paths or []:
        try:
            r = read_json(p)
            st, branches = r["settings"], r["branches"]
            parameter, fixed, well = st["parameter"], float(st["fixed"]), st["well"]
        except (ValueError, KeyError, TypeError, AttributeError):
            raise MeasurementError(f"--nfrc {p}: not an nfrc result (needs settings and branches)") from None
        if well not in ("plus", "minus"):
            raise MeasurementError(f"--nfrc {p}: its well is {well!r}, not plus or minus")
        if axis == "amplitude" and (parameter != "amplitude" or abs(fixed / forcing_hz - 1) > 1e-6):
            raise MeasurementError(
                f"--nfrc {p}: a continuation in amplitude at {forcing_hz:g} Hz is needed, this one is in {parameter} "
                f"at {fixed:g}"
            )
        if axis == "f_hz" and parameter != "f_hz":
            raise MeasurementError(
                f"--nfrc {p}: the records step the frequency: a continuation in frequency is needed, this one is in "
                f"{parameter}"
            )
        out.append({"label": Path(p).stem, "settings": st, "branches": branches, "bifurcations": r["bifurcations"]})
    return out


def continuation_vs_map(overlay: dict[str, Any], points: list[dict[str, Any]], axis: str) -> dict[str, Any]:
    """A continuation beside the map. In amplitude: its period-1 branch's first doubling beside the map's
    first period 2 sweeping up from its well (or in the records' order where the map does not say). In
    frequency: its folds beside where each of the map's sweeps from its well jumps (sweeping up the
    response leaves its branch at the upper fold, sweeping down at the lower one).
    """
    well = overlay["settings"]["well"]
    mine = [p for p in points if p["start"] in (well, None)]
    out: dict[str, Any] = {"label": overlay["label"], "well": well}
    if axis == "amplitude":
        pd = [b["amplitude"] for b in overlay["bifurcations"] if b["type"] == "period_doubling" and b["period"] == 1]
        up = [p for p in mine if p["direction"] in ("up", None)]
        return out | {"first_doubling": min(pd) if pd else None, "map_first_period_2": first_period_2(up)}
    folds = sorted(b["f_hz"] for b in overlay["bifurcations"] if b["type"] == "fold" and b["period"] == 1)
    sweeps: dict[str, list] = {}
    for p in mine:
        sweeps.setdefault(p["direction"] or "records", []).append(p)
    return out | {"folds": folds, "amplitude": overlay["settings"]["fixed"],
                  "map_jumps_hz": {d: jump(v) for d, v in sweeps.items()}}  # fmt: skip


def map_warnings(points, overlays, axis: str, wells) -> list[str]:
    """What the map cannot say: no wells to tell a cross-well response from an in-well one, or a
    continuation at another amplitude than the records'.
    """
    out = []
    if wells is None:
        out.append("no rest positions (--wells or the records' metadata): a cross-well response is not told from an "
                   "in-well one; the regime is the side of the median")  # fmt: skip
    if axis == "f_hz":
        a = float(np.median([p["amplitude"] for p in points]))
        for o in overlays:
            if abs(o["settings"]["fixed"] / a - 1) > 0.05:
                out.append(f"--nfrc {o['label']}: continued at amplitude {o['settings']['fixed']:g}, the records' "
                           f"forcing is {a:.4g} (median): the curves do not compare")  # fmt: skip
    return out


@dataclass(frozen=True)
class Campaign:
    """A stepped harmonic campaign, read and checked (``read``): its records, their forcing frequencies,
    the axis it steps (``"amplitude"`` at one frequency, or ``"f_hz"``), the continuations to draw over
    its map, and the wells its regimes are judged against.
    """

    entries: list[dict[str, Any]]
    records: list[Measurement]
    freqs: list[float]
    axis: str
    overlays: list[dict[str, Any]]
    wells: tuple[float, ...] | None

    @classmethod
    def read(cls, data: Sequence[str], columns=None, fs: float | None = None, forcing_hz: float | None = None,
             wells: tuple[float, ...] | None = None, nfrc: Sequence[str] | None = None,
             gravity: float | None = None) -> Campaign:  # fmt: skip
        """Read every record and continuation of ``data`` and check them (one ``MeasurementError``), before
        any analysis; ``gravity`` [m/s^2] along the motion overrides the records' metadata (0: horizontal).
        """
        entries = campaign_records(data)
        # each record's one response (a structure's: its element's relative motion), built once for every analysis
        recs = [response_for(load(e["file"], columns=columns, fs=fs, gravity=gravity)) for e in entries]
        freqs = forcing_frequencies(entries, recs, forcing_hz)
        axis = "f_hz" if max(freqs) / min(freqs) - 1 > 1e-9 else "amplitude"  # the campaign steps f, or A at one f
        overlays = read_nfrc_results(nfrc, axis, freqs[0])
        for e, rec, f in zip(entries, recs, freqs, strict=False):
            if not f < rec.fs / 2:
                raise MeasurementError(
                    f"{e['file']}: its forcing frequency {f:g} Hz is above its Nyquist frequency {rec.fs / 2:g} Hz"
                )
            if rec.input_name != recs[0].input_name:
                raise MeasurementError(
                    f"{e['file']}: input {rec.input_name}, the campaign's first record's: {recs[0].input_name}"
                )
            check_harmonic(rec, f)
        rests = (r.rest_positions for r in recs)  # a structure's: its element's relative rests
        wells = wells or next(((w["minus"], w["plus"]) for w in rests if len(w) == 2), None)
        return cls(entries, recs, freqs, axis, overlays, wells)

    def map(self, progress: Callable[[str], None] | None = None) -> dict[str, Any]:
        """The bifurcation map (``negstiff map``'s result, without its figure); ``progress`` hears of each
        record as it is analysed.
        """
        points = []
        for e, rec, f in zip(self.entries, self.records, self.freqs, strict=False):
            points.append({**e, "f_hz": f, **map_point(rec, f, self.wells)})
            p = points[-1]
            if progress:
                progress(f"  {Path(e['file']).name}: {f:g} Hz, amplitude {p['amplitude']:.4g}, period {p['period']}")
        sweeps: dict[str, Any] = {}
        for p in points:
            sweeps.setdefault(" ".join(x for x in (p["start"], p["direction"]) if x) or "records", []).append(p)
        summary: dict[str, Callable[[list[dict[str, Any]]], Any]] = (
            {"sequence": map_sequence, "first_period_2": first_period_2} if self.axis == "amplitude"
            else {"sequence": lambda v: map_sequence(v, "f_hz"), "jump_hz": jump}
        )  # fmt: skip
        return {
            "axis": self.axis,
            "forcing_hz": self.freqs[0] if self.axis == "amplitude" else None,
            "input": self.records[0].input_name,
            "wells_used": self.wells,
            "points": points,
            "sweeps": {k: {name: fn(v) for name, fn in summary.items()} for k, v in sweeps.items()},
            "continuations": [continuation_vs_map(o, points, self.axis) for o in self.overlays],
            "warnings": map_warnings(points, self.overlays, self.axis, self.wells),
        }
