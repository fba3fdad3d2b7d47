"""``Posterior``: the front door (module docstring of the package)."""

from __future__ import annotations

import copy
import functools
import math
import os
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np
from scipy import optimize

from negstiff.errors import ConvergenceWarning, InputError, MeasurementError, issue
from negstiff.inference.analysis.record_kind import RING_DOWN_KINDS
from negstiff.inference.estimators.base import ElementPlace, Estimator, element_of
from negstiff.inference.estimators.parameters import (
    RANDOM_STATE,
    AnyOf,
    Boolean,
    Instance,
    Interval,
    LawName,
    Options,
    seed_of,
)
from negstiff.inference.estimators.persistence import provenance
from negstiff.inference.estimators.posterior.diagnostics import (
    PosteriorResult,
    convergence_warnings,
    is_noise,
    noise_names,
    result_json,
    summarise,
)
from negstiff.inference.estimators.posterior.likelihood import (
    LogPosterior,
    information_parts,
    input_noise_rms,
    sandwich,
)
from negstiff.inference.estimators.posterior.parametrisation import (
    SHIFT,
    Parametrisation,
    coefficient_parametrisation,
    device_parametrisation,
    law_parametrisation,
    support_failures,
)
from negstiff.inference.estimators.posterior.sampling import (
    MOVES,
    ChainFile,
    ChainFilePath,
    check_chain_file,
    sample_ensembles,
)
from negstiff.inference.estimators.posterior.windows import DROP_FACTOR_AT_MAP, PosteriorError, Windows
from negstiff.inference.record.measurement import Measurement
from negstiff.inference.steps.plausibility import classified
from negstiff.models import Model, laws
from negstiff.models.device import NOMINAL
from negstiff.models.effects import ROWS

PILOT_STEPS = 200
"""Steps of the pilot run (one ensemble) that checks the Laplace whitening before the sampler's run
(``Posterior._pilot_whitened``)."""
PILOT_TOLERANCE = 3.0
"""The pilot's second half may sit this many whitened units from the origin, and spread within this factor of 1,
before the run is re-whitened by the pilot's mean and covariance."""
PILOT_SEED = 7919
"""The pilot's seed offset from the run's (its own stream of draws)."""
ALTERNATIONS = 10
"""The most rounds of the MAP search and the windows' start-state refinement, alternately (``point_estimate``)."""
ALTERNATION_TOL = 1e-3
"""A round that lowers the MAP search's cost by less than this share (the same windows kept) ends the alternation."""
WALL_RESIDUAL = 1e3
"""The MAP search's residual, per row, outside the prior's support or where the model diverges: a wall far above any
fit's residual, in metres or whitened. Whitened by the noise model at the profiled sensor variance every residual has
unit variance, so a wall of 1 cost what the best fit costs: the search stepped onto it (c_nl just below its bound 0
on a clean record, the input's noise 1e-8 m/s^2) and stopped there, its Jacobian zero, and the posterior's curvature
with it (numpy's "Eigenvalues did not converge"; measured)."""
FORCE_BAND_POINTS = 101
"""Displacements of the force band's grid over the record's stroke (``force_band``)."""
FORCE_BAND_DRAWS = 400
"""Posterior draws (at most) the force band's quantiles are taken over: its 5 and 95 % quantiles then move by
about 0.02 posterior sd from draw to draw of the band (the order statistics' spread), far below the band's width."""


def check_map_point(logpost: LogPosterior, nd: int) -> None:
    """Refuse (one ``PosteriorError``) a posterior whose MAP point lies outside the prior's support or whose windows
    diverge there, naming which, before the sampler looks for a start about it (it had searched 50 times and said
    only that no start point was found).
    """
    from negstiff.inference.estimators.posterior.windows import SIGMA_BOUNDS

    origin = np.zeros((1, nd))
    if np.isfinite(logpost(origin)[0][0]):
        return
    q = logpost.unwhiten(origin)
    theta, log_sigma = logpost.split(q)
    par = logpost.par
    phys = par.physical(theta)[0]
    why = [f"{n} = {v:.4g} outside ({lo:.4g}, {hi:.4g})" for n, v, lo, hi in
           zip(par.names, phys, par.lower, par.upper, strict=True) if not lo < v < hi]  # fmt: skip
    why += support_failures(par, phys)
    why += [f"the sensor noise it reads, {np.exp(ls):.3g} m, outside the prior's ({SIGMA_BOUNDS[0]:g}, "
            f"{SIGMA_BOUNDS[1]:g}) m" for ls in np.atleast_1d(log_sigma[0])
            if not math.log(SIGMA_BOUNDS[0]) < ls < math.log(SIGMA_BOUNDS[1])]  # fmt: skip
    if not why:
        why = ["its windows' runs diverge there"]
    raise PosteriorError(f"the posterior's MAP point has no density: {'; '.join(why)}")


