"""Output error with a discrete-time model: the model's own step is used, and a record sampled at
another step is refused instead of being stepped silently at the wrong rate."""
import numpy as np
import pytest

import casship as cs
from gaussian_reference import DT, cv_model


def record(step):
    t = np.arange(20) * step
    return cs.Dataset(t, {"a": np.ones(20), "y1": 0.5 * t**2, "y2": 0.5 * t**2 + 2 * t})


def test_a_discrete_time_model_is_taken_as_it_is():
    sigma = {"y1": 0.1, "y2": 0.1}
    direct = cs.OutputErrorProblem(cv_model(), record(DT), free=["g"], sigma=sigma)
    stepped = cs.OutputErrorProblem(cs.discretize(cv_model()), record(DT), free=["g"], sigma=sigma)
    assert direct.cost({"g": 0.8}) == stepped.cost({"g": 0.8})
    # x = t^2 / 2 and x + 2 v = t^2 / 2 + 2 t are the exact outputs of the unit input from rest
    assert direct.cost({"g": 1.0}) == pytest.approx(0.0, abs=1e-20)


@pytest.mark.parametrize("given", [cv_model, lambda: cs.discretize(cv_model())], ids=["model", "dmodel"])
def test_a_record_at_another_step_is_refused(given):
    with pytest.raises(ValueError, match="discrete-time"):
        cs.OutputErrorProblem(given(), record(2 * DT), free=["g"], sigma={"y1": 0.1, "y2": 0.1})
