"""The CasADi MPC course controller: constraints held, warm start, closed loop."""
import numpy as np
import pytest

import casship as cs
from casship import autopilot as ap
from casship.autopilot.mpc import MPCAutopilot, mpc_for_design


@pytest.fixture(scope="module")
def otter():
    return ap.design_autopilot(cs.models.otter(munk_moment=False))      # the condensed QP fails on the course-unstable Otter


def test_plan_respects_rudder_angle_rate_and_turn_rate_limits():
    nom = ap.Nomoto(K=0.185, T=107.3)
    mpc = MPCAutopilot(nom, period=5.0, horizon=40, steer_max=np.radians(35), rate_max=np.radians(2.32),
                       r_max=np.radians(1.0), q_e=1.0 / np.radians(1.0) ** 2, r_u=1.0)
    mem = mpc.memory0(0.0)
    mem, cmd, log = mpc.update(mem, np.radians(90.0), 0.0, 0.0, 0.5)        # a large course change
    X, U = mem["X"], mem["U"]
    tol = 1e-6
    assert np.all(np.abs(U) <= np.radians(2.32) + tol)
    assert np.all(np.abs(X[2, 1:]) <= np.radians(35) + tol)
    assert np.all(np.abs(X[1, 1:]) <= np.radians(1.0) + tol)
    assert np.max(np.abs(U)) == pytest.approx(np.radians(2.32), rel=1e-6)       # it uses the full rate
    # the plan obeys the discretised model
    A, B, E = mpc.model()
    np.testing.assert_allclose(X[:, 1:], A @ X[:, :-1] + B @ U, atol=1e-9)
    # the command ramps at the planned rate
    assert cmd == pytest.approx(mem["rate"] * 0.5)
    assert log["e"] == pytest.approx(-np.pi / 2)


def test_warm_start_gives_the_cold_start_solution():
    nom = ap.Nomoto(K=0.185, T=107.3, T1=118.0, T2=7.8, T3=18.5)
    mpc = MPCAutopilot(nom, period=5.0, horizon=30, steer_max=0.6, rate_max=0.04, r_max=0.02, r_u=100.0)
    assert mpc.order == 2
    solver = mpc._solver
    x0 = np.array([0.3, 0.001, 0.0, 0.05])
    target = np.zeros((2, 30))
    cold = solver.call({"x0": x0, "b": 0.01, "target": target, "U_guess": np.zeros((1, 30))})
    warm = solver.call({"x0": x0, "b": 0.01, "target": target, "U_guess": np.asarray(cold["U"])})
    np.testing.assert_allclose(np.asarray(warm["U"]), np.asarray(cold["U"]), atol=1e-9)


def test_mpc_closed_loop_on_the_otter(otter):
    mpc = mpc_for_design(otter)
    with pytest.raises(TypeError, match="run_stepwise"):
        otter.closed_loop_system(controller=mpc).step
    res = otter.simulate("course-20", 40.0, controller=mpc, stepwise=True)
    for m in res.metrics:
        assert m["overshoot_pct"] <= 10.0
        assert abs(m["steady_state_error_deg"]) <= 0.5
    assert np.all(np.abs(res.data["steer"]) <= otter.settings.steer_max + 1e-9)
    assert res.performance["rate_limited_fraction"] == 0.0


def test_mpc_settings_are_checked():
    with pytest.raises(ValueError, match="horizon"):
        MPCAutopilot(ap.Nomoto(0.1, 10.0), period=1.0, horizon=1, steer_max=1.0, rate_max=1.0, r_max=1.0)
    with pytest.raises(ValueError, match="rate_max"):
        MPCAutopilot(ap.Nomoto(0.1, 10.0), period=1.0, horizon=5, steer_max=1.0, rate_max=0.0, r_max=1.0)
