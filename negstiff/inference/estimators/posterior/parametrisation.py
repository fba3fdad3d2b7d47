"""What the posterior samples: the coefficient, device and law parametrisations, their priors and maps to the
simulator's kernel parameters.

* ``coefficient_parametrisation``: the reference study's cubic and quadratic damping, k1, k2, k3, c, c_nl (k0 a
  nuisance), the mass fixed.
* ``device_parametrisation``: the reference device in its physical parameters E, alpha, m (the rod-frame geometry
  of the ``geometric`` law, its other dimensions fixed at the drawings'), c, c_nl.
* ``law_parametrisation``: any restoring and damping law of ``models.laws``, every base field the laws free and
  every parameter of their parts (``Law.parts``: a monomial's size, a magnet's A and d, a spline's coefficients over
  the record's knots, the rod frame's k_f, D0, L and alpha), named as the refinement names them
  (``refine.parameter_names``: ``k1``, ``quintic_stiffness``, ``magnet.d``, ``spline.c3``). A batch of walkers'
  kernel parameters is made in one pass: the base and monomial rows written at once, the shaped parts' tables by
  ``effects.tabulate_members`` (every part's force and stiffness evaluated over the batch and its knots at once).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, cast

import numpy as np

from negstiff.inference.estimators.posterior.windows import SIGMA_BOUNDS
from negstiff.models import Model, effects, laws
from negstiff.models.device import Device
from negstiff.models.effects import DEVICE_ROWS, POLYNOMIAL_ROWS, ROWS
from negstiff.models.shaped import ShapedLaw, Spline


# ------------------------------------------------------------------------------------------------
# Parametrisations: physical parameters -> simulator kernel parameters, priors
# ------------------------------------------------------------------------------------------------
@dataclass
class Parametrisation:
    """What is sampled: names, kernel kind, the map to kernel parameters and the prior."""

    names: tuple[str, ...]  # physical parameters except sigma (sigma is always last)
    kind: str
    to_params: Callable[[np.ndarray], np.ndarray]  # (P, d) -> (17, P)
    lower: np.ndarray
    upper: np.ndarray
    gaussian: dict[int, tuple[float, float]] = field(default_factory=dict)  # index -> (mean, sd)
    description: list[str] = field(default_factory=list)
    # parameters the likelihood does not see, held at the start value by the point estimate, and the
    # sampler's scale for each (from its prior)
    fixed_sd: dict[int, float] = field(default_factory=dict)
    # sampled coordinates phi (default: theta itself): the maps both ways, the log |d theta / d phi|, and
    # phi -> the phi the likelihood is evaluated at (the fixed ones at the start value; the same likelihood)
    to_physical: Callable[[np.ndarray], np.ndarray] | None = None
    to_sampled: Callable[[np.ndarray], np.ndarray] | None = None
    log_jacobian: Callable[[np.ndarray], np.ndarray] | None = None
    reduce: Callable[[np.ndarray], np.ndarray] | None = None
    # a prior's support beyond its box (a law's: a spline's tail rising outward, the parts tabulated over the
    # record's stroke), by what each check asks: (B, d) physical parameters -> {what: (B,) bool}, the support their
    # conjunction (``inside``), each named where a point fails (``support_failures``); None: the box alone
    checks: Callable[[np.ndarray], dict[str, np.ndarray]] | None = None
    # a law's parametrisation: its map (names, kernel rows, forces, models of parameters); None otherwise
    law: LawMap | None = None

    def __post_init__(self):
        # a Gaussian prior enters the sampler's posterior, not the point estimate's least squares: it is
        # for parameters the likelihood does not see (the weighed mass)
        if not set(self.gaussian) <= set(self.fixed_sd):
            raise ValueError("a Gaussian prior is supported only on a parameter held by the point estimate")

    def free(self) -> np.ndarray:
        """Mask of the parameters the likelihood sees (estimated by the point estimate)."""
        mask = np.ones(len(self.names), bool)
        mask[list(self.fixed_sd)] = False
        return mask

    def physical(self, phi: np.ndarray) -> np.ndarray:
        """The physical parameters of sampled ones ``phi``."""
        return phi if self.to_physical is None else self.to_physical(phi)

    def log_prior_sampled(self, phi: np.ndarray, log_sigma: np.ndarray) -> np.ndarray:
        """Log prior density of the sampled coordinates: the physical prior times the Jacobian."""
        lp = self.log_prior(self.physical(phi), log_sigma)
        return lp if self.log_jacobian is None else lp + self.log_jacobian(phi)

    def inside(self, theta: np.ndarray) -> np.ndarray:
        """Whether each row of physical parameters ``theta`` (B, d) lies in the prior's support: (B,) bool."""
        ok = np.all((theta > self.lower) & (theta < self.upper), axis=1)
        if self.checks is not None and ok.any():
            ok[ok] = np.logical_and.reduce(list(self.checks(theta[ok]).values()))
        return ok

    def log_prior(self, theta: np.ndarray, log_sigma: np.ndarray) -> np.ndarray:
        """The log prior of physical parameters ``theta`` and noise levels ``log_sigma`` ((B,), or (B, R): each
        record's of a joint fit; flat within the bounds).
        """
        ok = self.inside(theta)
        in_bounds = (log_sigma > math.log(SIGMA_BOUNDS[0])) & (log_sigma < math.log(SIGMA_BOUNDS[1]))
        ok &= in_bounds if in_bounds.ndim == 1 else in_bounds.all(axis=1)  # (B, R): each record's noise
        lp = np.where(ok, 0.0, -np.inf)
        for i, (mu, sd) in self.gaussian.items():
            lp = lp - 0.5 * ((theta[:, i] - mu) / sd) ** 2
        return lp


