"""The estimators (scikit-learn's contract, ``base``; every parameter declared in ``parameters``): the
identifications (``identification``: one pipeline; ``nsi`` with ``subspace``, ``sindy``), the discrepancy
workflow (``discrepancy``, with the hybrid model in ``hybrid``), the Bayesian posterior (``posterior/``) and
model updating (``updating``).
"""
