"""A record as negstiff holds it: ``Measurement`` (one uniformly sampled record in SI units, with what is
derived from it kept beside it), ``load`` and ``from_arrays`` (``measurement``: files read through
``negstiff.io``, mapped, converted and checked), the response sensors a lab measures z with (``sensors``:
z from a velocity, an absolute displacement or an acceleration), and the frame of a derived z
(``frame.pin_frame``: a step of its own, called by the analyses that need it).
"""
