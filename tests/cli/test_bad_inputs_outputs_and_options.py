"""Bad outputs and options, kept as tests: every case the probe
found is refused cleanly (exit 2, one line on stderr, no traceback, nothing written, every input
byte-identical) or, where the input is legal, runs to a sound result. No command may write onto a file it
read, whatever the path spelling. A hypothesis search over every command's options, drawn from the
parser's own declarations, finds no traceback before the work starts."""

import json
import os
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from records import refused, write_csv

import negstiff.cli.commands as commands
from negstiff.cli import build_parser, main
from negstiff.cli.parser import ALIASES
from negstiff.errors import OutputError
from negstiff.files import check_outputs

MODEL = {"m": 0.2, "k1": 426.0, "k2": -3060.0, "k3": 7.77e5, "c": 3.5}
STRUCTURE = {"masses": [1.0, 0.2], "element": {"m": 0.2, "k1": 426.0, "k2": 1000.0, "k3": 6.7e5, "c": 3.5, "c_nl": 0.5},
             "at": [1, 2], "stiffness": [[4.0e4, 0.0], [0.0, 0.0]], "damping": [[20.0, 0.0], [0.0, 0.0]]}  # fmt: skip
TARGETS = {"f_minus": 11.4, "f_plus": 9.2, "z_minus": -0.029, "z_plus": 0.023}


def _columns(path: Path) -> dict:
    lines = [x for x in path.read_text().splitlines() if not x.startswith("#")]
    data = np.loadtxt(lines[1:], delimiter=",")
    return dict(zip(lines[0].split(","), data.T, strict=False))


def _csv(path: Path, cols: dict, meta: dict | None = None) -> Path:
    return write_csv(path, cols, meta)


@pytest.fixture(scope="module")
def lab(tmp_path_factory):
    """A small lab: a rig record, a harmonic record, a campaign folder, model and target files, and the
    probe's bad records (written with numpy from the rig record's columns)."""
    d = tmp_path_factory.mktemp("probe2")
    assert main(["rig", "random", "-o", str(d / "rec.csv"), "--duration", "12", "--seed", "1", "--quiet"]) == 0
    assert main(["rig", "harmonic", "-o", str(d / "harm.csv"), "--periods", "40", "--settle-periods", "20",
                 "--quiet"]) == 0  # fmt: skip
    assert main(["rig", "campaign", "--amplitudes", "5,6", "--periods", "20", "--settle-periods", "20",
                 "-o", str(d / "camp"), "--quiet"]) == 0  # fmt: skip
    (d / "model.json").write_text(json.dumps(MODEL))
    (d / "targets.json").write_text(json.dumps(TARGETS))
    raw = _columns(d / "rec.csv")
    t, u, z = raw["t"], raw["base_acc"], raw["z"]
    h = _columns(d / "harm.csv")
    _csv(d / "huge.csv", {"t": t, "base_acc": 1e300 * u, "z": 1e300 * z})
    _csv(d / "huge_input.csv", {"t": t, "base_acc": 1e300 * u, "z": z})
    _csv(d / "still.csv", {"t": t, "base_acc": np.full_like(u, 0.5), "z": z})
    _csv(d / "dead.csv", {"t": h["t"], "base_acc": h["base_acc"], "z": np.full_like(h["z"], 0.0228)})
    _csv(d / "zero.csv", {"t": h["t"], "base_acc": h["base_acc"], "z": np.zeros_like(h["z"])})
    _csv(d / "short.csv", {"t": t[:1024], "base_acc": u[:1024], "z": z[:1024]})
    _csv(d / "fs_huge.csv", {"base_acc": u, "z": z}, {"fs": "1e300"})
    _csv(d / "fs_tiny.csv", {"base_acc": u, "z": z}, {"fs": "1e-300"})
    # a structure's record (the device on a fixture): two responses and the masses in the header
    _csv(d / "rec2.csv", {"t": t, "base_acc": u, "z1": 0.05 * z, "z2": z}, {"masses": "1.0,0.2"})
    # a record with an auxiliary channel (a live one and a dead one), and a structure's model file
    _csv(d / "aux.csv", {"t": t, "base_acc": u, "z": z, "volt": np.sin(t), "dead": np.zeros_like(t)})
    (d / "structure.json").write_text(json.dumps(STRUCTURE))
    (d / "twoz.csv").write_text(
        "t,base_acc,z,y,z\n" + "".join(f"{a},{b},{c},0,{c}\n" for a, b, c in zip(t, u, z, strict=True))
    )
    return d