class Posterior(Estimator):
    """The Bayesian posterior of a record's model parameters, sampled with emcee and diagnosed with arviz.

    A multiple-shooting likelihood over short windows, curvature-adjusted, with an RK4 step resolved
    until its error moves the MAP point by less than 0.1 posterior sd (``docs/methods/posterior.md``).

    Parameters
    ----------
    model : {"coefficients", "device"}, default "coefficients"
        ``"coefficients"``: k1-k3, c, c_nl, sigma (mass fixed); ``"device"``: E, alpha, m, c, c_nl,
        sigma with the exact geometric K(z).
    law : str, optional
        A restoring-force law of ``models.laws`` (``"magnet"``, ``"septic"``, ``"geometric"``, ``"spline"``, ...):
        every parameter it frees and every parameter of its parts is sampled (``law_parametrisation``: a magnet's
        A and d, a spline's coefficients over the record's knots, the rod frame's k_f, D0, L and alpha), with the
        damping law's and sigma, about the laws' deterministic fit (the weak form at the law's shape,
        ``steps.shape.fit_shape``, refined by output error); the result adds the restoring force's credible band
        over the stroke (``force_band``). None (default): the coefficient parametrisation (``model``) unchanged.
    damping : str, optional
        The damping law with ``law`` (``models.laws``; default ``"quadratic"``, the reference study's). Given
        without ``law``: the cubic with this damping law, sampled as a law.
    mass_prior : {"weighed", "free"}, default "weighed"
        Device model only: the mass weighed (N(m, 2 %)) or free (the E-m ridge shows).
    window_s : float, default 0.125
        Window length [s].
    max_windows : int or None, default 240
        At most this many windows, evenly spread over the record (None: every window).
    n_walkers, n_ensembles : int, default 16, 4
        Walkers per ensemble, independent ensembles (each one arviz chain).
    tau_multiple, min_steps, max_steps, chunk : float, int, int, int
        Run-length control: stop when the run exceeds ``tau_multiple`` autocorrelation times.
    hdi_prob : float, default 0.9
        Credible-interval probability.
    oversample : int, default 1
        1: the input pre-emphasised for the simulator's interpolation; q > 1: interpolated to q x fs.
    adjust : bool, default True
        Curvature adjustment of the likelihood by the windows' sandwich covariance.
    input_noise : float, optional
        The input sensor's white noise rms [input units: m/s^2 or N]. The model's input is measured too: its
        noise reaches each window's response through the device (``Windows.set_input_noise``). None (default):
        estimated from the input's own spectral floor (``input_noise_rms``); 0: the input taken as exact.
    threads : int, optional
        Threads for the batched likelihood (default: ``NEGSTIFF_THREADS`` or the cores).
    seed : int, None or numpy.random.Generator, default 0
        Seeds every draw (same seed, same posterior); None: fresh entropy; a Generator: its next draw
        (scikit-learn's ``random_state``). The integer used is ``settings["seed"]``.
    progress : bool, default False
        A progress bar over emcee's steps.
    start : Model, Structure or Identification, optional
        Coefficient posterior only: the model the MAP search starts from (e.g. an identification's); on a
        structure's record (``element``) the structure it starts from: an ``Identification`` of the structure on
        this record (``NSI(element=...).fit(rec).result_``: its structure and each channel's zero) or a
        ``Structure`` (its channels' zeros then read from the record: ``equations.weak_frame``). None: a single DOF's
        weak-form estimate, refined; a structure's ``SINDy(element=...)``.
    refine_start : bool, default True
        Without ``start``: refine the weak-form estimate by output error before the MAP search.
    element : str or (int, int), optional
        Where the element acts on a record of N > 1 DOFs: ``"I-J"``, it moves DOF J relative to DOF I (0: the
        base). None: the single DOF. On a structure's record the element's k1-k3, c, c_nl and the sensors'
        sigma are sampled, each channel's zero and the linear structure's springs and dampers with them as nuisances
        (from the start's, ``SINDy(element=...)``'s by default; ``posterior.structure``), the masses given;
        ``model="coefficients"`` and no ``input_noise`` there.
    chain_file : str or os.PathLike, optional
        An HDF5 file (``.h5``, ``.hdf5``) the emcee chains are saved to as they run (emcee's ``HDFBackend``,
        each ensemble's chain, log probability and random state in its group ``ensemble_E``): a long run kept
        on disk, read with ``emcee.backends.HDFBackend(path, name="ensemble_0")``. A fresh run replaces the
        chains of a file it made before; any other existing HDF5 file is refused. None (default): in memory.
    resume : bool, default False
        Continue the chains saved in ``chain_file`` (by a run of the same record, settings and seed) instead of
        starting afresh: each ensemble from its saved walkers and random state, up to ``max_steps`` in all and
        under the same stopping rule, so a run stopped after k steps and resumed gives the chain one
        uninterrupted run would (``settings["resumed_steps"]``: each ensemble's saved steps). Another run's
        chains are refused.

    Attributes
    ----------
    result_ : PosteriorResult
        The posterior: ``result()`` is its JSON (``parameters``: each mean, sd, hdi_low, hdi_high, r_hat,
        ess_bulk; ``map``, ``correlation``, ``converged``, ``warnings``), ``result_.idata`` its arviz data.
    windows_ : Windows
        The record's windows the likelihood reads.
    warnings_ : list of str
        Every warning (an unconverged chain among them; also issued as ``NegstiffWarning``).
    structure_, offsets_ : Structure, tuple of float
        A structure's record only: the structure with the posterior mean's element, each channel's zero [m].

    Examples
    --------
    >>> from negstiff import Measurement, Posterior, Rig
    >>> from negstiff.models import SEED_LIKE_CUBIC
    >>> rec = Measurement.from_rig(Rig(SEED_LIKE_CUBIC, seed=4).random(duration=10.0, rms=20.0))
    >>> post = Posterior(seed=1, n_ensembles=2).fit(rec)
    >>> k3 = post.result()["parameters"]["k3"]
    >>> k3["hdi_low"] < k3["mean"] < k3["hdi_high"]
    True
    >>> abs(k3["mean"] - SEED_LIKE_CUBIC.k3) < 4 * k3["sd"]         # the truth within 4 sd
    True
    """

    _parameter_constraints = {
        "model": Options(("coefficients", "device")),
        "mass_prior": Options(("weighed", "free")),
        "window_s": Interval(float, 0.0, lo_open=True, unit="s"),
        "max_windows": Interval(int, 4, 10**6, none=True),
        "n_walkers": Interval(int, 16, 10**5),
        "n_ensembles": Interval(int, 1, 1000),
        "tau_multiple": Interval(float, 1.0),
        "min_steps": Interval(int, 1, 10**7),
        "max_steps": Interval(int, 1, 10**7),
        "chunk": Interval(int, 1, 10**7),
        "hdi_prob": Interval(float, 0.0, 0.999, lo_open=True),
        "oversample": Interval(int, 1, 16),
        "adjust": Boolean(),
        "input_noise": Interval(float, 0.0, none=True),
        "threads": Interval(int, 1, 1024, none=True),
        "seed": RANDOM_STATE,
        "progress": Boolean(),
        "start": AnyOf(
            (
                Instance("negstiff.models.equation", "Model"),
                Instance("negstiff.models.structure", "Structure"),
                Instance("negstiff.inference.estimators.results", "Identification"),
            ),
            none=True,
        ),  # fmt: skip
        "refine_start": Boolean(),
        "element": ElementPlace(),
        "chain_file": ChainFilePath(),
        "resume": Boolean(),
        "law": LawName("restoring", (None,)),
        "damping": LawName("damping", (None,)),
    }

    def __init__(
        self,
        *,
        model: str = "coefficients",
        mass_prior: str = "weighed",
        window_s: float = 0.125,
        max_windows: int | None = 240,
        n_walkers: int = 16,
        n_ensembles: int = 4,
        tau_multiple: float = 50.0,
        min_steps: int = 500,
        max_steps: int = 6000,
        chunk: int = 250,
        hdi_prob: float = 0.9,
        oversample: int = 1,
        adjust: bool = True,
        input_noise: float | None = None,
        threads: int | None = None,
        seed: int | np.random.Generator | None = 0,
        progress: bool = False,
        start: Model | None = None,
        refine_start: bool = True,
        element: str | tuple[int, int] | None = None,
        chain_file: str | os.PathLike | None = None,
        resume: bool = False,
        law: str | None = None,
        damping: str | None = None,
    ):
        self.model = model
        self.mass_prior = mass_prior
        self.window_s = window_s
        self.max_windows = max_windows
        self.n_walkers = n_walkers
        self.n_ensembles = n_ensembles
        self.tau_multiple = tau_multiple
        self.min_steps = min_steps
        self.max_steps = max_steps
        self.chunk = chunk
        self.hdi_prob = hdi_prob
        self.oversample = oversample
        self.adjust = adjust
        self.input_noise = input_noise
        self.threads = threads
        self.seed = seed
        self.progress = progress
        self.start = start
        self.refine_start = refine_start
        self.element = element
        self.chain_file = chain_file
        self.resume = resume
        self.law = law
        self.damping = damping

    def _validate(self) -> None:
        if self.start is not None and self.model != "coefficients":
            raise PosteriorError("a start model is a polynomial model, for the coefficient posterior")
        if self.law_pair() is not None and self.model != "coefficients":
            raise PosteriorError(f"law={self.law!r}, damping={self.damping!r}: a law's parameters are sampled as "
                                 "coefficients (model='coefficients'); the device model is the geometric law in its "
                                 "physical parameters")  # fmt: skip
        check_chain_file(self.chain_file, self.resume, self.n_ensembles)

    def law_pair(self) -> tuple[laws.Law, laws.Law] | None:
        """The restoring and the damping law sampled (``law``, ``damping``), or None: the coefficient or device
        parametrisation (``model``).
        """
        if self.law is None and self.damping is None:
            return None
        return (laws.get(self.law or laws.DEFAULT_RESTORING, "restoring"),
                laws.get(self.damping or laws.DEFAULT_DAMPING, "damping"))  # fmt: skip

    def walkers(self, ndim: int) -> int:
        """The walkers per ensemble: ``n_walkers``, or twice the dimension where that is more (a law's many
        parameters: emcee's moves need more walkers than dimensions, and its docs advise twice).
        """
        return max(int(self.n_walkers), 2 * int(ndim))

    def chains_to(self, centre: np.ndarray, scale: np.ndarray, ndim: int, seed: int) -> ChainFile | None:
        """Where this run's chains are saved (``chain_file``; None: in memory), the run named by the sampled
        coordinates' ``centre`` and ``scale``, their dimension and the seed (a resume must match them).
        """
        if self.chain_file is None:
            return None
        run = {"walkers": self.walkers(ndim), "ndim": int(ndim), "seed": int(seed), "moves": MOVES,
               "centre": np.ravel(centre).tolist(), "scale": np.ravel(scale).tolist()}  # fmt: skip
        return ChainFile(Path(self.chain_file), bool(self.resume), run)

    def result(self) -> dict[str, Any]:
        """The contract's posterior JSON (``result_json`` of ``result_``), with every warning and the record; on a
        structure's record also ``dofs``, ``element_at``, ``structure`` (the posterior mean's), ``offsets_m`` and
        ``modal`` (that structure's modes per well).
        """
        out = {**result_json(self.result_, self.hdi_prob), "warnings": list(self.warnings_), "record": self.record_}
        settings = self.result_.settings
        if "element_at" in settings:
            s = self.structure_
            out.update(dofs=s.n_dof, element_at=list(settings["element_at"]), structure=s.to_dict(),
                       offsets_m=list(settings["offsets_m"]),
                       modal={w: [m.to_json() for m in s.modes(w)] for w in s.equilibria()})  # fmt: skip
        return out

    @property
    def structure_(self):
        """A structure's record: the ``Structure`` with the posterior mean's element (its linear part fixed)."""
        from negstiff.inference.estimators.posterior.structure import mean_structure

        settings = self.result_.settings
        if "element_at" not in settings:
            raise AttributeError("structure_: a single DOF's posterior has no structure (its model is model_)")
        return mean_structure(settings, self.result_.summary)

    @property
    def offsets_(self) -> tuple[float, ...]:
        """A structure's record: each channel's zero [m] the posterior held (measured = physical + offset)."""
        settings = self.result_.settings
        if "offsets_m" not in settings:
            raise AttributeError("offsets_: a single DOF's posterior works in the record's pinned frame")
        return tuple(float(o) for o in settings["offsets_m"])

    def _summary(self) -> str:
        settings = self.result_.settings
        if "element_at" not in settings:
            return ""
        k3 = self.result_.summary["k3"]
        return f"{settings['dofs']} DOFs, element k3 {k3['mean']:.4g} +- {k3['sd']:.2g}"

    def _restore(self, result: dict[str, Any]) -> None:
        self.result_ = PosteriorResult.from_json(result)
        self.hdi_prob = result.get("hdi_prob", self.hdi_prob)  # the JSON's intervals are at its probability
        self.warnings_ = list(result.get("warnings", []))
        self.record_ = dict(result.get("record", {}))

    @property
    def model_(self):
        """The model at the posterior mean: a ``Model`` (coefficients, with the record's mass; 1 kg per unit
        mass) or a ``Device`` (device). Its uncertainty is ``result_`` 's.
        """
        res = self.result_
        if "element_at" in res.settings:  # a structure's: the element's law of the DOF it moves
            return self.structure_.element
        mean = {n: s["mean"] for n, s in res.summary.items()}
        if "law" in res.settings:  # a law's: its start model with the mean's parameters
            from negstiff.inference.steps.refine import with_values

            names = [n for n in res.names if not is_noise(n) and n != SHIFT]
            start = Model.from_dict(res.settings["law"]["start_model"])
            return with_values(start, names, np.array([mean[n] for n in names]))
        if "k1" in mean:
            mass = res.settings.get("model_mass") or res.settings.get("mass") or 1.0
            return Model(m=mass, k1=mean["k1"], k2=mean["k2"], k3=mean["k3"], c=mean["c"], c_nl=mean["c_nl"],
                         k0=mean.get("k0"))  # fmt: skip
        return NOMINAL.with_(E=mean["E"], alpha_deg=mean["alpha_deg"], m=mean["m"], c=mean["c"], c_nl=mean["c_nl"])

    def draw_models(self, n: int, seed: int | None = 0) -> list:
        """``n`` models drawn from the sampled posterior (steps and walkers of every ensemble, without replacement):
        the posterior mean's model (``model_``, its mass and constant) with each draw's coefficients. A credible band
        for what a model predicts: a backbone (``analysis.backbone``'s ``draws``), a continuation. The coefficient
        posterior of a single DOF or a structure's element; a fit rebuilt from its JSON has no draws (one
        ``InputError``).
        """
        from dataclasses import replace

        res = self.result_
        if "k1" not in res.names and "law" not in res.settings:
            raise InputError("draw_models: the device posterior's draws are devices, not coefficient models")
        flat = np.asarray(res.samples).reshape(-1, len(res.names))
        if flat.shape[0] == 0:
            raise InputError("draw_models: this posterior holds no draws (rebuilt from its JSON: keep its NetCDF)")
        if not (isinstance(n, int | np.integer) and 0 < n <= flat.shape[0]):
            raise InputError(f"draw_models: n must be 1 to {flat.shape[0]} (the draws held), got {n!r}")
        rows = flat[np.random.default_rng(seed).choice(flat.shape[0], int(n), replace=False)]
        if "law" in res.settings:  # every law parameter of each draw, in the posterior mean's model
            from negstiff.inference.steps.refine import with_values

            keep = [i for i, k in enumerate(res.names) if not is_noise(k) and k != SHIFT]
            base = self.model_
            return [with_values(base, [res.names[i] for i in keep], row[keep]) for row in rows]
        fields = [k for k in ("k0", "k1", "k2", "k3", "c", "c_nl") if k in res.names]
        base = self.model_
        return [replace(base, **{k: float(row[res.names.index(k)]) for k in fields}) for row in rows]

    # --- start point -------------------------------------------------------------------------------
    def _start(self, rec: Measurement, win: Windows) -> tuple[Parametrisation, np.ndarray]:
        pair = self.law_pair()
        if pair is not None:
            par, theta = self._law_start(rec, *pair)
            return par, moved_inside(par, theta)
        if self.model == "coefficients":
            from negstiff.inference.steps.weak import weak_least_squares

            given = self._device_start()
            if given is not None:  # an identified (output-error refined) model: the MAP search starts there
                self._check_start_mass(rec)
                start = given
                self.start_info_ = {"source": "given", "model": start.to_dict()}
            else:
                start = self._refined_start(rec, weak_least_squares(rec, ("1", "z", "z^2", "z^3", "v", "v|v|")))
            par = coefficient_parametrisation(start)
            theta = np.array([getattr(start, n) for n in par.names])
            # a start on or past a prior's bound (a refined c_nl of -0.004 on a hammer's record, measured) is where
            # the MAP search's residual is flat (outside the support: a zero Jacobian): moved inside by 1e-6 of the
            # prior's span (c_nl to 0.03 N s^2/m^2), where the search's first steps stay in the support (one ulp inside,
            # the search stayed at its start: the Duffing's frequency interval missed 12 Hz by 0.002 Hz, measured)
            # Only a start on or past a bound is moved, by at most a tenth of its own size (at least 1e-9 of the
            # span: off the bound, where the search's steps stay in the support): the prior's span has a floor of
            # 1e-3 of the largest coefficient's magnitude, in that coefficient's units (k3's), which on a record in a
            # strain gauge's units (k3 5e11 per unit mass) moved a viscous c of 4, inside, to 5000 and the start
            # diverged
            theta = moved_inside(par, theta)
        else:
            if rec.mass is None and self.mass_prior == "weighed":
                raise PosteriorError(f"{rec.source}: the device posterior with a weighed mass needs --mass or metadata")
            m0 = rec.mass if rec.mass is not None else NOMINAL.m
            prior = (m0, 0.02 * m0) if self.mass_prior == "weighed" else None
            start = NOMINAL.with_(m=m0, c=1.0, c_nl=0.1)
            par = device_parametrisation(start, prior)
            theta = np.array([start.E, start.alpha_deg, start.m, start.c, start.c_nl, 0.0])
            self.start_info_ = {"source": "the device's nominal values"}
        return par, theta

    def _law_start(self, rec: Measurement, restoring: laws.Law, damping: laws.Law) -> tuple[Parametrisation,
                                                                                            np.ndarray]:  # fmt: skip
        """The laws' deterministic start and parametrisation: ``start`` where given (it must hold the laws' parts),
        else the weak form's constrained least squares at the law's shape (``shape.fit_shape``: variable projection;
        a spline's knots over the record's stroke, their number chosen by the data) refined by output error within
        the laws (``_refined_start``, the base fields the laws leave out held at zero).
        """
        from negstiff.inference.steps.shape import fit_shape
        from negstiff.inference.steps.weak import Library, WeakForm, fit_support, known_input_gain, mass_of

        free = set(restoring.fields) | set(damping.fields)
        held = tuple(f for f in ("k0", "k1", "k2", "k3", "c", "c_nl") if f not in free)
        given = self._device_start()
        if given is not None:
            start = given
            missing = [p for p in (*restoring.parts, *damping.parts) if p not in start.extra]
            if missing:
                raise PosteriorError(f"the start model lacks the {restoring.name} and {damping.name} laws' "
                                     f"part(s) {', '.join(missing)}")  # fmt: skip
            if rec.mass is not None and abs(start.m / rec.mass - 1) > 1e-6:
                raise PosteriorError(f"{rec.source}: the start model's mass ({start.m:g} kg) is not the "
                                     f"record's ({rec.mass:g} kg)")  # fmt: skip
            self.start_info_ = {"source": "given", "model": start.to_dict()}
        else:
            shape = fit_shape(rec, restoring, damping)
            lib = Library.of_laws(restoring, damping, shape.shape)
            gain = known_input_gain(rec)
            phys = fit_support(WeakForm.of(rec).system(rec, library=lib), gain)
            weak = lib.model(phys, mass_of(rec, gain, phys[-1])[0])
            start = self._refined_start(rec, weak, held)
            self.start_info_["shape"] = shape.to_json()
            self.start_info_["law"] = {"restoring": restoring.name, "damping": damping.name}
        _, v, _, _ = rec.states("state")
        z = np.asarray(rec.z, float)
        reach = (float(np.min(z)), float(np.max(z)))
        par = law_parametrisation(
            start, restoring, damping, reach, float(np.std(z)), float(np.std(v)), float(np.max(np.abs(v)))
        )
        assert par.law is not None
        theta = par.law.start_values()
        if par.checks is not None and not par.inside(moved_inside(par, theta)[None])[0]:
            failed = support_failures(par, moved_inside(par, theta))
            raise PosteriorError(f"{rec.source}: the {restoring.name} and {damping.name} laws' deterministic fit "
                                 "lies outside the prior's support: it fails "
                                 + ("; ".join(failed) or "; ".join(par.description[1:])))  # fmt: skip
        return par, theta

    def _refined_start(self, rec: Measurement, weak: Model, held: tuple[str, ...] = ()) -> Model:
        """The weak-form estimate refined by simulation error over the record (``refine.refine``; the mass
        held: the coefficient posterior holds it too; the base fields ``held`` too: those a law leaves out), kept
        only if it is bounded and predicts the record at least as well; ``start_info_`` says which start was used
        and why.
        """
        from negstiff.inference.steps.refine import refine
        from negstiff.inference.steps.validation import boundedness

        info: dict[str, Any] = {"source": "weak-form least squares", "initial_model": weak.to_dict()}
        self.start_info_ = info
        if not self.refine_start:
            info["reason"] = "refinement switched off"
            return weak
        t0 = time.perf_counter()
        try:
            r = refine(weak, rec, held=held) if held else refine(weak, rec)
        except (ValueError, MeasurementError) as exc:
            info["reason"] = f"refinement failed, the weak-form estimate is the start: {exc}"
            return weak
        info["refinement"] = r.to_json()
        info["seconds"] = time.perf_counter() - t0
        bounded = boundedness(r.model, rec)
        if not bounded["ok"]:
            info["reason"] = f"refined model rejected: {bounded['warning']}"
            return weak
        stages = [s for s in r.stages if "rms_end_m" in s]
        if stages and not stages[-1]["rms_end_m"] <= stages[-1]["rms_start_m"]:
            info["reason"] = "refined model rejected: its simulation error did not fall"
            return weak
        info.update(source="output-error refinement of the weak-form estimate", model=r.model.to_dict())
        return r.model

    def _pilot_whitened(self, logpost: LogPosterior, nd: int, seed: int) -> LogPosterior:
        """``logpost`` as it is where a short pilot run finds the posterior close to the Laplace approximation the
        sampler whitens with (``PILOT_STEPS`` of one ensemble, at most the run's ``max_steps``: the second half's mean
        within ``PILOT_TOLERANCE`` of the origin, each sd within that factor of 1); else re-whitened by the pilot's
        mean and covariance.

        Where a parameter's posterior leans on its bound (c_nl of a device without quadratic damping: its MAP on
        the bound 0), the Laplace approximation at the MAP point misses the posterior: on a cross-well hammer
        record the chains spread 47 Laplace sd along c_nl, their mean 53 sd from the MAP, and the ensembles'
        autocorrelation reached 50-96 steps (25 s for a 10 s record; measured). The pilot's samples are not kept
        (an adaptation before the run, which then samples with its whitening fixed).
        """
        steps = min(PILOT_STEPS, self.max_steps)  # never longer than the run it prepares (a quick look's few steps)
        pilot = sample_ensembles(logpost, nd, n_walkers=self.walkers(nd), n_ensembles=1, seed=seed + PILOT_SEED,
                                 tau_multiple=self.tau_multiple, min_steps=steps, max_steps=steps, chunk=steps,
                                 progress=False, chain_file=None)  # fmt: skip
        y = np.asarray(pilot["chains"][0]).reshape(-1, nd)  # its second half (``sample_ensembles``' burn-in)
        mean, cov = y.mean(axis=0), np.cov(y.T)
        sd = np.sqrt(np.diag(cov))
        self.whitening_ = {"pilot_steps": steps, "pilot_mean_max_sd": float(np.max(np.abs(mean))),
                           "pilot_sd_range": [float(sd.min()), float(sd.max())], "rewhitened": False}  # fmt: skip
        if np.max(np.abs(mean)) <= PILOT_TOLERANCE and np.all((sd >= 1 / PILOT_TOLERANCE) & (sd <= PILOT_TOLERANCE)):
            return logpost
        try:
            factor = np.linalg.cholesky(cov)
        except np.linalg.LinAlgError:
            factor = np.diag(sd)
        self.whitening_["rewhitened"] = True
        out = copy.copy(logpost)  # the same posterior, about the pilot's mean, scaled by its covariance
        out.q0, out.scale = logpost.unwhiten(mean)[0], logpost.scale @ factor
        return out

    def _map(self, par: Parametrisation, win: Windows, theta: np.ndarray, sigma2: float | np.ndarray | None = None):
        """MAP point of theta (sigma profiled) by least squares on the projected residuals, with the
        parameters the likelihood does not see held; returns (theta, the least-squares solution). With the
        input's noise in the likelihood (``Windows.set_input_noise``) the residuals are whitened by the noise
        model at the sensor's variance ``sigma2`` (generalised least squares: the likelihood's own mode).
        """
        x_scale = np.maximum(np.abs(theta), 1e-6)
        gls = sigma2 is not None and (win.noise_basis is not None or win.n_groups > 1)  # a joint fit: each record's
        reduced = gls and win.noise_basis is not None and win.proj is not None  # whitened in the projected basis
        n_rows = win.n_windows * (win.length - (win.proj.shape[-1] if reduced and win.proj is not None else 0))

        def solve(start: np.ndarray, free: np.ndarray):
            def resid(x):
                th = start.copy()
                th[free] = x * x_scale[free]
                if not par.inside(th[None])[0]:
                    return np.full(n_rows, WALL_RESIDUAL)
                params = par.to_params(th[None])
                if not np.all(np.isfinite(params)):
                    return np.full(n_rows, WALL_RESIDUAL)
                zsim, div = win.simulate(params, par.kind)
                if div[0]:
                    return np.full(n_rows, WALL_RESIDUAL)
                if gls:
                    assert sigma2 is not None
                    return win.whitened_residuals(zsim[0], sigma2)
                return win.residuals(zsim)[0].ravel()

            sol = optimize.least_squares(resid, start[free] / x_scale[free], method="lm", x_scale="jac", max_nfev=400)
            th = start.copy()
            th[free] = sol.x * x_scale[free]
            return th, sol

        free = par.free()
        th, sol = solve(theta, free)
        # The prior's support is a wall for Levenberg-Marquardt (a constant residual outside it): a parameter whose
        # optimum lies on its bound (c_nl of a device without cubic damping: 0) stops the search where a step
        # first meets the wall, the others short of their optimum (a cross-well hammer record: k1 419.50 for 420,
        # 2.6 sd, its cost 23 % above the truth's; measured). Such a parameter is held just inside its bound while the
        # others are solved, then all are solved from there; the lower cost is kept. (Held where the first search
        # left it, within 1e-3 of the prior's span from the bound, and at least 1e-6 of it inside.)
        span = par.upper - par.lower
        edge = 1e-3 * span
        near = free & ((th - par.lower < edge) | (par.upper - th < edge))
        if near.any() and (free & ~near).any():
            held = th.copy()
            held[near] = np.clip(th[near], (par.lower + 1e-6 * span)[near], (par.upper - 1e-6 * span)[near])
            held, _ = solve(held, free & ~near)
            th2, sol2 = solve(held, free)
            if sol2.cost < sol.cost:
                th, sol = th2, sol2
        return th, sol

    def point_estimate(self, rec: Measurement | list[Measurement]):
        """Windows, MAP point and noise model of a record: (parametrisation, windows, theta, the least
        squares solution, sigma). The MAP point and the windows' start states are found alternately, each
        a profile over the other. The device's mass is held at its start (weighed) value: the
        likelihood depends on E/m, c/m, c_nl/m only (device-model.md), so the MAP point along the E-m
        ridge is the prior's.

        Several records of one device (a list: a lab's runs fitted together): each record's windows cut as its
        own (``Windows.joined``), the device's parameters shared, each record its own sensor noise (sigma: (R,))
        and input noise; the start model is the first record's.
        """
        from negstiff.inference.analysis.record_kind import identification_record, record_kind

        self._validate()
        recs = list(rec) if isinstance(rec, (list, tuple)) else [rec]
        kinds = [record_kind(r) for r in recs]
        self.record_kind_ = kinds[0].kind
        ring_down = kinds[0].kind in RING_DOWN_KINDS
        if ring_down:  # a hammer's force windowed, a decay's input zero; the windows between the pulses
            recs = [identification_record(r, k) for r, k in zip(recs, kinds, strict=True)]
        parts = [Windows.cut(r, self.window_s, self.max_windows, oversample=self.oversample, free=ring_down)
                 for r in recs]  # fmt: skip
        win = parts[0] if len(parts) == 1 else Windows.joined(parts)
        win.threads = self.threads
        rec = recs[0]
        par, theta = self._start(rec, win)
        zsim, div = win.simulate(par.to_params(theta[None]), par.kind)
        if div[0]:
            raise PosteriorError(f"{rec.source}: the start model diverges on the record's windows")
        # the MAP point and the windows' start states alternately, until the cost stops falling (three rounds at
        # least, ALTERNATIONS at most): three rounds alone stopped short on a cross-well hammer record (its cost 42 %
        # above the truth's, c 0.486 +- 0.005 for 0.5 with a variance inflation of 684; three more rounds reached
        # the truth's cost; measured)
        cost = math.inf
        for it in range(ALTERNATIONS):
            p_ = par.to_params(theta[None])[:, 0]
            win.refine_states(p_, par.kind)
            n_before = win.n_windows
            win.drop_unmatched(p_, par.kind)
            win.set_sensitivities(p_, par.kind)
            theta, sol = self._map(par, win, theta)
            if it == 0 and win.resolve_substeps(par.to_params(theta[None]), par.kind, sol.jac):
                theta, sol = self._map(par, win, theta)
            settled = win.n_windows == n_before and sol.cost > (1 - ALTERNATION_TOL) * cost
            cost = float(sol.cost)
            if it >= 2 and settled:
                break
        # at the MAP point the model matches every window it can follow to the noise (rms within ~10 % of
        # the median window's): a window 3x above the median is not followed (it turns back near the
        # saddle); measured on the as-built device, one such window held 90 % of the score's variance.
        # The least squares solution is then recomputed on the windows kept (the curvature adjustment
        # reads its Jacobian window by window).
        p_ = par.to_params(theta[None])[:, 0]
        win.refine_states(p_, par.kind)
        win.drop_unmatched(p_, par.kind, factor=DROP_FACTOR_AT_MAP)
        win.set_sensitivities(p_, par.kind)
        theta, sol = self._map(par, win, theta)
        if ring_down:  # no input in its windows: nothing of the input's noise reaches the likelihood
            found = [(0.0, f"none: {kinds[0].kind} record, its windows free decays between the pulses (no input)")]
        elif self.input_noise is None:
            found = [input_noise_rms(r) for r in recs]
        else:
            found = [(float(self.input_noise), "given")]
        joint = len(recs) > 1
        found = found * len(recs) if joint and len(found) == 1 else found  # given, or none: each record's the same
        s_u = np.array([f[0] for f in found]) if joint else found[0][0]
        self.input_noise_ = ({"rms": [f[0] for f in found], "source": [f[1] for f in found]} if joint
                             else {"rms": found[0][0], "source": found[0][1]})  # fmt: skip
        if np.any(np.asarray(s_u) > 0):
            # the likelihood's own mode: generalised least squares under the input's noise (two passes, the
            # sensor's variance re-read between them); its solution is whitened (the curvature adjustment's)
            r = sol.fun
            for _ in range(2):
                ms = win.mean_square(r)  # the sensor's variance or more (it holds the input's noise too)
                win.set_input_noise(par.to_params(theta[None])[:, 0], par.kind, np.square(s_u), ms)
                s2 = win.noise_sigma2(r) if not joint else win.noise_sigma2_groups(r)
                theta, sol = self._map(par, win, theta, s2)
                r = win.residuals(win.simulate(par.to_params(theta[None]), par.kind)[0])[0].ravel()
            s2 = win.noise_sigma2(r) if not joint else win.noise_sigma2_groups(r)
            return par, win, theta, sol, (float(np.sqrt(s2)) if not joint else np.sqrt(s2))
        if joint:  # each record's own sensor noise: the MAP point weighs each record's residuals by it
            s2 = win.mean_square(sol.fun)
            theta, sol = self._map(par, win, theta, s2)
            r = win.residuals(win.simulate(par.to_params(theta[None]), par.kind)[0])[0].ravel()
            return par, win, theta, sol, np.sqrt(win.mean_square(r))
        sigma = math.sqrt(win.mean_square(sol.fun))  # sol.fun: the projected residuals at theta
        return par, win, theta, sol, sigma

    # --- the run --------------------------------------------------------------------------------
    def _check_record(self, rec: Measurement) -> None:
        at = element_of(self, rec)
        if at is not None:
            from negstiff.inference.estimators.posterior.structure import window_starts

            name = type(self).__name__
            if self.model != "coefficients":
                raise PosteriorError(f"{name}(model={self.model!r}): a structure's posterior samples its element's "
                                     "coefficients (model='coefficients')")  # fmt: skip
            if self.start is not None:
                from negstiff.inference.estimators.posterior.structure import given_start

                given_start(self.start, rec, at, name)  # a structure of this record's DOFs, masses and element
            if self.law_pair() is not None:
                raise PosteriorError(f"{name}(law={self.law!r}, damping={self.damping!r}): a structure's posterior "
                                     "samples its element's cubic coefficients (no law read yet)")  # fmt: skip
            if self.input_noise:
                raise PosteriorError(f"{name}(input_noise={self.input_noise!r}): the input's noise is not carried "
                                     "through a structure (None or 0 there)")  # fmt: skip
            window_starts(rec, self.window_s, self.max_windows)
            from negstiff.inference.estimators.sindy import SINDy

            SINDy(element=self.element).check(rec)  # its start's checks, before any work (a decay gone to noise)
            return
        from negstiff.inference.analysis.record_kind import check_decay, record_kind

        kind = record_kind(rec)
        if kind.kind == "decay":  # no input: a response that rings down (``check_decay``)
            check_decay(rec, "the posterior")
        else:
            rec.require_excitation("the posterior")
        rec.require_motion("the posterior")
        if kind.kind in RING_DOWN_KINDS and self.input_noise:
            raise PosteriorError(f"{type(self).__name__}(input_noise={self.input_noise!r}): a {kind.kind} "
                                 "record's windows are free decays between the pulses: no input's noise reaches "
                                 "them")  # fmt: skip
        u_rms = float(np.std(rec.u))
        if self.input_noise and not self.input_noise < u_rms:  # no start point had a positive density, after the bar
            unit = "m/s^2" if rec.input_name == "base_acc" else "N"
            raise PosteriorError(f"{type(self).__name__}(input_noise={self.input_noise:g}): the input's noise must be "
                                 f"below the input's own rms, {u_rms:.3g} {unit} on {rec.source} (the input would be "
                                 "its noise alone); None reads it from the input's spectrum")  # fmt: skip
        self._check_start_mass(rec)
        Windows.check(rec, self.window_s)

    def _check_start_mass(self, rec: Measurement) -> None:
        """Refuse a start model (``start``) of another mass than the record's (in the record's check, before the
        progress line and the bar; ``point_estimate`` checks it too).
        """
        start = self._device_start()
        if (
            self.model == "coefficients"
            and start is not None
            and rec.mass is not None
            and abs(start.m / rec.mass - 1) > 1e-6
        ):
            raise PosteriorError(f"{rec.source}: the start model's mass ({start.m:g} kg) is not the record's "
                                 f"({rec.mass:g} kg)")  # fmt: skip

    def _device_start(self) -> Model | None:
        """The single DOF's start model: ``start`` (a ``Model``, or the device's as a structure of one DOF or its
        identification). A structure's start on a single DOF's record is refused (one line, in the record's check).
        """
        from negstiff.inference.estimators.results import Identification
        from negstiff.models.structure import Structure

        s = self.start
        if isinstance(s, Identification) and s.linear_part == "none":
            return s.model
        if isinstance(s, Structure) and s.n_dof == 1 and tuple(s.place) == (0, 1):
            return s.element
        if s is None or isinstance(s, Model):
            return s
        what = f"an identification of a structure ({s.linear_part} linear part)" if isinstance(s, Identification) \
            else "a structure"  # fmt: skip
        raise PosteriorError(f"{type(self).__name__}(start=...): {what} starts a structure's posterior (element=); "
                             "a single DOF's starts from a Model or the device's identification")  # fmt: skip

    def check(self, data):
        """``Estimator.check``; a list or tuple of records (a lab's runs of one device, fitted together: the
        device's parameters shared, each record its own windows, input noise and sensor noise) is checked record by
        record and as a set: records of one kind (base, force, or ring-downs: hammer and decay together) with the
        same sampling rate, input and mass, and a structure's of the same DOFs, masses and element place (each record
        its own channels' zeros and sensor noise). Returns the list (one record: that record).
        """
        if not isinstance(data, (list, tuple)):
            return super().check(data)
        if not data:
            raise InputError(f"{type(self).__name__}.fit: an empty list of records")
        recs = [super(Posterior, self).check(r) for r in data]
        if len(recs) == 1:
            return recs[0]
        from negstiff.inference.analysis.record_kind import record_kind

        first, kind = recs[0], record_kind(recs[0]).kind
        at = element_of(self, first)
        for r in recs[1:]:
            name = f"{r.source} (fitted with {first.source})"
            if element_of(self, r) != at or r.n_dof != first.n_dof:
                raise PosteriorError(f"{name}: {r.n_dof} DOF(s), the element at {element_of(self, r)}; the first "
                                     f"{first.n_dof}, at {at}: one structure's records")  # fmt: skip
            if at is not None and not np.allclose(r.dof_masses, first.dof_masses, rtol=1e-6, atol=0.0):
                raise PosteriorError(f"{name}: its masses {list(r.dof_masses)} kg are not the first's "
                                     f"{list(first.dof_masses)} kg: one structure")  # fmt: skip
            if abs(r.fs / first.fs - 1) > 1e-9:
                raise PosteriorError(f"{name}: sampled at {r.fs:g} Hz, the first at {first.fs:g} Hz: the records "
                                     "fitted together share the windows' length (resample one)")  # fmt: skip
            if r.input_name != first.input_name:
                raise PosteriorError(f"{name}: its input is {r.input_name}, the first's {first.input_name}")
            if (r.mass is None) != (first.mass is None) or (r.mass is not None and first.mass is not None
                                                             and abs(r.mass / first.mass - 1) > 1e-6):  # fmt: skip
                raise PosteriorError(f"{name}: its mass ({r.mass}) is not the first's ({first.mass}): one device")
            other = record_kind(r).kind
            # a hammer's record and a free decay are read alike (windows of free decay between the pulses): a lab's
            # hammer test and its release test are fitted together; a forced record's windows carry its input
            if other != kind and not {other, kind} <= set(RING_DOWN_KINDS):
                raise PosteriorError(f"{name}: a {other} record, the first a {kind} record: records of one kind are "
                                     "fitted together (or a hammer's with free decays)")  # fmt: skip
        return recs

    def fit(self, rec: Measurement | list[Measurement]) -> Posterior:
        """Sample the posterior of ``rec``; the result is ``result_`` (a ``PosteriorResult``). A list of records of
        one device: their joint posterior (``check``), each record its own sensor noise (``sigma_1`` ..).
        """
        rec = self.check(rec)
        seed = seed_of(self.seed)  # None or a Generator: the integer drawn here, recorded in the settings
        at = element_of(self, rec[0] if isinstance(rec, list) else rec)
        if at is not None:
            return self._fit_structure(rec, at, seed)

        t_start = time.perf_counter()
        par, win, theta, sol, sigma = self.point_estimate(rec)
        recs = list(rec) if isinstance(rec, list) else [rec]
        rec = recs[0]
        sigmas = np.atleast_1d(np.asarray(sigma, float))  # a joint fit: each record's sensor noise
        R = sigmas.size
        # Laplace approximation at the MAP point, curvature-adjusted (``curvature_adjustment``): the sampler
        # works in coordinates whitened by its Cholesky factor, where the posterior is close to N(0, I)
        # (DE moves then decorrelate in ~10 steps). Along the device's E-m ridge, which the data do not
        # see, the scale is the mass prior's.
        free = par.free()
        x_scale = np.maximum(np.abs(theta), 1e-6)
        # the scores of the likelihood sampled (with the input's noise, ``sol`` holds the whitened residuals)
        sig = sigma if win.noise_basis is None and R == 1 else 1.0
        H_x, meat_x = information_parts(sol.jac, sol.fun, win.n_windows, sig)
        A_x, V_x, inflation = sandwich(H_x, meat_x if self.adjust else None)
        # the two parts in the parameters' own units: what a joint fit with another record adds to (a design's
        # prediction, ``analysis.design``)
        unit = 1.0 / np.outer(x_scale[free], x_scale[free])
        laplace = {"parameters": [par.names[i] for i in np.flatnonzero(free)],
                   "information": (H_x * unit).tolist(),
                   "score_covariance": None if meat_x is None else (meat_x * unit).tolist()}  # fmt: skip
        cov = np.zeros((theta.size, theta.size))
        cov[np.ix_(free, free)] = V_x * np.outer(x_scale[free], x_scale[free])
        for i, sd in par.fixed_sd.items():  # the likelihood does not see them: the prior's scale
            cov[i, i] = sd**2
        for i in np.flatnonzero(~(np.diag(cov) > 0)):
            cov[i, i] = (1e-3 * x_scale[i]) ** 2
        try:
            chol = np.linalg.cholesky(cov)
        except np.linalg.LinAlgError:
            chol = np.diag(np.sqrt(np.diag(cov)))
        q0 = np.concatenate([theta, np.log(sigmas)])
        scale = np.zeros((q0.size, q0.size))
        scale[:-R, :-R] = chol
        scale[-R:, -R:] = np.diag(1.0 / np.sqrt(2 * win.dof_groups()))  # the sd of each log sigma
        A_theta = A_x * np.outer(x_scale[free], 1.0 / x_scale[free])
        logpost = LogPosterior(par, win, q0, scale, (theta, A_theta, free) if self.adjust else None)

        nd = q0.size
        check_map_point(logpost, nd)
        logpost = self._pilot_whitened(logpost, nd, seed)
        run = sample_ensembles(
            logpost,
            nd,
            n_walkers=self.walkers(nd),
            n_ensembles=self.n_ensembles,
            seed=seed,
            tau_multiple=self.tau_multiple,
            min_steps=self.min_steps,
            max_steps=self.max_steps,
            chunk=self.chunk,
            progress=self.progress,
            chain_file=self.chains_to(logpost.q0, logpost.scale, nd, seed),
        )
        chains, taus, warn = run["chains"], run["tau"], run["warnings"]
        n_keep = min(c.shape[0] for c in chains)
        y = np.stack([c[-n_keep:] for c in chains])  # (E, S, W, nd)
        q = logpost.unwhiten(y.reshape(-1, nd))
        q[:, :-R] = par.physical(q[:, :-R])
        q = q.reshape(y.shape)
        q[..., -R:] = np.exp(q[..., -R:])
        names = tuple(par.names) + noise_names(R)
        tau_arr = np.array(taus)
        res = PosteriorResult(
            names=names,
            samples=q,
            summary={},
            tau=tau_arr,
            warnings=warn,
            settings={},
            map_point={n: float(v) for n, v in zip(names, np.concatenate([theta, sigmas]), strict=False)},
        )
        res.summary = summarise(res.samples, names, tau_arr, self.hdi_prob)
        warn += convergence_warnings(res.summary, self.n_ensembles)
        warn += k2_frame_warning(rec, res.summary)
        res.settings = {
            "model": self.model,
            "mass_prior": self.mass_prior if self.model == "device" else None,
            "mass": rec.mass,
            "window_s": self.window_s,
            "windows": win.n_windows,
            "max_windows": self.max_windows,
            "substeps": win.substeps,
            "curvature_adjustment": self.adjust,
            "input_noise": dict(self.input_noise_),
            "variance_inflation": [round(float(v), 3) for v in inflation],
            "laplace": laplace,
            "windows_dropped": [{"start_s": t, "rms_m": r} for t, r in win.dropped],
            "samples_used": int(win.n_windows * win.length),
            "walkers": self.walkers(nd),
            "ensembles": self.n_ensembles,
            "kept_steps_per_ensemble": int(n_keep),
            "tau_max_steps": float(np.nanmax(tau_arr)) if np.isfinite(tau_arr).any() else None,
            "likelihood_calls": logpost.calls,
            "priors": par.description,
            "seed": seed,
            "chain_file": None if self.chain_file is None else str(self.chain_file),
            "resumed_steps": run["resumed_steps"],
            "elapsed_s": time.perf_counter() - t_start,
            "moves": MOVES,
            "whitening": self.whitening_,
            "start": self.start_info_,
            "model_mass": float(par.to_params(theta[None])[ROWS["m"], 0]),
            "record_kind": self.record_kind_,
            "input": rec.input_name,
            "fs": rec.fs,
            "duration_s": [r.duration for r in recs] if R > 1 else rec.duration,
        }
        if par.law is not None:
            lm = par.law
            res.settings["law"] = {"restoring": lm.restoring.name, "damping": lm.damping.name,
                                   "title": f"{lm.restoring.title}; {lm.damping.title}",
                                   "parameters": list(par.names), "start_model": lm.start.to_dict(),
                                   "frame": ("the record's" if lm.shift < 0 else
                                             f"the parts' own: the record's z less {SHIFT} (its summary among the "
                                             "nuisance parameters; force_band is in the record's frame)")}  # fmt: skip
            res.force_band = force_band(par, res.samples[..., : theta.size + 1], stroke_of(rec), self.hdi_prob, seed,
                                        np.concatenate([theta, sigmas[:1]]))  # fmt: skip
        self.logpost_, self.par_, self.windows_ = logpost, par, win
        tau_max = np.nanmax(tau_arr) if np.isfinite(tau_arr).any() else np.nan  # too short a chain: no tau
        res.thin = max(1, int(np.ceil(tau_max / 2))) if np.isfinite(tau_max) else 1
        if R > 1:
            per = np.bincount(win.groups, minlength=R)
            res.settings["records"] = [{"source": str(r.source), "samples": int(r.n), "duration_s": r.duration,
                                        "windows": int(per[g])} for g, r in enumerate(recs)]  # fmt: skip
        res.provenance = provenance(" + ".join(str(r.source) for r in recs), res.settings)
        res.build_idata = functools.partial(_idata, res, y, logpost, win)
        self.result_ = res
        # unconverged chains, and the record's own warnings: in the result and through Python's warnings,
        # the convergence checks that failed as one warning (a short run fails every parameter's twice)
        lines = classified(rec, None, res.warnings)
        issue(one_convergence_warning(lines))
        self.warnings_ = [text for _, text in lines]
        self.record_ = dict(rec.info) if R == 1 else {"records": [dict(r.info) for r in recs]}
        return self

    def _fit_structure(self, data: Measurement | list[Measurement], at: tuple[int, int], seed: int) -> Posterior:
        """The element's posterior on a structure's record, or on several records of one structure fitted together
        (``posterior.structure``).
        """
        from negstiff.inference.estimators.posterior.structure import fit_structure

        recs = list(data) if isinstance(data, list) else [data]
        t_start = time.perf_counter()
        res, _, sim = fit_structure(self, recs, at, seed)
        res.settings["elapsed_s"] = time.perf_counter() - t_start
        res.provenance = provenance(" + ".join(str(r.source) for r in recs), res.settings)
        self.result_, self.windows_ = res, sim
        self.input_noise_ = dict(res.settings["input_noise"])
        lines = classified(recs[0], None, res.warnings)
        issue(one_convergence_warning(lines))
        self.warnings_ = [text for _, text in lines]
        self.record_ = dict(recs[0].info) if len(recs) == 1 else {"records": [dict(r.info) for r in recs]}
        return self


