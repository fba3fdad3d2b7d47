"""Model updating of the physical device with a genetic algorithm (reference study section 4.1, Eq. 9).

The fitness compares the device's features (the two well frequencies and stable equilibria) with an
estimate (an ``identify`` result, or a targets JSON):

    eps_w = RMS{ 100 |w-_MOD - w-_EST| / w-_EST , 100 |w+_MOD - w+_EST| / w+_EST }
    eps_z = RMS{ 100 |z-_MOD - z-_EST| / |z-_EST| , 100 |z+_MOD - z+_EST| / |z+_EST| }
    eps   = eps_w + eps_z                                                     [%]

The evolution is pymoo's GA (Blank & Deb 2020): tournament selection, simulated binary crossover and
polynomial mutation (Deb 2001, the reference study's ref. [18]), elitist survival, seeded. The parameters are the
frame's Young's modulus E, the frame angle alpha and the moving mass m, within bounds around the
nominal design; the rest of the geometry is fixed.

Identifiability (device-model.md): the features depend on E and m only through E/m, so with m free
the GA returns one point of a ridge; weighing m (``fixed_mass``) pins E.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from negstiff.errors import InputError
from negstiff.inference.estimators.base import Estimator
from negstiff.inference.estimators.parameters import RANDOM_STATE, Instance, Interval, Options, seed_of
from negstiff.models import NOMINAL, Device

FEATURES = ("f_minus", "f_plus", "z_minus", "z_plus")
PENALTY = 1e3
"""Fitness [%] of a parameter set whose device has no double well."""


class UpdatingError(InputError):
    """Bad targets or settings for model updating."""


def fitness(model: Mapping[str, float], estimate: Mapping[str, float]) -> float:
    """Seed Eq. 9 [%] between two feature sets (frequencies in Hz or rad/s alike, equilibria in m)."""
    ew = math.sqrt(np.mean([(100 * (model[k] - estimate[k]) / estimate[k]) ** 2 for k in ("f_minus", "f_plus")]))
    ez = math.sqrt(np.mean([(100 * (model[k] - estimate[k]) / abs(estimate[k])) ** 2 for k in ("z_minus", "z_plus")]))
    return ew + ez


STROKE_KEY = "stroke_quantiles_m"
"""An identify result's quantiles of the z its identification part visited (the stroke and how often)."""


def model_features(model) -> dict[str, float] | None:
    """Eq. 9's features of a polynomial model: its stable equilibria and the frequencies of its
    linearisation there (None without a double well).
    """
    try:
        eq = model.equilibria()
    except ValueError:
        return None
    if eq.z_minus is None:
        return None
    ks = np.asarray(model.stiffness(np.array([eq.z_minus, eq.z_plus])), float)
    if np.any(ks <= 0):
        return None
    f = np.sqrt(ks / model.m) / (2 * math.pi)
    return {"f_minus": float(f[0]), "f_plus": float(f[1]), "z_minus": eq.z_minus, "z_plus": eq.z_plus}


def targets_from(data: Mapping[str, Any], source: str = "targets") -> dict[str, Any]:
    """Features from an ``identify`` result or a flat targets mapping.

    An identify result that carries its record's stroke (``stroke_quantiles_m``) gives the features of
    its own model, the model (``model``) and the stroke (``stroke_z``): the updater then compares like
    with like, the device's restoring force with the identified one over the states the record visited
    (``GAUpdater``). Older results (no stroke) give the method's well frequencies and its model's
    equilibria (the reference study's way).
    """
    if isinstance(data, Mapping) and data.get(STROKE_KEY) is not None and "model" in data:
        from negstiff.models import Model

        try:
            feats = model_features(Model.from_dict(data["model"]))
            stroke = [float(x) for x in data[STROKE_KEY]]
        except (ValueError, TypeError, KeyError) as exc:
            raise UpdatingError(f"{source}: unreadable model or stroke: {exc}") from None
        if feats is None:
            raise UpdatingError(f"{source}: the identified model has no double well: nothing to update against")
        if len(stroke) < 8 or not all(math.isfinite(x) for x in stroke):
            raise UpdatingError(f"{source}: {STROKE_KEY} needs at least 8 finite values")
        return {**feats, "stroke_z": stroke, "model": dict(data["model"])}
    try:
        if "modal" in data and "equilibria" in data:
            t = {
                "f_minus": data["modal"]["minus"]["f_hz"],
                "f_plus": data["modal"]["plus"]["f_hz"],
                "z_minus": data["equilibria"]["z_minus"],
                "z_plus": data["equilibria"]["z_plus"],
            }
        else:
            t = {k: data[k] for k in FEATURES}
    except (KeyError, TypeError):
        raise UpdatingError(
            f"{source}: needs an identify result (modal, equilibria) or the keys {', '.join(FEATURES)}"
        ) from None
    bad = [k for k, v in t.items() if v is None]
    if bad:
        raise UpdatingError(
            f"{source}: no value for {', '.join(bad)} (a single-well record cannot update a double-well device)"
        )
    t = {k: _target(source, k, v) for k, v in t.items()}
    if not (t["z_minus"] < 0 < t["z_plus"]) or min(t["f_minus"], t["f_plus"]) <= 0:
        raise UpdatingError(f"{source}: targets need z_minus < 0 < z_plus and positive frequencies, got {t}")
    if isinstance(data, Mapping) and "stroke_z" in data and "model" in data:  # targets_from's own output
        t |= {"stroke_z": list(data["stroke_z"]), "model": dict(data["model"])}
    return t


