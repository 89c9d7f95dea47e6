"""Yoshimura's low-speed hull model for a single-propeller, twin-rudder ship (Koike et al. 2023, Eq. 20-22).

States ``u, v, r, x, y, psi`` (``v`` = ``v_m`` at midship), inputs ``n`` [1/s], ``delta_s`` and
``delta_p`` [rad] (starboard and port rudder; positive turns the ship to starboard), port ``tau``
and noise ``w_u, w_v, w_r`` as for every casship ship (rigid body: :func:`casship.models.mmg.rigid_body_3dof`).

Hull (Yoshimura; Koike et al. 2023, Eq. 22, with the added-mass terms on the left-hand side)::

    X_H = rho/2 L d [ {X'_0F + (X'_0A - X'_0F) |beta|/pi} u U + X'_vr L v r ]
    Y_H = rho/2 L d [ Y'_v v |u| + Y'_r L r u - C_D I0(v, C_rY r L) ]
    N_H = rho/2 L^2 d [ N'_v v u + N'_r L r |u| - C_D I1(v, C_rN r L) ]

with the cross-flow integrals over the hull, ``xi = x/L``,
``I0(a, b) = int_{-1/2}^{1/2} |a + b xi| (a + b xi) dxi`` and ``I1(a, b) = int |a + b xi| (a + b xi) xi dxi``,
evaluated **in closed form** (:func:`crossflow_integrals`; exact, continuously differentiable,
tested against a fine quadrature) and ``C_D = -0.0591 L/d + 1.848``, ``C_rY = 0.52 L/B - 1.062``,
``C_rN = 0.0742 L/d - 0.297`` (the regressions of the reference table, section 5; Koike et al. 2023 write
``C_rY`` in the yaw integral, which we read as a misprint for ``C_rN``). To keep the model smooth at
rest (berthing), ``U = sqrt(u^2 + v^2 + e^2)``, ``|u| = sqrt(u^2 + e^2)`` and
``|beta| = atan2(sqrt(v^2 + e^2), u)`` with ``e = smooth_speed`` (1e-4 m/s by default).

Propeller and rudders (MMG-type, simplified for low speed — Koike et al. 2023 do not give them):
``T = rho D^2 (k0 n|n| D^2 + k1 |n| D u_P + k2 u_P^2)``, ``u_P = (1 - w_P0) u`` (constant wake),
``X_P = (1 - t_P) T``; for each rudder ``i`` at ``(x_R, y_i)``, ``y_s = +y_R``, ``y_p = -y_R``:
``u_R = eps sqrt(eta (u_P + kappa (sqrt(u_P^2 + 8 n|n| D^2 K_T/pi) - u_P))^2 + (1 - eta) u_P^2)``,
``v_R = -gamma_R (v + l_R r)`` (the small-drift form of ``U gamma_R beta_R``, finite at rest),
``alpha_i = delta_i - atan2(v_R, u_R)``, ``F_i = rho/2 A_R (u_R^2 + v_R^2) f_alpha sin(alpha_i)``;
``X_R = -(1 - t_R) sum F_i sin delta_i``, ``Y_R = -(1 + a_H) sum F_i cos delta_i``,
``N_R = -(x_R + a_H x_H) sum F_i cos delta_i + sum y_i (1 - t_R) F_i sin delta_i``.
The normal-force model has no stall: at the large angles of a VecTwin-type rudder (Koike et al. 2023 use
``delta_s`` in [-35, 105] deg) it is a crude approximation (at 105/-105 deg the rudders brake the ship).
"""
from __future__ import annotations

from typing import Mapping

import casadi as ca
import numpy as np

from ..builder import ModelBuilder
from ..model import Model
from ..vessel import Vessel
from .mmg import _param, declare_ship_limits, declare_ship_states, rigid_body_3dof
from ..errors import InputError

__all__ = ["yoshimura_twin_rudder", "esso_osaka_twin", "crossflow_integrals", "LOWSPEED_PARAMS",
           "ESSO_OSAKA_TWIN", "ESSO_OSAKA_SOURCES"]

