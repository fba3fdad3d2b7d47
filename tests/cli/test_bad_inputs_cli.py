"""The third bad-input probe (issue "Nothing lost, round three"), kept as tests: Ctrl-C from the first
millisecond, lab formats checked against their own headers, the wrong acceptances, the refusals made
before the work, and the library's errors that are negstiff's. Each case is refused cleanly (exit 2, one
line on stderr, no traceback, nothing written, every input byte-identical; in Python one ``InputError``)
or, where the input is legal, read to a sound result."""

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from processes import descendants
from records import refused

ROOT = Path(__file__).resolve().parents[2]


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
def _reproduce_with_its_processes(tmp_path):
    """``negstiff reproduce`` started in a session of its own, returned (process, its output folder) 1.5 s after
    its section processes started (while they import and begin their sections)."""
    out = tmp_path / "report"
    env = dict(os.environ, NEGSTIFF_CACHE="off")
    p = subprocess.Popen([sys.executable, "-m", "negstiff", "reproduce", "--fast", "--quiet", "-o", str(out)],
                         stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True, cwd=tmp_path, env=env,
                         start_new_session=True)  # fmt: skip
    deadline = time.monotonic() + 120
    while len(descendants(p.pid)) < 3 and p.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)  # the resource tracker and two section processes
    assert p.poll() is None, p.communicate()[1]
    time.sleep(1.5)
    return p, out


def test_ctrl_c_on_reproduce_is_one_line_and_the_workers_go_quietly(tmp_path):
    # the probe: Ctrl-C on reproduce printed the parent's one line, then each spawned worker's
    # KeyboardInterrupt traceback and the resource tracker's "5 leaked semaphore objects" (76-130 lines).
    # A terminal's Ctrl-C reaches the whole process group: it is sent so here, a second after the
    # section processes started (while they import and begin their sections)
    p, out = _reproduce_with_its_processes(tmp_path)
    os.killpg(p.pid, signal.SIGINT)
    _, err = p.communicate(timeout=90)  # stderr closes once every process holding it (workers, tracker) ended
    assert p.returncode == 130, err
    assert len(err.strip().splitlines()) == 1 and "interrupted" in err, err
    assert "Traceback" not in err and "leaked" not in err, err
    assert not out.exists()
    time.sleep(0.5)
    assert not _running_in_group(p.pid), "a process of the command is still running"


def test_sigterm_on_reproduce_ends_its_section_processes_too(tmp_path):
    # a kill of the command alone (SIGTERM to its process, as a scheduler or `kill PID` sends it, not to its group)
    # ended the parent with its one line and left the two section processes running, orphaned, for minutes
    p, out = _reproduce_with_its_processes(tmp_path)
    p.send_signal(signal.SIGTERM)
    _, err = p.communicate(timeout=90)
    assert p.returncode == 143, err
    assert len(err.strip().splitlines()) == 1 and "terminated" in err, err
    assert not out.exists()
    deadline = time.monotonic() + 10  # the resource tracker leaves once its last client is gone
    while _running_in_group(p.pid) and time.monotonic() < deadline:
        time.sleep(0.1)
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
    from negstiff.inference.record.reading import load

    truth = np.load(lab_files / "truth.npz")
    rec = load(lab_files / "two_segments.lvm", mass=0.2)
    assert rec.n == truth["z"].size and rec.fs == pytest.approx(FS, rel=1e-9)
    assert np.allclose(rec.u, truth["base_acc"], rtol=1e-8, atol=1e-8 * np.abs(truth["base_acc"]).max())
    assert np.allclose(rec.z, truth["z"], rtol=1e-8, atol=1e-8 * np.abs(truth["z"]).max())


