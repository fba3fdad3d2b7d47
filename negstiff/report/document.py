"""A report as a list of blocks (headings, text, tables, figures), rendered twice from the same
content: ``index.md`` (figures as PNG files beside it) and a self-contained ``index.html`` (figures
embedded), plus ``results.json``. The folder is written atomically.

Both open with the summary (``summary``) and a table of contents; every section (a level-2 heading) is
numbered and has an anchor. In the HTML a long paragraph (method detail) shows its first sentence and
folds the rest. A script builds a report from results with ``add`` (``negstiff.report.sections``:
one section per kind of result, the same the command ``negstiff report`` writes), ``add_text``,
``add_table``, ``add_figure`` and ``write``.
"""

from __future__ import annotations

import base64
import html
import json
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import matplotlib
import numpy as np

matplotlib.use("Agg")

from negstiff.errors import OutputError  # noqa: E402
from negstiff.files import atomic_dir, check_folder  # noqa: E402

from .numbers import fmt  # noqa: E402
from .sections import Blocks, Section, coefficient_blocks, coefficient_keys, section_for  # noqa: E402


@dataclass
class Report(Blocks):
    """A report (HTML and Markdown, with its results as JSON) built from results.

    Both renderings open with the summary and a table of contents; every section is numbered and has an
    anchor; long method detail is folded in the HTML.

    Parameters
    ----------
    title : str
        The report's title.
    blocks, figures, summary_lines : optional
        The content so far (built with ``add``, ``add_text``, ``add_table``, ``add_figure``, ``summary``).
    inputs : optional
        The files the report was built from (each record ``add`` takes that was read from a file): ``write``
        never replaces a folder holding one.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> from negstiff import Measurement, Report, Rig, SINDy
    >>> rec = Measurement.from_rig(Rig(seed=1).random(duration=30.0))
    >>> rep = Report("My device").add(rec).add(SINDy(seed=1).fit(rec), label="30 s")
    >>> out = rep.write(pathlib.Path(tempfile.mkdtemp()) / "report")
    >>> sorted(p.name for p in out.iterdir() if p.suffix != ".png")
    ['.negstiff-manifest.json', 'index.html', 'index.md', 'results.json']
    """

    title: str
    blocks: list[tuple[str, Any]] = field(default_factory=list)
    figures: dict[str, bytes] = field(default_factory=dict)
    summary_lines: list[str] = field(default_factory=list)
    inputs: list[Path] = field(default_factory=list)

    def summary(self, text: str) -> None:
        """A line of the summary the report opens with (what was found, in plain words)."""
        self.summary_lines.append(text)

    # --- building from results (a script's report, ``negstiff report``) ----------------------------
    def add(self, result, label: str = "") -> Report:
        """A section for ``result``: a record, a fitted ``NSI``/``SINDy``/``Posterior``/``Discrepancy``, an
        ``Identification``, an ``frf``/``characterise``/map result (``sections.section_for``). ``label``
        tells results of several records apart (a column of the coefficient table each). Returns the report.
        """
        sec = section_for(result, label)
        source = Path(str(getattr(result, "source", "") or "<memory>"))
        if source.is_file() and source not in self.inputs:
            self.inputs.append(source)
        self.figures.update(sec.figures)
        self.blocks.append(("section", sec))
        return self

    def add_failure(self, title: str, reason: str) -> Report:
        """A section that could not be made, in its place, with the reason."""
        sec = Section("failure", "", title)
        sec.warning(f"not made: {reason}")
        sec.summary.append(f"{title}: not made ({reason}).")
        self.blocks.append(("section", sec))
        return self

    def add_text(self, text: str, heading: str | None = None) -> Report:
        """A paragraph (under a new heading when given); returns the report, to chain."""
        if heading:
            self.heading(heading)
        self.text(text)
        return self

    def add_table(self, header: list[str], rows: list[list[Any]], heading: str | None = None) -> Report:
        """A table of ``header`` and ``rows`` (numbers at their significant figures); returns the report."""
        if heading:
            self.heading(heading)
        self.table(header, rows)
        return self

    def add_figure(self, fig, caption: str, name: str | None = None, heading: str | None = None) -> Report:
        """A matplotlib figure with its caption (PNG beside the Markdown, inline in the HTML); returns the report."""
        if heading:
            self.heading(heading)
        self.figure(name or f"figure_{len(self.figures) + 1}", fig, caption)
        return self

    def _composed(self) -> tuple[list[tuple[str, Any]], list[str]]:
        """The blocks as rendered and the summary: each section expanded in its place, and, where the report
        holds estimates, first the table of every coefficient (each method beside the posterior's
        interval, with a forest plot) and the held-out prediction errors against the noise floor.
        """
        secs = [b for k, b in self.blocks if k == "section"]
        summary = [line for s in secs for line in s.summary] + self.summary_lines
        head: list[tuple[str, Any]] = []
        estimates = {col: v for s in secs for col, v in s.estimates.items()}
        intervals = {f"{s.label or 'posterior'}": s.interval for s in secs if s.interval}
        if estimates or intervals:
            per_kg = any(s.kind == "record" and "mass" in s.json and s.json["mass"] is None and not s.json.get("masses")
                         for s in secs)  # fmt: skip
            element = any(s.kind == "record" and s.json.get("dofs", 1) > 1 for s in secs)  # a structure's
            blocks, figures, lines = coefficient_blocks(estimates, intervals, per_kg, element)
            self.figures.update(figures)
            head += blocks
            summary[1:1] = lines
        models = {col: m for s in secs for col, m in s.models.items()}
        band = next((s.band for s in secs if s.band), None)
        strokes = [s.stroke for s in secs if s.stroke]
        if band and models:
            summary[1:1] = [band_line(models, band)]
        if strokes and (band or any(m.extra for m in models.values())):  # a law beyond the cubic: its force drawn
            from .figures import force_figure

            stroke = (min(a for a, _ in strokes), max(b for _, b in strokes))
            fig = force_figure(models, stroke, "the restoring force over the stroke", band)
            Blocks.figure(self, "force_over_stroke", fig,
                          "Each method's restoring force K(z) over the stroke the record visited (wells marked)"
                          + (", in the posterior's credible band (shaded; its z in the record's pinned frame)"
                             if band else ""))  # fmt: skip
            head.append(self.blocks.pop())
        held = {k: v for s in secs for k, v in s.heldout.items()}
        if len(held) > 1:
            head += [("h", (2, "Held-out prediction")),
                     ("p", "Each model's free runs (restarted at measured states; each section says for how long) "
                           "over the part of the record not used to identify it, as a share of rms z, beside the "
                           "record's sensor-noise floor (a perfect model's error also carries the input's noise and "
                           "its start states')."),
                     ("table", (["model", "held-out error [% of rms z]"],
                                [[k, fmt(v, 3)] for k, v in held.items()]))]  # fmt: skip
        out: list[tuple[str, Any]] = list(head)
        for kind, b in self.blocks:
            if kind == "section":
                out.append(("h", (2, b.title)))
                out += b.blocks
            else:
                out.append((kind, b))
        return out, summary

    def results(self) -> dict[str, Any]:
        """Every section's results (the report's ``results.json``)."""
        secs = [b for k, b in self.blocks if k == "section"]
        out: dict[str, Any] = {"sections": [{"kind": s.kind, "label": s.label, "title": s.title, "result": s.json}
                                            for s in secs]}  # fmt: skip
        estimates = {col: v for s in secs for col, v in s.estimates.items()}
        intervals = {f"{s.label or 'posterior'}": s.interval for s in secs if s.interval}
        out["coefficients"] = {
            k: {**{col: est.get(k) for col, est in estimates.items()},
                **{("posterior" if lab == "posterior" else f"posterior ({lab})"): {
                    "mean": iv[k][0], "hdi_low": iv[k][1], "hdi_high": iv[k][2]}
                   for lab, iv in intervals.items() if k in iv}}
            for k in coefficient_keys(estimates, intervals)
        }  # fmt: skip
        out["heldout_percent"] = {k: v for s in secs for k, v in s.heldout.items()}
        out["summary"] = self._composed()[1]
        return out

    def heading(self, text: str, level: int = 2) -> None:
        """A heading of ``level`` (2: a section)."""
        self.blocks.append(("h", (level, text)))

    # --- rendering ---------------------------------------------------------------------------
    def _sections(self, blocks) -> list[tuple[int, str, str]]:
        """(block index, number, anchor) of every level-2 heading, numbered in order."""
        out, n = [], 0
        for i, (kind, b) in enumerate(blocks):
            if kind == "h" and b[0] == 2:
                n += 1
                out.append(
                    (i, str(n), f"s{n}-" + re.sub(r"[^a-z0-9]+", "-", _unnumbered(b[1]).lower()).strip("-")[:40])
                )
        return out

    def markdown(self) -> str:
        """The report as Markdown (figures as PNG files beside it)."""
        out = [f"# {self.title}", ""]
        blocks, summary = self._composed()
        sections = self._sections(blocks)
        numbers = {i: num for i, num, _ in sections}
        if summary:
            out += ["**Summary.**", ""] + [f"- {line}" for line in summary] + [""]
        if sections:
            out += ["**Contents.**", ""]
            out += [f"{num}. [{_unnumbered(blocks[i][1][1])}](#{anchor})" for i, num, anchor in sections] + [""]
        for i, (kind, b) in enumerate(blocks):
            if kind == "h":
                text = f"{numbers[i]}. {_unnumbered(b[1])}" if i in numbers else b[1]
                out += [f"{'#' * b[0]} {text}", ""]
            elif kind == "p":
                out += [b, ""]
            elif kind == "warn":
                out += [f"> **Warning:** {b}", ""]
            elif kind == "table":
                header, rows = b
                out += ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
                out += ["| " + " | ".join(r) + " |" for r in rows] + [""]
            elif kind == "fig":
                out += [f"![{b[1]}]({b[0]})", "", f"*{b[1]}*", ""]
        return "\n".join(out)

    def html(self) -> str:
        """The report as one self-contained HTML page (figures inline)."""

        def inline(s: str) -> str:
            s = html.escape(s)
            s = re.sub(r"\*\*(.+?)\*\*", r"<b>\1</b>", s)
            s = re.sub(r"`(.+?)`", r"<code>\1</code>", s)
            return re.sub(r"\*(.+?)\*", r"<i>\1</i>", s)

        parts = [
            f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{html.escape(self.title)}</title>",
            "<style>body{font-family:sans-serif;max-width:60em;margin:2em auto;line-height:1.45}"
            "table{border-collapse:collapse}td,th{border:1px solid #bbb;padding:2px 8px;text-align:right}"
            "th{background:#eee}img{max-width:100%}figcaption{font-style:italic;color:#444}"
            ".warn{background:#fee;border-left:4px solid #c00;padding:4px 8px}"
            ".summary{background:#eef5ff;border-left:4px solid #36c;padding:4px 12px}"
            "nav.toc{background:#f6f6f6;padding:4px 12px}nav.toc ol{margin:4px 0}"
            "details>summary{cursor:pointer}details>summary::marker{color:#36c}details[open]>summary{color:#444}"
            "</style></head><body>",
            f"<h1>{html.escape(self.title)}</h1>",
        ]
        blocks, summary = self._composed()
        sections = self._sections(blocks)
        numbers = {i: (num, anchor) for i, num, anchor in sections}
        if summary:
            items = "".join(f"<li>{inline(x)}</li>" for x in summary)
            head = "<section class='summary' id='summary'><h2 style='margin:6px 0'>Summary</h2>"
            parts.append(f"{head}<ul>{items}</ul></section>")
        if sections:
            parts.append("<nav class='toc' id='contents'><b>Contents</b><ol>" + "".join(
                f"<li><a href='#{anchor}'>{inline(_unnumbered(blocks[i][1][1]))}</a></li>"
                for i, num, anchor in sections) + "</ol></nav>")  # fmt: skip
        for i, (kind, b) in enumerate(blocks):
            if kind == "h":
                if i in numbers:
                    num, anchor = numbers[i]
                    parts.append(f"<h2 id='{anchor}'>{num}. {inline(_unnumbered(b[1]))}</h2>")
                else:
                    parts.append(f"<h{b[0]}>{inline(b[1])}</h{b[0]}>")
            elif kind == "p":
                parts.append(_folded(b, inline))
            elif kind == "warn":
                parts.append(f"<p class='warn'><b>Warning:</b> {inline(b)}</p>")
            elif kind == "table":
                header, rows = b
                parts.append("<table><tr>" + "".join(f"<th>{inline(h)}</th>" for h in header) + "</tr>")
                parts += ["<tr>" + "".join(f"<td>{inline(c)}</td>" for c in r) + "</tr>" for r in rows]
                parts.append("</table>")
            elif kind == "fig":
                data = base64.b64encode(self.figures[b[0]]).decode()
                parts.append(
                    f"<figure><img alt='{html.escape(b[1])}' src='data:image/png;base64,{data}'>"
                    f"<figcaption>{inline(b[1])}</figcaption></figure>"
                )
        parts.append("</body></html>")
        return "\n".join(parts)

    def write(self, folder: str | Path, results: dict[str, Any] | None = None) -> Path:
        """Write index.md, index.html, results.json (``results``, else the sections' own: ``results()``) and
        the PNGs into ``folder`` atomically, with the manifest of what was written (``negstiff.files.MANIFEST``).

        ``folder`` is replaced as a whole, so it must be new, empty, or hold only what negstiff wrote there
        (``negstiff.files.check_folder``): a folder holding another file (a user's, the record the report
        was built from) or a path that is a file is refused with an ``OutputError``, before anything is
        written, and left as it was.
        """
        check_folder(folder, "report folder", self.inputs)
        self._composed()  # the figures the composition draws (the forest plot)
        if results is None:
            results = self.results()
        with atomic_dir(folder) as tmp:
            for name, data in self.figures.items():
                (tmp / name).write_bytes(data)
            (tmp / "index.md").write_text(self.markdown())
            (tmp / "index.html").write_text(self.html())
            (tmp / "results.json").write_text(json.dumps(results, indent=2, default=_json_default) + "\n")
        return Path(folder)