# The maps are module-level functions bound with ``functools.partial`` (not closures): a fitted Posterior
# pickles with its parametrisation (a dask worker returns it, a cache keeps it).
def _coefficient_params(template: np.ndarray, names: tuple[str, ...], theta: np.ndarray) -> np.ndarray:
    p = np.repeat(template[:, None], theta.shape[0], axis=1)
    for i, name in enumerate(names):  # k1, k2, k3, c, c_nl, k0: each into its named row
        p[POLYNOMIAL_ROWS.get(name) or ROWS[name]] = theta[:, i]
    return p


def _device_params(template: np.ndarray, kf_per_E: float, theta: np.ndarray) -> np.ndarray:
    p = np.repeat(template[:, None], theta.shape[0], axis=1)
    p[DEVICE_ROWS["k_f"]] = kf_per_E * theta[:, 0]
    p[DEVICE_ROWS["alpha"]] = np.radians(theta[:, 1])
    p[ROWS["m"]], p[ROWS["c"]], p[ROWS["c_nl"]] = theta[:, 2], theta[:, 3], theta[:, 4]
    g = DEVICE_ROWS["g"]
    p[g] = template[g] + theta[:, 5]  # the static load's acceleration: g plus the nuisance offset
    return p


_MASS_SCALED = [0, 3, 4]  # E, c, c_nl: taken to the reference mass in the device's sampled coordinates


def _device_to_physical(m_ref: float, phi: np.ndarray) -> np.ndarray:
    out = phi.copy()
    out[:, _MASS_SCALED] *= (phi[:, 2] / m_ref)[:, None]
    return out


def _device_to_sampled(m_ref: float, theta: np.ndarray) -> np.ndarray:
    out = theta.copy()
    out[:, _MASS_SCALED] *= (m_ref / theta[:, 2])[:, None]
    return out


def _device_log_jacobian(m_ref: float, phi: np.ndarray) -> np.ndarray:
    return 3.0 * np.log(phi[:, 2] / m_ref)


def _device_reduce(m_ref: float, phi: np.ndarray) -> np.ndarray:
    out = phi.copy()
    out[:, 2] = m_ref
    return out


def coefficient_parametrisation(start: Model) -> Parametrisation:
    """k1, k2, k3, c, c_nl (and k0 as a nuisance: the record's static offset) around ``start``."""
    names = ("k1", "k2", "k3", "c", "c_nl", "k0")
    x = np.array([getattr(start, n) for n in names])
    span = 10 * np.maximum(np.abs(x), 1e-3 * np.max(np.abs(x)))
    lower, upper = x - span, x + span
    lower[2] = 0.0  # k3 > 0: a hardening spring, a bounded potential
    lower[3] = lower[4] = 0.0  # dissipative damping
    to_params = functools.partial(_coefficient_params, start.kernel_params(), names)

    desc = [
        "k1, k2, k0: uniform within 10x the magnitude of the deterministic start point on either side "
        "(k0, the static offset m g plus any accelerometer bias, is a nuisance parameter)",
        "k3: uniform on (0, 11 k3_start): a hardening spring (bounded potential)",
        "c, c_nl: uniform on (0, 11 x start): dissipative damping",
        f"sigma: log-uniform on ({SIGMA_BOUNDS[0]:g}, {SIGMA_BOUNDS[1]:g}) m",
        f"mass fixed at m = {start.m:g} kg" + (" (per unit mass)" if start.m == 1.0 else " (weighed)"),
    ]
    return Parametrisation(names, "polynomial", to_params, lower, upper, {}, desc)