# --- wrong acceptances ---------------------------------------------------------------------------------------
def _write_csv(path: Path, cols: dict, meta: dict | None = None, time_fmt: str = "%.9g") -> Path:
    """A CSV as a lab's export writes it: 9 significant digits, the time column in ``time_fmt``."""
    head = "".join(f"# {k}: {v}\n" for k, v in (meta or {}).items()) + ",".join(cols) + "\n"
    fmts = [time_fmt if k == "t" else "%.9g" for k in cols]
    rows = np.column_stack(list(cols.values()))
    path.write_text(head + "".join(",".join(f % x for f, x in zip(fmts, r, strict=True)) + "\n" for r in rows))
    return path


@pytest.fixture(scope="module")
def records(tmp_path_factory) -> Path:
    """The probe's records, each 20 s at 512 Hz of the 9 Hz oscillator (scipy), or a part of it."""
    d = tmp_path_factory.mktemp("acceptances")
    a, z = _oscillator()
    t = np.arange(a.size) / FS
    _write_csv(d / "rec.csv", {"t": t, "base_acc": a, "z": z})
    # a DAQ that stamps Unix time: 1.7e9 s, printed to the microsecond (the step, 1.953 ms, is resolved)
    _write_csv(d / "epoch.csv", {"t": 1.7e9 + t, "base_acc": a, "z": z}, time_fmt="%.6f")
    np.savez(d / "epoch.npz", t=1.7e9 + t, base_acc=a, z=z)
    rng = np.random.default_rng(5)
    _write_csv(d / "aux_huge.csv", {"t": t, "base_acc": a, "z": z, "volt": 1e300 * rng.standard_normal(a.size)})
    # a 9 Hz harmonic record (3 m/s^2), its steady state
    wn, zeta = 2 * np.pi * 9.0, 0.03
    u = 3.0 * np.sin(2 * np.pi * 9.0 * t)
    from scipy import signal as sps

    _, zh, _ = sps.lsim(([-1.0], [1.0, 2 * zeta * wn, wn**2]), u, t)
    _write_csv(d / "harm.csv", {"t": t, "base_acc": u, "z": zh + 2e-3 + 1e-7 * rng.standard_normal(t.size)})
    _write_csv(d / "ten_rows.csv", {"t": t[:10], "base_acc": a[:10], "z": z[:10]})
    (d / "friction.json").write_text(
        '{"m": 0.2, "k1": 426.0, "k2": -3060.0, "k3": 7.77e5, "c": 3.5, "extra": {"coulomb_friction": -0.5}}'
    )
    return d


@pytest.mark.parametrize("name", ["epoch.csv", "epoch.npz"])
def test_a_unix_epoch_time_column_is_read_by_its_spacing(records, name):
    # only the spacing of t matters: at 1.7e9 s float64 resolves 2.4e-7 s, a ten-thousandth of the 1.953 ms
    # step; the record is the one stamped from zero (its rate exactly, its start kept)
    from negstiff.inference.record.reading import load

    rec, ref = load(records / name), load(records / "rec.csv")
    assert rec.n == ref.n and rec.fs == pytest.approx(FS, rel=1e-9)
    assert rec.t0 == pytest.approx(1.7e9, abs=1e-3)
    assert np.allclose(rec.z, ref.z, rtol=1e-8, atol=0)  # the CSV's 9 significant digits


def test_a_time_column_float64_cannot_step_is_refused(tmp_path, capsys):
    # at 1e17 s float64's spacing is 16 s: a 512 Hz step cannot be told apart there
    t = 1e17 + np.arange(2048) * 16.0
    np.savez(tmp_path / "far.npz", t=t, base_acc=np.sin(t - t[0]), z=1e-3 * np.cos(t - t[0]))
    msg = refused(tmp_path, capsys, ["frf", tmp_path / "far.npz", "-o", tmp_path / "o.json"], [tmp_path / "o.json"])
    assert "column t" in msg


def test_an_aux_channel_beyond_any_instrument_is_refused(records, capsys, tmp_path):
    # the probe: a 1e300 aux channel was taken (the fit then selected no damping, held-out 134 %)
    out = tmp_path / "s.json"
    msg = refused(records, capsys, ["identify", "nsi", records / "aux_huge.csv", "--aux", "volt", "-o", out], [out])
    assert "volt" in msg


