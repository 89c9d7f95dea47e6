"""The problem specification: a frozen value the problems expose and cross-validation copies."""
import dataclasses

import numpy as np
import pytest

import casship as cs
from casship.identify import MLEProblem, OutputErrorProblem
from casship.identify.spec import ProblemSpec


def _runs(n=3):
    truth = cs.models.nomoto_first_order(K=0.1, T=20.0)
    runs = []
    for i in range(n):
        t = np.arange(0, 200.0, 1.0)
        delta = (0.1 + 0.05 * i) * np.sign(np.sin(2 * np.pi * t / (80 + 15 * i)))
        tr = cs.simulate(truth, truth.states(), t, {"delta": delta})
        d = cs.measure(tr, truth, {"psi": 0.005}, seed=i).with_columns(delta=delta)
        d.meta.update(name=f"run {i}", facility="AB"[i % 2])
        runs.append(d)
    return runs


def test_output_error_spec_holds_the_arguments_and_subsets_per_record_settings():
    runs = _runs()
    model = cs.models.nomoto_first_order()
    x0 = [np.array([0.0, 0.0]), np.array([0.01, 0.0]), np.array([0.02, 0.0])]
    prob = OutputErrorProblem(model, runs, free=["K", "T", "bias[delta]"], sigma={"psi": 0.005}, x0=x0,
                              share={"bias[delta]": "facility"}, record_weights=[1.0, 2.0, 3.0])
    spec = prob.spec
    assert spec.problem is OutputErrorProblem and spec.subject is model and list(spec.free) == ["K", "T", "bias[delta]"]
    assert spec.options.record_weights == [1.0, 2.0, 3.0] and spec.options.sigma == {"psi": 0.005}
    with pytest.raises(dataclasses.FrozenInstanceError):
        spec.free = ["K"]
    with pytest.raises(dataclasses.FrozenInstanceError):
        spec.options.segment = 3                  # the options are read-only too
    part = spec.with_records([runs[2], runs[0]], [2, 0])
    assert part.options.record_weights == [3.0, 1.0] and [v[0] for v in part.x0] == [0.02, 0.0]
    assert spec.options.record_weights == [1.0, 2.0, 3.0]           # the original is untouched
    sub = prob.subset([2, 0])
    assert list(sub.record_weights) == [3.0, 1.0] and sub.labels == ["run 2", "run 0"]
    assert sub.spec.share == {"bias[delta]": "facility"}
    # the same problem rebuilt from its spec costs the same
    assert spec.build().cost() == pytest.approx(prob.cost(), rel=1e-12)
    assert prob.replace(free=["K", "T"], share=None).free == ["K", "T"]
    with pytest.raises(ValueError, match="indices"):
        spec.with_records(runs[:1], [0, 1])


def test_mle_spec_names_its_estimator_and_rebuilds():
    runs = _runs(2)
    dm = cs.discretize(cs.models.nomoto_first_order(), 1.0)
    prob = MLEProblem(dm, runs, free=["K", "T"], Q=np.diag([1e-8]), R=np.diag([0.005 ** 2]),
                      measured=["psi"])
    spec = prob.spec
    assert isinstance(spec, ProblemSpec) and spec.subject_name == "estimator"
    assert spec.subject is prob.estimator and spec.options.Q is None   # the EKF it built carries Q, R
    assert "estimator" in spec.arguments() and "model" not in spec.arguments()
    assert spec.build().cost() == pytest.approx(prob.cost(), rel=1e-12)
    assert prob.subset([1]).labels == ["run 1"]