def device_parametrisation(start: Device, mass_prior: tuple[float, float] | None) -> Parametrisation:
    """E, alpha, m, c, c_nl of the device with its exact geometric restoring force.

    The restoring force is the ``geometric`` law's (``models.laws``: the rod frame of ``shaped.RodFrame`` with
    gravity's constant, K = m g + 2 k_f (s + D0) s'(z)) read in the device's physical parameters: k_f = 3 E I / l^3
    from Young's modulus and the arms' drawings, the frame angle alpha, the mass m, and L, D0 at the drawings'
    values (``docs/device-model.md``); ``law_parametrisation`` of the geometric law samples k_f, D0, L, alpha and
    k0 themselves, the mass held. At the same values both give the same force
    (``tests/methods/test_posterior_laws.py``).
    """
    names = ("E", "alpha_deg", "m", "c", "c_nl", "g_offset")
    lower = np.array([100e9, 2.0, 0.05, 0.0, 0.0, -0.5])
    upper = np.array([320e9, 14.0, 0.6, 50.0, 20.0, 0.5])
    to_params = functools.partial(_device_params, start.kernel_params(), start.k_f / start.E)

    gauss = {} if mass_prior is None else {2: mass_prior}
    m_ref = float(start.m)

    # m z'' + c z' + c_nl z'|z'| + K(z; E, alpha) = -m (b'' + g'): only E/m, c/m, c_nl/m, alpha, g' matter.
    # The sampler works in phi = (E, alpha, m, c, c_nl, g') with E, c, c_nl taken to the reference mass
    # (E m_ref / m, ...): the likelihood is a function of phi without m, and the posterior along the
    # ridge (a cone in E, m, c, c_nl, its width growing with m) becomes a cylinder the DE moves cross
    # in a few steps. The prior stays the physical one, times the Jacobian (m / m_ref)^3.
    to_physical = functools.partial(_device_to_physical, m_ref)
    to_sampled = functools.partial(_device_to_sampled, m_ref)
    log_jacobian = functools.partial(_device_log_jacobian, m_ref)
    reduce = functools.partial(_device_reduce, m_ref)

    if mass_prior is None:
        # uniform m, cut by E's bounds along the ridge: log m spans at most log(320/100)
        s_m = m_ref * min(math.log(upper[2] / lower[2]), math.log(upper[0] / lower[0])) / math.sqrt(12)
    else:
        s_m = mass_prior[1]

    desc = [
        "E: uniform on (100, 320) GPa (any steel or spring alloy, generously)",
        "alpha: uniform on (2, 14) deg (the design's 8 deg +- 6 deg of frame tolerance)",
        "m: uniform on (0.05, 0.6) kg"
        + ("" if mass_prior is None else f" times the scale's N({mass_prior[0]:g}, {mass_prior[1]:.2g}) kg (weighed)"),
        "c, c_nl: uniform on (0, 50) N s/m and (0, 20) N s^2/m^2 (dissipative)",
        f"sigma: log-uniform on ({SIGMA_BOUNDS[0]:g}, {SIGMA_BOUNDS[1]:g}) m",
        "g_offset: uniform on (-0.5, 0.5) m/s^2, a nuisance: the static load's apparent acceleration differs from g "
        "by the accelerometer's bias (without it alpha took the bias up, 0.05 deg off at 0.02 m/s^2, measured)",
        "geometry (L, l, b, h, D0) fixed at the drawings' values",
    ]
    return Parametrisation(
        names,
        "device",
        to_params,
        lower,
        upper,
        gauss,
        desc,
        {2: s_m},
        to_physical,
        to_sampled,
        log_jacobian,
        reduce,
    )


