"""Restoring-force and damping laws: the named forms a model's force may take, each a composition of parts.

A law frees some of the model file's base fields (``k0``..``k3``; ``c``, ``c_nl``) and adds parts of the effect
registry (``effects.REGISTRY``: monomials, a smoothed sign, the shaped parts of ``models.shaped``). Every method
reads a law the same way, as pysindy reads a feature library: at a shape of its shaped parts, the law is a list
of columns of z and z' (``Law.columns``), each column's coefficient one model field or one part coefficient
(``Law.model``). NSI takes the columns as its nonlinear basis, SINDy and the weak-form fits as their library,
the refinement and the posterior as their parameters, and the simulator as the model the coefficients make.

Adding a law is one entry of ``LAWS`` (a test adds one with ``registered``), as adding an effect is one entry of
the effect registry.

The restoring laws (``kind="restoring"``):

* ``cubic``: K = k3 z^3 + k2 z^2 - k1 z + k0, the reference study's Eq. (2).
* ``quintic``, ``septic``: polynomials of order 5 and 7 (the top coefficient must come out positive: a bounded
  tail, checked where a model is judged).
* ``magnet``: a linear spring, a constant (a tilt) and two facing magnets as point dipoles (``shaped.DipoleMagnet``).
* ``oblique_springs``: a linear spring, a constant and two oblique springs' negative stiffness
  (``shaped.ObliqueSprings``).
* ``geometric``: the reference study's rod-frame geometry (``shaped.RodFrame``) with gravity's constant.
* ``spline``: a smooth force with no formula, a cubic B-spline over the record's stroke (``shaped.Spline``).

The damping laws (``kind="damping"``): ``viscous`` (c z'), ``quadratic`` (c z' + c_nl z'|z'|, the reference
study's), ``cubic_damping`` (c z' + c3 z'^3), ``friction`` (c z' + F tanh(z'/v_s)) and ``polynomial_damping``
(c z' + c_nl z'|z'| + c3 z'^3: an equivalent damping ratio that may rise, then fall, with amplitude).
"""

from __future__ import annotations

import contextlib
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from . import effects
from .shaped import ShapedLaw

Shape = Mapping[str, Mapping[str, Any]]
"""The shapes of a law's shaped parts: part name -> its shape fields (``{"magnet": {"d": 0.02}}``)."""


@dataclass(frozen=True)
class Column:
    """One column of a law: its label, what its coefficient becomes (a base field, an effect, or a shaped
    part's coefficient ``index``), and the sign of that value relative to -m times the coefficient in z''.
    """

    label: str
    target: str
    index: int
    sign: float


