"""Fujiwara wind loads and uniform current as terms on a 3-DOF ship."""
import math

import numpy as np
import pytest

from casship import simulate
from casship.models import kvlcc2
from casship.models.wind import add_current, add_wind, fujiwara_coefficients, fujiwara_loads, relative_wind
from model_checks import assert_jacobians

G = {"A_F": 1000.0, "A_L": 4000.0, "L_OA": 300.0, "B": 50.0, "A_OD": 800.0, "H_BR": 40.0, "H_C": 12.0, "C": 6.0}


def test_hand_computed_value_bow_quarter():
    """30 deg off the starboard bow, 20 m/s apparent wind: the regression evaluated by hand."""
    L, B, A_F, A_L, A_OD, H_BR, C = 300.0, 50.0, 1000.0, 4000.0, 800.0, 40.0, 6.0
    C_LF = -0.922 + 0.507 * A_L / (L * B) + 1.162 * C / L                 # -0.76356
    C_XLI = 0.458 + 3.245 * A_L / (L * H_BR) - 2.313 * A_F / (B * H_BR)   # 0.383167
    C_ALF = -0.585 - 0.906 * A_OD / A_L + 3.239 * B / L                   # -0.226367
    C_CF = 0.404 + 0.368 * A_F / (B * H_BR) + 0.902 * H_BR / L            # 0.708267
    C_YLI = math.pi * A_L / L**2 + 0.116 + 3.345 * A_F / (L * B)          # 0.478626
    assert (C_LF, C_XLI, C_ALF, C_CF) == pytest.approx((-0.76356, 0.383167, -0.226367, 0.708267), abs=1e-6)
    th = math.radians(30.0)
    s, c = math.sin(th), math.cos(th)
    CX = C_LF * c + C_XLI * (s - 0.5 * s * c * c) * s * c + C_ALF * s * c**3
    CY = C_CF * s * s + C_YLI * (c + 0.5 * s * s * c) * s * c
    CN = CY * (0.927 * C / L - 0.149 * (th - math.pi / 2))
    q = 0.5 * 1.225 * 20.0**2
    X, Y, N = fujiwara_loads(20.0, th, G)
    assert X == pytest.approx(q * A_F * CX, rel=1e-12)
    assert Y == pytest.approx(-q * A_L * CY, rel=1e-12)        # pushed to port
    assert N == pytest.approx(-q * A_L * L * CN, rel=1e-12)    # bow pushed to port
    assert X < 0 and Y < 0 and N < 0
    assert Y == pytest.approx(-245.0 * 4000.0 * 0.37899, rel=1e-4)   # q = 245 Pa, C_Y = 0.37899 by hand


def test_signs_and_mirror_symmetry():
    for deg in (10, 45, 80, 100, 135, 170):
        g = math.radians(deg)
        cx_s, cy_s, cn_s = fujiwara_coefficients(g, G)
        cx_p, cy_p, cn_p = fujiwara_coefficients(-g, G)
        assert cx_s == pytest.approx(cx_p) and cy_s == pytest.approx(-cy_p) and cn_s == pytest.approx(-cn_p)
        assert cy_s < 0                        # wind from starboard pushes to port
    assert fujiwara_coefficients(0.0, G)[0] < 0 < fujiwara_coefficients(math.pi, G)[0]   # head / following
    # continuity at the 90 deg switch
    lo = np.array(fujiwara_coefficients(math.pi / 2 - 1e-9, G))
    hi = np.array(fujiwara_coefficients(math.pi / 2 + 1e-9, G))
    np.testing.assert_allclose(lo, hi, atol=1e-6)


def test_relative_wind():
    # ship at 5 m/s heading North, no wind: 5 m/s head wind
    U, g = relative_wind(5.0, 0.0, 0.0, 0.0, 0.0)
    assert U == pytest.approx(5.0) and g == pytest.approx(0.0)
    # ship at rest heading East, wind from North: wind on the port beam (gamma = -90 deg)
    U, g = relative_wind(0.0, 0.0, math.pi / 2, 10.0, 0.0)
    assert U == pytest.approx(10.0) and g == pytest.approx(-math.pi / 2)


def test_wind_term_enters_tau():
    ship = kvlcc2()
    windy = add_wind(ship)
    assert windy.input_names == ("delta", "n", "wind_speed", "wind_dir")
    x = ship.states(u=6.0, psi=0.4)
    p0 = ship.params()
    f0 = np.asarray(ship.f(x, ship.inputs(n=1.7), p0, np.zeros(3))).ravel()
    f1 = np.asarray(windy.f(x, windy.inputs(n=1.7, wind_speed=15.0, wind_dir=0.4), windy.params(),
                            np.zeros(3))).ravel()
    P = ship.param_dict()
    m = P["rho"] * P["nabla"]
    m_x = P["m_x_dash"] * 0.5 * P["rho"] * P["L_pp"] ** 2 * P["d"]
    geom = dict(ship.vessel.wind)
    geom.pop("source")
    X, Y, N = fujiwara_loads(21.0, 0.0, geom)          # head wind 15 + 6 m/s
    assert f1[0] - f0[0] == pytest.approx(X / (m + m_x), rel=1e-9)
    assert f1[2] == pytest.approx(f0[2], abs=1e-15)    # no yaw moment in a head wind
    assert_jacobians(windy, ship.states(u=5.0, v=-0.3, r=0.004, psi=1.0),
                     windy.inputs(delta=0.2, n=1.6, wind_speed=12.0, wind_dir=2.0))


def test_time_series_wind_drifts_a_ship_at_rest():
    ship = add_wind(kvlcc2())
    t = np.arange(0, 200, 1.0)
    speed = np.where(t < 100, 20.0, 0.0)             # wind from the West (blowing East), then calm
    tr = simulate(ship, ship.states(), t, {"delta": 0.0, "n": 0.0, "wind_speed": speed, "wind_dir": -np.pi / 2})
    assert tr["y"][-1] > 0.1 and tr["v"][99] > 0      # pushed to starboard = East
    assert abs(tr["v"][-1]) < abs(tr["v"][99])         # decays once the wind stops


def test_current_adds_to_kinematics():
    ship = add_current(kvlcc2())
    t = np.arange(0, 100, 1.0)
    tr = simulate(ship, ship.states(u=5.0), t, {"delta": 0.0, "n": 1.2, "current_speed": 1.0,
                                                 "current_dir": np.pi / 2})
    base = simulate(kvlcc2(), kvlcc2().states(u=5.0), t, {"delta": 0.0, "n": 1.2})
    np.testing.assert_allclose(tr["x"], base["x"], rtol=1e-12)
    np.testing.assert_allclose(tr["y"], t * 1.0, atol=1e-9)
    both = add_wind(ship)
    assert both.input_names[-2:] == ("wind_speed", "wind_dir")


def test_missing_geometry_raises():
    from casship.models import kvlcc2_l7
    with pytest.raises(ValueError, match="wind geometry"):
        add_wind(kvlcc2_l7())
