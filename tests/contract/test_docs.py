"""The documentation a user learns from: every public name has a numpydoc docstring whose examples run,
and the gallery's scripts are plain scripts (the docs build executes them; ``.ci/run`` builds the docs with
warnings as errors)."""

import doctest
import inspect
import re
import warnings

import pytest

import negstiff
import negstiff.datasets
import negstiff.testing
from negstiff import NegstiffWarning

PUBLIC = [(name, getattr(negstiff, name)) for name in negstiff.__all__ if name != "__version__"] + [
    (f"datasets.{name}", getattr(negstiff.datasets, name)) for name in ("silverbox", "silverbox_path")
]


def _section(doc: str, title: str) -> str | None:
    m = re.search(rf"^{title}\n-{{{len(title)}}}\n(.*?)(?=^\S[^\n]*\n-{{3,}}\n|\Z)", doc, re.M | re.S)
    return None if m is None else m.group(1)


def _documented_names(block: str) -> set[str]:
    names: set[str] = set()
    for line in block.splitlines():
        if line and not line.startswith(" ") and " : " in line + " ":
            names.update(n.strip().lstrip("*") for n in line.split(" :")[0].split(","))
        elif line.startswith("**"):
            names.add(line.strip().lstrip("*"))
    return names


@pytest.mark.parametrize("name, obj", PUBLIC, ids=[n for n, _ in PUBLIC])
def test_every_public_name_has_a_numpydoc_docstring_with_an_example(name, obj):
    doc = inspect.getdoc(obj)
    assert doc, f"{name} has no docstring"
    assert _section(doc, "Examples") and ">>>" in _section(doc, "Examples"), f"{name}: no Examples section"
    is_error = isinstance(obj, type) and issubclass(obj, (Exception, Warning))
    if callable(obj) and not is_error:
        params = [p.name for p in inspect.signature(obj).parameters.values() if p.name not in ("self", "cls")]
        if params:
            # a record or result dataclass documents its fields as Attributes
            block = (_section(doc, "Parameters") or "") + (_section(doc, "Attributes") or "")
            missing = set(params) - _documented_names(block)
            assert not missing, f"{name}: parameters not documented: {sorted(missing)}"
        if inspect.isfunction(obj) and inspect.signature(obj).return_annotation not in (None, "None"):
            assert _section(doc, "Returns"), f"{name}: no Returns section"
    if name in ("NSI", "SINDy", "Discrepancy", "Posterior", "GAUpdater"):
        attrs = _documented_names(_section(doc, "Attributes") or "")
        assert attrs and all(a.endswith("_") for a in attrs), f"{name}: Attributes must list the learned *_"


SLOW_EXAMPLES = {"Posterior", "design", "separation"}
"""An example that samples a posterior (about 10 s): run with -m slow, test_posterior.py and test_design.py keeping
Posterior, design and separation in the default suite."""


@pytest.mark.parametrize(
    "name, obj",
    [pytest.param(n, o, marks=pytest.mark.slow) if n in SLOW_EXAMPLES else (n, o) for n, o in PUBLIC],
    ids=[n for n, _ in PUBLIC],
)
def test_the_docstring_examples_run(name, obj, tmp_path, monkeypatch):
    # each example as a user would paste it: in a fresh namespace, in an empty working folder; a doctest
    # that issues a NegstiffWarning fails (an example must show a result negstiff believes)
    monkeypatch.chdir(tmp_path)
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    with warnings.catch_warnings():
        warnings.simplefilter("error", NegstiffWarning)
        for test in doctest.DocTestFinder(recurse=False).find(obj, name, globs={}):
            runner.run(test, out=lambda text: pytest.fail(f"{name}'s example failed:\n{text}"))
    assert runner.summarize(verbose=False).attempted > 0
