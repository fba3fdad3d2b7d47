"""The steps the estimators are made of, each written once: the record made physical (``frame``: an
unknown response scale calibrated, a derived z's frame pinned), the weak form of the equation of motion
(``weak``), the wells' first guesses (``wells``), held-out selection (``selection``), free-run validation
and boundedness (``validation``), output-error refinement (``refine``, on ``shooting``'s multiple shooting),
and the plausibility checks behind every warning (``plausibility``). The record's smoothed states and
derivatives are the record's own (``negstiff.inference.record.derivatives``).
"""