LOWSPEED_PARAMS: dict[str, tuple[str, str]] = {
    "rho": ("kg/m^3", "water density"),
    "L_pp": ("m", "length between perpendiculars"), "B": ("m", "breadth"), "d": ("m", "draught"),
    "m_dash": ("-", "mass / (0.5 rho L^2 d)"), "x_G_dash": ("-", "centre of gravity / L (forward +)"),
    "k_zz": ("-", "yaw radius of gyration / L"),
    "m_x_dash": ("-", "surge added mass / (0.5 rho L^2 d)"), "m_y_dash": ("-", "sway added mass / (0.5 rho L^2 d)"),
    "J_z_dash": ("-", "added yaw inertia / (0.5 rho L^4 d)"),
    "X_0F_dash": ("-", "ahead resistance coefficient"), "X_0A_dash": ("-", "astern resistance coefficient"),
    "X_vr_dash": ("-", "hull surge derivative"), "Y_v_dash": ("-", "hull sway derivative"),
    "Y_r_dash": ("-", "hull sway derivative"), "N_v_dash": ("-", "hull yaw derivative"),
    "N_r_dash": ("-", "hull yaw derivative"),
    "C_D": ("-", "cross-flow drag coefficient (-0.0591 L/d + 1.848)"),
    "C_rY": ("-", "cross-flow correction for sway (0.52 L/B - 1.062)"),
    "C_rN": ("-", "cross-flow correction for yaw (0.0742 L/d - 0.297)"),
    "D_p": ("m", "propeller diameter"), "t_P": ("-", "thrust deduction"), "w_P0": ("-", "wake fraction"),
    "k_0": ("-", "K_T constant"), "k_1": ("-", "K_T linear"), "k_2": ("-", "K_T quadratic"),
    "A_R": ("m^2", "area of one rudder"), "H_R": ("m", "rudder span"),
    "x_R_dash": ("-", "rudder position / L"), "y_R": ("m", "lateral offset of each rudder"),
    "t_R": ("-", "steering resistance deduction"), "a_H": ("-", "rudder force increase factor"),
    "x_H_dash": ("-", "position of the additional lateral force / L"),
    "gamma_R": ("-", "flow straightening coefficient"), "l_R_dash": ("-", "effective rudder position / L"),
    "epsilon": ("-", "wake ratio rudder/propeller"), "kappa": ("-", "propeller-race correction"),
    "f_alpha": ("-", "rudder lift gradient coefficient"),
}

_L, _B, _d = 3.0, 0.48925, 0.20114
#: Esso Osaka 3 m model with a single propeller and twin (VecTwin-type) rudders.
ESSO_OSAKA_TWIN: dict[str, float] = {
    "rho": 1000.0, "L_pp": _L, "B": _B, "d": _d,
    "m_dash": 0.2453, "x_G_dash": 0.03119, "k_zz": 0.25,
    "m_x_dash": 0.0467, "m_y_dash": 0.2579, "J_z_dash": 0.0286,
    "X_0F_dash": -0.02139, "X_0A_dash": -0.03189, "X_vr_dash": 0.4585, "Y_v_dash": -0.37283,
    "Y_r_dash": 0.1160, "N_v_dash": -0.14575, "N_r_dash": -0.04849,
    "C_D": -0.0591 * _L / _d + 1.848, "C_rY": 0.52 * _L / _B - 1.062, "C_rN": 0.0742 * _L / _d - 0.297,
    "D_p": 0.084, "t_P": 0.20, "w_P0": 0.40, "k_0": 0.2931, "k_1": -0.2753, "k_2": -0.1385,
    "A_R": 0.0105, "H_R": 0.11, "x_R_dash": -0.5, "y_R": 0.05, "t_R": 0.30, "a_H": 0.20, "x_H_dash": -0.45,
    "gamma_R": 0.50, "l_R_dash": -0.9, "epsilon": 1.0, "kappa": 0.5, "f_alpha": 2.0,
}
_HULL = "Esso Osaka 3 m model, Yoshimura low-speed set (reference table section 5: MATLAB hull_EO, " \
        "myozinaung/CGMRES_Autopilot_EssoOsaka mmg_eo.hpp, hullForceYoshimura)"
_ASSUMED = "ASSUMED for the preset (no published value at hand); identify from data"
ESSO_OSAKA_SOURCES: dict[str, str] = {k: _HULL for k in (
    "L_pp", "B", "d", "m_dash", "x_G_dash", "m_x_dash", "m_y_dash", "J_z_dash", "X_0F_dash", "X_0A_dash",
    "X_vr_dash", "Y_v_dash", "Y_r_dash", "N_v_dash", "N_r_dash")}
