"""Folder outputs lose nothing (issue "Nothing lost, round three"): a report or campaign folder is replaced as a
whole, so negstiff writes one only where nothing of the user's is: a new or empty folder, or one holding only
what negstiff wrote there (its manifest lists every file, unchanged; a folder of the version before the
manifest: only the files that version wrote). Anything else (a user's file, a file where the folder is wanted,
the record the report reads) is refused before any work, with one line, and left byte-identical. The command
line and the library go through the same check (``negstiff.files.check_folder``)."""

import hashlib
import json
import time
from pathlib import Path

import numpy as np
import pytest
from scipy import signal

from negstiff import OutputError, Report
from negstiff.cli import main
from negstiff.files import MANIFEST, atomic_dir, check_folder
from negstiff.inference.record.reading import load

FS = 256.0
"""Samples per second of the test record: 20 s of an 8 Hz oscillator is 160 periods, 5120 samples."""


@pytest.fixture(scope="module")
def rec(tmp_path_factory) -> Path:
    """20 s of a linear oscillator (8 Hz, 2 % damping) shaken by white base acceleration (1 m/s^2 rms),
    written as the lab would (CSV: t, base_acc, z): the cheapest record a report takes."""
    d = tmp_path_factory.mktemp("folder_outputs")
    rng = np.random.default_rng(7)
    t = np.arange(int(20 * FS)) / FS
    a = rng.standard_normal(t.size)
    wn, zeta = 2 * np.pi * 8.0, 0.02
    _, z, _ = signal.lsim(([-1.0], [1.0, 2 * zeta * wn, wn**2]), a, t)
    z += 1e-7 * rng.standard_normal(t.size)  # a displacement sensor's noise floor
    path = d / "rec.csv"
    np.savetxt(path, np.column_stack([t, a, z]), delimiter=",", header="t,base_acc,z", comments="", fmt="%.9g")
    return path


def _snapshot(d: Path) -> dict:
    """Every file under ``d`` (hidden ones too) by its bytes' hash."""
    return {str(p.relative_to(d)): hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(d.rglob("*"))
            if p.is_file()}  # fmt: skip


def _old_report_folder(folder: Path) -> None:
    """A report folder as the version before the manifest wrote it: results.json, index.md with its figure,
    index.html, the PNG."""
    folder.mkdir(parents=True)
    (folder / "results.json").write_text('{"summary": []}\n')
    (folder / "index.md").write_text("# old\n\n![The FRF](frf_record.png)\n")
    (folder / "index.html").write_text("<html></html>\n")
    (folder / "frf_record.png").write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(100))


def refused(capsys, argv, folder: Path, seconds: float = 10.0) -> str:
    """Exit 2 with one line on stderr, within ``seconds`` (before any work), the folder and its neighbours
    byte-identical, no temporary left beside it."""
    before = _snapshot(folder.parent)
    start = time.perf_counter()
    rc = main([str(a) for a in argv])
    took = time.perf_counter() - start
    err = capsys.readouterr().err
    lines = [x for x in err.strip().splitlines() if x.strip()]
    assert rc == 2, err
    assert len(lines) == 1 and "error" in lines[0] and "Traceback" not in err, err
    assert took < seconds, f"refused after {took:.1f} s: the check must come before the work"
    assert _snapshot(folder.parent) == before, "the folder or a neighbour was changed"
    assert not [p for p in folder.parent.iterdir() if p.name.startswith(".") and ".part" in p.name]
    return lines[0]


# --- the command line --------------------------------------------------------------------------------------
def test_report_keeps_a_users_file_in_an_old_report_folder(rec, tmp_path, capsys):
    # the case: out/old holds an old results.json (negstiff's marker) and the user's notes.txt
    out = tmp_path / "out" / "old"
    _old_report_folder(out)
    (out / "notes.txt").write_text("the user's notes")
    msg = refused(capsys, ["report", rec, "-o", out, "--only", "frf", "--quiet"], out)
    assert "notes.txt" in msg
    assert (out / "notes.txt").read_text() == "the user's notes"