def test_a_forcing_frequency_at_two_samples_a_period_is_refused(records, capsys, tmp_path):
    # 255 Hz sampled at 512 Hz is 2 samples a period: inside any anti-aliasing filter's roll-off, no
    # Poincare section can be read there (the record's forcing is 9 Hz)
    out = tmp_path / "c.json"
    msg = refused(records, capsys, ["characterise", records / "harm.csv", "--forcing-hz", "255", "-o", out], [out])
    assert "255" in msg


def test_a_model_with_negative_friction_is_refused(records, capsys, tmp_path):
    # a negative Coulomb friction feeds energy in: no physical device has it
    out = tmp_path / "s.csv"
    msg = refused(records, capsys, ["simulate", records / "friction.json", records / "rec.csv", "-o", out], [out])
    assert "coulomb_friction" in msg


STRUCTURE = {"masses": [1.0, 0.2], "element": {"m": 0.2, "k1": 426.0, "k2": 1000.0, "k3": 6.7e5, "c": 3.5, "c_nl": 0.5},
             "at": [1, 2], "stiffness": [[24674.0, 0.0], [0.0, 0.0]], "damping": [[3.1, 0.0], [0.0, 0.0]]}  # fmt: skip


@pytest.mark.parametrize("change, says", [
    ({"at": [0.5, 2]}, "two DOF numbers"),   # was read as (0, 2)
    ({"at": "12"}, "two DOF numbers"),       # was read as (1, 2)
    ({"masses": [True, 0.2]}, "m1 must be a number"),  # was 1 kg
    ({"masses": [1.0] * 100_000, "stiffness": None, "damping": None}, "at most 1000 DOFs"),  # 74.5 GiB, traceback
])  # fmt: skip
def test_a_structure_file_that_does_not_say_a_structure_is_refused(records, capsys, tmp_path, change, says):
    # a structure's JSON is read as written: an element's place is two DOF numbers, a mass a number, and a
    # structure of 100,000 DOFs is refused before its dense matrices are allocated; one line, nothing written
    import json

    system = tmp_path / "structure.json"
    system.write_text(json.dumps({k: v for k, v in {**STRUCTURE, **change}.items() if v is not None}))
    out = tmp_path / "s.csv"
    assert says in refused(tmp_path, capsys, ["simulate", system, records / "rec.csv", "-o", out], [out])


@pytest.mark.parametrize("extra", [["--forcing-hz", "512"], ["--nfrc", "nope.json"]])
def test_report_says_when_an_option_is_refused_by_every_analysis(records, capsys, tmp_path, extra):
    out = tmp_path / "rep"
    msg = refused(
        records,
        capsys,
        ["report", records / "rec.csv", *(["--only", "frf"] if extra[0] == "--nfrc" else []), *extra, "-o", out],
        [out],
    )
    assert extra[0] in msg


def test_report_with_every_section_not_made_exits_2(records, capsys, tmp_path):
    # ten rows: no analysis can be made from them; a report of nothing but "not made" is not a result
    out = tmp_path / "rep"
    refused(records, capsys, ["report", records / "ten_rows.csv", "--quiet", "-o", out], [out])


def test_posterior_with_an_input_noise_beyond_any_record_is_one_line(records, capsys, tmp_path):
    out = tmp_path / "p.json"
    refused(records, capsys, ["posterior", records / "rec.csv", "--input-noise", "1e300", "-o", out], [out])


# --- refusals before the work --------------------------------------------------------------------------------
def test_rig_refuses_an_unwritable_suffix_before_simulating(tmp_path, capsys):
    out = tmp_path / "r.lvm"
    start = time.perf_counter()
    msg = refused(tmp_path, capsys, ["rig", "random", "--duration", "600", "-o", out], [out])
    assert ".lvm" in msg and time.perf_counter() - start < 5, "refused after the simulation"