def stroke_of(rec: Measurement) -> tuple[float, float]:
    """The record's stroke: the 0.5 and 99.5 % quantiles of its z [m] (``steps.shape.stroke``)."""
    from negstiff.inference.steps.shape import stroke

    return stroke(rec)


def force_band(par: Parametrisation, samples: np.ndarray, stroke: tuple[float, float], prob: float, seed: int,
               map_point: np.ndarray) -> dict[str, Any]:  # fmt: skip
    """The restoring force's credible band over the record's stroke: K(z) [N] of at most ``FORCE_BAND_DRAWS``
    posterior draws (picked without replacement, seeded by ``seed``) on ``FORCE_BAND_POINTS`` displacements from the
    stroke's low to its high end, and each displacement's median and equal-tailed ``prob`` interval over the draws
    (pointwise: 5 and 95 % at ``prob`` 0.9), with the force at the MAP point. In the record's frame (its pinned z).
    """
    assert par.law is not None
    flat = np.asarray(samples).reshape(-1, samples.shape[-1])[:, :-1]  # sigma (the last) is no force's
    n = min(FORCE_BAND_DRAWS, flat.shape[0])
    rows = np.random.default_rng(seed).choice(flat.shape[0], n, replace=False)
    z = np.linspace(stroke[0], stroke[1], FORCE_BAND_POINTS)
    K = par.law.restoring_force(flat[rows], z)
    tail = 0.5 * (1.0 - prob)
    lo, med, hi = np.quantile(K, [tail, 0.5, 1.0 - tail], axis=0)
    return {"z_m": z.tolist(), "median_n": med.tolist(), "low_n": lo.tolist(), "high_n": hi.tolist(),
            "map_n": par.law.restoring_force(map_point[None, :-1], z)[0].tolist(), "prob": float(prob),
            "quantiles": [tail, 1.0 - tail], "draws": int(n), "stroke_quantiles": [0.005, 0.995],
            "mass_kg": float(par.law.start.m),
            "frame": "the record's z as the posterior read it (its pinned frame: record.response)"}  # fmt: skip