# ------------------------------------------------------------------------------------------------
# A law's parametrisation
# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class LawMap:
    """How a restoring and a damping law's parameters (``names``, ``refine.parameter_names``' spelling) make the
    simulator's kernel parameters, the restoring force and a model, for one row of parameters or a batch.

    ``start`` is the model whose parameters are varied (the deterministic start: its mass, its shaped parts' fixed
    fields, a spline's knots); ``rows`` the kernel row each base field or scalar part writes (-1: none, a parameter
    that is a shaped part's); ``parts`` each shaped part's registry name and the parameter columns of its
    ``parameters``.
    """

    restoring: laws.Law
    damping: laws.Law
    names: tuple[str, ...]
    start: Model
    template: np.ndarray
    rows: tuple[int, ...]
    parts: tuple[tuple[str, tuple[tuple[str, int], ...]], ...]
    shift: int = -1  # the column of ``SHIFT`` (the centred parts' centre in the record's frame), -1: none

    @classmethod
    def of(cls, start: Model, restoring: laws.Law, damping: laws.Law, names: tuple[str, ...]) -> LawMap:
        """The map of ``names`` (base fields, scalar parts, ``PART.PARAMETER``, ``SHIFT``) about ``start``."""
        lay = effects.layout()
        rows = []
        for n in names:
            if "." in n or n == SHIFT:
                rows.append(-1)
            elif n in POLYNOMIAL_ROWS:
                rows.append(POLYNOMIAL_ROWS[n])
            elif n in ROWS:
                rows.append(ROWS[n])
            else:  # a scalar part (a monomial, the smoothed sign): its layout row
                rows.append(lay.rows[n][0])
        parts = []
        for name in effects.REGISTRY:
            if isinstance(name.law, ShapedLaw) and name.name in start.extra:
                cols = tuple((n.partition(".")[2], i) for i, n in enumerate(names) if n.partition(".")[0] == name.name)
                parts.append((name.name, cols))
        template = start.kernel_params().copy()
        for r in set(rows) - {-1}:
            template[r] = 0.0  # written from the parameters (summed where two share a row)
        shift = names.index(SHIFT) if SHIFT in names else -1
        return cls(restoring, damping, tuple(names), start, template, tuple(rows), tuple(parts), shift)

    def start_values(self) -> np.ndarray:
        """The start's parameters (``refine.values_of``; the shift 0: the parts centred where the record's z is 0)."""
        from negstiff.inference.steps.refine import values_of

        law_names = [n for n in self.names if n != SHIFT]
        x = dict(zip(law_names, values_of(self.start, law_names), strict=True))
        return np.array([x.get(n, 0.0) for n in self.names])

    def _values(self, theta: np.ndarray) -> list[tuple[ShapedLaw, Mapping[str, Any]]]:
        """Each shaped part's batch of values (``ShapedLaw.batch``) of parameters ``theta`` (B, d)."""
        out: list[tuple[ShapedLaw, Mapping[str, Any]]] = []
        for name, cols in self.parts:
            law = effects.get(name).law
            assert isinstance(law, ShapedLaw)
            out.append((law, law.batch(self.start.extra[name], {f: theta[:, i] for f, i in cols})))
        return out

    def params(self, theta: np.ndarray) -> np.ndarray:
        """The kernel parameters (rows, B) of parameters ``theta`` (B, d): the start's, with the base and scalar
        rows written and each member's table of the shaped parts (NaN where a member's parts are not finite).
        """
        theta = np.atleast_2d(theta)
        p = np.repeat(self.template[:, None], theta.shape[0], axis=1)
        for i, r in enumerate(self.rows):
            if r >= 0:
                p[r] += theta[:, i]
        if self.parts:
            size = effects.layout().size
            p[size:] = effects.tabulate_members(self._values(theta))
            if self.shift >= 0:  # K(z - s) = (k0 + k1 s) - k1 z + parts(z - s): the table's knots moved by s
                s = theta[:, self.shift]
                k1 = theta[:, self.names.index("k1")] if "k1" in self.names else self.start.k1
                p[size] += s
                p[POLYNOMIAL_ROWS["k0"]] += k1 * s
        return p

    def restoring_force(self, theta: np.ndarray, z) -> np.ndarray:
        """K(z) [N] of each row of ``theta`` (B, d) at displacements ``z`` [m] (Z,): (B, Z). The base polynomial
        K = k3 z^3 + k2 z^2 - k1 z + k0, the scalar displacement parts and the shaped parts, all of the batch at
        once.
        """
        theta = np.atleast_2d(theta)
        z = np.asarray(z, float)[None, :]
        if self.shift >= 0:  # the law about its parts' centre s in the record's frame: K(z - s)
            z = z - theta[:, self.shift, None]
        start = self.start
        base = {k: np.full(theta.shape[0], float(getattr(start, k) or 0.0)) for k in ("k0", "k1", "k2", "k3")}
        K = np.zeros((theta.shape[0], z.shape[1]))
        fixed_extra = dict(start.extra)
        for i, n in enumerate(self.names):
            if n in base:
                base[n] = theta[:, i]
            elif "." not in n and n in fixed_extra:
                law = effects.get(n).law
                assert isinstance(law, effects.Monomial | effects.SmoothSign)  # a scalar part
                if law.displacement_only:  # its value a column of sizes (B, 1): the law broadcasts
                    K += law.force(cast(Any, theta[:, i, None]), z, 0.0)
                fixed_extra.pop(n)
        K += base["k3"][:, None] * z**3 + base["k2"][:, None] * z**2 - base["k1"][:, None] * z + base["k0"][:, None]
        for name, _ in self.parts:
            fixed_extra.pop(name, None)
        K += effects.stiffness_force(fixed_extra, z)  # the start's parts no parameter moves
        for law, value in self._values(theta):
            K += np.broadcast_to(law.force(value, z), K.shape)
        return K

    def damping_force(self, theta: np.ndarray, v) -> np.ndarray:
        """D(v) [N] of each row of ``theta`` (B, d) at velocities ``v`` [m/s] (V,): (B, V). The base c v +
        c_nl v|v| and the scalar velocity parts (their start's values where no parameter moves them).
        """
        theta = np.atleast_2d(theta)
        v = np.asarray(v, float)[None, :]
        coef = {k: np.full(theta.shape[0], float(getattr(self.start, k) or 0.0)) for k in ("c", "c_nl")}
        sizes = {n: np.full(theta.shape[0], float(val)) for n, val in self.start.extra.items()
                 if not n.startswith(effects.AUX_PREFIX)
                 and isinstance(effects.get(n).law, effects.Monomial | effects.SmoothSign)
                 and not effects.get(n).law.displacement_only}  # fmt: skip
        for i, n in enumerate(self.names):
            if n in coef:
                coef[n] = theta[:, i]
            elif n in sizes:
                sizes[n] = theta[:, i]
        D = coef["c"][:, None] * v + coef["c_nl"][:, None] * v * np.abs(v)
        for n, size in sizes.items():
            law = effects.get(n).law
            assert isinstance(law, effects.Monomial | effects.SmoothSign)  # a velocity part of its own
            D = D + law.force(cast(Any, size[:, None]), 0.0, v)
        return D

    def model(self, row: np.ndarray) -> Model:
        """The model of one row of parameters (the start's with them set: ``refine.with_values``); with a ``SHIFT``,
        the law's model in its parts' own frame (the record's z less the shift).
        """
        from negstiff.inference.steps.refine import with_values

        keep = [i for i, n in enumerate(self.names) if n != SHIFT]
        return with_values(self.start, [self.names[i] for i in keep], np.asarray(row, float)[keep])


