"""A kernel compiled ahead by a helper process is the kernel a fit then runs, loaded from numba's cache, not
compiled again (``models.compile_ahead``: a fresh install's first ``identify sindy`` compiles its two kernels side by
side).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

# a fresh process on an empty cache: the helper started and awaited as a fit does, then the kernel's simulations
# (another input, length and step than the helper's, one member and a batch) compile no ``_integrate`` of their own
PROBE = """
import json
import numpy as np
from numba.core import event
from negstiff.models import SEED_LIKE_CUBIC, compile_ahead
from negstiff.models.simulator import simulate, simulate_batch

compiled = []


class Listener(event.Listener):
    def on_start(self, ev):
        pass

    def on_end(self, ev):
        compiled.append(ev.data["dispatcher"].py_func.__name__)


event.register("numba:compile", Listener())
flags = compile_ahead.KINDS["polynomial"]
before = flags in compile_ahead.cached()
compile_ahead.start(["polynomial"])
started = flags in compile_ahead._PENDING
compile_ahead.wait_for(flags)
after = flags in compile_ahead.cached()
u = np.sin(2 * np.pi * 9.0 * np.arange(3000) / 512.0)
simulate(SEED_LIKE_CUBIC, u, 1 / 512, z0=0.02)
p = np.repeat(SEED_LIKE_CUBIC.kernel_params()[:, None], 3, axis=1)
simulate_batch(p, "polynomial", u, 1 / 512, np.zeros(2))
again = compile_ahead._PENDING.copy()
compile_ahead.start(["polynomial"])
print(json.dumps({"before": before, "started": started, "after": after, "compiled": compiled,
                  "restarted": bool(compile_ahead._PENDING) or bool(again)}))
"""


@pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="a helper needs a second core to compile beside a fit")
def test_a_kernel_compiled_by_its_helper_is_loaded_by_the_fit_not_compiled_again(tmp_path):
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba")}
    for name in ("NUMBA_DISABLE_JIT", "NEGSTIFF_COMPILE_AHEAD", "NEGSTIFF_THREADS"):
        env.pop(name, None)
    out = subprocess.run([sys.executable, "-c", PROBE], env=env, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    seen = json.loads(out.stdout.strip().splitlines()[-1])
    assert not seen["before"] and seen["started"], "an empty cache: the helper is started"
    assert seen["after"], "the helper, awaited, left the kernel in the cache"
    assert "_integrate" not in seen["compiled"], f"the fit's process compiled the kernel again: {seen['compiled']}"
    assert not seen["restarted"], "a kernel the cache holds starts no helper"


def test_helpers_off_start_nothing(monkeypatch):
    from negstiff.models import compile_ahead

    monkeypatch.setenv("NEGSTIFF_COMPILE_AHEAD", "off")
    monkeypatch.setattr(compile_ahead, "cached", set)  # as if the cache were empty
    compile_ahead.start(["polynomial"])
    assert not compile_ahead._PENDING