ESSO_OSAKA_SOURCES.update({
    "C_D": "regression -0.0591 L/d + 1.848 (reference table section 5)",
    "C_rY": "regression 0.52 L/B - 1.062 (reference table section 5)",
    "C_rN": "regression 0.0742 L/d - 0.297 (reference table section 5)",
    "rho": "fresh water (model basin / pond)", "k_zz": "0.25 L, the usual assumption",
    "k_0": "KVLCC2 K_T polynomial used as a stand-in (" + _ASSUMED + ")",
    "k_1": "KVLCC2 K_T polynomial used as a stand-in (" + _ASSUMED + ")",
    "k_2": "KVLCC2 K_T polynomial used as a stand-in (" + _ASSUMED + ")",
})
for _k in ("D_p", "t_P", "w_P0", "A_R", "H_R", "x_R_dash", "y_R", "t_R", "a_H", "x_H_dash", "gamma_R",
           "l_R_dash", "epsilon", "kappa", "f_alpha"):
    ESSO_OSAKA_SOURCES[_k] = _ASSUMED


def crossflow_integrals(a, b):
    """Closed-form cross-flow integrals ``I0 = int |g| g dxi`` and ``I1 = int |g| g xi dxi``.

    ``g = a + b xi`` over ``xi in [-1/2, 1/2]``. If ``g`` keeps its sign on the hull
    (``p q >= 0`` with ``p = a + b/2``, ``q = a - b/2``) then ``I0 = s (a^2 + b^2/12)`` and
    ``I1 = s a b / 6`` (``s = sign(a)``, polynomials, no division); otherwise, using
    ``int |g| g = |g|^3 / (3b)`` and ``int |g| g^2 = g^3 |g| / (4b)``,
    ``I0 = (|p|^3 - |q|^3) / (3b)`` and ``I1 = [(p^3|p| - q^3|q|)/(4b) - a (|p|^3 - |q|^3)/(3b)] / b``
    with ``|b| > 2|a|`` there. Both branches meet with equal values and first derivatives.
    Works on numbers and CasADi symbols.

    In the hull models ``g`` is the local cross-flow velocity along the hull, ``v + r L xi``
    (``xi = x/L``, forward positive), so ``a`` is the sway velocity at midship and ``b`` the yaw
    rate times the length (times a correction such as ``C_rY``); the cross-flow force is then
    ``-rho/2 d L C_D I0`` and its moment ``-rho/2 d L^2 C_D I1``.

    Parameters
    ----------
    a : float, array_like or casadi.SX/MX/DM
        Value of ``g`` at midship (``xi = 0``), e.g. the sway velocity [m/s].
    b : float, array_like or casadi.SX/MX/DM
        Slope of ``g`` over the nondimensional length, e.g. ``r L`` [m/s]; the same shape as ``a``
        (or broadcastable).

    Returns
    -------
    I0, I1 : ndarray or casadi.SX/MX/DM
        The two integrals, in the square of the unit of ``a`` and ``b`` (e.g. [m^2/s^2]);
        numpy arrays (0-d for scalars) for numbers, CasADi expressions for symbols.

    Examples
    --------
    >>> I0, I1 = crossflow_integrals(0.0, 1.0)   # pure yaw: no net force, a moment
    >>> float(I0), float(I1)
    (0.0, 0.03125)
    >>> from scipy.integrate import quad         # g = 0.2 + xi changes sign at xi = -0.2
    >>> I0_ref = quad(lambda xi: abs(0.2 + xi) * (0.2 + xi), -0.5, 0.5, points=[-0.2])[0]
    >>> I1_ref = quad(lambda xi: abs(0.2 + xi) * (0.2 + xi) * xi, -0.5, 0.5, points=[-0.2])[0]
    >>> I0, I1 = crossflow_integrals(0.2, 1.0)
    >>> bool(abs(I0 - I0_ref) < 1e-12 and abs(I1 - I1_ref) < 1e-12)
    True
    """
    lib = ca if any(isinstance(v, (ca.SX, ca.MX, ca.DM)) for v in (a, b)) else np
    p, q = a + b / 2, a - b / 2
    same = p * q >= 0
    if lib is ca:
        s = ca.sign(a)
        bs = ca.if_else(same, 1.0, b)
        fabs = ca.fabs
    else:
        s = np.sign(a)
        bs = np.where(same, 1.0, b)
        fabs = np.abs
    cube = (fabs(p) ** 3 - fabs(q) ** 3) / (3 * bs)
    quart = (p**3 * fabs(p) - q**3 * fabs(q)) / (4 * bs)
    I0_cross, I1_cross = cube, (quart - a * cube) / bs
    I0_same, I1_same = s * (a**2 + b**2 / 12), s * a * b / 6
    if lib is ca:
        return ca.if_else(same, I0_same, I0_cross), ca.if_else(same, I1_same, I1_cross)
    return np.where(same, I0_same, I0_cross), np.where(same, I1_same, I1_cross)


