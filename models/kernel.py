"""The compiled force law and Runge-Kutta loop of the simulator (numba), shared by the batched
simulator (``simulator``), the variational equations (``reference``) and the hybrid model's free runs
(``inference.hybrid``).

A member's parameters are one column of the kernel parameter vector (``effects.layout``): rows 0-16
are fixed (mass; the restoring force's rows 1-6, k0..k3 for a polynomial or the device's geometry;
damping; the effects with a fixed row), rows from 17 on hold the registry's other monomials, whose
powers ``mono`` gives (one row per monomial: row, z_power, z_odd, v_power, v_odd).
"""

from __future__ import annotations

import math
from typing import Any

import numba
import numpy as np

from .effects import COULOMB_VELOCITY_SCALE, ROWS

KIND_POLYNOMIAL, KIND_DEVICE = 0, 1
KINDS = {"polynomial": KIND_POLYNOMIAL, "device": KIND_DEVICE}
STATUS_OK, STATUS_DIVERGED, STATUS_GEOMETRY = 0, 1, 2
P_M, P_C, P_CNL, P_SIGN, P_V3 = ROWS["m"], ROWS["c"], ROWS["c_nl"], ROWS["sign"], ROWS["v^3"]
P_Z2, P_Z3, P_Z4, P_Z5 = ROWS["z^2"], ROWS["z^3"], ROWS["z^4"], ROWS["z^5"]
P_STOP_K, P_STOP_Z = ROWS["stop_k"], ROWS["stop_z"]

JIT: dict[str, Any] = {"cache": True, "nogil": True, "error_model": "numpy"}  # numpy error model: no zero-division
# branches in the loop, which is what lets LLVM vectorise over the batch (4x measured here).


@numba.njit(inline="always", **JIT)
def force(kind, coulomb, z, v, q):
    """Total non-inertial force D + K + extra [N] for one member's parameter tuple ``q``.

    polynomial: q[1..4] = k0, k1, k2, k3; device: q[1] = k_f, q[2] = L cos(alpha), q[3] = sin(alpha),
    q[4] = D0, q[5] = g (exact rod-frame geometry; NaN where the rods cannot reach z). ``kind`` and
    ``coulomb`` are compile-time constants in each specialised kernel, so their branches vanish.
    """
    if kind == KIND_POLYNOMIAL:
        k = ((q[4] * z + q[3]) * z - q[2]) * z + q[1]
    else:
        bb = q[2] - z * q[3]
        r2 = bb * bb - z * z
        r = math.sqrt(r2) if (r2 > 0.0 and bb > 0.0) else math.nan
        k = 2.0 * q[1] * (r - bb + q[4]) * (q[3] - (bb * q[3] + z) / r) + q[P_M] * q[5]
    k += z * z * (q[P_Z2] + z * (q[P_Z3] + z * (q[P_Z4] + z * q[P_Z5])))
    # one-sided stop (branch-free): k_s max(z - z_s, 0) for z_s > 0, k_s min(z - z_s, 0) for z_s < 0
    dz = z - q[P_STOP_Z]
    k += 0.5 * q[P_STOP_K] * (dz + math.copysign(1.0, q[P_STOP_Z]) * abs(dz))
    d = v * (q[P_C] + q[P_CNL] * abs(v) + q[P_V3] * v * v)
    if coulomb:
        d += q[P_SIGN] * math.tanh(v / COULOMB_VELOCITY_SCALE)
    return k + d


@numba.njit(inline="always", **JIT)
def monomials(z, v, p, b, mono):
    """The registry's monomials without a fixed row: sum of p[row, b] |z|^zp sgn(z)^zo |v|^vp sgn(v)^vo."""
    f = 0.0
    az = abs(z)
    av = abs(v)
    for j in range(mono.shape[0]):
        t = p[mono[j, 0], b]
        for _ in range(mono[j, 1]):
            t *= az
        if mono[j, 2] and z < 0.0:
            t = -t
        for _ in range(mono[j, 3]):
            t *= av
        if mono[j, 4] and v < 0.0:
            t = -t
        f += t
    return f


