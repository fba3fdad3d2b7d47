"""NSI of a single DOF on the base, in the time domain, around either stable well.

Marchesiello & Garibaldi (2008), MSSP 22:81-101 ("A time domain approach for identifying nonlinear
vibrating structures by subspace methods"); the reference-position shift of the reference study (Eqs. 5-7);
``docs/algorithms.md`` part A (a reconstruction verified numerically, followed here).

The nonlinear terms act as feedback forces on the underlying-linear system (ULS). Around the
reference z* (x = z - z*), per unit mass,

    x'' + (c/m) x' + (k1~/m) x = u - sum_j (c_j/m) g_j(x, x'),   u = -b'' (base) or f/m (force)

with the basis g = [x^2, x^3, x'|x'|] (reference study Eq. 7 for the polynomial, the reference study's damping model for
x'|x'|) and a constant K(z*)/m that vanishes when z* is the equilibrium. Every channel is made zero
mean, so the subspace step sees only the dynamics; the constant then follows from the time average
of the equation of motion (with the record's mean velocity and acceleration, both near zero). A
constant input channel, the alternative of algorithms.md A.7, is poorly determined (|Im/Re| ~ 0.4
noise-free) and leaks into k2~ through the mean of x^2 (+12 % measured), so it is not used. The extended input
[u, -g_1, ..., -g_J] (each channel scaled to unit std, A.2.8) goes through a generic LTI subspace
step (``subspace``), whose
extended FRF H_e(omega) = [H, c_1 H, ..., c_J H] gives c_j = mean over a band around resonance of
Re(H_e,j / H_e,0) (A.4), with |Im/Re| as the quality index. The ULS's natural frequency and damping
come from the physical pole of A_c (reference study Table 1). The well z* is found from the data: first the
modes of the displacement histogram, then the identified polynomial's own root (one more pass there).

Velocity for x'|x'|: the record's band states (``Measurement.states("band")``, computed once per record): a
Savitzky-Golay derivative whose window is fitted to the data's band (``derivatives.velocity_window``), so
it averages sensor noise without bending the response. The polynomial bases use the same smoothed
displacement (errors-in-variables, A.8). These are not the regression states the weak form uses (their
window is chosen for the least coefficient bias and may bend the band): NSI's frequency-domain fit needs
the band's gain flat.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import signal

from negstiff.errors import MeasurementError
from negstiff.inference.estimators import subspace
from negstiff.models.laws import FeedbackBasis

BASIS_NAMES = ("x2", "x3", "vabsv")
"""The cubic law's nonlinear basis with the reference study's damping: x^2, x^3, x'|x'| (their coefficients are
k2~, k3, c_nl); any other law's is ``FeedbackBasis``'s."""


def reduce(basis: np.ndarray, tol: float = 1e-9) -> np.ndarray:
    """A (functions, k) map onto the independent combinations of ``basis``'s columns (samples, functions): the
    right singular vectors above ``tol`` of the largest (the identity where they are independent already).
    """
    scale = basis.std(axis=0)
    scale[scale == 0] = 1.0
    _, sv, vt = np.linalg.svd(basis / scale, full_matrices=False)
    keep = sv > tol * sv.max() if sv.size else np.zeros(0, bool)
    if keep.all():
        return np.eye(basis.shape[1])
    return (vt[keep] / scale).T


INPUT_SPREAD = 0.1
"""An input covers NSI's averaging band when its power there is spread over at least this share of the
band's frequency bins (effective count (sum p)^2 / sum p^2 of a Welch spectrum): a multisine or random
input spreads over nearly all, a harmonic one over one or two."""


def covers_band(u: np.ndarray, fs: float, band: tuple[float, float]) -> bool:
    """Whether the input's power spreads over the band (``INPUT_SPREAD``) rather than sitting in a few lines."""
    f, p = signal.welch(u - u.mean(), fs, nperseg=min(u.size, int(8 * fs)))
    p = p[(f >= band[0]) & (f <= band[1])]
    if p.size < 3 or not p.sum() > 0:
        return False
    return float(p.sum() ** 2 / np.sum(p**2)) >= INPUT_SPREAD * p.size


def decay_feedback(ss: subspace.StateSpace, freqs: np.ndarray, wn: float, zeta: float, gains: np.ndarray) -> np.ndarray:
    """A free decay's nonlinear coefficients over the band, per unit mass (Anastasio & Marchesiello 2019, the
    free-decay form of NSI: no linear input, the feedback channels alone).

    Without a measured input the ratios H_e,j / H_e,0 of the forced form do not exist; the extended FRF's
    feedback columns are read against the identified pole's own per-unit-mass FRF instead, c_j = H_e,j(omega)
    (wn^2 - omega^2 + 2 i zeta wn omega), from the discrete-time model (the FRF level below Nyquist, as the
    forced form's input gain). ``gains`` rescales each standardised channel to the physical one (y std over
    the channel's std). Returns (F, J) complex: the real part is c_j, the imaginary part the quality index.
    """
    hd = ss.frf_discrete(freqs)[:, 0, :] * gains
    w = 2 * np.pi * freqs
    return hd * (wn**2 - w**2 + 2j * zeta * wn * w)[:, None]


