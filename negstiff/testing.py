"""Assertions for the consistency checks users write in pytest, with tolerances taken from the estimates'
own uncertainty, not picked by hand (after ``numpy.testing``). Each raises ``AssertionError`` with a
message that says what was compared, the numbers and the tolerance.

* ``assert_covers(posterior, k1=..., ...)``: the posterior's credible interval holds each value (a truth,
  or another method's estimate);
* ``assert_agree(a, b, sd_a, sd_b, k=3)``: two estimates agree within k combined standard errors;
* ``well_frequencies(posterior)``: each well's underlying-linear frequency over the posterior's draws
  (mean, sd): the uncertainty an identification's well frequency is judged against;
* ``assert_wells_agree(identification, posterior, k=3)``: an identification's own well frequencies lie
  within k posterior standard deviations of the posterior's (the record's own uncertainty);
* ``assert_methods_agree(a, b, record, k=3)``: two methods' own estimates of each well's frequency (NSI's
  subspace pole, SINDy's equation-error model: never their refined models, which reach the same
  output-error optimum) agree within k of their combined standard errors (``Identifier.own_estimate``:
  batch means over blocks of the record);
* ``assert_predicts(model, record, reference, factor=2)``: the model's short free runs restarted from the
  record's measured states follow it within ``factor`` times a reference model's error (the truth, or the
  best model at hand: the floor a record's noise sets is measured, not assumed).

Example (a pytest consistency check of a lab's record; ``tests/contract/test_testing.py`` runs it)::

    from negstiff import Posterior, SINDy, load
    from negstiff.testing import assert_predicts, assert_wells_agree

    def test_the_identified_model_is_consistent():
        rec = load("lab.csv", mass=0.212)
        sindy = SINDy().fit(rec)
        post = Posterior(seed=1).fit(rec)
        assert_wells_agree(sindy.result_, post, k=3)     # SINDy's wells within 3 posterior sd
        assert_predicts(sindy.model_, rec, reference=my_model, factor=2)   # as well as my own model, nearly
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

__all__ = ["assert_agree", "assert_covers", "assert_methods_agree", "assert_predicts", "assert_wells_agree",
           "cached_fit", "well_frequencies"]  # fmt: skip


def cached_fit(estimator, record, cache):
    """``estimator`` fitted on ``record``, from the folder ``cache`` when a fit of the same estimator class,
    parameters, record (its input, response, rate and mass) and negstiff version is there (a pickle), else
    fitted and kept there: a pytest file that checks facts about slow fits pays for them once, not every
    session (``cache``: e.g. ``request.config.cache.mkdir("negstiff-fits")``). A pickle is read only from a
    folder of your own; one that no longer loads (kept by an older negstiff, or cut short) is refitted and replaced.
    """
    import hashlib
    import json
    import pickle
    from pathlib import Path

    import negstiff
    from negstiff.files import atomic_path
    from negstiff.inference.estimators.persistence import encode_param

    h = hashlib.sha256()
    params = {k: encode_param(v) for k, v in estimator.get_params(deep=False).items()}
    h.update(json.dumps([type(estimator).__qualname__, params, negstiff.__version__], sort_keys=True,
                        default=str).encode())  # fmt: skip
    for a in (record.u, record.z):
        if a is not None:
            h.update(np.ascontiguousarray(a, float).tobytes())
    h.update(repr((float(record.fs), record.mass, record.input_name)).encode())
    path = Path(cache) / f"{type(estimator).__name__}-{h.hexdigest()[:24]}.pkl"
    if path.is_file():
        try:
            return pickle.loads(path.read_bytes())
        except Exception:  # noqa: BLE001 - a stale entry (a class moved since it was kept) or a broken one is refitted
            pass
    fitted = estimator.fit(record)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        Path(tmp).write_bytes(pickle.dumps(fitted))
    return fitted


def _summary(posterior) -> Mapping[str, Mapping[str, float]]:
    """The parameter summaries of a fitted ``Posterior``, a ``PosteriorResult``, or a posterior result JSON
    (a dict, its text or a path).
    """
    if isinstance(posterior, (Mapping, str)) or hasattr(posterior, "__fspath__"):
        d = _json(posterior)
        if "parameters" not in d:
            raise AssertionError(f"not a posterior result JSON: no 'parameters' (keys: {', '.join(sorted(d))})")
        return d["parameters"]
    if hasattr(posterior, "summary") and hasattr(posterior, "names"):
        return posterior.summary
    return posterior.result()["parameters"]


def _json(data) -> dict[str, Any]:
    from negstiff.inference.estimators.persistence import json_source

    return json_source(data)


def _model(model):
    """A ``Model`` of a ``Model``, a model file's dict, an identify result JSON (its ``model``), or a fitted
    estimator (its ``model_``).
    """
    from negstiff.models import Model

    if isinstance(model, Model) or getattr(model, "kind", None) == "device":
        return model
    if isinstance(model, (Mapping, str)) or hasattr(model, "__fspath__"):
        d = _json(model)
        return Model.from_dict(d["model"] if isinstance(d.get("model"), Mapping) else d)
    if hasattr(model, "model_"):
        return model.model_
    if hasattr(model, "model"):
        return model.model
    raise AssertionError(f"not a model: a {type(model).__name__}")


def assert_covers(posterior, **values: float) -> None:
    """Assert that the posterior's credible interval (``hdi_low``, ``hdi_high``) holds each value."""
    summary = _summary(posterior)
    missed = []
    for name, value in values.items():
        if name not in summary:
            raise AssertionError(f"the posterior has no parameter {name!r} (it has {', '.join(summary)})")
        s = summary[name]
        if not s["hdi_low"] <= value <= s["hdi_high"]:
            missed.append(f"{name} = {value:.6g} outside [{s['hdi_low']:.6g}, {s['hdi_high']:.6g}] "
                          f"(mean {s['mean']:.6g}, sd {s['sd']:.3g})")  # fmt: skip
    if missed:
        raise AssertionError("the posterior's credible interval does not hold: " + "; ".join(missed))


