"""Records written in the tests themselves with numpy and scipy (not with negstiff's rig or simulator), and
what they share: the test utility module (imported as ``from records import ...``)."""

import numpy as np

from negstiff import Model

TRUTH = Model(m=0.2, k1=426.0, k2=-3060.0, k3=7.77e5, c=0.35, c_nl=0.1)
FS = 512.0


def dop853_record(duration=60.0, rms=8.0, seed=7, start=0.024, fs=FS, rtol=1e-9):
    """(t, base_acc, z, z_dot) of TRUTH under a multisine base acceleration (2-30 Hz), integrated by
    scipy's DOP853 (``rtol``, 1e-9 by default) from rest at ``start``: a record negstiff's simulator did not make."""
    from scipy.integrate import solve_ivp

    rng = np.random.default_rng(seed)
    f = np.arange(2.0, 30.0, 0.25)
    w, ph = 2 * np.pi * f, rng.uniform(0, 2 * np.pi, f.size)
    a = rms * np.sqrt(2.0 / f.size)

    def acc(t):
        return a * np.cos(np.multiply.outer(t, w) + ph).sum(axis=-1)

    def rhs(t, x):
        z, v = x
        return [v, (-TRUTH.c * v - TRUTH.c_nl * v * abs(v) - TRUTH.restoring_force(z)) / TRUTH.m - acc(t)]

    t = np.arange(int(duration * fs)) / fs
    sol = solve_ivp(rhs, (0, t[-1]), [start, 0.0], t_eval=t, method="DOP853", rtol=rtol, atol=1e-3 * rtol)
    return t, acc(t), sol.y[0], sol.y[1]


def write_csv(path, cols, meta=None):
    head = "".join(f"# {k}: {v}\n" for k, v in (meta or {}).items()) + ",".join(cols) + "\n"
    rows = np.column_stack(list(cols.values()))
    path.write_text(head + "\n".join(",".join(f"{x:.10g}" for x in r) for r in rows) + "\n")
    return path


def write_npz_channels(path, channels, meta=None):
    """Channels under a lab's own names (``V1``, ``V2``), as a DAQ saves them: a foreign file, read with a map."""
    import json

    with open(path, "wb") as fh:
        np.savez(fh, **channels, **({"meta": json.dumps(meta)} if meta else {}))
    return path
