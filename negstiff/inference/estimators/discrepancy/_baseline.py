"""The discrepancy workflow's baseline: the seed's terms, a law at the record's shape, or the law the record asks
for (``law="auto"``, chosen by the identifications' comparison, ``law_choice.choose``).
"""

from __future__ import annotations

import math
from typing import Any

from negstiff.errors import InputError
from negstiff.inference.record.measurement import Measurement
from negstiff.inference.steps import law_choice
from negstiff.inference.steps.shape import fit_shape
from negstiff.inference.steps.weak import Library, WeakForm, fit_support, known_input_gain, mass_of
from negstiff.models import Model, laws

from ._candidates import DiscrepancyError, _damping_of, _displacement_labels
from ._weak import WeakSystems


class Baselines(WeakSystems):
    """The baseline's laws and terms (a layer of ``Discrepancy``)."""

    def _baseline(self, rec: Measurement) -> tuple[tuple[str, ...], str | None]:
        """The baseline's terms and its restoring law (``law``, ``damping``; module docstring, 1), and its account
        in ``baseline_law_``. None: ``baseline``'s terms, their velocity terms replaced by ``damping``'s columns where
        it is given; the law is then the cubic where they are its terms (the reference study's, the default) and
        none otherwise (``LINEAR_BASELINE``). A law: its columns at the record's shape (``_shape``). ``"auto"``: the
        law the record asks for, chosen as the identifications choose it (``law_choice.choose``).
        """
        damping = self._damping_law()
        damping_terms = tuple(c.label for c in laws.get(damping).column_list())
        choice = None
        velocity = damping_terms
        if self.law is None:
            restoring = tuple(t for t in self.baseline if t in _displacement_labels())
            velocity = tuple(t for t in self.baseline if t not in restoring)
            terms = restoring + (velocity if self.damping is None else damping_terms)
            cubic = self._law_terms(laws.DEFAULT_RESTORING)
            law = laws.DEFAULT_RESTORING if restoring == cubic else None
        else:
            law = self.law
            if law == "auto":
                choice = self._choose_law(rec)
                law = choice.best.law
            self._shape(rec, law)
            terms = self._law_terms(law) + damping_terms
        self.baseline_law_ = {
            "requested": self.law,
            "restoring": law,
            "damping": damping if self.law is not None or self.damping is not None else _damping_of(velocity),
            "terms": list(terms),
            "shape": None if law is None or not laws.get(law).shaped() else self._shapes[law].to_json(),  # type: ignore[union-attr]
            "choice": None if choice is None else self._choice_json(choice),
        }
        return terms, law

    def _law_estimate(self, rec: Measurement, part: Measurement, n: int, name: str) -> Model:
        """``law_choice.choose``'s estimate of the law ``name`` over the first ``n`` samples of ``part``: on the
        identification part itself the workflow's own fit (the law's columns at the record's shape, ``_shape``,
        and the damping law's, by weak least squares over [0, n_id)); on the comparison's fitting part the same
        fit of that part alone (its shape found there, on its first ``1 - selection / (1 - validation)``).
        """
        damping = self._damping_law()
        if part is rec and n == self.n_id_:
            self._shape(rec, name)
            terms = self._law_terms(name) + tuple(c.label for c in laws.get(damping).column_list())
            return self._refit_model(rec, terms, None, (), name)
        share = 1 - self.selection_fraction / (1 - self.validation_fraction)
        fit = fit_shape(part, name, damping, n_fit=int(round(share * n)), n_id=n, window_s=self.window_s)
        lib = Library.of_laws(name, damping, fit.shape)
        gain = known_input_gain(part)
        phys = fit_support(WeakForm.of(part).system(part, 0, n, library=lib), gain)
        return lib.model(phys, mass_of(part, gain, phys[-1])[0])

    def _choose_law(self, rec: Measurement) -> law_choice.Choice:
        """The restoring law the record asks for (``law="auto"``), by the identifications' comparison
        (``law_choice.choose``) with this workflow's estimate of each (``_law_estimate``).
        """
        try:
            return law_choice.choose(rec, self.n_id_, laws.names("restoring"),
                                     lambda part, n, name: self._law_estimate(rec, part, n, name),
                                     lambda m: m)  # fmt: skip
        except InputError as exc:
            raise DiscrepancyError(str(exc)) from None

    @staticmethod
    def _choice_json(choice: law_choice.Choice) -> dict[str, Any]:
        """The comparison that chose the baseline's law, as the identifications' ``law_choice``."""
        best = choice.best
        return {**choice.windows, "chosen": best.law, "candidates": [c.to_json() for c in choice.candidates],
                "summary": f"the laws were compared on what they predict ({choice.windows.get('windows')} windows of "
                           f"{choice.windows.get('window_s', math.nan):.3g} s restarted over the selection part): "
                           f"{best.law} chosen (median window {best.median_percent:.3g} %, weight "
                           f"{best.weight:.2f})"}  # fmt: skip
