"""The checks a record's values pass however it is made (``reading.load`` from a file, ``from_arrays`` from
arrays, ``Measurement`` itself): finite samples within a shaker-table record's SI magnitudes, a sampling rate a
record has, a uniform time base, the masses, the DOF a force acts on, the gravity along the motion, an unknown
scale the record can identify and the auxiliary channels. Each failure is one ``MeasurementError`` line naming
the source, the column or row, and what is wrong.
"""

from __future__ import annotations

import numpy as np

from negstiff.errors import MeasurementError
from negstiff.io.schema import (
    AUX_MAGNITUDE_LIMIT,
    GRAVITY_RANGE,
    INPUTS,
    KNOWN,
    MAGNITUDE_LIMITS,
    MASS_RANGE_KG,
    SAMPLING_RATE_RANGE_HZ,
    TIME_STEP_RESOLUTION,
    UNITS,
    dimension,
)

TIME_JITTER_FRACTION = 0.01
"""A time column's samples may sit this fraction of a step off a uniform grid (or by their printed
precision, whichever is larger) and still be uniform: lab exports round time."""


def checked_masses(source, masses, n_dof: int) -> tuple[float, ...]:
    """``n_dof`` masses [kg] within ``MASS_RANGE_KG`` (a string "m1,...,mN" too), or one ``MeasurementError``."""
    if isinstance(masses, str):
        try:
            masses = [float(x) for x in masses.split(",")]
        except ValueError:
            raise MeasurementError(f"{source}: masses must be numbers separated by commas, got {masses!r}") from None
    try:
        out = tuple(float(m) for m in np.atleast_1d(np.asarray(masses, dtype=float)))
    except (TypeError, ValueError):
        raise MeasurementError(f"{source}: masses must be numbers, got {masses!r}") from None
    lo, hi = MASS_RANGE_KG
    if len(out) != n_dof or not all(lo <= m <= hi for m in out):
        raise MeasurementError(f"{source}: masses must be {n_dof} masses of {lo:g} to {hi:g} kg (one per DOF, "
                               f"'# masses: m1,...,mN'), got {list(out)}")  # fmt: skip
    return out


def checked_force_dof(source, value, n_dof: int) -> int | None:
    """The metadata's ``force_dof`` (the DOF a force acts on, 1..N), checked; None when not given."""
    if value is None:
        return None
    try:
        k = int(value)
    except (TypeError, ValueError):
        raise MeasurementError(f"{source}: force_dof {value!r} is not a DOF number (1..{n_dof})") from None
    if not 1 <= k <= n_dof:
        raise MeasurementError(f"{source}: force_dof {k} is not a DOF of the record (1..{n_dof})")
    return k


def checked_gravity(source, g) -> float:
    """The gravity along the motion [m/s^2] within ``GRAVITY_RANGE``, or one ``MeasurementError``."""
    try:
        g = float(g)
    except (TypeError, ValueError):
        raise MeasurementError(f"{source}: gravity {g!r} is not a number (m/s^2 along the motion: 0 for a "
                               "horizontal device, 9.81 for a vertical one)") from None  # fmt: skip
    if not (GRAVITY_RANGE[0] <= g <= GRAVITY_RANGE[1]):
        lo, hi = GRAVITY_RANGE
        raise MeasurementError(f"{source}: gravity {g:g} m/s^2 along the motion is outside {lo:g}-{hi:g} (0 for a "
                               "horizontal device, 9.81 for a vertical one)")  # fmt: skip
    return g


SCALABLE = {"base_acc": ("z", "z_dot"), "force": ("z", "z_dot", "y", "y_dot", "y_acc")}
"""Response channels whose unknown scale (``*?``) the record's dynamics can estimate: those z is linear in
(a base-excited record's y, y_dot, y_acc mix the unknown scale with the base's known motion). One more: a
base-excited record's y_dot when it is the response, an absolute velocity of unknown gain (a vibrometer on the
ground): the base's known motion in z = integral of (g y_dot - b') says g (``sensors.absolute_velocity_gain``)."""


