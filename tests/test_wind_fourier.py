"""Koike et al.'s (2023) Eq. 34: Fujiwara's Fourier-form wind loads (1998 regression)."""
import numpy as np
import pytest

from casship.models import esso_osaka_twin
from casship.models.wind import fujiwara_coefficients, relative_wind
from casship.models.wind_fourier import (ESSO_OSAKA_3M_WIND, add_fourier_wind, fourier_wind_coefficients,
                                         fourier_wind_loads, fujiwara1998_coefficients)
from model_checks import assert_jacobians

G = {k: v for k, v in ESSO_OSAKA_3M_WIND.items() if k != "source"}


@pytest.mark.parametrize("deg, index", [(0.0, 0), (90.0, 1), (180.0, 0), (-90.0, 1)])
def test_agrees_with_the_independent_2005_regression_head_beam_and_stern(deg, index):
    """Two regressions of the same research group on different data: head, beam and stern wind
    coefficients of the Esso Osaka 3 m model agree within 10 % (a mistyped constant would not)."""
    gamma = np.radians(deg)
    new = fourier_wind_coefficients(gamma, fujiwara1998_coefficients(G))[index]
    old = fujiwara_coefficients(gamma, {k: v for k, v in G.items() if k != "C_BR"})[index]
    assert new == pytest.approx(old, rel=0.1)


def test_symmetry_and_physical_directions():
    c = fujiwara1998_coefficients(G)
    for deg in (10.0, 45.0, 100.0, 170.0):
        a, b = fourier_wind_coefficients(np.radians(deg), c), fourier_wind_coefficients(-np.radians(deg), c)
        assert a[0] == pytest.approx(b[0], abs=1e-12)               # C_X even
        assert a[1] == pytest.approx(-b[1], abs=1e-12)              # C_Y odd
        assert a[2] == pytest.approx(-b[2], abs=1e-12)              # C_N odd
    X, Y, N = fourier_wind_loads(10.0, np.radians(90.0), G)          # wind from starboard
    assert Y < 0 and N > 0            # pushed to port; superstructure aft: the bow turns into the wind
    assert fourier_wind_loads(10.0, 0.0, G)[0] < 0 < fourier_wind_loads(10.0, np.pi, G)[0]


def test_model_term_equals_the_loads():
    """The wind model's surge and yaw accelerations minus the wind-free ship's, at u = 0.3 m/s with a
    head-on and a beam wind, equal the loads over the (rigid-body + added) mass."""
    ship = esso_osaka_twin()
    windy = add_fourier_wind(ship, ESSO_OSAKA_3M_WIND)
    x = ship.states(u=0.3)
    for wind_dir in (0.0, np.pi / 2):
        u = windy.inputs(n=5.0, wind_speed=4.0, wind_dir=wind_dir)
        d = np.ravel(windy.f(x, u, windy.params(), np.zeros(windy.nw))) - \
            np.ravel(ship.f(x, ship.inputs(n=5.0), ship.params(), np.zeros(ship.nw)))
        U_A, gamma = relative_wind(0.3, 0.0, 0.0, 4.0, wind_dir)
        X, Y, N = fourier_wind_loads(U_A, gamma, G)
        p = ship.param_dict()
        L, dr, rho = p["L_pp"], p["d"], p["rho"]
        m = p["m_dash"] * 0.5 * rho * L**2 * dr
        mx = p["m_x_dash"] * 0.5 * rho * L**2 * dr
        assert d[ship.state_names.index("u")] == pytest.approx(X / (m + mx), rel=1e-9)
        if wind_dir:
            assert np.sign(d[ship.state_names.index("v")]) == np.sign(Y) != 0


def test_jacobians_and_bad_geometry():
    windy = add_fourier_wind(esso_osaka_twin(), ESSO_OSAKA_3M_WIND)
    assert_jacobians(windy, windy.states(u=0.4, v=0.05, r=0.01, psi=0.3),
                     windy.inputs(n=8.0, delta_s=0.2, delta_p=-0.1, wind_speed=2.0, wind_dir=1.0))
    with pytest.raises(ValueError, match="C_BR"):
        add_fourier_wind(esso_osaka_twin(), {k: v for k, v in G.items() if k != "C_BR"})
    with pytest.raises(ValueError, match="unknown wind geometry.*'H'"):
        add_fourier_wind(esso_osaka_twin(), {**G, "H": 1.0})
