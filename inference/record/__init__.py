"""A record as negstiff holds it: ``Measurement`` (one uniformly sampled record in SI units, with what is
derived from it kept beside it), ``load`` and ``from_arrays`` (``measurement``: files read through
``negstiff.io``, mapped, converted and checked), the response sensors a lab measures z with (``sensors``:
z from a velocity, an absolute displacement or an acceleration), and the record made physical
(``frame.pin_frame``: an unknown response scale calibrated and a derived z's frame pinned, a step of its own,
called by the analyses that need it).
"""
