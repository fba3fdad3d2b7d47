"""Size: each named effect's value in the model file's units and its interval, by a Laplace approximation of the
output error over the record's restarted windows.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from negstiff.errors import NotFittedError
from negstiff.inference.estimators.results import Identification
from negstiff.inference.record.measurement import Measurement
from negstiff.inference.steps.refine import parameter_names, parameter_scales, values_of, with_values
from negstiff.inference.steps.validation import RestartWindows, restart_windows
from negstiff.models import effects
from negstiff.models.structure import Structure

from ._candidates import _held, _size_of, law_of, law_parameters
from ._judging import Judging


class Intervals(Judging):
    """Each named effect's size and interval (a layer of ``Discrepancy``)."""

    def effect_size(self) -> dict[str, Any]:
        """The named effects' values in the model file's units (an effect that is a base field's term, such as
        ``quadratic_damping``, is read from its field: c_nl); a law's, its parameters in the final model (its base
        fields and its parts', ``PART.FIELD``; None where a later round replaced it).
        """
        out: dict[str, Any] = {}
        folds = {e.name: e.folds_into for e in effects.REGISTRY if e.folds_into}
        fields = self.model_.to_dict()
        for e in self.effects_:
            name = law_of(e)
            if name is not None:
                out[e] = law_parameters(self.model_, name) if name == self.law_ else None
                continue
            val = fields[folds[e]] if e in folds else self.model_.extra.get(e)
            out[e] = dict(val) if isinstance(val, dict) or hasattr(val, "keys") else val
        return out

    def _interval_windows(self, rec: Measurement, effect: str) -> tuple[RestartWindows, str]:
        """The windows an effect's interval is judged on, over the whole record as a posterior's data: runs of the
        record's predictable span (``_window_length``: ``window_s / 2`` at most) restarted one after the other,
        and one more before each episode where the effect acts (``_episodes``' windows, of the same length).
        """
        every = restart_windows(rec.n, rec.fs, self._window_length(rec) / rec.fs, min_step=8)
        starts = set(every.starts.tolist())
        force = self._effect_force(self.model_, effect, self._z0, self._v0)
        extra = 0
        if force is not None and np.any(np.abs(force) > 0):
            acting, episodes = self._episodes(rec, force, 0)
            if acting.mean() < 0.5:
                extra = len(set(episodes.starts.tolist()) - starts)
                starts |= set(episodes.starts.tolist())
        windows = self._after_pulses(rec, RestartWindows.at(sorted(starts), every.length))
        return windows, f"the record's windows, {extra} of them restarted where it acts"

    def effect_interval(self, data, prob: float = 0.9) -> dict[str, Any]:
        """Each named effect's size with its interval (probability ``prob``) on ``data`` (a ``Measurement`` or a path:
        the record this estimator was fitted on), read as the fit read it (``record_kind_``: a hammer's force
        windowed, a free decay's input zero; its windows ``window_s_`` long): ``_effect_interval``.
        """
        if not self.fitted:
            raise NotFittedError(f"this {type(self).__name__} is not fitted yet (effect_interval reads its fit): call "
                                 "fit first")  # fmt: skip
        from negstiff.inference.analysis.record_kind import identification_record

        rec = self.check(data)
        kind = vars(self).get("record_kind_")
        return self._effect_interval(rec if kind is None else identification_record(rec, kind), prob)

    def _effect_interval(self, rec: Measurement, prob: float = 0.9) -> dict[str, Any]:
        """Each named effect's size with its interval (probability ``prob``), by a Laplace approximation of the
        output error over the record's restarted windows (``_interval_windows``: runs of the record's predictable
        span, ``predictability_``, one after the other, and one more before each episode where the effect acts),
        every refined parameter free (``refine.parameter_names``). A run longer than the span would pass chaos's
        amplification in its linearisation off as information (an end stop's onset over 1 s windows: 25.943-25.982
        mm for a 26 mm truth, three windows of 88 holding 56 % of the true model's squared error; over 0.594 s
        windows 25.749-26.176 mm, measured).
        The posterior under a flat prior is taken Gaussian, its covariance the Gauss-Newton inverse Hessian made
        robust over windows (a sandwich with each window one cluster: the samples of a run are correlated, so the
        windows, not the samples, are the independent units); the effect's marginal is kept, widened by the
        distance between the reported value and these windows' mode (one Gauss-Newton step), and centred on the
        reported value. ``Posterior`` does not sample ``extra`` effects, hence this approximation. Also fills
        ``bayesian_`` (``_bayesian_opinion``) for each effect with an interval.
        """
        from scipy import stats

        zq = float(stats.norm.ppf(0.5 + prob / 2))
        out: dict[str, Any] = {}
        self.bayesian_: dict[str, Any] = {}
        for e in self.effects_:
            if law_of(e) is not None:
                out[e] = {"value": self.effect_size()[e], "interval": None, "prob": prob,
                          "method": "not available for a law: it replaces the restoring force, whose parameters "
                          "this approximation of an effect's size does not sample"}  # fmt: skip
                continue
            value = _size_of(self.model_, e)
            keys = sorted(value) if isinstance(value, dict) else [None]
            if value is None or effects.get(e).law.label is None and not isinstance(value, dict):
                out[e] = {"value": value, "interval": None, "prob": prob, "method": "not available for this effect"}
                continue
            windows, where = self._interval_windows(rec, e)
            length = windows.length
            names = parameter_names(self.model_, False, held=_held(self.terms_))
            mine = [f"{e}.{k}" if k is not None else e for k in keys]
            if len(windows) < 3 or not set(mine) <= set(names):
                out[e] = {"value": value, "interval": None, "prob": prob, "method": "not available for this effect"}
                continue
            theta = values_of(self.model_, names)
            scales = parameter_scales(self.model_, names, float(np.std(self._z0)), float(np.std(self._v0)))
            steps = 1e-3 * np.maximum(np.abs(theta), np.abs(scales))

            def residuals(th: np.ndarray, names=names, windows=windows) -> np.ndarray:
                return self._residuals_at(with_values(self.model_, names, th), rec, windows)

            r0 = residuals(theta)
            J = np.stack([(residuals(theta + np.eye(theta.size)[j] * steps[j]) - r0) / steps[j]
                          for j in range(theta.size)], axis=-1)  # fmt: skip  # (windows, samples, parameters)
            ok = np.isfinite(r0).all(axis=1) & np.isfinite(J).all(axis=(1, 2))
            r0, J = r0[ok], J[ok]
            n_w, p = r0.shape[0], theta.size
            if n_w <= p + 1:
                out[e] = {"value": value, "interval": None, "prob": prob, "method": "too few windows ran"}
                continue
            H = np.einsum("wsi,wsj->ij", J, J)
            g = np.einsum("wsi,ws->wi", J, r0)  # each window's score
            # inverted in the parameters' own scales: in SI units H spans 17 decades (k0 in N against a stop's onset
            # in m and its k in N/m), and pinv's cut-off then drops its least determined direction, the stop's k
            # traded against its onset and the cubic: the interval came out 100x too narrow (measured: k's standard
            # error 0.40 N/m against 49 N/m with the scales, H's condition number 2.8e16 against 7.7e6)
            Hi = scales[:, None] * np.linalg.pinv(scales[:, None] * H * scales[None, :]) * scales[None, :]
            cov_all = Hi @ (g.T @ g) @ Hi * n_w / (n_w - p)
            at = [names.index(n) for n in mine]
            cov = cov_all[np.ix_(at, at)]
            # the mode on these windows by one Gauss-Newton step from the final model (refined on the identification
            # part alone): where the two differ by more than the noise's scatter, the estimate carries an error the
            # noise does not explain (restart states, the form's misfit), so that difference joins the standard
            # error in quadrature and the interval stays centred on the reported value (measured: the mode alone
            # moved friction 1.6 % away from the truth on one record and the stop's k 0.06 % towards it on another)
            mode = (theta - Hi @ g.sum(axis=0))[at]
            theta = theta[at]
            se = np.sqrt(np.maximum(np.diag(cov), 0.0) + (mode - theta) ** 2)
            cov = cov + np.diag((mode - theta) ** 2)
            method = (f"Laplace approximation of the output error over {n_w} restarted windows "
                      f"({length / rec.fs:g} s; {where}), every parameter free, window-robust covariance, the "
                      "difference between the reported value and these windows' mode added in quadrature; "
                      "Posterior does not sample extra effects")  # fmt: skip
            model_value = [float(value[k]) if k is not None else float(value) for k in keys]
            parts = {(k if k is not None else "value"): {"value": m_, "windows_mode": float(t),
                                                         "standard_error": float(s_),
                                                         "interval": [float(m_ - zq * s_), float(m_ + zq * s_)]}
                     for k, t, m_, s_ in zip(keys, mode, model_value, se, strict=True)}  # fmt: skip
            if keys[0] is None:
                out[e] = {**parts["value"], "prob": prob, "method": method}
            else:
                out[e] = {**parts, "prob": prob, "method": method}
            ran = RestartWindows.at(windows.starts[ok], length)
            self.bayesian_[e] = self._bayesian_opinion(rec, e, ran, theta, cov, keys, where)
        return out


