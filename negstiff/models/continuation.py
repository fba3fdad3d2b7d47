"""Periodic responses of a model under harmonic excitation, continued in the excitation's amplitude or
frequency, with their Floquet stability and bifurcations (issue 16).

    m z'' + D(z') + K(z) + extra(z, z') = -m A sin(2 pi f t)    (base acceleration b'' = A sin(2 pi f t))
                                        =  A sin(2 pi f t)       (force)

A periodic orbit of period p/f (p = 1, 2, 4, ...) is a fixed point of the stroboscopic map: x(0) =
phi_{p/f}(x(0); lambda), x = (z, z'), lambda the amplitude or the frequency (**shooting**; Seydel,
*Practical Bifurcation and Stability Analysis*, 3rd ed., 7.3). The flow is the simulator's RK4 kernel
(``simulate_batch``) with the forcing given exactly at every Runge-Kutta stage time (``staged``), so
the orbit is the model's, with the kernel's O(h^4) error only (256 steps a period by default: 1e-8
of the amplitude on a linear oscillator). Shooting, not harmonic balance, because it handles every
model the simulator does (the exact device geometry, end stops, Coulomb friction) without truncating
the harmonics, and because the monodromy matrix comes with it.

* **Monodromy and Jacobians** by central differences of the flow: the base state, the state's four
  perturbations and the parameter's two run as one batched simulator call (seven members; in
  frequency the parameter's pair needs its own time step, a second call).
* **Pseudo-arclength continuation** (Keller 1977) of G(x, lambda) = phi(x; lambda) - x = 0 in scaled
  unknowns, predictor along the tangent (the null vector of [G_x, G_lambda]), Newton corrector on
  G = 0 and the arclength condition; the step grows after easy corrections and halves after hard ones,
  so folds are passed, not stopped at.
* **Stability**: the Floquet multipliers are the eigenvalues of the monodromy matrix M = phi_x. A
  **fold** is a real multiplier through +1 (det(M - I) changes sign, and so does d lambda / ds), a
  **period doubling** a multiplier through -1 (det(M + I) changes sign), a **Neimark-Sacker** a
  complex pair through the unit circle. (For a single-degree-of-freedom oscillator with positive
  damping, det M = exp(-int c_eff/m dt) < 1, so a complex pair can never leave the circle: no
  Neimark-Sacker bifurcation exists; the check serves models with negative effective damping, and is
  tested on a forced Duffing-Rayleigh oscillator against scipy's DOP853.)
  Each detected point is located by regula falsi on its test function along the branch (in the
  arclength of the step that crossed it), each trial orbit corrected onto the branch.
* **Branch switching** at a period doubling: the period-2p orbit is found by simulating from the
  bifurcating orbit a little beyond the doubling (where the period-p orbit is unstable), then
  correcting with the 2p map; it is continued like any branch.

Library check (2026-11). PyDSTool's PyCont: last release 0.91.0 (2020); periodic orbits only through
its AUTO interface (swig and a C compiler) and for autonomous systems, so a forced oscillator must be
autonomised by hand (a user's forced Duffing could not get its period: pydstool issue 166, 2021).
pycont-lite (MIT, first release 2025, one author): pseudo-arclength for G(u, p) = 0 with fold and
branch-point detection; it could follow G = phi(x) - x, but its stability and its test functions are
those of an equilibrium of G (G's Jacobian M - I stays regular at a period doubling), so it would
neither give Floquet multipliers nor see a doubling, and the corrector is the small part of this
module. BifurcationKit is Julia; the reference study's authors' HBSS_Cont is MATLAB under GPL-3 (not copied).
So the method is written here, on the suite's own simulator.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import fft as sp_fft

from negstiff.errors import InputError

from .simulator import simulate_batch
from .structure import Structure, relative, simulate_structures

STEPS_PER_PERIOD = 256
"""RK4 steps per forcing period: 128 samples x 2 substeps (the kernel's O(h^4) error: ~1e-8)."""
_SAMPLES = 128
_SUBSTEPS = 2
MAX_MULTIPLIER = 1e6
"""A branch ends where its orbit's largest Floquet multiplier exceeds this: a perturbation grows a
millionfold in one period, the central differences of the flow (1e-6 of the state) no longer give the
monodromy, and such orbits lie inside chaos no experiment can hold. Measured: the as-built device's
period-4 branch from z_plus crept on in ever smaller steps near 26 m/s^2 until the point limit (2000 orbits,
18 s); there the steps shrank instead, which ends a branch too (``Continuation.run``)."""
RETRACE_STEPS = 8
"""Small steps a bifurcation's step is retraced in where locating along the whole step fails (``_locate``)."""


class ContinuationError(InputError):
    """The continuation cannot start or go on (no periodic orbit found, the model diverges)."""


@dataclass(frozen=True)
class Point:
    """One periodic orbit: the parameters, the state at phase 0, its extremes and harmonics, stability."""

    amplitude: float
    f_hz: float
    x0: tuple[float, ...]
    """The state at phase 0: (z, z') of a single DOF; (z_1..z_N, z_1'..z_N') of a structure."""
    max_z: float
    min_z: float
    harmonics: tuple[float, ...]
    poincare_z: tuple[float, ...]
    multipliers: tuple[complex, ...]
    tangent_lambda: float

    @property
    def max_multiplier(self) -> float:
        """The largest Floquet multiplier's modulus."""
        return float(max(abs(m) for m in self.multipliers))

    @property
    def stable(self) -> bool:
        """Whether every Floquet multiplier lies inside the unit circle."""
        return self.max_multiplier < 1.0

    def halves(self, tol: float = 1e-6) -> bool:
        """Whether this orbit of an even number p of forcing periods repeats after p/2 of them (its z at
        phase 0 of period k and k + p/2 within ``tol`` of its stroke): the period-p/2 orbit it was born from.
        """
        p = len(self.poincare_z)
        if p < 2 or p % 2:
            return False
        z = np.array(self.poincare_z)
        return bool(np.max(np.abs(z[: p // 2] - z[p // 2 :])) <= tol * (self.max_z - self.min_z))

    def to_json(self) -> dict[str, Any]:
        """The point as JSON."""
        return {
            "amplitude": self.amplitude,
            "f_hz": self.f_hz,
            "z0": self.x0[0],
            "v0": self.x0[len(self.x0) // 2],
            **({"state": list(self.x0)} if len(self.x0) > 2 else {}),
            "max_z": self.max_z,
            "min_z": self.min_z,
            "harmonics": list(self.harmonics),
            "poincare_z": list(self.poincare_z),
            "stable": self.stable,
            "max_multiplier": self.max_multiplier,
            "multipliers": [[m.real, m.imag] for m in self.multipliers],
        }


@dataclass
class Branch:
    """A continued branch of period ``period`` (in forcing periods) in ``parameter``."""

    period: int
    parameter: str
    well: str
    points: list[Point] = field(default_factory=list)

    def to_json(self) -> dict[str, Any]:
        """The branch as JSON: its period, parameter and points."""
        return {
            "period": self.period,
            "parameter": self.parameter,
            "well": self.well,
            "points": [p.to_json() for p in self.points],
        }


class Shooting:
    """The stroboscopic map of a system under harmonic forcing, with its derivatives.

    ``system``: a ``Model`` or ``Device``; ``input_kind``: ``"base_acc"`` (A in m/s^2) or ``"force"``
    (A in N); ``period``: forcing periods per map.
    """

    def __init__(self, system, input_kind: str = "base_acc", period: int = 1, z_limit: float = 1.0):
        self.system, self.input_kind, self.period = system, input_kind, int(period)
        self.structure = isinstance(system, Structure)
        self.params = None if self.structure else system.kernel_params()
        self.dofs = system.n_dof if self.structure else 1
        self.dim = 2 * self.dofs
        self.z_limit = z_limit

    def state_scale(self, z_scale: float, f_hz: float) -> np.ndarray:
        """The state's scale for a response of half-stroke ``z_scale`` at ``f_hz``: z_scale for every
        displacement, 2 pi f z_scale for every velocity.
        """
        return np.r_[np.full(self.dofs, z_scale), np.full(self.dofs, 2 * np.pi * f_hz * z_scale)]

    def _forcing(self, amplitude: float, f_hz: float) -> tuple[np.ndarray, float]:
        """The forcing at every RK4 stage time over ``period`` periods, and the sample interval."""
        dt = 1.0 / (f_hz * _SAMPLES)
        n = _SAMPLES * self.period
        r = 2 * _SUBSTEPS
        t = np.arange(r * n + 1) * (dt / r)
        return amplitude * np.sin(2 * np.pi * f_hz * t), dt

    def flow(self, xs: np.ndarray, amplitudes, f_hz: float, store: bool = False):
        """phi(x; A, f) for states ``xs`` (B, 2) and one amplitude per member; (B, 2) end states, and the
        z samples of the members (B, N) when ``store``.
        """
        amplitudes = np.broadcast_to(np.asarray(amplitudes, float), (xs.shape[0],))
        rows, index = np.unique(amplitudes, return_inverse=True)
        u = np.stack([self._forcing(a, f_hz)[0] for a in rows])
        dt = 1.0 / (f_hz * _SAMPLES)
        if self.structure:  # the element's relative displacement r stands for z (the orbit's extremes, harmonics)
            sres = simulate_structures(
                self.system, u, dt, xs, input_kind=self.input_kind, input_index=index, substeps=_SUBSTEPS,
                store_velocity=True, staged=True, z_limit=self.z_limit, v_limit=1e3,
            )  # fmt: skip
            if np.any(sres.diverged):
                raise ContinuationError(f"the orbit left the admissible range: {sres.describe_failures()}")
            assert sres.z_dot is not None
            end = np.hstack([sres.z[:, :, -1], sres.z_dot[:, :, -1]])
            r = relative(sres.z, self.system.place)
            return (end, r) if store else end
        assert self.params is not None  # a single-DOF system's
        res = simulate_batch(
            np.repeat(self.params[:, None], xs.shape[0], axis=1), self.system.kind, u, dt, xs,
            input_kind=self.input_kind, input_index=index, substeps=_SUBSTEPS, store_velocity=True, staged=True,
            z_limit=self.z_limit, v_limit=1e3,
        )  # fmt: skip
        if np.any(res.diverged):
            raise ContinuationError(f"the orbit left the admissible range: {res.describe_failures()}")
        assert res.z_dot is not None  # store_velocity=True
        end = np.column_stack([res.z[:, -1], res.z_dot[:, -1]])
        return (end, res.z) if store else end

    def residual_and_jacobian(self, x: np.ndarray, amplitude: float, f_hz: float, parameter: str, scale,
                              store: bool = False):  # fmt: skip
        """G = phi(x) - x, the monodromy M (2x2), G_lambda (2,): central differences, one batched call (two
        in frequency); with ``store`` also the orbit's z samples (the unperturbed member's).
        """
        d = self.dim
        h = 1e-6 * np.asarray(scale[:d], float)
        hl = 1e-6 * scale[d]
        if not (f_hz - hl > 0 and np.all(np.isfinite(x))):  # a corrector step out of the physical range
            raise ContinuationError(f"the corrector left the physical range (f = {f_hz:.4g} Hz)")
        pert = np.zeros((1 + 2 * d, d))  # the state, then +-h along each coordinate in turn
        for k in range(d):
            pert[1 + 2 * k, k], pert[2 + 2 * k, k] = h[k], -h[k]
        xs = x[None, :] + pert
        amps = np.full(len(xs), amplitude)
        if parameter == "amplitude":
            xs = np.vstack([xs, x, x])
            amps = np.concatenate([amps, [amplitude + hl, amplitude - hl]])
            end, z = self.flow(xs, amps, f_hz, store=True)
            d_lambda = (end[1 + 2 * d] - end[2 + 2 * d]) / (2 * hl)
        else:
            end, z = self.flow(xs, amps, f_hz, store=True)
            ep = self.flow(x[None, :], amplitude, f_hz + hl)[0]
            em = self.flow(x[None, :], amplitude, f_hz - hl)[0]
            d_lambda = (ep - em) / (2 * hl)
        M = np.column_stack([(end[1 + 2 * k] - end[2 + 2 * k]) / (2 * h[k]) for k in range(d)])
        return (end[0] - x, M, d_lambda, z[0]) if store else (end[0] - x, M, d_lambda)

    def point(self, x: np.ndarray, amplitude: float, f_hz: float, M: np.ndarray, tangent_lambda: float,
              z: np.ndarray) -> Point:  # fmt: skip
        """The orbit from ``x`` (its z samples ``z``, N + 1 over the period) with its monodromy ``M``."""
        z = z[:-1]
        spec = sp_fft.rfft(z) / z.size
        harm = 2 * np.abs(spec[self.period :: self.period][:5])  # amplitudes at f, 2f, ... [m]
        mu = np.linalg.eigvals(M)
        state = tuple(float(q) for q in x)
        mus = tuple(complex(m) for m in mu)
        harmonics = tuple(float(h) for h in harm)
        poincare = tuple(float(q) for q in z[::_SAMPLES])  # z at phase 0 of each forcing period
        return Point(float(amplitude), float(f_hz), state, float(z.max()), float(z.min()), harmonics, poincare,
                     mus, float(tangent_lambda))  # fmt: skip


def _tests(M: np.ndarray) -> dict[str, float]:
    """Bifurcation test functions of a monodromy matrix: det(M - I) (fold), det(M + I) (doubling) and
    the complex pair's modulus less one (Neimark-Sacker; +1 when the multipliers are real).
    """
    mu = np.linalg.eigvals(M)
    pairs = mu[np.abs(mu.imag) > 1e-12]  # of two states: both or neither; of 2N: the largest pair counts
    return {
        "fold": float(np.linalg.det(M - np.eye(M.shape[0]))),
        "period_doubling": float(np.linalg.det(M + np.eye(M.shape[0]))),
        "neimark_sacker": float(np.abs(pairs).max() - 1.0) if pairs.size else math.nan,
    }


@dataclass(frozen=True)
class Bifurcation:
    """A bifurcation located along a branch: its type, where, and the crossing multiplier."""

    type: str
    amplitude: float
    f_hz: float
    well: str
    multiplier: complex
    period: int
    x0: tuple[float, ...] = (math.nan, math.nan)

    def value(self, parameter: str) -> float:
        """The continuation parameter's value here (``"amplitude"`` or ``"f_hz"``)."""
        return self.amplitude if parameter == "amplitude" else self.f_hz

    def to_json(self) -> dict[str, Any]:
        """The bifurcation as JSON."""
        mu = self.multiplier
        return {
            "type": self.type,
            "amplitude": self.amplitude,
            "f_hz": self.f_hz,
            "well": self.well,
            "multiplier": mu.real if abs(mu.imag) < 1e-12 else [mu.real, mu.imag],
            "period": self.period,
        }


class Continuation:
    """Pseudo-arclength continuation of the periodic orbits of one ``Shooting`` map (module docstring).

    ``parameter``: ``"amplitude"`` (at the fixed ``f_hz``) or ``"f_hz"`` (at the fixed ``amplitude``);
    ``ds``: the first step, in units of the parameter's range (the step adapts between ``ds_min`` and
    ``ds_max``).
    """

    def __init__(self, shooting: Shooting, parameter: str, fixed: float, well: str, lam_range: tuple[float, float],
                 ds: float = 0.01, ds_min: float = 1e-4, ds_max: float = 0.05, max_points: int = 2000):  # fmt: skip
        if parameter not in ("amplitude", "f_hz"):
            raise ContinuationError(f"the continuation parameter is amplitude or f_hz, not {parameter!r}")
        self.shooting, self.parameter, self.fixed, self.well = shooting, parameter, float(fixed), well
        self.lo, self.hi = sorted(map(float, lam_range))
        self.ds, self.ds_min, self.ds_max, self.max_points = ds, ds_min, ds_max, max_points
        self.reason = ""

    def _af(self, lam: float) -> tuple[float, float]:
        return (lam, self.fixed) if self.parameter == "amplitude" else (self.fixed, lam)

    def _eval(self, y: np.ndarray, scale: np.ndarray, store: bool = False):
        x, lam = y[:-1] * scale[:-1], y[-1] * scale[-1]
        a, f = self._af(lam)
        return self.shooting.residual_and_jacobian(x, a, f, self.parameter, scale, store)

    def correct_fixed(self, x: np.ndarray, lam: float, scale: np.ndarray, tol: float = 1e-10):
        """Newton on G(x) = 0 at a fixed parameter; returns (x, M)."""
        a, f = self._af(lam)
        for _ in range(20):
            G, M, _ = self.shooting.residual_and_jacobian(x, a, f, self.parameter, scale)
            dx = np.linalg.solve(M - np.eye(M.shape[0]), -G)
            x = x + dx
            if np.all(np.abs(dx) < tol * scale[:-1]):
                G, M, _ = self.shooting.residual_and_jacobian(x, a, f, self.parameter, scale)
                return x, M
        raise ContinuationError(f"no periodic orbit of period {self.shooting.period} found at {self.parameter} {lam:g}")

    @staticmethod
    def _jacobian(M: np.ndarray, Gl: np.ndarray, scale: np.ndarray) -> np.ndarray:
        """[G_x, G_lambda] (2x3) in the scaled unknowns, G scaled like the state."""
        return np.column_stack([(M - np.eye(M.shape[0])) * scale[None, :-1], Gl * scale[-1]]) / scale[:-1, None]

    @staticmethod
    def _tangent(M: np.ndarray, Gl: np.ndarray, scale: np.ndarray, previous: np.ndarray | None, sign: float):
        t = np.linalg.svd(Continuation._jacobian(M, Gl, scale))[2][-1]
        if previous is not None:
            return t if t @ previous >= 0 else -t
        return t if t[-1] * sign >= 0 else -t

    def run(self, x: np.ndarray, lam: float, direction: float, scale: np.ndarray) -> tuple[Branch, list[Bifurcation]]:
        """Continue from the orbit at state ``x`` (phase 0) and parameter ``lam`` towards ``direction``
        (+1: increasing parameter) until the parameter leaves its range. The state's scale follows the
        orbit's size, so a step moves the orbit by a fraction of itself (or the parameter by a fraction
        of its range), however much the response grows at a resonance.
        """
        sh = self.shooting
        scale = np.array(scale, float)
        z_floor = scale[0]
        x, M = self.correct_fixed(np.asarray(x, float), lam, scale)
        branch = Branch(sh.period, self.parameter, self.well)
        bifs: list[Bifurcation] = []
        y = np.r_[x, lam] / scale
        G, M, Gl, z = self._eval(y, scale, store=True)
        t = self._tangent(M, Gl, scale, None, direction)
        branch.points.append(sh.point(x, *self._af(lam), M, t[-1], z))
        last = (y * scale, M)  # the last accepted point: physical (z, z', lambda) and its monodromy matrix
        ds, crawl = self.ds, 0
        while len(branch.points) < self.max_points:
            y_new, ok, hard = self._correct(y, t, ds, scale)
            if not ok:
                ds /= 2
                if ds < self.ds_min:
                    lam = y[-1] * scale[-1]
                    self.reason = f"the corrector failed at {self.parameter} {lam:.5g} (step below ds_min)"
                    return branch, bifs
                continue
            step = (y, t, ds, scale)  # the arclength step just taken: where its bifurcations are located
            ds = ds if hard else min(1.5 * ds, self.ds_max)
            crawl = crawl + 1 if ds < 0.02 * self.ds_max else 0
            if crawl > 100:  # a hundred steps at a fiftieth of the largest: the corrector barely converges
                where = f"{self.parameter} {y[-1] * scale[-1]:.5g}"
                self.reason = f"the steps shrank below 1/50 of the largest for 100 orbits at {where}"
                return branch, bifs
            G, M, Gl, z = self._eval(y_new, scale, store=True)
            t = self._tangent(M, Gl, scale, t, direction)
            phys = y_new * scale
            point = sh.point(phys[:-1], *self._af(phys[-1]), M, t[-1], z)
            if point.halves():  # back through the doubling it was born at, onto the branch it came from
                self.reason = (f"the orbit became the period-{sh.period // 2} orbit (followed on its own branch) at "
                               f"{self.parameter} {phys[-1]:.5g}")  # fmt: skip
                break
            # only within the range asked for: the step that leaves it may cross a sign change beyond it
            found = self._detect(last, (phys, M), step)
            bifs += [b for b in found if self.lo <= b.value(self.parameter) <= self.hi]
            branch.points.append(point)
            last = (phys, M)
            # rescale the state to the orbit's size
            zs = max((point.max_z - point.min_z) / 2, z_floor)
            new = np.r_[sh.state_scale(zs, point.f_hz), scale[-1]]
            t = t * scale / new
            t /= np.linalg.norm(t)
            scale, y = new, phys / new
            if not (self.lo <= phys[-1] <= self.hi):
                self.reason = f"{self.parameter} left [{self.lo:g}, {self.hi:g}]"
                break
            if point.max_multiplier > MAX_MULTIPLIER:
                self.reason = (f"the orbit became too unstable to follow (|multiplier| {point.max_multiplier:.2g} > "
                               f"{MAX_MULTIPLIER:g}) at {self.parameter} {phys[-1]:.5g}")  # fmt: skip
                break
        return branch, bifs

    def _correct(self, y: np.ndarray, t: np.ndarray, ds: float, scale: np.ndarray, start: np.ndarray | None = None,
                 max_iter: int = 8):  # fmt: skip
        """Predictor along the tangent, Newton on G = 0 and the arclength condition (from ``start`` when
        given, else from the prediction). Returns (y, converged, hard: more than two iterations).
        """
        y_pred = y + ds * t
        y_new = (y_pred if start is None else start).copy()
        try:
            for it in range(max_iter):
                G, M, Gl = self._eval(y_new, scale)
                Gs = G / scale[:-1]
                J = np.vstack([self._jacobian(M, Gl, scale), t])
                step = np.linalg.solve(J, -np.concatenate([Gs, [t @ (y_new - y_pred)]]))
                y_new = y_new + step
                if np.max(np.abs(step)) < 1e-9 and np.max(np.abs(Gs)) < 1e-7:
                    # an orbit far off the predicted one is another branch's (Newton jumped): refused, the
                    # step halves (measured: an NSI model's period-4 branch jumped from 12 to 122 m/s^2)
                    if np.linalg.norm(y_new - y) > 3 * ds:
                        return y_new, False, True
                    return y_new, True, it > 2
        except (ContinuationError, np.linalg.LinAlgError):
            pass
        return y_new, False, True

    def _detect(self, prev, cur, step) -> list[Bifurcation]:
        """Bifurcations between the last accepted point ``prev`` and ``cur`` (each (physical (z, z', lambda),
        M)), reached by the arclength ``step`` (y, t, ds, scale: ``_correct``'s arguments).
        """
        out = []
        tp, tc = _tests(prev[1]), _tests(cur[1])
        for kind in ("fold", "period_doubling", "neimark_sacker"):
            a, b = tp[kind], tc[kind]
            if not (np.isfinite(a) and np.isfinite(b)) or a * b > 0:
                continue
            lam, M, x = self._locate(prev, cur, kind, step)
            mu = np.linalg.eigvals(M)
            target = {"fold": 1.0, "period_doubling": -1.0}.get(kind)
            m = mu[np.argmin(np.abs(mu - target))] if target is not None else mu[np.argmax(np.abs(mu))]
            a_, f_ = self._af(lam)
            out.append(Bifurcation(kind, float(a_), float(f_), self.well, complex(m), self.shooting.period,
                                   tuple(float(q) for q in x)))  # fmt: skip
        return out

    def _locate(self, prev, cur, kind: str, step, depth: int = 0) -> tuple[float, np.ndarray, np.ndarray]:
        """The zero of ``kind``'s test function on the branch between ``prev`` and ``cur``: regula falsi
        (Illinois) on the arclength s in [0, ds] of the step that reached ``cur``, each trial corrected onto
        the branch with the step's predictor and arclength condition (``_correct``). Along the branch, not at
        a fixed parameter: near a fold the parameter does not determine the orbit, and a fixed-parameter
        Newton converged onto other orbits (the previous code reported folds with a multiplier of 0.08 and
        doublings with multipliers near 0 instead of +1 and -1). Where the branch bends within the step so
        much that a hyperplane of the arclength condition meets it twice, the test function jumps instead of
        passing zero: then the step is retraced in ``RETRACE_STEPS`` small continuation steps and the zero located
        in the first that changes sign (twice at most). Returns (parameter, M, state).
        """
        y0, t0, ds, scale = step
        (p0, M0), (p1, M1) = prev, cur
        a, fa, ya = 0.0, _tests(M0)[kind], p0 / scale
        b, fb, yb = ds, _tests(M1)[kind], p1 / scale
        tol = 1e-7 * max(abs(fa), abs(fb))
        best = (abs(fb), p1[-1], M1, p1[:-1])
        for _ in range(30):
            if fb == fa or best[0] <= tol:
                break
            w = fb / (fb - fa)  # in (0, 1) while fa and fb differ in sign: the trial is inside [a, b]
            trial = b - w * (b - a)
            # Newton from the chord between the bracket's orbits (where the branch bends the tangent's
            # prediction led it onto another orbit), up to 20 iterations: next to a fold it converges
            # linearly (measured: 10 iterations to 1e-9)
            y_t, ok, _ = self._correct(y0, t0, trial, scale, start=yb - w * (yb - ya), max_iter=20)
            if not ok:
                break
            _, M_t, _ = self._eval(y_t, scale)
            f = _tests(M_t)[kind]
            best = min(best, (abs(f), y_t[-1] * scale[-1], M_t, y_t[:-1] * scale[:-1]), key=lambda r: r[0])
            if f * fb < 0:
                a, fa, ya = b, fb, yb
            else:
                fa /= 2  # Illinois: the endpoint kept twice counts half, so the bracket shrinks from both ends
            b, fb, yb = trial, f, y_t
            if abs(b - a) < 1e-10 * ds:
                break
        if best[0] <= tol or depth >= 2:
            return float(best[1]), best[2], best[3]
        # retrace the step in small continuation steps; locate in the first that changes sign
        y, t, M, f = y0, t0, M0, _tests(M0)[kind]
        for _ in range(RETRACE_STEPS):
            y_k, ok, _ = self._correct(y, t, ds / RETRACE_STEPS, scale, max_iter=20)
            if not ok:
                break
            _, M_k, Gl_k = self._eval(y_k, scale)
            f_k = _tests(M_k)[kind]
            if f_k * f <= 0:
                return self._locate(
                    (y * scale, M), (y_k * scale, M_k), kind, (y, t, ds / RETRACE_STEPS, scale), depth + 1
                )
            y, t, M, f = y_k, self._tangent(M_k, Gl_k, scale, t, 1.0), M_k, f_k
        return float(best[1]), best[2], best[3]


def settle(system, input_kind: str, z_start: float, amplitude: float, f_hz: float, periods: int = 200):
    """The state at phase 0 after ``periods`` forcing periods from rest at ``z_start`` (a start orbit)."""
    return Shooting(system, input_kind, period=periods).flow(_rest_state(system, z_start)[None, :], amplitude, f_hz)[0]


def _rest_state(system, z_start: float) -> np.ndarray:
    """Rest at ``z_start``: (z, 0) of a single DOF; of a structure, every DOF's static position with the element's
    relative displacement at ``z_start``, and no velocity.
    """
    if isinstance(system, Structure):
        return np.r_[system.static_positions(z_start), np.zeros(system.n_dof)]
    return np.array([z_start, 0.0])


def _span(value) -> tuple[float, float] | None:
    if isinstance(value, (tuple, list)):
        lo, hi = float(value[0]), float(value[1])
        if not hi > lo:
            raise ContinuationError(f"a continuation range needs its end above its start, got {lo:g}:{hi:g}")
        return lo, hi
    return None


FREQUENCY_LIMIT_HZ = 1e4
"""Forcing frequencies [Hz] a continuation may reach: a shaker table's band, far above any well's."""
AMPLITUDE_LIMITS = {"base_acc": 1e7, "force": 1e9}
"""Forcing amplitudes (m/s^2, N) beyond any shaker-table test (as a record's ``units.MAGNITUDE_LIMITS``)."""


def check_nfrc(system, *, freq, amplitude, well: str = "plus", input_kind: str = "base_acc", max_period: int = 4):
    """Everything ``nfrc`` refuses (``ContinuationError``, one line), before any work; returns the well's z."""
    try:
        a_span, f_span = _span(amplitude), _span(freq)
        f_lo, f_hi = f_span or (float(freq), float(freq))
        a_lo, a_hi = a_span or (float(amplitude), float(amplitude))
    except ContinuationError:
        raise
    except (TypeError, ValueError, IndexError):
        raise ContinuationError(
            f"freq and amplitude are numbers, or (start, stop) pairs; got {freq!r} and {amplitude!r}"
        ) from None
    if (a_span is None) == (f_span is None):
        raise ContinuationError("give a range for exactly one of the amplitude and the frequency (A1:A2 or F1:F2)")
    if input_kind not in AMPLITUDE_LIMITS:
        raise ContinuationError(f"the input is base_acc or force, got {input_kind!r}")
    unit = "m/s^2" if input_kind == "base_acc" else "N"
    if not (0 < f_lo <= f_hi <= FREQUENCY_LIMIT_HZ):
        raise ContinuationError(f"the forcing frequency must lie in (0, {FREQUENCY_LIMIT_HZ:g}] Hz, got {freq}")
    if not (0 <= a_lo <= a_hi <= AMPLITUDE_LIMITS[input_kind]):
        raise ContinuationError(
            f"the forcing amplitude must lie in [0, {AMPLITUDE_LIMITS[input_kind]:g}] {unit}, got {amplitude}"
        )
    if isinstance(max_period, bool) or not (isinstance(max_period, int) and 1 <= max_period <= 64):
        raise ContinuationError(f"max_period is an integer 1..64, got {max_period!r}")
    try:
        eq = system.element_equilibria() if isinstance(system, Structure) else system.equilibria()
        return eq.well(well)
    except ValueError as exc:  # no such well, or a restoring force without usable equilibria
        raise ContinuationError(f"--well {well}: {exc}") from None


def nfrc(system, *, freq, amplitude, well: str = "plus", input_kind: str = "base_acc", max_period: int = 4,
         ds: float = 0.01, ds_max: float = 0.05, max_points: int = 2000) -> dict[str, Any]:  # fmt: skip
    """Periodic responses of a model under harmonic excitation, continued, with their Floquet stability.

    Shooting with pseudo-arclength continuation (``docs/methods/continuation.md``), in amplitude
    (``amplitude=(A1, A2)`` at ``freq=f``) or in frequency (``freq=(f1, f2)`` at ``amplitude=A``),
    starting from the ``well`` at the range's start; period-doubled branches are followed up to
    ``max_period``.

    Parameters
    ----------
    system : Model or Device
        The model.
    freq : float or (float, float)
        Forcing frequency [Hz], or the range continued in.
    amplitude : float or (float, float)
        Forcing amplitude [m/s^2 for a base acceleration, N for a force], or the range continued in.
    well : {"plus", "minus"}, default "plus"
        The well the first branch starts from.
    input_kind : {"base_acc", "force"}, default "base_acc"
        What the forcing is.
    max_period : int, default 4
        Follow period-doubled branches up to this period.
    ds, ds_max : float
        Initial and largest arclength step (scaled units).
    max_points : int, default 2000
        Points per branch at most.

    Returns
    -------
    dict
        The result JSON's ``branches`` (each point's state, parameter, multipliers, stability),
        ``bifurcations`` (``type``: fold, period_doubling or neimark_sacker; ``amplitude``, ``f_hz``,
        ``multiplier``) and ``settings``.

    Examples
    --------
    >>> from negstiff import nfrc
    >>> from negstiff.models import SEED_LIKE_CUBIC
    >>> curve = nfrc(SEED_LIKE_CUBIC, freq=9.0, amplitude=(4.0, 16.0), well="plus", max_period=2)
    >>> first = next(b for b in curve["bifurcations"] if b["type"] == "period_doubling")
    >>> 12.0 < first["amplitude"] < 15.0
    True
    """
    z_well = check_nfrc(system, freq=freq, amplitude=amplitude, well=well, input_kind=input_kind,
                        max_period=max_period)  # fmt: skip
    a_span, f_span = _span(amplitude), _span(freq)
    parameter = "amplitude" if a_span else "f_hz"
    span = a_span or f_span
    if span is None:
        raise ContinuationError("give a range in amplitude (A1:A2) or in frequency (F1:F2)")
    lo, hi = span
    fixed = float(freq) if a_span else float(amplitude)
    a0, f0 = (lo, fixed) if a_span else (fixed, lo)
    x = settle(system, input_kind, z_well, a0, f0)
    sh = Shooting(system, input_kind, 1)
    _, z = sh.flow(x[None, :], a0, f0, store=True)
    z_scale = max(float(np.ptp(z)) / 2, 1e-3 * abs(z_well), 1e-7)
    scale = np.r_[sh.state_scale(z_scale, f0), hi - lo]
    branches: list[Any] = []
    bifurcations: list[Any] = []
    notes: list[str] = []
    todo = [(sh, x, lo)]
    while todo:
        shooting, x_start, lam_start = todo.pop(0)
        cont = Continuation(shooting, parameter, fixed, well, (lo, hi), ds, 1e-4 * ds, ds_max, max_points)
        try:
            branch, bifs = cont.run(x_start, lam_start, +1.0, scale)
            notes.append(f"period-{shooting.period} branch: {cont.reason or 'point limit'}")
        except ContinuationError as exc:
            notes.append(f"period-{shooting.period} branch from {parameter} {lam_start:g}: {exc}")
            continue
        branches.append(branch)
        # a branch that folds back passes a point twice: one entry per (type, period, parameter)
        for b in bifs:
            same = (o for o in bifurcations if o.type == b.type and o.period == b.period)
            if not any(abs(o.value(parameter) - b.value(parameter)) < 1e-4 * (hi - lo) for o in same):
                bifurcations.append(b)
        for b in [b for b in bifurcations if b in bifs]:
            if b.type == "period_doubling" and 2 * shooting.period <= max_period:
                start = _double(shooting, b, parameter, fixed, (lo, hi), scale)
                if start is None:
                    notes.append(f"no period-{2 * shooting.period} orbit found beyond the doubling at {b.amplitude:g}")
                else:
                    todo.append(start)
    return {
        "branches": [b.to_json() for b in branches],
        "bifurcations": [b.to_json() for b in bifurcations],
        "settings": {
            "parameter": parameter, "range": [lo, hi], "fixed": fixed, "well": well, "input": input_kind,
            "forcing": "b'' = A sin(2 pi f t)" if input_kind == "base_acc" else "f = A sin(2 pi f t)",
            "method": f"shooting on the RK4 kernel ({STEPS_PER_PERIOD} steps a period), pseudo-arclength, "
            "Floquet multipliers of the monodromy matrix (central differences)",
            "notes": notes,
        },
    }  # fmt: skip


def _double(shooting: Shooting, b: Bifurcation, parameter: str, fixed: float, span, scale):
    """The period-2p orbit a little beyond a doubling: simulated from the bifurcating orbit, nudged (where
    the period-p orbit is unstable the response settles onto the doubled one), then corrected.
    """
    lam_pd = b.value(parameter)
    system, kind = shooting.system, shooting.input_kind
    base = Continuation(shooting, parameter, fixed, b.well, span)
    doubled = Shooting(system, kind, 2 * shooting.period, shooting.z_limit)
    cont = Continuation(doubled, parameter, fixed, b.well, span)
    for frac in (0.002, 0.01, 0.03):
        lam = lam_pd + frac * (span[1] - span[0])
        if lam > span[1]:
            break
        a, f = (lam, fixed) if parameter == "amplitude" else (fixed, lam)
        try:
            x_p, _ = base.correct_fixed(np.array(b.x0), lam, scale)
            nudged = (x_p + np.r_[1e-3 * scale[0], np.zeros(x_p.size - 1)])[None, :]
            x = Shooting(system, kind, 400, shooting.z_limit).flow(nudged, a, f)[0]
            x2, _ = cont.correct_fixed(x, lam, scale)
        except ContinuationError:
            continue
        if np.linalg.norm((shooting.flow(x2[None, :], a, f)[0] - x2) / scale[:-1]) > 1e-4:
            return doubled, x2, lam
    return None