def _law_checks(lawmap: LawMap, reach: tuple[float, float], tails: tuple[str, ...], speeds: np.ndarray | None,
                theta: np.ndarray) -> dict[str, np.ndarray]:  # fmt: skip
    """Each check of the support beyond the box (``law_parametrisation``), by what it asks, each row's verdict:
    every shaped part's span covers the record's ``reach`` [m] (its table holds every z the record visited), each
    spline named in ``tails`` rises outward at both ends of its knots (its straight lines beyond them: a bounded
    potential), and, given ``speeds`` [m/s] (a damping law with signed parts), the damping force's power D(v) v is
    >= 0 at each.
    """
    out = {}
    ok = np.ones(theta.shape[0], bool)
    s = theta[:, lawmap.shift] if lawmap.shift >= 0 else 0.0  # the parts' centre in the record's frame
    for law, value in lawmap._values(theta):
        lo, hi = law.span(value)
        ok &= np.ravel(np.broadcast_to(lo, (theta.shape[0], 1))) + s < reach[0]
        ok &= np.ravel(np.broadcast_to(hi, (theta.shape[0], 1))) + s > reach[1]
    out["the shaped parts' tables span the record's stroke"] = ok
    for name in tails:
        spline = effects.get(name).law
        assert isinstance(spline, Spline)
        value = spline.batch(lawmap.start.extra[name], {f: theta[:, i] for f, i in dict(lawmap.parts)[name]})
        knots = np.asarray(value["knots"], float)
        k = spline.stiffness(value, knots[[0, -1]])
        out[f"{name} rises outward at its end knots"] = np.all(np.reshape(k, (theta.shape[0], 2)) > 0, axis=1)
    if speeds is not None:
        out[f"the damping dissipates at every speed up to {float(np.max(speeds)):.3g} m/s"] = np.all(
            lawmap.damping_force(theta, speeds) * speeds >= 0.0, axis=1
        )
    return out


