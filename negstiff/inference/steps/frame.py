"""The record made physical: what a derived or uncalibrated response leaves unknown, fixed by the record's
own physics, one step (``pin_frame``) that every analysis needing it calls (every estimator's ``check``,
``characterise``, ``frf``, a simulation's start state), never ``load``: a user who only reads a record
pays for no fit.

1. **The scale** of a response channel whose sensitivity is unknown (a column map's ``*?``: a laser
   vibrometer's volts, its gain not written down). In a base-excited record physics fixes the input's
   coefficient: z'' = -base_acc - (c z' + K(z)) / m. A response read in its sensor's units, z_read = z / s,
   obeys z_read'' = -base_acc / s - ..., so the coefficient the record's own dynamics learn for the input
   (``weak.input_coefficient`` over ``weak.stroke_library``: a restoring force with no formula, a spline over the
   stroke, with viscous and quadratic damping, unconstrained weak-form least squares) is -1 / s. For a
   force-driven record it is 1 / (m s): the mass must be known, or scale and mass trade off (``load`` refuses
   that record). ``calibrate_scale`` estimates s with its standard error (the spread of the estimates from parts
   of the record), multiplies the response by it, so that every coefficient found afterwards is in SI units, and
   says so in ``info["scale"]`` (a result's ``record.scale``).
2. **The frame** of a derived z: a z integrated from a velocity or an acceleration has an unknown constant;
   ``frame_offset`` finds it by physics (the wells at the rest positions the metadata states, else gravity:
   K(0) = m g, or for a device without gravity along its motion the wells' symmetry) and ``pin_frame``
   returns the record in the physical frame, with the offset, its uncertainty and the anchor in
   ``info["response"]``.

Each step reads the record's restoring force as one with no formula, a spline over the stroke it visited
(``weak.stroke_library``, ``record.stroke_spline``), so that a device whose force is not a polynomial (facing
magnets, oblique springs, the reference study's rod frame) leaves no misfit for the scale, the drift or the frame
to take up.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from negstiff.errors import MeasurementError
from negstiff.inference.record import stroke_spline
from negstiff.inference.record.measurement import Measurement
from negstiff.inference.record.sensors import integral_warnings
from negstiff.inference.steps.weak import (
    WeakForm,
    WeakFormError,
    fit_support,
    input_coefficient,
    known_input_gain,
    stroke_library,
)


def _crossings(x: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Zeros of a sampled function, by linear interpolation between the samples that bracket them."""
    i = np.flatnonzero(np.diff(np.sign(f)) != 0)
    return x[i] - f[i] * (x[i + 1] - x[i]) / (f[i + 1] - f[i])


def restoring_force(rec: Measurement, points: int = 4001) -> tuple[np.ndarray, np.ndarray]:
    """The record's restoring force per unit mass, K(x)/m [m/s^2], on ``points`` even points x [m] over the stroke
    it visited: the preparation's spline (``weak.stroke_library``: any smooth device's force) fitted to the record's
    weak form with viscous and quadratic damping, the input's coefficient fixed by physics (learned where it is not
    known: a force without a mass). In the record's own frame: K_rec(x) = K_true(x + C).
    """
    library = stroke_library(rec)
    gain = known_input_gain(rec)
    phys = fit_support(WeakForm.of(rec).system(rec, library=library), gain)
    assert library.shape is not None
    knots = np.asarray(library.shape["spline"]["knots"])
    x = np.linspace(knots[0], knots[-1], points)
    return x, -(stroke_spline.basis(x, knots) @ phys[: knots.size + 2])


