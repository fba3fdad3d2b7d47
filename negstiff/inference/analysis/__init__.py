"""The dynamics of harmonic records: periodicity on phase-synchronous samples (``periodicity``), Lyapunov
exponents (``lyapunov``), both composed by ``characterise``; a stepped campaign's bifurcation map
(``campaign``); frequency response functions (``frf``), of impact tests too
(``impact``); backbone curves of free decays (``backbone``).
"""
