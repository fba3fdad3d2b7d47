"""The command line of contract.md: exit codes, one-line errors, no partial outputs."""

import json

import numpy as np
import pytest

from negstiff.cli import main

MODEL = {"m": 0.2, "k1": 426.0, "k2": -3060.0, "k3": 7.77e5, "c": 3.5, "c_nl": 1.0}


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    d = tmp_path_factory.mktemp("cli")
    assert main(["rig", "random", "-o", str(d / "rec.csv"), "--duration", "10", "--seed", "1", "--quiet"]) == 0
    (d / "model.json").write_text(json.dumps(MODEL))
    return d


def test_rig_and_simulate_write_the_contract_files(workdir):
    out = workdir / "sim.csv"
    assert main(["simulate", str(workdir / "model.json"), str(workdir / "rec.csv"), "-o", str(out), "--quiet"]) == 0
    header = out.read_text().splitlines()[0]
    assert header == "t,base_acc,z,z_dot"
    data = np.loadtxt(out, delimiter=",", skiprows=1)
    assert data.shape == (5120, 4) and np.all(np.isfinite(data))
    assert (workdir / "rec.truth.json").exists()


def test_rig_writes_a_hammer_test_and_a_free_decay_a_lab_would_read(workdir, capsys):
    # the rig's hammer and release tests from the command line (they were the library's only): the hammer's record
    # is read as a hammer's (its hits found), the release's as a free decay; a structure's hammer names the DOF hit.
    # What the test cannot be is refused in one line before any work (no file, no progress line first)
    from negstiff import load
    from negstiff.inference.analysis.record_kind import record_kind
    from negstiff.models.device import SEED_LIKE_CUBIC
    from negstiff.models.structure import Structure

    hit, decay = workdir / "hit.csv", workdir / "decay.csv"
    assert main(["rig", "hammer", "--hits", "2", "--duration", "4", "-o", str(hit), "--quiet"]) == 0
    assert main(["rig", "release", "--z0", "0.03", "--duration", "4", "-o", str(decay), "--quiet"]) == 0
    assert record_kind(load(hit)).kind == "impact" and record_kind(load(decay)).kind == "decay"
    fixture = workdir / "fixture.json"
    s = Structure.on_fixture(SEED_LIKE_CUBIC, fixture_mass=1.0, fixture_hz=25.0, fixture_zeta=0.02)
    fixture.write_text(json.dumps(s.to_dict()))
    two = workdir / "hit2.csv"
    assert main(["rig", "hammer", "--model", str(fixture), "--dof", "1", "--duration", "3", "-o", str(two),
                 "--quiet"]) == 0  # fmt: skip
    rec = load(two)
    assert rec.n_dof == 2 and rec.force_dof == 1 and rec.input_name == "force"
    capsys.readouterr()
    for argv, says in ((["release"], "--z0"), (["hammer", "--sensor", "velocity"], "laser"),
                       (["release", "--z0", "0.03", "--sensor", "accelerometer"], "laser"),
                       (["hammer", "--model", str(fixture), "--dof", "3"], "DOF 1..2")):  # fmt: skip
        out = workdir / "refused.csv"
        assert main(["rig", *argv, "-o", str(out)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and says in err[0] and not out.exists(), err


def test_harmonic_and_campaign(workdir):
    assert (
        main(
            [
                "rig",
                "harmonic",
                "-o",
                str(workdir / "h.npz"),
                "--amplitude",
                "3",
                "--periods",
                "20",
                "--settle-periods",
                "20",
                "--quiet",
            ]
        )
        == 0
    )
    camp = workdir / "camp"
    assert (
        main(
            [
                "rig",
                "campaign",
                "-o",
                str(camp),
                "--amplitudes",
                "2,4",
                "--start",
                "both",
                "--direction",
                "both",
                "--periods",
                "8",
                "--settle-periods",
                "10",
                "--quiet",
            ]
        )
        == 0
    )
    index = json.loads((camp / "index.json").read_text())["records"]
    assert len(index) == 8 and all((camp / r["file"]).exists() for r in index)


def _bad(workdir, name, text):
    p = workdir / name
    p.write_text(text)
    return p


@pytest.mark.parametrize(
    "case",
    [
        "missing_column",
        "nan_row",
        "nonuniform_t",
        "nonincreasing_t",
        "too_few",
        "unknown_map_column",
        "unreadable",
        "bad_model",
        "unknown_effect",
        "no_file",
    ],
)
def test_bad_input_exits_2_with_one_line_and_no_output(workdir, capsys, case):
    model, rec = workdir / "model.json", workdir / "rec.csv"
    extra = []
    if case == "missing_column":
        rec = _bad(workdir, "b1.csv", "t,base_acc\n0,1\n0.1,2\n")
    elif case == "nan_row":
        rec = _bad(workdir, "b2.csv", "t,base_acc,z\n0,1,0.02\n0.1,nan,0.02\n0.2,1,0.02\n")
    elif case == "nonuniform_t":
        rows = "".join(f"{t:g},1,0.02\n" for t in (0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.8, 0.9, 1.0, 1.1))  # gap at row 7
        rec = _bad(workdir, "b3.csv", "t,base_acc,z\n" + rows)
    elif case == "nonincreasing_t":
        rec = _bad(workdir, "b4.csv", "t,base_acc,z\n0,1,0.02\n0.1,1,0.02\n0.1,1,0.02\n")
    elif case == "too_few":
        rec = _bad(workdir, "b5.csv", "# fs: 10\nbase_acc,z\n1,0.02\n")
    elif case == "unknown_map_column":
        extra = ["--columns", "base_acc=nope,z=z"]
    elif case == "unreadable":
        rec = workdir / "b7.csv"
        rec.write_bytes(b"\xff\xfe\x00garbage")
    elif case == "bad_model":
        model = _bad(workdir, "bad_model.json", '{"m": 0.2, "k1": 1')
    elif case == "no_file":
        rec = workdir / "does_not_exist.csv"
    out = workdir / f"out_{case}.csv"
    if case == "unknown_effect":
        args = ["rig", "random", "-o", str(out), "--duration", "2", "--effect", "warp_drive=1"]
    elif case == "missing_column":  # an input-only record simulates (below); it cannot be identified
        args = ["identify", "nsi", str(rec), "-o", str(out)]
    else:
        args = ["simulate", str(model), str(rec), "-o", str(out), *extra]
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "error" in err[0] and "Traceback" not in err[0]
    assert not out.exists()


def _check_report(out, sections):
    """The report folder holds index.md, index.html, results.json and real PNG figures (linked, not
    inlined into the markdown, inlined into the html), and every section asked for."""
    import re

    for f in ("index.md", "index.html", "results.json"):
        assert (out / f).stat().st_size > 0
    md = (out / "index.md").read_text()
    figs = re.findall(r"\]\(([^)]+\.png)\)", md)
    assert figs, "the report has figures"
    for f in figs:
        data = (out / f).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 1000
    assert md.count("data:image/png") == 0 and (out / "index.html").read_text().count("data:image/png") == len(figs)
    results = json.loads((out / "results.json").read_text())
    assert results["simulator"]["max_abs_dz_m"] < 1e-7
    for section in ("device", *sections):
        assert section in results, f"the report lacks its {section} section"
    assert "pending_sections" not in results
    return results


@pytest.mark.slow  # two minutes: the default suite runs the machinery on two sections (below)
def test_reproduce_fast_writes_a_complete_report(tmp_path, monkeypatch):
    from negstiff.experiments.reproduce import SECTIONS

    monkeypatch.setenv("NEGSTIFF_CACHE", str(tmp_path / "cache"))
    out = tmp_path / "paper"
    assert main(["reproduce", "--fast", "-o", str(out), "--quiet"]) == 0
    results = _check_report(out, SECTIONS)
    assert "sections_left_out" not in results
    # a second run replays every expensive section from the cache, with the same numbers
    out2 = tmp_path / "paper2"
    assert main(["reproduce", "--fast", "-o", str(out2), "--quiet"]) == 0
    again = json.loads((out2 / "results.json").read_text())
    for section in ("posterior", "sindy", "discrepancy"):
        assert json.dumps(again[section]) == json.dumps(results[section]), section


def test_reproduce_machinery_on_two_sections(tmp_path, monkeypatch, capsys):
    # The report's machinery (sections, figures, the html, results.json, the cache's replay with the
    # same numbers) on the NSI and SINDy sections (the two quickest in a fast run, 5 and 2 s, and the summary's
    # finding that needs both; the characterisation took 11 s); every section: the slow test above.
    from negstiff.experiments.reproduce import reproduce

    monkeypatch.setenv("NEGSTIFF_CACHE", str(tmp_path / "cache"))
    sections = ("nsi", "sindy")
    results = _check_report(reproduce(tmp_path / "a", fast=True, progress=False, sections=sections), sections)
    assert results["sections_left_out"] == [
        "updating",
        "characterisation",
        "posterior",
        "discrepancy",
        "silverbox",
        "continuation",
        "fixture",
    ]
    assert any((tmp_path / "cache").iterdir()), "the sections were cached"
    # the report's first screen: the summary (a finding of each section run, none of those left out), then the
    # table of contents; the conclusion closes it
    md = (tmp_path / "a" / "index.md").read_text()
    first = md[: md.index("## 1. ")]
    assert first.index("**Summary.**") < first.index("**Contents.**")
    assert "**Identification on the rig (known truth).** NSI and SINDy recover" in first
    assert "**Chaos.**" not in first and "**Silverbox" not in first
    assert "id='summary'" in (tmp_path / "a" / "index.html").read_text() and "Conclusion" in md
    # replayed from the cache, with a progress bar over the sections on stderr
    capsys.readouterr()
    again = json.loads(
        (reproduce(tmp_path / "b", fast=True, progress=True, sections=sections) / "results.json").read_text()
    )
    err = capsys.readouterr().err
    assert "reproduce: 100%" in err and "3/3" in err and "from the cache" in err
    for section in sections:
        assert json.dumps(again[section]) == json.dumps(results[section]), section
    with pytest.raises(ValueError, match="unknown sections"):
        reproduce(tmp_path / "c", fast=True, progress=False, sections=("nonsense",))


def test_reproduce_sizes_its_processes_to_the_machine(monkeypatch):
    # A many-core machine: no more section processes than sections, nor than memory holds at 2 GB each
    # (a section held up to 1.6 GB), and each process's own threads a share of the cores, not all of them
    import os

    from negstiff.experiments import reproduce as r

    monkeypatch.setattr(os, "cpu_count", lambda: 64)
    pages = {"SC_PAGE_SIZE": 4096, "SC_PHYS_PAGES": 64 * 1024**3 // 4096}
    monkeypatch.setattr(os, "sysconf", lambda name: pages[name])
    assert r.default_workers() == len(r._TABLE), "64 cores, 64 GB: one process per section"
    pages["SC_PHYS_PAGES"] = 8 * 1024**3 // 4096
    assert r.default_workers() == 4, "8 GB hold four processes"
    monkeypatch.delenv("NEGSTIFF_THREADS", raising=False)
    r._share_cores(16).restore_original_limits()  # this process's threads given back: it is no worker
    assert os.environ["NEGSTIFF_THREADS"] == "16"
    monkeypatch.setenv("NEGSTIFF_THREADS", "3")
    r._share_cores(16).restore_original_limits()
    assert os.environ["NEGSTIFF_THREADS"] == "3", "the user's setting stands"


def test_simulate_an_input_only_record_from_rest_at_z_plus(tmp_path):
    # contract: without a z column the model starts at rest at its z_plus
    from negstiff.models import Model

    rec = tmp_path / "in.csv"
    t = np.arange(512) / 512
    rec.write_text("t,base_acc\n" + "".join(f"{a:.6f},{0.0:.1f}\n" for a in t))
    out = tmp_path / "sim.csv"
    assert main(["simulate", str(tmp_path / "m.json"), str(rec), "-o", str(out), "--quiet"]) == 2  # no model yet
    (tmp_path / "m.json").write_text(json.dumps(MODEL))
    assert main(["simulate", str(tmp_path / "m.json"), str(rec), "-o", str(out), "--quiet"]) == 0
    z = np.loadtxt(out, delimiter=",", skiprows=1)[:, 2]
    z_plus = Model.from_dict(MODEL).equilibria().z_plus
    assert np.allclose(z, z_plus, atol=1e-9), "no input, at rest: it stays at z_plus"


def _rewrite_z(src, dst, f, column="z"):
    lines = src.read_text().splitlines()
    h = next(i for i, x in enumerate(lines) if x.startswith("t,"))
    j = lines[h].split(",").index(column)
    out = lines[: h + 1]
    for row in lines[h + 1 :]:
        p = row.split(",")
        p[j] = repr(f(float(p[j])))
        out.append(",".join(p))
    dst.write_text("\n".join(out) + "\n")
    return dst


def test_implausible_records_are_warned_about_loudly(workdir, tmp_path, capsys):
    # a laser zero 10 mm off the rods-horizontal position, a record in mm, a table acceleration in g:
    # identified (exit 0), with a warning in the result and on stderr even under --quiet
    src = tmp_path / "r.csv"
    assert main(["rig", "random", "-o", str(src), "--duration", "40", "--seed", "3", "--quiet"]) == 0
    cases = (
        ("shift", "z", lambda z: z + 0.01, "off the rods-horizontal"),
        ("mm", "z", lambda z: 1e3 * z, "in mm"),
        ("g", "base_acc", lambda a: a / 9.81, "is base_acc in g"),
    )
    for name, col, f, says in cases:
        path = _rewrite_z(src, tmp_path / f"{name}.csv", f, col)
        out = tmp_path / f"{name}.json"
        assert main(["identify", "nsi", str(path), "-o", str(out), "--quiet"]) == 0
        warnings = json.loads(out.read_text())["warnings"]
        assert any(says in w for w in warnings), warnings
        assert says in capsys.readouterr().err


def test_a_short_record_is_refused_with_the_length_it_needs(workdir, capsys):
    # 10 s is too short for SINDy's held-out selection: the message names the length needed, and that
    # length is more than the record has (it did not contradict itself)
    import re

    assert main(["identify", "sindy", str(workdir / "rec.csv"), "-o", str(workdir / "s.json"), "--quiet"]) == 2
    err = capsys.readouterr().err
    need = float(re.search(r"at least about ([0-9.]+) s", err).group(1))
    assert need > 10.0 and len(err.strip().splitlines()) == 1