UNREACHED_FITNESS_PERCENT = 10.0
"""A best fitness (the paper's Eq. 9) above this [%] is a device that cannot reach its targets (1-2 % on the paper's
data and the rig's records)."""

TARGET_RANGES = {"f": (1e-2, 1e3, "Hz"), "z": (-1.0, 1.0, "m")}
"""Where a well's frequency [Hz] and position [m] may lie: a shaker-table device's, in SI units."""


def _target(source: str, key: str, value: Any) -> float:
    """A target as a finite number in its physical range (``TARGET_RANGES``), or one ``UpdatingError``."""
    lo, hi, unit = TARGET_RANGES[key[0]]
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise UpdatingError(f"{source}: {key} must be a number [{unit}], got {value!r}")
    if not (math.isfinite(value) and lo <= value <= hi):
        raise UpdatingError(f"{source}: {key} = {value!r} {unit} is not a well of a shaker-table device "
                            f"({lo:g} to {hi:g} {unit})")  # fmt: skip
    return float(value)


def load_targets(path: str | Path) -> dict[str, float]:
    """The targets of a JSON file (an identify result or flat targets), checked; ``InputError`` otherwise."""
    from negstiff.files import read_json

    try:
        data = read_json(path, "targets file")
    except ValueError as exc:
        raise UpdatingError(str(exc)) from None
    if not isinstance(data, Mapping):
        raise UpdatingError(f"{path}: a targets file is a JSON object (an identify result, or {', '.join(FEATURES)})")
    return targets_from(data, str(path))


@dataclass(frozen=True)
class Bounds:
    """Search box around the nominal design: relative for E and m, absolute degrees for alpha."""

    E_rel: float = 0.25
    alpha_deg: float = 5.0
    m_rel: float = 0.25