def _frame_anchors(rec) -> tuple[float, dict[str, float]]:
    """In the record's own frame: the origin and the stable wells, all searched over the stroke the record
    visited. The origin is where the record's restoring force (``restoring_force``: a spline over its stroke)
    carries the weight (g per unit mass) between its wells, or, for a device with no gravity along its motion
    (``rec.gravity`` 0), midway between its wells (the symmetry of a horizontal double well); ``wells["barrier"]``
    is then the unstable equilibrium between them, whose distance from the midpoint measures how symmetric the
    device is.
    """
    x, K = restoring_force(rec)
    eq = _crossings(x, K)
    stable = [e for e in eq if np.interp(e, x, np.gradient(K, x)) > 0]
    if len(stable) == 1:  # an in-well record: one well, and no origin between wells to find
        return float("nan"), {"one": stable[0]}
    wells = {"minus": stable[0], "plus": stable[-1]} if len(stable) >= 2 else {}
    if rec.gravity == 0:
        if not wells:
            raise ValueError(
                "the fitted restoring force has no two wells over the visited stroke to be symmetric about"
            )
        between = [e for e in eq if wells["minus"] < e < wells["plus"]]
        mid = 0.5 * (wells["minus"] + wells["plus"])
        barrier = float(between[np.argmin(np.abs(np.array(between) - mid))]) if between else float("nan")
        return mid, {**wells, "barrier": barrier}
    roots = _crossings(x, K - rec.gravity)
    if not roots.size:
        raise ValueError("the fitted restoring force never carries the weight over the visited stroke")
    # the weight is carried next to the barrier: the unstable equilibrium nearest the middle of the outermost wells
    # (the spline may wiggle where the record barely went: a false well and barrier there must not be the middle)
    slope = np.gradient(K, x)
    unstable = np.array([e for e in eq if np.interp(e, x, slope) <= 0])
    centre = 0.5 * (wells["minus"] + wells["plus"]) if wells else float(np.median(rec.z))
    mid = float(unstable[np.argmin(np.abs(unstable - centre))]) if unstable.size else centre
    origin = float(roots[np.argmin(np.abs(roots - mid))])
    if wells and not wells["minus"] < origin < wells["plus"]:
        wells = {}  # a fit whose weight-carrying point is not between its wells pins nothing well
    return origin, wells


def frame_offset(rec, spread: bool = True, use_rest: bool = True) -> dict[str, Any]:
    """The frame constant C that makes a record's z physical (z_true = z + C).

    Two anchors, the better one used:

    * rest positions (``# z_minus_rest`` / ``# z_plus_rest`` metadata [m], measured statically
      before the test; ``# z_rest`` for the one well an in-well record stays in): C = z_rest -
      x_well, with x_well the fitted model's wells in the record's frame (well positions are what a
      record determines best); an in-well record can only be pinned this way;
    * the wells' symmetry, for a device with no gravity along its motion (``# gravity: 0``, a horizontal
      harvester): the origin midway between the fitted wells, and how far the barrier between them sits
      from it (``asymmetry_m``: how well the symmetry pins the frame);
    * gravity: the restoring force at z = 0 (rods horizontal) carries the weight, K(0) = m g (g per
      unit mass). A restoring force with no formula (a spline over the stroke, ``restoring_force``) with
      viscous and quadratic damping is fitted by weak-form least squares in the record's frame, where
      K_rec(x) = K_true(x + C); the origin solves K_rec(x) = m g between the fitted wells (a negative-stiffness
      device's origin is next to its unstable equilibrium). A force-driven record carries no weight
      in its equation (k0 is the force's offset): there the frame is not pinned.

    The uncertainty ``offset_se_m`` is the spread of the estimates from ``FRAME_PARTS`` parts of the
    record, scaled to the whole (sd / sqrt(parts)); ``spread=False`` skips the parts (``offset_se_m`` NaN:
    the plausibility check asks for it only when it warns); ``use_rest=False`` ignores the rest positions (the
    plausibility check asks where the physics alone put the frame). Returns a dict with ``offset_m`` (None
    when not pinned), ``offset_se_m``, ``method``.
    """
    rest = {w: rec.meta.get(f"z_{w}_rest") for w in ("minus", "plus")}
    try:
        rest = {w: float(v) for w, v in rest.items() if v is not None}
        if "z_rest" in rec.meta:  # the rest position of the one well an in-well record stays in
            rest["one"] = float(rec.meta["z_rest"])
    except ValueError:
        rest = {}
    if not use_rest:
        rest = {}
    horizontal = rec.gravity == 0
    if rec.input_name != "base_acc" and not rest and not horizontal:
        return {"offset_m": None, "method": "not pinned: a force-driven record carries no weight (k0 unknown)"}
    try:
        x, wells = _frame_anchors(rec)
        parts = []
        for seg in _parts(rec, FRAME_PART_MIN_S, FRAME_PARTS) if spread else ():
            try:
                part = _frame_anchors(seg)
            except Exception:
                continue
            if part[1]:  # only parts that visited both wells say where the origin between them is
                parts.append(part)
    except Exception as exc:  # a record too short or too poor for the fit: said, not pinned
        return {"offset_m": None, "method": f"not pinned: {' '.join(str(exc).split())}"}
    if "one" in wells:
        if "one" not in rest and len(rest) == 1:
            rest["one"] = next(iter(rest.values()))
        if "one" not in rest:
            return {
                "offset_m": None,
                "one_well": True,
                "method": "not pinned: the record stays in one well (no origin between wells to find); give that "
                "well's rest position as '# z_rest: VALUE' metadata [m]",
            }
    anchored = [w for w in rest if w in wells]
    if anchored:

        def offset(ws):
            return float(np.mean([rest[w] - ws[w] for w in anchored]))

        return {
            "offset_m": offset(wells),
            "offset_se_m": _se([offset(p[1]) for p in parts if all(w in p[1] for w in anchored)]),
            "method": "the fitted wells put at the rest positions of the file's metadata ("
            + ", ".join(f"z_{w}_rest = {rest[w]:g} m" for w in anchored)
            + ")",
        }
    if horizontal:
        if "minus" not in wells:
            return {
                "offset_m": None,
                "method": "not pinned: gravity 0 along the motion, and the record does not show "
                "two wells to be symmetric about; give the rest positions ('# z_minus_rest', '# z_plus_rest')",
            }
        return {
            "offset_m": -x,
            "offset_se_m": _se([-p[0] for p in parts]),
            "asymmetry_m": float(wells["barrier"] - x),
            "method": "the wells' symmetry (gravity 0 along the motion): the origin midway between the wells of a "
            "spline restoring force fitted to the record; the barrier between them sits "
            f"{1e3 * (wells['barrier'] - x):.3g} mm from that midpoint",
        }
    if rec.input_name != "base_acc":
        return {"offset_m": None, "method": "not pinned: a force-driven record carries no weight (k0 unknown)"}
    return {
        "offset_m": -x,
        "offset_se_m": _se([-p[0] for p in parts]),
        "method": "K(0) = m g: the frame in which a spline restoring force fitted to the record carries the "
        "weight at z = 0, between the wells",
    }


