"""The extra effects: one registry every part of negstiff reads.

An extra effect is a named force added to the left-hand side of the equation of motion,

    m z'' + D(z') + K(z) + sum_e F_e(z, z') = -m b''   (or f(t)),

and a model file carries it in its ``extra`` mapping under the effect's name. Each entry of
``REGISTRY`` says what the force is (its *law*), in what units its value is, and nothing else: the
model's force and potential (``models.equation``), the simulator's parameter rows (``kernel_rows``,
``layout``), the SINDy library (``library_terms``), the discrepancy catalogue, the refinement's
parameters and the CLI's help all derive from it. Adding an effect is one ``Effect(...)`` entry (a
test registers one with ``registered``): a ``Monomial`` law is simulated, identified and named without
touching any other file; only a new *kind* of law (beside monomials, the smoothed sign and the
one-sided stop) needs a compiled kernel of its own.

Three laws:

* ``Monomial`` a |z|^p sgn(z)^s |z'|^q sgn(z')^r: every polynomial stiffness or damping term (z^4 is
  p = 4, s = 0; z'^3 is q = 3, r = 1; a linear-in-|z| stiffness is p = 1, s = 0). A monomial that is
  a base field's term (z^2: k2, z^3: k3, z'|z'|: c_nl) *folds* into it: the simulator adds the two,
  the library has one column for both, and the refinement moves the named one only.
* ``SmoothSign`` F tanh(z' / v_s): Coulomb friction, smoothed over v_s.
* ``OneSidedStop`` k (z - z_s) beyond z_s, on z_s's side: contact beyond a gap; two values
  (``{"k": N/m, "z": m}``), the position a nonlinear parameter the discrepancy workflow searches.

The simulator's kernel evaluates the base force, a fixed set of monomial rows (z^2..z^5, z'^3), the
sign and the stop row with no branch (fast: the batch loop vectorises); a monomial outside that set
gets a row of its own after them and is summed by a loop compiled only into the kernels that need it
(``layout``).
"""

from __future__ import annotations

import contextlib
import functools
import math
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

import numpy as np

from .shaped import DipoleMagnet, ObliqueSprings, RodFrame, ShapedLaw, Spline

COULOMB_VELOCITY_SCALE = 1e-3
"""Velocity [m/s] over which a smoothed-sign (Coulomb) force changes sign (tanh smoothing)."""


def _signed_power(x: np.ndarray, power: int, odd: bool, product: bool = False) -> np.ndarray:
    """|x|^power sgn(x)^odd: numpy's power, or with ``product`` the product of the factors x x x ... (as
    pysindy's PolynomialLibrary forms its columns); |x| for the factors where the parity needs it. (The
    two differ in the last bit from the cube on; the library keeps each column as it was computed before
    the registry, so that every fit, and every number of the reference report, stays bit for bit).
    """
    if power == 0:
        return np.ones_like(x)
    base = x if odd == bool(power % 2) else np.abs(x)
    if product:
        out = base
        for _ in range(power - 1):
            out = out * base
    else:
        out = base**power
    if odd and not power % 2:
        out = out * np.sign(x)
    return out


def _label(var: str, power: int, odd: bool) -> str:
    if power == 0:
        return ""
    if odd == bool(power % 2):
        return var if power == 1 else f"{var}^{power}"
    if power == 1:
        return f"|{var}|"
    return f"{var}|{var}|" if power == 2 else (f"{var}|{var}|^{power - 1}" if odd else f"|{var}|^{power}")