FOLD_CHARS = 600
"""A paragraph longer than this is method detail in the HTML report: its first sentence shows, the rest
is folded (``<details>``); index.md keeps every paragraph whole."""


def _folded(text: str, inline) -> str:
    """A paragraph as HTML: whole when short, else its first sentence with the rest folded."""
    m = re.match(r"(.{40,}?[.;:])\s+(?=[A-Z(])", text) if len(text) > FOLD_CHARS else None
    if m is None:
        return f"<p>{inline(text)}</p>"
    rest = text[m.end() :]
    return (
        f"<details><summary>{inline(m.group(1))} <i>(more: {len(rest.split())} words)</i></summary>"
        f"<p>{inline(rest)}</p></details>"
    )


def _unnumbered(text: str) -> str:
    """A heading without a number it was written with ("4. NSI" -> "NSI"): the renderer numbers."""
    return re.sub(r"^\d+(\.\d+)*\.?\s+", "", text)


def _json_default(o: Any) -> Any:
    import numpy as np

    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def run_study(section, title: str, default_out: str, doc: str | None, argv=None) -> int:
    """Command-line entry of a standalone study: ``section(rep, results, fast, seed)`` into a report folder."""
    import argparse
    import sys

    ap = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("-o", "--out", default=default_out)
    ap.add_argument("--fast", action="store_true", help="a quick reduced run")
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args(argv)
    try:
        check_folder(a.out, "--out")  # before the study: a folder holding a user's file is refused
    except OutputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    rep = Report(title)
    results: dict[str, Any] = {}
    section(rep, results, a.fast, a.seed)
    rep.write(a.out, results)
    print(f"wrote {a.out}", file=sys.stderr)
    return 0


def band_line(models: dict[str, Any], band: dict[str, Any]) -> str:
    """The summary's line on each method's restoring force against the posterior's band: the share of the band's
    displacements (evenly over the stroke) where the method's K(z) lies inside it. A law's force is what its
    estimates say together (a spline's coefficients mean other functions on other knots: ``compared_by_force``).
    """
    z = np.asarray(band["z_m"], float)
    lo, hi = np.asarray(band["low_n"], float), np.asarray(band["high_n"], float)
    parts = []
    for col, model in models.items():
        with np.errstate(all="ignore"):
            k = np.asarray(model.restoring_force(z), float)
        parts.append(f"{col} over {100 * float(np.mean((k >= lo) & (k <= hi))):.0f} %")
    return (
        f"The restoring force inside the posterior's {100 * band['prob']:g} % band (share of the stroke): "
        + "; ".join(parts)
        + "."
    )
