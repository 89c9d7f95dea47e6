"""Otter USV (Maritime Robotics), horizontal-plane dynamics after Fossen's MSS ``otter.m`` / PVS ``otter.py``.

Source: Fossen, *Handbook of Marine Craft Hydrodynamics and Motion Control* (2nd ed., 2021), and
the Otter models of the MSS toolbox (``VESSELS/models/otter.m``, revision 2024-06-05) and of the
Python Vehicle Simulator (``vehicles/otter.py``), which both keep the Munk moment of the added-mass
Coriolis matrix (they only suggest cancelling it "if stability problems" arise).

Surge, sway and yaw of the 6-DOF model, with the constants of the project reference table (2.2):
L = 2.0 m, B = 1.08 m, hull mass 55 kg plus a payload (25 kg at ``r_p = [0.05, 0, -0.35]`` m), hull
CG ``r_g = [0.2, 0, -0.2]`` m, radii of gyration R66 = 0.25 L, pontoons (B_pont 0.25 m, y_pont
0.395 m, C_b 0.4), two propellers with thrust ``k n|n|`` (``k_pos = 0.02216/2`` forward,
``k_neg = 0.01289/2`` astern, ``n`` in rad/s) on lever arms ``-+y_pont``.

Equations (body origin CO at mid-length, ``nu = [u, v, r]``)::

    M nu' + C_RB(nu) nu + C_A(nu) nu + D nu = tau_prop + tau_crossflow + tau_nonlinear + tau(port)

* ``M = M_RB + M_A`` with ``M_RB = [[m, 0, 0], [0, m, m x_g], [0, m x_g, I_z]]`` (m = hull + payload,
  ``x_g`` the combined CG, ``I_z = I_g + m x_g^2`` with ``I_g = m_hull R66^2 + m_hull x_g^2 + m_p x_p^2``,
  as in MSS/PVS) and ``M_A = diag(-X_u', -Y_v', -N_r')``: ``X_u' = -2.7 rho nabla^(5/3)/L^2`` with
  ``nabla`` of the hull mass alone (MSS ``addedMassSurge(m, L, rho)`` with ``m`` = 55 kg),
  ``Y_v' = -1.5 m_hull``, ``N_r' = -1.7 I_g``;
* ``C_RB``: 3-DOF rigid-body Coriolis at CO with the CG offset; ``C_A``: the added-mass Coriolis
  matrix of ``M_A`` (Fossen 2021, Sec. 6.4, MSS ``m2c``), whose yaw row is the Munk moment
  ``(Y_v' - X_u') u v`` (destabilising: it turns the bow away from the flow). ``munk_moment=False``
  drops that yaw row as earlier MSS (2021-06-21) and PVS revisions did;
* ``D = diag(-X_u, -Y_v, -N_r)``, ``X_u = -24.4 g / U_max``, ``Y_v = -M22 / T_sway``,
  ``N_r = -M66 / T_yaw``, plus the nonlinear yaw damping ``10 N_r |r| r``;
* cross-flow drag ``Y = -rho/2 T C_D int |v + x r|(v + x r) dx``, ``N`` likewise with ``x``, evaluated in
  closed form (:func:`casship.models.lowspeed.crossflow_integrals`; MSS sums 21 strips), with ``C_D``
  from Hoerner's curve at ``B_pont / (2 T)`` (MSS ``Hoerner.m``, linear interpolation).

Inputs ``n1`` (port) and ``n2`` (starboard) propeller speeds [rad/s]; with ``propeller_dynamics=True``
the speeds are states driven by ``n1_cmd, n2_cmd`` through first-order lags (``T_n`` = 0.1 s, MSS).
Saturation of the speeds (``meta["n_max"]``, ``meta["n_min"]``) is left to the caller.
"""
from __future__ import annotations

from typing import Mapping

import casadi as ca
import numpy as np

from ..frames import body_to_ned
from ..builder import ModelBuilder
from ..model import Model
from ..vessel import Vessel
from .lowspeed import crossflow_integrals
from .mmg import declare_ship_states
from ..errors import InputError

__all__ = ["otter", "OTTER", "hoerner_cd"]

