"""KVLCC2 35 deg turning circle, 2000 s at dt = 0.1 s: casship vs the same MMG equations in NumPy + SciPy.

* casship: ``casship.simulate`` of :func:`casship.models.kvlcc2` (classical RK4, one step per 0.1 s
  sample, the whole record in one CasADi ``mapaccum`` fold), timed end to end including the build
  of the model and the fold.
* peer: the MMG standard-method equations (hull, propeller with the beta_P wake correction, rudder,
  rigid body at midship) written again in plain NumPy, integrated by ``scipy.integrate.solve_ivp``
  (RK45, rtol = atol = 1e-9, ``t_eval`` on the same grid); a second row uses the model's CasADi
  ``f`` as the right-hand side of ``solve_ivp``.

The rudder is at 35 deg from t = 0 and the propeller rate is the equilibrium for 7.97 m/s, so both
integrate the same smooth problem; here the adaptive solver takes long steps and interpolates onto
the output grid, while casship takes 20 000 fixed RK4 steps. A third row gives the rudder as a
signal sampled at 10 Hz and held (zero-order hold, as when an autopilot or a recorded rudder
drives the model: the 2.32 deg/s ramp to 35 deg from t = 10 s), which ``solve_ivp`` has to integrate
one interval at a time. Run ``python -m benchmarks.bench_turning [--quick]``.
"""
from __future__ import annotations

import sys

import numpy as np
from scipy.integrate import solve_ivp

import casship as cs
from benchmarks import format_table, median_time, row, solve_ivp_held
from casship.maneuvers import propeller_rate_for_speed

SPEED, RUDDER = 7.97, np.radians(35.0)


def numpy_mmg(P: dict, delta: float, n: float):
    """Right-hand side of the MMG standard method in NumPy (independent of the CasADi model code)."""
    rho, L, d = P["rho"], P["L_pp"], P["d"]
    m = rho * P["nabla"]
    q = 0.5 * rho * L**2 * d
    m_x, m_y, J_z = P["m_x_dash"] * q, P["m_y_dash"] * q, P["J_z_dash"] * q * L**2
    I_zG = m * (P["k_zz"] * L) ** 2
    x_G, D = P["x_G"], P["D_p"]
    m22, m23, m33 = m + m_y, x_G * m, I_zG + x_G**2 * m + J_z
    det = m22 * m33 - m23**2
    eta = D / P["H_R"]
    x_R, x_H = P["x_R_dash"] * L, P["x_H_dash"] * L

    def rhs(_t, s):
        u, v, r, _x, _y, psi = s
        U = np.sqrt(u * u + v * v + 1e-12)
        vp, rp = v / U, r * L / U
        XH = 0.5 * rho * L * d * U**2 * (-P["R_0_dash"] + P["X_vv_dash"] * vp**2 + P["X_vr_dash"] * vp * rp
                                          + P["X_rr_dash"] * rp**2 + P["X_vvvv_dash"] * vp**4)
        YH = 0.5 * rho * L * d * U**2 * (P["Y_v_dash"] * vp + P["Y_r_dash"] * rp + P["Y_vvv_dash"] * vp**3
                                          + P["Y_vvr_dash"] * vp**2 * rp + P["Y_vrr_dash"] * vp * rp**2
                                          + P["Y_rrr_dash"] * rp**3)
        NH = 0.5 * rho * L**2 * d * U**2 * (P["N_v_dash"] * vp + P["N_r_dash"] * rp + P["N_vvv_dash"] * vp**3
                                             + P["N_vvr_dash"] * vp**2 * rp + P["N_vrr_dash"] * vp * rp**2
                                             + P["N_rrr_dash"] * rp**3)
        beta = np.arctan2(-v, u)
        beta_P = beta - P["x_P_dash"] * rp
        C2 = P["C_2_plus"] if beta_P > 0 else P["C_2_minus"]
        wfac = (1 - P["w_P0"]) * (1 + (1 - np.exp(-P["C_1"] * abs(beta_P))) * (C2 - 1))
        uP = u * wfac
        J = uP / (n * D)
        KT = P["k_0"] + P["k_1"] * J + P["k_2"] * J * J
        XP = (1 - P["t_P"]) * rho * n * n * D**4 * KT
        uR = P["epsilon"] * uP * np.sqrt(eta * (1 + P["kappa"] * (np.sqrt(1 + 8 * KT / (np.pi * J * J)) - 1)) ** 2
                                         + 1 - eta)
        beta_R = beta - P["l_R_dash"] * rp
        gamma_R = P["gamma_R_minus"] if beta_R < 0 else P["gamma_R_plus"]
        vR = U * gamma_R * beta_R
        aR = delta - np.arctan2(vR, uR)
        FN = 0.5 * rho * P["A_R"] * (uR * uR + vR * vR) * P["f_alpha"] * np.sin(aR)
        X = XH + XP - (1 - P["t_R"]) * FN * np.sin(delta) + (m + m_y) * v * r + x_G * m * r * r
        Y = YH - (1 + P["a_H"]) * FN * np.cos(delta) - (m + m_x) * u * r
        N = NH - (x_R + P["a_H"] * x_H) * FN * np.cos(delta) - x_G * m * u * r
        cp, sp = np.cos(psi), np.sin(psi)
        return [X / (m + m_x), (m33 * Y - m23 * N) / det, (m22 * N - m23 * Y) / det,
                u * cp - v * sp, u * sp + v * cp, r]

    return rhs


