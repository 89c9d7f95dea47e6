"""Time gaps are checked at the state where they happen, online as in batch; a start where the model
is not finite is refused, naming the states to give."""
from __future__ import annotations

import numpy as np
import pytest

import casship as cs
from casship.simulation import ValidityError, stable_step


@pytest.fixture(scope="module")
def accelerating_ship():
    """KVLCC2 from 0.5 m/s to about 6.9 m/s at full propeller rate, sampled at 1 s, with the rows
    from 2000 to 2120 s missing (a 120 s gap at full speed)."""
    m = cs.models.get_model("kvlcc2")
    t = np.arange(0.0, 2400.0, 1.0)
    truth = cs.simulate(m, m.states(u=0.5), t, {"delta": 0.0, "n": 1.53})
    data = cs.measure(truth, m, {"x": 1.0, "y": 1.0, "psi": 1e-3}, seed=4).select(["delta", "n", "x", "y", "psi"])
    keep = (t <= 2000.0) | (t >= 2120.0)
    return m, truth, cs.Dataset(t[keep], {k: data[k][keep] for k in data.names})


def _ekf(m, **options):
    return cs.EKF(cs.discretize(m, 1.0, "rk4"), Q=1e-8, R={"x": 1.0, "y": 1.0, "psi": 1e-6},
                  measured=["x", "y", "psi"], options=options)


def test_the_limit_differs_by_state(accelerating_ship):
    m, truth, _ = accelerating_ship
    u = m.inputs(delta=0.0, n=1.53)
    slow, fast = (stable_step(m, m.states(u=s), u, m.params(), "rk4") for s in (0.5, truth["u"][2000]))
    assert slow > 120.0 > fast          # the gap passes at the start, not where it happens


def test_batch_gap_checked_at_full_speed(accelerating_ship):
    """Before: the limit was taken at the prior (238 s at 0.5 m/s), so the 120 s gap passed."""
    m, truth, data = accelerating_ship
    prior = cs.Gaussian(m.states(u=0.5), np.diag([0.1, 0.1, 1e-6, 1.0, 1.0, 1e-6]))
    with pytest.raises(ValueError, match=r"time gap of 120 s between t = 2000 and 2120 s .* from the estimate there"):
        _ekf(m).filter(data, prior)
    with pytest.warns(UserWarning, match=r"1 time gap\(s\) .* bridged by \d+ prediction-only row"):
        res = _ekf(m, on_gap="bridge").filter(data, prior)
    assert np.all(np.isfinite(res.x)) and len(res) > len(data)
    assert res["u"][-1] == pytest.approx(truth["u"][-1], abs=0.05)


@pytest.mark.parametrize("jit", [False, True], ids=["interpreted", "compiled"])
def test_online_gap_checked_at_full_speed_as_in_batch(accelerating_ship, jit):
    """Before: online, the limit was taken at the prior and only ever rose, so this gap was never checked."""
    m, truth, data = accelerating_ship
    prior = cs.Gaussian(m.states(u=0.5), np.diag([0.1, 0.1, 1e-6, 1.0, 1.0, 1e-6]))
    U, Y = data.matrix(["delta", "n"]), data.matrix(["x", "y", "psi"])
    run = _ekf(m, jit=jit).online(prior, u=U[0])
    dts = np.concatenate([[0.0], data.dt])
    with pytest.raises(ValueError, match=r"time gap of 120 s before update 2002 .* from the estimate there"):
        for k in range(len(data)):
            run.update(Y[k], dts[k], U[k - 1] if k else U[0], U[k])
    assert run.x[0] == pytest.approx(truth["u"][2000], abs=0.05)     # refused: the state is the one before it


def test_a_start_where_the_model_is_not_finite_is_refused(accelerating_ship):
    """Before: u = v = 0 gave NaN estimates ("variance of 'u' at row 0 is nan")."""
    m, _, data = accelerating_ship
    with pytest.raises(ValidityError, match=r"cannot start at the prior mean .* give the starting value: x0 u=\.\.\., v=\.\.\."):
        _ekf(m).filter(data, cs.Gaussian(m.states(), 1.0))
    with pytest.raises(ValidityError, match="cannot start"):
        _ekf(m).online(cs.Gaussian(m.states(), 1.0), u=[0.0, 1.53])


def test_prior_from_data_reads_the_track_and_names_its_sources(accelerating_ship):
    m, truth, data = accelerating_ship
    late = data.slice(1500, 2000)
    prior = cs.prior_from_data(m, late, measured=["x", "y", "psi"], R={"x": 1.0, "y": 1.0, "psi": 1e-6})
    i = m.index("u")
    assert prior.mean[i] == pytest.approx(truth["u"][1500], rel=0.02)
    assert prior.sources["u"].startswith("speed over ground of the track x, y")
    assert prior.sources["psi"].startswith("first sample of column 'psi'") and prior.cov[5, 5] == 1e-6
    assert prior.defaulted() == ["v"]
    given = cs.prior_from_data(m, late, measured=["x", "y", "psi"], x0={"v": 0.1})
    assert given.sources["v"] == "given" and given.mean[1] == 0.1
    with pytest.raises(ValueError, match=r"x0: unknown state\(s\) \['w'\]"):
        cs.prior_from_data(m, late, x0={"w": 1.0})
    res = _ekf(m).filter(late, prior)
    assert np.all(np.isfinite(res.x)) and np.isfinite(res.loglik)
