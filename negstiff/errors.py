"""negstiff's errors and warnings, one family for the library and the command line.

* ``InputError``: something the user gave (a file, a column, an option, a number, a parameter) cannot
  be used. Its message is one line that names the input and the problem; the command line prints it
  and exits with 2, before any work. Every domain error (``MeasurementError``, ``RigError``,
  ``GeometryError``, ``UpdatingError``, ``ContinuationError`` and the estimators' own) is one.
* ``OutputError``: an output cannot be written (a full disk, a path the file system refuses); nothing
  is left behind.
* ``NegstiffWarning``: a result a physicist would not believe (a record in mm, an input in g, an
  unconverged chain, a model that escapes). It goes through Python's ``warnings`` and into the result.

They live here, below ``models`` and ``inference``, so both raise the same classes.
"""

from __future__ import annotations


class InputError(ValueError):
    """Bad input: a file, option, unit or number negstiff refuses, with one line saying why.

    The command line turns it into exit 2 and that line on stderr, before any work.

    Examples
    --------
    >>> from negstiff import InputError, NSI
    >>> try:
    ...     NSI(block_rows=-1).fit("no_such_file.csv")
    ... except InputError as e:
    ...     print("refused:", type(e).__name__)
    refused: InputError
    """


class MeasurementError(InputError):
    """A record that cannot be read as one (an ``InputError``): the line names the file, column or row.

    Examples
    --------
    >>> import numpy as np
    >>> from negstiff import MeasurementError, from_arrays
    >>> try:
    ...     from_arrays(np.zeros(10), np.full(10, np.nan), 100.0)
    ... except MeasurementError as e:
    ...     print(e)
    <memory>: column z is NaN or inf at row 1
    """


class OutputError(InputError):
    """An output that cannot be written (disk full, name too long, not a regular file); nothing is left behind.

    Examples
    --------
    >>> from negstiff import OutputError, InputError
    >>> issubclass(OutputError, InputError)
    True
    """


class NegstiffWarning(UserWarning):
    """A result a physicist would not believe (a record in mm, an unconverged chain, an unbounded model).

    Issued through Python's ``warnings`` and kept in the result's ``warnings``; its subclasses
    (``RecordWarning``, ``FrameWarning``, ``ExtrapolationWarning``, ``BoundednessWarning``,
    ``ConvergenceWarning``, in ``negstiff.errors``) tell the kinds apart.

    Examples
    --------
    >>> import warnings
    >>> from negstiff import NegstiffWarning
    >>> with warnings.catch_warnings():
    ...     warnings.simplefilter("error", NegstiffWarning)     # make every such warning an error
    """


class NotFittedError(ValueError, AttributeError):
    """A learned attribute (``model_``, ``result_``, ...) read before ``fit`` (also an ``AttributeError``).

    Examples
    --------
    >>> from negstiff import NSI, NotFittedError
    >>> try:
    ...     NSI().model_
    ... except NotFittedError as e:
    ...     print(type(e).__name__)
    NotFittedError
    """


class RecordWarning(NegstiffWarning):
    """How a record was read looks wrong: units (mm read as m, an input in g), a derived response's error."""


class FrameWarning(NegstiffWarning):
    """A measured z whose zero is not where the record's physics carry the weight (a sensor offset?)."""


class ExtrapolationWarning(NegstiffWarning):
    """A result beyond what the record visited (a model's well outside the stroke)."""


class BoundednessWarning(NegstiffWarning):
    """An identified model that escapes beyond the stroke or diverges under the record's input."""


class ConvergenceWarning(NegstiffWarning):
    """A sampler or an optimiser that did not converge (R-hat, effective sample size, a diverged free run)."""


def issue(lines) -> None:
    """Each (category, text) through Python's ``warnings`` (a ``NegstiffWarning`` subclass): what a result
    holds in its ``warnings``, said where a script sees it.
    """
    import warnings

    for category, text in lines:
        warnings.warn(text, category, stacklevel=3)
