"""Follow one record through an estimator's ``fit`` and count where it goes: the structure check of the
"one home per concept" refactor, made by running the code rather than reading it.

A *stop* is a call of one of the package's own functions that receives the record: the
:class:`~negstiff.Measurement` itself (or any record made from it inside the fit, a pinned or calibrated
copy), an object holding one (derived states), or an array that shares memory with one of the record's
columns. The record's own methods (``rec.segment``, ``rec.states``) are not followed, as a reader does not
open them to follow the record: what they do, and whatever they call, is the record's inside (``--methods``
counts them and follows them). The walk is the sequence of stops in call order; it reports

- ``functions``: the distinct functions the record reaches,
- ``files``: the distinct files they live in,
- ``stays``: the walk with consecutive stops in the same file merged (a stay is one visit to a file),
- ``returns``: stays in a file the walk had already left.

Fewer files and fewer returns mean a reader follows the record through fewer places. The record is written
here with numpy and scipy (a seed-like asymmetric double well under a 2-30 Hz multisine base acceleration,
DOP853), so the script runs on any checkout that has ``negstiff.load``, ``NSI`` and ``Discrepancy``::

    python -m benchmarks.record_walk          # prints a table (Markdown)
    python -m benchmarks.record_walk --json   # the same as JSON

Tracing uses :func:`sys.setprofile`; the fits run a few times slower under it.
"""

from __future__ import annotations

import argparse
import functools
import json
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

_OWN = ("negstiff", "models", "inference", "experiments")
_SELF = Path(__file__).name


def _record_csv(folder: Path, duration: float = 60.0, seed: int = 7) -> Path:
    """A 60 s, 512 Hz record of a seed-like double well (0.2 kg), written as a lab CSV."""
    from scipy.integrate import solve_ivp

    m, k1, k2, k3, c, c_nl = 0.2, 426.0, -3060.0, 7.77e5, 0.35, 0.1
    rng = np.random.default_rng(seed)
    f = np.arange(2.0, 30.0, 0.25)
    w, ph = 2 * np.pi * f, rng.uniform(0, 2 * np.pi, f.size)
    a = 8.0 * np.sqrt(2.0 / f.size)

    def acc(t):
        return a * np.cos(np.multiply.outer(t, w) + ph).sum(axis=-1)

    def rhs(t, x):
        z, v = x
        r = k1 * z + k2 * z**2 + k3 * z**3
        return [v, (-c * v - c_nl * v * abs(v) - r) / m - acc(t)]

    t = np.arange(int(duration * 512)) / 512.0
    sol = solve_ivp(rhs, (0, t[-1]), [0.024, 0.0], t_eval=t, method="DOP853", rtol=1e-9, atol=1e-12)
    z = sol.y[0] + np.random.default_rng(seed + 1).normal(0, 3e-6, t.size)
    path = folder / "walk.csv"
    rows = np.column_stack([t, acc(t), z])
    path.write_text("# mass: 0.2\nt,base_acc,z\n" + "\n".join(",".join(f"{x:.10g}" for x in r) for r in rows))
    return path


def _own(filename: str) -> str | None:
    parts = Path(filename).parts
    for i in range(len(parts) - 1, -1, -1):
        if parts[i] in _OWN and parts[i] != parts[-1] and parts[-1] != _SELF:
            return "/".join(parts[i:])
    return None


class _Walker:
    def __init__(self, record: Any, methods: bool = False):
        from negstiff import Measurement

        self.kind = Measurement
        self.methods = methods
        self.columns = [v for v in vars(record).values() if isinstance(v, np.ndarray) and v.size > 1]
        self.stops: list[tuple[str, str]] = []
        self.inside: set[int] = set()

    def carries(self, value: Any, depth: int = 0) -> bool:
        if isinstance(value, self.kind):
            return True
        if isinstance(value, np.ndarray):
            return value.size > 1 and any(np.shares_memory(value, c) for c in self.columns)
        if depth == 0 and hasattr(value, "__dict__") and not isinstance(value, type):
            try:
                return any(self.carries(v, 1) for v in vars(value).values())
            except TypeError:
                return False
        if depth == 0 and isinstance(value, tuple | list) and len(value) < 16:
            return any(self.carries(v, 1) for v in value)
        return False

    def _inside_record(self, frame) -> bool:
        f = frame.f_back
        while f is not None:
            if id(f) in self.inside:
                return True
            f = f.f_back
        return False

    def __call__(self, frame, event, arg):
        if event == "return":
            self.inside.discard(id(frame))
            return
        if event != "call":
            return
        where = _own(frame.f_code.co_filename)
        if where is None or self._inside_record(frame):
            return
        code = frame.f_code
        names = code.co_varnames[: code.co_argcount + code.co_kwonlyargcount]
        args = [frame.f_locals.get(n) for n in names]
        if args and isinstance(args[0], self.kind) and names[0] == "self":
            attr = getattr(type(args[0]), code.co_name, None)
            if not self.methods or isinstance(attr, property | functools.cached_property):
                self.inside.add(id(frame))  # the record's own method and all it calls: its inside
                return
        # a method of an object that merely holds the record (an estimator) is not a stop
        own = [v for n, v in zip(names, args, strict=True) if n != "self" or isinstance(v, self.kind)]
        if any(self.carries(v) for v in own):
            self.stops.append((where, code.co_qualname))


def walk(fit: Callable[[Any], Any], record: Any, methods: bool = False) -> dict[str, Any]:
    """Run ``fit(record)`` under the profiler and count the record's stops, files, stays and returns
    (``methods``: the record's own methods counted as stops too).
    """
    walker = _Walker(record, methods)
    sys.setprofile(walker)
    try:
        fit(record)
    finally:
        sys.setprofile(None)
    files = [f for f, _ in walker.stops]
    stays = [f for i, f in enumerate(files) if i == 0 or f != files[i - 1]]
    returns = sum(1 for i, f in enumerate(stays) if f in stays[:i])
    first: dict[str, int] = {}
    for f in files:
        first[f] = first.get(f, 0) + 1
    return {
        "calls": len(walker.stops),
        "functions": len(set(walker.stops)),
        "files": len(first),
        "stays": len(stays),
        "returns": returns,
        "per_file": first,
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--json", action="store_true", help="print JSON instead of a Markdown table")
    parser.add_argument("--methods", action="store_true", help="count calls of the record's own methods as stops")
    args = parser.parse_args(argv)
    import warnings

    from negstiff import NSI, Discrepancy, load

    out = {}
    with tempfile.TemporaryDirectory() as tmp, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rec = load(_record_csv(Path(tmp)))
        out["NSI.fit"] = walk(lambda r: NSI().fit(r), rec, args.methods)
        out["Discrepancy.fit"] = walk(lambda r: Discrepancy().fit(r), rec, args.methods)
    if args.json:
        print(json.dumps(out, indent=1))
        return 0
    print("| fit | calls with the record | functions | files | stays | returns |")
    print("|---|---|---|---|---|---|")
    for name, w in out.items():
        print(f"| `{name}` | {w['calls']} | {w['functions']} | {w['files']} | {w['stays']} | {w['returns']} |")
    for name, w in out.items():
        print(f"\n{name}: " + ", ".join(f"{f} {n}" for f, n in sorted(w["per_file"].items(), key=lambda x: -x[1])))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
