"""MMG standard method and the KVLCC2 presets."""
import numpy as np
import pytest

from casship import simulate
from casship.models import get_model, kvlcc2, kvlcc2_l7
from model_checks import assert_jacobians


@pytest.mark.parametrize("factory", [kvlcc2, kvlcc2_l7])
def test_jacobians_match_central_differences(factory):
    ship = factory()
    rng = np.random.default_rng(3)
    U0 = ship.vessel.U0
    n0 = 1.8 * np.sqrt(320.0 / ship.vessel.L_pp)
    for _ in range(5):
        x = ship.states(u=U0 * rng.uniform(0.3, 1.1), v=U0 * rng.uniform(-0.2, 0.2),
                        r=U0 / ship.vessel.L_pp * rng.uniform(-0.6, 0.6), x=rng.normal(0, 100),
                        y=rng.normal(0, 100), psi=rng.uniform(-np.pi, np.pi))
        u = ship.inputs(delta=rng.uniform(-0.6, 0.6), n=n0 * rng.uniform(0.5, 1.2))
        assert_jacobians(ship, x, u)


def test_registered_names():
    assert get_model("kvlcc2").name == "kvlcc2"
    assert get_model("kvlcc2-l7").vessel.L_pp == 7.0


def test_port_starboard_symmetry():
    """The symmetric hull, rudder and (sign-balanced) wake: -delta mirrors +delta only if the
    flow-straightening and wake constants are made symmetric; with them, v, r, y, psi flip sign."""
    ship = kvlcc2({"gamma_R_minus": 0.5, "gamma_R_plus": 0.5, "C_2_plus": 1.3, "C_2_minus": 1.3})
    t = np.arange(0, 400, 0.5)
    x0 = ship.states(u=7.97)
    a = simulate(ship, x0, t, {"delta": np.radians(20), "n": 1.78})
    b = simulate(ship, x0, t, {"delta": -np.radians(20), "n": 1.78})
    for name in ("u", "x"):
        np.testing.assert_allclose(a[name], b[name], rtol=1e-9, atol=1e-9)
    for name in ("v", "r", "y", "psi"):
        np.testing.assert_allclose(a[name], -b[name], rtol=1e-9, atol=1e-9)
    assert a["psi"][-1] > np.radians(90)          # positive rudder turns to starboard


def test_default_preset_asymmetry_is_the_published_one():
    """With the published gamma_R (0.395/0.640) and C_2 (1.1/1.6) port and starboard differ."""
    ship = kvlcc2()
    t = np.arange(0, 300, 0.5)
    a = simulate(ship, ship.states(u=7.97), t, {"delta": np.radians(35), "n": 1.78})
    b = simulate(ship, ship.states(u=7.97), t, {"delta": -np.radians(35), "n": 1.78})
    assert a["psi"][-1] > 0 > b["psi"][-1]
    assert abs(a["psi"][-1] + b["psi"][-1]) > 1e-3


def test_zero_rudder_keeps_heading():
    ship = kvlcc2()
    t = np.arange(0, 600, 1.0)
    tr = simulate(ship, ship.states(u=7.97, psi=0.3), t, {"delta": 0.0, "n": 1.78})
    np.testing.assert_allclose(tr["psi"], 0.3, atol=1e-12)
    np.testing.assert_allclose(tr["v"], 0.0, atol=1e-12)
    course = np.arctan2(np.diff(tr["y"]), np.diff(tr["x"]))
    np.testing.assert_allclose(course, 0.3, atol=1e-9)


def test_no_propeller_decelerates():
    ship = kvlcc2()
    t = np.arange(0, 600, 1.0)
    tr = simulate(ship, ship.states(u=7.97), t, {"delta": 0.0, "n": 0.0})
    assert np.all(np.diff(tr["u"]) < 0)
    assert 0 < tr["u"][-1] < 0.7 * 7.97


def test_tau_port_and_noise_enter_through_the_mass_matrix():
    """A surge force F in ``tau`` changes du by F/(m + m_x); noise w_u adds directly."""
    ship = kvlcc2()
    pushed = ship.extend(lambda b: b.feed("tau", __import__("casadi").vertcat(b.param("F_push", 1e6), 0, 0)))
    x, u = ship.states(u=7.0), ship.inputs(n=1.7)
    f0 = np.asarray(ship.f(x, u, ship.params(), np.zeros(3))).ravel()
    f1 = np.asarray(pushed.f(x, u, pushed.params(), np.zeros(3))).ravel()
    P = ship.param_dict()
    m = P["rho"] * P["nabla"]
    m_x = P["m_x_dash"] * 0.5 * P["rho"] * P["L_pp"] ** 2 * P["d"]
    assert f1[0] - f0[0] == pytest.approx(1e6 / (m + m_x), rel=1e-12)
    fw = np.asarray(ship.f(x, u, ship.params(), np.array([0.1, 0, 0]))).ravel()
    assert fw[0] - f0[0] == pytest.approx(0.1, rel=1e-12)


def test_rudder_actuator_rate_limit():
    ship = kvlcc2(rudder_actuator=True)
    assert "delta" in ship.state_names and "delta_cmd" in ship.input_names
    t = np.arange(0, 30, 0.1)
    tr = simulate(ship, ship.states(u=7.97), t, {"delta_cmd": np.radians(35), "n": 1.78})
    rate = np.diff(tr["delta"]) / 0.1
    assert rate.max() <= np.radians(2.32) * (1 + 1e-9)
    assert rate.max() > 0.95 * np.radians(2.32)
    assert_jacobians(ship, tr.x[50], ship.inputs(delta_cmd=0.3, n=1.7))


def test_unknown_parameter_raises():
    with pytest.raises(ValueError, match="R0"):
        kvlcc2({"R0": 0.1})
