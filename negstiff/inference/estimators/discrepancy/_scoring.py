"""Name: each candidate (an effect, a measured channel's term, a law in place of the restoring force) refitted on
the fitting part and scored by its held-out weak residual; the simplest of those within one standard error of
the best, and why the first was named or not.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from negstiff.inference.record.measurement import Measurement
from negstiff.inference.steps import law_choice
from negstiff.inference.steps.selection import block_rows, block_scores, indistinguishable
from negstiff.inference.steps.validation import boundedness
from negstiff.models import effects, laws

from ._candidates import CUBIC_BASELINE, LAW_PREFIX, Candidate, DiscrepancyError, _scores, law_of
from ._locating import Locating


class Scoring(Locating):
    """Each candidate scored and the simplest chosen (a layer of ``Discrepancy``)."""

    def _size_of(self, rec: Measurement, cand: Candidate) -> dict[str, Any]:
        """A ranked effect's size as its fit on the scoring part has it (``{"size": ...}``; the model's entry for
        it), for a catalogue effect that scored; nothing for the baseline, a law or a channel. What a test
        design takes as each hypothesis (``analysis.separation``).
        """
        if (cand.effect == "none" or cand.coefficients is None or not math.isfinite(cand.heldout_percent)
                or law_of(cand.effect) is not None or cand.effect.startswith(effects.AUX_PREFIX)):  # fmt: skip
            return {}
        try:
            size = self._model(cand.coefficients, rec, cand.stop, cand.aux, cand.law).extra.get(cand.effect)
        except (ValueError, ArithmeticError):
            return {}
        if size is None:
            return {}
        # a stop's {"k", "z"} is the model's read-only mapping: a plain dict of floats, as JSON and pickle take it
        return {"size": {k: float(v) for k, v in size.items()} if hasattr(size, "items") else float(size)}

    def _score(self, rec: Measurement, cand: Candidate) -> Candidate:
        W, y = self._design(rec, 0, self.n_fit_, cand.stop, cand.aux, cand.law)
        coef = self._fit(W, y, cand.terms, cand.stop is not None, len(cand.aux), cand.law)
        Ws, ys = self._design(rec, self.n_fit_, self.n_id_, cand.stop, cand.aux, cand.law)
        r2 = (ys - Ws @ coef) ** 2
        rows = block_rows(self.window_s_, rec.fs, self._form.stride)
        nb = r2.size // rows
        if nb < 2:
            need = 2 * rows / max(1, r2.size) * rec.n  # samples of record that give two blocks
            raise DiscrepancyError(
                f"{rec.source}: too short for the discrepancy workflow: {rec.duration:.3g} s, at least about "
                f"{need / rec.fs:.3g} s are needed (the part from {100 * self.n_fit_ / rec.n:.0f} to "
                f"{100 * self.n_id_ / rec.n:.0f} % of the record scores each effect in {self.window_s_:g} s blocks, "
                "two at least)"
            )
        cand.block_ms = block_scores(r2, rows, ys.var())
        cand.heldout_percent = float(100 * np.sqrt(cand.block_ms.mean()))
        cand.coefficients = coef
        if law_of(cand.effect) is not None:
            # a law that fails the identifications' checks is never named (``law_choice.problems``: no stable well,
            # a well outside the stroke, an escape just past it, damping that feeds energy in), whatever it scores
            try:
                failed = law_choice.problems(self._model(coef, rec, cand.stop, cand.aux, cand.law), rec, self.n_id_)
            except (ValueError, ArithmeticError) as exc:
                failed = [" ".join(str(exc).split())]
            if failed:
                cand.notes["problems"] = failed
                cand.heldout_percent = math.inf
        elif cand.effect != "none":
            # the catalogue never names an effect whose fit opens an escape just past the stroke
            try:
                model = self._model(coef, rec, cand.stop, cand.aux, cand.law)
                escape = boundedness(model, rec.segment(0, self.n_id_), free_run=False)
                escape = escape["escape_z"]
            except ValueError:
                escape = None
            if escape is not None:
                cand.notes["escape_z"] = escape
                cand.heldout_percent = math.inf
        return cand

    def _law_candidate(self, rec: Measurement, name: str, terms: tuple[str, ...], stop: float | None,
                       aux: tuple[str, ...], law: str | None) -> Candidate:  # fmt: skip
        """The candidate that replaces the restoring force of ``terms`` (``law``'s, or the catalogue's terms of z
        alone) by the law ``name`` at its shape, the rest (the damping, a stop, the channels) held; scored as an
        effect is (``_score``). A law with no shape on the record is not a candidate, and says why.
        """
        cand = Candidate(f"{LAW_PREFIX}{name}", (), stop, aux, name)
        try:
            shape = self._shape(rec, name)
        except DiscrepancyError as exc:
            cand.notes["problems"] = [str(exc)]
            return cand
        rest = tuple(t for t in terms if t not in self._restoring_terms(terms, law))
        cand.terms = self._law_terms(name) + rest
        if shape.shape:
            cand.notes["shape"] = shape.to_json()["shape"]
        return self._score(rec, cand)

    def _extra_parameters(self, c: Candidate, terms: tuple[str, ...], law: str | None) -> int:
        """The parameters a candidate adds to the current model: an effect's values (an end stop's two), a
        channel's theta, a law's restoring parameters beyond the current restoring force's (``_n_parameters``:
        the geometric law's k0, k_f, k_f D0, L and alpha against the cubic's k0..k3 adds one; a magnet's none).
        """
        if c.effect == "none":
            return 0
        if law_of(c.effect) is not None:
            return self._n_parameters(c.terms, c.law) - self._n_parameters(terms, law)
        if c.effect.startswith(effects.AUX_PREFIX):
            return 1  # theta alone
        return effects.get(c.effect).n_values

    def _parsimonious(self, ranking: list[Candidate], terms: tuple[str, ...] = CUBIC_BASELINE,
                      law: str | None = laws.DEFAULT_RESTORING) -> Candidate:  # fmt: skip
        """Among the effects within max(1 SE, margin) of the best held-out residual, the one with the
        fewest parameters (``_extra_parameters``: the end stop has two, its stiffness and its position; a law
        what it adds to the current restoring force, ``terms`` of ``law``), then the lowest residual: a
        two-parameter stop that beats z^5 by 4 % on the as-built device is not evidence of a stop (measured).
        """
        top = ranking[0]
        ok = []
        for c in ranking:
            if c.effect == "none" or not np.isfinite(c.heldout_percent):
                continue
            if indistinguishable(_scores(c), _scores(top), self.margin):
                ok.append(c)
        if not ok:
            return top
        return min(ok, key=lambda c: (self._extra_parameters(c, terms, law), c.heldout_percent))

    def _first(self, ranking: list[Candidate], best: Candidate, iteration: dict[str, Any] | None,
               terms: tuple[str, ...], law: str | None, gain) -> dict[str, Any]:  # fmt: skip
        """Why the candidate ranked first (the least held-out weak residual) was named or not, in words: the
        result's ``iterations[].first``.
        """
        first = ranking[0]
        out: dict[str, Any] = {"effect": first.effect, "score": first.heldout_percent,
                               "named": bool(iteration is not None and iteration.get("kept")
                                             and best is first)}  # fmt: skip
        none = next(c for c in ranking if c.effect == "none")
        if first.effect == "none":
            out["why"] = "no candidate's held-out weak residual fell below the baseline's"
            return out
        if best is not first:
            n_first, n_best = (self._extra_parameters(c, terms, law) for c in (first, best))
            out["why"] = (f"{best.effect} scores within max(one standard error, {100 * self.margin:g} %) of it "
                          f"({best.heldout_percent:.3g} % against {first.heldout_percent:.3g} %) with fewer parameters "
                          f"({n_best} against {n_first}): the simpler of the two was the candidate")  # fmt: skip
            if iteration is None:
                out["why"] += (f", and its gain over the baseline ({100 * gain.gain / _scores(none).mean():.3g} %) was "
                               f"not beyond max(one standard error, {100 * self.margin:g} %)")  # fmt: skip
            elif not iteration.get("kept"):
                out["why"] += f"; {iteration['verdict']}"
            return out
        if iteration is None:
            out["why"] = (f"its gain over the baseline ({100 * gain.gain / _scores(none).mean():.3g} % of its held-out "
                          f"weak residual, one standard error {100 * gain.se / _scores(none).mean():.3g} %) is not "
                          f"beyond max(one standard error, {100 * self.margin:g} %)")  # fmt: skip
        elif not iteration.get("kept"):
            out["why"] = iteration["verdict"]
        return out
