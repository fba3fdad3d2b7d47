"""A pytest file that keeps its fits between sessions (``negstiff.testing.cached_fit``) fits nothing the
second time: the inner test file below is run twice in new pytest processes on one cache folder, and a
counter of the fits actually made (each ``NSI.fit`` appends a line to a file) says 1, then still 1; the
second session's checks see the same fitted numbers.
"""

import os
import subprocess
import sys
from pathlib import Path

INNER = """
import os, sys, warnings
from pathlib import Path
sys.path.insert(0, os.environ["TESTS_DIR"])
from records import FS, TRUTH, rk4_random_records
from negstiff import NSI, from_arrays
from negstiff.testing import cached_fit

COUNTER = Path(os.environ["FIT_COUNTER"])


def test_the_cached_fit_recovers_k3(monkeypatch):
    fit = NSI.fit

    def counted(self, data):
        with COUNTER.open("a") as fh:
            fh.write("fit\\n")
        return fit(self, data)

    monkeypatch.setattr(NSI, "fit", counted)
    ((u, z),) = rk4_random_records([31], duration=30.0)
    rec = from_arrays(u, z, FS, mass=TRUTH.m)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        nsi = cached_fit(NSI(), rec, os.environ["FIT_CACHE"])
    assert abs(nsi.model_.k3 / TRUTH.k3 - 1) < 0.01  # a cubic within 1 % on a 3 um laser's record
    Path(os.environ["FIT_COUNTER"] + ".k3").write_text(repr(nsi.model_.k3))
"""


def test_the_second_session_fits_nothing(tmp_path):
    (tmp_path / "test_inner.py").write_text(INNER)
    counter = tmp_path / "fits.txt"
    env = {**os.environ, "TESTS_DIR": str(Path(__file__).parents[1]), "FIT_CACHE": str(tmp_path / "cache"),
           "FIT_COUNTER": str(counter)}  # fmt: skip
    k3 = []
    for _ in range(2):
        done = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "test_inner.py"],
                              cwd=tmp_path, env=env, capture_output=True, text=True)  # fmt: skip
        assert done.returncode == 0, done.stdout[-2000:]
        k3.append(Path(str(counter) + ".k3").read_text())
    assert counter.read_text().count("fit") == 1  # the first session fitted, the second loaded its fit
    assert k3[0] == k3[1]
    assert len(list((tmp_path / "cache").glob("NSI-*.pkl"))) == 1
