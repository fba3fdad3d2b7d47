"""The stable wells a record visits, guessed in milliseconds from the record alone (no estimator): the
stable roots of a restoring force fitted by equation error. NSI starts from them; the characterisation and the
report name a record's wells by them.
"""

from __future__ import annotations

import numpy as np
from scipy import signal
from scipy.optimize import brentq

from negstiff.errors import MeasurementError
from negstiff.inference.record.measurement import Measurement
from negstiff.models import laws


def well_guesses(rec: Measurement, restoring=laws.DEFAULT_RESTORING, damping=laws.DEFAULT_DAMPING,
                 shape: laws.Shape | None = None) -> tuple[float | None, float]:  # fmt: skip
    """First guesses of the stable wells from the data: the stable roots, inside the measured range of z, of the
    restoring law's force (``models.laws``; the reference study's cubic by default, at ``shape``) fitted by
    equation error (least squares of u = z'' + D(z') + K(z)/m on Savitzky-Golay derivatives over a window of
    ~fs/25 samples). Biased by derivative noise, but good to a few percent of the well spacing, which is all
    NSI needs: it refines each well from its own fit. Returns (z_minus, z_plus) of a double well, (None, z_plus)
    of a single well.
    """
    restoring, damping = laws.get(restoring, "restoring"), laws.get(damping, "damping")
    w = max(9, int(round(rec.fs / 25)))
    w += 1 - w % 2
    z = signal.savgol_filter(rec.z, w, 3)
    v = signal.savgol_filter(rec.z, w, 3, deriv=1, delta=rec.dt)
    a = signal.savgol_filter(rec.z, w, 3, deriv=2, delta=rec.dt)
    lin = -rec.u if rec.input_name == "base_acc" else rec.u
    D = damping.columns(z, v, shape)
    K = restoring.columns(z, v, shape)
    theta = np.linalg.lstsq(np.column_stack([D, K]), lin - a, rcond=None)[0]
    k = theta[D.shape[1] :]  # K/m = sum_j k_j C_j(z)

    def force(x):
        return restoring.columns(np.atleast_1d(x), np.zeros(np.size(x)), shape) @ k

    def slope(x: float) -> float:
        h = 1e-6 * max(float(np.ptp(z)), 1e-9)
        return float((force(x + h) - force(x - h))[0] / (2 * h))

    lo, hi = float(z.min()), float(z.max())
    grid = np.linspace(lo, hi, 2001)
    f = force(grid)
    roots = [float(grid[i]) if f[i] == 0 else brentq(lambda x: float(force(x)[0]), grid[i], grid[i + 1], xtol=1e-15)
             for i in np.flatnonzero(np.sign(f[:-1]) * np.sign(f[1:]) <= 0) if f[i + 1] != 0 or f[i] == 0]  # fmt: skip
    roots = [r for r in roots if slope(r) > 0]
    stable = sorted(set(roots))
    if len(stable) >= 2:
        return float(stable[0]), float(stable[-1])
    if len(stable) == 1:
        return None, float(stable[0])
    raise MeasurementError(
        f"{rec.source}: no stable equilibrium found inside the measured range of z "
        "(is z the relative displacement, and is the input column right?)"
    )