@numba.njit(inline="always", **JIT)
def total_force(kind, coulomb, generic, z, v, q, p, b, mono):
    """``force`` plus, in the kernels compiled with ``generic``, the extra monomial rows."""
    if generic:
        return force(kind, coulomb, z, v, q) + monomials(z, v, p, b, mono)
    return force(kind, coulomb, z, v, q)


@numba.njit(inline="always", **JIT)
def extra_term(z, v, u, w, a, zc, vc, uc, iz, iv, iu, bz, bv):
    """The extra force hook: g(z, z', u), a weighted sum of tensor-product Gaussian bumps over (z, z') and of
    bumps over u (the hybrid model's non-parametric term, ``inference.hybrid``; bz, bv: scratch).
    """
    for i in range(zc.size):
        d = (z - zc[i]) * iz
        bz[i] = math.exp(-0.5 * d * d)
    for j in range(vc.size):
        d = (v - vc[j]) * iv
        bv[j] = math.exp(-0.5 * d * d)
    g = 0.0
    for i in range(zc.size):
        s = 0.0
        for j in range(vc.size):
            s += w[i, j] * bv[j]
        g += s * bz[i]
    for k in range(uc.size):
        d = (u - uc[k]) * iu
        g += a[k] * math.exp(-0.5 * d * d)
    return g


@numba.njit(inline="always", **JIT)
def member(p, b, kind):
    """Parameter tuple of member b, with the device's angle rows turned into L cos(a), sin(a)."""
    q = (
        p[0, b],
        p[1, b],
        p[2, b],
        p[3, b],
        p[4, b],
        p[5, b],
        p[6, b],
        p[7, b],
        p[8, b],
        p[9, b],
        p[10, b],
        p[11, b],
        p[12, b],
        p[13, b],
        p[14, b],
        p[15, b],
        p[16, b],
    )
    if kind == KIND_DEVICE:
        q = (q[0], q[1], q[2] * math.cos(q[3]), math.sin(q[3])) + q[4:]
    return q