class GAUpdater(Estimator):
    """Update the device's E, alpha and m with a genetic algorithm to match identified features.

    The reference study's fitness (its Eq. 9) on the well frequencies and equilibria, or, from an
    identification result, its restoring force over the stroke the record visited
    (``docs/methods/updating.md``).

    Parameters
    ----------
    start : Device, default NOMINAL
        The nominal design the search is centred on.
    pop_size, generations : int, default 60, 120
        The GA's size.
    bounds : Bounds, optional
        The search box around ``start`` (relative E and m, alpha in degrees).
    fixed_mass : float, optional
        Weighed mass [kg]: only E and alpha are updated (E and m are not separately identifiable from
        the features).
    seed : int, None or numpy.random.Generator, default 0
        The GA's random seed (same seed, same result); None: fresh entropy; a Generator: its next draw. The
        integer used is ``settings["seed"]`` (``seed_``).
    compare : {"auto", "features", "force"}, default "auto"
        What is matched: the features, or (``auto`` when the targets hold a model and its stroke) the
        restoring force.

    Attributes
    ----------
    device_ : Device
        The updated device.
    fitness_ : float
        Its Eq. 9 fitness [%] against the targets.
    objective_ : float
        What was minimised [%] (the fitness, or the restoring-force mismatch).
    features_ : dict
        The updated device's well frequencies [Hz] and equilibria [m].
    history_ : list of dict
        Each generation's best and mean objective.

    Examples
    --------
    >>> from negstiff import GAUpdater
    >>> targets = {"f_minus": 11.45, "f_plus": 9.20, "z_minus": -0.0287, "z_plus": 0.0228}
    >>> ga = GAUpdater(fixed_mass=0.212, generations=30, seed=1).fit(targets)
    >>> ga.fitness_ < 1.0                                           # [%], the reference study's Eq. 9
    True
    """

    _parameter_constraints = {
        "start": Instance("negstiff.models.device", "Device"),
        "pop_size": Interval(int, 4, 10**5),
        "generations": Interval(int, 1, 10**5),
        "bounds": Instance("negstiff.inference.estimators.updating", "Bounds"),
        "fixed_mass": Interval(float, 1e-9, 1e9, unit="kg", none=True),
        "seed": RANDOM_STATE,
        "compare": Options(("auto", "features", "restoring_force")),
    }

    def __init__(
        self,
        *,
        start: Device = NOMINAL,
        pop_size: int = 60,
        generations: int = 120,
        bounds: Bounds = Bounds(),
        fixed_mass: float | None = None,
        seed: int | np.random.Generator | None = 0,
        compare: str = "auto",
    ):
        self.start, self.pop_size, self.generations = start, pop_size, generations
        self.bounds, self.fixed_mass, self.seed, self.compare = bounds, fixed_mass, seed, compare

    def _device(self, x: np.ndarray) -> Device:
        m = self.fixed_mass if self.fixed_mass is not None else x[2]
        return self.start.with_(E=x[0], alpha_deg=x[1], m=m)

    def features_of(self, x: np.ndarray) -> dict[str, float] | None:
        """The device's exact Eq. 9 features (None where it has no double well)."""
        try:
            return self._device(x).features()
        except ValueError:
            return None

    def force_mismatch(self, x: np.ndarray, stroke: np.ndarray, k_id: np.ndarray) -> float:
        """Rms over the stroke's quantiles of the device's K/m less the identified K/m, % of the latter's
        spread (``PENALTY`` where the device cannot reach the stroke or has no double well).
        """
        try:
            d = self._device(x)
            k = np.asarray(d.restoring_force(stroke, include_extra=False), float) / d.m
            d.features()
        except ValueError:
            return PENALTY
        return float(100 * np.sqrt(np.mean((k - k_id) ** 2)) / np.std(k_id))

    def population_fitness(self, X: np.ndarray, targets, stroke: np.ndarray | None, k_id) -> np.ndarray:
        """``fitness`` (or ``force_mismatch`` where a ``stroke`` is given) of every row of the population
        X at once, ``PENALTY`` where a device has no double well or cannot reach the stroke.
        """
        s = self.start
        m = np.full(len(X), self.fixed_mass) if self.fixed_mass is not None else X[:, 2]
        F, ok = s.features_many(X[:, 0], X[:, 1], m)
        if stroke is None:
            feats = [dict(zip(("f_minus", "f_plus", "z_minus", "z_plus"), row, strict=False)) for row in F]
            return np.array([fitness(f, targets) if good else PENALTY for f, good in zip(feats, ok, strict=False)])
        force, reach = s.restoring_force_many(stroke, X[:, 0], X[:, 1], m)
        k = force / m[:, None]
        mismatch = 100 * np.sqrt(np.mean((k - k_id) ** 2, axis=1)) / np.std(k_id)
        return np.where(ok & reach.all(axis=1), mismatch, PENALTY)

    def check(self, targets: Mapping[str, Any]) -> dict[str, Any]:
        """Everything ``fit`` checks before the GA runs (the settings and the targets); the targets as
        ``fit`` uses them (``targets_from``).
        """
        self._validate_params()
        if not isinstance(targets, Mapping):
            raise UpdatingError(f"targets are a mapping (an identify result, or {', '.join(FEATURES)})")
        t = targets_from(targets)
        if self.compare == "restoring_force" and not ("stroke_z" in t and "model" in t):
            raise UpdatingError(
                "compare='restoring_force' needs an identify result with its stroke (stroke_quantiles_m)"
            )
        return t

    def fit(self, targets: Mapping[str, float], progress=None) -> GAUpdater:
        """Run the GA against ``targets`` (``f_minus, f_plus`` [Hz], ``z_minus, z_plus`` [m])."""
        targets = self.check(targets)
        self.seed_ = seed_of(self.seed)  # None or a Generator: the integer drawn here (the result's settings)
        from pymoo.algorithms.soo.nonconvex.ga import GA
        from pymoo.core.callback import Callback
        from pymoo.core.problem import Problem
        from pymoo.operators.crossover.sbx import SBX
        from pymoo.operators.mutation.pm import PM
        from pymoo.optimize import minimize

        stroke = targets.pop("stroke_z", None)
        model = targets.pop("model", None)
        by_force = stroke is not None and model is not None and self.compare != "features"
        k_id = None
        if by_force:
            from negstiff.models import Model

            stroke = np.asarray(stroke, float)
            identified = Model.from_dict(model)
            k_id = np.asarray(identified.restoring_force(stroke), float) / identified.m
        s, b = self.start, self.bounds
        xl = [s.E * (1 - b.E_rel), s.alpha_deg - b.alpha_deg]
        xu = [s.E * (1 + b.E_rel), s.alpha_deg + b.alpha_deg]
        if self.fixed_mass is None:
            xl.append(s.m * (1 - b.m_rel))
            xu.append(s.m * (1 + b.m_rel))
        updater = self

        class DeviceProblem(Problem):
            def __init__(self):
                super().__init__(n_var=len(xl), n_obj=1, xl=np.array(xl), xu=np.array(xu))

            def _evaluate(self, X, out, *args, **kwargs):
                if not updater.start.extra:  # the population at once (``Device.features_many``)
                    out["F"] = updater.population_fitness(X, targets, stroke if by_force else None, k_id)[:, None]
                    return
                f = []
                for x in X:
                    if by_force:
                        f.append(updater.force_mismatch(x, stroke, k_id))
                        continue
                    feats = updater.features_of(x)
                    f.append(PENALTY if feats is None else fitness(feats, targets))
                out["F"] = np.array(f)[:, None]

        history: list[dict[str, float]] = []

        class Record(Callback):
            def notify(self, algorithm):
                F = algorithm.pop.get("F")[:, 0]
                ok = F < PENALTY
                history.append(
                    {"best": float(algorithm.opt.get("F")[0, 0]), "mean": float(F[ok].mean()) if ok.any() else PENALTY}
                )
                if progress is not None:
                    progress(len(history), history[-1]["best"])

        alg = GA(
            pop_size=self.pop_size, crossover=SBX(prob=0.9, eta=15), mutation=PM(eta=20), eliminate_duplicates=True
        )
        res = minimize(
            DeviceProblem(), alg, ("n_gen", self.generations), seed=self.seed_, callback=Record(), verbose=False
        )
        x = np.atleast_1d(res.X)
        self.device_ = self._device(x)
        self.compared_ = (
            "the restoring force per unit mass over the quantiles of the record's stroke (identified model vs device)"
            if by_force
            else "exact device features (reference study Eq. 9)"
        )
        self.features_ = self.features_of(x)
        self.exact_features_ = self.features_
        # reference study Eq. 9, reported in either case (inf: the best device has no double well)
        self.fitness_ = math.inf if self.features_ is None else float(fitness(self.features_, targets))
        self.objective_ = float(res.F[0]) if by_force else self.fitness_
        self.stroke_ = stroke if by_force else None
        self.history_ = history
        self.targets_ = targets
        return self

    def warnings(self) -> list[str]:
        """What a physicist would not believe: a best device that still misses its targets."""
        if not self.fitness_ <= UNREACHED_FITNESS_PERCENT:
            return [
                f"the best device misses the targets by {self.fitness_:.3g} % (paper Eq. 9): the targets lie beyond "
                "what the search box around the nominal design reaches; check them, or widen the bounds"
            ]
        return []

    def _restore(self, result: dict[str, Any]) -> None:
        super()._restore(result)
        self.device_ = self.start.with_(E=result["E"], alpha_deg=result["alpha_deg"], m=result["m"])
        self.fitness_, self.objective_ = result["fitness_percent"], result["objective_percent"]
        self.features_, self.exact_features_ = result.get("features"), result.get("exact_features")
        self.history_, self.targets_ = result.get("generations", []), result.get("targets") or {}
        self.seed_ = result.get("settings", {}).get("seed", self.seed)

    def result(self) -> dict[str, Any]:
        """The contract's update JSON (plus features, targets, E/m and settings)."""
        d = self.device_
        return {
            "E": d.E,
            "alpha_deg": d.alpha_deg,
            "m": d.m,
            "fitness_percent": self.fitness_,
            "objective_percent": self.objective_,
            "generations": self.history_,
            "E_over_m": d.E / d.m,
            "features": self.features_,
            "exact_features": self.exact_features_,
            "compared": self.compared_,
            "targets": self.targets_,
            "mass_fixed": self.fixed_mass is not None,
            "warnings": self.warnings(),
            "start": {"E": self.start.E, "alpha_deg": self.start.alpha_deg, "m": self.start.m},
            # the updated device as the geometric law's model (``Device.law_model``): what every method reads
            "model": d.law_model().to_dict(),
            "law": "geometric",
            "settings": {
                "pop_size": self.pop_size,
                "generations": self.generations,
                "seed": self.seed_,
                "bounds": vars(self.bounds),
                "algorithm": "pymoo GA, SBX(0.9, 15), PM(20), elitist",
            },
        }