@dataclass(frozen=True)
class Monomial:
    """Force law a |z|^z_power sgn(z)^z_odd |z'|^v_power sgn(z')^v_odd (a [N per unit of the term])."""

    z_power: int = 0
    z_odd: bool = False
    v_power: int = 0
    v_odd: bool = False

    def __post_init__(self):
        for p, odd in ((self.z_power, self.z_odd), (self.v_power, self.v_odd)):
            if not (isinstance(p, int) and 0 <= p <= 9):
                raise ValueError(f"a monomial's powers are integers 0..9, got {p!r}")
            if odd and p == 0:
                raise ValueError("a bare sign is not a monomial (use SmoothSign)")

    @property
    def label(self) -> str:
        """The library term's name (z^4, v^3, v|v|, |z|, z^2 v, ...)."""
        zs, vs = _label("z", self.z_power, self.z_odd), _label("v", self.v_power, self.v_odd)
        return " ".join(s for s in (zs, vs) if s) or "1"

    @property
    def displacement_only(self) -> bool:
        """Whether the law depends on z alone (no velocity)."""
        return self.v_power == 0

    def force(self, value: float, z, v):
        """The force [N] of the law at size ``value`` and states ``z``, ``v``."""
        z, v = np.asarray(z, float), np.asarray(v, float)
        return value * _signed_power(z, self.z_power, self.z_odd) * _signed_power(v, self.v_power, self.v_odd)

    def potential(self, value: float, z):
        """int_0^z of the force (displacement-only laws): |z|^(p+1)/(p+1) times sgn(z) when the force is even."""
        z = np.asarray(z, float)
        p = self.z_power
        return value * _signed_power(z, p + 1, not self.z_odd) / (p + 1)

    def column(self, z, v, velocity_noise: float):
        """The library column: the law at unit value, its z factor as a product (module docstring of
        ``_signed_power``), its z' factor as numpy's power.
        """
        z, v = np.asarray(z, float), np.asarray(v, float)
        return _signed_power(z, self.z_power, self.z_odd, product=True) * _signed_power(v, self.v_power, self.v_odd)

    def scale(self, z_rms: float, v_rms: float) -> float:
        """The term's size at the record's rms state (the refinement's parameter scale)."""
        return z_rms**self.z_power * v_rms**self.v_power


@dataclass(frozen=True)
class SmoothSign:
    """Force law F tanh(z' / v_s) (Coulomb friction; F [N], v_s = ``COULOMB_VELOCITY_SCALE``)."""

    label = "sgn(v)"
    displacement_only = False

    def force(self, value: float, z, v):
        """The force [N]: ``value tanh(v / COULOMB_VELOCITY_SCALE)``."""
        return value * np.tanh(np.asarray(v, float) / COULOMB_VELOCITY_SCALE)

    def column(self, z, v, velocity_noise: float):
        """In the library, the expected sign of the true velocity given the estimated one,
        erf(z' / (sqrt(2) s_n)), s_n the velocity noise (at least v_s): ``inference.weak``.
        """
        from scipy import special

        scale = math.sqrt(2) * max(velocity_noise, COULOMB_VELOCITY_SCALE)
        return special.erf(np.asarray(v, float) / scale)

    def scale(self, z_rms: float, v_rms: float) -> float:
        """The term's typical size per unit value (1: the force is ``value`` at most)."""
        return 1.0


@dataclass(frozen=True)
class OneSidedStop:
    """Force law k (z - z_s) for z beyond z_s on z_s's side, zero before it (``{"k": N/m, "z": m}``)."""

    label = None  # no fixed library column: z_s is a nonlinear parameter (searched, then one column)
    displacement_only = True
    fields = ("k", "z")

    @staticmethod
    def check(name: str, value: dict[str, float]) -> Mapping[str, float]:
        """The law's own admissible values (finite numbers already): a stiffness k >= 0, a stop z != 0."""
        if value["k"] < 0 or value["z"] == 0:
            raise ValueError(f"{name} needs k >= 0 and a stop position z != 0")
        return MappingProxyType(value)

    @staticmethod
    def beyond(z, z_s: float):
        """Where ``z`` lies beyond the stop's onset ``z_s`` (on the side of its sign)."""
        return (np.asarray(z, float) - z_s) * np.sign(z_s) > 0

    def force(self, value: Mapping[str, float], z, v=None):
        """The stop's force [N]: ``k (z - z_s)`` beyond the onset, 0 before it."""
        z = np.asarray(z, float)
        return value["k"] * np.where(self.beyond(z, value["z"]), z - value["z"], 0.0)

    def potential(self, value: Mapping[str, float], z):
        """The stop's potential [J]: ``k (z - z_s)^2 / 2`` beyond the onset."""
        z = np.asarray(z, float)
        return 0.5 * value["k"] * np.where(self.beyond(z, value["z"]), (z - value["z"]) ** 2, 0.0)

    def column(self, z, z_s: float):
        """The library column of a stop at z_s (unit stiffness)."""
        return self.force({"k": 1.0, "z": z_s}, z)

    def parameters(self, value: Mapping[str, float]) -> dict[str, float]:
        """The value's parameters as flat named numbers (refinement, posterior): ``k`` and ``z``."""
        return {f: float(value[f]) for f in self.fields}

    def with_parameters(self, value: Mapping[str, float], params: Mapping[str, float]) -> dict[str, float]:
        """``value`` with some of its parameters replaced."""
        return {**dict(value), **{k: float(v) for k, v in params.items()}}


