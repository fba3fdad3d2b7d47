"""Independent references for the simulator: an adaptive DOP853 solution of the same equation
(``reference_solution``, what the fixed-step kernel is checked against) and the variational equations
of the largest Lyapunov exponent (``lyapunov_benettin``, Benettin et al. 1980: the exponent's ground
truth for a model).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from . import effects
from .effects import COULOMB_VELOCITY_SCALE
from .kernel import (
    KINDS,
    P_C,
    P_CNL,
    P_M,
    P_SIGN,
    P_STOP_K,
    P_STOP_Z,
    P_V3,
    P_Z2,
    P_Z3,
    P_Z4,
    P_Z5,
    _column,
    converted,
    device_flag,
    member_tables,
    total_force,
)


def reference_solution(
    system, u: np.ndarray, dt: float, z0: float, v0: float = 0.0, rtol: float = 1e-10, input_kind: str = "base_acc"
) -> np.ndarray:
    """Z at the samples by scipy's adaptive DOP853 (``rtol``), with the same linearly
    interpolated input: the independent reference the simulator is checked against.

    The input has a kink at every sample, which an adaptive integrator at tight tolerance crawls
    through; so each sample interval, where the input is smooth, is integrated on its own
    (scipy's DOP853 stepper restarted from the previous end state) with a scalar right-hand side.
    """
    p = system.kernel_params()
    m = p[P_M]
    gain = -1.0 if input_kind == "base_acc" else 1.0 / m
    u = np.asarray(u, float)
    n = u.size
    slope = np.diff(u, append=u[-1])
    ul, sl = u.tolist(), slope.tolist()
    ca, sa = math.cos(p[3]), math.sin(p[3])
    q = p.tolist()
    mono = effects.layout().monomials.tolist()
    shaped = effects.shaped_parts(getattr(system, "extra", {}))  # their own formulas, not the simulator's table

    def force(z: float, v: float) -> float:
        if system.kind == "polynomial":
            k = ((q[4] * z + q[3]) * z - q[2]) * z + q[1]
        else:
            bb = q[2] * ca - z * sa
            r = math.sqrt(bb * bb - z * z)
            k = 2.0 * q[1] * (r - bb + q[4]) * (sa - (bb * sa + z) / r) + m * q[5]
        k += z * z * (q[P_Z2] + z * (q[P_Z3] + z * (q[P_Z4] + z * q[P_Z5])))
        dz = z - q[P_STOP_Z]
        k += 0.5 * q[P_STOP_K] * (dz + math.copysign(1.0, q[P_STOP_Z]) * abs(dz))
        for law, value in shaped:
            k += float(law.force(value, z))
        d = v * (q[P_C] + q[P_CNL] * abs(v) + q[P_V3] * v * v)
        for row, zp, zo, vp, vo in mono:  # the registry's monomials without a fixed row
            k += (
                q[row] * abs(z) ** zp * (-1.0 if zo and z < 0 else 1.0) * abs(v) ** vp * (-1.0 if vo and v < 0 else 1.0)
            )
        return k + d + q[P_SIGN] * math.tanh(v / COULOMB_VELOCITY_SCALE)

    from scipy.integrate import DOP853

    out = np.empty(n)
    out[0] = z0
    state = [z0, v0]
    for k in range(n - 1):
        uk, sk = ul[k], sl[k]

        def rhs(t: float, x, uk=uk, sk=sk):
            return np.array((x[1], gain * (uk + sk * t / dt) - force(x[0], x[1]) / m))

        solver = DOP853(rhs, 0.0, state, dt, rtol=rtol, atol=1e-13)
        while solver.status == "running":
            solver.step()
        state = solver.y
        out[k + 1] = state[0]
    return out


@numba.njit(cache=True, error_model="numpy")
def _benettin(device, p, mono, ts, gain, u, dt, nsub, z0, v0, renorm):
    """RK4 of the state and one tangent vector; the tangent is renormalised every ``renorm`` samples
    and its log growth accumulated (Benettin et al. 1980). Jacobian of the force by central
    differences of the same force law the simulator integrates.
    """
    q = _column(converted(p, device), 0)
    tab = member_tables(p, ts)
    im = 1.0 / q[P_M]
    h = dt / nsub
    z, v, dz, dv = z0, v0, 1.0, 0.0
    n = u.shape[0]
    logs = np.zeros((n - 1) // renorm)
    acc = 0.0
    k_out = 0
    for k in range(n - 1):
        u0 = gain * u[k]
        du = gain * u[k + 1] - u0
        for j in range(nsub):
            st = np.empty((4, 4))
            zz, vv, ddz, ddv = z, v, dz, dv
            for s in range(4):
                c = 0.0 if s == 0 else (0.5 if s < 3 else 1.0)
                if s > 0:
                    zz = z + c * h * st[s - 1, 0]
                    vv = v + c * h * st[s - 1, 1]
                    ddz = dz + c * h * st[s - 1, 2]
                    ddv = dv + c * h * st[s - 1, 3]
                frac = (j + c) / nsub
                w = u0 + frac * du
                f = total_force(device, None, 1, 1, zz, vv, q, p, 0, mono, ts, tab) + q[P_SIGN] * math.tanh(
                    vv / COULOMB_VELOCITY_SCALE
                )
                ez = 1e-7 * max(1e-3, abs(zz))
                ev = 1e-6 * max(1e-2, abs(vv))
                fz = (
                    total_force(device, None, 1, 1, zz + ez, vv, q, p, 0, mono, ts, tab)
                    - total_force(device, None, 1, 1, zz - ez, vv, q, p, 0, mono, ts, tab)
                ) / (2 * ez)
                fv = (
                    total_force(device, None, 1, 1, zz, vv + ev, q, p, 0, mono, ts, tab)
                    - total_force(device, None, 1, 1, zz, vv - ev, q, p, 0, mono, ts, tab)
                ) / (2 * ev)
                fv += q[P_SIGN] / COULOMB_VELOCITY_SCALE / math.cosh(vv / COULOMB_VELOCITY_SCALE) ** 2
                st[s, 0] = vv
                st[s, 1] = w - f * im
                st[s, 2] = ddv
                st[s, 3] = -(fz * ddz + fv * ddv) * im
            z += h / 6.0 * (st[0, 0] + 2 * st[1, 0] + 2 * st[2, 0] + st[3, 0])
            v += h / 6.0 * (st[0, 1] + 2 * st[1, 1] + 2 * st[2, 1] + st[3, 1])
            dz += h / 6.0 * (st[0, 2] + 2 * st[1, 2] + 2 * st[2, 2] + st[3, 2])
            dv += h / 6.0 * (st[0, 3] + 2 * st[1, 3] + 2 * st[2, 3] + st[3, 3])
        if (k + 1) % renorm == 0:
            norm = math.sqrt(dz * dz + dv * dv)
            acc += math.log(norm)
            dz /= norm
            dv /= norm
            logs[k_out] = acc
            k_out += 1
    return logs


def lyapunov_benettin(
    system,
    u: np.ndarray,
    dt: float,
    z0: float,
    v0: float = 0.0,
    *,
    input_kind: str = "base_acc",
    substeps: int = 4,
    renorm_every: int = 16,
    transient_s: float = 10.0,
) -> dict:
    """Largest Lyapunov exponent [1/s] of ``system`` driven by ``u`` from the variational equations
    (ground truth for the model). The tangent norm is measured in (z [m], z' [m/s]); the exponent does
    not depend on that choice. The first ``transient_s`` seconds are discarded.

    Returns ``{"value", "running"(t, estimate)}``.
    """
    p = system.kernel_params()
    gain = -1.0 if input_kind == "base_acc" else 1.0 / p[P_M]
    lay = effects.layout()
    logs = _benettin(
        device_flag(KINDS[system.kind]),
        np.ascontiguousarray(p[:, None]),
        lay.monomials,
        lay.size if p.size > lay.size else -1,
        gain,
        np.asarray(u, float),
        float(dt),
        int(substeps),
        float(z0),
        float(v0),
        int(renorm_every),
    )
    t = (np.arange(logs.size) + 1) * renorm_every * dt
    k0 = int(np.searchsorted(t, transient_s))
    if logs.size - k0 < 2:
        raise ValueError("record too short for a Lyapunov exponent after the transient")
    lam = (logs[-1] - logs[k0]) / (t[-1] - t[k0])
    running = (logs[k0:] - logs[k0]) / np.maximum(t[k0:] - t[k0], 1e-12)
    return {"value": float(lam), "t": t[k0:], "running": running}