def assert_agree(
    a: float, b: float, sd_a: float, sd_b: float = 0.0, k: float = 3.0, what: str = "the estimates"
) -> None:
    """Assert ``|a - b| <= k sqrt(sd_a^2 + sd_b^2)``: two estimates agree within ``k`` combined standard errors."""
    tol = k * math.hypot(sd_a, sd_b)
    if not (math.isfinite(a) and math.isfinite(b) and abs(a - b) <= tol):
        z = abs(a - b) / math.hypot(sd_a, sd_b) if math.hypot(sd_a, sd_b) > 0 else math.inf
        raise AssertionError(
            f"{what} disagree: {a:.6g} and {b:.6g} differ by {abs(a - b):.3g}, {z:.2f} combined standard errors "
            f"(sd {sd_a:.3g} and {sd_b:.3g}); allowed {k:g}"
        )


def well_frequencies(posterior, draws: int = 400, seed: int = 0) -> dict[str, tuple[float, float]]:
    """Each well's underlying-linear frequency [Hz] over ``draws`` of a fitted coefficient ``Posterior``:
    ``{well: (mean, sd)}`` for the wells every draw has (the draws' models, with the record's mass).
    """
    from negstiff.models import Model

    rng = np.random.default_rng(seed)
    res = getattr(posterior, "result_", posterior)
    if isinstance(res, (Mapping, str)) or hasattr(res, "__fspath__") or res.samples.size == 0:
        # a result JSON holds no draws: its means, sds and correlation (a Gaussian, the Laplace approximation)
        d = _json(res) if not hasattr(res, "summary") else {"parameters": res.summary, "correlation": res.correlation,
                                                            "settings": res.settings}  # fmt: skip
        summ, corr = d["parameters"], d.get("correlation") or {}
        names = [n for n in ("k1", "k2", "k3", "c", "c_nl", "k0") if n in summ]
        if "k1" not in names:
            raise AssertionError("well_frequencies needs a coefficient posterior (model='coefficients')")
        sd = np.array([summ[n]["sd"] for n in names])
        R = np.array([[corr.get(a, {}).get(b, float(a == b)) for b in names] for a in names])
        pick = rng.multivariate_normal([summ[n]["mean"] for n in names], R * np.outer(sd, sd), size=draws)
        mass = d.get("settings", {}).get("mass") or 1.0
    else:
        names = list(res.names)
        if "k1" not in names:
            raise AssertionError("well_frequencies needs a coefficient posterior (model='coefficients')")
        flat = res.samples.reshape(-1, len(names))
        pick = flat[rng.choice(flat.shape[0], size=min(draws, flat.shape[0]), replace=False)]
        mass = res.settings.get("mass") or 1.0
    freqs: dict[str, list[float]] = {"minus": [], "plus": []}
    for row in pick:
        p = dict(zip(names, row, strict=False))
        try:
            model = Model(m=mass, k1=p["k1"], k2=p["k2"], k3=p["k3"], c=p["c"], c_nl=p["c_nl"], k0=p.get("k0"))
            for well in freqs:
                freqs[well].append(model.uls(well).f_hz)
        except ValueError:
            continue
    return {w: (float(np.mean(f)), float(np.std(f, ddof=1))) for w, f in freqs.items() if len(f) >= 0.9 * len(pick)}


