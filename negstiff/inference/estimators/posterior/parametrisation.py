"""What the posterior samples: the coefficient and device parametrisations, their priors and maps to the
simulator's kernel parameters.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from negstiff.inference.estimators.posterior.windows import SIGMA_BOUNDS
from negstiff.models import Model
from negstiff.models.device import Device
from negstiff.models.effects import DEVICE_ROWS, POLYNOMIAL_ROWS, ROWS


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

    def log_prior(self, theta: np.ndarray, log_sigma: np.ndarray) -> np.ndarray:
        """The log prior of physical parameters ``theta`` and noise levels ``log_sigma`` (flat within the bounds)."""
        ok = np.all((theta > self.lower) & (theta < self.upper), axis=1)
        ok &= (log_sigma > math.log(SIGMA_BOUNDS[0])) & (log_sigma < math.log(SIGMA_BOUNDS[1]))
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
    """E, alpha, m, c, c_nl of the device with its exact geometric restoring force."""
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
