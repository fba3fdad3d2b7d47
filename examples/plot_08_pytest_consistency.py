"""
A pytest consistency check
==========================

A lab's regression test: the identified model must agree with the posterior within its own
uncertainty, and predict as well as a reference model. ``negstiff.testing`` takes the tolerances
from the estimates' uncertainty, never from a number picked by hand. Put the function in a
``test_*.py`` file and pytest runs it; here it is called directly.
"""

from negstiff import Measurement, Posterior, Rig, SINDy
from negstiff.models import SEED_LIKE_CUBIC
from negstiff.testing import assert_covers, assert_predicts, assert_wells_agree


def test_device_model_is_consistent():
    rec = Measurement.from_rig(Rig(SEED_LIKE_CUBIC, seed=8).random(duration=40.0, rms=20.0))
    sindy = SINDy(seed=1).fit(rec)
    post = Posterior(seed=1, hdi_prob=0.99).fit(rec.segment(0, int(20 * rec.fs)))
    assert_covers(post, k1=SEED_LIKE_CUBIC.k1, k3=SEED_LIKE_CUBIC.k3)  # the truth in the 99 % intervals
    assert_wells_agree(sindy, post, k=3)  # SINDy's wells within 3 posterior standard deviations
    assert_predicts(sindy.model_, rec, reference=SEED_LIKE_CUBIC, factor=2)  # nearly as good as the truth


# %%
# pytest would collect the function from a ``test_*.py`` file; here it is called directly
test_device_model_is_consistent()
print("consistent")