# --- 1. no command writes onto a file it read, whatever the spelling --------------------------------------
def _campaign_files(lab):
    return sorted(p for p in (lab / "camp").iterdir() if p.suffix == ".csv") + [lab / "camp" / "index.json"]


@pytest.mark.parametrize("target", ["first_record", "index"])
@pytest.mark.parametrize("spelling", ["relative", "absolute", "dotted", "symlink", "hardlink"])
def test_map_never_writes_onto_the_files_it_reads_from_a_folder(lab, capsys, monkeypatch, target, spelling):
    # the probe: `map camp/ -o camp/plus_up_001_6.csv` replaced that record with the map's JSON
    monkeypatch.chdir(lab)
    victim = _campaign_files(lab)[0 if target == "first_record" else -1]
    rel = victim.relative_to(lab)
    out = {
        "relative": rel,
        "absolute": victim,
        "dotted": Path("camp/../camp") / rel.name,
        "symlink": lab / f"link_{target}",
        "hardlink": lab / f"hard_{target}",
    }[spelling]
    if spelling == "symlink" and not out.exists():
        out.symlink_to(victim)
    if spelling == "hardlink" and not out.exists():
        os.link(victim, out)
    msg = refused(lab, capsys, ["map", "camp", "-o", out])
    assert "would overwrite the input" in msg


@pytest.mark.parametrize("command", ["simulate", "identify", "frf", "characterise", "posterior", "discrepancy", "map"])
def test_no_command_writes_onto_its_record_through_a_link(lab, capsys, command):
    link = lab / f"alias_{command}.csv"
    if not link.exists():
        link.symlink_to(lab / "rec.csv")
    argv = {
        "simulate": ["simulate", lab / "model.json", lab / "rec.csv"],
        "identify": ["identify", "nsi", lab / "rec.csv"],
        "frf": ["frf", lab / "rec.csv"],
        "characterise": ["characterise", lab / "rec.csv", "--forcing-hz", "9"],
        "posterior": ["posterior", lab / "rec.csv"],
        "discrepancy": ["discrepancy", lab / "rec.csv"],
        "map": ["map", lab / "rec.csv", "--forcing-hz", "9"],
    }[command]
    assert "would overwrite the input" in refused(lab, capsys, [*argv, "-o", link])
    if command != "simulate":  # a result never replaces the folder-relative spelling of its own input either
        dotted = lab / ".." / lab.name / "rec.csv"
        assert "would overwrite the input" in refused(lab, capsys, [*argv, "-o", dotted])


def test_folder_outputs_never_replace_a_folder_holding_an_input_or_foreign_files(lab, capsys, tmp_path):
    # rig campaign and reproduce replace their folder as a whole: never one holding an input or a user's files
    refused(lab, capsys, ["rig", "campaign", "--model", lab / "model.json", "-o", lab])
    (tmp_path / "notes.txt").write_text("a user's file")
    refused(lab, capsys, ["rig", "campaign", "-o", tmp_path])
    refused(lab, capsys, ["reproduce", "-o", tmp_path])
    assert (tmp_path / "notes.txt").read_text() == "a user's file"


# --- 2. numbers that reached the numerics ------------------------------------------------------------------
HUGE_DATA = {
    "identify-nsi": ["identify", "nsi", "huge.csv"],
    "identify-sindy": ["identify", "sindy", "huge.csv"],
    "posterior": ["posterior", "huge.csv"],
    "discrepancy": ["discrepancy", "huge.csv"],
    "simulate": ["simulate", "model.json", "huge_input.csv"],
    "characterise": ["characterise", "huge.csv", "--forcing-hz", "9"],
    "frf": ["frf", "huge_input.csv"],
}


