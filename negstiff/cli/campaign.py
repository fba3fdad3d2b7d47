"""A stepped campaign for ``negstiff map``: its records (files, or a folder with ``index.json`` as ``negstiff
rig campaign`` writes it), its forcing frequency, and the ``negstiff nfrc`` results drawn over its map."""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any, Sequence

from .common import InputError

MEASUREMENT_SUFFIXES = (".csv", ".txt", ".npz", ".mat", ".uff", ".unv", ".tdms", ".lvm")


def campaign_records(data: Sequence[str]) -> list[dict[str, Any]]:
    """The records of a stepped campaign, each ``{"file", "start", "direction", "forcing_hz"}`` (None where
    not known yet): the files in the order given, or one folder: its ``index.json`` (``negstiff rig
    campaign``'s: file, start_well, direction, forcing_hz), else its measurement files by name."""
    from negstiff.files import read_json

    folder = Path(data[0]) if len(data) == 1 and Path(data[0]).is_dir() else None
    if folder is None:
        return [{"file": d, "start": None, "direction": None, "forcing_hz": None} for d in data]
    index = folder / "index.json"
    if not index.is_file():
        files = sorted((p for p in folder.iterdir() if p.suffix.lower() in MEASUREMENT_SUFFIXES), key=_natural)
        if not files:
            raise InputError(f"{folder}: no measurement files ({', '.join(MEASUREMENT_SUFFIXES)}) and no index.json")
        return [{"file": str(p), "start": None, "direction": None, "forcing_hz": None} for p in files]
    try:
        return [
            {"file": str(folder / r["file"]), "start": r.get("start_well"), "direction": r.get("direction"),
             "forcing_hz": float(r["forcing_hz"]) if "forcing_hz" in r else None}
            for r in read_json(index)["records"]
        ]  # fmt: skip
    except (ValueError, KeyError, TypeError, AttributeError):
        raise InputError(f"{index}: not a campaign index (records: file, start_well, direction, forcing_hz)") from None


def campaign_files(data: Sequence[str] | None) -> list[Path]:
    """Every file ``map`` reads for ``data``: the records (a folder's, by its index or its names) and the
    folder's index; checked against the outputs before any work."""
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
    ``given`` (--forcing-hz); a given one that disagrees with the file's is refused."""
    out = []
    for e, rec in zip(entries, recs):
        stated = e["forcing_hz"]
        if stated is None and "forcing_hz" in rec.meta:
            try:
                stated = float(rec.meta["forcing_hz"])
            except ValueError:
                raise InputError(
                    f"{e['file']}: metadata forcing_hz = {rec.meta['forcing_hz']!r} is not a number"
                ) from None
        if stated is not None and not (stated > 0 and math.isfinite(stated)):
            raise InputError(f"{e['file']}: its forcing frequency {stated:g} Hz is not a positive number")
        if given is not None and stated is not None and abs(given / stated - 1) > 1e-9:
            raise InputError(f"--forcing-hz {given:g} disagrees with {e['file']} ({stated:g} Hz)")
        if stated is None and given is None:
            raise InputError(f"{e['file']}: no forcing frequency (no index or metadata forcing_hz): give --forcing-hz")
        out.append(float(stated if stated is not None else given))
    return out


def read_nfrc_results(paths: Sequence[str] | None, axis: str, forcing_hz: float) -> list[dict[str, Any]]:
    """Each ``--nfrc`` result, checked before any analysis: a continuation along the map's ``axis``
    (``amplitude``: at ``forcing_hz``; ``f_hz``: its amplitude is compared with the records' afterwards)."""
    from negstiff.files import read_json

    out = []
    for p in paths or []:
        try:
            r = read_json(p)
            st, branches = r["settings"], r["branches"]
            parameter, fixed, well = st["parameter"], float(st["fixed"]), st["well"]
        except (ValueError, KeyError, TypeError, AttributeError):
            raise InputError(f"--nfrc {p}: not an nfrc result (needs settings and branches)") from None
        if well not in ("plus", "minus"):
            raise InputError(f"--nfrc {p}: its well is {well!r}, not plus or minus")
        if axis == "amplitude" and (parameter != "amplitude" or abs(fixed / forcing_hz - 1) > 1e-6):
            raise InputError(f"--nfrc {p}: a continuation in amplitude at {forcing_hz:g} Hz is needed, this one is "
                             f"in {parameter} at {fixed:g}")  # fmt: skip
        if axis == "f_hz" and parameter != "f_hz":
            raise InputError(f"--nfrc {p}: the records step the frequency: a continuation in frequency is needed, "
                             f"this one is in {parameter}")  # fmt: skip
        out.append({"label": Path(p).stem, "settings": st, "branches": branches, "bifurcations": r["bifurcations"]})
    return out


def continuation_vs_map(overlay: dict[str, Any], points: list[dict[str, Any]], axis: str) -> dict[str, Any]:
    """A continuation beside the map. In amplitude: its period-1 branch's first doubling beside the map's
    first period 2 sweeping up from its well (or in the records' order where the map does not say). In
    frequency: its folds beside where each of the map's sweeps from its well jumps (sweeping up the
    response leaves its branch at the upper fold, sweeping down at the lower one)."""
    from negstiff.inference.characterize import first_period_2, jump

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
