"""Reference values of the autopilot's bookkeeping: the gains a speed schedule hands out (each against
an independent point design at that speed, and the hand-computed interpolation between), and the MPC's
reference preview (the reference model's exact response, entering the plan at the sample of the step)."""
from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from scipy.linalg import expm

from casship import autopilot as ap
from casship.autopilot.mpc import MPCAutopilot
from casship.autopilot.nomoto import Nomoto
from casship.autopilot.plants import piecewise_linear
from casship.autopilot.reference import ReferenceModel
from casship.models import get_model

GAINS = ("Kp", "Kd", "Ki", "m", "d", "m_hf", "T3")


@pytest.fixture(scope="module")
def schedule():
    ship = get_model("kvlcc2")
    U0 = ship.vessel.U0
    speeds = [0.4 * U0, 0.7 * U0, U0]
    d = ap.design_autopilot(ship, U0 / 2, schedule=speeds)
    points = [ap.design_autopilot(ship, v) for v in speeds]        # designed on their own, no schedule
    return d.autopilot, points


def test_schedule_hands_out_each_point_designs_gains_at_its_speed(schedule):
    law, points = schedule
    for v, point in zip(law.speeds, points):
        got, want = law.at(v), point.autopilot
        for name in GAINS:
            assert getattr(got.gains, name) == pytest.approx(getattr(want.gains, name), rel=1e-9), (v, name)
        for name in ("wn", "zeta", "r_max"):
            assert getattr(got.reference, name) == pytest.approx(getattr(want.reference, name), rel=1e-9)
        assert got.steer_max == pytest.approx(want.steer_max, rel=1e-12)
        if want.steering is not None:
            np.testing.assert_allclose(got.steering.steer, want.steering.steer, rtol=1e-9)
            np.testing.assert_allclose(got.steering.rates, want.steering.rates, rtol=1e-9)
            assert got.steering.r_top == pytest.approx(want.steering.r_top, rel=1e-9)


def test_schedule_between_design_speeds_is_the_linear_interpolation(schedule):
    law, points = schedule
    v0, v1, v2 = law.speeds
    for frac in (0.25, 0.5, 0.75):
        for lo, hi, a, b in ((points[0], points[1], v0, v1), (points[1], points[2], v1, v2)):
            got = law.at(a + frac * (b - a)).gains
            for name in GAINS:
                want = (1 - frac) * getattr(lo.gains, name) + frac * getattr(hi.gains, name)
                assert getattr(got, name) == pytest.approx(want, rel=1e-9), (frac, name)
    # held beyond the designed range
    for name in GAINS:
        assert getattr(law.at(0.5 * v0).gains, name) == pytest.approx(getattr(points[0].gains, name), rel=1e-9)
        assert getattr(law.at(2.0 * v2).gains, name) == pytest.approx(getattr(points[2].gains, name), rel=1e-9)


@pytest.mark.parametrize("x, want", [(0.0, 10.0), (1.0, 10.0), (1.5, 15.0), (2.0, 20.0), (3.0, 10.0), (3.5, 5.0),
                                     (4.0, 0.0), (9.0, 0.0)])
def test_piecewise_linear_by_hand(x, want):
    xs, ys = [1.0, 2.0, 4.0], [10.0, 20.0, 0.0]
    assert piecewise_linear(x, xs, ys) == pytest.approx(want, abs=1e-12)
    s = ca.SX.sym("s")
    f = ca.Function("f", [s], [piecewise_linear(s, xs, ys)])
    assert float(f(x)) == pytest.approx(want, abs=1e-12)


# -- the MPC's preview of the reference model ------------------------------------------------------------------
WN, PERIOD, DT, N = 0.05, 2.0, 1.0, 12


def mpc():
    return MPCAutopilot(Nomoto(K=0.05, T=30.0), PERIOD, N, np.radians(35.0), np.radians(2.3), np.radians(1.0),
                        q_e=1.0, q_r=10.0, r_u=100.0, reference=ReferenceModel(WN, 1.0, 1.0), replan=DT)


def reference_A():
    w, z = WN, 1.0
    return np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [-w**3, -(2 * z + 1) * w**2, -(2 * z + 1) * w]])


def test_preview_matrix_is_the_reference_models_exact_response_one_period_per_step():
    M = mpc().preview_matrix()
    A = reference_A()
    for k in range(N):               # plan step k is the state at (k + 1) periods
        np.testing.assert_allclose(M[2 * k:2 * k + 2], expm(A * (k + 1) * PERIOD)[:2], rtol=1e-10, atol=1e-14)


def test_a_reference_step_enters_the_plan_at_the_sample_it_is_commanded(monkeypatch):
    m = mpc()
    targets = []
    solve = MPCAutopilot._solve

    def spy(self, args):
        targets.append(np.array(args["target"], dtype=float))
        return solve(self, args)

    monkeypatch.setattr(MPCAutopilot, "_solve", spy)
    mem = m.memory0(0.0)
    step_at, s = 3, np.radians(10.0)
    for j in range(6):
        ref = s if j >= step_at else 0.0
        mem, _, _ = m.update(mem, ref, 0.0, 0.0, DT)
    assert len(targets) == 6                     # re-planned every sample
    for j in range(step_at):
        assert not targets[j].any(), j           # nothing commanded yet: the plan tracks zero
    # at the step: one loop step of the reference model (Euler, as in the PID law) from rest, then its
    # exact response relative to the new command, one column per period
    xr = np.array([0.0, 0.0, DT * WN**3 * s])
    z = xr - np.array([s, 0.0, 0.0])
    A = reference_A()
    want = np.column_stack([expm(A * (k + 1) * PERIOD)[:2] @ z for k in range(N)])
    np.testing.assert_allclose(targets[step_at], want, rtol=1e-10, atol=1e-16)
    assert targets[step_at][0, 0] == pytest.approx(-s, rel=0.01)       # the error enters in full at once
