"""The restoring force a record's preparation reads: a smooth force with no formula over the stroke the record visited.

Before any identification the record itself is made physical, and each step asks the record's own dynamics a
question that a restoring force K(z) must take part in answering: an absolute vibrometer's gain
(``sensors.absolute_velocity_gain``), the scale of a response of unknown sensitivity (``frame.calibrate_scale``),
the drift a velocity's integral leaves in z (``frame.drift_by_physics``: K(z - d) ~ K(z) - d K'(z)) and the frame
of a derived z (``frame.frame_offset``: the wells, where the weight is carried). None of the questions is about
the force's form, so none assumes one: a polynomial that does not follow the device leaves a misfit that the
unknown the step estimates then takes up (a quintic put a magnet harvester's vibrometer gain 6.6 % high, and a
cubic's slowly varying z^2 coefficient moved the in-well record's z by 1.35 mm that was not drift; measured on
``tests/law_records.py``'s records).

The force is a cubic B-spline (de Boor 1978, "A Practical Guide to Splines", Springer; ``models.shaped.Spline``)
with ``STROKE_INTERVALS`` even intervals over the whole stroke [min z, max z], continued by straight lines beyond.
It holds any smooth device: a cubic, a quintic or a septic polynomial, facing magnets (point dipoles), oblique
springs and the reference study's rod frame alike (``STROKE_INTERVALS``). The knots span the extremes, not the
stroke's quantiles: with 16 intervals over the 0.5-99.5 % quantiles the straight lines beyond them missed the
septic's steep outer force by 2.2 % rms of the force over the record's samples and the rod frame's by 1.0 %
(measured; over the extremes 2.6e-4 and 7.8e-5), a misfit that the steps' unknowns would take up again.
"""

from __future__ import annotations

import numpy as np

from negstiff.models.shaped import Spline

STROKE_INTERVALS = 16
"""Even intervals of the preparation's spline over the stroke. The least-squares spline over each test record's
own z misses the true restoring force by this share of its rms (knots over [min z, max z], 8 / 12 / 16
intervals, measured): the magnet harvester's chaos (+-27 mm across two wells, the dipoles' steep
repulsion) 1.0e-2 / 9.5e-4 / 2.2e-4, in one well 5e-6 / 1e-6 / 3e-7; the septic polynomial 4.1e-3 / 8.4e-4 /
2.6e-4; oblique springs 4.2e-4 / 6.7e-5 / 2.0e-5; the rod frame 1.0e-3 / 2.4e-4 / 7.8e-5 (a quintic: 0.13,
5.7e-5, 3.4e-2, 4.7e-3, 4.8e-3). 16 intervals put every one of them below the equation error's noise floor of a
lab record (a few 1e-3), and cost 19 columns (a cubic polynomial's space is inside it: its misfit is nil)."""

_SPLINE = Spline()


def knots(z: np.ndarray, intervals: int | None = None) -> np.ndarray:
    """The preparation spline's knots [m]: ``intervals`` (default ``STROKE_INTERVALS``) even intervals over
    [min z, max z].

    Raises
    ------
    ValueError
        When z does not move (no stroke to span).
    """
    z = np.asarray(z, float)
    lo, hi = float(np.min(z)), float(np.max(z))
    if not hi > lo:
        raise ValueError("z does not move: no stroke for a restoring force")
    return np.linspace(lo, hi, (STROKE_INTERVALS if intervals is None else intervals) + 1)


def shape(z: np.ndarray, intervals: int | None = None) -> dict[str, dict[str, tuple[float, ...]]]:
    """The shape of the ``spline`` law (``models.laws``) over z's stroke: ``{"spline": {"knots": ...}}``, the
    shape a ``weak.Library.of_laws("spline", ...)`` takes.
    """
    return {"spline": {"knots": tuple(float(k) for k in knots(z, intervals))}}


def basis(z: np.ndarray, knots: np.ndarray) -> np.ndarray:
    """The spline's columns at z (samples, ``len(knots) + 2``): K(z) = basis @ coefficients. They sum to one."""
    return _SPLINE.column_matrix({"knots": knots}, np.asarray(z, float))


def slopes(z: np.ndarray, knots: np.ndarray) -> np.ndarray:
    """The columns' derivatives at z [1/m] (samples, ``len(knots) + 2``): K'(z) = slopes @ coefficients. They sum
    to zero.
    """
    return _SPLINE.slope_columns({"knots": knots}, z)