def checked_unknown_scale(source, name: str | None, input_name: str, mass: float | None, present) -> dict | None:
    """``info["scale"]`` for a response channel marked ``*?`` (None without one), after checking that the
    record can identify it: the input's coefficient must be known (-1 for a base acceleration; 1/m for a
    force, so a force-driven record needs its mass).
    """
    if name is None:
        return None
    absolute = input_name == "base_acc" and name == "y_dot" and not any(k in present for k in ("z", "z_dot", "y"))
    if name not in SCALABLE[input_name] and not absolute:
        what = (
            "the input's scale is what makes a response's scale identifiable: it must be known"
            if name in INPUTS
            else f"only {', '.join(SCALABLE[input_name])} of a {input_name} record can be"
        )
        raise MeasurementError(f"{source}: {name}'s scale is marked unknown (*?): {what}")  # fmt: skip
    if name not in present:
        raise MeasurementError(f"{source}: {name}'s scale is marked unknown (*?), but the record has no {name}")
    if input_name == "force" and mass is None:
        raise MeasurementError(
            f"{source}: {name}'s scale is marked unknown (*?), but a force-driven record without a mass cannot "
            "identify it (z'' = force / m - ...: scale and mass trade off); give the mass (--mass or '# mass:')"
        )
    if absolute:  # its gain is estimated with z (``sensors.absolute_velocity_gain``); z's scale then as z_dot's
        status = ("unknown: y_dot's gain estimated as z was derived (the base's known motion in z), the measured "
                  "point's participation in the input from the record's dynamics when analysed")  # fmt: skip
        return {"channel": name, "value": None, "status": status}
    return {"channel": name, "value": None, "status": "unknown: estimated from the record's dynamics when analysed"}


def aux_channels(source, raw: dict[str, np.ndarray], names, n: int) -> dict[str, np.ndarray]:
    """The auxiliary channels ``names`` (the file's own column names: a piezo's voltage, a coil's current),
    checked finite and of the record's length; refused when absent or a contract column.
    """
    out = {}
    for name in names or ():
        name = str(name).strip()
        if name in KNOWN:
            raise MeasurementError(f"{source}: --aux {name}: {name} is a measurement column, not an auxiliary channel")
        if name not in raw:
            raise MeasurementError(f"{source}: --aux {name}: no such column (columns: {', '.join(raw) or 'none'})")
        v = np.asarray(raw[name], float)
        if v.ndim != 1 or v.size != n:
            raise MeasurementError(f"{source}: auxiliary channel {name} has {v.size} samples, the record {n}")
        check_values(source, {name: v})  # finite (a channel of its own: no contract magnitude)
        big = np.flatnonzero(np.abs(v) > AUX_MAGNITUDE_LIMIT)
        if big.size:
            raise MeasurementError(
                f"{source}: auxiliary channel {name} is {v[big[0]]:.3g} at row {big[0] + 1}, beyond any lab "
                f"instrument's reading (|{name}| <= {AUX_MAGNITUDE_LIMIT:g} in its units): scale it to its units"
            )
        out[name] = v
    return out


def is_constant(x: np.ndarray) -> bool:
    """No variation beyond the values' own floating-point resolution."""
    span = float(np.ptp(x))
    return bool(span <= 64 * np.finfo(float).eps * float(np.max(np.abs(x))) or span < 1e-15)


def check_values(source, cols: dict[str, np.ndarray]) -> None:
    """Every value finite and, for a contract column, within the magnitude no shaker-table record in SI
    exceeds (``units.MAGNITUDE_LIMITS``); one ``MeasurementError`` naming the column, the row and the unit.
    """
    for k, v in cols.items():
        bad = np.flatnonzero(~np.isfinite(v))
        if bad.size:
            raise MeasurementError(f"{source}: column {k} is NaN or inf at row {bad[0] + 1}")
        dim = dimension(k)
        if dim is None or not v.size:
            continue
        if dim == "time":  # its magnitude does not matter (Unix time), its steps do
            _check_time_steps(source, k, v)
            continue
        limit = MAGNITUDE_LIMITS[dim]
        big = np.flatnonzero(np.abs(v) > limit)
        if big.size:
            unit = next(iter(UNITS[dim]))
            raise MeasurementError(
                f"{source}: column {k} is {v[big[0]]:.3g} {unit} at row {big[0] + 1}, beyond any shaker-table record "
                f"(|{k}| <= {limit:g} {unit}): is it in SI units? scale it with --columns {k}=COL*FACTOR"
            )