def moved_inside(par: Parametrisation, theta: np.ndarray) -> np.ndarray:
    """A start ``theta`` on or past a prior's bound moved inside (``Posterior._start``'s reasons): by 1e-6 of the
    prior's span, at most a tenth of its own size (at least 1e-9 of the span).
    """
    span = par.upper - par.lower
    margin = np.minimum(1e-6 * span, np.maximum(0.1 * np.abs(theta), 1e-9 * span))
    inside = np.where(theta >= par.upper, par.upper - margin, theta)
    return np.where(theta <= par.lower, par.lower + margin, inside)


def k2_frame_warning(rec: Measurement, summary: dict[str, Any]) -> list[str]:
    """The warning a ring-down's posterior carries where its k2 rests on z's zero more than on the data: about one
    well the record reads the restoring force's curvature there, K''(z*) = 2 k2 + 6 k3 z*, and with k0 a nuisance (a
    cubic with a free constant is the same model in any frame) k2 follows only from z's zero, which an offset d moves
    by 3 k3 d. Said where a zero off by the displacement's own noise (``Measurement.noise_floor``) moves it beyond its
    standard deviation (a symmetric Duffing's decay: k2 24.7 +- 9.9 for a truth of 0, unsaid before).
    """
    from negstiff.inference.analysis.record_kind import record_kind

    if "k2" not in summary or "k3" not in summary or rec.n_dof != 1 or record_kind(rec).kind not in RING_DOWN_KINDS:
        return []
    noise = math.sqrt(max(float(rec.noise_floor()[0]), 0.0))
    k2, k3 = summary["k2"], float(summary["k3"]["mean"])
    shift = 3 * abs(k3) * noise
    if not shift > k2["sd"]:
        return []
    return [
        f"k2 = {k2['mean']:.3g} +- {k2['sd']:.3g} holds for z's zero as measured: a ring-down about one well reads "
        f"the restoring force's curvature there (2 k2 + 6 k3 z*), and a zero off by the displacement's own noise "
        f"({1e6 * noise:.2g} um) moves k2 by 3 k3 d = {shift:.3g}, beyond its standard deviation"
    ]