@pytest.mark.parametrize("case", list(HUGE_DATA))
def test_1e300_scale_data_is_refused_naming_the_column_and_unit(lab, capsys, case):
    argv = [lab / a if a.endswith((".csv", ".json")) else a for a in HUGE_DATA[case]]
    msg = refused(lab, capsys, [*argv, "-o", lab / "out.json"], [lab / "out.json"])
    assert "beyond any shaker-table record" in msg and ("m/s^2" in msg or " m " in msg)


@pytest.mark.parametrize("source", ["option-huge", "option-tiny", "metadata-huge", "metadata-tiny"])
def test_absurd_sampling_rates_are_refused(lab, capsys, source):
    argv = {
        "option-huge": ["identify", "nsi", lab / "rec.csv", "--fs", "1e300"],
        "option-tiny": ["identify", "nsi", lab / "rec.csv", "--fs", "1e-300"],
        "metadata-huge": ["identify", "nsi", lab / "fs_huge.csv"],
        "metadata-tiny": ["identify", "nsi", lab / "fs_tiny.csv"],
    }[source]
    refused(lab, capsys, [*argv, "-o", lab / "out.json"], [lab / "out.json"])


def test_a_constant_input_is_refused_by_the_posterior(lab, capsys):
    msg = refused(lab, capsys, ["posterior", lab / "still.csv", "-o", lab / "out.json"], [lab / "out.json"])
    assert "input base_acc is constant" in msg


@pytest.mark.parametrize(
    "targets",
    [
        {**TARGETS, "f_minus": {"a": 1}},
        {**TARGETS, "z_plus": [0.02]},
        {**TARGETS, "f_plus": "9.2"},
        {**TARGETS, "f_plus": True},
        {**TARGETS, "f_minus": 1e9},
        {**TARGETS, "z_plus": 1e6},
        [1, 2, 3],
        "targets",
    ],
    ids=["dict", "list", "string", "boolean", "absurd_frequency", "absurd_well", "a_list", "a_string"],
)
def test_update_targets_of_the_wrong_type_or_absurd_are_refused(lab, capsys, tmp_path, targets):
    f = tmp_path / "t.json"
    f.write_text(json.dumps(targets))
    refused(lab, capsys, ["update", f, "-o", tmp_path / "o.json"], [tmp_path / "o.json"])


@pytest.mark.parametrize("command", ["simulate", "nfrc", "rig", "update"])
def test_json_nested_200000_deep_is_refused(lab, capsys, tmp_path, command):
    deep = tmp_path / "deep.json"
    deep.write_text("[" * 200_000 + "]" * 200_000)
    out = tmp_path / "o.json"
    argv = {
        "simulate": ["simulate", deep, lab / "rec.csv", "-o", out],
        "nfrc": ["nfrc", deep, "--freq", "9", "--amplitude", "2:4", "-o", out],
        "rig": ["rig", "random", "--model", deep, "-o", tmp_path / "r.csv"],
        "update": ["update", deep, "-o", out],
    }[command]
    assert "nested" in refused(lab, capsys, argv, [out, tmp_path / "r.csv"])


@pytest.mark.parametrize(
    "argv",
    [
        ["rig", "random", "--duration", "1e5", "--fs", "1e6"],
        ["rig", "campaign", "--amplitudes", "1:1000:0.001", "--periods", "1000000"],
        ["rig", "campaign", "--freqs", "1:100:0.0001", "--periods", "1000000"],
    ],
    ids=["record", "campaign", "stepped_sine"],
)
def test_work_the_machine_cannot_hold_is_refused_before_allocating(lab, capsys, tmp_path, argv):
    t0 = time.process_time()
    msg = refused(lab, capsys, [*argv, "-o", tmp_path / "r"], [tmp_path / "r"])
    assert "of memory" in msg and "available" in msg
    assert time.process_time() - t0 < 60  # refused by arithmetic, not after allocating (terabytes otherwise)


