"""The compiled force law and the one Runge-Kutta loop of negstiff (numba): every simulation, of the single-DOF
model (N = 1), of a structure of N DOFs (``structure``), of the hybrid model (``inference.hybrid``, through the
extra force hook), runs in ``_integrate``, called by ``simulator.integrate``. The force law is shared with the
variational equations (``reference``).

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
def force(device, coulomb, z, v, q):
    """Total non-inertial force D + K + extra [N] for one member's parameter tuple ``q``.

    polynomial: q[1..4] = k0, k1, k2, k3; device: q[1] = k_f, q[2] = L cos(alpha), q[3] = sin(alpha),
    q[4] = D0, q[5] = g (exact rod-frame geometry; NaN where the rods cannot reach z). ``device`` (None: the
    polynomial) and ``coulomb`` (None: no smoothed sign) are constants of each kernel (``_integrate``), so their
    branches vanish.
    """
    if device is None:
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
    if coulomb is not None:
        d += q[P_SIGN] * math.tanh(v / COULOMB_VELOCITY_SCALE)
    return k + d


@numba.njit(**JIT)  # called, not inlined in numba's IR: each inlined copy of a loop is compile time (LLVM inlines it)
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
def tabled(z, tab, b):
    """The shaped parts' force from member b's table (``effects.tabulate``; ``tab`` (B, rows): each member's table
    contiguous, ``member_tables``): the cubic of z's interval (knot spacings from the first knot), the end
    knots' tangent lines beyond them, each four coefficients in one cache line; no branch on the data but the
    guard that sends a NaN state to the first segment (the result stays NaN).
    """
    x = (z - tab[b, 0]) * tab[b, 1]
    last = tab[b, 2]  # the last knot's index: the right tail's segment
    xc = x if x > -1.0 else -1.0
    xc = xc if xc < last else last
    i = int(math.floor(xc))
    t = x - (i if i > 0 else 0)  # the left tail's t is measured from the first knot, as the first interval's
    r = 3 + 4 * (i + 1)
    return tab[b, r] + t * (tab[b, r + 1] + t * (tab[b, r + 2] + t * tab[b, r + 3]))


@numba.njit(inline="always", **JIT)
def member_tables(p, ts):
    """Each member's table rows (from ``ts``; -1: none) as one contiguous row per member (B, rows), copied once
    per call: in the parameter array a member's table is strided by the batch.
    """
    if ts < 0:  # a table of zeros: one knot at 0, its two tangent segments zero (``tabled`` reads it as any)
        none = np.zeros((p.shape[1], 11))
        none[:, 1] = 1.0
        return none
    return np.ascontiguousarray(p[ts:, :].T)


@numba.njit(inline="always", **JIT)
def total_force(device, coulomb, generic, table, z, v, q, p, b, mono, ts, tab):
    """``force`` plus, in the kernels compiled with ``generic`` (not None), the extra monomial rows, and in those
    compiled with ``table``, the shaped parts' table (``ts`` its first row in ``p``, -1: none; ``tab`` the members'
    tables, ``member_tables``).
    """
    f = force(device, coulomb, z, v, q)
    if generic is not None:
        f += monomials(z, v, p, b, mono)
    if table is not None:  # a member without a table (ts -1) reads a table of zeros: a branch on ts here, in the stage
        f += tabled(z, tab, b)  # loop, made a law's record 2.8x the polynomial's time against 1.4x without (measured)
    return f


@numba.njit(inline="always", **JIT)
def _bumps(x, c, g, out):
    """Gaussian bumps exp(-(x - c_i)^2 / (2 w^2)) on an even grid of centres ``c`` into ``out`` (its first c.size
    entries), ``g`` the grid's ``grid_constants``: the first centre's bump, then each next one by the ratio of
    neighbouring bumps, e_(i+1) = e_i exp(d s) exp(-(2i + 1) s^2 / 2) (d = (x - c_0) / w, s the step over the
    width), so two exponentials a grid, not one a bump (they were most of a hybrid free run's time; measured in
    ``reports/benchmarks.md``). d is capped where exp(d s) would overflow (every bump is zero there).
    """
    if c.size == 0:  # a hybrid without input bumps: nothing to read (c[0] is no element)
        return
    d = min((x - c[0]) * g[0], g[4])
    e = math.exp(-0.5 * d * d)
    r = math.exp(d * g[1]) * g[2]
    for i in range(c.size):
        out[i] = e
        e *= r
        r *= g[3]


def grid_constants(centres: np.ndarray, width: float) -> np.ndarray:
    """What ``_bumps`` reads of bumps of ``width`` on an even grid of ``centres``: (1 / width, s, exp(-s^2 / 2),
    exp(-s^2), the cap of d), s the grid's step over the width. One ``ValueError`` for an uneven grid.
    """
    c = np.asarray(centres, float)
    step = float(c[1] - c[0]) if c.size > 1 else float(width)
    if c.size > 2 and not np.allclose(np.diff(c), step, rtol=1e-9, atol=0.0):
        raise ValueError("the bumps' centres are not an even grid")
    s = step / float(width)
    return np.array([1.0 / float(width), s, math.exp(-0.5 * s * s), math.exp(-s * s), 700.0 / max(abs(s), 1e-300)])


@numba.njit(inline="always", **JIT)  # inlined: as a call (13 arguments, 7 of them arrays) it took half its time
def extra_term(z, v, u, w, a, zc, vc, uc, gz, gv, gu, bz, bv):
    """The extra force hook: g(z, z', u), a weighted sum of tensor-product Gaussian bumps over (z, z') and of
    bumps over u (the hybrid model's non-parametric term, ``inference.hybrid``), each grid's bumps by ``_bumps``
    (``gz``, ``gv``, ``gu``: the grids' ``grid_constants``; bz, bv: scratch, bz at least as long as uc).
    """
    _bumps(z, zc, gz, bz)
    _bumps(v, vc, gv, bv)
    g = 0.0
    for i in range(zc.size):
        s = 0.0
        for j in range(vc.size):
            s += w[i, j] * bv[j]
        g += s * bz[i]
    _bumps(u, uc, gu, bz)
    for k in range(uc.size):
        g += a[k] * bz[k]
    return g


@numba.njit(inline="always", **JIT)
def _column(q, b):
    """Member b's parameter tuple from a converted parameter array (``converted``)."""
    return (q[0, b], q[1, b], q[2, b], q[3, b], q[4, b], q[5, b], q[6, b], q[7, b], q[8, b], q[9, b], q[10, b],
            q[11, b], q[12, b], q[13, b], q[14, b], q[15, b], q[16, b])  # fmt: skip


@numba.njit(inline="always", **JIT)
def converted(p, device):
    """The parameter array with the device's angle rows turned into L cos(a), sin(a), once per call (not per step);
    ``_column`` reads one member's tuple from it.
    """
    q = p.copy()
    if device is not None:
        for b in range(p.shape[1]):
            q[2, b] = p[2, b] * math.cos(p[3, b])
            q[3, b] = math.sin(p[3, b])
    return q


@numba.njit(inline="always", **JIT)
def _accelerations(device, coulomb, generic, table, extra, linear, q, mono, ts, tab, ei, ej, minv, lk, lc, zs, vs, w,
                   ur, scratch, acc, hook):  # fmt: skip
    """Every member's accelerations at one Runge-Kutta stage, one loop over the batch per operation (the batch is
    the inner loop everywhere, which is what LLVM vectorises): the element's force law on the relative motion r
    of DOF ``ej`` and DOF ``ei`` (-1: the base), plus the extra hook; the linear structure ``lk``, ``lc``
    (``linear``); the element's force on ``ej`` and, opposite, on ``ei``. Arguments are bundled in tuples: a call of
    more than 30 arguments is a ``*args`` call in Python 3.12's bytecode, which numba's inliner refuses.
    """
    r, rv, f, lin, bz, bv = scratch
    hw, ha, hzc, hvc, huc, hgz, hgv, hgu = hook
    nb = q.shape[1]
    nd = zs.shape[0]
    if ei >= 0:
        for b in range(nb):
            r[b] = zs[ej, b] - zs[ei, b]
            rv[b] = vs[ej, b] - vs[ei, b]
    else:
        for b in range(nb):
            r[b] = zs[ej, b]
            rv[b] = vs[ej, b]
    for b in range(nb):  # vectorised over the batch: the table's look-up is a loop of its own (a gather)
        f[b] = total_force(device, coulomb, generic, None, r[b], rv[b], _column(q, b), q, b, mono, ts, tab)
    if table is not None:
        for b in range(nb):
            f[b] += tabled(r[b], tab, b)
    if extra is not None:
        for b in range(nb):
            f[b] += extra_term(r[b], rv[b], ur[b], hw, ha, hzc, hvc, huc, hgz, hgv, hgu, bz, bv)
    for d in range(nd):
        if linear:
            for b in range(nb):
                lin[b] = 0.0
            for e in range(nd):
                for b in range(nb):
                    lin[b] += lk[d, e, b] * zs[e, b] + lc[d, e, b] * vs[e, b]
            if d == ej:
                for b in range(nb):
                    lin[b] += f[b]
            elif d == ei:
                for b in range(nb):
                    lin[b] -= f[b]
            for b in range(nb):
                acc[d, b] = w[d, b] - lin[b] * minv[d, b]
        elif d == ej:
            for b in range(nb):
                acc[d, b] = w[d, b] - f[b] * minv[d, b]
        elif d == ei:
            for b in range(nb):
                acc[d, b] = w[d, b] + f[b] * minv[d, b]
        else:
            for b in range(nb):
                acc[d, b] = w[d, b]


@numba.njit(inline="always", **JIT)
def _fused_step(device, coulomb, generic, table, extra, q, mono, ts, tab, im, h, z, v, wa, wm, wb, ra, rm, rb, hook,
                scratch):  # fmt: skip
    """One Runge-Kutta step of every member of one DOF on the base without a linear structure (the single-DOF
    model): ``_integrate``'s stage-wise step with its four stages fused in one loop over the batch, the same
    operations in the same order (the same numbers to the last bit, tested), the state in registers. The
    stage-wise loops cost 2-4x at one DOF (each loop's set-up, paid some twenty times per step, measured).
    """
    hw, ha, hzc, hvc, huc, hgz, hgv, hgu = hook
    bz, bv = scratch[4], scratch[5]
    for b in range(z.size):
        qb = _column(q, b)
        zb = z[b]
        vb = v[b]
        zs, vs = zb, vb
        a1 = a2 = a3 = a4 = v2 = v3 = v4 = 0.0
        for s in range(4):  # one call site of the force law (each inlined copy is compile time; LLVM unrolls this)
            f = total_force(device, coulomb, generic, table, zs, vs, qb, q, b, mono, ts, tab)
            if extra is not None:
                f += extra_term(zs, vs, ra[b] if s == 0 else (rb[b] if s == 3 else rm[b]), hw, ha, hzc, hvc, huc, hgz,
                                hgv, hgu, bz, bv)  # fmt: skip
            acc = (wa[b] if s == 0 else (wb[b] if s == 3 else wm[b])) - f * im[b]
            if s == 0:
                a1 = acc
                zs = zb + 0.5 * h * vb
                v2 = vb + 0.5 * h * a1
                vs = v2
            elif s == 1:
                a2 = acc
                zs = zb + 0.5 * h * v2
                v3 = vb + 0.5 * h * a2
                vs = v3
            elif s == 2:
                a3 = acc
                zs = zb + h * v3
                v4 = vb + h * a3
                vs = v4
            else:
                a4 = acc
        z[b] = zb + h / 6.0 * (vb + 2.0 * v2 + 2.0 * v3 + v4)
        v[b] = vb + h / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4)


@numba.njit(**JIT)
def _integrate(device, coulomb, generic, table, extra, fused, stagewise, p, mono, ts, ei, ej, minv, lk, lc, gain, u,
               uidx, dt, nsub, z0, v0, z_limit, v_limit, out_z, out_v, store_v, status, fail_step, hook):  # fmt: skip
    """RK4 of B systems of N degrees of freedom over the T - 1 sample intervals of each member's input row
    ``u[uidx[b]]`` (state z, z' of each DOF, relative to the base): the package's one Runge-Kutta loop, every
    simulation of negstiff runs here, the single-DOF model as N = 1 (one DOF on the base, no linear structure).

        M z'' + C z' + K z + l F(z_J - z_I, z_J' - z_I') = gain u,   l = e_J - e_I,

    F the element's force law of member b's column of ``p`` (``force`` and the registry's terms), ``minv`` (N, B)
    the inverse masses, ``lk``/``lc`` (N, N, B) the linear structure (all zero: skipped), ``gain`` (N, B) the
    input's gain per DOF, ``z0``/``v0`` (N, B); outputs (T, N, B).

    The input row holds either the T samples (linearly interpolated inside each interval) or, when it has
    2 ``nsub`` (T - 1) + 1 columns, the input at every Runge-Kutta stage time (``stage_input``), read as it is.
    ``extra`` (a staged input) adds the hook ``extra_term`` with its weights and bumps (``hook``: w, a, the centres
    in z, z', u and each grid's ``grid_constants``) to the element's force.

    ``fused``: the fused step of one DOF on the base without a linear structure (``_fused_step``); ``stagewise``: the
    stage-wise loops of any structure; one of the two, the caller chooses (``simulator.integrate``). The seven flags
    (``device``: the rod frame's exact geometry, else the polynomial) are None (off) or 1 (on), so each combination
    is a signature of its own, compiled once and cached (``kernel_flags`` chooses them). numba's dead-branch pruning
    resolves an argument's None before it types and inlines anything, so a branch under a flag that is None is
    never compiled; an int argument's branch it keeps (hence a flag for each of the two steps: under one flag's
    None and not-None both steps were compiled, 4.6 s against 2.6 s). Called directly from Python, not through a
    compiled wrapper per combination: a wrapper linked and optimised the loop's code a second time (the
    polynomial's kernel compiled in 3.1 s through its wrapper), and a literal argument (``numba.literally``) made
    every call from Python retype the loop (2 s a call).
    """
    nb = p.shape[1]
    nd = minv.shape[0]
    n = out_z.shape[0]
    staged = u.shape[1] != n
    linear = False
    for d in range(lk.shape[0]):
        for e in range(lk.shape[1]):
            for b in range(lk.shape[2]):
                if lk[d, e, b] != 0.0 or lc[d, e, b] != 0.0:
                    linear = True
    h = dt / nsub
    q = converted(p, device)
    tab = member_tables(p, ts)
    if fused is not None and (nd != 1 or ei >= 0 or linear):
        raise ValueError("the fused step runs one DOF on the base without a linear structure")
    z = z0.copy()
    v = v0.copy()
    zt = np.empty((nd, nb))
    vt = np.empty((nd, nb))
    v2 = np.empty((nd, nb))
    v3 = np.empty((nd, nb))
    a1 = np.empty((nd, nb))
    a2 = np.empty((nd, nb))
    a3 = np.empty((nd, nb))
    a4 = np.empty((nd, nb))
    ua = np.empty((nd, nb))
    ub = np.empty((nd, nb))
    wa = np.empty((nd, nb))
    wm = np.empty((nd, nb))
    wb = np.empty((nd, nb))
    ra = np.empty(nb)
    rm = np.empty(nb)
    rb = np.empty(nb)
    r = np.empty(nb)
    rv = np.empty(nb)
    f = np.empty(nb)
    lin = np.empty(nb)
    scratch = (r, rv, f, lin, np.empty(max(hook[2].size, hook[4].size)), np.empty(hook[3].size))
    alive = np.ones(nb, dtype=np.bool_)
    for d in range(nd):
        for b in range(nb):
            out_z[0, d, b] = z[d, b]
            if store_v:
                out_v[0, d, b] = v[d, b]
    for k in range(n - 1):
        if not staged:
            for d in range(nd):
                for b in range(nb):  # gather the input once per sample, outside the vectorised loops
                    ua[d, b] = gain[d, b] * u[uidx[b], k]
                    ub[d, b] = gain[d, b] * u[uidx[b], k + 1]
        for j in range(nsub):
            if staged:  # the input at the step's start, midpoint and end
                c = 2 * (k * nsub + j)
                for b in range(nb):
                    ra[b] = u[uidx[b], c]
                    rm[b] = u[uidx[b], c + 1]
                    rb[b] = u[uidx[b], c + 2]
                for d in range(nd):
                    for b in range(nb):
                        wa[d, b] = gain[d, b] * ra[b]
                        wm[d, b] = gain[d, b] * rm[b]
                        wb[d, b] = gain[d, b] * rb[b]
            else:
                fa = j / nsub
                fm = (j + 0.5) / nsub
                fb = (j + 1.0) / nsub
                for d in range(nd):
                    for b in range(nb):
                        du = ub[d, b] - ua[d, b]
                        wa[d, b] = ua[d, b] + fa * du
                        wm[d, b] = ua[d, b] + fm * du
                        wb[d, b] = ua[d, b] + fb * du
            if fused is not None:
                _fused_step(device, coulomb, generic, table, extra, q, mono, ts, tab, minv[0], h, z[0], v[0], wa[0],
                            wm[0], wb[0], ra, rm, rb, hook, scratch)  # fmt: skip
            if stagewise is not None:
                # the four stages through one call site: numba inlines a function by copying its IR, and four copies
                # of the stage (each with the force law inlined) took minutes to compile; with one, ~9 s
                for s in range(4):
                    if s == 0:
                        zs, vs, w, ur, acc = z, v, wa, ra, a1
                    elif s == 1:
                        zs, vs, w, ur, acc = zt, v2, wm, rm, a2
                    elif s == 2:
                        zs, vs, w, ur, acc = zt, v3, wm, rm, a3
                    else:
                        zs, vs, w, ur, acc = zt, vt, wb, rb, a4
                    _accelerations(device, coulomb, generic, table, extra, linear, q, mono, ts, tab, ei, ej, minv, lk,
                                   lc, zs, vs, w, ur, scratch, acc, hook)  # fmt: skip
                    if s == 0:
                        for d in range(nd):
                            for b in range(nb):
                                zt[d, b] = z[d, b] + 0.5 * h * v[d, b]
                                v2[d, b] = v[d, b] + 0.5 * h * a1[d, b]
                    elif s == 1:
                        for d in range(nd):
                            for b in range(nb):
                                zt[d, b] = z[d, b] + 0.5 * h * v2[d, b]
                                v3[d, b] = v[d, b] + 0.5 * h * a2[d, b]
                    elif s == 2:
                        for d in range(nd):
                            for b in range(nb):
                                zt[d, b] = z[d, b] + h * v3[d, b]
                                vt[d, b] = v[d, b] + h * a3[d, b]
                for d in range(nd):
                    for b in range(nb):
                        z[d, b] = z[d, b] + h / 6.0 * (v[d, b] + 2.0 * v2[d, b] + 2.0 * v3[d, b] + vt[d, b])
                        v[d, b] = v[d, b] + h / 6.0 * (a1[d, b] + 2.0 * a2[d, b] + 2.0 * a3[d, b] + a4[d, b])
        bad = False
        for d in range(nd):
            for b in range(nb):
                if not (abs(z[d, b]) < z_limit and abs(v[d, b]) < v_limit):
                    bad = True
        if bad:  # some member out of range now or before (its state NaN): stop it, say why and when
            for b in range(nb):
                ok = True
                nonfinite = False
                for d in range(nd):
                    if not (abs(z[d, b]) < z_limit and abs(v[d, b]) < v_limit):
                        ok = False
                    if not math.isfinite(z[d, b]):
                        nonfinite = True
                if alive[b] and not ok:
                    alive[b] = False
                    fail_step[b] = k + 1
                    status[b] = STATUS_GEOMETRY if (device is not None and nonfinite) else STATUS_DIVERGED
                if not alive[b]:
                    for d in range(nd):
                        z[d, b] = math.nan
                        v[d, b] = math.nan
        for d in range(nd):
            for b in range(nb):
                out_z[k + 1, d, b] = z[d, b]
            if store_v:
                for b in range(nb):
                    out_v[k + 1, d, b] = v[d, b]
    return 0


NO_HOOK = (np.zeros((0, 0)), *(np.zeros(0) for _ in range(7)))
"""The extra force hook's arguments of a kernel without it: empty, never read (``extra`` None)."""


def device_flag(kind: int) -> int | None:
    """``_integrate``'s ``device`` flag of a restoring-force kind (``KINDS``): 1 for the rod frame's exact
    geometry, None for the polynomial.
    """
    return 1 if kind == KIND_DEVICE else None


def kernel_flags(kind: int, p: np.ndarray, mono: np.ndarray, hook: bool = False, table: bool = False,
                 staged: bool = False) -> tuple[int | None, ...]:  # fmt: skip
    """The compiled kernel for a batch, as ``_integrate``'s seven leading flags (None: off, 1: on): its
    restoring-force kind (``device``), whether any member has a smoothed sign (``coulomb``), whether the batch
    uses extra monomial rows (``generic``) or a table of shaped parts (``table``; then one general kernel, sign
    included), whether the extra force hook is used (``extra``), and whether it runs the fused step of one DOF on
    the base (``fused``) or the stage-wise loops of a structure (``stagewise``; asked by ``staged``).
    """
    device = device_flag(kind)
    sign = bool(np.any(p[P_SIGN] != 0.0))
    steps = (None, 1) if staged else (1, None)  # (fused, stagewise)
    if hook:
        if kind == KIND_POLYNOMIAL and not (sign or table or mono.shape[0]):
            # the hook's polynomial physics without a smoothed sign, extra monomials or tables (the hybrid's
            # usual physics): those terms' code, evaluated at zero, had cost a third of a free run (measured)
            return (None, None, None, None, 1, *steps)
        return (device, 1, 1, 1, 1, *steps)
    if table and kind == KIND_POLYNOMIAL and not sign and not mono.shape[0]:  # a shaped law: the table alone
        return (None, None, None, 1, None, *steps)
    if mono.shape[0] or table:
        return (device, 1, 1, 1, None, *steps)
    return (device, 1 if sign else None, None, None, None, *steps)
