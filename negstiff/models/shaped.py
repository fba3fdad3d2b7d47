"""Restoring-force parts with a shape: forces of z linear in some parameters and nonlinear in the others.

A shaped part's force is linear in its coefficients and nonlinear in its shape,

    F(z) = sum_j a_j phi_j(z; s),        a: coefficients,  s: shape,

so that, the shape given, every identification method reads the part as columns phi_j (NSI's basis, SINDy's
library, a least-squares fit), and the shape is searched around them (variable projection: Golub & Pereyra
1973, "The differentiation of pseudo-inverses and nonlinear least squares problems whose variables separate",
SIAM J. Numer. Anal. 10:413). A model file names a part under its registry entry (``effects.REGISTRY``) with the
part's fields (``{"magnet": {"A": ..., "d": ...}}``).

The parts:

* ``DipoleMagnet``: two facing magnets as point dipoles. A cantilever's tip magnet displaced by z across a fixed
  magnet at a gap d has the interaction energy U = A / (d^2 + z^2)^(3/2) (A > 0: repulsion), a force
  dU/dz = -3 A z / (d^2 + z^2)^(5/2): a negative stiffness near z = 0 that vanishes far from it, which the beam's
  own stiffness turns into two wells (Moon & Holmes 1979, J. Sound Vib. 65:275; the point-dipole form of the
  bistable harvesters, Mann & Owens 2010, J. Sound Vib. 329:1215; Stanton, McGehee & Mann 2010, Physica D
  239:640, whose full dipole-dipole energy differs by the moments' orientation term).
* ``ObliqueSprings``: two springs of stiffness k, free length L0, hinged at a half-span a from the axis of
  motion, push with 2 k z (1 - L0 / sqrt(a^2 + z^2)), the quasi-zero-stiffness isolator's negative-stiffness
  mechanism (Carrella, Brennan & Waters 2007, J. Sound Vib. 301:678, Eq. 2): a linear spring 2 k z (a model's k1)
  and this part, -2 P z / sqrt(a^2 + z^2) with P = k L0.
* ``RodFrame``: the reference study's device, the exact rod-frame geometry of ``docs/device-model.md``:
  F = 2 k_f (s + D0) s'(z), s = -B + sqrt(B^2 - z^2), B = L cos(alpha) - z sin(alpha); linear in k_f and
  k_f D0, its shape the rod length L and the frame angle alpha.
* ``Spline``: a smooth force with no formula, a cubic B-spline over the record's stroke continued by straight
  lines beyond it (de Boor 1978, "A Practical Guide to Splines"; scipy's ``BSpline``), its knots spaced evenly
  over the stroke and their number chosen by the data (``inference.steps.law_fit``).

Every part evaluates for arrays of values (a batch of posterior draws or a GA population: fields of shape (B, 1)
against z of shape (T,) give (B, T)), gives its force, stiffness and potential (closed forms where they exist),
and its ``span``: the z range where the part acts, over which the simulator tabulates it (``effects.tabulate``)
and equilibria are sought.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np


def rod_geometry(z, L, ca, sa, second: bool = True):
    """s(z), s'(z), s''(z) of the rod-frame geometry for a frame of length L at angle alpha (ca, sa: its
    cosine and sine; arrays broadcast against z); s'' None without ``second``.
    """
    B = L * ca - z * sa
    R = np.sqrt(B * B - z * z)
    s = R - B
    q = B * sa + z
    s1 = sa - q / R
    if not second:
        return s, s1, None
    s2 = -(ca * ca * R * R + q * q) / R**3
    return s, s1, s2


def rod_reach(L, alpha_rad) -> tuple[Any, Any]:
    """The open interval of z [m] the rods of length L at frame angle alpha can reach (B^2 > z^2)."""
    ca, sa = np.cos(alpha_rad), np.sin(alpha_rad)
    return -L * ca / (1 - sa), L * ca / (1 + sa)


def _number(x) -> Any:
    """A 0-d value as a float, an array of values (a batch's) as an array: a span of one value is two numbers."""
    return float(x) if np.ndim(x) == 0 else np.asarray(x, float)


class ShapedLaw:
    """A displacement force linear in its coefficients and nonlinear in its shape (module docstring).

    A subclass names its ``fields`` (a model file's mapping), which of them are the ``shape``, and writes
    ``columns`` (the phi_j at a shape) and the map between its fields and its coefficients a_j.
    """

    label: ClassVar[str | None] = None  # no fixed library column: its columns depend on the shape
    displacement_only: ClassVar[bool] = True
    fields: ClassVar[tuple[str, ...]] = ()
    shape: ClassVar[tuple[str, ...]] = ()
    bounds: ClassVar[dict[str, tuple[float, float]]] = {}
    """Each field's physically admissible open interval (``check``'s ranges), where it has one: a prior's box."""
    centred: ClassVar[bool] = False
    """Whether the part's force is odd about its own z = 0, a centre a record's frame need not share (facing
    magnets, a pair of oblique springs: their centre is where the lab's z is zero only by construction)."""
    parameters_compared: ClassVar[bool] = True
    """Whether two fits' parameters of the part mean the same thing, to be compared one by one (a spline's do not:
    its coefficients weigh basis functions on knots each fit chooses; its force is compared instead)."""

    # --- the part's algebra (subclasses) ------------------------------------------------------------
    def columns(self, shape: Mapping[str, Any], z) -> list[np.ndarray]:
        """The columns phi_j(z; shape), one array each (the shape's fields broadcast against z)."""
        raise NotImplementedError

    def coefficients(self, value: Mapping[str, Any]) -> list[np.ndarray]:
        """The coefficients a_j of a value, one array each (broadcasting as the value's fields do)."""
        raise NotImplementedError

    def value_of(self, shape: Mapping[str, Any], coefficients) -> dict[str, Any]:
        """The value (fields) of a shape and coefficients a_j."""
        raise NotImplementedError

    def span(self, value: Mapping[str, Any]) -> tuple[float, float]:
        """The z range [m] where the part acts (tabulated by the simulator, searched for equilibria)."""
        raise NotImplementedError

    def shape_bounds(self, stroke: tuple[float, float]) -> dict[str, tuple[float, float]]:
        """Admissible values of each shape field for a record whose z spans ``stroke`` [m] (the search's box)."""
        raise NotImplementedError

    def shape_guesses(self, stroke: tuple[float, float]) -> list[dict[str, float]]:
        """Starting shapes for the search over a record whose z spans ``stroke`` [m]."""
        raise NotImplementedError

    # --- shared ------------------------------------------------------------------------------------
    def shape_of(self, value: Mapping[str, Any]) -> dict[str, Any]:
        """The shape fields of a value."""
        return {k: value[k] for k in self.shape}

    def column_matrix(self, shape: Mapping[str, Any], z) -> np.ndarray:
        """The columns at one shape as a matrix (T, n): a least-squares problem's."""
        z = np.asarray(z, float)
        return np.column_stack([np.broadcast_to(c, z.shape) for c in self.columns(shape, z)])

    def force(self, value: Mapping[str, Any], z, v=None):
        """The part's force [N] at z [m]: sum_j a_j phi_j."""
        z = np.asarray(z, float)
        cols = self.columns(self.shape_of(value), z)
        return sum(a * c for a, c in zip(self.coefficients(value), cols, strict=True))

    def stiffness(self, value: Mapping[str, Any], z):
        """dF/dz [N/m] (central differences of ``force`` unless a subclass knows it in closed form)."""
        z = np.asarray(z, float)
        lo, hi = self.span(value)
        h = 1e-6 * max(hi - lo, 1e-9)
        return (self.force(value, z + h) - self.force(value, z - h)) / (2 * h)

    def potential(self, value: Mapping[str, Any], z):
        """int_0^z F dz [J] (Gauss-Legendre quadrature of ``force`` unless known in closed form)."""
        z = np.asarray(z, float)
        x, w = np.polynomial.legendre.leggauss(24)
        nodes = 0.5 * z[..., None] * (x + 1.0)
        f = self.force(value, nodes.reshape(-1)).reshape(nodes.shape)
        return 0.5 * z * np.sum(w * f, axis=-1)

    def check(self, name: str, value: Mapping[str, Any]) -> Mapping[str, Any]:
        """The part's admissible values (finite numbers already): subclasses add their physics."""
        return MappingProxyType(dict(value))

    def parameters(self, value: Mapping[str, Any]) -> dict[str, float]:
        """The value's parameters as flat named numbers (refinement, posterior): its fields."""
        return {k: float(value[k]) for k in self.fields}

    def with_parameters(self, value: Mapping[str, Any], params: Mapping[str, float]) -> dict[str, Any]:
        """``value`` with some of its ``parameters`` replaced."""
        return {**dict(value), **{k: float(v) for k, v in params.items()}}

    def batch(self, value: Mapping[str, Any], params: Mapping[str, np.ndarray]) -> dict[str, Any]:
        """A batch of B values: ``value`` with some of its ``parameters`` given one number per member (arrays of
        shape (B,)), as the part's methods take a batch (fields of shape (B, 1), broadcasting against z of shape
        (T,) or (B, T)); the others shared. ``with_parameters`` for a posterior's walkers or a GA's population.
        """
        return {**dict(value), **{k: np.asarray(v, float)[:, None] for k, v in params.items()}}

    def scale(self, value: Mapping[str, Any], z_rms: float) -> dict[str, float]:
        """Each parameter's natural size at a record's rms displacement (refinement's scaling)."""
        return {k: max(abs(float(value[k])), 1e-12) for k in self.fields}


class WidthShaped(ShapedLaw):
    """A part with one coefficient (``fields[0]``) and a shape of one width w > 0 (``shape[0]``: a magnets' gap, the
    springs' half-span) that its force decays or saturates over: it acts within +-``SPAN_WIDTHS`` widths, the
    search looks between ``WIDTH_BOUNDS`` half-strokes (``inference.steps.shape``: a grid across them, then Brent),
    and its starting shapes are ``WIDTH_GUESSES`` half-strokes (a subclass sets them).
    """

    SPAN_WIDTHS: ClassVar[float] = 8.0
    WIDTH_BOUNDS: ClassVar[tuple[float, float]] = (0.1, 5.0)
    WIDTH_GUESSES: ClassVar[tuple[float, ...]] = (0.5, 1.0, 2.0)
    WIDTH_WORD: ClassVar[str] = "width"

    def span(self, value):
        """+-``SPAN_WIDTHS`` widths, per member of a batch."""
        w = np.asarray(value[self.shape[0]], float)
        return _number(-self.SPAN_WIDTHS * w), _number(self.SPAN_WIDTHS * w)

    def check(self, name, value):
        """A width > 0."""
        w = self.shape[0]
        if not value[w] > 0:
            raise ValueError(f"{name} needs a {self.WIDTH_WORD} {w} > 0 [m], got {value[w]}")
        return MappingProxyType(dict(value))

    def shape_bounds(self, stroke):
        """The width between ``WIDTH_BOUNDS`` half-strokes."""
        half = 0.5 * (stroke[1] - stroke[0])
        return {self.shape[0]: (self.WIDTH_BOUNDS[0] * half, self.WIDTH_BOUNDS[1] * half)}

    def shape_guesses(self, stroke):
        """Widths of ``WIDTH_GUESSES`` half-strokes."""
        half = 0.5 * (stroke[1] - stroke[0])
        return [{self.shape[0]: f * half} for f in self.WIDTH_GUESSES]

    def coefficients(self, value):
        """(the one coefficient,)."""
        return [np.asarray(value[self.fields[0]], float)]

    def value_of(self, shape, coefficients):
        """The value of the width and the one coefficient."""
        return {self.fields[0]: float(coefficients[0]), self.shape[0]: float(shape[self.shape[0]])}


@dataclass(frozen=True)
class DipoleMagnet(WidthShaped):
    """Facing magnets as point dipoles: F = -3 A z / (d^2 + z^2)^(5/2) [N] (``{"A": N m^4, "d": m}``)."""

    fields: ClassVar[tuple[str, ...]] = ("A", "d")
    shape: ClassVar[tuple[str, ...]] = ("d",)
    bounds: ClassVar[dict[str, tuple[float, float]]] = {"d": (0.0, np.inf)}
    centred: ClassVar[bool] = True
    # beyond +-8 gaps the force is below 1e-3 of its peak (it decays as z^-4); a harvester's wells lie near d / 2 to d
    WIDTH_WORD: ClassVar[str] = "gap"

    def columns(self, shape, z):
        """The one column -3 z / (d^2 + z^2)^(5/2) [m^-4]."""
        d = np.asarray(shape["d"], float)
        return [-3.0 * z / (d * d + z * z) ** 2.5]

    def stiffness(self, value, z):
        """dF/dz = -3 A (d^2 - 4 z^2) / (d^2 + z^2)^(7/2)."""
        z = np.asarray(z, float)
        A, d = np.asarray(value["A"], float), np.asarray(value["d"], float)
        return -3.0 * A * (d * d - 4.0 * z * z) / (d * d + z * z) ** 3.5

    def potential(self, value, z):
        """A ((d^2 + z^2)^(-3/2) - d^-3) [J], zero at z = 0."""
        z = np.asarray(z, float)
        A, d = np.asarray(value["A"], float), np.asarray(value["d"], float)
        return A * ((d * d + z * z) ** -1.5 - d**-3.0)


@dataclass(frozen=True)
class ObliqueSprings(WidthShaped):
    """Two oblique springs' negative stiffness: F = -2 P z / sqrt(a^2 + z^2) [N] (``{"P": N, "a": m}``).

    Two springs of stiffness k and free length L0, hinged at a half-span a from the axis of motion, push with
    2 k z (1 - L0 / sqrt(a^2 + z^2)) (Carrella, Brennan & Waters 2007, Eq. 2): the 2 k z is a linear spring (a
    model's k1 holds it with any other spring in parallel), the rest this part, with P = k L0.
    """

    fields: ClassVar[tuple[str, ...]] = ("P", "a")
    shape: ClassVar[tuple[str, ...]] = ("a",)
    bounds: ClassVar[dict[str, tuple[float, float]]] = {"a": (0.0, np.inf)}
    centred: ClassVar[bool] = True
    # beyond +-8 half-spans the part's stiffness is below 1/500 of its value at z = 0
    WIDTH_BOUNDS: ClassVar[tuple[float, float]] = (0.05, 10.0)
    WIDTH_GUESSES: ClassVar[tuple[float, ...]] = (0.5, 1.5, 4.0)
    WIDTH_WORD: ClassVar[str] = "half-span"

    def columns(self, shape, z):
        """The one column -2 z / sqrt(a^2 + z^2)."""
        a = np.asarray(shape["a"], float)
        z = np.asarray(z, float)
        return [-2.0 * z / np.sqrt(a * a + z * z)]

    def stiffness(self, value, z):
        """dF/dz = -2 P a^2 / (a^2 + z^2)^(3/2)."""
        z = np.asarray(z, float)
        P, a = np.asarray(value["P"], float), np.asarray(value["a"], float)
        return -2.0 * P * a * a / (a * a + z * z) ** 1.5

    def potential(self, value, z):
        """The part's energy -2 P (sqrt(a^2 + z^2) - a) [J], zero at z = 0."""
        z = np.asarray(z, float)
        P, a = np.asarray(value["P"], float), np.asarray(value["a"], float)
        return -2.0 * P * (np.sqrt(a * a + z * z) - a)


@dataclass(frozen=True)
class RodFrame(ShapedLaw):
    """The reference study's rod-frame geometry: F = 2 k_f (s + D0) s'(z) [N]
    (``{"k_f": N/m, "D0": m, "L": m, "alpha_deg": deg}``; gravity is the model's k0).
    """

    fields: ClassVar[tuple[str, ...]] = ("k_f", "D0", "L", "alpha_deg")
    shape: ClassVar[tuple[str, ...]] = ("L", "alpha_deg")
    bounds: ClassVar[dict[str, tuple[float, float]]] = {"k_f": (0.0, np.inf), "D0": (0.0, np.inf), "L": (0.0, np.inf),
                                                        "alpha_deg": (-60.0, 60.0)}  # fmt: skip

    @staticmethod
    def _geometry(shape, z, second=False):
        a = np.radians(np.asarray(shape["alpha_deg"], float))
        L = np.asarray(shape["L"], float)
        with np.errstate(invalid="ignore"):
            return rod_geometry(np.asarray(z, float), L, np.cos(a), np.sin(a), second=second)

    def columns(self, shape, z):
        """2 s s' and 2 s' (NaN where the rods cannot reach z): the coefficients are k_f and k_f D0."""
        s, s1, _ = self._geometry(shape, z)
        return [2.0 * s * s1, 2.0 * s1]

    def coefficients(self, value):
        """(k_f, k_f D0)."""
        k, D0 = np.asarray(value["k_f"], float), np.asarray(value["D0"], float)
        return [k, k * D0]

    def value_of(self, shape, coefficients):
        """``{"k_f", "D0", "L", "alpha_deg"}``; D0 = (k_f D0) / k_f."""
        k = float(coefficients[0])
        return {"k_f": k, "D0": float(coefficients[1]) / k if k else 0.0, "L": float(shape["L"]),
                "alpha_deg": float(shape["alpha_deg"])}  # fmt: skip

    def stiffness(self, value, z):
        """dF/dz = 2 k_f (s'^2 + (s + D0) s'')."""
        s, s1, s2 = self._geometry(value, z, second=True)
        k, D0 = np.asarray(value["k_f"], float), np.asarray(value["D0"], float)
        return 2.0 * k * (s1 * s1 + (s + D0) * s2)

    def potential(self, value, z):
        """k_f ((s + D0)^2 - D0^2) [J], zero at z = 0."""
        s, _, _ = self._geometry(value, z)
        k, D0 = np.asarray(value["k_f"], float), np.asarray(value["D0"], float)
        return k * ((s + D0) ** 2 - D0 * D0)

    def span(self, value):
        """The reach of the rods, 2 % short of each end (the force grows without bound at the ends); per member of
        a batch.
        """
        lo, hi = rod_reach(np.asarray(value["L"], float), np.radians(np.asarray(value["alpha_deg"], float)))
        return _number(0.98 * lo), _number(0.98 * hi)

    def check(self, name, value):
        """Positive k_f, D0 and L, and a frame angle within (-60, 60) degrees (``Device``'s own ranges)."""
        if not (value["k_f"] > 0 and value["D0"] > 0 and value["L"] > 0 and -60 < value["alpha_deg"] < 60):
            raise ValueError(f"{name} needs k_f, D0, L > 0 and -60 < alpha_deg < 60")
        return MappingProxyType(dict(value))

    def shape_bounds(self, stroke):
        """Rods long enough to reach the stroke (L > 1.05 max |z| / cos 30 deg) and up to ten times it; the frame
        angle within +-30 degrees.
        """
        reach = max(abs(stroke[0]), abs(stroke[1]))
        return {"L": (1.3 * reach, 10.0 * reach), "alpha_deg": (-30.0, 30.0)}

    def shape_guesses(self, stroke):
        """Rods of 1.6, 2.5 and 4 times the stroke's reach, the frame level."""
        reach = max(abs(stroke[0]), abs(stroke[1]))
        return [{"L": f * reach, "alpha_deg": 0.0} for f in (1.6, 2.5, 4.0)]


@dataclass(frozen=True)
class Spline(ShapedLaw):
    """A cubic B-spline force over [lo, hi] continued by straight lines (``{"knots": (lo, ..., hi) m,
    "coef": (...) N}``: the interior and end knots, evenly spaced; len(coef) = len(knots) + 2).
    """

    parameters_compared: ClassVar[bool] = False
    fields: ClassVar[tuple[str, ...]] = ("knots", "coef")
    shape: ClassVar[tuple[str, ...]] = ("knots",)
    DEGREE: ClassVar[int] = 3

    @staticmethod
    def _t(knots) -> np.ndarray:
        k = np.asarray(knots, float)
        return np.concatenate([np.full(3, k[0]), k, np.full(3, k[-1])])

    def columns(self, shape, z):
        """The B-spline basis at z, each function continued linearly beyond the end knots (so the force is)."""
        z = np.asarray(z, float)
        # each column contiguous: a library stacks them (19 columns of 794,624 samples: 31 ms from contiguous ones,
        # 52 ms from the strided columns of a row-major matrix, measured)
        cols = self._basis(shape, z, order="F")
        return list(np.moveaxis(cols.reshape(*z.shape, cols.shape[1]), -1, 0))

    def column_matrix(self, shape, z) -> np.ndarray:
        """The columns as a matrix (T, n), made as one (split into columns and stacked again, it was one of the two
        stackings that took 0.3 s of a vibrometer's 1.5 s gain search, measured).
        """
        return self._basis(shape, np.asarray(z, float).reshape(-1))

    def _basis(self, shape, z: np.ndarray, order: str = "C") -> np.ndarray:
        """The basis at z's samples as a matrix (samples, n) in memory ``order``: ``columns``' values."""
        from scipy.interpolate import BSpline

        knots = np.asarray(shape["knots"], float)
        t = self._t(knots)
        n = t.size - 4
        z = np.asarray(z, float)
        lo, hi = knots[0], knots[-1]
        flat = np.clip(z, lo, hi).reshape(-1)
        # extrapolate=True on the clipped z: the same matrix, without scipy's bounds check (Python's min and max over
        # the samples: two thirds of the call's time on a 150,000-sample record, measured)
        cols = BSpline.design_matrix(flat, t, 3, extrapolate=True).toarray(order=order)
        # each function's slope at the end knots (the straight lines beyond): of the derivative's own B-spline
        slopes = BSpline(t, np.eye(n), 3).derivative()(np.array([lo, hi]))  # (2, n)
        zf = z.reshape(-1)
        for out, end, slope in ((zf < lo, lo, slopes[0]), (zf > hi, hi, slopes[1])):
            if out.any():  # the few samples beyond the end knots alone
                cols[out] += (zf[out] - end)[:, None] * slope
        return cols

    def slope_columns(self, shape, z) -> np.ndarray:
        """Each column's derivative at z [1/m] (samples, columns): the B-spline basis' derivative (quadratic
        pieces), constant beyond the end knots (the straight lines). They sum to zero, as the columns sum to one.
        """
        from scipy.interpolate import BSpline

        knots = np.asarray(shape["knots"], float)
        t = self._t(knots)
        z = np.clip(np.asarray(z, float).reshape(-1), knots[0], knots[-1])
        return np.asarray(BSpline(t, np.eye(t.size - 4), 3).derivative()(z))

    def coefficients(self, value):
        """The B-spline coefficients (the last axis of ``coef``)."""
        return list(np.moveaxis(np.asarray(value["coef"], float), -1, 0))

    def value_of(self, shape, coefficients):
        """``{"knots", "coef"}``."""
        return {"knots": tuple(float(k) for k in shape["knots"]), "coef": tuple(float(c) for c in coefficients)}

    def span(self, value):
        """The knots' span, widened by half of it on each side (beyond: straight lines, tabulated exactly)."""
        k = np.asarray(value["knots"], float)
        w = 0.5 * (k[-1] - k[0])
        return float(k[0] - w), float(k[-1] + w)

    @classmethod
    def _integrals(cls, knots, z) -> np.ndarray:
        """Each basis function's integral from the first knot to z, (*z.shape, n): the B-splines' antiderivatives
        inside, their straight continuations' beyond.
        """
        from scipy.interpolate import BSpline

        knots = np.asarray(knots, float)
        t = cls._t(knots)
        basis = BSpline(t, np.eye(t.size - 4), 3)
        lo, hi = knots[0], knots[-1]
        z = np.asarray(z, float)
        out = basis.antiderivative()(np.clip(z, lo, hi))
        for end, side in ((lo, z < lo), (hi, z > hi)):
            dz = np.where(side, z - end, 0.0)[..., None]
            out = out + basis(end) * dz + 0.5 * basis.derivative()(end) * dz * dz
        return out

    def stiffness(self, value, z):
        """dF/dz [N/m]: the basis functions' derivatives (constant beyond the end knots, as the lines are), weighted
        by the coefficients (their last axis; a batch's leading axes broadcast against z's).
        """
        from scipy.interpolate import BSpline

        knots = np.asarray(value["knots"], float)
        t = self._t(knots)
        slope = BSpline(t, np.eye(t.size - 4), 3).derivative()(np.clip(np.asarray(z, float), knots[0], knots[-1]))
        return np.sum(np.asarray(value["coef"], float) * slope, axis=-1)

    def potential(self, value, z):
        """int_0^z F dz [J]: the spline's antiderivative inside, the straight lines' beyond (the coefficients' last
        axis their own; a batch's leading axes broadcast against z's).
        """
        z = np.asarray(z, float)
        knots = np.asarray(value["knots"], float)
        coef = np.asarray(value["coef"], float)
        return np.sum(coef * (self._integrals(knots, z) - self._integrals(knots, 0.0)), axis=-1)  # z's own shape

    def check(self, name, value):
        """At least two knots, increasing, and len(knots) + 2 coefficients."""
        knots, coef = value["knots"], value["coef"]
        if len(knots) < 2 or np.any(np.diff(knots) <= 0) or len(coef) != len(knots) + 2:
            raise ValueError(f"{name} needs increasing knots (at least two) and len(knots) + 2 coefficients")
        return MappingProxyType({"knots": tuple(knots), "coef": tuple(coef)})

    def parameters(self, value):
        """The coefficients, named c0, c1, ... (the knots are the shape, fixed by the data)."""
        return {f"c{j}": float(c) for j, c in enumerate(value["coef"])}

    def with_parameters(self, value, params):
        """``value`` with some coefficients (``cJ``) replaced."""
        coef = list(value["coef"])
        for k, v in params.items():
            coef[int(k[1:])] = float(v)
        return {"knots": tuple(value["knots"]), "coef": tuple(coef)}

    def batch(self, value, params):
        """A batch of B splines over the same knots: ``coef`` of shape (B, 1, n), each coefficient ``cJ`` given
        (an array of shape (B,)) or shared (``value``'s).
        """
        n = max((np.size(v) for v in params.values()), default=1)
        coef = np.repeat(np.asarray(value["coef"], float)[None, :], n, axis=0)
        for k, v in params.items():
            coef[:, int(k[1:])] = np.asarray(v, float)
        return {"knots": tuple(value["knots"]), "coef": coef[:, None, :]}

    def scale(self, value, z_rms):
        """Each coefficient's size, or the largest's thousandth."""
        c = np.abs(np.asarray(value["coef"], float))
        floor = max(1e-3 * float(c.max(initial=0.0)), 1e-12)
        return {f"c{j}": max(float(cj), floor) for j, cj in enumerate(c)}

    def shape_bounds(self, stroke):
        """None: the knots are set from the stroke and their number chosen from the data (no search)."""
        return {}

    def shape_guesses(self, stroke, counts=(4, 6, 8, 12)):
        """Evenly spaced knots over the stroke, 4 to 12 intervals (the data choose among them)."""
        return [{"knots": tuple(np.linspace(stroke[0], stroke[1], n + 1))} for n in counts]
