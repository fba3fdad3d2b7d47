"""A stepped campaign for ``negstiff map``: its records (files, or a folder with ``index.json`` as ``negstiff
rig campaign`` writes it), its forcing frequency, and the ``negstiff nfrc`` results drawn over its map."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Sequence

from .common import InputError

MEASUREMENT_SUFFIXES = (".csv", ".txt", ".npz", ".mat", ".uff", ".unv", ".tdms", ".lvm")


def campaign_records(data: Sequence[str], forcing_hz: float | None) -> tuple[list[dict[str, Any]], float]:
    """The records of a stepped campaign, each ``{"file", "start", "direction"}`` (None where unknown), and
    its forcing frequency: the files in the order given, or one folder: its ``index.json`` (``negstiff rig
    campaign``'s: file, start_well, direction, forcing_hz), else its measurement files by name."""
    from negstiff.files import read_json

    folder = Path(data[0]) if len(data) == 1 and Path(data[0]).is_dir() else None
    if folder is None:
        return [{"file": d, "start": None, "direction": None} for d in data], _forcing(forcing_hz, None, data[0])
    index = folder / "index.json"
    if not index.is_file():
        files = sorted(p for p in folder.iterdir() if p.suffix.lower() in MEASUREMENT_SUFFIXES)
        if not files:
            raise InputError(f"{folder}: no measurement files ({', '.join(MEASUREMENT_SUFFIXES)}) and no index.json")
        return [{"file": str(p), "start": None, "direction": None} for p in files], _forcing(forcing_hz, None, folder)
    try:
        rows = read_json(index)["records"]
        recs = [{"file": str(folder / r["file"]), "start": r.get("start_well"), "direction": r.get("direction")}
                for r in rows]  # fmt: skip
        freqs = {float(r["forcing_hz"]) for r in rows if "forcing_hz" in r}
    except (ValueError, KeyError, TypeError, AttributeError):
        raise InputError(f"{index}: not a campaign index (records: file, start_well, direction, forcing_hz)") from None
    if len(freqs) > 1:
        raise InputError(f"{index}: the records have {len(freqs)} forcing frequencies; a map has one")
    return recs, _forcing(forcing_hz, freqs.pop() if freqs else None, index)


def _forcing(given: float | None, indexed: float | None, where) -> float:
    if given is not None and indexed is not None and abs(given / indexed - 1) > 1e-9:
        raise InputError(f"--forcing-hz {given:g} disagrees with {where} ({indexed:g} Hz)")
    if given is None and indexed is None:
        raise InputError(f"{where}: no forcing frequency: give --forcing-hz")
    return float(given if given is not None else indexed)


def read_nfrc_results(paths: Sequence[str] | None, forcing_hz: float) -> list[dict[str, Any]]:
    """Each ``--nfrc`` result, checked before any work: a continuation in amplitude at ``forcing_hz``."""
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
        if parameter != "amplitude" or abs(fixed / forcing_hz - 1) > 1e-6:
            raise InputError(f"--nfrc {p}: a continuation in amplitude at {forcing_hz:g} Hz is needed, this one is "
                             f"in {parameter} at {fixed:g}")  # fmt: skip
        out.append({"label": Path(p).stem, "settings": st, "branches": branches, "bifurcations": r["bifurcations"]})
    return out


def continuation_vs_map(overlay: dict[str, Any], points: list[dict[str, Any]]) -> dict[str, Any]:
    """A continuation's first doubling of its period-1 branch beside the map's first period 2 sweeping up
    from its well (or in the records' order where the map does not say)."""
    from negstiff.inference.characterize import first_period_2

    well = overlay["settings"]["well"]
    pd = [b["amplitude"] for b in overlay["bifurcations"] if b["type"] == "period_doubling" and b["period"] == 1]
    mine = [p for p in points if p["start"] == well and p["direction"] in ("up", None)]
    sweep = mine or [p for p in points if p["start"] is None]
    return {"label": overlay["label"], "well": well, "first_doubling": min(pd) if pd else None,
            "map_first_period_2": first_period_2(sweep)}  # fmt: skip