def yoshimura_twin_rudder(values: Mapping[str, float], *, name: str = "mmg-twin-lowspeed", doc: str = "",
                          sources: Mapping[str, str] | None = None, vessel: Vessel | None = None,
                          smooth_speed: float = 1e-4) -> Model:
    """Low-speed MMG model (Yoshimura hull, single propeller, twin rudders) with given parameters.

    Parameters
    ----------
    values : mapping
        A value for every name in :data:`LOWSPEED_PARAMS`.
    name, doc : str
    sources : mapping, optional
        Parameter name -> source text.
    vessel : Vessel, optional
        The ship; its ``rudders`` become ``("delta_s", "delta_p")`` and ``propellers`` ``("n",)``, and
        the rudders get the validity limit ``vessel.rudder_max``.
    smooth_speed : float
        ``e`` [m/s] of the smooth ``|u|``, ``U`` and ``|beta|`` (see the module docstring).

    Returns
    -------
    Model
        States ``u, v, r, x, y, psi``; inputs ``n, delta_s, delta_p``.
    """
    unknown = set(values) - set(LOWSPEED_PARAMS)
    if unknown:
        raise InputError(f"unknown low-speed parameter(s) {sorted(unknown)}; known: {list(LOWSPEED_PARAMS)}")
    sources = dict(sources or {})
    b = ModelBuilder(name, doc or "Yoshimura low-speed MMG model, single propeller, twin rudders "
                                  "(Koike et al. 2023, Eq. 20-22)")
    P = {k: _param(b, k, values, sources, LOWSPEED_PARAMS) for k in LOWSPEED_PARAMS}
    states = declare_ship_states(b)
    u, v, r = states[:3]
    n = b.input("n", unit="1/s", doc="propeller revolutions per second")
    delta_s = b.input("delta_s", unit="rad", doc="starboard rudder angle (positive turns to starboard)")
    delta_p = b.input("delta_p", unit="rad", doc="port rudder angle (positive turns to starboard)")
    rho, L, d = P["rho"], P["L_pp"], P["d"]
    e2 = smooth_speed**2
    U = ca.sqrt(u**2 + v**2 + e2)
    abs_u = ca.sqrt(u**2 + e2)
    abs_beta = ca.atan2(ca.sqrt(v**2 + e2), u)
    # hull
    I0, _ = crossflow_integrals(v, P["C_rY"] * r * L)
    _, I1 = crossflow_integrals(v, P["C_rN"] * r * L)
    X_H = 0.5 * rho * L * d * ((P["X_0F_dash"] + (P["X_0A_dash"] - P["X_0F_dash"]) * abs_beta / np.pi) * u * U
                               + P["X_vr_dash"] * L * v * r)
    Y_H = 0.5 * rho * L * d * (P["Y_v_dash"] * v * abs_u + P["Y_r_dash"] * L * r * u - P["C_D"] * I0)
    N_H = 0.5 * rho * L**2 * d * (P["N_v_dash"] * v * u + P["N_r_dash"] * L * r * abs_u - P["C_D"] * I1)
    # propeller
    D = P["D_p"]
    abs_n = ca.sqrt(n**2 + 1e-12)
    u_P = (1 - P["w_P0"]) * u
    n2KT = P["k_0"] * n * abs_n * D**2 + P["k_1"] * abs_n * D * u_P + P["k_2"] * u_P**2
    X_P = (1 - P["t_P"]) * rho * D**2 * n2KT
    # rudders
    eta = D / P["H_R"]
    race = ca.sqrt(ca.fmax(u_P**2 + 8 * n2KT / np.pi, 0.0) + 1e-12)
    u_R = P["epsilon"] * ca.sqrt(eta * (u_P + P["kappa"] * (race - u_P)) ** 2 + (1 - eta) * u_P**2 + 1e-12)
    v_R = -P["gamma_R"] * (v + P["l_R_dash"] * L * r)
    inflow = ca.atan2(v_R, u_R)
    q_R = 0.5 * rho * P["A_R"] * (u_R**2 + v_R**2) * P["f_alpha"]
    x_R, x_H = P["x_R_dash"] * L, P["x_H_dash"] * L
    X_R = Y_R = N_R = 0
    for delta, y_i in ((delta_s, P["y_R"]), (delta_p, -P["y_R"])):
        F = q_R * ca.sin(delta - inflow)
        Xi = -(1 - P["t_R"]) * F * ca.sin(delta)
        Yi = -(1 + P["a_H"]) * F * ca.cos(delta)
        X_R = X_R + Xi
        Y_R = Y_R + Yi
        N_R = N_R - (x_R + P["a_H"] * x_H) * F * ca.cos(delta) - y_i * Xi
    m = P["m_dash"] * 0.5 * rho * L**2 * d
    rigid_body_3dof(b, (X_H + X_P + X_R, Y_H + Y_R, N_H + N_R), m=m,
                    m_x=P["m_x_dash"] * 0.5 * rho * L**2 * d, m_y=P["m_y_dash"] * 0.5 * rho * L**2 * d,
                    I_zG=m * (P["k_zz"] * L) ** 2, J_z=P["J_z_dash"] * 0.5 * rho * L**4 * d,
                    x_G=P["x_G_dash"] * L, states=states)
    if vessel is not None:
        b.vessel = vessel.replace(rudders=("delta_s", "delta_p"), propellers=("n",))
        declare_ship_limits(b, vessel.replace(U0=None, rudders=("delta_s", "delta_p"), propellers=("n",)))
    return b.build()


