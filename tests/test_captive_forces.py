"""The rig force of a model at a prescribed motion, PMM motions and the harmonic projection."""
from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from casship.builder import ModelBuilder
from casship.errors import InputError
from casship.identify.captive_forces import CaptivePredictor, captive_forces, harmonics, pmm_motion
from casship.io.captive import HARMONICS
from casship.models import kvlcc2_l7
from casship.models.mmg import declare_ship_states, mmg_force_parts, rigid_body_3dof

from captive_records import design

LIN = {"Yv": -900.0, "Yr": 300.0, "Nv": -400.0, "Nr": -2500.0, "m": 1200.0, "m_x": 60.0, "m_y": 900.0,
       "I_zG": 4000.0, "J_z": 700.0, "x_G": 0.0, "rho": 1000.0, "L_pp": 5.0}


def linear_ship():
    """A linear 3-DOF ship: Y = Yv v + Yr r, N = Nv v + Nr r, with the MMG rigid body at midship."""
    b = ModelBuilder("linear-ship")
    states = declare_ship_states(b)
    u, v, r = states[:3]
    b.input("delta")
    b.input("n")
    P = {k: b.param(k, val) for k, val in LIN.items()}
    force = (0 * u, P["Yv"] * v + P["Yr"] * r, P["Nv"] * v + P["Nr"] * r)
    rigid_body_3dof(b, force, m=P["m"], m_x=P["m_x"], m_y=P["m_y"], I_zG=P["I_zG"], J_z=P["J_z"], x_G=P["x_G"],
                    states=states)
    return b.build()


def test_harmonics_of_a_trigonometric_polynomial_are_exact():
    th = 2 * np.pi * np.arange(64) / 64
    f = 0.3 + 1.5 * np.sin(th) - 0.7 * np.cos(th) + 0.2 * np.sin(2 * th) + 0.1 * np.cos(3 * th) + 5 * np.cos(9 * th)
    np.testing.assert_allclose(harmonics(f), [0.3, 1.5, -0.7, 0.2, 0.0, 0.0, 0.1], atol=1e-13)
    with pytest.raises(InputError, match="cannot resolve"):
        harmonics(f[:6])


def test_pure_sway_of_a_linear_model_gives_the_analytic_components():
    """Sway y = y_max sin(wt): Y on the rig = Yv v - (m + m_y) vdot, so in1 = (m + m_y) y_max w^2,
    out1 = Yv y_max w; N = Nv v - x_G m vdot; the other harmonics vanish."""
    ship = linear_ship()
    U, L, w, vdot_amp = 1.2, LIN["L_pp"], 2 * np.pi * 0.05, -0.15
    p = ship.params(x_G=0.4)
    F = captive_forces(ship)
    mo = pmm_motion("pure_sway", U, omega=w, vdot_amp=vdot_amp, L=L)
    y_max = -vdot_amp * U**2 / (w**2 * L)
    X = np.array([ship.states(u=a, v=b, r=c) for a, b, c in zip(mo["u"], mo["v"], mo["r"])]).T
    A = np.vstack([mo["du"], mo["dv"], mo["dr"]])
    out = np.asarray(F.map(X.shape[1])(X, A, np.zeros((2, X.shape[1])), np.tile(p[:, None], X.shape[1])))
    hY, hN = harmonics(out[1]), harmonics(out[2])
    m = LIN["m"]
    expect_Y = [0, (m + LIN["m_y"]) * y_max * w**2, LIN["Yv"] * y_max * w, 0, 0, 0, 0]
    expect_N = [0, 0.4 * m * y_max * w**2, LIN["Nv"] * y_max * w, 0, 0, 0, 0]
    scale = np.max(np.abs(expect_Y))
    np.testing.assert_allclose(hY, expect_Y, rtol=1e-12, atol=1e-12 * scale)
    np.testing.assert_allclose(hN, expect_N, rtol=1e-12, atol=1e-12 * scale)


def test_pure_yaw_moment_of_a_linear_model_is_analytic_and_non_dimensional():
    """psi = psi_max sin(wt), no sway: N = Nr r - (I_zG + J_z) rdot (x_G = 0), i.e.
    in1' = (I_zG + J_z) psi_max w^2 / (0.5 rho U^2 L^3), out1' = Nr psi_max w / (0.5 rho U^2 L^3)."""
    ship = linear_ship()
    tests = design(U=1.2, L=LIN["L_pp"])
    pr = CaptivePredictor(ship, tests, ("N",), HARMONICS, dynamic_kinds=("pure_yaw",), static_kinds=())
    y = pr.predict(ship.params())
    dy = tests.dynamic
    q = 0.5 * LIN["rho"] * 1.2**2 * LIN["L_pp"] ** 3
    for o, val in zip(pr.observations, y):
        i = o.index
        w = -dy.rdot_amp[i] * 1.2 / (dy.r_amp[i] * LIN["L_pp"])
        psi_max = dy.r_amp[i] * 1.2 / (w * LIN["L_pp"])
        expect = {"in1": (LIN["I_zG"] + LIN["J_z"]) * psi_max * w**2 / q, "out1": LIN["Nr"] * psi_max * w / q}
        assert val == pytest.approx(expect.get(o.component, 0.0), rel=1e-12, abs=1e-12 * abs(expect["out1"]))


