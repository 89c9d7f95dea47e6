"""Otter USV and Mariner-class ship: Jacobians, symmetry, straight runs, deceleration, metadata."""
import numpy as np
import pytest

from casship import simulate
from casship.maneuvers import propeller_rate_for_speed, run_maneuver
from casship.models import get_model, mariner, otter
from casship.models.otter import hoerner_cd
from model_checks import assert_jacobians

SYMMETRIC = {"Y0": 0.0, "Y0u": 0.0, "Y0uu": 0.0, "N0": 0.0, "N0u": 0.0, "N0uu": 0.0}


@pytest.mark.parametrize("propeller_dynamics", [False, True])
def test_otter_jacobians(propeller_dynamics):
    boat = otter(propeller_dynamics=propeller_dynamics)
    rng = np.random.default_rng(5)
    for _ in range(5):
        vals = dict(u=rng.uniform(-0.5, 3), v=rng.uniform(-0.5, 0.5), r=rng.uniform(-0.5, 0.5),
                    x=rng.normal(), y=rng.normal(), psi=rng.uniform(-3, 3))
        if propeller_dynamics:
            vals.update(n1=rng.uniform(-90, 100), n2=rng.uniform(-90, 100))
            inp = boat.inputs(n1_cmd=50.0, n2_cmd=-20.0)
        else:
            inp = boat.inputs(n1=rng.uniform(-90, 100), n2=rng.uniform(-90, 100))
        assert_jacobians(boat, boat.states(**vals), inp)


def test_otter_constants_and_thrust_asymmetry():
    boat = otter()
    assert boat.vessel.draught == pytest.approx(80 / 1025 / (2 * 0.4 * 0.25 * 2.0))
    assert boat.meta["C_D"] == pytest.approx(hoerner_cd(0.25, boat.vessel.draught))
    assert boat.vessel.propeller_range[1] == pytest.approx(np.sqrt(0.5 * 24.4 * 9.81 / (0.02216 / 2)))
    # at rest, forward thrust k_pos n^2 exceeds astern thrust k_neg n^2 by k_pos/k_neg
    x0 = boat.states()
    fwd = np.asarray(boat.f(x0, boat.inputs(n1=50, n2=50), boat.params(), np.zeros(3))).ravel()[0]
    aft = np.asarray(boat.f(x0, boat.inputs(n1=-50, n2=-50), boat.params(), np.zeros(3))).ravel()[0]
    assert fwd / -aft == pytest.approx(0.02216 / 0.01289)


def test_otter_mirror_and_straight_run():
    boat = otter()
    t = np.arange(0, 40, 0.05)
    a = simulate(boat, boat.states(u=1.5), t, {"n1": 90.0, "n2": 60.0})
    b = simulate(boat, boat.states(u=1.5), t, {"n1": 60.0, "n2": 90.0})
    np.testing.assert_allclose(a["u"], b["u"], rtol=1e-10)
    for name in ("v", "r", "y", "psi"):
        np.testing.assert_allclose(a[name], -b[name], rtol=1e-9, atol=1e-12)
    assert a["r"][-1] > 0          # stronger port propeller turns to starboard
    n = propeller_rate_for_speed(boat, 2.0)
    s = simulate(boat, boat.states(u=2.0, psi=1.0), t, {"n1": n, "n2": n})
    np.testing.assert_allclose(s["u"], 2.0, atol=1e-9)
    np.testing.assert_allclose(s["psi"], 1.0, atol=1e-12)
    z = simulate(boat, boat.states(u=2.0), t, {"n1": 0.0, "n2": 0.0})
    assert np.all(np.diff(z["u"]) < 0) and z["u"][-1] < 0.5


def test_mariner_jacobians_and_registry():
    ship = get_model("mariner")
    rng = np.random.default_rng(9)
    for _ in range(5):
        x = ship.states(u=rng.uniform(4, 9), v=rng.uniform(-1, 1), r=rng.uniform(-0.01, 0.01), psi=rng.uniform(-3, 3))
        assert_jacobians(ship, x, ship.inputs(delta=rng.uniform(-0.6, 0.6)))
    act = mariner(rudder_actuator=True)
    assert_jacobians(act, act.states(u=7.0, v=0.2, r=0.003, delta=0.1), act.inputs(delta_cmd=0.3))


def test_mariner_symmetry_heading_and_rudder_sign():
    ship = mariner(SYMMETRIC)
    t = np.arange(0, 300, 0.5)
    x0 = ship.states(u=7.7175)
    a = simulate(ship, x0, t, {"delta": np.radians(15)})
    b = simulate(ship, x0, t, {"delta": -np.radians(15)})
    for name in ("v", "r", "y", "psi"):
        np.testing.assert_allclose(a[name], -b[name], rtol=1e-9, atol=1e-9)
    assert a["psi"][-1] > 0        # positive rudder: heading increases
    s = simulate(ship, x0, t, {"delta": 0.0})
    np.testing.assert_allclose(s["psi"], 0.0, atol=1e-12)
    np.testing.assert_allclose(s["u"], 7.7175, atol=1e-12)
    # the published asymmetric terms make the ship drift off course with zero rudder
    drift = simulate(mariner(), x0, t, {"delta": 0.0})
    assert abs(drift["psi"][-1]) > 1e-3


def test_mariner_decelerates_in_a_turn_and_zigzag_runs():
    res = run_maneuver(mariner(), "turning", rudder_deg=35, duration=600)
    assert res.metrics["steady_speed_mps"] < 0.9 * 7.7175
    assert res.metrics["turn_direction"] == 1
    zz = run_maneuver(mariner(), "zigzag", rudder_deg=20, first="port", duration=400)
    assert zz.metrics["first_side"] == -1 and zz.metrics["overshoot_1_deg"] > 0
