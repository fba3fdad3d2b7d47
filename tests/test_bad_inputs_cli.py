"""The third bad-input probe (issue "Nothing lost, round three"), kept as tests: Ctrl-C from the first
millisecond, lab formats checked against their own headers, the wrong acceptances, the refusals made
before the work, and the library's errors that are negstiff's. Each case is refused cleanly (exit 2, one
line on stderr, no traceback, nothing written, every input byte-identical; in Python one ``InputError``)
or, where the input is legal, read to a sound result."""

import hashlib
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from negstiff.cli import main

ROOT = Path(__file__).resolve().parents[1]


def _snapshot(d: Path) -> dict:
    return {str(p.relative_to(d)): hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(d.rglob("*"))
            if p.is_file() and not p.is_symlink()}  # fmt: skip


def refused(folder: Path, capsys, argv, outputs=()) -> str:
    """Exit 2, one line naming an error, no traceback, no output written, every file of ``folder``
    unchanged."""
    before = _snapshot(folder)
    try:
        rc = main([str(a) for a in argv])
    except SystemExit as exc:  # argparse's errors
        rc = exc.code
    err = capsys.readouterr().err
    lines = [x for x in err.strip().splitlines() if x.strip()]
    assert rc == 2, f"exit {rc} for {argv}: {err}"
    assert len(lines) == 1 and "error" in lines[0] and "Traceback" not in err, err
    for o in outputs:
        assert not os.path.exists(o), f"{o} was written"
    assert _snapshot(folder) == before, "an input was modified"
    return lines[0]


# --- Ctrl-C: one line and exit 130 from the first millisecond ----------------------------------------------
def _mapped(pid: int, name: str) -> bool:
    """Whether process ``pid`` has loaded a shared object whose path holds ``name`` (Linux's /proc)."""
    try:
        return name in Path(f"/proc/{pid}/maps").read_text()
    except OSError:
        return False


def _commands():
    yield [sys.executable, "-m", "negstiff"]
    script = shutil.which("negstiff", path=os.path.dirname(sys.executable))
    if script:  # the console entry (negstiff.cli:run), as installed
        yield [script]


@pytest.mark.skipif(not Path("/proc/self/maps").exists(), reason="needs Linux's /proc to see the imports")
@pytest.mark.parametrize("command", list(_commands()), ids=lambda c: "console" if len(c) == 1 else "module")
def test_ctrl_c_during_the_imports_is_one_line_and_exit_130(command, tmp_path):
    # the probe: Ctrl-C while numpy imports (the first second of every command) printed a traceback of
    # 10-29 lines. numpy's compiled core appearing in the process's memory map is the moment the heavy
    # imports are under way; the interrupt then must end the command with one line and exit 130
    out = tmp_path / "r.json"
    p = subprocess.Popen([*command, "frf", str(tmp_path / "rec.csv"), "-o", str(out)], stderr=subprocess.PIPE,
                         stdout=subprocess.DEVNULL, text=True, cwd=tmp_path)  # fmt: skip
    deadline = time.monotonic() + 60
    while not _mapped(p.pid, "_multiarray_umath") and p.poll() is None and time.monotonic() < deadline:
        time.sleep(0.0005)
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=60)
    assert p.returncode == 130, err
    assert len(err.strip().splitlines()) == 1 and "interrupted" in err and "Traceback" not in err, err
    assert not out.exists()


def _descendants(pid: int) -> list[int]:
    """The processes below ``pid`` (its children's children too), from /proc."""
    kids = []
    for task in Path(f"/proc/{pid}/task").glob("*"):
        try:
            kids += [int(k) for k in (task / "children").read_text().split()]
        except OSError:
            pass
    return kids + [g for k in kids for g in _descendants(k)]


def _running_in_group(pgid: int) -> list[int]:
    """The processes of process group ``pgid`` that are alive (not zombies waiting to be reaped)."""
    alive = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[2]) == pgid and fields[0] not in "ZX":
            alive.append(int(stat.parent.name))
    return alive


