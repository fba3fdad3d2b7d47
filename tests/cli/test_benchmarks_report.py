"""The benchmark's report keeps what it measured: each section is written into the Markdown as soon as it is
measured, in place of its own blocks, every other section's text kept and in its place (a rerun of one section,
``--only``, or a later section's failure, loses nothing); its figures go to the JSON beside it."""

import json

import pytest

from benchmarks import benchmarks as bench


def _report(tmp_path):
    path = tmp_path / "benchmarks.md"
    lines = ["# negstiff benchmarks", "", "Machine: old.", "", "## Simulator (issue 2)", "", "sim old", "",
             "## Waits (issue 18)", "", "waits old", "", "## Peers: equation discovery", "", "peers old"]  # fmt: skip
    path.write_text("\n".join(lines))
    return path


def test_one_section_rerun_replaces_its_block_and_keeps_the_others_in_place(tmp_path):
    path = _report(tmp_path)
    bench.write_section(str(path), "waits", ["", "## Waits (issue 18)", "", "waits new"], quick=False)
    text = path.read_text()
    assert "waits new" in text and "waits old" not in text
    assert text.index("sim old") < text.index("waits new") < text.index("peers old")
    assert "section `waits`" in text and text.startswith("# negstiff benchmarks")


def test_a_new_section_goes_where_the_order_puts_it(tmp_path):
    path = _report(tmp_path)
    # NSI comes after the waits and before the peers in the report, whatever order the sections are measured in
    bench.write_section(str(path), "nsi", ["", "## NSI (issue 4)", "", "nsi new"], quick=True)
    text = path.read_text()
    assert text.index("waits old") < text.index("nsi new") < text.index("peers old")
    assert "(--quick)" in text


def test_figures_are_kept_per_section_in_the_json_beside(tmp_path):
    out = str(tmp_path / "benchmarks.md")
    bench.write_figures(out, "simulator", {"single": {"numba_s": 0.0129}}, quick=False)
    bench.write_figures(out, "nsi", {"t": 2.5}, quick=False)
    data = json.loads((tmp_path / "benchmarks.json").read_text())
    assert data["simulator"]["figures"]["single"]["numba_s"] == pytest.approx(0.0129)
    assert set(data) == {"simulator", "nsi"}


def test_an_unknown_section_is_one_line_and_exit_2(capsys):
    with pytest.raises(SystemExit) as exc:
        bench.main(["--only", "simulatr", "-o", "/nonexistent/b.md"])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert "unknown section simulatr" in err[-1]
