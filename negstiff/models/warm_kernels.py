"""Each compiled kernel of the models, compiled (or loaded from numba's cache) by a tiny call: what a fresh
install's first run queues before its work (``reproduce``'s sections, the test suite's workers) and what a
compile-ahead helper runs (``compile_ahead``): ``python -m negstiff.models.warm_kernels NAME``.

A module of its own: the simulator waits on the helpers (``compile_ahead.wait_for``) and the helpers run the
simulator, so the two ends live apart (no import cycle).
"""

from __future__ import annotations

import sys

import numpy as np

KERNELS = ("polynomial", "device", "polynomial_sign", "benettin", "structure", "table", "generic", "device_sign")
"""The models' kernels by name: the polynomial's and the device's fused steps, each with a smoothed sign too, the
Benettin exponent's, the stage-wise kernel of the polynomial element on a sprung fixture (``structure``), a law's
table (``table``) and the general kernel (extra monomial rows, or a table with a smoothed sign: ``generic``)."""


def warm(name: str) -> None:
    """Compile the kernel ``name`` (one of ``KERNELS``) or load it from numba's cache, with a tiny call (the same
    argument types as every caller's: ``simulator.integrate`` makes them so).
    """
    from .device import AS_BUILT, SEED_LIKE_CUBIC
    from .kernel import P_SIGN
    from .simulator import simulate_batch

    u = np.zeros(64)
    if name in ("polynomial", "polynomial_sign"):
        p = SEED_LIKE_CUBIC.kernel_params()
        if name == "polynomial_sign":
            p[P_SIGN] = 1e-3
        simulate_batch(p, "polynomial", u, 1e-3, np.zeros(2))
    elif name in ("device", "device_sign"):
        p = AS_BUILT.kernel_params()
        if name == "device_sign":
            p[P_SIGN] = 1e-3
        simulate_batch(p, "device", u, 1e-3, np.array([AS_BUILT.equilibria().z_plus, 0.0]))
    elif name in ("table", "generic"):  # the device's geometric law as a law's table; with a sign: the general one
        p = AS_BUILT.law_model().kernel_params()
        if name == "generic":
            p[P_SIGN] = 1e-3
        simulate_batch(p, "polynomial", u, 1e-3, np.array([AS_BUILT.equilibria().z_plus, 0.0]))
    elif name == "structure":  # the polynomial element on a sprung fixture: two DOFs, the stage-wise loops
        from .structure import Structure, simulate_structures

        fixture = Structure.on_fixture(SEED_LIKE_CUBIC, fixture_mass=1.0, fixture_hz=25.0, fixture_zeta=0.02)
        x0 = np.r_[fixture.static_positions(fixture.element_equilibria().z_plus), 0.0, 0.0]
        simulate_structures([fixture], u, 1e-3, x0)
    elif name == "benettin":
        from .reference import lyapunov_benettin

        lyapunov_benettin(SEED_LIKE_CUBIC, u, 1e-3, SEED_LIKE_CUBIC.equilibria().z_plus, transient_s=0.0)
    else:
        raise ValueError(f"unknown kernel {name!r}: one of {KERNELS}")


if __name__ == "__main__":
    warm(sys.argv[1])