@numba.njit(inline="always", **JIT)
def _integrate(
    kind,
    coulomb,
    generic,
    extra,
    p,
    mono,
    gain,
    u,
    uidx,
    dt,
    nsub,
    z0,
    v0,
    z_limit,
    v_limit,
    out_z,
    out_v,
    store_v,
    status,
    fail_step,
    hw,
    ha,
    hzc,
    hvc,
    huc,
    hiz,
    hiv,
    hiu,
):
    """RK4 over the N sample intervals of each member's input row ``u[uidx[b]]``; outputs time-major. The
    package's one Runge-Kutta stage loop: every simulation of negstiff runs here.

    ``out_z.shape[0]`` is N + 1 output samples. The input row holds either the N + 1 samples (linearly
    interpolated inside each interval) or, when it has 2 ``nsub`` N + 1 columns, the input at every
    Runge-Kutta stage time (``stage_input``), read as it is. ``extra`` (a staged input) adds the hook
    ``extra_term`` with its weights and bumps (``hw`` ... ``hiu``) to every member's force.
    """
    nb = p.shape[1]
    n = out_z.shape[0]
    staged = u.shape[1] != n
    h = dt / nsub
    z = z0.copy()
    v = v0.copy()
    ua = np.empty(nb)
    ub = np.empty(nb)
    wa = np.empty(nb)
    wm = np.empty(nb)
    wb = np.empty(nb)
    ra = np.empty(nb)
    rm = np.empty(nb)
    rb = np.empty(nb)
    bz = np.empty(hzc.size)
    bv = np.empty(hvc.size)
    alive = np.ones(nb, dtype=np.bool_)
    for b in range(nb):
        out_z[0, b] = z[b]
        if store_v:
            out_v[0, b] = v[b]
    for k in range(n - 1):
        if not staged:
            for b in range(nb):  # gather the input once per sample, outside the vectorised loop
                ua[b] = gain[b] * u[uidx[b], k]
                ub[b] = gain[b] * u[uidx[b], k + 1]
        for j in range(nsub):
            if staged:  # the input at the step's start, midpoint and end
                c = 2 * (k * nsub + j)
                for b in range(nb):
                    ra[b] = u[uidx[b], c]
                    rm[b] = u[uidx[b], c + 1]
                    rb[b] = u[uidx[b], c + 2]
                    wa[b] = gain[b] * ra[b]
                    wm[b] = gain[b] * rm[b]
                    wb[b] = gain[b] * rb[b]
            else:
                fa = j / nsub
                fm = (j + 0.5) / nsub
                fb = (j + 1.0) / nsub
                for b in range(nb):
                    du = ub[b] - ua[b]
                    wa[b] = ua[b] + fa * du
                    wm[b] = ua[b] + fm * du
                    wb[b] = ua[b] + fb * du
            for b in range(nb):
                q = member(p, b, kind)
                im = 1.0 / q[P_M]
                zb = z[b]
                vb = v[b]
                f1 = total_force(kind, coulomb, generic, zb, vb, q, p, b, mono)
                if extra:
                    f1 += extra_term(zb, vb, ra[b], hw, ha, hzc, hvc, huc, hiz, hiv, hiu, bz, bv)
                a1 = wa[b] - f1 * im
                z2 = zb + 0.5 * h * vb
                v2 = vb + 0.5 * h * a1
                f2 = total_force(kind, coulomb, generic, z2, v2, q, p, b, mono)
                if extra:
                    f2 += extra_term(z2, v2, rm[b], hw, ha, hzc, hvc, huc, hiz, hiv, hiu, bz, bv)
                a2 = wm[b] - f2 * im
                z3 = zb + 0.5 * h * v2
                v3 = vb + 0.5 * h * a2
                f3 = total_force(kind, coulomb, generic, z3, v3, q, p, b, mono)
                if extra:
                    f3 += extra_term(z3, v3, rm[b], hw, ha, hzc, hvc, huc, hiz, hiv, hiu, bz, bv)
                a3 = wm[b] - f3 * im
                z4 = zb + h * v3
                v4 = vb + h * a3
                f4 = total_force(kind, coulomb, generic, z4, v4, q, p, b, mono)
                if extra:
                    f4 += extra_term(z4, v4, rb[b], hw, ha, hzc, hvc, huc, hiz, hiv, hiu, bz, bv)
                a4 = wb[b] - f4 * im
                z[b] = zb + h / 6.0 * (vb + 2.0 * v2 + 2.0 * v3 + v4)
                v[b] = vb + h / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4)
        for b in range(nb):
            if alive[b] and not (abs(z[b]) < z_limit and abs(v[b]) < v_limit):
                alive[b] = False
                fail_step[b] = k + 1
                status[b] = STATUS_GEOMETRY if (kind == KIND_DEVICE and not math.isfinite(z[b])) else STATUS_DIVERGED
            if not alive[b]:
                z[b] = math.nan
                v[b] = math.nan
            out_z[k + 1, b] = z[b]
            if store_v:
                out_v[k + 1, b] = v[b]
    return 0


_NO_W = np.zeros((0, 0))
_NO_V = np.zeros(0)
"""The extra force hook's arguments in the kernels without it: empty, never read (``extra`` is False)."""

# One compiled kernel per (restoring-force kind, smoothed sign present, extra monomials present): the
# flags are constants inside each, so the batch loop has no data-dependent branches. (A factory of
# closures would repeat less, but numba's on-disk cache cannot tell such closures apart.)
# fmt: off
@numba.njit(**JIT)
def _kernel_poly(p, mono, gain, u, uidx, dt, nsub, z0, v0, zl, vl, oz, ov, sv, st, fs):
    return _integrate(KIND_POLYNOMIAL, False, False, False, p, mono, gain, u, uidx, dt, nsub,
                      z0, v0, zl, vl, oz, ov, sv, st, fs, _NO_W, _NO_V, _NO_V, _NO_V, _NO_V, 1.0, 1.0, 1.0)