def one_convergence_warning(lines: list[tuple[type, str]]) -> list[tuple[type, str]]:
    """``lines`` with the convergence checks that failed (R-hat, ESS, an ensemble's length) merged into one
    ``ConvergenceWarning``: the result lists each; a script sees one warning per run.
    """
    conv = [text for cat, text in lines if issubclass(cat, ConvergenceWarning)]
    if len(conv) <= 1:
        return lines
    merged = f"the posterior has not converged ({len(conv)} checks failed): " + "; ".join(conv)
    return [(ConvergenceWarning, merged), *((c, t) for c, t in lines if not issubclass(c, ConvergenceWarning))]


def _idata(res: PosteriorResult, y: np.ndarray, logpost: LogPosterior, win: Windows):
    """Arviz DataTree: posterior (thinned by half the autocorrelation time), sample stats, observed data
    and pointwise (per-window) log likelihood; and that log likelihood.

    ``chain`` is an independent ensemble: the walkers of one emcee ensemble move together (each move
    draws on the others), so they are not independent chains, and treating them as such made arviz's
    R-hat (1.08-1.10) disagree with the across-ensemble R-hat negstiff reports. A chain's ``draw`` runs
    walker by walker, each walker's steps in order (draw = walker x kept steps + step), so arviz's
    autocorrelation sees each walker's own series. Every dimension is named: ``window`` (the
    multiple-shooting windows), ``time`` (a window's samples), ``state`` (z, z_dot).
    """
    import arviz as az

    E, S, W, d = res.samples.shape
    th = res.thin
    post = np.moveaxis(res.samples[:, ::th], 2, 1)  # (E, W, S', d): walker-major within an ensemble
    Sp = post.shape[2]
    chains = post.reshape(E, W * Sp, d)
    q = np.moveaxis(y[:, ::th], 2, 1).reshape(E * W * Sp, d)
    ll = np.concatenate(
        [logpost.loglik(logpost.unwhiten(q[i : i + 2048]), pointwise=True) for i in range(0, q.shape[0], 2048)]
    ).reshape(E, W * Sp, -1)
    data = {
        "posterior": {n: chains[..., i] for i, n in enumerate(res.names)},
        "sample_stats": {"lp": ll.sum(axis=2)},
        "log_likelihood": {"z": ll},
        "observed_data": {"z": win.z},
        "constant_data": {"window_start_state": win.x0, "u": win.u},
    }
    dims = {"z": ["window", "time"], "window_start_state": ["window", "state"], "u": ["window", "input_time"]}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        tree = az.from_dict(data, dims=dims, coords={"state": ["z", "z_dot"]})
    # the run's provenance (record, settings, versions) travels with the data (NetCDF attributes)
    tree.attrs.update({k: v for k, v in res.provenance.items() if isinstance(v, (str, int, float))})
    return tree, ll