#: Constants of the Otter USV (MSS otter.m; PVS otter.py).
OTTER: dict[str, float] = {
    "L": 2.0, "B": 1.08, "m_hull": 55.0, "m_p": 25.0, "x_p": 0.05, "x_g_hull": 0.2, "R66": 0.25 * 2.0,
    "T_sway": 1.0, "T_yaw": 1.0, "U_max": 6 * 0.5144, "B_pont": 0.25, "y_pont": 0.395, "Cb_pont": 0.4,
    "k_pos": 0.02216 / 2, "k_neg": 0.01289 / 2, "rho": 1025.0, "g": 9.81,
    "Yvdot_over_m": -1.5, "Nrdot_over_Iz": -1.7, "Xudot_factor": -2.7, "N_r_nonlinear": 10.0,
}
_SRC = "MSS otter.m / PVS otter.py (reference table 2.2)"

# Hoerner's 2-D cross-flow drag curve, B/2T -> C_D (MSS Hoerner.m, digitised from Leite et al. 1998).
_HOERNER = np.array([
    [0.0109, 1.9661], [0.1766, 1.9657], [0.3530, 1.8976], [0.4519, 1.7872], [0.4728, 1.5837], [0.4929, 1.2786],
    [0.4933, 1.2108], [0.5585, 1.0836], [0.6464, 0.9986], [0.8336, 0.8796], [0.9880, 0.8284], [1.3081, 0.7599],
    [1.6392, 0.6914], [1.8600, 0.6571], [2.3129, 0.6307], [2.6000, 0.5962], [3.0088, 0.5868], [3.4508, 0.5859],
    [3.7379, 0.5599], [4.0031, 0.5593]])


def hoerner_cd(B: float, T: float) -> float:
    """2-D cross-flow drag coefficient from Hoerner's curve at ``B / (2 T)`` (constant beyond the table).

    Linear interpolation in the tabulated curve (as MSS ``Hoerner.m``); below the first and above the
    last tabulated ratio the end values are used.

    Parameters
    ----------
    B : float
        Breadth of the section (for the Otter: one pontoon) [m].
    T : float
        Draught of the section [m].

    Returns
    -------
    float
        The drag coefficient ``C_D`` (dimensionless).

    Examples
    --------
    >>> round(hoerner_cd(0.3, 0.2), 4)   # B / (2 T) = 0.75
    0.9327
    """
    return float(np.interp(B / (2 * T), _HOERNER[:, 0], _HOERNER[:, 1]))