# --- a structure's -------------------------------------------------------------------------------------------------
def effect_intervals(result: Identification, named: list[str], prob: float = 0.9) -> dict[str, Any]:
    """Each named effect's value with its interval (probability ``prob``): the refinement's window-robust standard
    error of the effect's coefficient (``refine._standard_errors``, the structure's other parameters and the
    channels' zeros free), a Gaussian interval about the refined value; None without a kept refinement (the weak
    form's value stands alone). Conditional on the model's form, as the single DOF's Laplace interval is.
    """
    from scipy import stats

    zq = float(stats.norm.ppf(0.5 + prob / 2))
    account: dict[str, Any] = dict(result.refinement or {})
    se_all = account.get("standard_errors") or {}
    out: dict[str, Any] = {}
    structure = result.system
    assert isinstance(structure, Structure)  # the discrepancy workflow reads a structure with its masses
    for e in named:
        value = structure.element.extra.get(e)
        se = se_all.get(e)
        if not account.get("applied") or se is None or not isinstance(value, (int, float)) or not math.isfinite(se):
            out[e] = {"value": value, "interval": None, "prob": prob,
                      "method": "not available: no refinement kept, or the effect is not one coefficient"}  # fmt: skip
            continue
        out[e] = {"value": float(value), "standard_error": float(se),
                  "interval": [float(value - zq * se), float(value + zq * se)], "prob": prob,
                  "method": "the output-error refinement's window-robust standard error (its last stage's restarted "
                            "windows, every parameter and the channels' zeros free), a Gaussian interval"}  # fmt: skip
    return out
