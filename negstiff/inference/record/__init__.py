"""A record as negstiff holds it: ``Measurement`` (one uniformly sampled record in SI units, with what is
derived from it kept beside it), ``load`` and ``from_arrays`` (``measurement``: files read through
``negstiff.io``, mapped, converted and checked), the response sensors a lab measures z with (``sensors``:
z from a velocity, an absolute displacement or an acceleration) and the record's smoothed states and
derivatives (``derivatives``). This layer imports no step: making a record physical (its frame pinned, an
unknown scale calibrated) fits the equation of motion, and is the step ``negstiff.inference.steps.frame``.
"""