@pytest.mark.skipif(not Path("/proc/self/task").exists(), reason="needs Linux's /proc to see the workers")
def test_ctrl_c_on_reproduce_is_one_line_and_the_workers_go_quietly(tmp_path):
    # the probe: Ctrl-C on reproduce printed the parent's one line, then each spawned worker's
    # KeyboardInterrupt traceback and the resource tracker's "5 leaked semaphore objects" (76-130 lines).
    # A terminal's Ctrl-C reaches the whole process group: it is sent so here, a second after the
    # section processes started (while they import and begin their sections)
    out = tmp_path / "report"
    env = dict(os.environ, NEGSTIFF_CACHE="off")
    p = subprocess.Popen([sys.executable, "-m", "negstiff", "reproduce", "--fast", "--quiet", "-o", str(out)],
                         stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True, cwd=tmp_path, env=env,
                         start_new_session=True)  # fmt: skip
    deadline = time.monotonic() + 120
    while len(_descendants(p.pid)) < 3 and p.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)  # the resource tracker and two section processes
    assert p.poll() is None, p.communicate()[1]
    time.sleep(1.5)
    os.killpg(p.pid, signal.SIGINT)
    _, err = p.communicate(timeout=90)  # stderr closes once every process holding it (workers, tracker) ended
    assert p.returncode == 130, err
    assert len(err.strip().splitlines()) == 1 and "interrupted" in err, err
    assert "Traceback" not in err and "leaked" not in err, err
    assert not out.exists()
    time.sleep(0.5)
    assert not _running_in_group(p.pid), "a process of the command is still running"


# --- lab formats checked against their own header -----------------------------------------------------------
FS = 512.0
"""Samples per second of the lab-format records: 20 s is 10,240 samples (UFF headers say 10240)."""


def _oscillator(n: int = 10_240, seed: int = 3):
    """(base_acc, z) of a linear oscillator (9 Hz, 3 % damping) under white base acceleration (1 m/s^2 rms),
    integrated with scipy, with a displacement sensor's noise floor (1e-7 m) and a 2 mm offset."""
    from scipy import signal as sps

    rng = np.random.default_rng(seed)
    t = np.arange(n) / FS
    a = rng.standard_normal(n)
    wn, zeta = 2 * np.pi * 9.0, 0.03
    _, z, _ = sps.lsim(([-1.0], [1.0, 2 * zeta * wn, wn**2]), a, t)
    return a, z + 2e-3 + 1e-7 * rng.standard_normal(n)


def _uff58(name: str, data, unit: str):
    """An ASCII type-58 time response as pyuff prepares it."""
    import pyuff

    x = np.arange(np.size(data)) / FS
    zero = {f"{a}_{b}": 0 for a in ("orddenom", "z_axis") for b in ("spec_data_type", "len_unit_exp",
                                                                       "force_unit_exp", "temp_unit_exp")}  # fmt: skip
    return pyuff.prepare_58(
        binary=0, id1=name, func_type=1, rsp_node=1, rsp_dir=3, ref_node=0, ref_dir=0,
        data=np.asarray(data, float), x=x, ord_data_type=4, num_pts=x.size, abscissa_spacing=1, abscissa_min=0.0,
        abscissa_inc=1 / FS, abscissa_spec_data_type=17, abscissa_len_unit_exp=0, abscissa_force_unit_exp=0,
        abscissa_temp_unit_exp=0, abscissa_axis_units_lab="s", ordinate_spec_data_type=0, ordinate_len_unit_exp=0,
        ordinate_force_unit_exp=0, ordinate_temp_unit_exp=0, ordinate_axis_units_lab=unit, orddenom_axis_units_lab="",
        z_axis_axis_units_lab="", z_axis_value=0.0, **zero,
    )  # fmt: skip


def _write_uff(path: Path, channels: list[tuple[str, np.ndarray, str]]) -> Path:
    import pyuff

    u = pyuff.UFF(str(path))
    for i, (name, data, unit) in enumerate(channels):
        u.write_sets(_uff58(name, data, unit), mode="overwrite" if i == 0 else "add")
    return path


def _lvm_header() -> list[str]:
    return ["LabVIEW Measurement\t", "Writer_Version\t2", "Reader_Version\t2", "Separator\tTab",
            "Decimal_Separator\t.", "Multi_Headings\tNo", "X_Columns\tOne", "Time_Pref\tRelative",
            "Operator\tlab", "Date\t2026/11/22", "Time\t10:00:00", "***End_of_Header***\t", ""]  # fmt: skip


def _lvm_segment(names: list[str], data: np.ndarray, t0: float, units: list[str]) -> list[str]:
    """One segment as LabVIEW's Write To Measurement File writes it: its channel header, then its rows
    (tab separated, one X column, 9 significant digits)."""
    n, dt = len(names), 1 / FS
    head = [
        "Channels\t" + "\t".join([str(n)] * n),
        "Samples\t" + "\t".join([str(len(data))] * n),
        "Date\t" + "\t".join(["2026/11/22"] * n),
        "Time\t" + "\t".join(["10:00:00"] * n),
        "Y_Unit_Label\t" + "\t".join(units),
        "X_Dimension\t" + "\t".join(["Time"] * n),
        "X0\t" + "\t".join([f"{t0:.16E}"] * n),
        "Delta_X\t" + "\t".join([f"{dt:.16E}"] * n),
        "***End_of_Header***\t",
        "X_Value\t" + "\t".join(names) + "\tComment",
    ]
    return head + [f"{t0 + i * dt:.6f}\t" + "\t".join(f"{v:.9E}" for v in row) for i, row in enumerate(data)] + [""]