def support_failures(par: Parametrisation, theta: np.ndarray) -> list[str]:
    """What one row of parameters ``theta`` (d,) fails of a parametrisation's support (its ``checks``)."""
    if par.checks is None:
        return []
    return [what for what, ok in par.checks(np.atleast_2d(theta)).items() if not ok[0]]


SHIFT = "z_shift"
"""The name of a law's nuisance parameter: the centre of its centred parts (``ShapedLaw.centred``: facing magnets,
oblique springs) in the record's frame [m]."""
SHIFT_WIDTH = 0.1
"""The shift's uniform prior: within this share of the record's stroke (its lowest to highest z) either side of 0."""

PRIOR_WIDTH = 10.0
"""A law parameter's uniform prior spans this many times its size on either side of the deterministic start (its
size: the start's magnitude, or the parameter's natural scale where the start is near zero), cut by physics."""


def _top_power(restoring: laws.Law) -> tuple[str, int] | None:
    """The restoring law's highest power of z that it frees, and the parameter that sizes it (a field or a part)."""
    terms = [(f, effects.BASE_TERMS[f][0].z_power) for f in restoring.fields]
    for p in restoring.parts:
        law = effects.get(p).law
        if isinstance(law, effects.Monomial) and law.displacement_only:
            terms.append((p, law.z_power))
    return max(terms, key=lambda t: t[1]) if terms else None