def test_report_rewrites_a_folder_negstiff_wrote_and_lists_what_it_wrote(rec, tmp_path):
    out = tmp_path / "rep"
    assert main(["report", str(rec), "-o", str(out), "--only", "frf", "--quiet"]) == 0
    listed = json.loads((out / MANIFEST).read_text())["files"]
    on_disk = {p.name for p in out.iterdir()} - {MANIFEST}
    assert set(listed) == on_disk and {"index.md", "index.html", "results.json"} <= on_disk
    for name, entry in listed.items():  # sizes and hashes of what is there
        assert entry["bytes"] == (out / name).stat().st_size
        assert entry["sha256"] == hashlib.sha256((out / name).read_bytes()).hexdigest()
    assert main(["report", str(rec), "-o", str(out), "--only", "frf", "--quiet"]) == 0  # its own folder again
    assert set(json.loads((out / MANIFEST).read_text())["files"]) == on_disk
    assert [p.name for p in tmp_path.iterdir()] == ["rep"], "nothing left beside the folder"


def test_report_refuses_a_file_negstiff_wrote_once_the_user_changed_it(rec, tmp_path, capsys):
    out = tmp_path / "rep"
    assert main(["report", str(rec), "-o", str(out), "--only", "frf", "--quiet"]) == 0
    with open(out / "index.md", "a") as fh:
        fh.write("\nMy reading of the FRF.\n")
    msg = refused(capsys, ["report", rec, "-o", out, "--only", "frf", "--quiet"], out)
    assert "index.md" in msg and "changed" in msg


def test_a_folder_written_before_the_manifest_is_replaced_when_it_holds_only_negstiffs_files(rec, tmp_path):
    out = tmp_path / "old"
    _old_report_folder(out)
    assert main(["report", str(rec), "-o", str(out), "--only", "frf", "--quiet"]) == 0
    assert (out / MANIFEST).is_file() and json.loads((out / "results.json").read_text())["summary"]


def test_report_refuses_a_file_where_its_folder_is_wanted(rec, tmp_path, capsys):
    out = tmp_path / "out"
    out.write_text("a file of the user's")
    msg = refused(capsys, ["report", rec, "-o", out, "--only", "frf", "--quiet"], out)
    assert "not a folder" in msg and out.read_text() == "a file of the user's"


def test_rig_campaign_keeps_a_users_file_beside_an_index(tmp_path, capsys):
    out = tmp_path / "camp"
    out.mkdir()
    (out / "index.json").write_text('{"records": []}\n')
    (out / "notes.txt").write_text("the user's notes")
    msg = refused(capsys, ["rig", "campaign", "--amplitudes", "5,6", "-o", out, "--quiet"], out, seconds=3.0)
    assert "notes.txt" in msg and (out / "notes.txt").read_text() == "the user's notes"


def test_reproduce_keeps_a_users_file_beside_results_and_refuses_before_the_study(tmp_path, capsys):
    out = tmp_path / "paper"
    _old_report_folder(out)
    (out / "notes.txt").write_text("the user's notes")
    msg = refused(capsys, ["reproduce", "--fast", "-o", out, "--quiet"], out, seconds=3.0)
    assert "notes.txt" in msg and (out / "notes.txt").read_text() == "the user's notes"


def test_the_library_reproduce_refuses_before_the_study(tmp_path):
    from negstiff.experiments.reproduce import reproduce

    (tmp_path / "notes.txt").write_text("the user's notes")
    start = time.perf_counter()
    with pytest.raises(OutputError, match="notes.txt"):
        reproduce(tmp_path, fast=True, progress=False)
    assert time.perf_counter() - start < 3.0
    assert [p.name for p in tmp_path.iterdir()] == ["notes.txt"]