@dataclass(frozen=True)
class MeasuredChannel:
    """Force law theta a(t) of a measured auxiliary channel a(t) (a harvester's piezo voltage: the
    electromechanical coupling): no function of the state, so no kernel row and no library column of z,
    z'; it drives the model through the record's input (``Measurement.driving``). Named ``aux:CHANNEL``.
    """

    channel: str
    label = None
    displacement_only = False


AUX_PREFIX = "aux:"
"""The name of a measured channel's term: ``aux:CHANNEL`` (``aux:voltage``)."""


def measured_channels(extra: Mapping[str, Any]) -> dict[str, float]:
    """The measured channels an ``extra`` mapping has terms in: {channel: theta} of its ``aux:CHANNEL``."""
    return {k[len(AUX_PREFIX) :]: float(v) for k, v in extra.items() if k.startswith(AUX_PREFIX)}


def measured_channel(name: str) -> Effect:
    """The term of a measured auxiliary channel, ``aux:CHANNEL``; its value theta [N per channel unit]."""
    channel = name[len(AUX_PREFIX) :]
    if not channel:
        raise ValueError(f"extra effect {name!r}: name the channel after {AUX_PREFIX!r} (aux:voltage)")
    return Effect(name, MeasuredChannel(channel), "N per channel unit")


@dataclass(frozen=True)
class Effect:
    """One registry entry: the name a model file uses, the force law, the value's units, and whether it is
    ``catalogued``: a term of the default library (SINDy's) and a candidate of the discrepancy workflow's
    catalogue. A law's own part (a magnet's dipole, a spline, the septic term) is not: a law names it
    (``models.laws``), and every method reads it there.
    """

    name: str
    law: Monomial | SmoothSign | OneSidedStop | MeasuredChannel | ShapedLaw
    units: str
    catalogued: bool = True

    @property
    def n_values(self) -> int:
        """The number of values the effect takes (an end stop: k and z)."""
        return len(getattr(self.law, "fields", ())) or 1

    @property
    def scalar(self) -> bool:
        """Whether the effect takes one number."""
        return not hasattr(self.law, "fields")

    @property
    def dissipative(self) -> bool:
        """A force odd in the velocity alone (friction, velocity-power damping): a physical device's value
        is >= 0 (a negative one feeds energy in); a fitted model's may not be.
        """
        law = self.law
        return isinstance(law, SmoothSign) or (isinstance(law, Monomial) and law.z_power == 0 and law.v_odd)

    @property
    def folds_into(self) -> str | None:
        """The base field whose term this effect's law is (k2, k3, c_nl), or None."""
        return next((f for f, (law, _) in BASE_TERMS.items() if law == self.law), None)

    def value(self, raw: Any) -> Any:
        """Validate a model file's value: a finite number, or the law's fields (the stop's ``{"k", "z"}``),
        each finite, then the law's own ``check``.
        """
        if self.scalar:
            return finite(self.name, raw)
        law = self.law
        assert isinstance(law, OneSidedStop | ShapedLaw)  # the laws with fields
        fields = law.fields
        if not isinstance(raw, Mapping) or set(raw) != set(fields):
            raise ValueError(f"extra effect {self.name} takes {{{', '.join(repr(f) for f in fields)}}} ({self.units})")

        def number_or_list(f: str, x: Any) -> Any:
            if isinstance(x, list | tuple | np.ndarray):
                return tuple(finite(f"{self.name}.{f}[{i}]", xi) for i, xi in enumerate(x))
            return finite(f"{self.name}.{f}", x)

        return law.check(self.name, {f: number_or_list(f, raw[f]) for f in fields})

    def help(self) -> str:
        """``name`` or ``name=k:N/m,z:m`` for the CLI."""
        if self.scalar:
            return self.name
        assert isinstance(self.law, OneSidedStop | ShapedLaw)
        pairs = zip(self.law.fields, self.units.split(", "), strict=True)
        return f"{self.name}=" + ",".join(f"{f}:{u}" for f, u in pairs)


