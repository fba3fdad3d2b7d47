"""The shaking table's motion and a lab's route from its accelerometer to displacement: the true
table motion of a target acceleration (``table_motion``) and the band-limited integrals a lab computes
(``integrate_fft``, ``integrate_twice``).
"""

from __future__ import annotations

import numpy as np
from scipy import fft as sp_fft
from scipy import signal
from scipy.integrate import cumulative_trapezoid


def table_motion(acc_target: np.ndarray, fs: float, min_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """Consistent true table displacement b [m] and acceleration b'' [m/s^2] from a target b''.

    The target is projected on frequencies >= ``min_hz`` (a shaker has no DC stroke) and integrated
    twice in the frequency domain, so b'' is exactly the second derivative of b.
    """
    n = acc_target.size
    spec = sp_fft.rfft(acc_target)
    f = np.fft.rfftfreq(n, 1 / fs)
    spec[f < min_hz] = 0.0
    w = 2 * np.pi * f
    disp_spec = np.zeros_like(spec)
    disp_spec[f >= min_hz] = -spec[f >= min_hz] / w[f >= min_hz] ** 2
    return sp_fft.irfft(disp_spec, n), sp_fft.irfft(spec, n)


def integrate_fft(x: np.ndarray, fs: float, highpass_hz: float, order: int = 2) -> np.ndarray:
    """Band-limited integral of ``order`` 1 or 2 of a sampled signal (a lab's route from an
    accelerometer to velocity or displacement): exact 1/(i w)^order above ``highpass_hz``, a cosine
    taper down to half of it, nothing below (a shaker has no DC stroke, and sensor noise integrated
    grows as 1/f^order).
    """
    n = x.size
    spec = sp_fft.rfft(x - x.mean())
    f = np.fft.rfftfreq(n, 1 / fs)
    gain = np.zeros(f.size, dtype=complex if order % 2 else float)
    band = f >= highpass_hz
    gain[band] = 1.0 / (2j * np.pi * f[band]) ** order if order % 2 else -1.0 / (2 * np.pi * f[band]) ** order
    taper = (f >= highpass_hz / 2) & ~band
    ft = f[taper]
    w = 0.5 * (1 - np.cos(np.pi * (ft / (highpass_hz / 2) - 1)))
    gain[taper] = w / (2j * np.pi * ft) ** order if order % 2 else -w / (2 * np.pi * ft) ** order
    return sp_fft.irfft(spec * gain, n)


def integrate_twice(acc: np.ndarray, fs: float, highpass_hz: float, method: str = "fft") -> np.ndarray:
    """Base displacement from measured acceleration as a lab computes it (``Sensors.integration``)."""
    if method == "time":
        sos = signal.butter(4, highpass_hz, "highpass", fs=fs, output="sos")
        vel = signal.sosfiltfilt(sos, cumulative_trapezoid(acc, dx=1 / fs, initial=0.0))
        return signal.sosfiltfilt(sos, cumulative_trapezoid(vel, dx=1 / fs, initial=0.0))
    if method != "fft":
        raise ValueError(f"integration must be 'fft' or 'time', got {method!r}")
    return integrate_fft(acc, fs, highpass_hz, order=2)