# --- the library: Report.write --------------------------------------------------------------------------
def test_report_write_keeps_a_thesis_in_the_folder(rec, tmp_path):
    out = tmp_path / "thesis"
    out.mkdir()
    (out / "thesis.tex").write_text("\\chapter{Results}\n")
    with pytest.raises(OutputError, match="thesis.tex"):
        Report("r").add(load(rec)).write(out)
    assert _snapshot(tmp_path) == {"thesis/thesis.tex": hashlib.sha256(b"\\chapter{Results}\n").hexdigest()}


def test_report_write_never_replaces_the_folder_of_the_record_it_was_built_from(rec, tmp_path):
    # the record sits in a folder negstiff wrote (a campaign's, say): its manifest lists it, yet the report
    # read it, so the folder is refused and the record stays byte-identical
    folder = tmp_path / "records"
    with atomic_dir(folder) as tmp:
        (tmp / "rec.csv").write_bytes(rec.read_bytes())
    before = _snapshot(tmp_path)
    with pytest.raises(OutputError, match="input"):
        Report("r").add(load(folder / "rec.csv")).write(folder)
    assert _snapshot(tmp_path) == before
    with pytest.raises(OutputError):  # and the record's own folder, in the user's place
        Report("r").add(load(rec)).write(rec.parent)
    assert (rec.parent / "rec.csv").read_bytes() == (folder / "rec.csv").read_bytes()


def test_report_write_refuses_a_file_path_and_leaves_it_as_it_was(rec, tmp_path):
    path = tmp_path / "summary"
    path.write_text("a file of the user's")
    with pytest.raises(OutputError, match="not a folder"):
        Report("r").add(load(rec)).write(path)
    assert [p.name for p in tmp_path.iterdir()] == ["summary"] and path.read_text() == "a file of the user's"


def test_a_file_that_arrives_while_the_folder_is_written_is_kept(tmp_path):
    # the check before the work cannot see a file saved during a long run: the move into place looks again
    out = tmp_path / "rep"
    with atomic_dir(out) as tmp:
        (tmp / "results.json").write_text("{}\n")
    with pytest.raises(OutputError, match="late.txt"), atomic_dir(out) as tmp:
        (tmp / "results.json").write_text('{"new": 1}\n')
        (out / "late.txt").write_text("saved during the run")
    assert (out / "late.txt").read_text() == "saved during the run" and (out / "results.json").read_text() == "{}\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rep"]


# --- the rule, on folders made by hand --------------------------------------------------------------------
def test_an_old_campaign_folder_is_replaceable_only_with_nothing_but_its_records(tmp_path):
    camp = tmp_path / "camp"
    camp.mkdir()
    names = ["plus_up_000_5.csv", "plus_up_001_6.5.csv"]
    (camp / "index.json").write_text(json.dumps({"records": [{"file": n} for n in names]}))
    for n in names:
        (camp / n).write_text("t,base_acc,z\n")
        (camp / n).with_name(Path(n).stem + ".truth.json").write_text("{}")
    assert check_folder(camp) == camp.resolve()
    (camp / "fit.py").write_text("# the user's script")
    with pytest.raises(OutputError, match="fit.py"):
        check_folder(camp)


@pytest.mark.parametrize("kind", ["subfolder", "empty subfolder", "link", "hidden", "bad manifest"])
def test_anything_not_listed_in_the_manifest_is_refused(tmp_path, kind):
    out = tmp_path / "rep"
    with atomic_dir(out) as tmp:
        (tmp / "results.json").write_text("{}\n")
    check_folder(out)  # as negstiff wrote it
    if kind == "subfolder":
        (out / "mine").mkdir()
        (out / "mine" / "data.csv").write_text("1\n")
    elif kind == "empty subfolder":
        (out / "mine").mkdir()
    elif kind == "link":
        (out / "data").symlink_to(tmp_path)
    elif kind == "hidden":
        (out / ".notes").write_text("x")
    else:
        (out / MANIFEST).write_text("not json")
    with pytest.raises(OutputError):
        check_folder(out)