def otter(params: Mapping[str, float] | None = None, *, propeller_dynamics: bool = False,
          T_n: float = 0.1, munk_moment: bool = True) -> Model:
    """Otter USV, surge-sway-yaw (MSS ``otter.m``), two propeller speed inputs.

    Parameters
    ----------
    params : mapping, optional
        Overrides of :data:`OTTER` (e.g. ``{"m_p": 0.0}`` without payload).
    propeller_dynamics : bool
        Propeller speeds as states ``n1, n2`` with inputs ``n1_cmd, n2_cmd`` (lag ``T_n``).
    T_n : float
        Propeller time constant [s] (MSS: 0.1 s).
    munk_moment : bool
        Keep the Munk yaw moment of the added-mass Coriolis matrix (default, as current MSS and
        PVS; without it the craft turns about a third slower at the same propeller commands).

    Returns
    -------
    Model
        States ``u, v, r, x, y, psi`` (+ ``n1, n2``), inputs ``n1, n2`` [rad/s] (or ``*_cmd``);
        ``vessel``: ``L_pp``, ``B``, ``draught``, ``mass``, ``U0`` (2 m/s) and the propeller range
        ``(n_min, n_max)`` [rad/s] (the MSS saturation; ``vessel.propeller_range``); the propeller
        inputs get it as their validity limit. ``meta["C_D"]``: the cross-flow drag coefficient.
    """
    values = dict(OTTER)
    for key, val in (params or {}).items():
        if key not in values:
            raise InputError(f"unknown Otter parameter {key!r}; known: {sorted(values)}")
        values[key] = float(val)
    m_tot = values["m_hull"] + values["m_p"]
    nabla = m_tot / values["rho"]
    draft = nabla / (2 * values["Cb_pont"] * values["B_pont"] * values["L"])
    b = ModelBuilder("otter", "Otter USV surge-sway-yaw dynamics (Fossen, MSS otter.m)")
    P = {k: b.param(k, v, source=_SRC) for k, v in values.items()}
    C_D = b.param("C_D", hoerner_cd(values["B_pont"], draft), bounds=(0.0, np.inf),
                  doc="2-D cross-flow drag coefficient (Hoerner at B_pont/2T)", source="MSS Hoerner.m")
    states = declare_ship_states(b)
    u, v, r, _x, _y, psi = states
    if propeller_dynamics:
        Tn = b.param("T_n", T_n, bounds=(1e-6, np.inf), unit="s", doc="propeller time constant")
        n1, n2 = b.state("n1", unit="rad/s"), b.state("n2", unit="rad/s")
        c1, c2 = b.input("n1_cmd", unit="rad/s"), b.input("n2_cmd", unit="rad/s")
        b.ode(n1=(c1 - n1) / Tn, n2=(c2 - n2) / Tn)
    else:
        n1 = b.input("n1", unit="rad/s", doc="port propeller speed")
        n2 = b.input("n2", unit="rad/s", doc="starboard propeller speed")
    rho, L = P["rho"], P["L"]
    m_h, m_p = P["m_hull"], P["m_p"]
    m = m_h + m_p
    x_g = (m_h * P["x_g_hull"] + m_p * P["x_p"]) / m
    # yaw inertia as in MSS/PVS: hull radius of gyration plus the parallel-axis terms of the hull
    # (at the combined CG) and of the payload; M_RB then adds m x_g^2 when moved to CO
    Ig = m_h * P["R66"] ** 2 + m_h * x_g**2 + m_p * P["x_p"] ** 2
    nab = m / rho
    T = nab / (2 * P["Cb_pont"] * P["B_pont"] * L)
    a11 = -P["Xudot_factor"] * rho * (m_h / rho) ** (5.0 / 3.0) / L**2     # MSS: hull mass only
    a22 = -P["Yvdot_over_m"] * m_h
    a66 = -P["Nrdot_over_Iz"] * Ig
    M11, M22, M23, M33 = m + a11, m + a22, m * x_g, Ig + m * x_g**2 + a66
    X_u = -24.4 * P["g"] / P["U_max"]
    Y_v = -M22 / P["T_sway"]
    N_r = -M33 / P["T_yaw"]
    # propellers
    def thrust(n):
        return ca.if_else(n > 0, P["k_pos"], P["k_neg"]) * n * ca.fabs(n)
    T1, T2 = thrust(n1), thrust(n2)
    tau_X = T1 + T2
    tau_N = P["y_pont"] * (T1 - T2)
    # cross-flow drag (closed form of MSS crossFlowDrag)
    I0, I1 = crossflow_integrals(v, r * L)
    Y_cf = -0.5 * rho * T * C_D * L * I0
    N_cf = -0.5 * rho * T * C_D * L**2 * I1
    # Coriolis: rigid body at CO (CG offset x_g) and added mass, whose yaw row is the Munk moment
    C_rb = ca.vertcat(-m * (v + x_g * r) * r, m * u * r, m * x_g * u * r)
    C_a = ca.vertcat(-a22 * v * r, a11 * u * r, (a22 - a11) * u * v if munk_moment else 0)
    port = b.port("tau", 3)
    rhs = ca.vertcat(tau_X + X_u * u, Y_v * v + Y_cf, tau_N + N_r * r + P["N_r_nonlinear"] * N_r * ca.fabs(r) * r
                     + N_cf) - C_rb - C_a + port
    du = rhs[0] / M11
    det = M22 * M33 - M23**2
    dv = (M33 * rhs[1] - M23 * rhs[2]) / det
    dr = (M22 * rhs[2] - M23 * rhs[1]) / det
    xd, yd, psid = body_to_ned(u, v, r, psi)
    b.ode(u=du + b.noise("w_u", unit="m/s^2"), v=dv + b.noise("w_v", unit="m/s^2"),
          r=dr + b.noise("w_r", unit="rad/s^2"), x=xd, y=yd, psi=psid)
    for name in ("u", "v", "r", "x", "y", "psi"):
        b.output(name, b.sym(name))
    g = values["g"]
    n_range = (float(-np.sqrt(0.5 * 13.6 * g / values["k_neg"])), float(np.sqrt(0.5 * 24.4 * g / values["k_pos"])))
    b.vessel = Vessel("Otter USV", L_pp=values["L"], B=values["B"], draught=float(draft), mass=float(m_tot), U0=2.0,
                      propellers=("n1_cmd", "n2_cmd") if propeller_dynamics else ("n1", "n2"),
                      propeller_range=n_range, param_set="otter/MSS", source=_SRC)
    b.meta["C_D"] = hoerner_cd(values["B_pont"], draft)
    for name in b.vessel.propellers:
        b.limit(name, *n_range, why="propeller saturation (MSS otter.m)")
    return b.build()