@pytest.fixture(scope="module")
def lab_files(tmp_path_factory) -> Path:
    """A lab's files of one record (20 s at 512 Hz), each written as its front end writes it, and each with
    one of the probe's oddities."""
    d = tmp_path_factory.mktemp("lab_formats")
    a, z = _oscillator()
    good = _write_uff(d / "good.uff", [("base_acc", a, "m/s^2"), ("z", z, "m")])
    lines = good.read_text().splitlines(keepends=True)
    mid = len(lines) // 2  # the boundary of the two datasets: both lose lines, the reader splices them
    (d / "lost_lines.uff").write_text("".join(lines[: mid - 250] + lines[mid + 250 :]))
    lost_in_z = lines[: 3 * len(lines) // 4] + lines[3 * len(lines) // 4 + 500 :]
    (d / "lost_in_z.uff").write_text("".join(lost_in_z))  # 500 lines (2,000 samples) lost inside z
    text = good.read_text()
    for points in (20_000, 5_000):  # the header's point count (record 7) over 10,240 values written
        (d / f"says_{points}.uff").write_text(text.replace("     10240         1", f"{points:10d}         1"))
    _write_uff(d / "two_z.uff", [("base_acc", a, "m/s^2"), ("z", z, "m"), ("z", 0.5 * z, "m")])
    half = a.size // 2
    data = np.column_stack([a, z])
    (d / "two_segments.lvm").write_text("\n".join(
        _lvm_header() + _lvm_segment(["base_acc", "z"], data[:half], 0.0, ["m/s^2", "m"])
        + _lvm_segment(["base_acc", "z"], data[half:], half / FS, ["m/s^2", "m"])))  # fmt: skip
    (d / "two_z.lvm").write_text("\n".join(_lvm_header() + _lvm_segment(
        ["base_acc", "z", "z"], np.column_stack([a, z, 0.5 * z]), 0.0, ["m/s^2", "m", "m"])))  # fmt: skip
    rows = [f"{x:.9g},{y:.9g}" for x, y in zip(a, z, strict=True)]
    rows[len(rows) // 2] = "# the DAQ's buffer overran here"  # a sample replaced by a comment line
    (d / "comment_in_data.csv").write_text(f"# fs: {FS:g}\nbase_acc,z\n" + "\n".join(rows) + "\n")
    np.savez(d / "truth.npz", base_acc=a, z=z)
    return d


@pytest.mark.parametrize(
    "name, says",
    [
        ("lost_lines.uff", "point"),  # 500 lines lost across the datasets' boundary: one spliced record
        ("lost_in_z.uff", "point"),  # 500 lines lost inside z: 2,000 samples short
        ("says_20000.uff", "20000"),
        ("says_5000.uff", "5000"),
        ("two_z.uff", "'z'"),  # two datasets named z: the second was ignored
        ("two_z.lvm", "'z'"),  # two channels named z: the later was used
        ("comment_in_data.csv", "comment"),  # with # fs: and no t, a dropped sample is undetectable afterwards
    ],
)
def test_lab_files_that_contradict_their_own_header_are_refused(lab_files, capsys, tmp_path, name, says):
    out = tmp_path / "frf.json"
    msg = refused(lab_files, capsys, ["frf", lab_files / name, "-o", out, "--quiet"], [out])
    assert name in msg and says in msg, msg


def test_a_two_segment_lvm_is_read_whole(lab_files):
    # LabVIEW's multi-segment files (a header per segment, the same channels, time going on) are one record:
    # every segment is read, in order, to the 9 significant digits LabVIEW printed
    from negstiff.inference.record.measurement import load

    truth = np.load(lab_files / "truth.npz")
    rec = load(lab_files / "two_segments.lvm", mass=0.2)
    assert rec.n == truth["z"].size and rec.fs == pytest.approx(FS, rel=1e-9)
    assert np.allclose(rec.u, truth["base_acc"], rtol=1e-8, atol=1e-8 * np.abs(truth["base_acc"]).max())
    assert np.allclose(rec.z, truth["z"], rtol=1e-8, atol=1e-8 * np.abs(truth["z"]).max())
