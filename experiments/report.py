"""A report as a list of blocks (headings, text, tables, figures), rendered twice from the same
content: ``index.md`` (figures as PNG files beside it) and a self-contained ``index.html`` (figures
embedded), plus ``results.json``. The folder is written atomically."""

from __future__ import annotations

import base64
import html
import json
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from negstiff.files import atomic_dir  # noqa: E402


def fmt(x: Any, digits: int = 4) -> str:
    """A number as a person reads it (``digits`` significant figures), or the value as text."""
    if isinstance(x, bool) or x is None:
        return str(x)
    if isinstance(x, (int, float)):
        if not math.isfinite(x):
            return str(x)
        if x != 0 and (abs(x) >= 1e5 or abs(x) < 1e-3):
            return f"{x:.{digits - 1}e}"
        return f"{x:.{digits}g}"
    return str(x)


@dataclass
class Report:
    """Blocks of a report and the figures they reference."""

    title: str
    blocks: list[tuple[str, Any]] = field(default_factory=list)
    figures: dict[str, bytes] = field(default_factory=dict)

    def heading(self, text: str, level: int = 2) -> None:
        self.blocks.append(("h", (level, text)))

    def text(self, text: str) -> None:
        self.blocks.append(("p", text))

    def warning(self, text: str) -> None:
        self.blocks.append(("warn", text))

    def table(self, header: list[str], rows: list[list[Any]]) -> None:
        self.blocks.append(("table", (header, [[fmt(c) for c in r] for r in rows])))

    def figure(self, name: str, fig, caption: str) -> None:
        """Add a matplotlib figure as ``name``.png with a caption (the figure is closed)."""
        import io

        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
        plt.close(fig)
        self.figures[f"{name}.png"] = buf.getvalue()
        self.blocks.append(("fig", (f"{name}.png", caption)))

    # --- rendering ---------------------------------------------------------------------------
    def markdown(self) -> str:
        out = [f"# {self.title}", ""]
        for kind, b in self.blocks:
            if kind == "h":
                out += [f"{'#' * b[0]} {b[1]}", ""]
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
            ".warn{background:#fee;border-left:4px solid #c00;padding:4px 8px}</style></head><body>",
            f"<h1>{html.escape(self.title)}</h1>",
        ]
        for kind, b in self.blocks:
            if kind == "h":
                parts.append(f"<h{b[0]}>{inline(b[1])}</h{b[0]}>")
            elif kind == "p":
                parts.append(f"<p>{inline(b)}</p>")
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

    def write(self, folder: str | Path, results: dict[str, Any]) -> Path:
        """Write index.md, index.html, results.json and the PNGs into ``folder`` atomically."""
        with atomic_dir(folder) as tmp:
            for name, data in self.figures.items():
                (tmp / name).write_bytes(data)
            (tmp / "index.md").write_text(self.markdown())
            (tmp / "index.html").write_text(self.html())
            (tmp / "results.json").write_text(json.dumps(results, indent=2, default=_json_default) + "\n")
        return Path(folder)


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
    rep = Report(title)
    results: dict[str, Any] = {}
    section(rep, results, a.fast, a.seed)
    rep.write(a.out, results)
    print(f"wrote {a.out}", file=sys.stderr)
    return 0
