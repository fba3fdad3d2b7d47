"""The estimator contract (inference/estimator.py, after scikit-learn's): parameters stored as given in
__init__, validated in fit, fit returns self, learned state in attributes ending in _, result() the
contract's JSON."""

import inspect

import pytest

from negstiff.inference.discrepancy import Discrepancy
from negstiff.inference.estimator import Estimator
from negstiff.inference.nsi import NSI
from negstiff.inference.posterior import Posterior
from negstiff.inference.sindy import SINDy
from negstiff.inference.updating import GAUpdater, UpdatingError

ESTIMATORS = (NSI, SINDy, Discrepancy, Posterior, GAUpdater)


@pytest.mark.parametrize("cls", ESTIMATORS, ids=lambda c: c.__name__)
def test_parameters_are_stored_as_given(cls):
    # every constructor parameter is an attribute of the same name holding its default; repr shows them
    est = cls()
    assert isinstance(est, Estimator)
    params = est.get_params()
    sig = inspect.signature(cls.__init__).parameters
    assert set(params) == set(sig) - {"self"}
    for name, p in sig.items():
        if name != "self" and not isinstance(p.default, (tuple, list)):
            assert params[name] is p.default or params[name] == p.default, name
    assert repr(est).startswith(cls.__name__ + "(")


def test_bad_parameters_are_refused_by_fit_not_by_the_constructor():
    # scikit-learn's convention: the constructor stores, fit validates (before any work)
    ga = GAUpdater(pop_size=2)
    with pytest.raises(UpdatingError, match="pop_size"):
        ga.fit({"f_minus": 5.0, "f_plus": 6.0, "z_minus": -0.01, "z_plus": 0.01})
    post = Posterior(model="nonsense")
    with pytest.raises(ValueError, match="model must be"):
        post.fit(None)
