"""A gated EKF that trusted a frozen GNSS receiver finds the ship again with ``reacquire``."""
import numpy as np
import pytest

import casship as cs
from casship.models import sog_cog

Q = np.diag([1e-2, 1e-3])


def frozen_record(seed=10):
    m = sog_cog()
    rng = np.random.default_rng(seed)
    prior = cs.Gaussian(m.states(U=3.0, chi=0.5), [4.0, 4.0, 0.25, 0.01, 1e-4])
    t = np.arange(2400) * 0.1
    truth = cs.simulate(m, prior.sample(1, rng)[0], t, w=rng.standard_normal((t.size, 2)) @ np.sqrt(Q),
                        method="euler")
    data = cs.measure(truth, m, {"x_n": 1.0, "y_n": 1.0}, seed=rng)
    frozen = (t >= 100.0) & (t < 160.0)            # the receiver repeats its last fix for a minute
    k0 = np.flatnonzero(frozen)[0] - 1
    stuck = data.with_columns(x_n=np.where(frozen, data["x_n"][k0], data["x_n"]),
                              y_n=np.where(frozen, data["y_n"][k0], data["y_n"]))
    return m, truth, stuck, prior


def run(options, data, prior):
    return cs.EKF(cs.discretize(sog_cog(), 0.1, method="euler"), Q, 1.0, options=options).filter(data, prior)


def error(res, truth):
    return np.hypot(res["x_n"] - truth["x_n"], res["y_n"] - truth["y_n"])


def test_gated_filter_with_reacquire_recovers_after_a_frozen_sensor():
    m, truth, stuck, prior = frozen_record()
    after = stuck.t > 190.0
    locked = run({"gate": 0.999}, stuck, prior)
    assert locked.rejected[after].sum() > 100                  # without re-acquisition it stays lost
    res = run({"gate": 0.999, "reacquire": 10}, stuck, prior)
    assert res.rejected[after].sum() <= 3
    assert error(res, truth)[after].max() < 1.5


def test_reacquire_changes_nothing_on_clean_data_and_online_equals_batch():
    m, truth, _, prior = frozen_record(seed=3)
    clean = cs.measure(truth, m, {"x_n": 1.0, "y_n": 1.0}, seed=4)
    plain = run({"gate": 0.999}, clean, prior)
    ekf = cs.EKF(cs.discretize(sog_cog(), 0.1, method="euler"), Q, 1.0, options={"gate": 0.999, "reacquire": 10})
    res = ekf.filter(clean, prior)
    assert plain.rejected.sum() < 10                      # nothing close to ten in a row on clean data
    np.testing.assert_allclose(res.x, plain.x, rtol=0, atol=1e-12)
    compiled = cs.EKF(ekf.dmodel, Q, 1.0, options={"gate": 0.999, "reacquire": 10, "jit": True})
    for est in (ekf, compiled):                           # the compiled update carries the count too
        run_online = est.online(prior)
        xs = [run_online.update(np.array([clean["x_n"][k], clean["y_n"][k]]), 0.0 if k == 0 else 0.1)
              for k in range(300)]
        np.testing.assert_allclose(np.array(xs), res.x[:300], rtol=0, atol=1e-10)
    assert ekf.memory == ("x", "P", "rejections")             # the count of rejections is memory too
    assert ekf.step.name_out()[:3] == ["x", "P", "rejections"]


def test_reacquire_needs_a_gate_and_a_positive_count():
    dm = cs.discretize(sog_cog(), 0.1)
    with pytest.raises(ValueError, match="needs a 'gate'"):
        cs.EKF(dm, Q, 1.0, options={"reacquire": 5})
    with pytest.raises(ValueError, match="positive number"):
        cs.EKF(dm, Q, 1.0, options={"gate": 0.99, "reacquire": 0})
