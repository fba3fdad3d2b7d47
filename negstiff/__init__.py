"""negstiff: identification, model updating and uncertainty quantification of nonlinear
(bistable, negative-stiffness) oscillators.

The parts: ``negstiff.models`` (the physics: device, equation of motion, simulator, virtual rig),
``negstiff.inference`` (learning from data: loading, identification, updating, posteriors),
``negstiff.experiments`` (studies that write ``reports/``), and the ``negstiff`` command line.
"""

__version__ = "0.1.0"
