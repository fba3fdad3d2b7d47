"""Physically-based model of the negative-stiffness device (``docs/device-model.md``).

A bushing of mass m slides on a vertical guide; two rigid rods of length L hinge on it and on the tips
of the two arms of a U-shaped frame. Each arm is a cantilever leaf spring (free length l, width b,
thickness h, Young's modulus E) of tip stiffness k_f = 3 E I / l^3, I = b h^3 / 12, whose tip moves
along a line inclined by the frame angle alpha. With s the tip travel along that line (s = 0 at
z = 0, s = -D0 for an unloaded arm), the fixed rod length gives

    s(z) = -B + sqrt(B^2 - z^2),   B = L cos(alpha) - z sin(alpha)

and the potential of the two arms plus gravity, and the restoring force, are

    U(z) = k_f (s + D0)^2 - k_f D0^2 + m g z,     K(z) = dU/dz = 2 k_f (s + D0) s'(z) + m g.

The Taylor expansion at z = 0 gives the cubic of the reference study's Eq. (2):
k1 = 2 D0 k_f / (L cos a), k2 = -3 D0 k_f tan(a) / (L^2 cos a), k0 = m g, and

    k3 = k_f (L cos a - D0 (1 + 4 sin^2 a)) / (L^3 cos^3 a)

(derived symbolically; device-model.md gives the leading term k_f / (L^2 cos^2 a), which drops the
D0/L correction, 14 % for this device).
The exact K(z) departs from any cubic over the full stroke (the model-form gap the suite shows).

The geometry exists only while B^2 > z^2, i.e. for
-L cos a / (1 - sin a) < z < L cos a / (1 + sin a); outside it ``GeometryError`` is raised.

Calibration (see ``experiments/calibration.py`` and the report): the fixed geometry below and the
as-built E, alpha, m put the rig's device at the reference study's headline figures (Table 1 and Figure 4).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from negstiff.constants import G
from negstiff.errors import InputError

from . import effects
from .equation import Equilibria, Model, UnderlyingLinear, find_equilibria
from .shaped import rod_geometry


class GeometryError(InputError):
    """A displacement outside the range where the rod-frame geometry has a solution."""


def arm_stiffness(E, b: float, h: float, l: float):  # noqa: E741 - the arm's free length, as in device-model.md
    """Tip stiffness of one arm of the frame, 3 E I / l^3 with I = b h^3 / 12 [N/m] (E [Pa], a number or an
    array; b, h, l [m]): the one place the frame's linear stiffness is written.
    """
    return 3 * E * (b * h**3 / 12) / l**3


@dataclass(frozen=True)
class Device:
    """The physical device: geometry, material and mass, with its damping and extra effects (SI units).

    Its exact restoring force K(z) follows from the rod-frame geometry (``docs/device-model.md``).

    Parameters
    ----------
    E : float
        Young's modulus of the frame [Pa].
    alpha_deg : float
        Frame angle [deg].
    m : float
        Moving mass [kg].
    L : float
        Rod length [m].
    l, b, h : float
        Arm free length, width and thickness [m].
    D0 : float
        Arm pre-compression at z = 0 [m].
    c, c_nl : float
        Viscous [N s/m] and quadratic [N s^2/m^2] damping of the guide.
    extra : dict, optional
        Named extra effects (``models.effects``).

    Examples
    --------
    >>> from negstiff.models import AS_BUILT
    >>> eq = AS_BUILT.equilibria()
    >>> round(1e3 * eq.z_minus, 1), round(1e3 * eq.z_plus, 1)
    (-28.7, 22.8)
    >>> cubic = AS_BUILT.lsq_cubic()      # the least-squares cubic Model of the exact K(z)
    """

    E: float
    alpha_deg: float
    m: float
    L: float
    l: float  # noqa: E741 - the arm's free length, as in device-model.md
    b: float
    h: float
    D0: float
    c: float = 0.0
    c_nl: float = 0.0
    extra: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self):
        for name in ("E", "alpha_deg", "m", "L", "l", "b", "h", "D0", "c", "c_nl"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
                raise ValueError(f"device parameter {name} must be a number, got {v!r}")
        for name in ("E", "m", "L", "l", "b", "h", "D0"):
            v = float(getattr(self, name))
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"device parameter {name} must be positive and finite, got {v}")
        if not (math.isfinite(self.alpha_deg) and -60 < self.alpha_deg < 60):
            raise ValueError(f"frame angle alpha_deg must lie in (-60, 60) degrees, got {self.alpha_deg}")
        object.__setattr__(self, "extra", effects.normalise(self.extra))

    def __repr__(self) -> str:
        extra = f", extra={effects.plain(self.extra)!r}" if self.extra else ""
        return (
            f"Device(E={self.E:.6g}, alpha_deg={self.alpha_deg:.6g}, m={self.m:.6g}, L={self.L:.6g}, l={self.l:.6g}, "
            f"b={self.b:.6g}, h={self.h:.6g}, D0={self.D0:.6g}, c={self.c:.6g}, c_nl={self.c_nl:.6g}{extra})"
        )

    def __reduce__(self):
        """Pickled (and deep-copied) by its fields, the read-only ``extra`` as plain dicts: a model crosses
        process boundaries (dask, multiprocessing) and ``sklearn.base.clone`` copies it.
        """
        values = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        return _rebuild, (type(self), {**values, "extra": effects.plain(self.extra)})

    # --- derived constants ---------------------------------------------------------------------
    @property
    def alpha(self) -> float:
        """Frame angle [rad]."""
        return math.radians(self.alpha_deg)

    @property
    def k_f(self) -> float:
        """Tip stiffness of one arm [N/m] (``arm_stiffness``)."""
        return arm_stiffness(self.E, self.b, self.h, self.l)

    def restoring_force_many(self, z, E, alpha_deg, m) -> tuple[np.ndarray, np.ndarray]:
        """K(z) [N] of this device with (E, alpha_deg, m) replaced by each of n triples, at once: (n, len(z)),
        and where each device reaches z (the geometry has a solution); no extra effects.
        """
        ca, sa = np.cos(np.radians(alpha_deg))[:, None], np.sin(np.radians(alpha_deg))[:, None]
        reach = (z > -self.L * ca / (1 - sa)) & (z < self.L * ca / (1 + sa))
        with np.errstate(invalid="ignore"):
            g, g1, _ = rod_geometry(z, self.L, ca, sa, second=False)
        kf = arm_stiffness(E, self.b, self.h, self.l)[:, None]
        return 2 * kf * (g + self.D0) * g1 + (m * G)[:, None], reach

    def stroke_limits(self) -> tuple[float, float]:
        """Open interval of z [m] in which the geometry has a solution (B^2 > z^2)."""
        ca, sa = math.cos(self.alpha), math.sin(self.alpha)
        return -self.L * ca / (1 - sa), self.L * ca / (1 + sa)

    def with_(self, **changes) -> Device:
        """A copy with some parameters changed (``dataclasses.replace``)."""
        return replace(self, **changes)

    # --- exact geometry ------------------------------------------------------------------------
    def _check_stroke(self, z: np.ndarray) -> None:
        lo, hi = self.stroke_limits()
        bad = (z <= lo) | (z >= hi) | ~np.isfinite(z)
        if np.any(bad):
            zb = float(np.asarray(z)[bad].flat[0])
            raise GeometryError(
                f"z = {zb * 1e3:.2f} mm is outside the device's stroke "
                f"({lo * 1e3:.1f} mm, {hi * 1e3:.1f} mm): the rods cannot reach it"
            )

    def _s_derivs(self, z):
        """s(z), s'(z), s''(z) of the rod-frame geometry."""
        z = np.asarray(z, float)
        self._check_stroke(z)
        return rod_geometry(z, self.L, math.cos(self.alpha), math.sin(self.alpha))

    def restoring_force(self, z, include_extra: bool = True):
        """Exact K(z) = 2 k_f (s + D0) s' + m g [N], plus the displacement-only extra effects."""
        s, s1, _ = self._s_derivs(z)
        k = 2 * self.k_f * (s + self.D0) * s1 + self.m * G
        return k + effects.stiffness_force(self.extra, z) if include_extra else k

    def stiffness(self, z, include_extra: bool = True):
        """dK/dz = 2 k_f (s'^2 + (s + D0) s'') [N/m]."""
        s, s1, s2 = self._s_derivs(z)
        ks = 2 * self.k_f * (s1 * s1 + (s + self.D0) * s2)
        if include_extra and self.extra:
            hz = 1e-7
            ks = ks + (
                effects.stiffness_force(self.extra, np.asarray(z) + hz)
                - effects.stiffness_force(self.extra, np.asarray(z) - hz)
            ) / (2 * hz)
        return ks

    def potential(self, z, include_extra: bool = True):
        """U(z) = k_f ((s + D0)^2 - D0^2) + m g z [J], zero at z = 0."""
        z = np.asarray(z, float)
        s, _, _ = self._s_derivs(z)
        u = self.k_f * ((s + self.D0) ** 2 - self.D0**2) + self.m * G * z
        return u + effects.stiffness_potential(self.extra, z) if include_extra else u

    def damping_force(self, zdot):
        """The damping force ``c z' + c_nl z'|z'|`` [N]."""
        zdot = np.asarray(zdot, float)
        return self.c * zdot + self.c_nl * zdot * np.abs(zdot)

    def total_force(self, z, zdot):
        """D(z') + K(z) + extra(z, z') [N]."""
        return (
            self.damping_force(zdot) + self.restoring_force(z, include_extra=False) + effects.force(self.extra, z, zdot)
        )

    # --- equilibria, wells, features -----------------------------------------------------------
    def _geometry_at(self, z: float) -> tuple[float, float, float, float, float]:
        """(s, B, R, q, cos alpha) of ``_s_derivs`` at one z [m] in floats: the same operations in the same
        order, so the same numbers to the bit, without numpy's per-call cost (Brent's method calls the
        force ~50 times per ``equilibria``; through numpy that was 3/4 of the GA's time, measured).
        """
        alpha = self.alpha
        ca, sa = math.cos(alpha), math.sin(alpha)
        if not -self.L * ca / (1 - sa) < z < self.L * ca / (1 + sa):
            self._check_stroke(np.asarray(z, float))  # raises the stroke's error
        B = self.L * ca - z * sa
        R = math.sqrt(B * B - z * z)
        return R - B, sa, R, B * sa + z, ca

    def _force_floats(self, z):
        """``restoring_force`` without extra effects; in floats for a float z (``_geometry_at``)."""
        if not isinstance(z, float):
            return self.restoring_force(z, include_extra=False)
        s, sa, R, q, _ = self._geometry_at(z)
        return 2 * self.k_f * (s + self.D0) * (sa - q / R) + self.m * G

    def _stiffness_floats(self, z):
        """``stiffness`` without extra effects; in floats for a float z (``_geometry_at``)."""
        if not isinstance(z, float):
            return self.stiffness(z, include_extra=False)
        s, sa, R, q, ca = self._geometry_at(z)
        s1 = sa - q / R
        s2 = -(ca * ca * R * R + q * q) / R**3
        return 2 * self.k_f * (s1 * s1 + (s + self.D0) * s2)

    def features_many(self, E, alpha_deg, m) -> tuple[np.ndarray, np.ndarray]:
        """``features`` of this device with (E, alpha_deg, m) replaced by each of n triples, at once: (n, 4)
        rows (f_minus, f_plus, z_minus, z_plus) and whether each is a double well (its row NaN if not).

        The roots of ``equilibria``'s grid are bracketed the same way, then bisected together to the
        last representable point (Brent's method one device at a time: 0.5 ms a device, most of a GA's
        time). Not for devices with extra effects.
        """
        if self.extra:
            raise ValueError("features_many: a device with extra effects takes features() one by one")
        E, a, m = (np.asarray(x, float) for x in np.broadcast_arrays(E, alpha_deg, m))
        ca, sa = np.cos(np.radians(a))[:, None], np.sin(np.radians(a))[:, None]
        kf = arm_stiffness(E, self.b, self.h, self.l)[:, None]
        mg = (m * G)[:, None]
        lo, hi = -self.L * ca[:, 0] / (1 - sa[:, 0]), self.L * ca[:, 0] / (1 + sa[:, 0])
        span = hi - lo
        z = np.linspace(lo + 1e-4 * span, hi - 1e-4 * span, 4001, axis=1)

        def force(zz, rows):
            s, s1, _ = rod_geometry(zz, self.L, ca[rows], sa[rows], second=False)
            return 2 * kf[rows] * (s + self.D0) * s1 + mg[rows]

        f = force(z, slice(None))
        r, c = np.nonzero(np.sign(f[:, :-1]) * np.sign(f[:, 1:]) <= 0)
        exact, bracket = f[r, c] == 0.0, (f[r, c] != 0.0) & (f[r, c + 1] != 0.0)
        rows, a_, b_ = r[bracket], z[r, c][bracket], z[r, c + 1][bracket]
        fa, fb = f[r, c][bracket], f[r, c + 1][bracket]
        x = a_ - fa * (b_ - a_) / (fb - fa)  # the cell's secant point, then Newton on the analytic K'
        for _ in range(12):
            g, g1, g2 = rod_geometry(x, self.L, ca[rows, 0], sa[rows, 0])
            step = (2 * kf[rows, 0] * (g + self.D0) * g1 + mg[rows, 0]) / (
                2 * kf[rows, 0] * (g1 * g1 + (g + self.D0) * g2)
            )
            x = x - step
            if np.all(np.abs(step) <= 4 * np.finfo(float).eps * np.abs(x)):
                break
        lost = ~((x >= a_) & (x <= b_))  # Newton left its cell (a double root): bisect that cell
        if lost.any():
            x[lost] = self._bisect(force, rows[lost], a_[lost], b_[lost], fa[lost])
        roots = np.concatenate([z[r, c][exact], x])
        owner = np.concatenate([r[exact], rows])
        order = np.lexsort((roots, owner))
        roots, owner = roots[order], owner[order]
        keep = np.ones(roots.size, bool)
        keep[1:] = (owner[1:] != owner[:-1]) | (roots[1:] != roots[:-1])  # a root found twice counts once
        roots, owner = roots[keep], owner[keep]
        g, g1, g2 = rod_geometry(roots, self.L, ca[owner, 0], sa[owner, 0])
        ks = 2 * kf[owner, 0] * (g1 * g1 + (g + self.D0) * g2)
        out, ok = np.full((E.size, 4), np.nan), np.zeros(E.size, bool)
        three = np.flatnonzero(np.bincount(owner, minlength=E.size) == 3)
        at = np.searchsorted(owner, three)[:, None] + np.arange(3)  # each such device's three roots, sorted
        ks3, z3 = ks[at], roots[at]
        well = (ks3[:, 0] > 0) & (ks3[:, 1] <= 0) & (ks3[:, 2] > 0)  # stable, unstable, stable
        idx = three[well]
        out[idx, :2] = np.sqrt(ks3[well][:, [0, 2]] / m[idx, None]) / (2 * math.pi)
        out[idx, 2:] = z3[well][:, [0, 2]]
        ok[idx] = True
        return out, ok

    @staticmethod
    def _bisect(force, rows, a, b, fa) -> np.ndarray:
        """Bisection of the brackets [a, b] of ``force`` (rows: the devices) to the last representable
        midpoint.
        """
        a, b, fa = a[:, None], b[:, None], fa[:, None]
        for _ in range(200):
            mid = 0.5 * (a + b)
            live = (mid > a) & (mid < b)
            if not live.any():
                break
            fm = force(mid, rows)
            left = np.sign(fm) == np.sign(fa)
            a, fa = np.where(live & left, mid, a), np.where(live & left, fm, fa)
            b = np.where(live & ~left, mid, b)
        return a[:, 0]

    def equilibria(self) -> Equilibria:
        """Stable-unstable-stable equilibria of the exact K(z) inside the stroke."""
        lo, hi = self.stroke_limits()
        span = hi - lo
        if self.extra:
            return find_equilibria(self.restoring_force, self.stiffness, lo + 1e-4 * span, hi - 1e-4 * span)
        return find_equilibria(self._force_floats, self._stiffness_floats, lo + 1e-4 * span, hi - 1e-4 * span)

    def uls(self, well: str) -> UnderlyingLinear:
        """Underlying-linear system around the ``"minus"`` or ``"plus"`` well (exact K'(z*))."""
        zs = self.equilibria().well(well)
        k1t = float(self.stiffness(zs))
        _, _, k2t, k3t = self.taylor(zs)
        return UnderlyingLinear(
            zs, k1t, k2t, k3t, math.sqrt(k1t / self.m) / (2 * math.pi), self.c / (2 * math.sqrt(k1t * self.m))
        )

    def features(self) -> dict[str, float]:
        """The GA's features (reference study Eq. 9): well frequencies [Hz] and stable equilibria [m]."""
        eq = self.equilibria()
        if eq.z_minus is None:
            raise ValueError("the device has one well: its features (two wells) are not defined")
        ks = self.stiffness(np.array([eq.z_minus, eq.z_plus]))
        f = np.sqrt(ks / self.m) / (2 * math.pi)
        return {"f_minus": float(f[0]), "f_plus": float(f[1]), "z_minus": eq.z_minus, "z_plus": eq.z_plus}

    # --- cubic approximations -------------------------------------------------------------------
    def taylor(self, z_ref: float = 0.0, h: float = 2e-4) -> tuple[float, float, float, float]:
        """Taylor coefficients (K, K', K''/2, K'''/6) of the exact K about ``z_ref``.

        K' is analytic; K'' and K''' come from central differences of the analytic K'
        (step ``h`` [m]; relative error O((h/L)^2)).
        """
        ks = self.stiffness(np.array([z_ref - h, z_ref, z_ref + h]), include_extra=False)
        return (
            float(self.restoring_force(z_ref, include_extra=False)),
            float(ks[1]),
            float((ks[2] - ks[0]) / (2 * h) / 2),
            float((ks[2] - 2 * ks[1] + ks[0]) / h**2 / 6),
        )

    def taylor_cubic(self) -> Model:
        """The reference study's Eq. (2) cubic from the closed-form Taylor expansion at z = 0."""
        ca, ta = math.cos(self.alpha), math.tan(self.alpha)
        kf, L, D0 = self.k_f, self.L, self.D0
        return Model(
            m=self.m,
            k0=self.m * G,
            k1=2 * D0 * kf / (L * ca),
            k2=-3 * D0 * kf * ta / (L**2 * ca),
            k3=kf * (L * ca - D0 * (1 + 4 * math.sin(self.alpha) ** 2)) / (L**3 * ca**3),
            c=self.c,
            c_nl=self.c_nl,
            extra=self.extra,
        )

    def lsq_cubic(self, z_lo: float = -0.030, z_hi: float = 0.030, n: int = 601) -> Model:
        """Least-squares cubic (k0 fixed to m g) of the exact K over [z_lo, z_hi] [m]."""
        z = np.linspace(z_lo, z_hi, n)
        r = self.restoring_force(z, include_extra=False) - self.m * G
        A = np.column_stack([z**3, z**2, -z])
        (k3, k2, k1), *_ = np.linalg.lstsq(A, r, rcond=None)
        return Model(m=self.m, k0=self.m * G, k1=k1, k2=k2, k3=k3, c=self.c, c_nl=self.c_nl, extra=self.extra)

    def law_model(self) -> Model:
        """The device as a ``Model`` of the geometric law (``models.laws``: gravity's constant and the rod frame's
        part, ``shaped.RodFrame``, with this device's k_f, D0, L and alpha), its damping and extra effects: the same
        force as ``restoring_force`` (the same ``rod_geometry``), read by every method that reads a law (NSI's and
        SINDy's ``law="geometric"``, the posterior's, the simulator's table).
        """
        frame = {"k_f": self.k_f, "D0": self.D0, "L": self.L, "alpha_deg": self.alpha_deg}
        return Model(m=self.m, k1=0.0, k2=0.0, k3=0.0, k0=self.m * G, c=self.c, c_nl=self.c_nl,
                     extra={**effects.plain(self.extra), "rod_frame": frame})  # fmt: skip

    # --- serialisation and simulator interface --------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """The device as a device file's JSON mapping."""
        extra = effects.plain(self.extra)
        return {
            "E": self.E,
            "alpha_deg": self.alpha_deg,
            "m": self.m,
            "L": self.L,
            "l": self.l,
            "b": self.b,
            "h": self.h,
            "D0": self.D0,
            "c": self.c,
            "c_nl": self.c_nl,
            "extra": extra,
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Device:
        """The device of a device file's mapping (``to_dict``'s)."""
        return cls(
            **{k: d[k] for k in ("E", "alpha_deg", "m", "L", "l", "b", "h", "D0")},
            c=d.get("c", 0.0),
            c_nl=d.get("c_nl", 0.0),
            extra=d.get("extra") or {},
        )

    kind = "device"

    def kernel_params(self) -> np.ndarray:
        """Parameter vector for the geometric simulator kernel: rows 1-5 = k_f, L, alpha, D0, g."""
        p = effects.kernel_rows(self.m, self.c, self.c_nl, self.extra)
        for name, row in effects.DEVICE_ROWS.items():
            p[row] = G if name == "g" else getattr(self, name)
        return p


GEOMETRY: dict[str, Any] = {"L": 0.060, "l": 0.094, "b": 0.020, "h": 0.0012, "D0": 0.0059}
"""Fixed geometry of the rig's device [m] (rods, arms, pre-compression); calibrated once so that the
as-built device reproduces the reference study's Table 1 and z_plus (``experiments/calibration.py``)."""

NOMINAL = Device(E=206e9, alpha_deg=8.0, m=0.200, c=0.0, c_nl=0.0, **GEOMETRY)
"""The design drawings: catalogue steel, the designed frame angle, the designed moving mass."""

AS_BUILT = Device(E=197e9, alpha_deg=6.9, m=0.212, c=1.5, c_nl=0.5, **GEOMETRY)
"""The device the virtual rig simulates (the truth): E 4.4 % below catalogue, the frame 1.1 deg
flatter than drawn, the mass heavier by the fasteners (E/m 10 % below the design's).

Features: 11.45 Hz / 9.20 Hz well frequencies, wells at -28.7 / +22.8 mm (seed: 11.41 / 9.19 Hz,
z_plus = 23 mm). Damping (c = 1.5 N s/m, c_nl = 0.5 N s^2/m^2, dissipative at every speed) puts
the 9 Hz period-doubling cascade where the reference study saw it (P2 at 14.5-15, P4 at 15.5, cross-well chaos
from 16 m/s^2, starting from z_plus) at the cost of ULS damping ratios of 4.9 % / 6.1 % instead of
the reference study's 11 % / 20 %: with viscous plus positive quadratic damping, this geometry cannot have
both (at the reference study's ratios the cascade moves to about 21 m/s^2). The report says so."""


def _seed_like_cubic():
    from .equation import Model

    lsq = AS_BUILT.lsq_cubic()
    return Model(m=lsq.m, k1=lsq.k1, k2=lsq.k2, k3=lsq.k3, c=3.5, c_nl=0.5)


SEED_LIKE_CUBIC = _seed_like_cubic()
"""Polynomial truth for identification studies: the as-built device's least-squares cubic with
damping of the reference study's size (c = 3.5 N s/m: well damping ratios 11 % / 16 %, seed 11 % / 20 %), so the
coefficients that NSI, SINDy and the posteriors must recover exist exactly."""
SEED_LIKE_CROSS_WELL_RMS = 20.0
"""Random base-excitation level [m/s^2 rms, 2-40 Hz] at which SEED_LIKE_CUBIC crosses between its
wells 6-8 times a minute while the true model's held-out free run stays predictable (floor <= 1.3 %
over 60 s on 3 seeds; at 22-24 m/s^2 chaos pushes the floor to 13 % on some records)."""


def _rebuild(cls, values):
    """``__reduce__``'s inverse: the class built from its fields (validated again)."""
    return cls(**values)


def load_system(path) -> Device | Model:
    """Read a model file or a device file, checked.

    Parameters
    ----------
    path : str or pathlib.Path
        A model file (the contract's polynomial model JSON, or an ``identify`` result holding one as
        ``model``), a device file (the geometry: ``E``, ``alpha_deg``, ...) or a structure of N DOFs
        (``masses``, ``element``, ``at``, ``stiffness``, ``damping``; or a structure's ``identify`` result).

    Returns
    -------
    Model, Device or Structure
        The system the file describes.

    Raises
    ------
    GeometryError
        One line naming the file for anything that is not a model or a device (an ``InputError``).

    Examples
    --------
    >>> import json, tempfile, pathlib
    >>> from negstiff import load_system
    >>> path = pathlib.Path(tempfile.mkdtemp()) / "model.json"
    >>> _ = path.write_text(json.dumps({"m": 0.212, "k1": 438.6, "k2": 1001, "k3": 6.72e5, "c": 3.5}))
    >>> load_system(path).k3
    672000.0
    """
    from pathlib import Path

    from negstiff.files import read_json

    path = Path(path)
    try:
        d = read_json(path, "model file")
    except ValueError as exc:
        raise GeometryError(str(exc)) from None
    if isinstance(d, dict) and isinstance(d.get("model"), dict):  # an identify result holds a model
        d = d["model"]
    if isinstance(d, dict) and isinstance(d.get("structure"), dict):  # a structure's identify result holds one
        d = d["structure"]
    if not isinstance(d, dict):
        raise GeometryError(f"{path}: a model file is a JSON object")
    if "masses" in d:  # a structure of N DOFs (``models.structure``)
        from .structure import Structure

        try:
            return Structure.from_dict(d)  # type: ignore[return-value]
        except InputError as exc:
            raise GeometryError(f"{path}: {exc}") from None
    try:
        return Device.from_dict(d) if "E" in d else Model.from_dict(d)
    except (KeyError, TypeError, ValueError) as exc:
        raise GeometryError(f"{path}: {' '.join(str(exc).split())}") from None