def law_parametrisation(start: Model, restoring: laws.Law, damping: laws.Law, reach: tuple[float, float],
                        z_rms: float, v_rms: float, v_max: float | None = None) -> Parametrisation:  # fmt: skip
    """Every parameter of a restoring and a damping law about the deterministic start ``start`` (the laws' model:
    the weak form at the law's shape, refined by output error), with uniform priors cut by physics (module
    docstring; ``description`` states each).

    Parameters
    ----------
    start : Model
        The laws' model (its mass held, as the coefficient posterior holds it).
    restoring, damping : Law
        The laws (``models.laws``).
    reach : (float, float)
        The record's lowest and highest z [m]: the shaped parts must be tabulated over it (their span covers it).
    z_rms, v_rms : float
        The record's rms displacement [m] and velocity [m/s]: each parameter's natural scale (``refine``'s).
    v_max : float, optional
        The record's largest speed [m/s] (default: 3 ``v_rms``): a damping law with ``signed`` parts dissipates at
        every speed up to it.

    Returns
    -------
    Parametrisation
        Its ``law`` the map to kernel parameters, forces and models (``LawMap``).
    """
    from negstiff.inference.steps.refine import parameter_names, parameter_scales, values_of

    v_max = 3.0 * v_rms if v_max is None else v_max
    free = set(restoring.fields) | set(damping.fields)
    held = tuple(f for f in ("k0", "k1", "k2", "k3", "c", "c_nl") if f not in free)
    names = parameter_names(start, False, held)
    x = values_of(start, names)
    size = np.maximum(np.abs(x), parameter_scales(start, names, z_rms, v_rms))
    for i, n in enumerate(names):  # a shaped part's parameter: its own scale (a spline's: its largest coefficient)
        part, _, fld = n.partition(".")
        if fld:
            law = effects.get(part).law
            assert isinstance(law, ShapedLaw)
            value = start.extra[part]
            coef = np.abs(np.asarray(value["coef"], float)) if isinstance(law, Spline) else None
            size[i] = float(coef.max()) if coef is not None else max(abs(x[i]), law.scale(value, z_rms)[fld])
    lower, upper = x - PRIOR_WIDTH * size, x + PRIOR_WIDTH * size
    desc = [f"every parameter uniform within {PRIOR_WIDTH:g}x its size on either side of the deterministic start "
            "(its size: the start's magnitude, or its natural scale at the record's rms state where that is larger; "
            "a spline's coefficients: the largest one's), cut by physics:"]  # fmt: skip
    for i, n in enumerate(names):
        part, _, fld = n.partition(".")
        if n in damping.signed:  # its sign the data's: the law's damping as a whole dissipates (the support)
            desc.append(f"{n}: either sign, the {damping.name} law's damping force dissipating at every speed up to "
                        f"the record's largest, {v_max:.3g} m/s")  # fmt: skip
        elif not fld and n in ("c", "c_nl") or (not fld and n not in effects.BASE_TERMS and effects.get(n).dissipative):
            lower[i] = max(lower[i], 0.0)
            desc.append(f"{n}: > 0 (dissipative)")
        if fld:
            law = effects.get(part).law
            assert isinstance(law, ShapedLaw)
            if fld in law.bounds:
                lo_b, hi_b = law.bounds[fld]
                lower[i], upper[i] = max(lower[i], lo_b), min(upper[i], hi_b)
                desc.append(f"{n}: within ({lo_b:g}, {hi_b:g}) ({part}'s physical range)")
    top = _top_power(restoring)
    if top is not None and top[1] >= 3 and top[1] % 2:  # an odd top power: its coefficient positive, a bounded tail
        i = names.index(top[0])
        lower[i] = max(lower[i], 0.0)
        desc.append(f"{top[0]}: > 0 (the top power z^{top[1]} hardens: a bounded potential)")
    elif top is not None and top[0] == "k1" and restoring.shaped():
        i = names.index("k1")  # the shaped parts fade or saturate far out: the linear spring bounds the potential
        upper[i] = min(upper[i], 0.0)
        desc.append("k1: < 0 (K holds -k1 z: the linear spring stiffens the device beyond where its "
                    f"{', '.join(restoring.shaped())} part acts, a bounded potential)")  # fmt: skip
    if start.m == 1.0:
        desc.append(f"mass fixed at m = {start.m:g} kg (per unit mass)")
    else:
        desc.append(f"mass fixed at m = {start.m:g} kg (weighed)")
    desc.append(f"sigma: log-uniform on ({SIGMA_BOUNDS[0]:g}, {SIGMA_BOUNDS[1]:g}) m")
    centred = [p for p, law in restoring.shaped().items() if law.centred]
    if centred and set(restoring.fields) <= {"k0", "k1"} and set(restoring.parts) <= set(restoring.shaped()):
        # the parts' centre where the record's z is 0 only by construction (a derived z pinned between the fitted
        # wells, a laser zeroed elsewhere): a nuisance, its uncertainty carried into the force's band
        half = SHIFT_WIDTH * (reach[1] - reach[0])
        names = (*names, SHIFT)
        lower, upper = np.append(lower, -half), np.append(upper, half)
        desc.append(f"{SHIFT}: uniform on ({-1e3 * half:.3g}, {1e3 * half:.3g}) mm, a nuisance: the "
                    f"{', '.join(centred)} part's centre in the record's frame (K(z) is the law's K(z - {SHIFT}); the "
                    "models of the mean and of the draws are in the part's own frame)")  # fmt: skip
    lawmap = LawMap.of(start, restoring, damping, names)
    tails = tuple(p for p, law in restoring.shaped().items() if isinstance(law, Spline))
    for p in tails:
        desc.append(f"{p}: rising at both end knots (its straight lines beyond them: a bounded potential)")
    if lawmap.parts:
        desc.append(f"the shaped parts ({', '.join(n for n, _ in lawmap.parts)}) tabulated over every z the record "
                    f"visited, [{1e3 * reach[0]:.4g}, {1e3 * reach[1]:.4g}] mm: their span covers it")  # fmt: skip
    speeds = np.linspace(-v_max, v_max, 41) if damping.signed else None
    checks = functools.partial(_law_checks, lawmap, (float(reach[0]), float(reach[1])), tails, speeds)
    desc.append(f"restoring law {restoring.name} ({restoring.title}); damping law {damping.name} ({damping.title})")
    return Parametrisation(tuple(names), start.kind, lawmap.params, lower, upper, {}, desc, checks=checks,
                           law=lawmap)  # fmt: skip