def _check_time_steps(source, k: str, v: np.ndarray) -> None:
    """A time column float64 resolves: its spacing at the column's largest value within
    ``TIME_STEP_RESOLUTION`` of the median step (steps that are not there, none or not finite, are the
    time base's to refuse).
    """
    if v.size < 2:
        return
    with np.errstate(over="ignore", invalid="ignore"):
        step = float(np.median(np.abs(np.diff(v))))
    top = float(np.max(np.abs(v)))
    ulp = float(np.spacing(top))
    if np.isfinite(step) and step > 0 and not ulp <= TIME_STEP_RESOLUTION * step:
        raise MeasurementError(
            f"{source}: column {k} reaches {top:.3g} s, where float64 resolves steps of {ulp:.2g} s, not its step "
            f"of {step:.3g} s: subtract the start time from it (or give the rate, fs, instead)"
        )


def check_sampling_rate(source, fs: float, where: str) -> float:
    """A sampling rate [Hz] within ``units.SAMPLING_RATE_RANGE_HZ``, or one ``MeasurementError`` naming
    where it came from.
    """
    lo, hi = SAMPLING_RATE_RANGE_HZ
    if isinstance(fs, bool) or not isinstance(fs, (int, float, np.integer, np.floating)) or not lo <= fs <= hi:
        raise MeasurementError(f"{source}: sampling rate {fs!r} Hz ({where}) is not a rate a record has "
                               f"({lo:g} to {hi:g} Hz)")  # fmt: skip
    return float(fs)


def time_base(t: np.ndarray, resolution: np.ndarray | None, path) -> tuple[float, float, float]:
    """The step of a time column that is uniform within its printed precision (or 1 % of a step).

    Returns (mean step [s], largest deviation from the uniform grid [s], coarsest printed
    resolution [s]). A step that is not positive, or a gap, dropout or repeated block, raises
    ``MeasurementError`` naming the first bad row (1-based data row).
    """
    n = t.size
    d = np.diff(t)
    if np.any(d <= 0):
        r = int(np.flatnonzero(d <= 0)[0]) + 2
        raise MeasurementError(
            f"{path}: column t is not increasing at row {r} (t = {t[r - 1]:.9g} s after {t[r - 2]:.9g} s)"
        )
    res = np.zeros(n) if resolution is None else np.asarray(resolution, float)
    res = res + 4 * np.spacing(np.abs(t))  # the column's own floating-point resolution
    # the typical step: the median of the printed steps, itself off by up to one printed unit
    k = int(np.argsort(d)[d.size // 2])
    step = float(d[k])
    # a step may deviate by the rounding of its two ends (half a printed unit each) plus the median's own
    # rounding, or by 1 % of a step from each end's grid position
    tol_d = np.maximum(0.5 * (res[1:] + res[:-1]) + res[k : k + 2].max(), 2 * TIME_JITTER_FRACTION * step)
    # a step half a typical step off is a gap or a repeat whatever the printing: rounding explains it only
    # where the column is printed too coarsely to show its own sampling (then --fs is the way)
    tol_d = np.minimum(tol_d, 0.5 * step)
    bad = np.flatnonzero(np.abs(d - step) > tol_d * (1 + 1e-9))
    if bad.size:
        r = int(bad[0]) + 2
        raise MeasurementError(
            f"{path}: column t is not uniformly sampled at row {r} (step {d[r - 2]:.6g} s, typical {step:.6g} s: "
            "a gap, dropout or repeated block; only rounding of the printed time is tolerated)"
        )
    i = np.arange(n) - (n - 1) / 2  # the clock's step: least squares over every sample (rounding averages out)
    dt = float(i @ (t - t.mean()) / (i @ i))
    dev = np.abs(t - (t.mean() + dt * i))
    # half a printed unit (or 1 % of a step), plus the fitted grid's own error (~ resolution / sqrt(n))
    tol = np.maximum(0.5 * res, TIME_JITTER_FRACTION * dt) + 1e-3 * res.max() + 1e-12 * dt
    slow = np.flatnonzero(dev > tol)
    if slow.size:
        r = int(slow[0]) + 1
        raise MeasurementError(
            f"{path}: column t is not uniformly sampled at row {r} (t = {t[r - 1]:.9g} s, {dev[r - 1]:.3g} s off "
            f"the uniform grid of step {dt:.6g} s; the clock drifts)"
        )
    return float(dt), float(dev.max()), float(res.max())
