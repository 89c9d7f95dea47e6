"""The KVLCC2 MMG preset against the published MMG standard method (Yasukawa & Yoshimura 2015),
written out below in plain NumPy from the paper's equations (not from casship's code) with the
published KVLCC2 values, term by term: each hull derivative alone, the propeller thrust, the rudder
forces, the asymmetry terms and the whole model, compared through the model's accelerations."""
import numpy as np
import pytest

import casship as cs

# Yasukawa & Yoshimura (2015), KVLCC2 at full scale (the values the preset must carry)
SHIP = dict(rho=1025.0, L_pp=320.0, B=58.0, d=20.8, nabla=312600.0, x_G=11.2, k_zz=0.25, D_p=9.86, H_R=15.80,
            A_R=112.5, w_P0=0.35)
HULL = dict(R_0_dash=0.022, X_vv_dash=-0.040, X_vr_dash=0.002, X_rr_dash=0.011, X_vvvv_dash=0.771,
            Y_v_dash=-0.315, Y_r_dash=0.083, Y_vvv_dash=-1.607, Y_vvr_dash=0.379, Y_vrr_dash=-0.391,
            Y_rrr_dash=0.008, N_v_dash=-0.137, N_r_dash=-0.049, N_vvv_dash=-0.030, N_vvr_dash=-0.294,
            N_vrr_dash=0.055, N_rrr_dash=-0.013)
OTHER = dict(m_x_dash=0.022, m_y_dash=0.223, J_z_dash=0.011, t_P=0.220, x_P_dash=-0.48, k_0=0.2931, k_1=-0.2753,
             k_2=-0.1385, C_1=2.0, C_2_plus=1.6, C_2_minus=1.1, t_R=0.387, a_H=0.312, x_H_dash=-0.464,
             x_R_dash=-0.5, gamma_R_minus=0.395, gamma_R_plus=0.640, l_R_dash=-0.710, epsilon=1.09, kappa=0.50,
             f_alpha=2.747)
PUBLISHED = {**SHIP, **HULL, **OTHER}

# (u [m/s], v [m/s], r [rad/s], delta [rad], n [1/s]): drift and yaw of both signs, rudder both ways
STATES = [(7.0, 0.30, 0.004, 0.20, 1.50), (6.0, -0.50, -0.003, -0.30, 1.40), (5.0, 0.80, -0.006, 0.61, 1.00),
          (7.9, -0.10, 0.0015, -0.05, 1.53)]


def reference_forces(c, u, v, r, delta, n):
    """Hull, propeller and rudder forces ``(X, Y, N)`` at midship, MMG standard method (Eqs. 7-27)."""
    rho, L, d = c["rho"], c["L_pp"], c["d"]
    U = np.hypot(u, v)
    vp, rp = v / U, r * L / U                                   # v' = v_m / U, r' = r L / U
    beta = np.arctan(-v / u)
    X_H = 0.5 * rho * L * d * U**2 * (-c["R_0_dash"] + c["X_vv_dash"] * vp**2 + c["X_vr_dash"] * vp * rp
                                      + c["X_rr_dash"] * rp**2 + c["X_vvvv_dash"] * vp**4)
    Y_H = 0.5 * rho * L * d * U**2 * (c["Y_v_dash"] * vp + c["Y_r_dash"] * rp + c["Y_vvv_dash"] * vp**3
                                      + c["Y_vvr_dash"] * vp**2 * rp + c["Y_vrr_dash"] * vp * rp**2
                                      + c["Y_rrr_dash"] * rp**3)
    N_H = 0.5 * rho * L**2 * d * U**2 * (c["N_v_dash"] * vp + c["N_r_dash"] * rp + c["N_vvv_dash"] * vp**3
                                         + c["N_vvr_dash"] * vp**2 * rp + c["N_vrr_dash"] * vp * rp**2
                                         + c["N_rrr_dash"] * rp**3)
    # propeller: wake with the drift at the propeller, thrust from the open-water polynomial
    beta_P = beta - c["x_P_dash"] * rp
    C_2 = c["C_2_plus"] if beta_P > 0 else c["C_2_minus"]
    wake = 1 - (1 - c["w_P0"]) * (1 + (1 - np.exp(-c["C_1"] * abs(beta_P))) * (C_2 - 1))     # w_P
    D = c["D_p"]
    J_P = u * (1 - wake) / (n * D)
    K_T = c["k_0"] + c["k_1"] * J_P + c["k_2"] * J_P**2
    thrust = rho * n**2 * D**4 * K_T
    X_P = (1 - c["t_P"]) * thrust
    # rudder: inflow from the propeller race, flow straightening of the drift at the rudder
    eta = D / c["H_R"]
    u_P = u * (1 - wake)
    u_R = c["epsilon"] * u_P * np.sqrt(eta * (1 + c["kappa"] * (np.sqrt(1 + 8 * K_T / (np.pi * J_P**2)) - 1)) ** 2
                                       + (1 - eta))
    beta_R = beta - c["l_R_dash"] * rp
    gamma_R = c["gamma_R_minus"] if beta_R < 0 else c["gamma_R_plus"]
    v_R = U * gamma_R * beta_R
    alpha_R = delta - c.get("delta_0", 0.0) - np.arctan(v_R / u_R)
    F_N = 0.5 * rho * c["A_R"] * (u_R**2 + v_R**2) * c["f_alpha"] * np.sin(alpha_R)
    X_R = -(1 - c["t_R"]) * F_N * np.sin(delta)
    Y_R = -(1 + c["a_H"]) * F_N * np.cos(delta)
    N_R = -(c["x_R_dash"] * L + c["a_H"] * c["x_H_dash"] * L) * F_N * np.cos(delta)
    # propeller-induced side force and moment of the asymmetric extension (zero in the published model)
    Y_P, N_P = c.get("Y_0_dash", 0.0) * thrust, c.get("N_0_dash", 0.0) * L * thrust
    return np.array([X_H + X_P + X_R, Y_H + Y_P + Y_R, N_H + N_P + N_R])