# --- 3. outputs checked whole before the work --------------------------------------------------------------
COMMANDS = {
    "rig": ["rig", "random", "--duration", "2"],
    "simulate": ["simulate", "model.json", "rec.csv"],
    "identify": ["identify", "nsi", "rec.csv"],
    "frf": ["frf", "rec.csv"],
    "nfrc": ["nfrc", "model.json", "--freq", "9", "--amplitude", "2:4"],
    "posterior": ["posterior", "rec.csv"],
    "discrepancy": ["discrepancy", "rec.csv"],
    "characterise": ["characterise", "harm.csv", "--forcing-hz", "9"],
    "map": ["map", "camp"],
    "update": ["update", "targets.json"],
    "reproduce": ["reproduce", "--fast"],
}


def _argv(lab, command):
    return [lab / a if a.endswith((".csv", ".json")) or a == "camp" else a for a in COMMANDS[command]]


@pytest.mark.parametrize("command", list(COMMANDS))
def test_an_empty_output_path_is_refused_before_any_work(lab, capsys, command):
    assert "empty path" in refused(lab, capsys, [*_argv(lab, command), "-o", ""])


def test_a_legal_255_character_name_is_written_and_a_truth_name_too_long_is_refused(lab, capsys, tmp_path):
    # the temporary '.NAME.xxxx.part' of a 255-character name was too long: the work was lost at the end
    name = "f" * 250 + ".json"
    assert main(["frf", str(lab / "rec.csv"), "-o", str(tmp_path / name), "--quiet"]) == 0
    assert json.loads((tmp_path / name).read_text())["f_hz"] > 0
    assert (tmp_path / name).with_suffix(".png").stat().st_size > 0
    assert not list(tmp_path.glob(".*part"))
    # a rig record of a legal name whose truth file's name would not be: refused before the work
    msg = refused(lab, capsys, ["rig", "random", "--duration", "2", "-o", tmp_path / ("r" * 251 + ".csv")])
    assert "longer than the file system takes" in msg


def test_a_full_disk_leaves_nothing_behind(lab, tmp_path):
    # the file system refuses the figure (a 20 kB file size limit, as a full disk refuses): one line, exit 2,
    # neither the figure nor the result written (they land together or not at all)
    def limit():
        resource.setrlimit(resource.RLIMIT_FSIZE, (20_000, 20_000))

    out = tmp_path / "f.json"
    p = subprocess.run([sys.executable, "-m", "negstiff", "frf", str(lab / "rec.csv"), "-o", str(out), "--quiet"],
                       preexec_fn=limit, capture_output=True, text=True, timeout=300)  # fmt: skip
    assert p.returncode == 2, p.stderr
    assert p.stderr.count("\n") == 1 and "cannot write" in p.stderr and "Traceback" not in p.stderr
    assert list(tmp_path.iterdir()) == []


def test_a_truth_path_that_is_a_folder_is_refused_before_the_record_is_written(lab, capsys, tmp_path):
    (tmp_path / "r.truth.json").mkdir()
    msg = refused(lab, capsys, ["rig", "random", "--duration", "2", "-o", tmp_path / "r.csv"], [tmp_path / "r.csv"])
    assert "truth" in msg and "folder" in msg


@pytest.mark.parametrize("command", ["frf", "nfrc", "map"])
def test_a_result_never_overwrites_its_own_figure(lab, capsys, tmp_path, command):
    refused(lab, capsys, [*_argv(lab, command), "-o", tmp_path / "n.png"], [tmp_path / "n.png"])


def test_two_outputs_of_one_command_are_never_the_same_file(lab, capsys, tmp_path):
    p = tmp_path / "p.nc"
    assert "give them different paths" in refused(lab, capsys, ["posterior", lab / "rec.csv", "--idata", p, "-o", p])


def test_an_output_that_is_not_a_regular_file_is_refused(lab, capsys, tmp_path):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    assert "not a regular file" in refused(lab, capsys, ["frf", lab / "rec.csv", "-o", fifo])
    assert fifo.is_fifo()
    with pytest.raises(OutputError, match="not a regular file"):  # a character device: never replaced
        check_outputs({"--out": "/dev/null"})


