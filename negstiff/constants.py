"""Physical constants used across negstiff (SI units)."""

G: float = 9.81
"""Gravitational acceleration [m/s^2]; the contract's default ``k0 = m * G``."""
STANDARD_GRAVITY: float = 9.80665
"""Standard gravity [m/s^2] (ISO 80000-3): the 'g' an accelerometer's calibration is stated in."""
