"""Parameter constraints: what each estimator parameter may be, declared once beside the estimator.

After scikit-learn's ``_parameter_constraints`` (``sklearn/utils/_param_validation.py``): every estimator
class holds ``_parameter_constraints = {name: Constraint, ...}``; ``Estimator.check`` (the first step of
``fit``) checks every parameter against it and raises one ``InputError`` naming the estimator, the
parameter, the value and what is allowed. The command line builds its options' range checks from the same
declarations (``negstiff.cli.common.declared``: the command being run imports its estimator and reads them;
``negstiff --help`` and the other commands build no estimator options and import none).

Written here rather than imported from scikit-learn: its validation helpers are private API, and
scikit-learn would become a dependency for them.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from typing import Any, override

from negstiff.errors import InputError


class Constraint:
    """What a parameter may be; ``check`` raises ``InputError`` otherwise."""

    def accepts(self, value: Any) -> bool:
        """Whether ``value`` is allowed."""
        raise NotImplementedError

    def describe(self) -> str:
        """The allowed values, in words (the end of "NAME must be ...")."""
        raise NotImplementedError

    def check(self, owner: str, name: str, value: Any) -> None:
        """Raise ``InputError`` naming ``owner``, ``name`` and the allowed values unless ``value`` is allowed."""
        if not self.accepts(value):
            raise InputError(f"{owner}({name}={value!r}): {name} must be {self.describe()}")


def _is_int(v: Any) -> bool:
    return isinstance(v, numbers.Integral) and not isinstance(v, bool)


def _is_real(v: Any) -> bool:
    return isinstance(v, numbers.Real) and not isinstance(v, bool) and math.isfinite(float(v))


@dataclass(frozen=True)
class Interval(Constraint):
    """A number of ``kind`` (``int`` or ``float``: any finite real) in [lo, hi] (``lo_open``/``hi_open``:
    the bound excluded; None: unbounded), in ``unit``; ``none`` admits None (a default computed later); ``even``:
    an even integer only (a model order: two states per mode).
    """

    kind: type
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    hi_open: bool = False
    unit: str = ""
    none: bool = False
    even: bool = False

    @override
    def accepts(self, value: Any) -> bool:
        if value is None:
            return self.none
        if not (_is_int(value) if self.kind is int else _is_real(value)):
            return False
        if self.lo is not None and (value < self.lo or (self.lo_open and value == self.lo)):
            return False
        if self.even and value % 2:
            return False
        return not (self.hi is not None and (value > self.hi or (self.hi_open and value == self.hi)))

    @override
    def describe(self) -> str:
        what = ("an even integer" if self.even else "an integer") if self.kind is int else "a finite number"
        if self.lo is not None or self.hi is not None:
            lo = "-inf" if self.lo is None else f"{self.lo:g}"
            hi = "inf" if self.hi is None else f"{self.hi:g}"
            what += f" in {'(' if self.lo_open else '['}{lo}, {hi}{')' if self.hi_open else ']'}"
        return what + (f" {self.unit}" if self.unit else "") + (" or None" if self.none else "")


@dataclass(frozen=True)
class Options(Constraint):
    """One of ``values``."""

    values: tuple

    @override
    def accepts(self, value: Any) -> bool:
        return isinstance(value, str | type(None)) and value in self.values

    @override
    def describe(self) -> str:
        return "one of " + ", ".join(repr(v) for v in self.values)


@dataclass(frozen=True)
class LawName(Constraint):
    """The name of a registered law of ``kind`` (``models.laws``: read when checked, so a law registered later
    counts), or one of ``also`` (``"auto"``: compare the laws; None: the method's default).
    """

    kind: str
    also: tuple = ()

    @override
    def accepts(self, value: Any) -> bool:
        from negstiff.models import laws

        return (isinstance(value, str) and value in laws.names(self.kind)) or value in self.also

    @override
    def describe(self) -> str:
        from negstiff.models import laws

        return "one of " + ", ".join(repr(v) for v in (*laws.names(self.kind), *self.also))


@dataclass(frozen=True)
class Boolean(Constraint):
    """True or False (or None, "where it applies", with ``none``)."""

    none: bool = False

    @override
    def accepts(self, value: Any) -> bool:
        return isinstance(value, bool) or (self.none and value is None)

    @override
    def describe(self) -> str:
        return "True, False or None" if self.none else "True or False"


@dataclass(frozen=True)
class Pair(Constraint):
    """Two increasing numbers (lo < hi), each within ``each``."""

    each: Interval

    @override
    def accepts(self, value: Any) -> bool:
        try:
            a, b = value
        except (TypeError, ValueError):
            return False
        return self.each.accepts(a) and self.each.accepts(b) and a < b

    @override
    def describe(self) -> str:
        return f"two increasing numbers (lo, hi), each {self.each.describe()}"


@dataclass(frozen=True)
class Several(Constraint):
    """A non-empty sequence of values, each within ``each``."""

    each: Constraint

    @override
    def accepts(self, value: Any) -> bool:
        if isinstance(value, str | bytes) or not hasattr(value, "__len__") or len(value) == 0:
            return False
        return all(self.each.accepts(v) for v in value)

    @override
    def describe(self) -> str:
        return f"a non-empty sequence, each {self.each.describe()}"


@dataclass(frozen=True)
class Instance(Constraint):
    """An instance of the class named ``name`` (its module ``module``), or None with ``none``: checked by
    name, so a declaration need not import the class (``--help`` reads declarations from the source).
    """

    module: str
    name: str
    none: bool = False

    @override
    def accepts(self, value: Any) -> bool:
        if value is None:
            return self.none
        import importlib

        return isinstance(value, getattr(importlib.import_module(self.module), self.name))

    @override
    def describe(self) -> str:
        return f"a {self.name}" + (" or None" if self.none else "")


@dataclass(frozen=True)
class AnyOf(Constraint):
    """Any one of ``options`` (constraints: ``Instance``'s of several classes), or None with ``none``."""

    options: tuple[Constraint, ...]
    none: bool = False

    @override
    def accepts(self, value: Any) -> bool:
        return self.none if value is None else any(o.accepts(value) for o in self.options)

    @override
    def describe(self) -> str:
        return ", ".join(o.describe() for o in self.options) + (" or None" if self.none else "")


SEED = Interval(int, 0, 2**32 - 1)
"""A random seed: numpy's SeedSequence takes any non-negative integer; the command line's 32 bits."""


@dataclass(frozen=True)
class RandomState(Interval):
    """A seed as scikit-learn's ``random_state``: a non-negative integer (``lo``-``hi``), None (fresh entropy:
    not reproducible) or a ``numpy.random.Generator`` (its next draw seeds the run); ``seed_of`` resolves it
    in ``fit``, where the seed used is recorded.
    """

    @override
    def accepts(self, value: Any) -> bool:
        import numpy as np

        return isinstance(value, np.random.Generator) or super().accepts(value)

    @override
    def describe(self) -> str:
        return super().describe() + " or a numpy.random.Generator"


def seed_of(seed: Any) -> int:
    """The integer seed a ``RandomState`` parameter gives: itself, a fresh one (None), or the next draw of a
    ``numpy.random.Generator`` (so one generator seeds several fits differently, as in scikit-learn).
    """
    import numpy as np

    if seed is None:
        return int(np.random.SeedSequence().generate_state(1)[0])
    if isinstance(seed, np.random.Generator):
        return int(seed.integers(0, 2**31 - 1))
    return int(seed)


RANDOM_STATE = RandomState(int, 0, 2**32 - 1, none=True)
"""A seed, None or a ``numpy.random.Generator`` (``RandomState``)."""

FRACTION = Interval(float, 0.0, 1.0, lo_open=True, hi_open=True)
"""A share of a record, strictly between none and all of it."""

RESTORING_LAW = LawName("restoring", ("auto", None))
"""A restoring law's name, ``"auto"`` (compare them all) or None (the method's default; the others tried if it
fails its checks)."""
DAMPING_LAW = LawName("damping")
"""A damping law's name."""

NAMESPACE = {c.__name__: c for c in (Interval, Options, Boolean, Pair, Several, Instance, RandomState, LawName)} | {
    "int": int, "float": float, "SEED": SEED, "RANDOM_STATE": RANDOM_STATE, "FRACTION": FRACTION,
    "RESTORING_LAW": RESTORING_LAW, "DAMPING_LAW": DAMPING_LAW}  # fmt: skip
"""What a declaration may name (``negstiff.cli.common.declared`` evaluates declarations in it)."""