@pytest.mark.parametrize(
    "argv",
    [
        ["frf", "ten_rows.csv"],
        # SINDy and the discrepancy workflow score candidates in two 2 s blocks of the weak-form rows of 20 % of
        # the record; 20 s holds fewer (the test function's width eats into them): estimator.check_length
        ["identify", "sindy", "rec.csv"],
        ["discrepancy", "rec.csv"],
    ],
    ids=["frf-10-rows", "sindy-20s", "discrepancy-20s"],
)
def test_too_short_is_refused_before_the_progress_line(records, capsys, tmp_path, argv):
    # the refusal is the only line: the check needs no work, so it comes before "identify: N samples ..."
    argv = [records / a if a.endswith(".csv") else a for a in argv]
    out = tmp_path / "o.json"
    msg = refused(records, capsys, [*argv, "-o", out], [out])
    assert "short" in msg or "few" in msg, msg


def test_simulate_divergence_is_refused_before_the_progress_line(records, capsys, tmp_path):
    # a model whose cubic stiffness is negative escapes to infinity under any input: one line, no progress
    (tmp_path / "escape.json").write_text('{"m": 0.2, "k1": 426.0, "k2": 0.0, "k3": -7.77e5, "c": 3.5}')
    out = tmp_path / "s.csv"
    msg = refused(tmp_path, capsys, ["simulate", tmp_path / "escape.json", records / "rec.csv", "-o", out], [out])
    assert "simulat" in msg


# --- the library's errors are negstiff's ---------------------------------------------------------------------
def _u_z(n: int = 2048):
    t = np.arange(n) / FS
    return np.sin(2 * np.pi * 9 * t), 1e-3 * np.sin(2 * np.pi * 9 * t - 0.3)


@pytest.mark.parametrize(
    "call",
    [
        lambda u, z: __import__("negstiff").from_arrays(None, z, FS),
        lambda u, z: __import__("negstiff").from_arrays(u, z, FS, aux="v"),
        lambda u, z: __import__("negstiff").from_arrays(u + 1j * u, z, FS),
        lambda u, z: __import__("negstiff").from_arrays(u, z + 1j * z, FS),
        lambda u, z: __import__("negstiff").Model(m=-0.2, k1=426.0, k2=0.0, k3=7.77e5),
        lambda u, z: __import__("negstiff").Model(m=0.2, k1=426.0, k2=0.0, k3="big"),
        lambda u, z: __import__("negstiff").Model(m=0.2, k1=426.0, k2=0.0, k3=7.77e5, extra={"coulomb_friction": "x"}),
        lambda u, z: __import__("negstiff").Structure(("a", 0.2), (426.0,)),
        lambda u, z: __import__("negstiff").simulate(
            __import__("negstiff").Model(m=0.2, k1=426.0, k2=0.0, k3=7.77e5), np.r_[u[:-1], np.nan], 1 / FS
        ),
        lambda u, z: __import__("negstiff").Rig(seed=-1),
        lambda u, z: __import__("negstiff").Rig(seed=1.5),
    ],
    ids=[
        "u-None",
        "aux-string",
        "u-complex",
        "z-complex",
        "negative-mass",
        "k3-text",
        "effect-text",
        "structure-text-mass",
        "simulate-nan-input",
        "rig-negative-seed",
        "rig-float-seed",
    ],  # fmt: skip
)
def test_library_refusals_are_one_input_error(call):
    # a program gets one negstiff InputError with one line (never a KeyError, numpy's ValueError or a
    # ComplexWarning that drops the imaginary part)
    import warnings

    from negstiff.errors import InputError

    u, z = _u_z()
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a warning instead of the refusal fails the test
        with pytest.raises(InputError) as info:
            call(u, z)
    assert "\n" not in str(info.value).strip(), str(info.value)


# --- the hypothesis search over the library's constructors --------------------------------------------------
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