@dataclass(frozen=True)
class Law:
    """A named law: the base fields it frees and the registry parts it adds (module docstring).

    Parameters
    ----------
    name : str
        The name the CLI (``--law``, ``--damping``) and the results use.
    kind : {"restoring", "damping"}
        Which force the law is.
    fields : tuple of str
        The model file's base fields it frees (the others are zero).
    parts : tuple of str
        The effect registry's entries it adds.
    title : str
        One line for people: the law's formula.
    reference : str
        Where the form comes from.
    signed : tuple of str
        A damping law's parts whose coefficient the data may give either sign: the law's damping as a whole must
        dissipate at every speed the record reached, not each term (``polynomial_damping``'s z'^3 term, negative
        where the damping ratio falls again at large amplitude). Every other dissipative part is >= 0.
    """

    name: str
    kind: str
    fields: tuple[str, ...]
    parts: tuple[str, ...] = ()
    title: str = ""
    reference: str = ""
    signed: tuple[str, ...] = ()

    def __post_init__(self):
        if self.kind not in ("restoring", "damping"):
            raise ValueError(f"a law is 'restoring' or 'damping', got {self.kind!r}")
        for f in self.fields:
            if f not in effects.BASE_TERMS:
                raise ValueError(f"law {self.name}: {f!r} is not a base field ({', '.join(effects.BASE_TERMS)})")
        for p in self.parts:
            effects.get(p)  # raises for an unknown part
        if set(self.signed) - set(self.parts) or (self.signed and self.kind != "damping"):
            raise ValueError(f"law {self.name}: signed parts are some of a damping law's parts")

    # --- its parts ------------------------------------------------------------------------------------
    def shaped(self) -> dict[str, ShapedLaw]:
        """The law's shaped parts by name (their columns depend on a shape: ``models.shaped``)."""
        return {p: law for p in self.parts if isinstance(law := effects.get(p).law, ShapedLaw)}

    def shape_guesses(self, stroke: tuple[float, float]) -> list[dict[str, dict[str, Any]]]:
        """Starting shapes of the law's shaped parts for a record whose z spans ``stroke`` [m] (every combination
        of each part's guesses; one empty shape for a law without shaped parts).
        """
        out: list[dict[str, dict[str, Any]]] = [{}]
        for name, law in self.shaped().items():
            out = [{**s, name: g} for s in out for g in law.shape_guesses(stroke)]
        return out

    def shape_of(self, model) -> dict[str, dict[str, Any]]:
        """The shapes of the law's shaped parts in a model."""
        return {name: law.shape_of(model.extra[name]) for name, law in self.shaped().items() if name in model.extra}

    # --- columns ------------------------------------------------------------------------------------
    def column_list(self, shape: Shape | None = None) -> list[Column]:
        """The law's columns (labels and targets) at ``shape``: the base fields' terms, then each scalar part's,
        then each shaped part's coefficients.
        """
        cols = [Column(effects.BASE_TERMS[f][0].label, f, 0, effects.BASE_TERMS[f][1]) for f in self.fields]
        for p in self.parts:
            e = effects.get(p)
            if isinstance(e.law, ShapedLaw):
                n = len(e.law.columns((shape or {})[p], np.zeros(1)))
                cols += [Column(f"{p}[{j}]", p, j, -1.0) for j in range(n)]
            else:
                assert isinstance(e.law, effects.Monomial | effects.SmoothSign)  # a column of its own
                cols.append(Column(e.law.label, p, 0, -1.0))
        return cols

    def columns(self, z, v, shape: Shape | None = None, velocity_noise: float = 0.0) -> np.ndarray:
        """The law's columns evaluated at the states z [m], z' [m/s] (samples, columns), at ``shape``; a smoothed
        sign's column is the expected sign of the true velocity given the noisy one (``effects.SmoothSign``).
        """
        out = self.column_arrays(z, v, shape, velocity_noise)
        return np.column_stack(out) if out else np.zeros((np.size(z), 0))

    def column_arrays(self, z, v, shape: Shape | None = None, velocity_noise: float = 0.0) -> list[np.ndarray]:
        """``columns``, one array each: a library of several laws stacks all of theirs once (stacked law by law and
        then again, every sample was copied three times: on a 396 s record at 2048 Hz the column stacking of a
        refused identification took 1.4 s, 0.9 s once, measured).
        """
        z, v = np.asarray(z, float), np.asarray(v, float)
        out = [effects.BASE_TERMS[f][0].column(z, v, velocity_noise) for f in self.fields]
        for p in self.parts:
            law = effects.get(p).law
            if isinstance(law, ShapedLaw):
                out += [np.broadcast_to(c, z.shape) for c in law.columns((shape or {})[p], z)]
            else:
                assert isinstance(law, effects.Monomial | effects.SmoothSign)  # a column of its own
                out.append(law.column(z, v, velocity_noise))
        return out

    def values(self, coefficients, mass: float, shape: Shape | None = None) -> tuple[dict[str, float], dict]:
        """The model fields and extra effects of the law's z'' coefficients (per unit mass; ``column_list``'s
        order) and the mass: base fields and scalar effects ``sign x m x coefficient``, a shaped part's value from
        its shape and its coefficients ``-m x coefficient``.
        """
        coefficients = np.asarray(coefficients, float)
        fields: dict[str, float] = {}
        extra: dict[str, Any] = {}
        shaped: dict[str, list[float]] = {}
        for col, c in zip(self.column_list(shape), coefficients, strict=True):
            value = col.sign * mass * float(c)
            if col.target in effects.BASE_TERMS:
                fields[col.target] = value
            elif col.target in self.shaped():
                shaped.setdefault(col.target, []).append(value)
            else:
                extra[col.target] = value
        for name, coef in shaped.items():
            extra[name] = self.shaped()[name].value_of((shape or {})[name], coef)
        return fields, extra