def finite(name: str, value: Any) -> float:
    """A model parameter as a finite float, or a one-line ValueError."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f"model parameter {name} must be a number, got {value!r}")
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f"model parameter {name} is not finite ({value})")
    return value


BASE_TERMS: Mapping[str, tuple[Monomial, float]] = MappingProxyType(
    {
        "k0": (Monomial(), -1.0),
        "k1": (Monomial(1, True), 1.0),
        "k2": (Monomial(2), -1.0),
        "k3": (Monomial(3, True), -1.0),
        "c": (Monomial(0, False, 1, True), -1.0),
        "c_nl": (Monomial(0, False, 2, True), -1.0),
    }
)
"""The model file's base fields as library terms, and the sign of each field relative to -m times the
term's coefficient in z'' (K holds -k1 z, so k1 = +m coefficient)."""

REGISTRY: list[Effect] = [
    Effect("coulomb_friction", SmoothSign(), "N"),
    Effect("quadratic_damping", Monomial(0, False, 2, True), "N s^2/m^2"),
    Effect("cubic_damping", Monomial(0, False, 3, True), "N s^3/m^3"),
    Effect("quadratic_stiffness", Monomial(2), "N/m^2"),
    Effect("cubic_stiffness", Monomial(3, True), "N/m^3"),
    Effect("quartic_stiffness", Monomial(4), "N/m^4"),
    Effect("quintic_stiffness", Monomial(5, True), "N/m^5"),
    Effect("end_stop", OneSidedStop(), "N/m, m"),
    # the laws' own parts (``models.laws``): not in the default library or the discrepancy's catalogue
    Effect("sextic_stiffness", Monomial(6), "N/m^6", catalogued=False),
    Effect("septic_stiffness", Monomial(7, True), "N/m^7", catalogued=False),
    Effect("magnet", DipoleMagnet(), "N m^4, m", catalogued=False),
    Effect("oblique_springs", ObliqueSprings(), "N, m", catalogued=False),
    Effect("rod_frame", RodFrame(), "N/m, m, m, deg", catalogued=False),
    Effect("spline", Spline(), "m, N", catalogued=False),
]
"""The effects a model file may name, in the order the CLI lists them."""


def names() -> tuple[str, ...]:
    """The registered effects' names."""
    return tuple(e.name for e in REGISTRY)


def get(name: str) -> Effect:
    """The effect named ``name`` (an ``aux:`` name: a measured channel); ``KeyError`` otherwise."""
    if name.startswith(AUX_PREFIX):
        return measured_channel(name)
    for e in REGISTRY:
        if e.name == name:
            return e
    raise ValueError(f"unknown extra effect {name!r}; known: {', '.join(names())}")


@contextlib.contextmanager
def registered(*effects: Effect):
    """Add effects to the registry for the duration of a ``with`` block (tests, experiments)."""
    with registered_in(REGISTRY, effects, names(), "an effect", layout.cache_clear):
        yield effects


@contextlib.contextmanager
def registered_in(registry: list, items, known, what: str, changed=lambda: None):
    """Add named ``items`` to ``registry`` for a ``with`` block (an effect's, a law's), refusing a name in
    ``known``; ``changed`` runs after each change (a cached layout cleared).
    """
    for item in items:
        if item.name in known:
            raise ValueError(f"{what} named {item.name!r} is registered already")
    registry.extend(items)
    try:
        changed()
        yield items
    finally:
        for item in items:
            registry.remove(item)
        changed()