def test_static_rig_force_equals_the_mmg_force():
    """Without rotation or acceleration the rig holds the model's hydrodynamic force exactly."""
    ship = kvlcc2_l7(asymmetry=True, smooth=True)
    F = captive_forces(ship, ("X", "Y", "N", "RY", "T"))
    p = ship.params(delta_0=0.02)
    u, v, delta, n = 1.1, -0.3, 0.2, 10.0
    got = np.asarray(F(ship.states(u=u, v=v), [0, 0, 0], ship.inputs(delta=delta, n=n), p)).ravel()
    P = dict(zip(ship.param_names, p))
    from casship.models.mmg import SMOOTH_WIDTH
    parts = mmg_force_parts(P, u, v, 0.0, delta, n, SMOOTH_WIDTH)
    np.testing.assert_allclose(got, [float(parts[k]) for k in ("X", "Y", "N", "RY", "T")], rtol=1e-12)


def test_prediction_jacobian_matches_central_differences():
    ship = kvlcc2_l7(asymmetry=True, smooth=True)
    tests = design()
    pr = CaptivePredictor(ship, tests, ("X", "Y", "N", "RY"), dynamic_kinds=("yaw_drift",))
    p = ship.params()
    y, J = pr.jacobian(p)
    for name in ("N_vvr_dash", "Y_vrr_dash", "a_H", "x_H_dash", "m_y_dash", "w_P0", "gamma_R_plus"):
        i = ship.index(name, "param")
        h = 1e-6 * max(1.0, abs(p[i]))
        dp = np.zeros_like(p)
        dp[i] = h
        fd = (pr.predict(p + dp) - pr.predict(p - dp)) / (2 * h)
        np.testing.assert_allclose(J[:, i], fd, rtol=1e-5, atol=1e-6 * np.max(np.abs(fd)) + 1e-11)


def test_model_without_the_force_port_is_refused():
    b = ModelBuilder("no-port")
    for s in ("u", "v", "r"):
        b.state(s)
    b.ode(u=0 * b.sym("u"), v=0 * b.sym("v"), r=0 * b.sym("r"))
    with pytest.raises(InputError, match="port 'tau'"):
        captive_forces(b.build())
    with pytest.raises(InputError, match="unknown channel"):
        captive_forces(linear_ship(), ("Z",))
    with pytest.raises(InputError, match="need an MMG"):
        captive_forces(linear_ship(), ("RY",))


def test_yaw_motion_kinematics():
    """Yaw with drift: speed U / cos(phi) along the path, v/u = -tan(beta), r and rdot consistent."""
    mo = pmm_motion("yaw_drift", 1.0, beta=0.2, omega=0.5, r_amp=0.3, L=4.0, n=32)
    np.testing.assert_allclose(mo["v"] / mo["u"], -np.tan(0.2) * np.ones(32), rtol=1e-14)
    psi_max = 0.3 * 1.0 / (0.5 * 4.0)
    np.testing.assert_allclose(harmonics(mo["r"], 1), [0, 0, psi_max * 0.5], atol=1e-14)
    np.testing.assert_allclose(harmonics(mo["dr"], 1), [0, -psi_max * 0.25, 0], atol=1e-14)
    th = mo["theta"]
    np.testing.assert_allclose(np.hypot(mo["u"], mo["v"]), 1.0 / np.cos(psi_max * np.sin(th)), rtol=1e-14)


def test_prediction_jacobian_in_the_scale_parameters_and_over_every_test_kind():
    """The non-dimensionalisation depends on L_pp and rho: their columns carry the scale's derivative;
    static and dynamic tests together, every channel."""
    ship = kvlcc2_l7(asymmetry=True, smooth=True)
    pr = CaptivePredictor(ship, design(), ("X", "Y", "N", "RY"))
    assert {o.test for o in pr.observations} == {"static", "dynamic"}
    p = ship.params()
    y, J = pr.jacobian(p)
    np.testing.assert_allclose(y, pr.predict(p), rtol=1e-13, atol=1e-15)
    for name in ("L_pp", "rho", "N_r_dash", "f_alpha", "t_P"):
        i = ship.index(name, "param")
        h = 1e-6 * max(1.0, abs(p[i]))
        dp = np.zeros_like(p)
        dp[i] = h
        fd = (pr.predict(p + dp) - pr.predict(p - dp)) / (2 * h)
        assert np.max(np.abs(fd)) > 0, name
        np.testing.assert_allclose(J[:, i], fd, rtol=1e-5, atol=1e-6 * np.max(np.abs(fd)) + 1e-11)