def test_sigterm_during_a_campaign_leaves_nothing(lab, tmp_path):
    out = tmp_path / "camp"
    cmd = [sys.executable, "-m", "negstiff", "rig", "campaign", "--amplitudes", "4:30:0.5", "--start", "both",
           "--direction", "both", "-o", str(out), "--quiet"]  # fmt: skip
    p = subprocess.Popen(cmd, stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 120  # wait until its folder is being written, then kill it
    while time.time() < deadline and not list(tmp_path.glob(".camp*")) and p.poll() is None:
        time.sleep(0.05)
    p.send_signal(signal.SIGTERM)
    _, err = p.communicate(timeout=60)
    assert p.returncode == 143, err
    assert len(err.strip().splitlines()) == 1 and "terminated" in err
    assert list(tmp_path.iterdir()) == []


KILLED_WHILE_MADE = """
import os, signal, sys, tempfile
from pathlib import Path
from negstiff import files
maker = sys.argv[1]
seen = []
real = getattr(tempfile, maker)
def made_then_killed(*args, **kwargs):
    out = real(*args, **kwargs)
    os.kill(os.getpid(), signal.SIGTERM)
    return out
signal.signal(signal.SIGTERM, lambda signum, frame: seen.append(set(files._PENDING)))
setattr(tempfile, maker, made_then_killed)
making = files.atomic_dir if maker == "mkdtemp" else files.atomic_path
with making(Path(sys.argv[2]) / "out") as tmp:
    print("registered" if seen and tmp in seen[0] else f"not registered: {seen}")
"""
"""A process (its main thread: a command's, where signal handlers run) whose temporary output's maker is killed the
moment it has made it (``test_a_kill_the_moment_a_temporary_output_appears_finds_it_pending``)."""


@pytest.mark.parametrize("maker", ["mkdtemp", "mkstemp"])
def test_a_kill_the_moment_a_temporary_output_appears_finds_it_pending(tmp_path, maker):
    # the command's kill handler removes the outputs pending (``files.remove_pending``): a kill delivered the moment
    # a temporary output exists on disk, before it is registered as pending, left it behind (CI, once: the test
    # above, its kill sent when the campaign's folder appeared). Here the kill comes from inside the maker, just
    # after the temporary is made, in a process's main thread as the command's: its handler must already find it
    # pending
    p = subprocess.run([sys.executable, "-c", KILLED_WHILE_MADE, maker, str(tmp_path)], capture_output=True, text=True)
    assert p.returncode == 0 and p.stdout.strip() == "registered", (p.stdout, p.stderr)


# --- 4. bad data accepted ----------------------------------------------------------------------------------
def _truncated(lab, tmp_path, suffix, keep):
    rec = tmp_path / f"full{suffix}"
    assert main(["rig", "random", "--duration", "20", "-o", str(rec), "--quiet"]) == 0
    cut = tmp_path / f"cut{suffix}"
    cut.write_bytes(rec.read_bytes()[: int(keep * rec.stat().st_size)])
    return cut


@pytest.mark.parametrize("suffix", [".uff", ".tdms"])
def test_a_truncated_lab_file_is_refused_not_read_in_part(lab, capsys, tmp_path, suffix):
    # a truncated UFF lost its last channels and z was derived from another one (12 s of 20 s read)
    cut = _truncated(lab, tmp_path, suffix, 0.6)
    msg = refused(lab, capsys, ["frf", cut, "-o", tmp_path / "o.json"], [tmp_path / "o.json"])
    assert "incomplete" in msg  # and npTDMS's own log lines are not printed (one line in all)


def test_two_columns_of_one_name_are_refused(lab, capsys):
    assert "twice" in refused(lab, capsys, ["frf", lab / "twoz.csv", "-o", lab / "o.json"])
    msg = refused(lab, capsys, ["frf", lab / "rec.csv", "--columns", "z=z,z=y", "-o", lab / "o.json"])
    assert "twice" in msg


@pytest.mark.parametrize("record", ["dead.csv", "zero.csv"])
def test_a_dead_response_is_refused_by_characterise(lab, capsys, record):
    msg = refused(lab, capsys, ["characterise", lab / record, "--forcing-hz", "9", "-o", lab / "o.json"])
    assert "constant" in msg and "dead" in msg


def test_equal_wells_and_a_negative_friction_are_refused(lab, capsys, tmp_path):
    refused(lab, capsys, ["characterise", lab / "harm.csv", "--forcing-hz", "9", "--wells", "0.02,0.02",
                          "-o", tmp_path / "o.json"])  # fmt: skip
    msg = refused(lab, capsys, ["rig", "random", "--effect", "coulomb_friction=-0.1", "-o", tmp_path / "r.csv"])
    assert "dissipates" in msg


@pytest.mark.parametrize("record", ["still.csv", "huge_input.csv"])
def test_frf_refuses_a_dead_or_absurd_input_instead_of_reporting_no_peak(lab, capsys, record):
    refused(lab, capsys, ["frf", lab / record, "-o", lab / "o.json"], [lab / "o.json"])


def test_a_gigabyte_of_nul_bytes_after_a_valid_head_is_refused_without_reading_it(lab, capsys, tmp_path):
    import tracemalloc

    from negstiff import load
    from negstiff.errors import MeasurementError

    f = tmp_path / "nul.csv"
    with open(f, "wb") as fh:
        fh.write(b"t,base_acc,z\n0,1,0.02\n0.002,2,0.03\n")
        fh.truncate(2**30)  # a sparse gigabyte of NULs
    assert "NUL byte at byte 35" in refused(lab, capsys, ["frf", f, "-o", tmp_path / "o.json"])
    tracemalloc.start()
    try:
        with pytest.raises(MeasurementError, match="NUL byte"):
            load(f)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 64 * 2**20  # the first 16 MiB chunk was read (bytes 0-35 are the head), not the gigabyte


def test_a_file_too_large_for_the_memory_is_refused_before_it_is_read(lab, capsys, monkeypatch):
    import negstiff.resources

    monkeypatch.setattr(negstiff.resources, "available_memory", lambda: 2**20)  # a machine with 1 MiB free
    assert "of memory" in refused(lab, capsys, ["frf", lab / "rec.csv", "-o", lab / "o.json"])


# --- 5. one line: the library's checks come before any progress output ---------------------------------------
@pytest.mark.parametrize(
    "argv",
    [
        ["identify", "nsi", "short.csv"],
        ["identify", "sindy", "short.csv"],
        ["discrepancy", "short.csv"],
        ["posterior", "still.csv"],
        ["update", "single_well.json"],
        ["characterise", "dead.csv", "--forcing-hz", "9"],
        ["map", "dead.csv", "--forcing-hz", "9"],
        ["nfrc", "one_well_model.json", "--freq", "9", "--amplitude", "2:4", "--well", "minus"],
        ["nfrc", "model.json", "--freq", "1e300", "--amplitude", "2:4"],
    ],
    ids=lambda a: "-".join(a[:3]),
)
def test_refusals_come_before_the_progress_line(lab, capsys, argv):
    (lab / "one_well_model.json").write_text(json.dumps({"m": 0.2, "k1": -400.0, "k2": 0.0, "k3": 1e5, "c": 1.0}))
    (lab / "single_well.json").write_text(json.dumps({
        "modal": {"minus": {"f_hz": None, "zeta": None}, "plus": {"f_hz": 9.2, "zeta": 0.05}},
        "equilibria": {"z_minus": None, "z_0": None, "z_plus": 0.023}}))  # fmt: skip
    argv = [lab / a if a.endswith((".csv", ".json")) else a for a in argv]
    refused(lab, capsys, [*argv, "-o", lab / "o.json"], [lab / "o.json"])  # not --quiet: progress would show


# --- 6. a hypothesis search over every command's declared options --------------------------------------------
class _WorkStarts(Exception):
    """Raised by the first progress line: every check has passed."""


def _declared_options():
    """{(command, mode): [(option, action)]} from the parser itself."""
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command").choices
    return {
        name: [a for a in p._actions if a.option_strings and a.dest not in ("help", "quiet", "out", "idata")]
        for name, p in sub.items()
        if name not in ALIASES
    }  # fmt: skip (an alias is its command's parser)


OPTIONS = _declared_options()
TEXTS = {  # the options whose values are text: good ones and bad ones
    "columns": ["base_acc=base_acc,z=z", "z=nope", "base_acc", "base_acc=base_acc*1e300", "z=z,z=y"],
    "band": ["2:40", "40:2", "a:b", "0:1e300", "1e-300:2e-300"],
    "amplitudes": ["5,6", "30:4:1", "a,b", "1:1e9:1e-9", "nan,1"],
    "freqs": ["8,9", "0:1:0", "1e300", "9:8:0.1"],
    "wells": ["-0.029,0.023", "0.02,0.02", "1e300,1e301", "a"],
    "effect": [["coulomb_friction=0.1"], ["coulomb_friction=-1"], ["end_stop=k:1e300,z:0.03"], ["warp=1"]],
    "freq": ["9", "8:10", "0", "1e300", "inf"],
    "amplitude": ["3", "2:4", "-1", "1e300"],
    "nfrc": [["targets.json"]],
    "frf": [["targets.json"]],
    "start": ["model.json", "targets.json"],
    "model": ["model.json", "targets.json"],
    # a structure's options: the element's place, the masses, the DOFs the file must hold
    "element": ["1-2", "0-2", "2-1", "1-1", "0-3", "a-b", "12", "-1-2", "1.5-2", ""],
    "masses": ["1.0,0.2", "1,-1", "a,b", "1e300,1", "1", "1,2,3", "nan,1", "0,0.2", ""],
    # round four: the report's analyses (the command's alias among them), auxiliary channels, a start far out
    "only": ["characterize", "characterise", "nsi,frf", "frf", "bogus", "", "map"],
    "aux": ["volt", "dead", "volt,dead", "nosuch", "z", ""],
    "z0": ["0.023", "1e6", "-1e300", "nan", "x"],
}
BASES = {
    "rig": lambda lab, out, mode: ["rig", mode, "-o", out],
    "simulate": lambda lab, out, mode: ["simulate", lab / "model.json", lab / "rec.csv", "-o", out],
    "identify": lambda lab, out, mode: ["identify", mode, lab / "rec.csv", "-o", out],
    "frf": lambda lab, out, mode: ["frf", lab / "rec.csv", "-o", out],
    "nfrc": lambda lab, out, mode: ["nfrc", lab / "model.json", "-o", out],
    "posterior": lambda lab, out, mode: ["posterior", lab / "rec.csv", "-o", out],
    "discrepancy": lambda lab, out, mode: ["discrepancy", lab / "rec.csv", "-o", out],
    "characterise": lambda lab, out, mode: ["characterise", lab / "harm.csv", "-o", out],
    "map": lambda lab, out, mode: ["map", lab / "camp", "-o", out],
    "update": lambda lab, out, mode: ["update", lab / "targets.json", "-o", out],
    "reproduce": lambda lab, out, mode: ["reproduce", "-o", out],
    "report": lambda lab, out, mode: ["report", lab / "rec.csv", "-o", out],
    # the same commands on a structure's record (N read from the file; --dofs, --element, --masses drawn)
    "identify@2dof": lambda lab, out, mode: ["identify", mode, lab / "rec2.csv", "-o", out],
    "frf@2dof": lambda lab, out, mode: ["frf", lab / "rec2.csv", "-o", out],
    "posterior@2dof": lambda lab, out, mode: ["posterior", lab / "rec2.csv", "-o", out],
    "discrepancy@2dof": lambda lab, out, mode: ["discrepancy", lab / "rec2.csv", "-o", out],
    # round four: a structure simulated, and a record with auxiliary channels (its --aux drawn more often)
    "simulate@2dof": lambda lab, out, mode: ["simulate", lab / "structure.json", lab / "rec.csv", "-o", out],
    "identify@aux": lambda lab, out, mode: ["identify", mode, lab / "aux.csv", "-o", out],
    "discrepancy@aux": lambda lab, out, mode: ["discrepancy", lab / "aux.csv", "-o", out],
}
MODES = {"rig": ["random", "harmonic", "sweep", "campaign"], "identify": ["nsi", "sindy"],
         "identify@2dof": ["nsi", "sindy"], "identify@aux": ["nsi", "sindy"]}  # fmt: skip


def _values(action):
    """Values an option may be given: from its declared range (inside, on and beyond the bounds) or choices."""
    t = action.type
    if action.choices:
        return st.sampled_from(list(action.choices) + ["bogus"])
    if action.nargs == 0:
        return st.just(None)
    if hasattr(t, "kind"):
        lo, hi = t.lo, t.hi
        if t.kind is int:
            inside = st.integers(lo if lo is not None else -(10**6), hi if hi is not None else 10**6)
        else:  # uniform draws miss the small and the huge: draw the decade too
            top = hi if hi is not None else 1e300
            inside = st.one_of(
                st.floats(lo if lo is not None else -1e300, top, allow_nan=False),
                st.integers(-300, 300)
                .map(lambda e: 10.0**e)
                .filter(lambda v: (lo is None or v >= lo) and v <= top and not (t.lo_open and v == lo)),
            )
        edges = [v for v in (lo, hi) if v is not None]
        beyond = [v - 1 for v in edges] + [v + 1 for v in edges] + ["nan", "inf", "-inf", "1e308", "x"]
        return st.one_of(inside.map(str), st.sampled_from([str(v) for v in edges + beyond]))
    name = action.dest
    if name in TEXTS:
        return st.sampled_from(TEXTS[name])
    return st.sampled_from(["1", "x"])


@st.composite
def invocations(draw, lab, out):
    command = draw(st.sampled_from(sorted(BASES)))
    mode = draw(st.sampled_from(MODES.get(command, [None])))
    argv = BASES[command](lab, out, mode)
    if command == "characterise":
        argv += ["--forcing-hz", draw(st.sampled_from(["9", "300", "1e-9"]))]
    if command == "nfrc":
        argv += ["--freq", draw(st.sampled_from(TEXTS["freq"]))]
        argv += ["--amplitude", draw(st.sampled_from(TEXTS["amplitude"]))]
    actions = [a for a in OPTIONS[command.split("@")[0]] if a.dest not in ("forcing_hz",) or command == "map"]
    if command.endswith("@2dof"):  # the structure's options drawn more often than the rest
        actions += [a for a in actions if a.dest in ("dofs", "element", "masses", "z0")] * 3
    if command.endswith("@aux"):
        actions += [a for a in actions if a.dest == "aux"] * 3
    for action in draw(st.lists(st.sampled_from(actions), max_size=4, unique_by=lambda a: a.dest)):
        value = draw(_values(action))
        values = value if isinstance(value, list) else [value]
        for v in values:
            if v is None:
                argv.append(action.option_strings[-1])
            else:
                v = str(lab / v) if isinstance(v, str) and v.endswith(".json") else v
                argv.append(f"{action.option_strings[-1]}={v}")
    return [str(a) for a in argv]


@pytest.fixture
def no_work(monkeypatch):
    """The work of a command starts with its first progress line (or the report's run): stop there."""

    def start(*args, **kwargs):
        raise _WorkStarts

    monkeypatch.setattr(commands, "say", start)
    import negstiff.experiments.reproduce as reproduce

    monkeypatch.setattr(reproduce, "reproduce", start)


@settings(max_examples=250, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture],
          derandomize=True)  # fmt: skip
@given(data=st.data())
def test_no_option_value_of_any_command_gives_a_traceback(lab, capsys, no_work, data, tmp_path_factory):
    out = tmp_path_factory.mktemp("h") / "o.json"
    argv = data.draw(invocations(lab, out))
    try:
        rc = main(argv)
    except SystemExit as exc:
        rc = exc.code
    except _WorkStarts:
        rc = "started"
    event(f"{argv[0]}: {rc}")
    err = capsys.readouterr().err
    assert "Traceback" not in err
    if rc != "started":
        lines = [x for x in err.strip().splitlines() if x.strip()]
        assert rc == 2 and len(lines) == 1, f"{argv}: exit {rc}: {err}"
        assert not out.exists()