@numba.njit(**JIT)
def _kernel_poly_sign(p, mono, gain, u, uidx, dt, nsub, z0, v0, zl, vl, oz, ov, sv, st, fs):
    return _integrate(KIND_POLYNOMIAL, True, False, False, p, mono, gain, u, uidx, dt, nsub,
                      z0, v0, zl, vl, oz, ov, sv, st, fs, _NO_W, _NO_V, _NO_V, _NO_V, _NO_V, 1.0, 1.0, 1.0)


@numba.njit(**JIT)
def _kernel_device(p, mono, gain, u, uidx, dt, nsub, z0, v0, zl, vl, oz, ov, sv, st, fs):
    return _integrate(KIND_DEVICE, False, False, False, p, mono, gain, u, uidx, dt, nsub,
                      z0, v0, zl, vl, oz, ov, sv, st, fs, _NO_W, _NO_V, _NO_V, _NO_V, _NO_V, 1.0, 1.0, 1.0)


@numba.njit(**JIT)
def _kernel_device_sign(p, mono, gain, u, uidx, dt, nsub, z0, v0, zl, vl, oz, ov, sv, st, fs):
    return _integrate(KIND_DEVICE, True, False, False, p, mono, gain, u, uidx, dt, nsub,
                      z0, v0, zl, vl, oz, ov, sv, st, fs, _NO_W, _NO_V, _NO_V, _NO_V, _NO_V, 1.0, 1.0, 1.0)


@numba.njit(**JIT)
def _kernel_poly_generic(p, mono, gain, u, uidx, dt, nsub, z0, v0, zl, vl, oz, ov, sv, st, fs):
    return _integrate(KIND_POLYNOMIAL, True, True, False, p, mono, gain, u, uidx, dt, nsub,
                      z0, v0, zl, vl, oz, ov, sv, st, fs, _NO_W, _NO_V, _NO_V, _NO_V, _NO_V, 1.0, 1.0, 1.0)


@numba.njit(**JIT)
def _kernel_device_generic(p, mono, gain, u, uidx, dt, nsub, z0, v0, zl, vl, oz, ov, sv, st, fs):
    return _integrate(KIND_DEVICE, True, True, False, p, mono, gain, u, uidx, dt, nsub,
                      z0, v0, zl, vl, oz, ov, sv, st, fs, _NO_W, _NO_V, _NO_V, _NO_V, _NO_V, 1.0, 1.0, 1.0)


@numba.njit(**JIT)
def _kernel_poly_extra(p, mono, gain, u, uidx, dt, nsub, z0, v0, zl, vl, oz, ov, sv, st, fs, hw, ha, hzc, hvc, huc,
                       hiz, hiv, hiu):
    return _integrate(KIND_POLYNOMIAL, True, True, True, p, mono, gain, u, uidx, dt, nsub,
                      z0, v0, zl, vl, oz, ov, sv, st, fs, hw, ha, hzc, hvc, huc, hiz, hiv, hiu)


@numba.njit(**JIT)
def _kernel_device_extra(p, mono, gain, u, uidx, dt, nsub, z0, v0, zl, vl, oz, ov, sv, st, fs, hw, ha, hzc, hvc,
                         huc, hiz, hiv, hiu):
    return _integrate(KIND_DEVICE, True, True, True, p, mono, gain, u, uidx, dt, nsub,
                      z0, v0, zl, vl, oz, ov, sv, st, fs, hw, ha, hzc, hvc, huc, hiz, hiv, hiu)
# fmt: on


def kernel_with_term(kind: int):
    """The compiled kernel with the extra force hook (``extra_term``), for a restoring-force kind."""
    return _kernel_poly_extra if kind == KIND_POLYNOMIAL else _kernel_device_extra


