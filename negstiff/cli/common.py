"""What every command shares: input errors, argument types, reading a system file, writing a result
JSON, the lines on stderr, and the check that no output overwrites an input.
"""

from __future__ import annotations

import argparse
import importlib
import inspect
import json
import math
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from negstiff.errors import InputError  # noqa: E402 (the one bad-input error, library and CLI)


class Parser(argparse.ArgumentParser):
    """argparse with the contract's error form: one line naming the option, exit 2 (no usage dump)."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {' '.join(message.split())} (see {self.prog} --help)\n")


def _estimator(estimator: str):
    """The estimator class ``"nsi.NSI"`` names (``negstiff.inference.estimators.nsi.NSI``), imported: only the
    command that uses it builds its options (``build_parser(only=...)``), and it imports the estimator to
    run anyway (1.1 s of imports, the compiled simulator's among them; ``negstiff --help`` pays none).
    """
    module, cls = estimator.rsplit(".", 1)
    return getattr(importlib.import_module(f"negstiff.inference.{module}"), cls)


def declared(estimator: str, parameter: str, what: str = ""):
    """The argparse type of an option that sets an estimator's parameter: the parameter's declared
    constraint (``_parameter_constraints``, ``"nsi.NSI"``: ``negstiff.inference.estimators.nsi.NSI``), so the command
    line checks the range the library checks, from one declaration.
    """
    c = _estimator(estimator)._parameter_constraints[parameter]
    unit = f" {c.unit}" if getattr(c, "unit", "") else ""
    return number(c.kind, c.lo, c.hi, lo_open=c.lo_open, hi_open=c.hi_open, what=what or unit,
                  even=getattr(c, "even", False))  # fmt: skip


def default(estimator: str, parameter: str) -> Any:
    """The default of an estimator's parameter, from its ``__init__`` signature (``"nsi.NSI"``:
    ``negstiff.inference.estimators.nsi.NSI``), so the CLI states the estimator's own default.
    """
    return inspect.signature(_estimator(estimator)).parameters[parameter].default


def number(kind, lo=None, hi=None, lo_open=False, what="", hi_open=False, even=False):
    """An argparse type: a number of ``kind`` in [lo, hi] (open at lo with ``lo_open``, at hi with ``hi_open``;
    an even integer with ``even``).
    """

    def parse(text: str):
        try:
            v = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not {'an integer' if kind is int else 'a number'}") from None
        if kind is float and not np.isfinite(v):
            raise argparse.ArgumentTypeError(f"{text!r} is not a finite number")
        if lo is not None and (v < lo or (lo_open and v == lo)):
            raise argparse.ArgumentTypeError(f"{text} is out of range: must be {'>' if lo_open else '>='} {lo:g}{what}")
        if hi is not None and (v > hi or (hi_open and v == hi)):
            raise argparse.ArgumentTypeError(f"{text} is out of range: must be {'<' if hi_open else '<='} {hi:g}{what}")
        if even and v % 2:
            raise argparse.ArgumentTypeError(f"{text} is odd: must be even{what}")
        return v

    parse.__name__ = kind.__name__
    parse.kind, parse.lo, parse.hi, parse.lo_open, parse.hi_open = kind, lo, hi, lo_open, hi_open  # for tests
    parse.even = even
    return parse


POSITIVE = number(float, 0.0, lo_open=True)


POSITIVE_INT = number(int, 1)


def mass_option():
    """A moving mass [kg] in the range a record may state (``measurement.MASS_RANGE_KG``)."""
    from negstiff.io.schema import MASS_RANGE_KG

    return number(float, *MASS_RANGE_KG, what=" kg")


def acceleration_option(lo_open: bool = True):
    """A table acceleration [m/s^2] up to the magnitude of any shaker-table record (``units.MAGNITUDE_LIMITS``)."""
    from negstiff.io.schema import MAGNITUDE_LIMITS

    return number(float, 0.0, MAGNITUDE_LIMITS["acceleration"], lo_open=lo_open, what=" m/s^2")


SEED = number(int, 0, 2**32 - 1)


def bad_input_types() -> tuple[type[BaseException], ...]:
    """The domain's errors (bad input: one line, exit 2). A plain ValueError from inside is a bug and
    keeps its traceback; where a user's value reaches a validating constructor, the command turns its
    ValueError into an InputError at that call. Every domain error is an ``InputError``
    (``negstiff.errors``).
    """
    return (InputError, FileNotFoundError, json.JSONDecodeError)


def wants_progress(args) -> bool:
    return not getattr(args, "quiet", False)


def parse_effects(items: Sequence[str] | None) -> dict[str, Any]:
    """``NAME=VALUE`` (a stop: ``NAME=k:2e4,z:0.035``) into an extra-effects mapping."""
    out: dict[str, Any] = {}
    for item in items or []:
        if "=" not in item:
            raise InputError(f"--effect {item!r}: expected NAME=VALUE (e.g. coulomb_friction=0.05)")
        name, value = item.split("=", 1)
        try:
            if ":" in value:
                out[name] = {k: float(v) for k, v in (kv.split(":", 1) for kv in value.split(","))}
            else:
                out[name] = float(value)
        except ValueError:
            raise InputError(f"--effect {item!r}: the value is not a number (or k:N/m,z:m for a stop)") from None
    return out


MAX_AMPLITUDE_STEPS = 1_000_000
"""Values a stepped range may unfold to before anything is allocated (beyond, the memory check of the run they
step refuses what the machine cannot hold; 1:1e9:1e-9 is 1e18 values)."""


def parse_amplitudes(text: str, option: str = "--amplitudes") -> list[float]:
    """``4:30:0.5`` (start:stop:step, stop included) or ``5,10,15`` (the values of ``option``)."""
    try:
        if ":" in text:
            a, b, s = (float(x) for x in text.split(":"))
            if not all(np.isfinite((a, b, s))) or s <= 0 or b < a:
                raise ValueError
        else:
            return [float(x) for x in text.split(",")]
    except ValueError:
        raise InputError(f"{option} {text!r}: use start:stop:step (e.g. 4:30:0.5) or a list 5,10,15") from None
    steps = math.floor((b - a) / s + 0.5) + 1
    if steps > MAX_AMPLITUDE_STEPS:  # counted before numpy allocates them (1:1e9:1e-9: 1e18 steps)
        raise InputError(f"{option} {text!r}: {steps:.3g} values; at most {MAX_AMPLITUDE_STEPS} in one run")
    return list(np.round(np.arange(a, b + s / 2, s), 10))


def write_json(path: str | Path, data: dict) -> None:
    """Write a result JSON atomically (NaN and inf become null: JSON has no such numbers)."""
    from negstiff.files import write_text

    write_text(path, json.dumps(_finite(data), indent=2) + "\n")


def _finite(o):
    if isinstance(o, dict):
        return {k: _finite(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_finite(v) for v in o]
    if isinstance(o, (float, np.floating)):
        return float(o) if np.isfinite(o) else None
    if isinstance(o, np.integer):
        return int(o)
    if isinstance(o, np.ndarray):
        return _finite(o.tolist())
    return o


def say(args, text: str) -> None:
    if wants_progress(args):
        print(text, file=sys.stderr)


def warn(args, warnings: Sequence[str]) -> None:
    """Warnings are loud: on stderr even with --quiet (and in the result)."""
    for w in warnings:
        print(f"negstiff {args.command}: WARNING: {w}", file=sys.stderr)


def say_refinement(args, info: dict | None) -> None:
    """One line on the output-error refinement: held-out free-run error before and after, kept or not."""
    if not info:
        return
    h = info.get("heldout")
    if h is None:
        say(args, f"refinement: {info['reason']}")
        return
    # a single DOF's restarted windows beside its one long run; a structure's validation is its restarted windows
    a, b = (e["restarted_rms_percent"] if e.get("restarted_rms_percent") is not None else e.get("rms_percent")
            for e in (h["initial"], h["refined"]))  # fmt: skip
    fmt = lambda x: "diverged" if x is None or not np.isfinite(x) else f"{x:.3g} %"  # noqa: E731
    say(args, f"refinement by simulation error ({info['seconds']:.1f} s): held-out restarted free runs "
               f"{fmt(a)} -> {fmt(b)} rms, {info['reason'].split(':')[0]}")  # fmt: skip


FIGURE_COMMANDS = ("frf", "nfrc", "map", "design")
"""Commands that write a figure beside their result (the result's path with .png)."""


def io_paths(args) -> tuple[list[Path], dict[str, str | Path], dict[str, str]]:
    """What a command reads and writes: (every input file, {label: output}, {label: marker} of the
    outputs that are folders). A folder input counts as the files read from it (``map``).
    """
    inputs: list[Path] = []
    for name in ("model", "input", "targets", "start", "frf", "nfrc", "posterior"):
        v = getattr(args, name, None)
        inputs += [Path(x) for x in (v if isinstance(v, list) else [v] if v else [])]
    data = getattr(args, "data", None)
    if args.command == "map" or (args.command == "report" and data and (len(data) > 1 or Path(data[0]).is_dir())):
        from negstiff.inference.analysis.campaign import campaign_files

        inputs += campaign_files(data)
    elif args.command == "report" and data:
        inputs.append(Path(data[0]))
    elif data:
        inputs += [Path(x) for x in (data if isinstance(data, list) else [data])]  # posterior: one or several
    outputs: dict[str, str | Path] = {}
    folders: dict[str, str] = {}
    out = getattr(args, "out", None)
    if out is None:
        return inputs, outputs, folders
    if not str(out).strip():  # Path('') is '.': the empty path is refused as the user gave it
        return inputs, {"--out": out}, folders
    if args.command in ("reproduce", "report") or (args.command == "rig" and args.mode == "campaign"):
        outputs["--out"] = Path(out)
        folders["--out"] = "index.json" if args.command == "rig" else "results.json"
    elif args.command == "rig":
        rec = out_path(args)
        outputs["--out"] = rec
        outputs["its truth file"] = rec.with_name(rec.stem + ".truth.json")
    else:
        outputs["--out"] = out
        if args.command in FIGURE_COMMANDS:
            if Path(out).suffix.lower() == ".png":
                raise InputError(f"--out {out}: the figure is written beside the result as {Path(out).name}; "
                                 "give the result another name (R.json)")  # fmt: skip
            outputs["its figure"] = Path(out).with_suffix(".png")
    if getattr(args, "idata", None) is not None:
        outputs["--idata"] = args.idata
    if getattr(args, "chain_file", None) is not None:  # written as the run goes (resumed: continued)
        outputs["--chain-file"] = args.chain_file
    return inputs, outputs, folders


def check_paths(args) -> None:
    """Before any work: every output can be written, and none is an input or another output
    (``negstiff.files.check_outputs``).
    """
    from negstiff.files import check_outputs

    inputs, outputs, folders = io_paths(args)
    check_outputs(outputs, inputs, folders)


def parse_span(text: str, option: str) -> float | tuple[float, float]:
    """``X`` (a positive number) or ``X1:X2`` (a range, X2 > X1 >= 0)."""
    try:
        if ":" in text:
            lo, hi = (float(x) for x in text.split(":"))
            if not (np.isfinite(lo) and np.isfinite(hi) and 0 <= lo < hi):
                raise ValueError
            return lo, hi
        v = float(text)
        if not (np.isfinite(v) and v > 0):
            raise ValueError
        return v
    except ValueError:
        raise InputError(f"{option} {text!r}: give a positive number or a range X1:X2 with X2 > X1 >= 0") from None


def parse_band(text: str | None) -> tuple[float, float] | None:
    if text is None:
        return None
    try:
        lo, hi = (float(x) for x in text.split(":"))
        if not (0 <= lo < hi and np.isfinite(hi)):
            raise ValueError
    except ValueError:
        raise InputError(f"--band {text!r}: give F1:F2 in Hz with 0 <= F1 < F2 (e.g. 2:40)") from None
    return lo, hi


def export_options(args) -> dict[str, Any]:
    """How the rig's file is written (a lab's export: time decimals, accelerations in g)."""
    return {"time_decimals": args.time_decimals, "acc_unit": args.acc_unit}


def out_path(args) -> Path:
    """The record's path; ``--format`` sets (or checks) its suffix."""
    out = Path(args.out)
    if args.format and out.suffix.lower().lstrip(".") != args.format:
        if out.suffix and not (args.format == "uff" and out.suffix.lower() == ".unv"):
            raise InputError(f"--format {args.format}: the output {out} has another suffix ({out.suffix})")
        out = out.with_suffix(f".{args.format}")
    return out