def main(quick: bool = False) -> list[dict]:
    duration = 500.0 if quick else 2000.0
    t = np.arange(0.0, duration + 1e-9, 0.1)
    ship = cs.models.kvlcc2()
    n = propeller_rate_for_speed(ship, SPEED)
    x0 = ship.states(u=SPEED)
    inputs = {"delta": RUDDER, "n": n}
    p = ship.params()
    rhs = numpy_mmg(ship.param_dict(), RUDDER, n)
    u_vec, w0 = ship.inputs(delta=RUDDER, n=n), np.zeros(ship.nw)

    def casadi_rhs(_t, s):
        return np.asarray(ship.f(s, u_vec, p, w0)).ravel()

    probe = np.array([6.0, -0.8, 0.004, 10.0, -5.0, 0.7])
    gap = np.max(np.abs(np.asarray(rhs(0.0, probe)) - casadi_rhs(0.0, probe)) / (np.abs(casadi_rhs(0.0, probe)) + 1e-12))
    if gap > 1e-9:
        raise RuntimeError(f"NumPy MMG right-hand side differs from the model's f (relative {gap:.3g})")

    def run_casship():
        return cs.simulate(cs.models.kvlcc2(), x0, t, inputs)

    def run_scipy(fun):
        return lambda: solve_ivp(fun, (t[0], t[-1]), x0, method="RK45", t_eval=t, rtol=1e-9, atol=1e-9)

    traj = run_casship()
    ref = run_scipy(rhs)()
    if not ref.success:
        raise RuntimeError(f"solve_ivp failed: {ref.message}")
    err = np.abs(traj.x - ref.y.T).max(axis=0)
    check = (f"max abs diff u,v = {err[:2].max():.1e} m/s, r = {err[2]:.1e} rad/s, x,y = {err[3:5].max():.1e} m, "
             f"psi = {err[5]:.1e} rad over {t.size} samples")
    repeat = 3 if quick else 5
    t_cs = median_time(run_casship, repeat=repeat)
    t_np = median_time(run_scipy(rhs), repeat=max(1, repeat // 2))
    t_ca = median_time(run_scipy(casadi_rhs), repeat=1, warmup=0)
    name = f"KVLCC2 35 deg turning circle, {duration:g} s at dt 0.1 s"
    return [row(name, t_cs, "NumPy MMG + scipy solve_ivp RK45", t_np, check, samples=int(t.size)),
            row(name, t_cs, "CasADi f + scipy solve_ivp RK45", t_ca, check, samples=int(t.size)),
            _sampled_rudder(ship, n, t[: 2001] if quick else t, repeat)]


def _sampled_rudder(ship, n, t, repeat) -> dict:
    """Rudder sampled at 10 Hz (ramp at 2.32 deg/s to 35 deg from t = 10 s), held over each sample."""
    x0 = ship.states(u=SPEED)
    delta = np.clip(np.radians(2.32) * (t - 10.0), 0.0, RUDDER)
    P = ship.param_dict()

    def run_casship():
        return cs.simulate(cs.models.kvlcc2(), x0, t, {"delta": delta, "n": n})

    def run_scipy():
        return solve_ivp_held(lambda k: numpy_mmg(P, delta[k], n), t, x0)

    err = np.abs(run_casship().x - run_scipy()).max(axis=0)
    check = (f"max abs diff u,v = {err[:2].max():.1e} m/s, x,y = {err[3:5].max():.1e} m, psi = {err[5]:.1e} rad "
             f"over {t.size} samples")
    t_cs = median_time(run_casship, repeat=repeat)
    t_sp = median_time(run_scipy, repeat=1, warmup=0)
    name = f"KVLCC2 turning circle, {t[-1]:g} s, rudder sampled at 10 Hz (ZOH)"
    return row(name, t_cs, "NumPy MMG + scipy solve_ivp RK45 per interval", t_sp, check, samples=int(t.size))


if __name__ == "__main__":
    print(format_table(main(quick="--quick" in sys.argv)))
