"""The baselines the benchmarks measure against: what a user would write without negstiff (scipy's
``solve_ivp`` with a Python right-hand side) and the practical limit (a plain C RK4 loop compiled with
the system compiler), and the timer (median of repeats).
"""

from __future__ import annotations

import ctypes
import shutil
import subprocess
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

C_RK4 = r"""
#include <math.h>
/* Plain RK4 for m z'' + c z' + c_nl z'|z'| + k3 z^3 + k2 z^2 - k1 z + k0 = -m u,
   u linearly interpolated between samples, nsub steps per sample. */
static inline double acc(double z, double v, double w, const double *p) {
    double m = p[0], k0 = p[1], k1 = p[2], k2 = p[3], k3 = p[4], c = p[5], cnl = p[6];
    return w - (((k3 * z + k2) * z - k1) * z + k0 + v * (c + cnl * fabs(v))) / m;
}
void rk4(const double *p, const double *u, long n, double dt, int nsub, double z0, double v0, double *out) {
    double z = z0, v = v0, h = dt / nsub;
    out[0] = z;
    for (long k = 0; k < n - 1; k++) {
        double u0 = -u[k], du = -(u[k + 1] - u[k]);
        for (int j = 0; j < nsub; j++) {
            double wa = u0 + du * j / nsub, wm = u0 + du * (j + 0.5) / nsub, wb = u0 + du * (j + 1.0) / nsub;
            double a1 = acc(z, v, wa, p);
            double z2 = z + 0.5 * h * v, v2 = v + 0.5 * h * a1, a2 = acc(z2, v2, wm, p);
            double z3 = z + 0.5 * h * v2, v3 = v + 0.5 * h * a2, a3 = acc(z3, v3, wm, p);
            double z4 = z + h * v3, v4 = v + h * a3, a4 = acc(z4, v4, wb, p);
            z += h / 6.0 * (v + 2 * v2 + 2 * v3 + v4);
            v += h / 6.0 * (a1 + 2 * a2 + 2 * a3 + a4);
        }
        out[k + 1] = z;
    }
}
"""


def median_time[T](fn: Callable[[], T], repeats: int) -> tuple[float, T]:
    """The median wall time [s] of ``repeats`` calls of ``fn`` (at least one), and the last call's result."""
    times: list[float] = []
    out = None
    for _ in range(repeats):
        # the previous call's result freed before the next call, as a caller's loop frees it: a batch's 300 MB
        # output kept alive made the next call fault in fresh pages, 2.4x the polynomial batch's time (measured)
        del out
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times)), out


def build_c_rk4():
    """Compile the C RK4 loop with the system compiler; None if there is none."""
    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        return None
    d = Path(tempfile.mkdtemp(prefix="negstiff-bench-"))
    (d / "rk4.c").write_text(C_RK4)
    lib = d / "rk4.so"
    subprocess.run(
        [cc, "-O3", "-march=native", "-shared", "-fPIC", "-o", str(lib), str(d / "rk4.c"), "-lm"],
        check=True,
        capture_output=True,
    )
    f = ctypes.CDLL(str(lib)).rk4
    dp = ctypes.POINTER(ctypes.c_double)
    f.argtypes = [dp, dp, ctypes.c_long, ctypes.c_double, ctypes.c_int, ctypes.c_double, ctypes.c_double, dp]

    def run(model, u, dt, nsub, z0, v0):
        p = np.ascontiguousarray([model.m, model.k0, model.k1, model.k2, model.k3, model.c, model.c_nl])
        u = np.ascontiguousarray(u, dtype=float)
        out = np.empty(u.size)
        f(p.ctypes.data_as(dp), u.ctypes.data_as(dp), u.size, dt, nsub, z0, v0, out.ctypes.data_as(dp))
        return out

    return run


def solve_ivp_run(model, u, dt, z0, v0):
    t = np.arange(u.size) * dt

    def rhs(tt, x):
        w = -np.interp(tt, t, u)
        z, v = x
        return [
            v,
            w
            - (((model.k3 * z + model.k2) * z - model.k1) * z + model.k0 + v * (model.c + model.c_nl * abs(v)))
            / model.m,
        ]

    return solve_ivp(rhs, (0, t[-1]), [z0, v0], t_eval=t, method="RK45", rtol=1e-8, atol=1e-10).y[0]
