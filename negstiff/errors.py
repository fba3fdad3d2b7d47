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
    """Bad input: one line naming the input and the problem (the command line's exit 2)."""


class MeasurementError(InputError):
    """Bad measurement input; the message is one line naming the file and the problem."""


class OutputError(InputError):
    """An output cannot be written (disk full, name too long, not a regular file); nothing was left."""


class NegstiffWarning(UserWarning):
    """A result that looks implausible (units, frame, convergence, boundedness): loud, never silent."""


class NotFittedError(ValueError, AttributeError):
    """A learned attribute (``model_``, ``result()``) asked of an estimator before ``fit`` (as scikit-learn's)."""


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