def assert_wells_agree(identification, posterior, k: float = 3.0) -> None:
    """Assert that each well frequency of an identification (an ``Identification``, an identify result
    JSON, or a fitted ``NSI``/``SINDy``) lies within ``k`` standard deviations of the posterior's
    (``well_frequencies``): the record's own uncertainty sets the tolerance.
    """
    modal = _modal(identification)
    post = well_frequencies(posterior)
    compared = 0
    for well, (mean, sd) in post.items():
        f = modal.get(well, {}).get("f_hz")
        if f is None:
            continue
        assert_agree(f, mean, 0.0, sd, k, what=f"the {well} well's frequency [Hz] (identified, posterior mean)")
        compared += 1
    if not compared:
        raise AssertionError(f"no well to compare: identified {sorted(modal)}, posterior {sorted(post)}")


def _modal(identification) -> Mapping[str, Mapping[str, Any]]:
    """Each well's ``{"f_hz", ...}``: an identification's own (``modal``), or a model's linearisation (a
    ``Model``, a model file's dict).
    """
    if isinstance(identification, (Mapping, str)) or hasattr(identification, "__fspath__"):
        d = _json(identification)
        if isinstance(d.get("modal"), Mapping):
            return d["modal"]
    elif getattr(identification, "modal", None) is not None:
        return identification.modal
    elif "result_" in getattr(identification, "__dict__", {}):
        return identification.result_.modal
    model = _model(identification)
    out: dict[str, Mapping[str, Any]] = {}
    for well in ("minus", "plus"):
        try:
            out[well] = {"f_hz": model.uls(well).f_hz}
        except ValueError:
            continue
    return out


def assert_methods_agree(a, b, record=None, k: float = 3.0, blocks: int = 3) -> None:
    """Assert that two methods' own estimates of each well's frequency (a structure's: each of its modes) agree
    within ``k`` combined standard errors. ``a``, ``b``: fitted identifications (NSI, SINDy; their ``own_estimate``
    on ``record``, the record they were fitted on, in ``blocks`` blocks) or ``own_estimate`` results. The refined
    models are not compared: both methods refine to the same output-error optimum, so their agreement says nothing.
    """
    own = []
    for est in (a, b):
        if isinstance(est, Mapping):
            own.append(est)
        else:
            if record is None:
                raise AssertionError("assert_methods_agree: the record the estimators were fitted on is needed")
            own.append(est.own_estimate(record, blocks=blocks))
    compared = 0
    names = f"{own[0].get('method', 'first')}, {own[1].get('method', 'second')}"
    for well, ms_a in own[0]["modal"].items():
        ms_b = own[1]["modal"].get(well, {})
        # a structure's well holds its modes by frequency (each compared with the other's of the same rank)
        listed = isinstance(ms_a, list) and isinstance(ms_b, list)
        pairs = list(zip(ms_a, ms_b, strict=False)) if listed else [(ms_a, ms_b)]  # modes one found, the other not
        for i, (ma, mb) in enumerate(pairs):
            what = f"the {well} well's" + (f" mode {i + 1}" if isinstance(ms_a, list) else "")
            if ma.get("f_hz") is None or mb.get("f_hz") is None:
                continue
            if ma.get("f_hz_se") is None or mb.get("f_hz_se") is None:
                raise AssertionError(f"{what} frequency has no standard error (a block missed the well)")
            assert_agree(ma["f_hz"], mb["f_hz"], ma["f_hz_se"], mb["f_hz_se"], k,
                         what=f"{what} own frequencies [Hz] ({names})")  # fmt: skip
            compared += 1
    if not compared:
        raise AssertionError("no well both methods estimated")


def assert_predicts(model, record, reference, factor: float = 2.0, window_s: float = 0.125) -> None:
    """Assert that ``model`` (a ``Model``, a model file's dict, an identify result JSON or a fitted estimator)
    predicts ``record`` within ``factor`` times the error of ``reference`` (the
    truth of a simulated record, or the best model a user has): free runs of ``window_s`` restarted from
    the record's measured states (``validation.restarted_free_runs``; 0.125 s, the posterior's windows,
    short enough that cross-well chaos does not amplify the start states' error), their rms error as a
    share of rms z. Even the truth errs by its record's noise: the input's and the start states', not
    only the displacement sensor's white floor (on the rig's records the truth's 0.125 s error is 4-5x
    that floor), so the floor is measured with a reference model, never assumed.
    """
    errors = [_restarted_error(_model(m), record, window_s) for m in (model, reference)]
    if not errors[0] <= factor * errors[1]:
        raise AssertionError(
            f"{record.source}: the model's restarted {window_s:g} s free runs miss the record by {errors[0]:.3g} % rms "
            f"(of rms z), {errors[0] / errors[1]:.2f} times the reference's {errors[1]:.3g} %; allowed {factor:g} times"
        )


def _restarted_error(model, record, window_s: float) -> float:
    from negstiff.inference.steps.validation import restarted_free_runs

    zs, v, _, _ = record.states("state")
    runs = restarted_free_runs(model, record, 0, window_s, zs, v)
    if not runs:
        raise AssertionError(f"{record.source}: shorter than one {window_s:g} s window")
    return float(runs["restarted_rms_percent"])
