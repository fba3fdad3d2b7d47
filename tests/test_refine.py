"""Output-error refinement (issue: models that predict real data), first stage: the library function.
Known truth first (a rig record of a polynomial model, the refinement started off the truth), then
the Silverbox benchmark against the output-error Duffing fit the issue quotes."""

import numpy as np
import pytest

from negstiff.inference.derivatives import state_derivatives
from negstiff.inference.measurement import from_arrays, load
from negstiff.inference.refine import free_run_rms, refine
from negstiff.inference.sindy import SINDy
from negstiff.models import Model
from negstiff.models.device import SEED_LIKE_CROSS_WELL_RMS, SEED_LIKE_CUBIC
from negstiff.models.rig import Rig, Sensors


def test_refinement_returns_to_the_truth_from_a_perturbed_start():
    # Fact: started 5 % off in k1-k3 and 30 % off in c, c_nl, the simulation-error minimum of a
    # noise-free cross-well record is the truth: k1-k3 and c within 0.1 % (0.02 % measured); c_nl within
    # 3 % (it trades with c on 20 s, and the 512 Hz record's linearly interpolated input differs from
    # the rig's 4x oversampled one by ~8 um of response: 1.6 % measured); the windows' error falls to
    # that floor (7.7 um refined from the truth itself; 2.5x it allowed)
    truth = SEED_LIKE_CUBIC
    rec = Rig(truth, seed=6, sensors=Sensors.noiseless()).random(duration=20, rms=SEED_LIKE_CROSS_WELL_RMS)
    m = from_arrays(rec.columns["base_acc"], rec.columns["z"], rec.fs, mass=truth.m)
    start = Model.from_dict({**truth.to_dict(), "k1": truth.k1 * 1.05, "k2": truth.k2 * 0.95, "k3": truth.k3 * 1.05,
                             "c": truth.c * 1.3, "c_nl": truth.c_nl * 0.7})  # fmt: skip
    r = refine(start, m)
    for k in ("k1", "k2", "k3", "c"):
        assert getattr(r.model, k) == pytest.approx(getattr(truth, k), rel=1e-3), k
    assert r.model.c_nl == pytest.approx(truth.c_nl, rel=0.03)
    assert r.stages[-1]["rms_end_m"] < 2.5 * 7.7e-6 < 0.05 * r.stages[0]["rms_start_m"]
    assert r.initial_model == start


def test_silverbox_sindy_refined_predicts_like_an_output_error_duffing(request):
    # Silverbox, standard split: trained on 40650-105712 only, scored by a free run on the multisine
    # test (first 50 samples not scored). SINDy's equation-error model: 2.67 mV; refined by simulation
    # error: at or below the five-parameter output-error Duffing fit's 0.91 mV (the anchor).
    path = request.config.rootpath / "../shared/data/silverbox/SNLS80mV.mat"
    if not path.exists():
        pytest.skip("shared/ data not beside the repository")
    m = load(path, columns="force=V1,z=V2", fs=610.35)
    train, test = m.segment(40650, 105712), m.segment(105712, 127400)
    zs, v, _, _ = state_derivatives(test.z, test.fs, purpose="state")

    def test_mv(model):
        return 1e3 * free_run_rms(model, test.segment(49, test.n), x0=(zs[49], v[49]))

    est = SINDy().fit(train)
    before = test_mv(est.model_)
    r = refine(est.model_, train, free_mass=True)
    after = test_mv(r.model)
    assert after <= 0.91 and after < before / 2.5, (before, after)
    assert np.isfinite(1e3 * free_run_rms(r.model, m.segment(0, 40575))), "the refined model survives the arrow"
