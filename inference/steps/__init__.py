"""The steps the estimators are made of, each written once: smoothed states and derivatives
(``derivatives``), the weak form of the equation of motion (``weak``), held-out selection (``selection``),
free-run validation and boundedness (``validation``), output-error refinement (``refine``, on
``shooting``'s multiple shooting), and the plausibility checks behind every warning (``plausibility``).
"""
