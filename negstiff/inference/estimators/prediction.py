"""What a fitted model says about a record: restarted free runs (``predict``), their score (``score``), a free
simulation under any input (``simulate``) and the equation it learned (``equations``, ``print``), the same
for every estimator whose fit learns a model (``model_``: NSI, SINDy, Discrepancy, the posterior's mean).

The score is the **median window's** error: the record is cut into ``window_s`` windows (2 s by default,
the held-out validation's), each simulated from the record's measured state at its start (the smoothed z
and z' every free run of negstiff starts from, ``Measurement.states("state")``) under the measured input;
each window's rms error is taken as a share of the scored part's rms z, and the median over the windows is
the score [%]. In cross-well chaos a model within a few ppm of the truth still loses a window now and then
to a switch of wells its start state's error decided (a pooled rms over six 2 s windows moved 50x for one
such window, measured): the median is moved by one such window no more than by one window's rank, and
the spread (quartiles, the worst window) is reported beside it, never hidden.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np

from negstiff.errors import InputError

SCORE_METRIC = (
    "median over restarted free-run windows of the window's rms error, % of the scored part's rms z "
    "(windows restarted from the record's measured states)"
)
"""What ``score`` and the held-out headline (``validation.median_window_percent``) measure, in words."""


def window_errors(window_ms: np.ndarray, z: np.ndarray) -> dict[str, Any]:
    """The median window's error and the spread over the windows: ``window_ms`` each window's mean square
    error (NaN: the run diverged), ``z`` the scored part's measured displacement. Percent of rms z; a
    diverged window counts as the worst (it ranks above every finite one).
    """
    ms = np.asarray(window_ms, float)
    if ms.size == 0:
        return {}
    scale = float(np.sqrt(np.mean(np.asarray(z, float) ** 2)))
    pct = np.where(np.isfinite(ms), 100 * np.sqrt(np.where(np.isfinite(ms), ms, 0.0)) / scale, np.inf)
    q = np.percentile(np.where(np.isfinite(pct), pct, np.finfo(float).max), [25, 50, 75])
    q = np.where(q >= np.finfo(float).max, np.inf, q)
    return {
        "median_window_percent": float(q[1]),
        "window_percent_quartiles": [float(q[0]), float(q[2])],
        "worst_window_percent": float(np.max(pct)),
        "best_window_percent": float(np.min(pct)),
        "windows_scored": int(ms.size),
        "windows_diverged": int((~np.isfinite(ms)).sum()),
        "score_metric": SCORE_METRIC,
    }


@dataclass(frozen=True)
class Prediction:
    """A model's restarted free runs over a record (``predict``).

    Attributes
    ----------
    t : numpy.ndarray
        Time of each predicted sample [s], (windows, samples per window), from the record's start.
    z : numpy.ndarray
        The predicted z [m], same shape (NaN after a run diverged); a structure's, (windows, channels, samples):
        its channels' z, or a state-space model's outputs (the sensors' displacements or accelerations).
    measured : numpy.ndarray
        The record's z (a structure's channels or outputs) over the same samples.
    starts : numpy.ndarray
        Each window's first sample in the record.
    window_s : float
        Window length [s].
    score_percent : float
        The median window's rms error, % of rms z (``SCORE_METRIC``).
    errors : dict
        ``window_errors``: the median, quartiles, best and worst window, windows diverged.
    """

    t: np.ndarray
    z: np.ndarray
    measured: np.ndarray
    starts: np.ndarray
    window_s: float
    score_percent: float
    errors: dict[str, Any] = field(default_factory=dict)
    metric: str = SCORE_METRIC


def as_record(data, who: str):
    """A ``Measurement`` of ``data`` (a record or a file path), in the physical frame (``frame.pin_frame``)."""
    from negstiff.inference.record.measurement import Measurement
    from negstiff.inference.record.reading import load
    from negstiff.inference.steps.frame import pin_frame

    if isinstance(data, (str, PathLike)):
        data = load(Path(data))
    if not isinstance(data, Measurement):
        raise InputError(f"{who} takes a Measurement or a file path, got {type(data).__name__}")
    return pin_frame(data)


def restarted_runs(model, rec, window_s: float, start: int = 0) -> Prediction:
    """Free runs of ``window_s`` over [start, N) of ``rec``, each restarted from the record's measured state
    (the one cutting of restarted windows, ``validation.restart_windows``, run by ``simulate_windows``), and
    their score.
    """
    from negstiff.inference.steps.validation import restart_windows, simulate_windows

    windows = restart_windows(rec.n, rec.fs, window_s, start=start)
    if windows.length < 2 or len(windows) < 1:
        raise InputError(f"{rec.source}: shorter than one {window_s:g} s window after sample {start}")
    zs, v, _, _ = rec.states("state")
    res = simulate_windows(model, rec, windows, zs, v)
    starts, w, n_win = windows.starts, windows.length, len(windows)
    meas = rec.displacement[windows.index]
    z = np.array(res.z, float)
    z[res.diverged] = np.nan
    ms = np.full(n_win, np.nan)
    ok = ~res.diverged
    ms[ok] = np.mean((z[ok] - meas[ok]) ** 2, axis=1)
    errors = window_errors(ms, meas)
    t = (starts[:, None] + np.arange(w)[None, :]) / rec.fs
    return Prediction(t=t, z=z, measured=meas, starts=starts, window_s=float(window_s),
                      score_percent=errors["median_window_percent"], errors=errors)  # fmt: skip


def structure_runs(structure, rec, window_s: float, offsets=None) -> Prediction:
    """A structure's restarted free runs over ``rec`` (``predict``): windows of ``window_s``, each from the
    record's band-smoothed state of every channel at its start (``validation.structure_windows``, the held-out
    validation's runs), the channels ``offsets`` [m] above the structure's frame; each window's error as a share of
    the channels' rms about their means.
    """
    from negstiff.inference.steps.validation import channel_scales, structure_window_errors, structure_windows

    if rec.n_dof != structure.n_dof:
        raise InputError(f"{rec.source}: {rec.n_dof} channel(s), the structure {structure.n_dof} DOFs")
    windows, zs, v = structure_windows(rec, structure.place, 0, window_s)
    err, diverged = structure_window_errors([structure], rec, windows, zs, v, offsets)
    measured = windows.measured(rec.channels)
    z = err[0] + measured
    z[diverged[0]] = np.nan
    scale = channel_scales(rec, 0)
    ms = np.where(diverged[0], np.nan, np.mean((err[0] / scale[None, :, None]) ** 2, axis=(1, 2)))
    metric = (
        "median over restarted free-run windows of the window's rms error over every channel, % of each "
        "channel's rms about its mean (windows restarted from the record's measured states)"
    )
    errors = {**window_errors(ms, np.ones(1)), "score_metric": metric}  # the errors already shares of each rms
    t = (windows.starts[:, None] + np.arange(windows.length)[None, :]) / rec.fs
    return Prediction(t=t, z=z, measured=measured, starts=windows.starts, window_s=float(window_s),
                      score_percent=errors["median_window_percent"], errors=errors, metric=metric)  # fmt: skip


def state_space_runs(model, rec, window_s: float) -> Prediction:
    """The model's restarted free runs over ``rec`` (``predict``): windows of ``window_s`` (at least four times
    its order in samples), each from the state the model reads off the window before it, the record read as the
    identification read its own (``model.cut_hz``, its rate decimated to the model's). Another record of the
    same structure (another level, a validation record) is read so: the benchmarks' way of judging a model.
    """
    from negstiff.inference.estimators.nsi._state_space import Sampling, read_record, window_plan, window_run

    q = rec.fs * model.dt
    if model.cut_hz is None or rec.input_name != "force" or rec.n_dof != model.n_sensors or not (
            round(q) >= 1 and abs(q - round(q)) < 1e-6):  # fmt: skip
        raise InputError(
            f"{rec.source}: a structure's state-space model predicts a record of its own kind: a measured force, "
            f"{model.n_sensors} sensors, a rate that decimates to its {1 / model.dt:.6g} Hz"
            + ("" if model.cut_hz is not None else " (and a model that keeps its band: identify it again)")
            + f"; this record: {rec.input_name}, {rec.n_dof} sensors, {rec.fs:.6g} Hz"
        )
    sampling = Sampling(model.output, rec.fs, model.cut_hz, int(round(q)))
    u, y, r, vr = read_record(rec, model.at, sampling)
    n_win, plan = window_plan(model, u.size, rec.fs / sampling.q, window_s)
    starts = np.array(plan, dtype=int)
    if not starts.size:
        raise InputError(f"{rec.source}: shorter than two windows of {n_win * sampling.q / rec.fs:.3g} s (the first "
                         "is the stretch the start state is read from)")  # fmt: skip
    runs = [window_run(model, True, u, y, r, vr, int(s0), n_win) for s0 in starts]
    z = np.array([run for run, _ in runs])
    measured = np.array([y[:, s0 : s0 + n_win] for s0 in starts])
    gone = np.array([g for _, g in runs])
    centred = measured - y.mean(axis=1)[None, :, None]
    ms = np.where(gone, np.nan, np.nanmean((z - measured) ** 2, axis=(1, 2)))
    metric = (f"median over restarted free-run windows of the window's rms error, % of the rms of the model's "
              f"outputs (the sensors' {model.output}s)")  # fmt: skip
    errors = {**window_errors(ms, centred), "score_metric": metric}
    t = (starts[:, None] + np.arange(n_win)[None, :]) * sampling.q / rec.fs
    return Prediction(t=t, z=z, measured=measured, starts=starts * sampling.q, window_s=n_win * sampling.q / rec.fs,
                      score_percent=errors["median_window_percent"], errors=errors, metric=metric)  # fmt: skip


def _term(coef: float, name: str, digits: int) -> str:
    sign = "-" if coef < 0 else "+"
    return f" {sign} {abs(coef):.{digits}g}{' ' + name if name else ''}"


def equation_of(model, digits: int = 4, input_name: str = "base_acc") -> str:
    """The equation of motion of ``model`` with its numbers (the contract's form, SI units):
    ``m z'' + c z' + c_nl z'|z'| + k3 z^3 + k2 z^2 - k1 z + k0 + extra = -m base_acc`` (or ``= force``).
    A ``Device``: its geometric restoring force named with its E and alpha.
    """
    m = float(model.m)
    restoring, damping, extra = _law_terms(model, "z", digits)
    lhs = f"{m:.{digits}g} z''" + damping + restoring + extra
    rhs = f"-{m:.{digits}g} base_acc" if input_name == "base_acc" else "force"
    return f"{lhs.replace('+ -', '- ')} = {rhs}"


def _law_terms(model, x: str, digits: int) -> tuple[str, str, str]:
    """The terms of ``model``'s law in the variable ``x`` (z, or an element's r): its restoring force (k3 x^3 + k2 x^2
    - k1 x + k0, or a ``Device``'s geometric force named with its E and alpha), its damping (c x' + c_nl x'|x'|) and
    its extra effects, each string starting with its sign.
    """
    if getattr(model, "kind", "") == "device":
        restoring = f" + K_device({x}; E={model.E:.{digits}g} Pa, alpha={model.alpha_deg:.{digits}g} deg)"
    else:
        restoring = (_term(model.k3, f"{x}^3", digits) + _term(model.k2, f"{x}^2", digits)
                     + _term(-model.k1, x, digits) + _term(model.k0, "", digits))  # fmt: skip
    damping = _term(model.c, f"{x}'", digits) + _term(model.c_nl, f"{x}'|{x}'|", digits)
    extra = "".join(f" + {name}({value if not isinstance(value, float) else f'{value:.{digits}g}'})"
                    for name, value in dict(getattr(model, "extra", {}) or {}).items())  # fmt: skip
    return restoring, damping, extra


def structure_equations(structure, digits: int = 4, input_name: str = "base_acc",
                        force_dof: int | None = None) -> list[str]:  # fmt: skip
    """A structure's equations of motion, one line per DOF (``m_i z_i'' + sum_j C_ij z_j' + sum_j K_ij z_j +- g =
    input``, the element's force g on J and, opposite, on I), and g's law of r = z_J - z_I (the single DOF's form,
    ``equation_of``); a force acts on ``force_dof`` (default: the element's J).
    """
    i_el, j_el = structure.place
    out = []
    for i in range(structure.n_dof):
        terms = [f"{structure.masses[i]:.{digits}g} z{i + 1}''"]
        terms += [_term(float(c), f"z{j + 1}'", digits) for j, c in enumerate(structure.C[i]) if c]
        terms += [_term(float(k), f"z{j + 1}", digits) for j, k in enumerate(structure.K[i]) if k]
        if i + 1 == j_el:
            terms.append(" + g")
        elif i + 1 == i_el:
            terms.append(" - g")
        if input_name == "base_acc":
            rhs = f"-{structure.masses[i]:.{digits}g} base_acc"
        else:
            rhs = "force" if i + 1 == (force_dof or j_el) else "0"
        out.append(f"{terms[0]}{''.join(terms[1:])} = {rhs}".replace("+ -", "- "))
    r = f"z{j_el}" + (f" - z{i_el}" if i_el else "")
    restoring, damping, extra = _law_terms(structure.element, "r", digits)
    out.append(f"g = {(restoring + damping).strip().removeprefix('+ ')}{extra}, r = {r}")
    return out


class ModelPredictions:
    """``predict``, ``score``, ``simulate``, ``equations`` and ``print`` of a fitted ``model_`` (module
    docstring); mixed into every estimator (``base.Estimator``).
    """

    def _structure(self):
        """The structure a fit on a structure's record learned (``structure_``: NSI's, SINDy's, the discrepancy
        workflow's, the posterior mean's) and each channel's zero (``offsets_``), or (None, None).
        """
        if getattr(vars(self).get("result_"), "linear_part", "physical") != "physical":
            # the device on its base runs as its model (``restarted_runs``), a state-space model from the state it
            # reads off each window (``state_space_runs``)
            return None, None
        try:
            structure = self.structure_
        except AttributeError:  # not fitted (NotFittedError), or a posterior of the device's coefficients
            return None, None
        if structure is None:
            return None, None
        try:
            offsets = self.offsets_
        except AttributeError:
            offsets = None
        return structure, offsets

    def predict(self, record, window_s: float = 2.0) -> Prediction:
        """Restarted free runs of the fitted model over ``record`` (a ``Measurement`` or a path): the record
        cut into ``window_s`` windows, each simulated from the record's measured state at its start under
        its measured input.

        Returns
        -------
        Prediction
            The predicted z per window, the measured z beside it, and the score (``SCORE_METRIC``).
        """
        if not (isinstance(window_s, (int, float)) and math.isfinite(window_s) and window_s > 0):
            raise InputError(f"predict(window_s={window_s!r}): a window is a positive number of seconds")
        rec = as_record(record, f"{type(self).__name__}.predict")
        # the whole model the fit learned: a structure's (its element's ``model_`` is a part of it), else ``model_``
        structure, offsets = self._structure()
        if structure is not None:
            return structure_runs(structure, rec, float(window_s), offsets)
        model = self.model_  # type: ignore[attr-defined]
        if hasattr(model, "initial_state"):  # a structure read through its sensors (``StateSpaceStructure``)
            return state_space_runs(model, rec, float(window_s))
        return restarted_runs(model, rec, float(window_s))

    def score(self, record, window_s: float = 2.0) -> float:
        """The fitted model's score on ``record`` [%]: the median over ``window_s`` restarted free-run windows
        of each window's rms error as a share of rms z (``SCORE_METRIC``; lower is better, the record's noise
        sets its floor). ``predict(record).errors`` holds the spread.
        """
        return self.predict(record, window_s).score_percent

    def simulate(self, input, fs: float | None = None, *, z0: float | None = None, v0: float | None = None,
                 input_kind: str | None = None):  # fmt: skip
        """The fitted model's free run under ``input``: a ``Measurement`` (its input column; starting from its
        measured state at the first sample unless ``z0``/``v0`` are given, as ``negstiff simulate``) or an
        array sampled at ``fs`` [Hz] (starting at rest in the plus well unless ``z0`` is given).

        Returns
        -------
        negstiff.models.simulator.SimulationResult
            The simulator's result (``z``, ``v``, ``diverged``, ...).
        """
        from negstiff.inference.record.measurement import Measurement
        from negstiff.models.simulator import simulate

        structure, offsets = self._structure()
        model = self.model_  # type: ignore[attr-defined]
        if hasattr(model, "initial_state"):  # a state-space model reads its start state off a record's stretch
            raise InputError(
                f"{type(self).__name__}.simulate: a structure read through its sensors (a state-space "
                "model) starts from the state it reads off a measured stretch; predict(record) runs it"
            )
        if structure is not None and isinstance(input, (Measurement, str, PathLike)):
            # the whole structure, from every channel's measured state at the first sample (the fit's channel zeros):
            # each channel's least-error state, as a single DOF's and the held-out windows' (``free_run_states``). From
            # the band-smoothed states a fit of the tests' fixture record missed the first 0.25 s of 0.5 s records by
            # 1.1 mm at the median of 40 starts (an edge's smoothed velocity), from these by 15 um (measured)
            from negstiff.models.structure import simulate_structures

            rec = as_record(input, f"{type(self).__name__}.simulate")
            zs, vs = rec.free_run_states()
            o = np.zeros(rec.n_dof) if offsets is None else np.array(offsets, dtype=float)
            x0 = np.concatenate([zs[:, 0] - o, vs[:, 0]])[None]
            return simulate_structures(structure, rec.u[None], rec.dt, x0, input_kind=input_kind or rec.input_name,
                                       force_dof=rec.force_dof, store_velocity=True)  # fmt: skip
        if structure is not None:
            model = structure  # from rest, the element's relative displacement at z0 (``simulator.simulate``)
        if isinstance(input, (Measurement, str, PathLike)):
            rec = as_record(input, f"{type(self).__name__}.simulate")
            if z0 is None and rec.z is not None:
                zs, vs = rec.free_run_states()
                z0, v0 = float(zs[0, 0]), float(vs[0, 0]) if v0 is None else v0
            return simulate(model, rec.u, rec.dt, z0=z0, v0=v0 or 0.0, input_kind=input_kind or rec.input_name)
        u = np.asarray(input, float)
        if fs is None or not fs > 0 or u.ndim != 1 or not np.all(np.isfinite(u)):
            raise InputError("simulate takes a Measurement, or a finite 1-D input array with its rate fs > 0 [Hz]")
        return simulate(model, u, 1.0 / fs, z0=z0, v0=v0 or 0.0, input_kind=input_kind or "base_acc")

    def equations(self, digits: int = 4) -> list[str]:
        """The fitted equation of motion, one line per DOF (pysindy's ``equations``): numbers to ``digits``
        significant figures, SI units, the contract's signs (``equation_of``).
        """
        settings = getattr(self.__dict__.get("result_"), "settings", None) or {}
        structure, _ = self._structure()
        if structure is not None:  # a structure's: one line per DOF and its element's law
            return structure_equations(structure, digits, settings.get("input", "base_acc"), settings.get("force_dof"))
        input_name = settings.get("input", "base_acc")
        return [equation_of(self.model_, digits, input_name)]  # type: ignore[attr-defined]

    def print(self, digits: int = 4) -> None:
        """Print ``equations`` (pysindy's ``print``)."""
        for line in self.equations(digits):
            print(line)