def compose(restoring: Law, damping: Law, coefficients, mass: float, shape: Shape | None = None,
            k0: float | None = None):  # fmt: skip
    """The model of a restoring and a damping law's z'' coefficients (restoring first, then damping, as
    ``Law.column_list`` orders each) and the mass; ``k0`` given where the restoring law leaves it out.
    """
    from .equation import Model

    n = len(restoring.column_list(shape))
    fr, er = restoring.values(coefficients[:n], mass, shape)
    fd, ed = damping.values(coefficients[n:], mass, shape)
    fields = {k: 0.0 for k in ("k1", "k2", "k3", "c", "c_nl")} | fr | fd
    if "k0" not in fields:
        fields["k0"] = 0.0 if k0 is None else k0
    return Model(m=mass, **fields, extra={**er, **ed})


LAWS: list[Law] = [
    Law("cubic", "restoring", ("k0", "k1", "k2", "k3"), (), "K = k3 z^3 + k2 z^2 - k1 z + k0",
        "the reference study, Eq. (2)"),
    Law("quintic", "restoring", ("k0", "k1", "k2", "k3"), ("quartic_stiffness", "quintic_stiffness"),
        "K = k5 z^5 + k4 z^4 + k3 z^3 + k2 z^2 - k1 z + k0", "a polynomial of order 5"),
    Law("septic", "restoring", ("k0", "k1", "k2", "k3"),
        ("quartic_stiffness", "quintic_stiffness", "sextic_stiffness", "septic_stiffness"),
        "K = k7 z^7 + ... + k2 z^2 - k1 z + k0", "a polynomial of order 7"),
    Law("magnet", "restoring", ("k0", "k1"), ("magnet",), "K = k0 - k1 z - 3 A z / (d^2 + z^2)^(5/2)",
        "point dipoles: Moon & Holmes 1979; Mann & Owens 2010; Stanton, McGehee & Mann 2010"),
    Law("oblique_springs", "restoring", ("k0", "k1"), ("oblique_springs",),
        "K = k0 - k1 z - 2 P z / sqrt(a^2 + z^2)", "Carrella, Brennan & Waters 2007, Eq. (2)"),
    Law("geometric", "restoring", ("k0",), ("rod_frame",), "K = k0 + 2 k_f (s + D0) s'(z)",
        "the reference device's rod frame: docs/device-model.md"),
    Law("spline", "restoring", (), ("spline",), "K = a cubic B-spline over the stroke, straight beyond it",
        "de Boor 1978; knots chosen by the data"),
    Law("viscous", "damping", ("c",), (), "D = c z'", "linear viscous damping"),
    Law("quadratic", "damping", ("c", "c_nl"), (), "D = c z' + c_nl z'|z'|", "the reference study's damping"),
    Law("cubic_damping", "damping", ("c",), ("cubic_damping",), "D = c z' + c3 z'^3", "a cubic damper"),
    Law("friction", "damping", ("c",), ("coulomb_friction",), "D = c z' + F tanh(z' / v_s)",
        "viscous and Coulomb friction, smoothed"),
    Law("polynomial_damping", "damping", ("c", "c_nl"), ("cubic_damping",), "D = c z' + c_nl z'|z'| + c3 z'^3",
        "a damping ratio that may rise and then fall with amplitude (an eddy current's, a joint's)",
        signed=("cubic_damping",)),
]  # fmt: skip
"""The laws, in the order the CLI lists them."""

DEFAULT_RESTORING = "cubic"
DEFAULT_DAMPING = "quadratic"


def names(kind: str | None = None) -> tuple[str, ...]:
    """The laws' names (of one ``kind``: ``"restoring"`` or ``"damping"``)."""
    return tuple(law.name for law in LAWS if kind is None or law.kind == kind)


def get(name: str | Law, kind: str | None = None) -> Law:
    """The law named ``name`` (a ``Law`` passes through), checked against ``kind``; ``ValueError`` otherwise."""
    if isinstance(name, Law):
        law = name
    else:
        law = next((x for x in LAWS if x.name == name), None)  # type: ignore[assignment]
        if law is None:
            known = names(kind)
            raise ValueError(f"unknown {kind + ' ' if kind else ''}law {name!r}; known: {', '.join(known)}")
    if kind is not None and law.kind != kind:
        raise ValueError(f"{law.name} is a {law.kind} law, not a {kind} one; {kind} laws: {', '.join(names(kind))}")
    return law