CARELESS = st.one_of(
    st.none(),
    st.booleans(),
    st.text(max_size=4),
    st.sampled_from([0, -1, 1, 0.2, -0.2, 1e300, -1e300, float("nan"), float("inf"), 1 + 2j, 2**70]),
    st.floats(allow_nan=True, allow_infinity=True),
    st.lists(st.floats(-1e3, 1e3), max_size=3),
    st.dictionaries(st.text(max_size=3), st.floats(-1, 1), max_size=2),
)
"""What a careless or unlucky caller passes for one number: nothing, text, a flag, a non-finite or huge value,
a complex one, a list, a mapping."""

LIBRARY_SETTINGS = settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _clean_or_input_error(call) -> None:
    """``call()`` returns, or raises one negstiff InputError with a one-line message; no other exception
    and no warning (a ComplexWarning, an overflow)."""
    import warnings

    from negstiff.errors import InputError

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        try:
            call()
        except InputError as exc:
            assert str(exc).strip() and "\n" not in str(exc).strip(), repr(exc)


@LIBRARY_SETTINGS
@given(name=st.sampled_from(["m", "k1", "k2", "k3", "c", "c_nl", "k0", "extra"]), value=CARELESS)
def test_model_takes_any_value_or_says_which_is_wrong(name, value):
    from negstiff import Model

    kw = {"m": 0.2, "k1": 426.0, "k2": -3060.0, "k3": 7.77e5, "c": 3.5, "c_nl": 0.0}
    _clean_or_input_error(lambda: Model(**{**kw, name: value}))


@LIBRARY_SETTINGS
@given(name=st.sampled_from(["seed", "fs", "oversample", "weigh_resolution", "effects"]), value=CARELESS)
def test_rig_takes_any_setting_or_says_which_is_wrong(name, value):
    from negstiff import Rig

    _clean_or_input_error(lambda: Rig(**{name: value}))


@LIBRARY_SETTINGS
@given(
    which=st.sampled_from(["u", "z", "fs", "input_name", "mass", "aux", "z_dot", "gravity"]),
    value=st.one_of(CARELESS, st.builds(lambda n: np.ones(n), st.integers(0, 5))),
)
def test_from_arrays_takes_any_argument_or_says_which_is_wrong(which, value):
    from negstiff import from_arrays

    u, z = _u_z(1024)
    kw = {"u": u, "z": z, "fs": FS, "mass": 0.2}
    kw[which] = value
    _clean_or_input_error(lambda: from_arrays(**kw))


# round four: the estimators' constructors (an odd NSI order was taken), each checked against a record
def _estimator_params():
    from negstiff import NSI, Discrepancy, GAUpdater, Posterior, SINDy

    return [
        (cls, name)
        for cls in (NSI, SINDy, Discrepancy, Posterior, GAUpdater)
        for name in cls._param_names()
        if name not in ("start", "chain_file")
    ]  # fmt: skip (a file is not a number: the CLI's search draws those)


@LIBRARY_SETTINGS
@given(which=st.sampled_from(_estimator_params()), value=st.one_of(CARELESS, st.integers(-3, 25)))
def test_an_estimator_takes_any_setting_or_says_which_is_wrong(which, value):
    cls, name = which
    u, z = _u_z(4096)
    # two tones, not one: a harmonic record's periodic orbit is refused by the record's check whatever the setting
    t = np.arange(u.size) / FS
    u, z = u + np.sin(2 * np.pi * 13.7 * t), z + 1e-3 * np.sin(2 * np.pi * 13.7 * t - 0.5)
    data = {"f_minus": 11.4, "f_plus": 9.2, "z_minus": -0.029, "z_plus": 0.023} if cls.__name__ == "GAUpdater" else \
        __import__("negstiff").from_arrays(u, z, FS, mass=0.2)  # fmt: skip
    _clean_or_input_error(lambda: cls(**{name: value}).check(data))
