"""Physical constants used across negstiff (SI units)."""

G: float = 9.81
"""Gravitational acceleration [m/s^2]; the contract's default ``k0 = m * G``."""
