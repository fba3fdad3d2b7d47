"""Bayesian inference with emcee: posteriors over the coefficients (k1, k2, k3, c, c_nl), the device
(E, alpha, m, c, c_nl) or the parameters of a restoring and a damping law (``models.laws``: a magnet's A and d, a
spline's coefficients, ...; ``Posterior(law=...)``, with the restoring force's credible band over the stroke),
with the exact forward model inside a multiple-shooting output-error likelihood.

Likelihood. z is measured with noise; z' and z'' are not measured. The record is cut into windows of
``window_s`` seconds; each is simulated from the measured state at its start (Savitzky-Golay z, z'
of least predicted velocity error, ``derivatives``) under the measured input, all windows of all
walkers in one batched simulator call (emcee ``vectorize=True``). Short windows keep cross-well
chaos from amplifying differences (device-model.md); one long free run could not be matched.
The measured start state is uncertain (z' to ~1 % rms), and a wrong start leaves a decaying free
oscillation in the window's residual: each window's start state is a nuisance parameter, profiled
out to first order by projecting the residual off the window's two initial-state sensitivities
(computed by finite differences at the maximum a posteriori point; they depend on the parameters
only weakly). With i.i.d. Gaussian sensor noise sigma (sampled, log-uniform prior):

    log L = -(N - 2 W)/2 log(2 pi sigma^2) - sum_w |P_w (z_w - z_sim,w(theta*))|^2 / (2 sigma^2)

Windows are 0.125 s: with 0.25 s windows the cross-well chaos roughens the likelihood and the
point estimate scattered 1.2-1.3x wider than its curvature said even with white noise alone
(measured: 40 records of 8 s, accelerometer noise off; 0.9-1.05x with 0.125 s windows). A window
that starts near the saddle and cannot be followed from any nearby start state is dropped
(``Windows.drop_unmatched``; listed in the result). The i.i.d. Gaussian noise model is wrong in a
known way (the accelerometer's noise enters through the model's input and through z's double
integration, both correlated within a window): theta* = theta_hat + A (theta - theta_hat) is the
curvature adjustment by the windows' sandwich covariance (``curvature_adjustment``), which widens
the posterior where the windows' scatter says the data carry less information than the model
claims. The device's likelihood depends on E/m, c/m, c_nl/m only: it is evaluated at the reference
mass, and the sampler works in (E, c, c_nl at the reference mass, m, ...), where the E-m ridge is a
cylinder whose length is the mass prior's (``device_parametrisation``).

Sampler. emcee ensembles in coordinates whitened by a Laplace approximation at the MAP point (scipy
``least_squares`` on the same residual), walkers started from that Gaussian, moved half the time by an
independence Metropolis-Hastings proposal from that approximation (a Student t: ``laplace_independence_move``)
and half by emcee's differential evolution (``MOVES``; not emcee 3.1.6's snooker move, whose stationary
distribution is not the target: ecosystem.md 2). Independent ensembles (default 4, seeds seed..seed+3) run until
every parameter's integrated autocorrelation time tau satisfies steps >= ``tau_multiple`` tau (the
emcee docs' rule) or ``max_steps`` is reached (then a loud warning). R-hat (rank-normalised, split)
is computed across ensembles, each ensemble one chain (walkers of one ensemble are not independent);
ESS bulk and tail across all walkers, and capped by the emcee estimate N / tau.

A structure's record (N > 1 DOFs, ``Posterior(element="I-J")``): the element's coefficients are sampled with each
channel's zero and the linear structure's springs and dampers as nuisances, started from ``SINDy(element=...)``'s,
the masses given (``structure.py``), under the same curvature adjustment, sampler and summaries.
"""

from negstiff.inference.estimators.posterior.core import Posterior
from negstiff.inference.estimators.posterior.diagnostics import (
    PosteriorResult,
    convergence_warnings,
    result_json,
    summarise,
)
from negstiff.inference.estimators.posterior.likelihood import LogPosterior, curvature_adjustment
from negstiff.inference.estimators.posterior.parametrisation import (
    LawMap,
    Parametrisation,
    coefficient_parametrisation,
    device_parametrisation,
    law_parametrisation,
)
from negstiff.inference.estimators.posterior.sampling import sample_ensembles
from negstiff.inference.estimators.posterior.windows import (
    COEFFICIENT_NAMES,
    DEVICE_NAMES,
    DROP_FACTOR,
    DROP_FACTOR_AT_MAP,
    SIGMA_BOUNDS,
    PosteriorError,
    Windows,
)

__all__ = [
    "COEFFICIENT_NAMES",
    "DEVICE_NAMES",
    "DROP_FACTOR",
    "DROP_FACTOR_AT_MAP",
    "SIGMA_BOUNDS",
    "LawMap",
    "LogPosterior",
    "Parametrisation",
    "Posterior",
    "PosteriorError",
    "PosteriorResult",
    "Windows",
    "coefficient_parametrisation",
    "convergence_warnings",
    "curvature_adjustment",
    "device_parametrisation",
    "law_parametrisation",
    "result_json",
    "sample_ensembles",
    "summarise",
]