def reference_accelerations(c, u, v, r, delta, n):
    """``du, dv, dr`` from the equations of motion at midship (Eq. 4) with the forces above."""
    rho, L, d = c["rho"], c["L_pp"], c["d"]
    m = rho * c["nabla"]
    m_x, m_y = c["m_x_dash"] * 0.5 * rho * L**2 * d, c["m_y_dash"] * 0.5 * rho * L**2 * d
    J_z, I_zG, x_G = c["J_z_dash"] * 0.5 * rho * L**4 * d, m * (c["k_zz"] * L) ** 2, c["x_G"]
    X, Y, N = reference_forces(c, u, v, r, delta, n)
    M = np.array([[m + m_x, 0, 0], [0, m + m_y, x_G * m], [0, x_G * m, I_zG + x_G**2 * m + J_z]])
    rhs = np.array([X + (m + m_y) * v * r + x_G * m * r**2, Y - (m + m_x) * u * r, N - x_G * m * u * r])
    return np.linalg.solve(M, rhs)


def model_accelerations(model, values, u, v, r, delta, n, psi=0.4):
    xdot = np.asarray(model.f([u, v, r, 0.0, 0.0, psi], [delta, n], model.params(**values), np.zeros(3))).ravel()
    np.testing.assert_allclose(xdot[3:], [u * np.cos(psi) - v * np.sin(psi), u * np.sin(psi) + v * np.cos(psi), r],
                               rtol=1e-12)
    return xdot[:3]


def check(model, values, rtol=1e-9):
    for state in STATES:
        expected = reference_accelerations(values, *state)
        got = model_accelerations(model, values, *state)
        scale = np.abs(expected).max()
        np.testing.assert_allclose(got, expected, rtol=rtol, atol=1e-12 * scale, err_msg=str(state))


def test_the_preset_carries_the_published_values():
    model = cs.models.kvlcc2()
    values = model.param_dict()
    assert {k: values[k] for k in PUBLISHED} == pytest.approx(PUBLISHED, rel=1e-12)


def test_whole_model_equals_the_published_method():
    check(cs.models.kvlcc2(), PUBLISHED)


@pytest.mark.parametrize("term", list(HULL))
def test_each_hull_derivative_alone(term):
    """Only ``term`` is nonzero among the hull derivatives; no rudder (A_R = 0) and no thrust (K_T = 0):
    the accelerations come from that one term and the rigid body."""
    values = {**PUBLISHED, **{k: 0.0 for k in HULL}, term: PUBLISHED[term], "A_R": 0.0, "k_0": 0.0, "k_1": 0.0,
              "k_2": 0.0}
    check(cs.models.kvlcc2(), values)


def test_propeller_thrust_alone():
    """No hull forces and no rudder: the surge acceleration is the thrust with the drift-dependent wake."""
    values = {**PUBLISHED, **{k: 0.0 for k in HULL}, "A_R": 0.0}
    check(cs.models.kvlcc2(), values)
    model = cs.models.kvlcc2()
    for state in STATES:                   # the wake really changes with the drift at the propeller (C_1, C_2)
        assert model_accelerations(model, values, *state)[0] != pytest.approx(
            model_accelerations(model, {**values, "C_1": 0.0}, *state)[0], rel=1e-6)


def test_rudder_forces_alone():
    """No hull forces and no propeller surge force (``t_P = 1`` removes ``X_P`` but keeps the
    propeller race at the rudder): the forces are the rudder's."""
    check(cs.models.kvlcc2(), {**PUBLISHED, **{k: 0.0 for k in HULL}, "t_P": 1.0})


def test_asymmetry_terms():
    values = {**PUBLISHED, "delta_0": np.radians(1.5), "Y_0_dash": 0.02, "N_0_dash": -0.01}
    check(cs.models.kvlcc2(asymmetry=True), values)
    check(cs.models.kvlcc2(asymmetry=True), {**values, **{k: 0.0 for k in HULL}, "t_P": 1.0})