def of_model(model, kind: str = "restoring") -> Law:
    """The simplest law that holds ``model``'s force of one ``kind``: the first of ``LAWS`` whose parts include
    every extra effect of that kind the model has and whose fields include its nonzero base fields.
    """
    disp = {"restoring": True, "damping": False}[kind]
    used = {n for n, v in model.extra.items() if not n.startswith(effects.AUX_PREFIX)
            and effects.get(n).law.displacement_only == disp}  # fmt: skip
    base = {f for f in (("k1", "k2", "k3") if disp else ("c", "c_nl")) if getattr(model, f) != 0}
    for law in LAWS:
        if law.kind == kind and used <= set(law.parts) and base <= set(law.fields):
            return law
    raise ValueError(f"no {kind} law holds the model's {', '.join(sorted(used | base))}")


@contextlib.contextmanager
def registered(*laws: Law):
    """Add laws for the duration of a ``with`` block (tests, experiments)."""
    with effects.registered_in(LAWS, laws, names(), "a law"):
        yield laws


@dataclass(frozen=True)
class FeedbackBasis:
    """NSI's nonlinear basis about a reference z* for a restoring and a damping law at a shape:
    the law's columns with their value and slope at z* taken off (they are the ULS's constant and stiffness),
    so each basis function vanishes to first order at x = z - z* = 0.

    A column that is a power of z (a polynomial law's z^2, z^3, ...) is re-expanded about z* as the powers of x
    (reference study Eq. 7: the same span, exact); any other column (a magnet's, the rod frame's, a spline's)
    enters as its remainder R(x) = C(z* + x) - C(z*) - C'(z*) x. The damping law's columns but the viscous one
    are functions of x' alone and enter as they are. Where the remainders are linearly dependent (a spline
    holds every straight line), only their independent combinations are kept (``reduce``).
    """

    restoring: Law
    damping: Law
    shape: Shape

    def names(self) -> tuple[str, ...]:
        """The basis functions' names: x2, x3, ... for powers, ``LABEL~`` for remainders, the damping's labels
        (``vabsv`` for x'|x'|, as the reference study's basis).
        """
        disp = [self._name(c) for c in self.restoring.column_list(self.shape) if self._kind(c) != "linear"]
        vel = ["vabsv" if c.label == "v|v|" else c.label for c in self.damping.column_list(self.shape)
               if c.label != "v"]  # fmt: skip
        return tuple(disp + vel)

    @staticmethod
    def _kind(col: Column) -> str:
        if col.label in ("1", "z"):
            return "linear"
        if col.label.startswith("z^") and col.label[2:].isdigit():
            return "power"
        return "remainder"

    def _name(self, col: Column) -> str:
        return f"x{col.label[2:]}" if self._kind(col) == "power" else f"{col.label}~"

    def displacement(self, x: np.ndarray, z_ref: float) -> np.ndarray:
        """The displacement basis functions at x = z - z* (samples, functions)."""
        x = np.asarray(x, float)
        cols = [c for c in self.restoring.column_list(self.shape)]
        out = []
        if any(self._kind(c) == "remainder" for c in cols):
            h = 1e-6 * max(abs(z_ref), float(np.std(x)), 1e-6)
            at = self.restoring.columns(np.array([z_ref - h, z_ref, z_ref + h]), np.zeros(3), self.shape)
            here = self.restoring.columns(z_ref + x, np.zeros_like(x), self.shape)
        for j, c in enumerate(cols):
            kind = self._kind(c)
            if kind == "power":
                out.append(x ** int(c.label[2:]))
            elif kind == "remainder":
                slope = (at[2, j] - at[0, j]) / (2 * h)
                out.append(here[:, j] - at[1, j] - slope * x)
        return np.column_stack(out) if out else np.zeros((x.size, 0))

    def velocity(self, v: np.ndarray, velocity_noise: float = 0.0) -> np.ndarray:
        """The damping basis functions at x' (samples, functions)."""
        v = np.asarray(v, float)
        cols = self.damping.columns(np.zeros_like(v), v, self.shape, velocity_noise)
        keep = [j for j, c in enumerate(self.damping.column_list(self.shape)) if c.label != "v"]
        return cols[:, keep]
