"""Data that ships with negstiff: the Silverbox benchmark, a real electronic Duffing oscillator.

The Silverbox (Wigren & Schoukens, ECC 2013) is freely distributed benchmark data; negstiff carries
it (1.9 MB, compressed, values unchanged; citation in ``negstiff/data/silverbox/README.md``) so the
main job, the tests and the examples run from a fresh install with nothing beside it.

Examples
--------
>>> from negstiff.datasets import silverbox
>>> rec = silverbox()
>>> rec.n, round(rec.fs, 2), rec.input_name
(131072, 610.35, 'force')
"""

from __future__ import annotations

import os
from importlib import resources
from pathlib import Path

from negstiff.errors import InputError

__all__ = ["SILVERBOX_FS", "silverbox", "silverbox_path"]

SILVERBOX_FS = 610.35
"""The Silverbox's sampling frequency [Hz]: 10**7 / 2**14."""


def silverbox_path() -> Path:
    """Where the Silverbox file is read from.

    Returns
    -------
    pathlib.Path
        ``$NEGSTIFF_SILVERBOX`` when set (a copy of ``SNLS80mV.mat`` or ``SNLS80mV.csv``), else the
        copy inside the installed package.

    Raises
    ------
    InputError
        ``$NEGSTIFF_SILVERBOX`` names no file.

    Examples
    --------
    >>> from negstiff.datasets import silverbox_path
    >>> silverbox_path().name
    'SNLS80mV.mat'
    """
    env = os.environ.get("NEGSTIFF_SILVERBOX")
    if env:
        p = Path(env)
        if not p.is_file():
            raise InputError(f"NEGSTIFF_SILVERBOX={env} is not a file: unset it to use the copy shipped with negstiff")
        return p
    return Path(str(resources.files("negstiff") / "data" / "silverbox" / "SNLS80mV.mat"))


def silverbox():
    """The Silverbox record: force input V1 [V], displacement output V2 [V], 610.35 Hz, 131072 samples.

    Returns
    -------
    Measurement
        A force record without a mass (the circuit's ``m`` is not known): estimators report
        coefficients per unit mass. The benchmark's split is in ``negstiff.experiments.silverbox``
        (``TRAIN``, ``TEST``, ``ARROW``).

    Examples
    --------
    >>> from negstiff.datasets import silverbox
    >>> train = silverbox().segment(40650, 105712)
    >>> train.n
    65062
    """
    from negstiff.inference.record.measurement import load

    return load(silverbox_path(), columns="force=V1,z=V2", fs=SILVERBOX_FS)