def kernel(kind: int, p: np.ndarray, mono: np.ndarray):
    """The compiled kernel for a batch: its restoring-force kind, whether any member has a smoothed
    sign, whether the registry has extra monomial rows (then one general kernel, sign included).
    """
    if mono.shape[0]:
        return _kernel_poly_generic if kind == KIND_POLYNOMIAL else _kernel_device_generic
    sign = bool(np.any(p[P_SIGN] != 0.0))
    return {
        (KIND_POLYNOMIAL, False): _kernel_poly,
        (KIND_POLYNOMIAL, True): _kernel_poly_sign,
        (KIND_DEVICE, False): _kernel_device,
        (KIND_DEVICE, True): _kernel_device_sign,
    }[(kind, sign)]


# --- structures of N degrees of freedom ----------------------------------------------------------------
@numba.njit(inline="always", **JIT)
def _structure_acc(kind, p, b, mono, q, nd, ei, ej, minv, lk, lc, zs, vs, w, acc):
    """Accelerations of every DOF of member b at one Runge-Kutta stage: the element's force law (``force`` of
    the same member tuple ``q``) on the relative motion of DOFs ``ej`` and ``ei`` (``ei`` -1: the base),
    acting on ``ej`` and, with the opposite sign, on ``ei``; plus the linear structure ``lk``, ``lc``.
    """
    if ei >= 0:
        r = zs[ej] - zs[ei]
        rv = vs[ej] - vs[ei]
    else:
        r = zs[ej]
        rv = vs[ej]
    f = total_force(kind, True, True, r, rv, q, p, b, mono)
    for d in range(nd):
        lin = 0.0
        for e in range(nd):
            lin += lk[d, e, b] * zs[e] + lc[d, e, b] * vs[e]
        if d == ej:
            lin += f
        elif d == ei:
            lin -= f
        acc[d] = w[d] - lin * minv[d, b]


