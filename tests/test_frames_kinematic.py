"""Frames, WGS-84 geodesy and the kinematic models."""
import casadi as ca
import numpy as np
import pytest

import casship as cs
from casship import frames
from casship.models import constant_acceleration, double_integrator, sog_cog, sog_cog_latlon, tomera_kinematic

LAT0, LON0 = np.radians(63.43), np.radians(10.39)       # Trondheimsfjord


# -- WGS-84 ------------------------------------------------------------------------------------------

def test_wgs84_radii_known_values():
    a, f = 6378137.0, 1 / 298.257223563
    e2 = f * (2 - f)
    r_n, r_m = frames.wgs84_radii(0.0)
    assert r_n == pytest.approx(a, abs=1e-6)
    assert r_m == pytest.approx(6335439.327, abs=1e-3)           # a (1 - e^2)
    r_n, r_m = frames.wgs84_radii(np.pi / 2)
    assert r_n == pytest.approx(6399593.626, abs=1e-3) and r_m == pytest.approx(6399593.626, abs=1e-3)
    r_n, r_m = frames.wgs84_radii(np.radians(45.0))
    assert r_n == pytest.approx(6388838.290, abs=1e-3)
    assert r_m == pytest.approx(6367381.816, abs=1e-3)
    assert r_m == pytest.approx(a * (1 - e2) / (1 - e2 / 2) ** 1.5, rel=1e-15)
    # the same function works on CasADi symbols
    lat = ca.SX.sym("lat")
    fn = ca.Function("radii", [lat], list(frames.wgs84_radii(lat)))
    np.testing.assert_allclose([float(v) for v in fn(0.7)], frames.wgs84_radii(0.7), rtol=1e-15)


def test_latlon_ne_round_trip_and_agreement_with_pymap3d():
    pymap3d = pytest.importorskip("pymap3d")
    rng = np.random.default_rng(2)
    north, east = rng.uniform(-2000.0, 2000.0, 20), rng.uniform(-2000.0, 2000.0, 20)
    lat, lon = frames.ne_to_latlon(north, east, LAT0, LON0)
    n2, e2 = frames.latlon_to_ne(lat, lon, LAT0, LON0)
    np.testing.assert_allclose(n2, north, atol=1e-9)
    np.testing.assert_allclose(e2, east, atol=1e-9)
    n3, e3, _ = pymap3d.geodetic2ned(lat, lon, 0.0, LAT0, LON0, 0.0, deg=False)
    # tangent plane vs exact local NED: differences of second order in the distance d
    # (about d^2 tan(lat) / R, under a metre at 2 km and 63 deg North)
    gap = np.hypot(n3 - north, e3 - east)
    assert np.max(gap / np.hypot(north, east) ** 2) < 2 * np.tan(LAT0) / 6.36e6


def test_latlon_to_ne_across_the_date_line():
    n, e = frames.latlon_to_ne(0.0, np.radians(-179.99), 0.0, np.radians(179.99))
    assert n == 0.0 and e == pytest.approx(np.radians(0.02) * 6378137.0, rel=1e-12)


# -- body <-> NED -----------------------------------------------------------------------------------

def test_body_to_ned_known_values_and_round_trip():
    xd, yd, psid = frames.body_to_ned(1.0, 0.0, 0.1, np.pi / 2)           # heading east
    assert xd == pytest.approx(0.0, abs=1e-15) and yd == pytest.approx(1.0) and psid == 0.1
    xd, yd, _ = frames.body_to_ned(0.0, 1.0, 0.0, 0.0)                    # sway to starboard = east
    assert (xd, yd) == (0.0, 1.0)
    rng = np.random.default_rng(1)
    u, v, r, psi = rng.normal(size=(4, 50))
    back = frames.ned_to_body(*frames.body_to_ned(u, v, r, psi), psi)
    np.testing.assert_allclose(np.array(back), [u, v, r], atol=1e-14)
    speed, course = frames.course_speed(*frames.body_to_ned(u, v, r, psi)[:2])
    np.testing.assert_allclose(speed, np.hypot(u, v), rtol=1e-14)
    np.testing.assert_allclose(cs.wrap(course - psi), np.arctan2(v, u), atol=1e-12)   # chi = psi + beta


def test_rotation_is_symbolic_too():
    s = ca.SX.sym("s", 4)
    fn = ca.Function("rot", [s], [ca.vertcat(*frames.body_to_ned(s[0], s[1], s[2], s[3]))])
    np.testing.assert_allclose(np.array(fn([2.0, 0.5, 0.1, 0.3])).ravel(), frames.body_to_ned(2.0, 0.5, 0.1, 0.3))


# -- the kinematic models ---------------------------------------------------------------------------

