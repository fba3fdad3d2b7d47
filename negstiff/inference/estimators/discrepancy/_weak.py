"""The weak-form systems the discrepancy workflow fits: the library's columns, a law's own at its shape, the measured
channels' and an end stop's at its searched onset, each projected once per span; their least squares with the
input's coefficient fixed by physics, and the model each fit gives.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from negstiff.errors import MeasurementError
from negstiff.inference.estimators.base import Estimator
from negstiff.inference.record.measurement import Measurement
from negstiff.inference.steps.shape import ShapeFit, fit_shape
from negstiff.inference.steps.weak import WeakForm, known_input_gain, mass_of, model_from, test_function
from negstiff.inference.steps.weak import terms as library_terms
from negstiff.models import Model, laws

from ._candidates import STOP_MIN_SAMPLES, DiscrepancyError, _damping_of, _displacement_labels, _stop


class WeakSystems(Estimator):
    """The weak-form systems and fits of the discrepancy workflow (its first layer; the state a fit learns is the
    estimator's own, ``*_`` attributes and the fit's private caches).
    """

    def _systems(self, rec: Measurement) -> None:
        n_id = int(round(rec.n * (1 - self.validation_fraction)))
        n_fit = int(round(rec.n * (1 - self.validation_fraction - self.selection_fraction)))
        ident = rec.segment(0, n_id)
        self._form = WeakForm.of(ident)
        self._zs, self._v = self._form.zs, self._form.v
        # the measured states the gap's free runs start from, whole record (before and after share them)
        self._z0, self._v0, _, _ = rec.states("state")
        self._gain = known_input_gain(rec)
        self.n_id_, self.n_fit_ = n_id, n_fit
        self._library_systems: dict[tuple[int, int], tuple[Measurement, np.ndarray, np.ndarray]] = {}
        self._aux_columns: dict[tuple[int, int, str], tuple[Measurement, np.ndarray]] = {}
        self._law_columns: dict[tuple[int, int, str], tuple[Measurement, np.ndarray]] = {}
        self._shapes: dict[str, ShapeFit | str] = {}  # each law's shape on the record, or why it has none

    def _damping_law(self) -> str:
        """The damping law the laws' shapes are fitted with: ``damping``, else the one whose columns are the
        baseline's velocity terms (the reference study's ``quadratic`` where none is).
        """
        if self.damping is not None:
            return self.damping
        return _damping_of(tuple(t for t in self.baseline if t not in _displacement_labels())) or laws.DEFAULT_DAMPING

    def _shape(self, rec: Measurement, law: str) -> ShapeFit:
        """``law``'s shape on the record (``shape.fit_shape`` on the fitting part, a spline's knots scored on the
        selection part), found once; ``DiscrepancyError`` saying why where it has none.
        """
        hit = self._shapes.get(law)
        if hit is None:
            try:
                hit = fit_shape(rec, law, self._damping_law(), n_fit=self.n_fit_, n_id=self.n_id_,
                                window_s=self.window_s)  # fmt: skip
            except (MeasurementError, ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
                hit = " ".join(str(exc).split()) or type(exc).__name__
            self._shapes[law] = hit
        if isinstance(hit, str):
            raise DiscrepancyError(f"{rec.source}: the {law} law has no shape on this record: {hit}")
        return hit

    def _law_extra(self, law: str | None) -> tuple[str, ...]:
        """The columns of ``law`` (at its shape) that the catalogue has not (a shaped part's, z^6, z^7), in the
        law's order; none without a law.
        """
        if law is None:
            return ()
        lw = laws.get(law)
        known = set(library_terms())
        labels = [c.label for c in lw.column_list(self._shapes_of(law))]
        return tuple(t for t in labels if t not in known)

    def _shapes_of(self, law: str) -> dict[str, Any]:
        """The shape fields of ``law``'s shaped parts (empty for a law without: no fit needed)."""
        if not laws.get(law).shaped():
            return {}
        hit = self._shapes.get(law)
        assert isinstance(hit, ShapeFit), f"the {law} law's shape is sought first (_shape)"
        return hit.shape

    def _law_terms(self, law: str) -> tuple[str, ...]:
        """The restoring force's columns of ``law`` (labels, at its shape)."""
        return tuple(c.label for c in laws.get(law).column_list(self._shapes_of(law)))

    def _restoring_terms(self, terms, law: str | None) -> tuple[str, ...]:
        """The restoring force's share of ``terms``: the displacement-only catalogue terms and ``law``'s own."""
        own = set(_displacement_labels()) | set(self._law_extra(law))
        return tuple(t for t in terms if t in own)

    def _n_parameters(self, terms, law: str | None) -> int:
        """The restoring force's parameters: its columns' coefficients and its shaped parts' searched shape fields
        (a spline's knots are set by the stroke: none).
        """
        shape = 0 if law is None else sum(len(p.shape_bounds((-1.0, 1.0))) for p in laws.get(law).shaped().values())
        return len(self._restoring_terms(terms, law)) + shape

    def _design(self, rec: Measurement, lo: int, hi: int, stop: float | None, aux: tuple[str, ...] = (),
                law: str | None = None):  # fmt: skip
        """Weak system over samples [lo, hi): the library's columns, the input's, a column per measured
        auxiliary channel in ``aux`` (its projection, like the input's), ``law``'s columns the catalogue has not
        (``_law_extra``, at its shape) and an end-stop column last. The library's part is projected once per span
        and record (a fit asks for the same two spans ~75 times, one per candidate stop and effect: 16 of a
        discrepancy study's 36 s went to projecting them again), a law's once per span too.
        """
        hit = self._library_systems.get((lo, hi))
        if hit is None or hit[0] is not rec:
            sysd = self._form.system(rec, lo, hi)
            read = self._between_pulses(rec, lo, hi, sysd.y_physical.size)
            hit = (rec, sysd.W_physical * read[:, None], sysd.y_physical * read)
            for a in hit[1:]:
                a.setflags(write=False)
            self._library_systems[(lo, hi)] = hit
        W, y = hit[1], hit[2]
        for name in aux:  # projected once per span like the library (the stop's column moves; these do not)
            cached = self._aux_columns.get((lo, hi, name))
            if cached is None or cached[0] is not rec:
                Wa = self._form.project(np.asarray(rec.aux[name][lo:hi], float)[:, None], rec.dt)[:, 0]
                cached = self._aux_columns[(lo, hi, name)] = (rec, Wa)
            W = np.column_stack([W, cached[1][: W.shape[0]]])
        extra = self._law_extra(law)
        if extra:
            assert law is not None
            cached = self._law_columns.get((lo, hi, law))
            if cached is None or cached[0] is not rec:
                lw = laws.get(law)
                at = [i for i, c in enumerate(lw.column_list(self._shapes_of(law))) if c.label in extra]
                with np.errstate(invalid="ignore", over="ignore"):
                    cols = lw.columns(self._zs[lo:hi], self._v[lo:hi], self._shapes_of(law),
                                      self._form.velocity_noise)[:, at]  # fmt: skip
                cached = self._law_columns[(lo, hi, law)] = (rec, self._form.project(cols, rec.dt))
            W = np.column_stack([W, cached[1][: W.shape[0]]])
        if stop is not None:
            z = self._zs[lo:hi]
            col = _stop()[1].column(z, stop)
            Ws = self._form.project(col[:, None], rec.dt)[:, 0]
            W = np.column_stack([W, Ws[: W.shape[0]]])
        if aux or extra or stop is not None:  # a row the library's part does not read (``_between_pulses``) reads none
            W = W * self._between_pulses(rec, lo, hi, y.size)[:, None]
        return W, y

    def _between_pulses(self, rec: Measurement, lo: int, hi: int, rows: int) -> np.ndarray:
        """Which of the ``rows`` weak-form rows of samples [lo, hi) the fits read (1.0) and which they do not (0.0):
        on a hammer's record (``record_kind``) a row whose test function holds a sample of a pulse is not read (the
        hits set the ring-downs' states, the rows after them read the ring-downs, as its restarted windows start
        after the pulses: ``_after_pulses``); on any other record every row. A pulse of a few samples is not
        resolved by its samples (a 40 N, 4 ms half-sine at 1 kHz integrates 5 % short, its phase decides), and the
        rows across it made the fit trade the missing impulse for damping: on the seed-like double well hit four
        times, c 0.561 and c_nl -0.303 against 0.5 and 0, the held-out gap 3.9 % against the true model's 0.32 %;
        with them not read, c 0.5006, c_nl -0.003, the gap 0.36 % (1 um of noise, measured).
        """
        kind = vars(self).get("record_kind_")
        if kind is None or kind.kind != "impact":
            return np.ones(rows)
        support = test_function(self._form.half, rec.dt)[0].size
        busy = np.concatenate([[0], np.cumsum(np.asarray(rec.u)[lo:hi] != 0)])
        first = np.minimum(np.arange(rows) * self._form.stride, hi - lo)
        last = np.minimum(first + support, hi - lo)
        return ((busy[last] - busy[first]) == 0).astype(float)

    def _fit(self, W: np.ndarray, y: np.ndarray, terms: tuple[str, ...], stop: bool, n_aux: int = 0,
             law: str | None = None) -> np.ndarray:  # fmt: skip
        """Least squares on ``terms`` (+ the auxiliary channels' and the stop's columns), the input's
        coefficient fixed by physics; ``law``: the restoring law whose own columns (``_design``) ``terms`` may name.
        """
        lib = library_terms()
        n_lib = len(lib)
        extra = self._law_extra(law)
        aux_cols = list(range(n_lib + 1, n_lib + 1 + n_aux))  # after the input's; the law's next, the stop's last
        index = {t: i for i, t in enumerate(lib)} | {t: n_lib + 1 + n_aux + j for j, t in enumerate(extra)}
        cols = [index[t] for t in terms] + aux_cols + ([W.shape[1] - 1] if stop else [])
        target = y.copy()
        if self._gain is not None:
            target = target - self._gain * W[:, n_lib]
        else:
            cols = cols + [n_lib]
        A = W[:, cols]
        scale = np.sqrt(np.mean(A**2, axis=0))  # rms, not std: the constant's column has none
        scale[scale == 0] = 1.0
        coef = np.linalg.lstsq(A / scale, target, rcond=None)[0] / scale
        full = np.zeros(n_lib + 1 + n_aux + len(extra) + int(stop))
        full[cols] = coef
        if self._gain is not None:
            full[n_lib] = self._gain
        return full

    def _model(self, coef: np.ndarray, rec: Measurement, stop: float | None, aux: tuple[str, ...] = (),
               law: str | None = None) -> Model:  # fmt: skip
        n_lib = len(library_terms())
        # weak.model_from's order: the library's terms, the channels' (here after the input's column), the input
        phys = np.concatenate([coef[:n_lib], coef[n_lib + 1 : n_lib + 1 + len(aux)], coef[n_lib : n_lib + 1]])
        mass = mass_of(rec, self._gain, phys[-1])[0]
        model = model_from(phys, mass, aux)
        labels = self._law_extra(law)
        if labels:  # the law's own parts (a shaped part's value from its shape and coefficients, z^6, z^7)
            assert law is not None
            lw, shape = laws.get(law), self._shapes_of(law)
            cols = lw.column_list(shape)
            at = n_lib + 1 + len(aux)
            own = dict(zip(labels, coef[at : at + len(labels)], strict=True))
            _, parts = lw.values([own.get(c.label, 0.0) for c in cols], mass, shape)
            targets = {c.target for c in cols if c.label in own}
            own_parts = {k: v for k, v in parts.items() if k in targets}
            model = Model(**{**model.to_dict(), "extra": {**dict(model.extra), **own_parts}})
        if stop is not None:
            k = -mass * float(coef[-1])
            if k > 0:
                extra = {**dict(model.extra), _stop()[0]: {"k": k, "z": stop}}
                model = Model(**{**model.to_dict(), "extra": extra})
        return model

    def _refit_model(self, rec: Measurement, terms, stop, aux: tuple[str, ...] = (), law: str | None = None) -> Model:
        W, y = self._design(rec, 0, self.n_id_, stop, aux, law)
        return self._model(self._fit(W, y, terms, stop is not None, len(aux), law), rec, stop, aux, law)

    def _fit_stop(self, rec: Measurement, terms: tuple[str, ...], aux: tuple[str, ...] = (), upto: int | None = None,
                  keep: np.ndarray | None = None, law: str | None = None) -> float:  # fmt: skip
        """The end stop's position (a nonlinear parameter) by least squares on the fitting part (or the weak rows
        ``keep`` of [0, ``upto``)): a grid over the outer 0.05-10 % of the stroke on either side (an onset with at
        least ``STOP_MIN_SAMPLES`` samples beyond it), refined by a bounded scalar search between the best grid
        point's neighbours. The grid reaches 0.05 %: a stop hit in 0.2 % of a record (the plus well's bumper on a
        record that lives in the minus well) lies beyond the 0.5 % point, and a search that starts there never
        reaches it (measured: onset 24.3 mm and k 340-640 N/m for a 3000 N/m stop at 28 mm, then not named).
        """
        from scipy import optimize

        upto = self.n_fit_ if upto is None else upto

        def ss(zs: float) -> float:
            W, y = self._design(rec, 0, upto, zs, aux, law)
            if keep is not None:
                W, y = W[keep], y[keep]
            coef = self._fit(W, y, terms, True, len(aux), law)
            return float(np.sum((y - W @ coef) ** 2)) if coef[-1] < 0 else math.inf  # a stop pushes back

        z = self._zs[:upto]
        qs = tuple(q for q in (0.05, 0.1, 0.2, 0.5, 1, 2, 3, 5, 7, 10) if q / 100 * z.size >= STOP_MIN_SAMPLES)
        grid = [float(np.percentile(z, q)) for q in qs] + [float(np.percentile(z, 100 - q)) for q in qs]
        vals = [ss(g) for g in grid]
        i = int(np.argmin(vals))
        side = grid[: len(qs)] if i < len(qs) else grid[len(qs) :]
        j = side.index(grid[i])
        lo, hi = sorted((side[max(j - 1, 0)], side[min(j + 1, len(side) - 1)]))
        if hi > lo:
            # a position where the stop would pull (inf) makes the bounded search's parabola inf - inf: its
            # golden-section step takes over, as intended; numpy's notice of the NaN is not the user's business
            with np.errstate(invalid="ignore"):
                r = optimize.minimize_scalar(ss, bounds=(lo, hi), method="bounded", options={"xatol": 1e-5})
            if r.fun < vals[i]:
                return float(r.x)
        return grid[i]