FRAME_SE_WARN_M = 2e-5
"""A frame standard error above this [m] is warned about: on the paper's cubic (k2 / 3 k3 = 0.5 mm) 20 um moves
k2 by 4 %."""

FRAME_PARTS = 4
"""Parts of the record (at most) whose separate frame estimates give the frame's standard error."""

FRAME_PART_MIN_S = 30.0
"""... each at least this long where the record allows (two parts at least): a 10 s part of a
cross-well record may visit one well only, and its frame estimate is then off by millimetres."""


def _parts(rec: Measurement, min_s: float, most: int) -> list[Measurement]:
    """The record cut into equal parts, at most ``most``, each at least ``min_s`` seconds where the record
    allows (two at least): the separate estimates whose spread gives a standard error (``_se``).
    """
    n_parts = int(np.clip(rec.duration // min_s, 2, most))
    edges = np.linspace(0, rec.n, n_parts + 1).astype(int)
    return [rec.segment(a, b) for a, b in zip(edges[:-1], edges[1:], strict=False)]


def _se(estimates: list[float]) -> float:
    """Standard error of the whole record's estimate from its parts' (NaN with fewer than two)."""
    if len(estimates) < 2:
        return float("nan")
    return float(np.std(estimates, ddof=1) / np.sqrt(len(estimates)))


SCALE_PARTS = 4
"""Parts of the record (at most) whose separate estimates give the scale's standard error."""

SCALE_PART_MIN_S = 20.0
"""... each at least this long where the record allows (two parts at least)."""


def _scale_of(rec: Measurement) -> float:
    """The response's scale from the input's coefficient the record's dynamics learn (over ``weak.stroke_library``:
    a spline restoring force, so that a device whose force is not a polynomial does not bias it).
    """
    c = input_coefficient(rec, library=stroke_library(rec))
    physical = known_input_gain(rec)
    assert physical is not None  # load refuses a force record of unknown scale without a mass
    if not np.isfinite(c) or c == 0:
        raise MeasurementError(f"{rec.source}: the record's dynamics give the input no weight: its response's scale "
                               "cannot be estimated (does the response follow the input?)")  # fmt: skip
    return physical / c


def _with_integral_warnings(resp: dict[str, Any], si: bool) -> dict[str, Any]:
    """``resp`` with its integral's warnings said anew from its numbers (SI millimetres, or the column's
    units as read when its scale is still unknown).
    """
    if "integrated_from" not in resp:
        return resp
    kept = [w for w in resp.get("warnings", []) if not w.startswith("z integrated from")]
    said = integral_warnings(resp) if si else integral_warnings(resp, "(units as read)", 1.0)
    return {**resp, "warnings": said + kept}


DRIFT_STEPS = 30
"""Gauss-Newton steps of the drift's physical refinement at most (each re-linearises the restoring force about the
last estimate; ``drift_by_physics``). A residual drift of several millimetres (wells 31 mm apart) took six steps
on the tests' 120 s absolute-vibrometer record, the last two quadratically convergent (measured)."""

DRIFT_CONVERGED = 1e-4
"""The refinement stops when a step moves the drift by less than this fraction of z's 5-95 % range."""

DRIFT_HALVINGS = 4
"""A step that makes the restoring force's fit worse is halved, at most this many times in a row (damped
Gauss-Newton)."""

DRIFT_KNOT_PERIODS = 10.0
"""The drift's knots are this many periods of the record's dominant frequency apart (a hat spans twenty: slow
beside the dynamics), at least ``DRIFT_KNOT_MIN_S`` and at most half the separation's corner period. What the
separation leaves lies just above its corner (a double integral's error most of all); measured on the tests'
records, z's error after knots every 10 / 5 / 2 / 1 s: 0.082 / 0.027 / 0.0087 / 0.0034 mm rms on the vibrometer's,
1.15 / 0.77 / 0.18 / 0.06 mm on an accelerometer's double integral."""

DRIFT_KNOT_MIN_S = 1.0


def _knots(t_end: float, spacing: float) -> np.ndarray:
    """Knots every ``spacing`` s (about) over [0, t_end], at least the two ends."""
    return np.linspace(0.0, t_end, max(2, int(round(t_end / spacing)) + 1))


def _hats(t: np.ndarray, knots: np.ndarray):
    """Piecewise-linear hat functions of time on ``knots``, evaluated at ``t`` (rows), as a sparse matrix (two entries
    a row) -- a partition of unity: their sum is one everywhere; ``_hats(t, knots) @ values`` is
    ``np.interp(t, knots, values)``. Sparse (``scipy.sparse``): a 396 s record's hats at 2048 Hz, dense, were 160,000
    rows by 258 columns (330 MB) for 320,000 nonzero entries.
    """
    from scipy import sparse

    i = np.clip(np.searchsorted(knots, t, side="right") - 1, 0, knots.size - 2)
    f = np.clip((t - knots[i]) / (knots[i + 1] - knots[i]), 0.0, 1.0)
    rows = np.repeat(np.arange(t.size), 2)
    return sparse.csr_matrix((np.column_stack([1.0 - f, f]).ravel(), (rows, np.column_stack([i, i + 1]).ravel())),
                             shape=(t.size, knots.size))  # fmt: skip


def _contrasts(H):
    """Hat functions less the last one (rows: times; k - 1 columns): coefficients on them are the values at the
    first k - 1 knots of a curve whose values at the knots sum to zero (the last is minus their sum). A drift's
    constant is no drift (it moves z's frame, which the frame's step pins) and, as d K'(z), it is almost the
    restoring force's own change of frame: left free, it would make the fit ill-conditioned. Sparse, as ``H``: only
    the last interval's rows are full.
    """
    from scipy import sparse

    last = H[:, -1:]
    return (H[:, :-1] - sparse.csr_matrix(last) @ sparse.csr_matrix(np.ones((1, H.shape[1] - 1)))).tocsr()


GRAM_MAX_CONDITION = 1e8
"""``_least_squares`` solves by the normal equations where their matrix's condition number is below this (the
solution's relative error then below ~1e-8), else by numpy's SVD route."""


def _least_squares(G: np.ndarray, b: np.ndarray, dense) -> np.ndarray:
    """The x minimising |A x - y| for a tall, column-scaled ``A`` given by its normal equations ``G`` = A^T A and
    ``b`` = A^T y: by their Cholesky factor (scipy) where they are well conditioned, else ``numpy.linalg.lstsq`` on
    ``dense()`` = (A, y), formed only then. The drift's step is a tall system (a 396 s record at 2048 Hz: 162,186 rows
    by 185 columns, condition number 34, measured) on which numpy's SVD route took 1.1 s a step and the Gram matrix
    with its Cholesky factor 0.2 s; the two agree to ~cond^2 eps (1e-13 there).
    """
    from scipy import linalg

    w = np.linalg.eigvalsh(G)
    if w[0] > 0.0 and w[-1] < GRAM_MAX_CONDITION * w[0]:
        return linalg.cho_solve(linalg.cho_factor(G, check_finite=False), b, check_finite=False)
    A, y = dense()
    return np.linalg.lstsq(A, y, rcond=None)[0]


def _drift_step(form: WeakForm, rec: Measurement, drift: np.ndarray, C, knots: np.ndarray) -> tuple[float, np.ndarray]:
    """One Gauss-Newton step of the drift (``drift_by_physics``) from ``drift`` [z's unit, per sample]: the relative
    residual of the restoring force's fit with the drift taken off (the spline over the stroke of z - d), and the
    step at the time knots ``knots``.

    The step's system is [W, C K'] (the force's columns and the drift's, ``C`` the sparse contrasts), solved by its
    normal equations assembled block by block, the drift's columns kept sparse: formed densely, each step built and
    scaled a 160,000 by 250 matrix (1.2 s of a 396 s record's 1.3 s step, measured).
    """
    from scipy import sparse

    library = stroke_library(rec, rec.z - drift)
    system = form.system(rec, library=library, drift=drift)
    assert library.shape is not None
    n_k = len(library.shape["spline"]["knots"]) + 2
    W, y = system.W_physical, system.y_physical
    phys = fit_support(system, None)
    r = y - W @ phys
    residual = float(r @ r / (y @ y))
    spline = phys[:n_k]  # z'' = B(z) a + ...: the restoring force per unit mass is -B(z) a
    zs = form.zs - drift
    slope = form.project((stroke_spline.slopes(zs, np.asarray(library.shape["spline"]["knots"])) @ spline)[:, None],
                         rec.dt)[:, 0]  # fmt: skip
    D = sparse.diags(slope) @ C  # the drift's columns: each knot's contrast times K'(z)
    n = W.shape[0]
    mean_d = np.asarray(D.sum(axis=0)).ravel() / n
    var_d = np.asarray(D.multiply(D).sum(axis=0)).ravel() / n - mean_d**2
    scale = np.concatenate([W.std(axis=0), np.sqrt(np.maximum(var_d, 0.0))])
    scale[scale == 0] = 1.0
    WtD = np.asarray((D.T @ W).T)
    G = np.block([[W.T @ W, WtD], [WtD.T, (D.T @ D).toarray()]]) / np.outer(scale, scale)
    b = np.concatenate([W.T @ y, D.T @ y]) / scale
    theta = _least_squares(G, b, lambda: (np.column_stack([W, D.toarray()]) / scale, y)) / scale
    gamma = theta[W.shape[1] :]  # z'' holds B(z - d) a ~ B(z) a - d B'(z) a: gamma = -d (at the knots)
    if not np.all(np.isfinite(gamma)):
        raise ValueError("the drift's step is not finite")
    step_knots = -np.append(gamma, -gamma.sum())
    return residual, np.interp(np.arange(rec.n) / rec.fs, knots, step_knots)  # the hats' sum, without their matrix


def drift_by_physics(rec: Measurement) -> Measurement:
    """``rec`` with what its integral's drift separation left of the drift removed by the record's physics.

    A drift d(t) left in z shifts the restoring force: the equation holds in z - d, so with the force fitted in z,
    K(z - d) ~ K(z) - d(t) K'(z). The record's weak form (``weak.WeakForm``) is fitted over the preparation's
    library (``weak.stroke_library``: a restoring force with no formula, a spline over the stroke, with viscous and
    quadratic damping; the input's coefficient learned, the response's scale may be unknown); K'(z) is taken from
    that spline and the fit repeated with a slowly varying coefficient of K'(z) (hat functions of time
    ``DRIFT_KNOT_PERIODS`` periods of the dominant frequency apart, their values summing to zero: ``_contrasts``)
    beside the fixed columns, which gives the step of d(t). Taking d off z (the weak form's states and target,
    ``WeakForm.system``'s ``drift``) and re-linearising is Gauss-Newton on the drift and the force together (Nocedal
    & Wright 2006, "Numerical Optimization", 10.3), repeated until a step moves d by less than ``DRIFT_CONVERGED``
    of z's range (``DRIFT_STEPS`` at most; a step that worsens the force's fit is halved, ``DRIFT_HALVINGS``).
    For a cubic the first step reads the z^2 coefficient's shift -3 k3 d(t) that a cubic's scheme read, with the
    z and constant terms' shifts of the same d; for a device whose force is not a polynomial, the polynomial's
    misfit is not taken for drift (a cubic's scheme moved the magnet harvester's in-well z by 1.35 mm that was not
    drift, measured). A bistable device is sensitive to this: 0.5 mm of drift in z moves its restoring force by
    K'(z) 0.5 mm, a quarter of the input's force on the tests' vibrometer record, where it turned NSI's well
    frequencies 30 % low and left SINDy without damping (measured).

    Applied only to a z integrated from a velocity whose drift was separated (``sensors.velocity_to_z``'s
    ``drift``); other records are returned as they are. What it moved is in ``info["response"]["drift"]``.
    """
    resp = rec.info.get("response", {})
    drift = resp.get("drift")
    if rec.z is None or not drift or "physics_span_m" in drift:
        return rec
    done = rec.derived.get("drift_by_physics")
    if done is not None:
        return done
    spacing = float(np.clip(DRIFT_KNOT_PERIODS / drift["dominant_hz"], DRIFT_KNOT_MIN_S, 0.5 / drift["cutoff_hz"]))
    q = np.quantile(rec.z, [0.05, 0.95])
    total, step = np.zeros(rec.n), np.zeros(rec.n)
    best, halvings, steps = float("inf"), 0, 0
    try:
        form = WeakForm.of(rec)
        rows = -(-(rec.n - 2 * form.centre(rec.dt)) // form.stride)  # the test functions' rows (``weak_project``)
        knots = _knots(rec.duration, spacing)
        C = _contrasts(_hats((form.centre(rec.dt) + form.stride * np.arange(rows)) / rec.fs, knots))
        for _ in range(DRIFT_STEPS):
            residual, new = _drift_step(form, rec, total, C, knots)
            if residual > best and halvings < DRIFT_HALVINGS:  # the last step made the force's fit worse: half of it
                step = 0.5 * step
                total = total - step
                halvings += 1
                continue
            best, halvings, steps = min(best, residual), 0, steps + 1
            step = new
            total = total + step
            if np.ptp(step) < DRIFT_CONVERGED * (q[1] - q[0]):
                break
    except (WeakFormError, np.linalg.LinAlgError, ValueError):
        return rec
    total -= total.mean()
    drift = {**drift, "physics_span_m": float(np.ptp(total)), "physics_rms_m": float(np.std(total)),
             "physics": f"then the restoring force's slow shift (-d(t) K'(z), K a spline over the stroke, knots "
             f"every {spacing:.3g} s) taken off: {steps} Gauss-Newton steps"}  # fmt: skip
    si = not (rec.info.get("scale") and rec.info["scale"].get("value") is None)
    resp = _with_integral_warnings({**resp, "drift": drift}, si)
    out = replace(rec, z=rec.z - total, info={**rec.info, "response": resp})
    rec.derived["drift_by_physics"] = out
    return out


def calibrate_scale(rec: Measurement) -> Measurement:
    """``rec`` with its response channel of unknown scale multiplied by the scale its dynamics say (the
    value, its standard error and how in ``info["scale"]``); ``rec`` itself when no scale is unknown or it
    was calibrated already. Raises ``MeasurementError`` when the record cannot say.
    """
    info = rec.info.get("scale")
    if not info or info.get("value") is not None:
        return rec
    done = rec.derived.get("calibrated")
    if done is not None:
        return done
    s = _scale_of(rec)
    parts = []
    for seg in _parts(rec, SCALE_PART_MIN_S, SCALE_PARTS):
        try:
            parts.append(_scale_of(seg))
        except (MeasurementError, ValueError, np.linalg.LinAlgError):
            continue
    se = _se(parts)
    channel = info["channel"]
    scaled = {k: getattr(rec, k) * s for k in ("z", "z_dot", "y") if getattr(rec, k) is not None}
    if rec.input_name == "base_acc" and "y" in scaled:  # not SCALABLE: load refuses it; kept out for safety
        scaled.pop("y")
    new_info = {
        **info,
        "value": float(s),
        "se": se,
        "parts": [float(p) for p in parts],
        "status": f"estimated: {channel} in SI = {channel} as read x {s:.6g} (+- {se:.2g}), from the input's "
        "coefficient in the record's own dynamics (physics fixes it); every coefficient is in SI units",
    }
    gain = (rec.info.get("response") or {}).get("gain")
    if gain:  # an absolute velocity of unknown gain: its gain was found at load; this scale is the point's share
        new_info["status"] = (f"estimated: z in SI = z as derived x {s:.6g} (+- {se:.2g}), the measured point's "
                              f"participation in the device's motion ({channel}'s gain was estimated at load: "
                              "info['response']['gain']), from the input's coefficient in the record's own dynamics; "
                              "every coefficient is in SI units")  # fmt: skip
    resp = dict(rec.info.get("response", {}))
    for k in ("velocity_noise_m_s", "integration_error_m", "trend_m_s", "trend_se_m_s"):
        if isinstance(resp.get(k), (int, float)):
            resp[k] = resp[k] * abs(s)
    if resp.get("drift"):
        resp["drift"] = {k: v * abs(s) if k.endswith("_m") else v for k, v in resp["drift"].items()}
    resp = _with_integral_warnings(resp, si=True)  # said in the column's units as read: now in SI
    out = replace(rec, **scaled, info={**rec.info, "scale": new_info, "response": resp})
    rec.derived["calibrated"] = out
    return out


def pin_frame(rec: Measurement) -> Measurement:
    """Put a derived z in the physical frame.

    A z integrated from a velocity (or derived from an accelerometer) has no known constant; the
    record's physics fix it (the fitted wells at the metadata's rest positions, else gravity: K(0) = m g,
    else, for a horizontal device, the midpoint between the wells). A response of unknown scale is
    calibrated first. Pinned once per record (the result is kept with it); every estimator calls it.

    Parameters
    ----------
    rec : Measurement
        The record.

    Returns
    -------
    Measurement
        ``rec`` with z in the physical frame when its constant was unknown, and the offset, its
        uncertainty and the anchor in ``info["response"]``; otherwise ``rec`` itself.

    Examples
    --------
    >>> from negstiff import Measurement, Rig, pin_frame
    >>> from negstiff.models.rig import Sensors
    >>> rec = Measurement.from_rig(Rig(seed=2, sensors=Sensors(response="velocity")).random(duration=60.0))
    >>> rec.info["response"]["z_constant_known"]
    False
    >>> pin_frame(rec).info["response"]["frame"][:52]
    'the fitted wells put at the rest positions of the fi'
    """
    rec = calibrate_scale(drift_by_physics(rec))  # the drift's remnant off, then a response of unknown scale
    # made SI (its frame is then in metres)
    resp = rec.info.get("response", {})
    if rec.z is None or resp.get("z_constant_known", True) or resp.get("frame") is not None:
        return rec
    pinned = rec.derived.get("pinned")
    if pinned is not None:
        return pinned
    fo = frame_offset(rec)
    resp = {**resp, "frame_offset_m": fo["offset_m"], "frame_offset_se_m": fo.get("offset_se_m"), "frame": fo["method"],
            **({"frame_asymmetry_m": fo["asymmetry_m"]} if "asymmetry_m" in fo else {})}  # fmt: skip
    se = fo.get("offset_se_m")
    se = 0.0 if se is None else se
    if fo["offset_m"] is not None and not np.isfinite(se):
        resp["warnings"] = [
            *resp.get("warnings", []),
            "z's frame uncertainty could not be estimated (no two "
            "parts of the record visit both wells); k2 and k1 inherit the frame's error "
            "(dk2 = 3 k3 dC)",
        ]
    elif fo["offset_m"] is None:
        resp["warnings"] = [
            *resp.get("warnings", []),
            f"z's frame is unknown ({fo['method']}); the coefficients k0-k2 are in the record's own frame",
        ]
    elif se > FRAME_SE_WARN_M:
        resp["warnings"] = [
            *resp.get("warnings", []),
            f"z's frame is uncertain: offset {1e3 * fo['offset_m']:.3f} "
            f"+- {1e3 * se:.3f} mm (the record visits one well little?); k2 and k1 inherit it "
            "(dk2 = 3 k3 dC)",
        ]
    z = rec.z if fo["offset_m"] is None else rec.z + fo["offset_m"]
    pinned = replace(rec, z=z, info={**rec.info, "response": resp})
    rec.derived["pinned"] = pinned
    return pinned
