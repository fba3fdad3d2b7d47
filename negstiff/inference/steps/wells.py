"""The stable wells a record visits, guessed in milliseconds from the record alone (no estimator): the
stable roots of a cubic restoring force fitted by equation error. NSI starts from them; the
characterisation and the report name a record's wells by them.
"""

from __future__ import annotations

import numpy as np
from scipy import signal

from negstiff.errors import MeasurementError
from negstiff.inference.record.measurement import Measurement


def well_guesses(rec: Measurement) -> tuple[float | None, float]:
    """First guesses of the stable wells from the data: the stable roots of a cubic restoring force
    fitted by equation error (least squares of u = z'' + a z' + b z'|z'| + K(z)/m on Savitzky-Golay
    derivatives over a window of ~fs/25 samples). Biased by derivative noise, but good to a few
    percent of the well spacing, which is all NSI needs: it refines each well from its own fit.
    Returns (z_minus, z_plus) of a double well, (None, z_plus) of a single well.
    """
    w = max(9, int(round(rec.fs / 25)))
    w += 1 - w % 2
    z = signal.savgol_filter(rec.z, w, 3)
    v = signal.savgol_filter(rec.z, w, 3, deriv=1, delta=rec.dt)
    a = signal.savgol_filter(rec.z, w, 3, deriv=2, delta=rec.dt)
    lin = -rec.u if rec.input_name == "base_acc" else rec.u
    X = np.column_stack([v, v * np.abs(v), np.ones_like(z), z, z**2, z**3])
    theta = np.linalg.lstsq(X, lin - a, rcond=None)[0]
    poly = theta[:1:-1]  # K/m coefficients, highest power first
    roots = np.roots(poly)
    real = np.sort(roots[np.abs(roots.imag) < 1e-9 * max(1.0, np.abs(roots).max())].real)
    dpoly = np.polyder(poly)
    stable = [r for r in real if np.polyval(dpoly, r) > 0 and z.min() <= r <= z.max()]
    if len(stable) >= 2:
        return float(stable[0]), float(stable[-1])
    if len(stable) == 1:
        return None, float(stable[0])
    raise MeasurementError(
        f"{rec.source}: no stable equilibrium found inside the measured range of z "
        "(is z the relative displacement, and is the input column right?)"
    )