# --- forces and potentials of an ``extra`` mapping ---------------------------------------------------
def normalise(extra: Mapping[str, Any] | None) -> Mapping[str, Any]:
    """Validate an ``extra`` mapping and return it read-only (scalars as float, the stop as a mapping)."""
    return MappingProxyType({name: get(name).value(value) for name, value in dict(extra or {}).items()})


def plain(extra: Mapping[str, Any]) -> dict[str, Any]:
    """An ``extra`` mapping as plain dicts (what ``normalise`` made read-only), for pickling and JSON."""
    return {k: dict(v) if isinstance(v, Mapping) else v for k, v in extra.items()}


def force(extra: Mapping[str, Any], z, zdot):
    """Force of the extra effects [N] at displacement ``z`` [m] and velocity ``zdot`` [m/s]."""
    z, zdot = np.asarray(z, float), np.asarray(zdot, float)
    f = np.zeros(np.broadcast(z, zdot).shape)
    for e in REGISTRY:
        if e.name in extra and not isinstance(e.law, MeasuredChannel) and not e.law.displacement_only:
            f = f + e.law.force(extra[e.name], z, zdot)
    return f + stiffness_force(extra, z)


def stiffness_force(extra: Mapping[str, Any], z):
    """The displacement-only part of the extra effects [N] (it belongs to the restoring force)."""
    z = np.asarray(z, float)
    f = np.zeros(z.shape)
    for e in REGISTRY:
        if e.name in extra and not isinstance(e.law, MeasuredChannel) and e.law.displacement_only:
            f = f + e.law.force(extra[e.name], z, 0.0)
    return f


def stiffness_potential(extra: Mapping[str, Any], z):
    """Potential energy [J] of the displacement-only extra effects, zero at z = 0."""
    z = np.asarray(z, float)
    u = np.zeros(z.shape)
    for e in REGISTRY:
        if e.name in extra and isinstance(e.law, Monomial | OneSidedStop | ShapedLaw) and e.law.displacement_only:
            u = u + e.law.potential(extra[e.name], z)
    return u


# --- the simulator's parameter layout ------------------------------------------------------------------
ROWS: Mapping[str, int] = MappingProxyType(
    {"m": 0, "c": 7, "c_nl": 8, "sign": 9, "v^3": 10, "z^2": 11, "z^3": 12, "z^4": 13, "z^5": 14, "stop_k": 15,
     "stop_z": 16}
)  # fmt: skip
"""Named rows of the kernel parameter vector both restoring-force kinds share (rows 1-6 are the
restoring force's own: k0..k3 for a polynomial, the geometry for the device). A monomial whose label
names a row is evaluated there, branch-free."""
N_FIXED = 17
POLYNOMIAL_ROWS: Mapping[str, int] = MappingProxyType({"k0": 1, "k1": 2, "k2": 3, "k3": 4})
"""The polynomial restoring force's rows [N, N/m, N/m^2, N/m^3]."""
DEVICE_ROWS: Mapping[str, int] = MappingProxyType({"k_f": 1, "L": 2, "alpha": 3, "D0": 4, "g": 5})
"""The device's rows: arm stiffness [N/m], rod length [m], frame angle [rad], pre-compression [m], g [m/s^2]."""


@dataclass(frozen=True)
class Layout:
    """The kernel parameter vector: its size, the row each effect writes, and the extra monomial rows
    (``monomials``: one (row, z_power, z_odd, v_power, v_odd) per effect with no fixed row).
    """

    size: int
    rows: Mapping[str, tuple[int, ...]]
    monomials: np.ndarray


def _fixed_rows(e: Effect) -> tuple[int, ...] | None:
    if isinstance(e.law, SmoothSign):
        return (ROWS["sign"],)
    if isinstance(e.law, OneSidedStop):
        return ROWS["stop_k"], ROWS["stop_z"]
    label, folds = e.law.label, e.folds_into
    if label is not None and label in ROWS:
        return (ROWS[label],)
    return (ROWS[folds],) if folds is not None and folds in ROWS else None


