"""The package's structure (issue "One home per concept"), checked on its source and at run time: no import
cycle anywhere (an import inside a function is laziness, never a way round a cycle), no module-level cache
of a record's arrays, one Runge-Kutta loop for the equation of motion, and a command line that reads,
calls the library and writes (no numerical analysis of its own)."""

import ast
import sys
from pathlib import Path

import numpy as np
import pytest

import negstiff

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = {"negstiff": ROOT / "negstiff"}
"""The package is its folder: the import path is the layout."""


def _modules() -> dict[str, Path]:
    out = {}
    for pkg, folder in PACKAGES.items():
        for f in folder.rglob("*.py"):
            parts = list(f.relative_to(folder).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join([pkg, *parts])] = f
    return out


def _imports(modules: dict[str, Path]) -> dict[str, dict[str, bool]]:
    """module -> {imported package module: at module level?}, every import statement of the file."""
    edges: dict[str, dict[str, bool]] = {}
    for mod, f in modules.items():
        tree = ast.parse(f.read_text())
        is_pkg = f.name == "__init__.py"
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                base = mod.split(".")[: None if is_pkg else -1]
                target = (
                    ".".join(base[: len(base) - node.level + 1] + [node.module or ""]).strip(".")
                    if node.level
                    else node.module
                )
                subs = [f"{target}.{a.name}" for a in node.names if f"{target}.{a.name}" in modules]
                targets = subs if len(subs) == len(node.names) else [target, *subs]
            elif isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            else:
                continue
            for t in targets:
                while t and t not in modules:
                    t = t.rpartition(".")[0]
                if t and t != mod:
                    here = edges.setdefault(mod, {})
                    here[t] = here.get(t, False) or node in tree.body
    return edges


def test_no_import_cycle_in_the_package():
    # imports inside functions count: one that closes a cycle hides it, which is what this forbids
    edges = _imports(_modules())
    index, low, stack, on, cycles = {}, {}, [], set(), []
    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10_000))

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in edges.get(v, {}):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                cycles.append(sorted(comp))

    for v in list(edges):
        if v not in index:
            visit(v)
    assert not cycles, f"import cycles: {cycles}"


LAYERS = [
    ("negstiff.errors", "negstiff.constants", "negstiff.resources", "negstiff.files"),
    ("negstiff.io",),
    ("negstiff.models",),
    ("negstiff.inference.record",),
    ("negstiff.inference.steps",),
    ("negstiff.inference.estimators", "negstiff.inference.analysis"),
    ("negstiff.inference", "negstiff.datasets", "negstiff.testing"),
    ("negstiff.report",),
    ("negstiff.experiments",),
    ("negstiff.cli", "negstiff.__main__"),
]
"""The package's layers, lowest first (``negstiff.inference`` itself is its parts' front door, loading names on
first use): a module imports its own layer and the ones below, never one above
(the front door ``negstiff`` itself, which loads names on first use, is above all and is imported only for
its version)."""


def _layer(module: str) -> int | None:
    for rank, names in enumerate(LAYERS):
        if any(module == n or module.startswith(n + ".") for n in names):
            return rank
    return None


def test_no_layer_imports_one_above_it():
    # the layout is the import path: the folders are the layers, and the arrows point down only; the
    # reference study (negstiff.experiments) is imported by the command line alone
    upward = []
    for mod, targets in _imports(_modules()).items():
        for target in targets:
            a, b = _layer(mod), _layer(target)
            if a is not None and b is not None and b > a:
                upward.append(f"{mod} -> {target}")
    assert not upward, f"imports of a layer above: {upward}"
    outside = [m for m in _modules() if _layer(m) is None and m != "negstiff"]
    assert not outside, f"modules outside every layer: {outside}"


def test_the_layout_is_the_import_path():
    # every module of the package is the file its name says (no package-dir remapping, no __path__ addition)
    import importlib

    for name, f in _modules().items():
        if name == "negstiff.__main__":  # runs the command line when imported
            continue
        module = importlib.import_module(name)
        assert Path(module.__file__).resolve() == f.resolve(), name


def test_the_default_install_does_not_pull_dask():
    # dask is an extra (studies over many records on a cluster); the library's dependencies name none of it
    import tomllib

    deps = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["dependencies"]
    assert not [d for d in deps if d.lower().startswith(("dask", "distributed"))], deps


def test_no_module_level_cache_holds_a_records_arrays(tmp_path):
    # after a whole identification, no module's globals hold arrays in a container (a record's states and
    # segments live with the record: Measurement.derived)
    from negstiff import SINDy, from_arrays

    t = np.arange(30 * 512) / 512
    z = 0.02 + 1e-3 * np.sin(2 * np.pi * 9 * t) + 2e-4 * np.sin(2 * np.pi * 23 * t)
    SINDy(n_models=4).fit(from_arrays(np.sin(2 * np.pi * 9 * t), z, 512.0, mass=0.2))
    found = []
    for name, module in list(sys.modules.items()):
        if not name.startswith("negstiff"):
            continue
        for key, value in vars(module).items():
            if isinstance(value, (dict, list, set)) and not key.startswith("__"):
                items = value.values() if isinstance(value, dict) else value
                if any(isinstance(v, np.ndarray) and v.size > 64 or isinstance(v, tuple) and any(
                        isinstance(x, np.ndarray) and x.size > 64 for x in v) for v in items):  # fmt: skip
                    found.append(f"{name}.{key}")
    assert not found, f"module-level containers holding arrays: {found}"


def test_one_runge_kutta_loop_for_the_equation_of_motion():
    # the stage combination z + h/6 (k1 + 2 k2 + 2 k3 + k4) of the equation of motion is written once (the
    # kernel); the other RK4 in the library integrates the variational equations (state and tangent) of the
    # Benettin exponent, a reference of another system (the benchmarks' plain C loop is a peer, not the library)
    library = [f for name, f in _modules().items() if not name.startswith("negstiff.experiments")]
    files = sorted(str(f.relative_to(ROOT)) for f in library if "h / 6.0 * (" in f.read_text())
    assert files == ["negstiff/models/kernel.py", "negstiff/models/reference.py"], files
    assert "variational equations" in (ROOT / "negstiff/models/reference.py").read_text()


@pytest.mark.parametrize("module", sorted(p.name for p in (ROOT / "negstiff/cli").glob("*.py")))
def test_the_command_line_does_no_numerical_analysis(module):
    # its numpy is for writing a simulation's columns and checking an option's numbers, its matplotlib for
    # saving the library's figures, nothing else
    tree = ast.parse((ROOT / "negstiff/cli" / module).read_text())
    imported = {a.name.split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    imported |= {(n.module or "").split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
    assert not imported & {"scipy", "numba", "emcee", "arviz", "pysindy", "pymoo"}
    used = {n.attr for n in ast.walk(tree) if isinstance(n, ast.Attribute) and getattr(n.value, "id", "") == "np"}
    assert used <= {"column_stack", "savetxt", "isfinite", "diff", "round", "arange", "floating", "integer", "ndarray"}


def test_the_front_door_is_the_package():
    assert negstiff.__file__.endswith("negstiff/__init__.py")