@dataclass(frozen=True)
class _WellForce:
    """An identified restoring force per unit mass about a reference z_g: const + wn^2 x + sum_j c_j D_j(x),
    x = z - z_g, D_j the law's displacement basis (``FeedbackBasis.displacement``).
    """

    basis: FeedbackBasis
    z_g: float
    const: float
    wn2: float
    c: np.ndarray

    def __call__(self, x):
        x = np.atleast_1d(np.asarray(x, float))
        return self.const + self.wn2 * x + self.basis.displacement(x, self.z_g) @ self.c

    def at(self, z):
        """The force at absolute z [m] (per unit mass)."""
        return self(np.asarray(z, float) - self.z_g)

    def derivatives(self, x: float) -> tuple[float, float, float]:
        """The first three derivatives at x: exact for powers, central differences elsewhere."""
        powers = [(j, int(n[1:])) for j, n in enumerate(self.basis.names()[: self.c.size]) if n[1:].isdigit()]
        out = [self.wn2, 0.0, 0.0]
        for j, p in powers:
            out[0] += self.c[j] * p * x ** (p - 1)
            out[1] += self.c[j] * p * (p - 1) * x ** (p - 2) if p >= 2 else 0.0
            out[2] += self.c[j] * p * (p - 1) * (p - 2) * x ** (p - 3) if p >= 3 else 0.0
        rest = [j for j in range(self.c.size) if j not in dict(powers)]
        if rest:
            h = 1e-4 * max(abs(self.z_g), 1e-2)
            xs = x + h * np.arange(-2, 3)
            g = self.basis.displacement(xs, self.z_g)[:, rest] @ self.c[rest]
            out[0] += float((g[3] - g[1]) / (2 * h))
            out[1] += float((g[3] - 2 * g[2] + g[1]) / h**2)
            out[2] += float((g[4] - 2 * g[3] + 2 * g[1] - g[0]) / (2 * h**3))
        return float(out[0]), float(out[1]), float(out[2])


def _stable_root(force: _WellForce, span: float) -> float | None:
    """The stable root (positive slope) of ``force`` nearest x = 0 within twice the motion's span: sign changes
    on a grid, then Brent's method.
    """
    from scipy.optimize import brentq

    grid = np.linspace(-2 * span, 2 * span, 4001)
    f = force(grid)
    roots = []
    for i in np.flatnonzero(np.sign(f[:-1]) * np.sign(f[1:]) <= 0):
        if f[i] == 0.0:
            roots.append(float(grid[i]))
        elif f[i + 1] != 0.0:
            roots.append(brentq(lambda x: float(force(x)[0]), grid[i], grid[i + 1], xtol=1e-15, rtol=1e-14))
    stable = [r for r in roots if force.derivatives(r)[0] > 0]
    return min(stable, key=abs) if stable else None


class NSIError(MeasurementError):
    """The record cannot be identified (too short, not enough excitation, no physical pole)."""


@dataclass(frozen=True)
class WellFit:
    """NSI around one reference well (per unit mass unless ``mass`` scales it later)."""

    z_ref: float
    f_hz: float
    zeta: float
    coefficients: dict[str, float]
    """Per unit mass, shifted frame at z_ref: k1_tilde, k2_tilde, k3, c, c_nl; and the last pass's
    constant (K/m at its reference) and shift to the root, which show how well z_ref converged."""
    quality: dict[str, float]
    """|Im/Re| of each nonlinear coefficient over the averaging band."""
    band_hz: tuple[float, float]
    singular_values: list[float]
    frf: dict[str, Any]
    lq_routes: tuple[str, ...] = ()
    """Each pass's route of the subspace step's LQ factor (``subspace.LQ_ROUTES``)."""
    force: Any = None
    """The identified restoring force about the well (``_WellForce``: per unit mass, K(z*) = 0 at ``z_ref``)."""
    damping_coefficients: tuple[float, ...] = ()
    """The damping law's coefficients per unit mass, its columns' order (c first)."""


def physical_pole(ss: subspace.StateSpace, column: int | None = 0) -> complex:
    """The pole of the ULS: among underdamped stable poles (0 < zeta < 0.7), the one with the
    largest modal contribution |residue / Re(lambda)| to the linear input column (Marchesiello,
    Fasana & Garibaldi 2016; algorithms.md A.5). For order 2 it is the only pair. ``column`` None (a free
    decay, no linear input): the contribution to all input columns (the feedback channels) together.
    """
    lam, psi = np.linalg.eig(ss.A)
    left = np.linalg.inv(psi)
    best, score = None, -1.0
    for r, lr in enumerate(lam):
        if lr.imag <= 0:
            continue
        zeta = -lr.real / abs(lr)
        if not 0 < zeta < 0.7:
            continue
        b = left[r] @ (ss.B if column is None else ss.B[:, column])
        res = abs((ss.C @ psi[:, r])[0]) * float(np.linalg.norm(np.atleast_1d(b)))
        s = res / abs(lr.real)
        if s > score:
            best, score = lr, s
    if best is None:
        raise NSIError("no stable underdamped pole was identified (no physical mode in the data)")
    return complex(best)