def test_latlon_model_agrees_with_north_east_model_over_a_short_track():
    ne, ll = sog_cog(), sog_cog_latlon()
    U, chi, om = 5.0, np.radians(30.0), np.radians(0.3)
    x_ne = ne.states(U=U, chi=chi, omega_chi=om)
    x_ll = ll.states(lat=LAT0, lon=LON0, U=U, chi=chi, omega_chi=om)
    p = ne.params(alpha1=0.0, alpha2=0.0)          # constant speed and turn rate: a circular arc
    # the rates agree exactly at the origin of the tangent plane
    r_n, r_m = frames.wgs84_radii(LAT0)
    f_ne = np.array(ne.f(x_ne, [], p, [0, 0])).ravel()
    f_ll = np.array(ll.f(x_ll, [], p, [0, 0])).ravel()
    np.testing.assert_allclose(f_ll[:2] * [r_m, r_n * np.cos(LAT0)], f_ne[:2], rtol=1e-14)
    np.testing.assert_allclose(f_ll[2:], f_ne[2:], rtol=1e-15)

    def gap(duration):
        t = np.arange(0.0, duration + 1e-9, 1.0)
        a = cs.simulate(ne, x_ne, t, p=p, max_step=0.25)
        b = cs.simulate(ll, x_ll, t, p=p, max_step=0.25)
        n, e = frames.latlon_to_ne(b["lat"], b["lon"], LAT0, LON0)
        return np.max(np.hypot(n - a["x_n"], e - a["y_n"])), np.hypot(a["x_n"][-1], a["y_n"][-1])

    err, dist = gap(200.0)                          # about 1 km, turning by 60 deg
    print(f"lat/lon vs North-East over {dist:.0f} m: {err:.3g} m")
    assert dist > 900.0 and err < 0.2
    err2, dist2 = gap(100.0)
    # what remains is the Earth's curvature: it shrinks with the square of the distance
    assert err2 / err == pytest.approx((dist2 / dist) ** 2, rel=0.3)


def test_double_integrator_matrices():
    m = double_integrator("x", "vx", g=(1.0, 0.01))
    A, B, _, G = m.f_jac(m.states(), m.inputs(), m.params(), np.zeros(m.nw))
    np.testing.assert_array_equal(np.array(A), [[0.0, 1.0], [0.0, 0.0]])
    np.testing.assert_array_equal(np.array(G), [[1.0, 0.0], [0.0, 0.01]])
    C = np.array(m.h_jac(m.states(), m.inputs(), m.params())[0])
    np.testing.assert_array_equal(C, [[1.0, 0.0]])
    # exact discretisation: RK4 is exact for this nilpotent A
    Ad, _, _ = cs.discretize(m, 0.5).linearize(m.states(), m.inputs())
    np.testing.assert_allclose(Ad, [[1.0, 0.5], [0.0, 1.0]], rtol=1e-15)


def test_tomera_and_constant_acceleration_models():
    m = tomera_kinematic()
    assert m.state_names == ("x", "vx", "y", "vy", "psi", "r") and m.output_names == ("x", "y", "psi")
    assert list(m.angle_outputs) == [False, False, True]
    ca_model = constant_acceleration("s")
    traj = cs.simulate(ca_model, [1.0, 2.0, 0.5], np.linspace(0.0, 4.0, 9))
    np.testing.assert_allclose(traj["s"], 1.0 + 2.0 * traj.t + 0.25 * traj.t**2, rtol=1e-13)


def test_body_kinematics_draws_the_exact_circle():
    m = cs.models.get_model("body-kinematics")
    u, v, r = 4.0, 0.5, 0.02
    t = np.linspace(0.0, 300.0, 301)
    traj = cs.simulate(m, m.states(), t, {"u": u, "v": v, "r": r})
    psi = r * t
    # integral of R(psi) [u, v] with psi = r t
    x = (u * np.sin(psi) + v * (np.cos(psi) - 1.0)) / r
    y = (u * (1.0 - np.cos(psi)) + v * np.sin(psi)) / r
    np.testing.assert_allclose(traj["x"], x, atol=1e-6)
    np.testing.assert_allclose(traj["y"], y, atol=1e-6)
    np.testing.assert_allclose(traj["psi"], psi, atol=1e-12)
    assert m.output_names == ("x", "y", "psi") and list(m.angle_outputs) == [False, False, True]


def test_tangent_plane_conversions_work_on_symbols():
    s = ca.SX.sym("s", 2)
    to_ne = ca.Function("to_ne", [s], [ca.vertcat(*frames.latlon_to_ne(s[0], s[1], LAT0, LON0))])
    to_ll = ca.Function("to_ll", [s], [ca.vertcat(*frames.ne_to_latlon(s[0], s[1], LAT0, LON0))])
    lat, lon = LAT0 + 1e-4, LON0 - 2e-4
    np.testing.assert_allclose(np.array(to_ne([lat, lon])).ravel(), frames.latlon_to_ne(lat, lon, LAT0, LON0),
                               rtol=1e-14)
    np.testing.assert_allclose(np.array(to_ll([120.0, -40.0])).ravel(), frames.ne_to_latlon(120.0, -40.0, LAT0, LON0),
                               rtol=1e-15)