def esso_osaka_twin(params: Mapping[str, float] | None = None, *, smooth_speed: float = 1e-4) -> Model:
    """Preset for Koike et al.'s (2023) berthing study: Esso Osaka 3 m model, one propeller, twin rudders.

    Hull: Yoshimura's low-speed coefficients of the Esso Osaka model (reference table section 5).
    Propeller and rudder constants are **assumed** (marked in each parameter's ``source``); treat
    them as a plausible starting point for identification, not as published values.

    Parameters
    ----------
    params : mapping, optional
        Overrides of :data:`ESSO_OSAKA_TWIN`.
    smooth_speed : float
        See :func:`yoshimura_twin_rudder`.

    Examples
    --------
    >>> from casship.models import esso_osaka_twin
    >>> ship = esso_osaka_twin()
    >>> ship.input_names
    ('n', 'delta_s', 'delta_p')
    """
    values = dict(ESSO_OSAKA_TWIN)
    for key, val in (params or {}).items():
        if key not in LOWSPEED_PARAMS:
            raise InputError(f"unknown low-speed parameter {key!r}; known: {list(LOWSPEED_PARAMS)}")
        values[key] = float(val)
    vessel = Vessel("Esso Osaka 3 m model, single propeller, twin rudders", L_pp=values["L_pp"], B=values["B"],
                    draught=values["d"], scale=1.0, U0=0.4, rudder_rate=np.radians(20.0),
                    rudder_max=np.radians(105.0), param_set="esso-osaka/Yoshimura-lowspeed+assumed",
                    source="Yoshimura low-speed hull (reference table section 5); propeller and rudder assumed",
                    wind={"A_F": 0.0535, "A_L": 0.2306, "L_OA": 3.08, "B": 0.48925, "A_OD": 0.062, "H_BR": 0.25,
                     "H_C": 0.045, "C": -0.35,
                     "source": "estimated above-water geometry of a 3 m tanker model (not published)"})
    return yoshimura_twin_rudder(values, name="mmg-twin-lowspeed",
                                 doc="Esso Osaka 3 m, Yoshimura low-speed hull, single propeller, twin rudders "
                                     "(Koike et al. 2023, Eq. 20-22)",
                                 sources=ESSO_OSAKA_SOURCES, vessel=vessel, smooth_speed=smooth_speed)