@functools.lru_cache(maxsize=1)
def layout() -> Layout:
    """The kernel's parameter layout of every registered effect."""
    rows: dict[str, tuple[int, ...]] = {}
    mono: list[tuple[int, int, int, int, int]] = []
    used: dict[int, str] = {}
    for e in REGISTRY:
        if isinstance(e.law, ShapedLaw):  # evaluated from the model's table (``tabulate``), no row of its own
            rows[e.name] = ()
            continue
        fixed = _fixed_rows(e)
        if fixed is None:
            r = N_FIXED + len(mono)
            law = e.law
            assert isinstance(law, Monomial)  # a sign, a stop or a channel has its fixed rows
            mono.append((r, law.z_power, int(law.z_odd), law.v_power, int(law.v_odd)))
            fixed = (r,)
        elif not isinstance(e.law, Monomial):  # a monomial may share a row (it adds); a sign or stop may not
            clash = [used[r] for r in fixed if r in used]
            if clash:
                raise ValueError(f"effects {clash[0]} and {e.name} both need the kernel's {type(e.law).__name__} row")
        for r in fixed:
            used.setdefault(r, e.name)
        rows[e.name] = fixed
    table = np.array(mono, dtype=np.int64).reshape(-1, 5)
    return Layout(N_FIXED + len(mono), MappingProxyType(rows), table)


def kernel_rows(m: float, c: float, c_nl: float, extra: Mapping[str, Any]) -> np.ndarray:
    """The kernel parameter vector with the rows both restoring-force kinds share filled in (mass,
    damping, every effect); the caller writes the restoring force's rows 1-6.
    """
    lay = layout()
    p = np.zeros(lay.size)
    p[ROWS["m"]], p[ROWS["c"]], p[ROWS["c_nl"]] = m, c, c_nl
    for name, value in extra.items():
        if name.startswith(AUX_PREFIX):  # a measured channel's term drives through the input, not a row
            continue
        rows = lay.rows[name]
        if len(rows) == 1:
            p[rows[0]] += value
        elif len(rows) == 2:
            p[rows[0]], p[rows[1]] = value["k"], value["z"]
    table = tabulate(extra)
    return p if table is None else np.concatenate([p, table])


TABLE_KNOTS = 257
"""Knots of the simulator's table of a model's shaped parts (``tabulate``): the cubic Hermite interpolant of the
force and stiffness at the knots errs by at most h^4 max|F^(4)| / 384 (h the knot spacing), 1e-10 of a magnet's
force over +-8 gaps."""
TABLE_ROWS = 3 + 4 * (TABLE_KNOTS + 1)
"""Rows the table adds after the layout's: its first knot [m], the inverse knot spacing [1/m], the last knot's
index, then four polynomial coefficients [N] (in t, knot spacings from the segment's start) for each segment: the
tangent line below the first knot, the Hermite cubic of each interval, the tangent line beyond the last knot."""


def shaped_parts(extra: Mapping[str, Any]) -> list[tuple[ShapedLaw, Mapping[str, Any]]]:
    """The model's shaped parts (``models.shaped``) with their values, in the registry's order."""
    return [(e.law, extra[e.name]) for e in REGISTRY if e.name in extra and isinstance(e.law, ShapedLaw)]


def tabulate(extra: Mapping[str, Any]) -> np.ndarray | None:
    """The table the simulator's kernel interpolates for the model's shaped parts (``TABLE_ROWS``): their total
    force and stiffness at ``TABLE_KNOTS`` knots evenly spread over the hull of their spans, continued by the end
    knots' tangent lines beyond it (as a spline's own force is); None without shaped parts.

    A law without a compiled row costs one table look-up and a cubic per force evaluation, whatever its formula:
    that is what lets any law be simulated at about the polynomial's speed (``benchmarks``).
    """
    parts = shaped_parts(extra)
    if not parts:
        return None
    table = tabulate_members(parts)
    if not np.all(np.isfinite(table)):
        names = ", ".join(type(law).__name__ for law, _ in parts)
        raise ValueError(f"a shaped force law ({names}) is not finite over its span")
    return table[:, 0]


