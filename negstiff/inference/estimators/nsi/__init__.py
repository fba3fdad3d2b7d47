"""Nonlinear subspace identification (NSI): one estimator, its linear part what the record holds.

The nonlinear element's basis functions act as feedback forces on the underlying-linear system (ULS), identified
by the package's LTI subspace step (``subspace``) with the basis as inputs beside the excitation; the element's
coefficients come from the extended FRF (Marchesiello & Garibaldi 2008, MSSP 22:81-101; ``docs/algorithms.md``
part A). The linear part is:

- a single DOF on the base (``_well``): m, c and k about either stable well, the reference moved to the
  identified equilibrium each pass (the reference study's Eqs. 5-7), the shared stages after it (``Identifier``);
- a structure of N DOFs with its masses (``_physical``): M, C, K about each well, the element between DOFs I-J;
- a structure read through its sensors without masses (``_state_space``): a state-space model of the order the
  stabilisation diagram shows, the element sized through the measured driving point.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from tqdm import tqdm

from negstiff.errors import InputError
from negstiff.inference.analysis.record_kind import check_decay, identification_record, record_kind
from negstiff.inference.estimators.base import ElementPlace, element_of
from negstiff.inference.estimators.identification import Estimate, Identifier, check_ring_down_scores, visited_well
from negstiff.inference.estimators.parameters import DAMPING_LAW, FRACTION, RESTORING_LAW, Boolean, Interval, Pair
from negstiff.inference.estimators.results import StructureResults
from negstiff.inference.record.measurement import Measurement, per_unit_mass_warning
from negstiff.inference.steps.refine import stroke_quantiles
from negstiff.inference.steps.shape import fit_shape
from negstiff.inference.steps.weak import free_decay, known_input_gain, mass_of
from negstiff.inference.steps.wells import well_guesses
from negstiff.models import Model, laws
from negstiff.models.laws import FeedbackBasis
from negstiff.resources import on_fit_threads, thread_budget

from .. import subspace
from ._physical import identify_nsi
from ._physical import stabilisation as structure_stabilisation
from ._state_space import choose_state_space_law, identify_state_space
from ._well import (
    BASIS_NAMES,
    NSIError,
    WellFit,
    _stable_root,
    _WellForce,
    covers_band,
    decay_feedback,
    physical_pole,
    reduce,
)

Basis = FeedbackBasis
"""The name NSI's law basis had here (``laws.FeedbackBasis`` now): an NSI fitted and pickled before the move (its
``basis_``) still loads."""


class NSI(StructureResults, Identifier):
    """Nonlinear subspace identification around both stable wells, of a single DOF or of a structure of N DOFs
    carrying the element between DOFs I-J (``element``; ``_physical``).

    Each well's underlying-linear system and the nonlinear coefficients as feedback forces
    (``docs/methods/nsi.md``), combined into one z-frame model, validated on the held-out tail and
    refined by output error. scikit-learn style: configure, ``fit``, read the ``*_`` attributes.

    Parameters
    ----------
    order : int, default 2
        State dimension of the ULS model per DOF (2: a single-degree-of-freedom device; a record of N DOFs is
        identified at order x N).
    block_rows : int, default 30
        Block rows i of the Hankel matrices.
    band : (float, float), default (0.6, 1.6)
        Fractions of the well frequency over which Re(c_j) is averaged.
    validation_fraction : float, default 0.2
        Held-out tail for the free-run validation (the contract's last 20 %).
    passes : int, default 2
        Identification passes per well at most (each at the z* refined by the previous one; the loop
        stops when the shift falls below 0.1 % of the motion's spread).
    refine : bool or None, default None
        Finish by output-error refinement (kept only if it predicts the held-out tail no worse; a structure's over
        every channel, its channels' zeros with it: ``structure_result``). None: run it, but on a structure read
        through its sensors without masses (a state-space linear part, not refined: ``refine=True`` there is one
        ``InputError``).
    progress : bool, default False
        A progress bar over the identification passes on stderr, shown once they take more than 2 s.
    element : str or (int, int), optional
        Where the element acts on a record of N > 1 DOFs: ``"I-J"``, it moves DOF J relative to DOF I (0: the
        base). None: the single DOF (on the base). Its result is an ``Identification`` for any N
        (``structure_``, ``element_``, ``offsets_``).

    law : str or None, default None
        The restoring-force law (``models.laws``: ``"cubic"``, ``"quintic"``, ``"septic"``, ``"magnet"``,
        ``"oblique_springs"``, ``"geometric"``, ``"spline"``) whose columns the method reads, a shaped part's shape
        found on the record (``shape.fit_shape``); ``"auto"``: every law estimated and the one that predicts the
        record best kept (``law_choice``); None: the method's own default (the cubic), the other laws
        compared where it fails its checks, and said.
    damping : str, default "quadratic"
        The damping law read with ``law`` (``"viscous"``, ``"quadratic"``, ``"cubic_damping"``, ``"friction"``).

    Attributes
    ----------
    result_ : Identification
        Everything ``fit`` learned; ``result()`` is the contract's JSON.
    model_ : Model
        The final model (refined, where that predicted no worse).
    initial_model_ : Model
        NSI's own (equation-error) estimate.
    modal_ : dict
        ``{"minus", "plus"}`` -> ``{"f_hz", "zeta"}`` of each well's underlying-linear system.
    wells_ : dict
        Each well's fit: its reference z*, frequency, damping and coefficients.
    validation_ : Bunch
        The free run over the held-out tail (``rms_percent``, ``restarted_rms_percent``, ...).
    warnings_ : list of str
        Every warning about the record and the result (also issued as ``NegstiffWarning``).

    Examples
    --------
    >>> from negstiff import Measurement, NSI, Rig
    >>> from negstiff.models import SEED_LIKE_CUBIC
    >>> rec = Measurement.from_rig(Rig(SEED_LIKE_CUBIC, seed=1).random(duration=30.0, rms=20.0))
    >>> nsi = NSI().fit(rec)
    >>> abs(nsi.model_.k3 / SEED_LIKE_CUBIC.k3 - 1) < 0.02       # the truth within 2 %
    True
    >>> sorted(nsi.modal_)
    ['minus', 'plus']
    """

    method = "nsi"
    reads_sensors_without_masses = True
    """A structure's record without masses is read through a state-space linear part (``_state_space``)."""
    _parameter_constraints = {
        "order": Interval(int, 2, 20, even=True),  # two states per mode: an odd order splits one
        "block_rows": Interval(int, 2, 500),
        "band": Pair(Interval(float, 0.0, 10.0, lo_open=True)),
        "validation_fraction": FRACTION,
        "passes": Interval(int, 1, 20),
        "refine": Boolean(none=True),
        "progress": Boolean(),
        "element": ElementPlace(),
        "law": RESTORING_LAW,
        "damping": DAMPING_LAW,
    }

    def __init__(
        self,
        *,
        order: int = 2,
        block_rows: int = 30,
        band: tuple[float, float] = (0.6, 1.6),
        validation_fraction: float = 0.2,
        passes: int = 2,
        refine: bool | None = None,
        progress: bool = False,
        element: str | tuple[int, int] | None = None,
        law: str | None = None,
        damping: str = laws.DEFAULT_DAMPING,
    ):
        self.element = element
        self.law = law
        self.damping = damping
        self.order = order
        self.block_rows = block_rows
        self.band = band
        self.validation_fraction = validation_fraction
        self.passes = passes
        self.refine = refine
        self.progress = progress

    # --- one well ----------------------------------------------------------------------------
    def extended_input(
        self, rec: Measurement, zs: np.ndarray, v: np.ndarray, z_ref: float, basis: FeedbackBasis | None = None
    ):
        """The subspace step's problem about ``z_ref``: x = z - z_ref, the standardised input channels (the
        input and the basis functions' negatives, ``FeedbackBasis``; a free decay's: the basis functions alone), their
        scales and means, and the map from the channels' combinations back to the basis functions (``reduce``).
        ``zs`` and ``v`` are the record's band states (``states("band")``); the basis is built from them
        low-passed (``Measurement.basis_states``). ``basis`` None: the cubic's with the reference study's damping.
        """
        basis = FeedbackBasis(laws.get("cubic"), laws.get("quadratic"), {}) if basis is None else basis
        x = zs - z_ref
        zb, vb = rec.basis_states()  # the band states without the noise's band, computed once per record
        xb = zb - z_ref
        functions = np.column_stack([basis.displacement(xb, z_ref), basis.velocity(vb)])
        combine = reduce(functions)
        if combine.shape != (functions.shape[1],) * 2 or np.any(combine != np.eye(functions.shape[1])):
            functions = functions @ combine
        chans = -functions
        if not free_decay(rec):  # no input: the feedback channels alone drive the ULS from its initial state
            lin = -rec.u if rec.input_name == "base_acc" else rec.u
            chans = np.column_stack([lin, chans])
        means = chans.mean(axis=0)
        scale = chans.std(axis=0)
        if np.any(scale == 0):
            raise NSIError(f"{rec.source}: not enough excitation: the input or a basis function is constant")
        w = (chans - means) / scale
        if np.linalg.cond(np.corrcoef(w.T)) > 1e8:
            raise NSIError(
                f"{rec.source}: not enough excitation: the basis functions are collinear (the record "
                "does not reach the nonlinear range)"
            )
        return x, w, scale, means, combine

    def fit_well(self, rec: Measurement, zs: np.ndarray, v: np.ndarray, z_ref: float, bar=None,
                 basis: FeedbackBasis | None = None) -> WellFit:  # fmt: skip
        """Identify the ULS and the nonlinear coefficients around ``z_ref``.

        Each pass identifies about the current reference z_g, then moves the reference to the identified
        restoring force's stable root r nearest z_g. The reported ULS (f, zeta) is the last pass's pole; the
        shifted coefficients (k1~, k2~, k3: the force's derivatives at the root) are the last pass's force's at r
        (reference study Eq. 7 for the cubic), so that K(z*) = 0 there. ``bar`` (a tqdm bar, optional) is
        advanced by ``passes`` over the well, one per pass. ``basis``: the law's (``FeedbackBasis``; None: the cubic's).
        """
        basis = FeedbackBasis(laws.get("cubic"), laws.get("quadratic"), {}) if basis is None else basis
        names = basis.names()
        n_disp = len(names) - basis.velocity(np.zeros(1)).shape[1]
        routes = []
        span = float(np.ptp(zs))
        for done in range(1, self.passes + 1):
            x, w, scale, means, combine = self.extended_input(rec, zs, v, z_ref, basis)
            y = x - x.mean()
            ys = y.std()
            try:
                ss = subspace.identify(w, (y / ys)[:, None], rec.dt, self.order, self.block_rows)
            except (ValueError, np.linalg.LinAlgError) as exc:
                raise NSIError(f"{rec.source}: subspace step failed ({exc})") from None
            routes.append(str(ss.lq_route))
            decay = free_decay(rec)
            lam = physical_pole(ss, None if decay else 0)
            wn, zeta = abs(lam), -lam.real / abs(lam)
            fn = wn / (2 * math.pi)
            band = (self.band[0] * fn, self.band[1] * fn)
            freqs = np.linspace(band[0], band[1], 64)
            if decay:
                he = ss.frf(freqs)[:, 0, :]
                ratio = decay_feedback(ss, freqs, wn, zeta, ys / scale)
                coef = ratio.real.mean(axis=0)
                quality = np.abs(ratio.imag).mean(axis=0) / np.maximum(np.abs(coef), 1e-300)
                gain_est = gain = 1.0  # per unit mass: the ULS's own x'' + 2 zeta wn x' + wn^2 x (no input to scale)
                combined = coef
            else:
                he = ss.frf(freqs)[:, 0, :]
                ratio = he[:, 1:] / he[:, :1] * (scale[0] / scale[1:])
                coef = ratio.real.mean(axis=0)
                quality = np.abs(ratio.imag).mean(axis=0) / np.maximum(np.abs(coef), 1e-300)
                # input gain b of x'' + ... = b u, from the discrete-time FRF level: exactly 1 for base
                # excitation (the estimate is kept as a check), 1/m for a force record. The ratios give
                # c_j / b, so b * ratio is per unit mass, like the pole's k/m and c/m.
                hd = ss.frf_discrete(freqs)[:, 0, 0] * ys / scale[0]
                w_ = 2 * np.pi * freqs
                gain_est = float(np.mean((hd * (wn**2 - w_**2 + 2j * zeta * wn * w_)).real))
                gain = 1.0 if rec.input_name == "base_acc" else gain_est
                # the ratios c_j / b need the input's FRF over the band; an input that does not cover the band
                # (a harmonic one: a line) leaves it to the model's extrapolation, 2 % low on a chaotic harvester
                # record (measured), and every coefficient 2 % high. The feedback channels are then read
                # against the pole's own FRF at the known gain (b_est * ratio: as for a force record).
                narrow = rec.input_name == "base_acc" and not covers_band(rec.u, rec.fs, band)
                combined = (gain_est if narrow else gain) * coef
            # time-averaged equation of motion (channels hold -g_j): the constant K(z_g)/m
            const = (
                (0.0 if decay else gain * means[0])
                - wn**2 * x.mean()
                - 2 * zeta * wn * v.mean()
                - (v[-1] - v[0]) / (v.size * rec.dt)  # mean acceleration over the record
                + sum(c * means[j + (0 if decay else 1)] for j, c in enumerate(combined))
            )
            c = combine @ combined  # each basis function's coefficient
            # restoring force about z_g, per unit mass: const + wn^2 x + sum_j c_j D_j(x)
            force = _WellForce(basis, z_ref, const, wn**2, np.asarray(c[:n_disp], float))
            r = _stable_root(force, span)
            if r is None:
                raise NSIError(
                    f"{rec.source}: the identified restoring force has no stable equilibrium near "
                    f"z = {z_ref * 1e3:.2f} mm"
                )
            z_ref = z_ref + r
            if bar is not None:
                bar.update()
            if abs(r) < 1e-3 * zs.std():  # already at the well: another pass would change nothing
                if bar is not None:
                    bar.update(self.passes - done)
                break
        assert r is not None  # every pass found its root or raised
        d1, d2, d3 = force.derivatives(r)
        damping = dict(zip(names[n_disp:], c[n_disp:], strict=True))
        coefficients = {
            "k1_tilde": d1,
            "k2_tilde": d2 / 2,
            "k3": d3 / 6,
            "c": 2 * zeta * wn,
            "c_nl": damping.get("vabsv", 0.0),
            "const_residual": const,
            "shift_last_pass": r,
            "input_gain": gain_est,
            **({} if names == BASIS_NAMES else {"basis": dict(zip(names, c.tolist(), strict=True))}),
        }
        w_ = 2 * np.pi * freqs
        h0 = 1.0 / (wn**2 - w_**2 + 2j * zeta * wn * w_) if decay else he[:, 0] * ys / scale[0]
        return WellFit(
            z_ref,
            fn,
            zeta,
            coefficients,
            dict(zip(names, quality, strict=False)) if combine.shape[1] == len(names) else {},
            band,
            list(ss.singular_values[:8]),
            {
                "f_hz": freqs,
                "H": h0,
                "ratio": ratio,
                "poles": [(abs(p) / (2 * math.pi), -p.real / abs(p)) for p in ss.poles() if p.imag >= 0],
            },
            tuple(routes),
            force=force,
            damping_coefficients=(2 * zeta * wn, *c[n_disp:]),
        )

    def _check_record(self, rec: Measurement) -> None:
        at = element_of(self, rec)
        rec.require(max(2000, 40 * self.block_rows), "NSI")
        if record_kind(rec).kind != "decay":
            rec.require_excitation("NSI")
        else:
            check_decay(rec, "NSI")
        rec.require_motion("NSI")
        if at is not None:
            check_ring_down_scores(self, rec)
        self._check_response(rec)

    def fit(self, data) -> NSI:
        """Identify from ``data`` (a ``Measurement`` or a file path): a single DOF's record through the shared
        stages (``Identifier.fit``), a structure's (N > 1 DOFs) through ``_physical.identify_nsi``.

        A single DOF's record is read by its kind (``record_kind``): a hammer's force windowed (each hit's
        offset removed, zero between the pulses), a free decay (an input at its floor throughout) through the
        decay form (``decay_feedback``); the kind is the result's ``record_kind``.
        """
        rec = self.check(data)
        at = element_of(self, rec)
        kind = record_kind(rec)
        self.record_kind_ = kind
        if at is None:
            return super().fit(identification_record(rec, kind))
        if rec.masses is None:
            # the masses unknown: the linear part a state-space model of the order the record shows, the element
            # sized through the measured driving point (``_state_space``), its basis the law's
            self.result_ = (choose_state_space_law(self, rec, at) if self.law == "auto"
                            else identify_state_space(self, rec, at))  # fmt: skip
        elif self.law is not None:
            raise InputError(
                f"{type(self).__name__}(law={self.law!r}): a structure with its masses reads the cubic element "
                "(element=); give no law, or leave the masses out (its element then reads the law)"
            )
        else:
            self.result_ = identify_nsi(self, identification_record(rec, kind), at)
        return self

    def _fit_wells(self, rec: Measurement, zs: np.ndarray, v: np.ndarray, refs: dict[str, float | None], bar,
                   basis: FeedbackBasis) -> dict[str, WellFit]:  # fmt: skip
        """``fit_well`` about each reference of ``refs`` that is not None, in its order; two wells on two threads
        where the command's budget has two cores (``resources.thread_budget``): each well's subspace steps are its own
        (BLAS on one thread each, ``fit_threads``), so the numbers are those of one thread, and their linear algebra
        releases the interpreter.
        """
        todo = {name: ref for name, ref in refs.items() if ref is not None}
        rec.basis_states()  # made once, before the threads read it
        if len(todo) < 2 or thread_budget() < 2:
            return {name: self.fit_well(rec, zs, v, ref, bar, basis) for name, ref in todo.items()}
        from concurrent.futures import ThreadPoolExecutor

        with ThreadPoolExecutor(len(todo)) as pool:
            futures = {name: pool.submit(self.fit_well, rec, zs, v, ref, bar, basis) for name, ref in todo.items()}
            return {name: f.result() for name, f in futures.items()}

    def _estimate(self, rec: Measurement, n_id: int, law: laws.Law | None = None) -> Estimate:
        """NSI's own estimate: each well's underlying-linear system and nonlinear coefficients from the
        identification part, averaged into one z-frame model (the shared stages follow: ``Identifier``); the
        nonlinear basis is ``law``'s (None: the cubic) and the damping law's (``FeedbackBasis``), a shaped part's
        shape the record's (``shape.fit_shape``).
        """
        ident = rec.segment(0, n_id)
        restoring, damping = laws.get(law or laws.DEFAULT_RESTORING, "restoring"), laws.get(self.damping, "damping")
        shape_fit = None
        if restoring.shaped():
            shape_fit = fit_shape(ident, restoring, damping, n_fit=int(round(0.75 * n_id)), n_id=n_id)
        basis = self.basis_ = FeedbackBasis(restoring, damping, {} if shape_fit is None else shape_fit.shape)
        zs, v, _, band = ident.states("band")
        z_minus, z_plus = well_guesses(ident, restoring, damping, basis.shape)
        bar = tqdm(
            total=self.passes * (1 if z_minus is None else 2), desc="NSI passes", unit="pass", leave=False,
            disable=not self.progress, delay=2.0,
        )  # fmt: skip
        with bar:
            wells = self._fit_wells(ident, zs, v, {"plus": z_plus, "minus": z_minus}, bar, basis)
        gains = [w.coefficients["input_gain"] for w in wells.values()]
        # the one mass rule (``weak.mass_of``): a force record without a mass gets it from the FRF level (b = 1/m);
        # a free decay has no input to scale by: the mass given, else per unit mass
        if free_decay(rec):
            mass, mass_source = mass_of(rec, 1.0, 1.0)
            gains = [1.0 / mass]
        else:
            mass, mass_source = mass_of(rec, known_input_gain(rec), float(np.mean(gains)), what="the FRF level")
        stroke = (float(zs.min()), float(zs.max()))
        frames = [self._z_frame(w, basis, stroke) for w in wells.values()]
        try:
            models = [laws.compose(restoring, damping, f, mass, basis.shape) for f in frames]
            model = laws.compose(restoring, damping, np.mean(frames, axis=0), mass, basis.shape)
        except InputError as exc:  # a law's part outside its physical range (a rod frame's negative stiffness)
            raise NSIError(f"{rec.source}: the {restoring.name} law's identified parameters are not physical for "
                           f"this record ({' '.join(str(exc).split())})") from None  # fmt: skip
        try:
            model.equilibria()  # usable: a bistable or single-well restoring force
        except ValueError as exc:  # a well's fit that is no bistable oscillator: the record's verdict, not a bug
            raise NSIError(f"{rec.source}: the identified restoring force is not usable ({exc})") from None
        q = stroke_quantiles(ident.displacement)
        if z_minus is None and visited_well(rec, z_plus, (model,), (float(q[0]), float(q[-1]))) == "minus":
            wells = {"minus": wells["plus"]}  # one well visited: named by where it lies (``visited_well``)
        self.wells_ = wells
        self.models_by_well_ = {name: mm for name, mm in zip(wells, models, strict=False)}
        modal: dict[str, dict[str, float | None]] = {
            w: {"f_hz": wells[w].f_hz, "zeta": wells[w].zeta} if w in wells else {"f_hz": None, "zeta": None}
            for w in ("minus", "plus")
        }
        return Estimate(
            model=model,
            mass_source=mass_source,
            input_gain=float(np.mean(gains)),
            modal=modal,
            warnings=(
                *(
                    f"NSI's basis is the restoring force's and the damping's: the record's measured channel {a!r} is "
                    "not used (SINDy and the discrepancy workflow offer it as a term)"
                    for a in rec.aux
                ),
                *filter(None, [per_unit_mass_warning(rec)]),
            ),
            details={"wells": self._wells_json(), **self._kind_json()},
            settings={
                "order": self.order,
                "block_rows": self.block_rows,
                "band_fraction": list(self.band),
                "passes": self.passes,
                "velocity": f"Savitzky-Golay (window, order) = {band['window']}",
                "basis": list(basis.names()),
                "law": restoring.name,
                "damping_law": damping.name,
                **({} if shape_fit is None else {"shape": shape_fit.to_json()}),
            },
        )

    def _renamed_well(self, old: str, new: str) -> None:
        """The one well's fit and model under the name the final model gives it (``Identifier._name_own_well``)."""
        self.wells_ = {new if w == old else w: fit for w, fit in self.wells_.items()}
        self.models_by_well_ = {new if w == old else w: mm for w, mm in self.models_by_well_.items()}

    def _final_details(self, rec: Measurement, model: Model, details: dict[str, Any]) -> dict[str, Any]:
        """``g_estimate``: the final model's k0/m, the gravity the record's own physics carries (base excitation)."""
        return {**details, "g_estimate": model.k0 / model.m if rec.input_name == "base_acc" else None}

    def _kind_json(self) -> dict[str, Any]:
        kind = vars(self).get("record_kind_")
        return {} if kind is None else {"record_kind": {"kind": kind.kind, "how": kind.how}}

    def _wells_json(self) -> dict[str, Any]:
        return {
            name: {
                "z_ref": w.z_ref,
                "f_hz": w.f_hz,
                "zeta": w.zeta,
                "coefficients": w.coefficients,
                "quality_im_over_re": w.quality,
                "band_hz": list(w.band_hz),
                "singular_values": w.singular_values,
                "lq_routes": list(w.lq_routes),
                "z_frame_model": self.models_by_well_[name].to_dict(),
            }
            for name, w in self.wells_.items()
        }

    @on_fit_threads  # its subspace steps are ``fit``'s: BLAS on ``fit``'s threads, whatever the process's pool (on
    # the pool's, one reproduce's diagram differed from another's in one entry, at 1e-15)
    def stabilisation(self, rec: Measurement, orders=(2, 4, 6, 8), block_rows=(10, 20, 30, 40)) -> list[dict]:
        """Stabilisation diagram (Marchesiello, Fasana & Garibaldi 2016; algorithms.md A.5): for each
        (order, block rows) and each well found by ``fit``, every identified pole and the physical
        pole's coefficients. Run after ``fit`` (it reuses the refined wells).
        """
        if rec.n_dof > 1:
            orders_n = tuple(o * rec.n_dof for o in orders)  # the order per DOF, as ``order``
            return structure_stabilisation(self, rec, orders=orders_n, block_rows=block_rows)
        n_id = self.settings_["identification_samples"]
        ident = rec.segment(0, n_id)
        zs, v, _, _ = ident.states("band")
        rows = []
        for name, well in self.wells_.items():
            for i in block_rows:
                for n in orders:
                    est = NSI(order=n, block_rows=i, band=self.band, passes=1)
                    try:
                        wf = est.fit_well(ident, zs, v, well.z_ref, basis=vars(self).get("basis_"))
                    except NSIError as exc:
                        rows.append({"well": name, "order": n, "block_rows": i, "error": str(exc)})
                        continue
                    rows.append(
                        {
                            "well": name,
                            "order": n,
                            "block_rows": i,
                            "f_hz": wf.f_hz,
                            "zeta": wf.zeta,
                            "coefficients": wf.coefficients,
                            "poles": wf.frf["poles"],
                        }
                    )
        return rows

    @staticmethod
    def _z_frame(w: WellFit, basis: FeedbackBasis, stroke: tuple[float, float]) -> np.ndarray:
        """A well's model as the law's z'' coefficients per unit mass (``models.laws``' column order, restoring then
        damping): the law's restoring columns fitted by least squares to the well's identified force over the
        stroke (exact where the law holds the force: the cubic's re-expansion, reference study Eq. 7), its damping
        the well's.
        """
        z = np.linspace(stroke[0], stroke[1], 401)
        C = basis.restoring.columns(z, np.zeros_like(z), basis.shape)
        scale = np.where(np.ptp(C, axis=0) > 0, C.std(axis=0), np.abs(C).mean(axis=0))
        scale[scale == 0] = 1.0
        theta = np.linalg.lstsq(C / scale, w.force.at(z), rcond=None)[0] / scale
        return -np.concatenate([theta, w.damping_coefficients])