@numba.njit(**JIT)
def _integrate_structure(kind, p, mono, ei, ej, minv, lk, lc, gain, u, uidx, dt, nsub, z0, v0, z_limit, v_limit,
                         out_z, out_v, store_v, status, fail_step):  # fmt: skip
    """RK4 of B structures of N degrees of freedom (state z, z' of each DOF, relative to the base).

        M z'' + C z' + K z + l F(z_J - z_I, z_J' - z_I') = gain u,   l = e_J - e_I,

    F the element's force law of member b's column of ``p`` (the single-DOF kernel's ``force``, with every
    registry term), ``minv`` (N, B) the inverse masses, ``lk``/``lc`` (N, N, B) the linear structure,
    ``gain`` (N, B) the input's gain per DOF. Inputs as ``_integrate`` (sample rows linearly interpolated, or
    staged). Outputs (T, N, B). For N = 1 with no linear structure every operation is the single-DOF
    kernel's, in its order: the same numbers to the last bit (tested).
    """
    nb = p.shape[1]
    nd = minv.shape[0]
    n = out_z.shape[0]
    staged = u.shape[1] != n
    h = dt / nsub
    z = z0.copy()
    v = v0.copy()
    zb = np.empty(nd)
    vb = np.empty(nd)
    zt = np.empty(nd)
    vt = np.empty(nd)
    a1 = np.empty(nd)
    a2 = np.empty(nd)
    a3 = np.empty(nd)
    a4 = np.empty(nd)
    v2 = np.empty(nd)
    v3 = np.empty(nd)
    wa = np.empty(nd)
    wm = np.empty(nd)
    wb = np.empty(nd)
    alive = np.ones(nb, dtype=np.bool_)
    for b in range(nb):
        for d in range(nd):
            out_z[0, d, b] = z[d, b]
            if store_v:
                out_v[0, d, b] = v[d, b]
    for k in range(n - 1):
        for j in range(nsub):
            for b in range(nb):
                if staged:
                    c = 2 * (k * nsub + j)
                    for d in range(nd):
                        wa[d] = gain[d, b] * u[uidx[b], c]
                        wm[d] = gain[d, b] * u[uidx[b], c + 1]
                        wb[d] = gain[d, b] * u[uidx[b], c + 2]
                else:
                    fa = j / nsub
                    fm = (j + 0.5) / nsub
                    fb = (j + 1.0) / nsub
                    for d in range(nd):
                        ua = gain[d, b] * u[uidx[b], k]
                        du = gain[d, b] * u[uidx[b], k + 1] - ua
                        wa[d] = ua + fa * du
                        wm[d] = ua + fm * du
                        wb[d] = ua + fb * du
                q = member(p, b, kind)
                for d in range(nd):
                    zb[d] = z[d, b]
                    vb[d] = v[d, b]
                _structure_acc(kind, p, b, mono, q, nd, ei, ej, minv, lk, lc, zb, vb, wa, a1)
                for d in range(nd):
                    zt[d] = zb[d] + 0.5 * h * vb[d]
                    v2[d] = vb[d] + 0.5 * h * a1[d]
                _structure_acc(kind, p, b, mono, q, nd, ei, ej, minv, lk, lc, zt, v2, wm, a2)
                for d in range(nd):
                    zt[d] = zb[d] + 0.5 * h * v2[d]
                    v3[d] = vb[d] + 0.5 * h * a2[d]
                _structure_acc(kind, p, b, mono, q, nd, ei, ej, minv, lk, lc, zt, v3, wm, a3)
                for d in range(nd):
                    zt[d] = zb[d] + h * v3[d]
                    vt[d] = vb[d] + h * a3[d]
                _structure_acc(kind, p, b, mono, q, nd, ei, ej, minv, lk, lc, zt, vt, wb, a4)
                for d in range(nd):
                    z[d, b] = zb[d] + h / 6.0 * (vb[d] + 2.0 * v2[d] + 2.0 * v3[d] + vt[d])
                    v[d, b] = vb[d] + h / 6.0 * (a1[d] + 2.0 * a2[d] + 2.0 * a3[d] + a4[d])
        for b in range(nb):
            ok = True
            for d in range(nd):
                if not (abs(z[d, b]) < z_limit and abs(v[d, b]) < v_limit):
                    ok = False
            if alive[b] and not ok:
                alive[b] = False
                fail_step[b] = k + 1
                nonfinite = False
                for d in range(nd):
                    if not math.isfinite(z[d, b]):
                        nonfinite = True
                status[b] = STATUS_GEOMETRY if (kind == KIND_DEVICE and nonfinite) else STATUS_DIVERGED
            for d in range(nd):
                if not alive[b]:
                    z[d, b] = math.nan
                    v[d, b] = math.nan
                out_z[k + 1, d, b] = z[d, b]
                if store_v:
                    out_v[k + 1, d, b] = v[d, b]
    return 0


# fmt: off
@numba.njit(**JIT)
def _kernel_structure_poly(p, mono, ei, ej, minv, lk, lc, gain, u, uidx, dt, nsub, z0, v0, zl, vl, oz, ov, sv, st,
                           fs):
    return _integrate_structure(KIND_POLYNOMIAL, p, mono, ei, ej, minv, lk, lc, gain, u, uidx, dt, nsub, z0, v0, zl,
                                vl, oz, ov, sv, st, fs)


@numba.njit(**JIT)
def _kernel_structure_device(p, mono, ei, ej, minv, lk, lc, gain, u, uidx, dt, nsub, z0, v0, zl, vl, oz, ov, sv, st,
                             fs):
    return _integrate_structure(KIND_DEVICE, p, mono, ei, ej, minv, lk, lc, gain, u, uidx, dt, nsub, z0, v0, zl, vl,
                                oz, ov, sv, st, fs)
# fmt: on


def structure_kernel(kind: int):
    """The compiled N-DOF kernel for a restoring-force kind (every registry term compiled in)."""
    return _kernel_structure_poly if kind == KIND_POLYNOMIAL else _kernel_structure_device