def tabulate_members(parts: list[tuple[ShapedLaw, Mapping[str, Any]]]) -> np.ndarray:
    """The simulator's tables (``tabulate``) of a batch of B members at once, (``TABLE_ROWS``, B): one table per
    member, its knots over the hull of that member's spans, every part's force and stiffness evaluated for the
    whole batch in one call (a posterior's walkers, a GA's population).

    Each part's value holds its fields as a batch of values (``models.shaped``): a field of shape (B, 1) (a
    spline's coefficients (B, 1, n)) is one value per member, a number (or a spline's knots) is shared. One value
    per part gives B = 1. A member whose parts are not finite over its span (a rod shorter than its offset) has
    a table of NaN there: the caller decides what it means (a posterior: outside the prior's support).
    """
    spans = [law.span(value) for law, value in parts]
    lo = np.asarray(spans[0][0], float)
    hi = np.asarray(spans[0][1], float)
    for a, b in spans[1:]:
        lo, hi = np.minimum(lo, a), np.maximum(hi, b)
    lo, hi = np.atleast_1d(lo.reshape(-1)), np.atleast_1d(hi.reshape(-1))  # (B,) or (1,): the batch's first axis
    z = np.linspace(lo, hi, TABLE_KNOTS, axis=-1)  # (B, knots): each member its own (or one for all)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        forces = [law.force(value, z) for law, value in parts]
        slopes = [law.stiffness(value, z) for law, value in parts]
        shape = np.broadcast_shapes(z.shape, *(np.shape(x) for x in forces + slopes))  # (B, knots)
        n = shape[0]
        lo, hi = np.broadcast_to(lo, (n,)), np.broadcast_to(hi, (n,))
        h = (hi - lo) / (TABLE_KNOTS - 1)
        f, d = np.zeros(shape), np.zeros(shape)
        for x in forces:
            f = f + x
        for x in slopes:
            d = d + x
        d = h[:, None] * d
        df = f[:, 1:] - f[:, :-1]
        # each member's segments (B, knots + 1, 4): the tangent line below the first knot, the Hermite cubic of each
        # interval, the tangent line beyond the last knot
        cubic = np.stack([f[:, :-1], d[:, :-1], 3 * df - 2 * d[:, :-1] - d[:, 1:], d[:, :-1] + d[:, 1:] - 2 * df], -1)
    zero = np.zeros_like(f[:, 0])
    first = np.stack([f[:, 0], d[:, 0], zero, zero], axis=-1)[:, None]
    last = np.stack([f[:, -1], d[:, -1], zero, zero], axis=-1)[:, None]
    segments = np.concatenate([first, cubic, last], axis=1).reshape(n, -1)
    head = np.column_stack([lo, 1.0 / h, np.full(n, float(TABLE_KNOTS - 1))])
    return np.ascontiguousarray(np.concatenate([head, segments], axis=1).T)


# --- the identification library ---------------------------------------------------------------------
@dataclass(frozen=True)
class Term:
    """A library column: its label, the law it evaluates and what it maps to (a base field, with the
    sign of the field relative to -m times the coefficient, or an effect, sign -1).
    """

    label: str
    law: Monomial | SmoothSign
    field: str
    sign: float


def library_terms() -> tuple[Term, ...]:
    """The library: the base fields' terms and every effect with a column of its own; displacement
    terms first (base, then effects by power), then velocity and mixed terms (base, monomials, then the
    sign), so a term's position is stable when effects are added.
    """
    base = [Term(law.label, law, f, s) for f, (law, s) in BASE_TERMS.items()]
    own = [Term(e.law.label, e.law, e.name, -1.0) for e in REGISTRY
           if e.catalogued and isinstance(e.law, Monomial | SmoothSign) and e.folds_into is None]  # fmt: skip

    def key(t: Term):
        is_base = t.field in BASE_TERMS
        group = 0 if t.law.displacement_only else 1
        rank = (0, t.law.z_power, t.law.v_power) if isinstance(t.law, Monomial) else (1, 0, 0)
        return (group, not is_base, rank if not is_base else (0, 0, 0))

    return tuple(sorted(base + own, key=key))
