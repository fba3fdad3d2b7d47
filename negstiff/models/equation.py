"""Equation of motion of the negative-stiffness oscillator (the reference study, Eqs. 1-7).

    m z'' + D(z') + K(z) + extra(z, z') = -m b''      (base excitation)
                                        =  f(t)       (force-driven rig)

    K(z) = k3 z^3 + k2 z^2 - k1 z + k0                (Eq. 2; k1 enters with a minus sign)
    U(z) = k3 z^4/4 + k2 z^3/3 - k1 z^2/2 + k0 z      (Eq. 3)
    D(z') = c z' + c_nl z'|z'|

Around a stable equilibrium z*, x = z - z* (Eq. 5) gives the shifted restoring force (Eq. 7)

    K(x + z*) = k3 x^3 + k2~ x^2 + k1~ x,   k2~ = k2 + 3 k3 z*,   k1~ = 3 k3 z*^2 + 2 k2 z* - k1,

whose linear part is the underlying-linear system (ULS) of that well, with natural frequency
omega = sqrt(k1~ / m) (Eq. 4).

Extra effects are named terms added to the force, each an entry of the registry in
``models.effects`` (the model file's ``extra`` mapping names them).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from negstiff.constants import G
from negstiff.errors import InputError

from . import effects
from .effects import finite


@dataclass(frozen=True)
class Equilibria:
    """Equilibrium positions [m]: stable ``z_minus`` < unstable ``z_0`` < stable ``z_plus``.

    A single-well system has only ``z_plus``; the others are None.
    """

    z_minus: float | None
    z_0: float | None
    z_plus: float

    def as_dict(self) -> dict[str, float | None]:
        """The equilibria as a mapping (the result JSON's ``equilibria``)."""
        return {"z_minus": self.z_minus, "z_0": self.z_0, "z_plus": self.z_plus}

    def well(self, name: str) -> float:
        """Position of the stable equilibrium ``"minus"`` or ``"plus"``."""
        z = {"minus": self.z_minus, "plus": self.z_plus}[name]
        if z is None:
            raise ValueError(f"the system has no {name} well (single-well)")
        return z


@dataclass(frozen=True)
class UnderlyingLinear:
    """Underlying-linear system (ULS) around a stable equilibrium (reference study Eqs. 4-7)."""

    z_ref: float
    """Reference position z* [m]."""
    k1_tilde: float
    """Linear stiffness at the well, K'(z*) [N/m]."""
    k2_tilde: float
    """Quadratic coefficient in the shifted frame, k2 + 3 k3 z* [N/m^2]."""
    k3: float
    """Cubic coefficient in the shifted frame, the third derivative K^(3)(z*) / 6 [N/m^3] (of a cubic, k3 itself:
    frame-independent)."""
    f_hz: float
    """Undamped natural frequency sqrt(k1~/m)/(2 pi) [Hz]."""
    zeta: float
    """Viscous damping ratio c / (2 sqrt(k1~ m)) [-]."""


def find_equilibria(force, stiffness, z_lo: float, z_hi: float, n_grid: int = 4001) -> Equilibria:
    """Equilibria of a scalar restoring force on [z_lo, z_hi] by sign changes and Brent's method."""
    from scipy.optimize import brentq

    grid = np.linspace(z_lo, z_hi, n_grid)
    f = force(grid)
    roots = []
    for i in np.flatnonzero(np.sign(f[:-1]) * np.sign(f[1:]) <= 0):
        if f[i] == 0.0:
            roots.append(grid[i])
        elif f[i + 1] != 0.0:
            roots.append(brentq(force, grid[i], grid[i + 1], xtol=1e-15, rtol=1e-14))
    roots = sorted(set(float(r) for r in roots))
    stable = [r for r in roots if stiffness(r) > 0]
    unstable = [r for r in roots if stiffness(r) <= 0]
    if len(stable) == 2 and len(unstable) == 1 and stable[0] < unstable[0] < stable[1]:
        return Equilibria(stable[0], unstable[0], stable[1])
    if len(stable) == 1 and not unstable:
        return Equilibria(None, None, stable[0])

    def mm(zs):  # at most four, in mm: a flat force has a root at every grid point
        shown = ", ".join(f"{1e3 * z:.3g}" for z in zs[:4])
        return f"[{shown}{', ...' if len(zs) > 4 else ''}] mm ({len(zs)})" if len(zs) > 4 else f"[{shown}] mm"

    raise ValueError(
        f"restoring force has equilibria {mm(roots)}, stable {mm(stable)}; expected one stable, or "
        "stable-unstable-stable"
    )


def check_dissipation(extra: Mapping[str, Any], source: str = "model") -> None:
    """Refuse (``InputError``) a dissipative extra effect (friction, velocity-power damping) below zero: it
    feeds energy in, which no physical device does (a fitted model's may; this is for a model a user gives to
    be simulated as a device).

    Parameters
    ----------
    extra : mapping
        A model's or a device's extra effects (``{"coulomb_friction": 0.1}``).
    source : str
        What the model is, for the message (its file).
    """
    for name, value in extra.items():
        effect = effects.get(name)
        if effect.scalar and effect.dissipative and value < 0:
            raise InputError(f"{source}: effect {name} = {value:g} {effect.units}: a {name.replace('_', ' ')} "
                             "dissipates energy, its value is >= 0 on a physical device")  # fmt: skip


@dataclass(frozen=True)
class Model:
    """The polynomial (z-frame) model of the contract's model file.

    ``m z'' + c z' + c_nl z'|z'| + k3 z^3 + k2 z^2 - k1 z + k0 + extra(z, z') = -m base_acc`` (or ``= force``).

    Parameters
    ----------
    m : float
        Mass [kg] (1 for mass-normalised coefficients).
    k1, k2, k3 : float
        Restoring-force coefficients [N/m, N/m^2, N/m^3] of ``K(z) = k3 z^3 + k2 z^2 - k1 z + k0``.
    c : float
        Viscous damping [N s/m].
    c_nl : float
        Quadratic damping [N s^2/m^2].
    k0 : float, optional
        Constant force [N]; defaults to ``m * G`` (gravity along the motion; 0 for a horizontal device).
    extra : dict, optional
        Named extra effects (``models.effects``: ``{"coulomb_friction": 0.1}``).

    Examples
    --------
    >>> from negstiff import Model
    >>> model = Model(m=0.212, k1=438.6, k2=1001.0, k3=6.72e5, c=3.5, c_nl=0.5)
    >>> eq = model.equilibria()
    >>> eq.z_minus < eq.z_0 < eq.z_plus
    True
    >>> round(1e3 * eq.z_plus, 1)
    21.9
    """

    m: float
    k1: float
    k2: float
    k3: float
    c: float = 0.0
    c_nl: float = 0.0
    k0: float | None = None
    extra: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self):
        try:  # the registry's checks say what is wrong; a program gets negstiff's error for it
            for name in ("m", "k1", "k2", "k3", "c", "c_nl"):
                object.__setattr__(self, name, finite(name, getattr(self, name)))
            k0 = self.m * G if self.k0 is None else finite("k0", self.k0)
            extra = effects.normalise(self.extra)
        except (TypeError, ValueError, KeyError) as exc:
            raise InputError(" ".join(str(exc).strip("'\"").split()) or f"model: {type(exc).__name__}") from None
        if self.m <= 0:
            raise InputError(f"model mass m must be positive, got {self.m}")
        object.__setattr__(self, "k0", k0)
        object.__setattr__(self, "extra", extra)

    def __repr__(self) -> str:
        extra = f", extra={effects.plain(self.extra)!r}" if self.extra else ""
        return (
            f"Model(m={self.m:.6g}, k1={self.k1:.6g}, k2={self.k2:.6g}, k3={self.k3:.6g}, c={self.c:.6g}, "
            f"c_nl={self.c_nl:.6g}, k0={self.k0:.6g}{extra})"
        )

    def __reduce__(self):
        """Pickled (and deep-copied) by its fields, the read-only ``extra`` as plain dicts: a model crosses
        process boundaries (dask, multiprocessing) and ``sklearn.base.clone`` copies it.
        """
        values = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        return _rebuild, (type(self), {**values, "extra": effects.plain(self.extra)})

    # --- forces and energy -------------------------------------------------------------------
    def restoring_force(self, z, include_extra: bool = True):
        """K(z) [N] (Eq. 2), plus the displacement-only extra effects when ``include_extra``."""
        z = np.asarray(z, float)
        k = ((self.k3 * z + self.k2) * z - self.k1) * z + self.k0
        return k + effects.stiffness_force(self.extra, z) if include_extra else k

    def stiffness(self, z, include_extra: bool = True):
        """dK/dz [N/m]."""
        z = np.asarray(z, float)
        ks = (3 * self.k3 * z + 2 * self.k2) * z - self.k1
        if include_extra and self.extra:
            h = 1e-7
            ks = ks + (effects.stiffness_force(self.extra, z + h) - effects.stiffness_force(self.extra, z - h)) / (
                2 * h
            )
        return ks

    def potential(self, z, include_extra: bool = True):
        """U(z) [J] (Eq. 3), zero at z = 0."""
        z = np.asarray(z, float)
        u = (((self.k3 / 4 * z + self.k2 / 3) * z - self.k1 / 2) * z + self.k0) * z
        return u + effects.stiffness_potential(self.extra, z) if include_extra else u

    def damping_force(self, zdot):
        """The damping force ``D(z') = c z' + c_nl z'|z'|`` [N] (without the velocity-dependent extra effects)."""
        zdot = np.asarray(zdot, float)
        return self.c * zdot + self.c_nl * zdot * np.abs(zdot)

    def total_force(self, z, zdot):
        """D(z') + K(z) + extra(z, z') [N]: everything on the left-hand side but inertia."""
        return (
            self.damping_force(zdot) + self.restoring_force(z, include_extra=False) + effects.force(self.extra, z, zdot)
        )

    # --- equilibria and linearisation ---------------------------------------------------------
    def equilibria(self) -> Equilibria:
        """Equilibria of K(z) (with the stiffness extra effects), sorted and classified: sought near the cubic's
        roots, or over the spans of the model's shaped parts where they hold the force (a magnet's, a spline's:
        ``models.shaped``).
        """
        shaped = effects.shaped_parts(self.extra)
        if shaped and self.k3 <= 0:  # the shaped parts hold the force: its equilibria lie where they act
            spans = np.array([law.span(value) for law, value in shaped])
            return find_equilibria(self.restoring_force, self.stiffness, float(spans[:, 0].min()),
                                   float(spans[:, 1].max()))  # fmt: skip
        if self.k3 <= 0 and not self.extra:
            raise ValueError("k3 must be positive (hardening) for a bounded double- or single-well model")
        k0 = self.k0
        assert k0 is not None  # set by __post_init__
        # Cauchy bound of the cubic's roots, widened for the extra terms
        bound = 1 + max(abs(self.k2), abs(self.k1), abs(k0)) / abs(self.k3 or 1.0)
        roots = np.roots([self.k3, self.k2, -self.k1, k0]) if self.k3 > 0 else np.array([])
        real = np.sort(roots[np.abs(roots.imag) <= 1e-9 * np.maximum(1, np.abs(roots))].real)
        if real.size and not self.extra:
            bound = 1.01 * np.max(np.abs(real)) + 1e-6
        elif real.size:
            # a quartic or quintic term always has far roots of its own; the device's equilibria are the
            # ones near the cubic's: search 3x as far out (a higher-order term's far roots lie beyond any
            # stroke, e.g. -0.67 m for 1e6 z^4 on the rig's cubic)
            bound = 3.0 * np.max(np.abs(real)) + 1e-6
        return find_equilibria(self.restoring_force, self.stiffness, -bound, bound)

    def uls(self, well: str) -> UnderlyingLinear:
        """Underlying-linear system around the ``"minus"`` or ``"plus"`` well (Eqs. 4-7)."""
        zs = self.equilibria().well(well)
        k1t = float(self.stiffness(zs))
        k2t, k3t = self.k2 + 3 * self.k3 * zs, self.k3
        if self.extra:  # the displacement effects' own K''/2 and K'''/6 at the well, by central differences
            h = 1e-4 * max(abs(zs), 1e-2)
            ks = [float(effects.stiffness_force(self.extra, zs + j * h)) for j in (-2, -1, 0, 1, 2)]
            k2t += (ks[3] - 2 * ks[2] + ks[1]) / h**2 / 2
            k3t += (ks[4] - 2 * ks[3] + 2 * ks[1] - ks[0]) / (2 * h**3) / 6
        return UnderlyingLinear(
            zs, k1t, k2t, k3t, math.sqrt(k1t / self.m) / (2 * math.pi), self.c / (2 * math.sqrt(k1t * self.m))
        )

    @staticmethod
    def from_shifted(z_ref: float, k1_tilde: float, k2_tilde: float, k3: float, **kw) -> Model:
        """Back-transform shifted-frame coefficients (Eq. 7) to the z frame.

        k2 = k2~ - 3 k3 z*, and k1 from k1~ = 3 k3 z*^2 + 2 k2 z* - k1. ``k0`` is then fixed by the
        equilibrium condition K(z*) = 0 unless given.
        """
        k2 = k2_tilde - 3 * k3 * z_ref
        k1 = 3 * k3 * z_ref**2 + 2 * k2 * z_ref - k1_tilde
        if "k0" not in kw or kw["k0"] is None:
            kw["k0"] = -((k3 * z_ref + k2) * z_ref - k1) * z_ref
        return Model(k1=k1, k2=k2, k3=k3, **kw)

    # --- serialisation -----------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """The contract's model JSON fields."""
        extra = effects.plain(self.extra)
        return {
            "m": self.m,
            "k0": self.k0,
            "k1": self.k1,
            "k2": self.k2,
            "k3": self.k3,
            "c": self.c,
            "c_nl": self.c_nl,
            "extra": extra,
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Model:
        """Build from the contract's model JSON (``k0`` defaults to ``m*g``; ``extra`` to none)."""
        missing = [k for k in ("m", "k1", "k2", "k3") if k not in d]
        if missing:
            raise ValueError(f"model lacks {', '.join(missing)}")
        unknown = set(d) - {"m", "k0", "k1", "k2", "k3", "c", "c_nl", "extra"}
        if unknown:
            raise ValueError(f"model has unknown fields {', '.join(sorted(unknown))}")
        return cls(
            m=d["m"],
            k1=d["k1"],
            k2=d["k2"],
            k3=d["k3"],
            c=d.get("c", 0.0),
            c_nl=d.get("c_nl", 0.0),
            k0=d.get("k0"),
            extra=d.get("extra") or {},
        )

    # --- simulator interface -----------------------------------------------------------------
    kind = "polynomial"

    def kernel_params(self) -> np.ndarray:
        """Parameter vector for the simulator kernel (rows 1-4: k0..k3; the others: ``effects.layout``)."""
        p = effects.kernel_rows(self.m, self.c, self.c_nl, self.extra)
        for name, row in effects.POLYNOMIAL_ROWS.items():
            p[row] = getattr(self, name)
        return p


def _rebuild(cls, values):
    """``__reduce__``'s inverse: the class built from its fields (validated again)."""
    return cls(**values)
