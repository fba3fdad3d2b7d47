"""negstiff: identification, model updating and uncertainty quantification of nonlinear
(bistable, negative-stiffness) oscillators.

The parts: ``negstiff.models`` (the physics: device, equation of motion, simulator, virtual rig),
``negstiff.inference`` (learning from data: loading, identification, updating, posteriors),
``negstiff.experiments`` (studies that write ``reports/``), and the ``negstiff`` command line.
"""

from pathlib import Path as _Path

__version__ = "0.1.0"

# In a source checkout the parts are the top-level folders models/, inference/, experiments/ beside
# this one (the project's layout); installed, setuptools puts them inside this package. Let a
# checkout import as the installed package does (e.g. ``python -m pytest`` from the repository).
_here = _Path(__file__).resolve().parent
if not (_here / "models").is_dir() and (_here.parent / "models" / "__init__.py").is_file():
    __path__.append(str(_here.parent))  # noqa: F821 - a package's __path__
