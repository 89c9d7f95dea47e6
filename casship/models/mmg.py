"""MMG standard method for ship manoeuvring (Yasukawa & Yoshimura 2015), generic in its parameters.

States ``u, v, r, x, y, psi`` (``v`` is the sway velocity ``v_m`` at midship, ``x`` North, ``y`` East,
``psi`` heading from North, clockwise positive); inputs ``delta`` [rad] (positive turns the ship
to starboard, heading increases) and ``n`` [1/s] (propeller revolutions). Forces are taken at
midship in body axes.

Every ship model built here exposes

* a port ``tau`` (size 3): an extra generalised force ``[X, Y, N]`` [N, N, N m] at midship in body
  axes, added to the hull, propeller and rudder forces before the mass matrix is inverted
  (wind, tugs, thrusters: see :mod:`casship.models.wind`);
* process-noise channels ``w_u, w_v, w_r`` [m/s^2, m/s^2, rad/s^2] added to the accelerations;
* outputs equal to the six states (use :meth:`casship.Model.with_outputs` for other sensors).

The rigid-body part (Yasukawa & Yoshimura 2015, Eq. 4, written at midship with the centre of
gravity ``x_G`` forward of midship)::

    (m + m_x) du - (m + m_y) v r - x_G m r^2           = X
    (m + m_y) dv + x_G m dr + (m + m_x) u r            = Y
    (I_zG + x_G^2 m + J_z) dr + x_G m (dv + u r)       = N

is shared with the low-speed model (:mod:`casship.models.lowspeed`) through :func:`rigid_body_3dof`.
"""
from __future__ import annotations

from typing import Mapping

import casadi as ca
import numpy as np

from ..frames import body_to_ned
from ..builder import ModelBuilder
from ..model import Model
from ..vessel import Vessel
from ..errors import InputError

__all__ = ["mmg_standard", "MMG_PARAMS", "MMG_ASYMMETRY_PARAMS", "MMG_RUDDER_LIFT_PARAMS", "MMG_BOUNDS", "SMOOTH_WIDTH",
           "RUDDER_INFLOWS", "RUDDER_LIFTS",
           "rigid_body_3dof",
           "mmg_force_parts", "declare_ship_states", "declare_ship_limits", "add_rudder_actuator", "smooth_saturation", "mmg_propeller",
           "smooth_abs", "smooth_step"]

# name -> (unit, description). The numeric values come from a preset (see casship.models.kvlcc2).
MMG_PARAMS: dict[str, tuple[str, str]] = {
    "rho": ("kg/m^3", "water density"),
    "L_pp": ("m", "length between perpendiculars"),
    "B": ("m", "breadth"),
    "d": ("m", "draught"),
    "nabla": ("m^3", "displacement volume"),
    "x_G": ("m", "centre of gravity forward of midship"),
    "k_zz": ("-", "yaw radius of gyration / L_pp"),
    "m_x_dash": ("-", "surge added mass / (0.5 rho L^2 d)"),
    "m_y_dash": ("-", "sway added mass / (0.5 rho L^2 d)"),
    "J_z_dash": ("-", "yaw added moment of inertia / (0.5 rho L^4 d)"),
    "R_0_dash": ("-", "straight-run resistance coefficient"),
    "X_vv_dash": ("-", "hull surge derivative"), "X_vr_dash": ("-", "hull surge derivative"),
    "X_rr_dash": ("-", "hull surge derivative"), "X_vvvv_dash": ("-", "hull surge derivative"),
    "Y_v_dash": ("-", "hull sway derivative"), "Y_r_dash": ("-", "hull sway derivative"),
    "Y_vvv_dash": ("-", "hull sway derivative"), "Y_vvr_dash": ("-", "hull sway derivative"),
    "Y_vrr_dash": ("-", "hull sway derivative"), "Y_rrr_dash": ("-", "hull sway derivative"),
    "N_v_dash": ("-", "hull yaw derivative"), "N_r_dash": ("-", "hull yaw derivative"),
    "N_vvv_dash": ("-", "hull yaw derivative"), "N_vvr_dash": ("-", "hull yaw derivative"),
    "N_vrr_dash": ("-", "hull yaw derivative"), "N_rrr_dash": ("-", "hull yaw derivative"),
    "D_p": ("m", "propeller diameter"),
    "t_P": ("-", "thrust deduction factor"),
    "w_P0": ("-", "wake fraction at the propeller in straight run"),
    "x_P_dash": ("-", "propeller position / L_pp (aft negative)"),
    "k_0": ("-", "K_T polynomial constant"), "k_1": ("-", "K_T polynomial linear"),
    "k_2": ("-", "K_T polynomial quadratic"),
    "C_1": ("-", "wake correction constant"),
    "C_2_plus": ("-", "wake correction constant for beta_P > 0"),
    "C_2_minus": ("-", "wake correction constant for beta_P < 0"),
    "A_R": ("m^2", "rudder area"),
    "H_R": ("m", "rudder span"),
    "t_R": ("-", "steering resistance deduction factor"),
    "a_H": ("-", "rudder force increase factor"),
    "x_H_dash": ("-", "position of the additional lateral force / L_pp"),
    "x_R_dash": ("-", "rudder position / L_pp (aft negative)"),
    "gamma_R_minus": ("-", "flow straightening coefficient for beta_R < 0"),
    "gamma_R_plus": ("-", "flow straightening coefficient for beta_R > 0"),
    "l_R_dash": ("-", "effective longitudinal rudder position / L_pp"),
    "epsilon": ("-", "ratio of wake fractions at rudder and propeller"),
    "kappa": ("-", "propeller-race inflow correction"),
    "f_alpha": ("-", "rudder lift gradient coefficient"),
}


#: Asymmetry terms of the extended variant (``asymmetry=True``); all zero in the published model.
MMG_ASYMMETRY_PARAMS: dict[str, tuple[str, str]] = {
    "delta_0": ("rad", "rudder neutral angle: the rudder angle of zero normal force in straight run"),
    "Y_0_dash": ("-", "propeller-induced side force / propeller thrust"),
    "N_0_dash": ("-", "propeller-induced yaw moment / (propeller thrust L_pp), at midship"),
}

#: Parameter of the rudder-lift variant (``rudder_lift="cubic"``); zero gives the published sine.
MMG_RUDDER_LIFT_PARAMS: dict[str, tuple[str, str]] = {
    "c_alpha3": ("-", "loss of rudder lift slope at large effective angle: F_N proportional to "
                      "sin(alpha_R) - c_alpha3 sin(alpha_R)^3"),
}

#: Parameter of the rudder-lever variant (``rudder_lever="loading"``); zero gives the published constant lever.
MMG_RUDDER_LEVER_PARAMS: dict[str, tuple[str, str]] = {
    "x_HJ_dash": ("-", "change of x'_H with the propeller advance ratio: x'_H + x'_HJ J_P, the point of the "
                       "hull's share of the rudder force moving with the propeller loading"),
}

_POS = (0.0, np.inf)
#: Physical bounds of the MMG parameters (an identification cannot leave them).
MMG_BOUNDS: dict[str, tuple[float, float]] = {
    **{k: _POS for k in ("rho", "L_pp", "B", "d", "nabla", "k_zz", "m_x_dash", "m_y_dash", "J_z_dash", "R_0_dash",
                         "D_p", "C_1", "C_2_plus", "C_2_minus", "A_R", "H_R", "gamma_R_minus", "gamma_R_plus",
                         "epsilon", "f_alpha")},
    "t_P": (0.0, 1.0), "w_P0": (0.0, 1.0), "t_R": (0.0, 1.0), "a_H": (0.0, 1.0),
    "kappa": (0.0, 1.0),       # between the propeller disk (about 0.5) and the far race (1.0)
    "delta_0": (-np.radians(10.0), np.radians(10.0)),
    # c_alpha3 <= 1 keeps the normal force rising up to 35 deg (its peak is at sin^2 alpha_R = 1 / (3 c_alpha3))
    "c_alpha3": (-1.0, 1.0),
}

#: Forms of the rudder inflow speed ``u_R`` (see :func:`mmg_standard`, option ``rudder_inflow``).
RUDDER_INFLOWS = ("published", "race-additive")

#: Forms of the rudder normal force against the effective angle (see :func:`mmg_standard`, option ``rudder_lift``).
RUDDER_LIFTS = ("sine", "cubic")

#: Forms of the lever of the hull's share of the rudder force (see :func:`mmg_standard`, option ``rudder_lever``).
RUDDER_LEVERS = ("constant", "loading")

#: Width [rad] of the smooth sign switches of ``smooth=True`` (see :func:`mmg_standard`).
SMOOTH_WIDTH = 0.01


def smooth_abs(x, width: float):
    """``sqrt(x^2 + width^2) - width``: a smooth ``|x|`` (zero at zero, within ``width`` of ``|x|``).

    Parameters
    ----------
    x : SX, MX or float
        Argument.
    width : float
        Width of the rounded corner [unit of ``x``].

    Returns
    -------
    SX, MX or float
    """
    return ca.sqrt(x**2 + width**2) - width


def smooth_step(x, width: float):
    """``(1 + tanh(x / width)) / 2``: a smooth switch from 0 (``x << -width``) to 1 (``x >> width``).

    Parameters
    ----------
    x : SX, MX or float
        Argument.
    width : float
        Width of the switch [unit of ``x``].

    Returns
    -------
    SX, MX or float
    """
    return 0.5 * (1 + ca.tanh(x / width))


def smooth_saturation(x, limit):
    """``limit * tanh(x / limit)``: a smooth (differentiable) saturation to ``(-limit, limit)``.

    Used for the rudder rate limit so that Jacobians exist everywhere; it equals ``x`` to first
    order for ``|x| << limit`` and approaches ``+-limit`` for large ``|x|``.

    Parameters
    ----------
    x : SX, MX or float
        Argument.
    limit : float or SX
        Saturation level (positive).

    Returns
    -------
    SX, MX or float
    """
    return limit * ca.tanh(x / limit)


def declare_ship_states(b: ModelBuilder):
    """Declare the shared 3-DOF ship states ``u, v, r, x, y, psi`` and return their symbols.

    Parameters
    ----------
    b : ModelBuilder
        The builder to declare them in.

    Returns
    -------
    tuple of SX
        ``(u, v, r, x, y, psi)``.
    """
    u = b.state("u", unit="m/s", doc="surge velocity")
    v = b.state("v", unit="m/s", doc="sway velocity at midship (v_m)")
    r = b.state("r", unit="rad/s", doc="yaw rate")
    x = b.state("x", unit="m", doc="North position of midship")
    y = b.state("y", unit="m", doc="East position of midship")
    psi = b.state("psi", unit="rad", angle=True, doc="heading from North, clockwise")
    return u, v, r, x, y, psi


def add_rudder_actuator(b: ModelBuilder, names: tuple[str, ...], time_constant: float, rate_limit: float,
                        max_angle: float | None = None) -> dict[str, ca.SX]:
    """Rudder angle states driven by commanded angles through a first-order lag with a rate limit.

    For each rudder ``name`` the model gets a state ``name`` [rad] and an input ``name + "_cmd"``
    [rad] with ``d(name)/dt = S((cmd - name) / T_rud)``, where ``S`` is :func:`smooth_saturation`
    at ``rudder_rate_max`` (parameters ``T_rud`` [s] and ``rudder_rate_max`` [rad/s]). The command is
    not clipped; clip it with ``max_angle`` if given (hard ``fmin``/``fmax``, documented limit).

    Parameters
    ----------
    b : ModelBuilder
        The builder.
    names : tuple of str
        Rudder state names (each gets an input ``name + "_cmd"``).
    time_constant : float
        Nominal ``T_rud`` [s].
    rate_limit : float
        Nominal ``rudder_rate_max`` [rad/s].
    max_angle : float, optional
        Clip of the commanded angle [rad].

    Returns
    -------
    dict
        Rudder name -> state symbol.
    """
    T = b.param("T_rud", time_constant, bounds=(1e-6, np.inf), unit="s", doc="rudder actuator time constant")
    rmax = b.param("rudder_rate_max", rate_limit, bounds=(1e-9, np.inf), unit="rad/s",
                   doc="rudder rate limit (smooth tanh saturation)")
    out = {}
    for name in names:
        state = b.state(name, unit="rad", doc=f"actual rudder angle {name}")
        cmd = b.input(f"{name}_cmd", unit="rad", doc=f"commanded rudder angle {name}")
        if max_angle is not None:
            cmd = ca.fmin(ca.fmax(cmd, -max_angle), max_angle)
        b.ode(**{name: smooth_saturation((cmd - state) / T, rmax)})
        out[name] = state
    return out


def rigid_body_3dof(b: ModelBuilder, force: tuple, *, m, m_x, m_y, I_zG, J_z, x_G, states) -> None:
    """Add the 3-DOF rigid-body equations at midship, the ``tau`` port, noise and kinematics.

    Parameters
    ----------
    b : ModelBuilder
        Builder holding the states from :func:`declare_ship_states`.
    force : (X, Y, N)
        Hydrodynamic force and moment at midship in body axes [N, N, N m].
    m, m_x, m_y, I_zG, J_z, x_G : SX
        Mass, added masses, yaw inertia about G, added yaw inertia, CG position.
    states : tuple
        ``(u, v, r, x, y, psi)`` symbols.
    """
    u, v, r, _x, _y, psi = states
    tau = b.port("tau", 3)
    X = force[0] + tau[0] + (m + m_y) * v * r + x_G * m * r**2
    Y = force[1] + tau[1] - (m + m_x) * u * r
    N = force[2] + tau[2] - x_G * m * u * r
    # Solve the sway/yaw 2x2 block of the mass matrix explicitly.
    m22, m23, m33 = m + m_y, x_G * m, I_zG + x_G**2 * m + J_z
    det = m22 * m33 - m23**2
    du = X / (m + m_x)
    dv = (m33 * Y - m23 * N) / det
    dr = (m22 * N - m23 * Y) / det
    xd, yd, psid = body_to_ned(u, v, r, psi)
    b.ode(u=du + b.noise("w_u", unit="m/s^2"), v=dv + b.noise("w_v", unit="m/s^2"),
          r=dr + b.noise("w_r", unit="rad/s^2"), x=xd, y=yd, psi=psid)
    for name in ("u", "v", "r", "x", "y", "psi"):
        b.output(name, b.sym(name))


def _param(b: ModelBuilder, name: str, values: Mapping[str, float], sources: Mapping[str, str],
           table: Mapping[str, tuple[str, str]], default: float | None = None):
    if name not in values and default is None:
        raise InputError(f"no value given for parameter {name!r}")
    unit, doc = table[name]
    return b.param(name, values.get(name, default), bounds=MMG_BOUNDS.get(name), unit=unit, doc=doc,
                   source=sources.get(name, "extended MMG (asymmetry), zero in the published model"
                                      if default is not None else ""))


def mmg_standard(values: Mapping[str, float], *, name: str = "mmg", doc: str = "",
                 sources: Mapping[str, str] | None = None, vessel: Vessel | None = None,
                 rudder_actuator: bool = False, rudder_time_constant: float = 1.0,
                 rudder_rate_max: float = np.radians(2.32), rudder_max: float | None = None,
                 asymmetry: bool = False, smooth: bool = False, rudder_inflow: str = "published",
                 rudder_lift: str = "sine", rudder_lever: str = "constant", meta: Mapping | None = None) -> Model:
    """MMG standard-method model (Yasukawa & Yoshimura 2015) with the given parameter values.

    Hull (Eq. 8): ``X_H = 0.5 rho L d U^2 (-R0' + X'vv v'^2 + X'vr v' r' + X'rr r'^2 + X'vvvv v'^4)``,
    ``Y_H``, ``N_H`` with the cubic polynomials in ``v' = v/U``, ``r' = r L/U``.
    Propeller (Eq. 10-16): ``X_P = (1 - t_P) rho n^2 D^4 K_T(J_P)``, ``K_T = k0 + k1 J + k2 J^2``,
    ``J_P = u (1 - w_P) / (n D)``, wake ``(1 - w_P) = (1 - w_P0) [1 + (1 - exp(-C1 |beta_P|)) (C2 - 1)]``
    with ``beta_P = beta - x'_P r'`` and ``C2 = C_2_plus`` for ``beta_P > 0`` else ``C_2_minus``.
    Rudder (Eq. 17-27): ``F_N = 0.5 rho A_R U_R^2 f_alpha sin(alpha_R)``,
    ``alpha_R = delta - atan(v_R / u_R)``, ``v_R = U gamma_R beta_R``, ``beta_R = beta - l'_R r'``,
    ``u_R = eps u_P sqrt(eta {1 + kappa (sqrt(1 + 8 K_T / (pi J^2)) - 1)}^2 + 1 - eta)``, ``eta = D_p / H_R``;
    ``X_R = -(1 - t_R) F_N sin(delta)``, ``Y_R = -(1 + a_H) F_N cos(delta)``,
    ``N_R = -(x_R + a_H x_H) F_N cos(delta)``.

    The propeller terms are written with ``u_P = u (1 - w_P)`` so that they stay finite at ``n = 0``:
    ``n^2 D^4 K_T = k0 n^2 D^4 + k1 n D^3 u_P + k2 D^2 u_P^2`` and
    ``u_P sqrt(1 + 8 K_T/(pi J^2)) = sqrt(u_P^2 + 8 n^2 D^2 K_T / pi)`` (valid for ``u_P > 0``; the
    radicand is floored at zero). The model is meant for ahead motion (``u > 0``, ``n >= 0``); use
    :func:`casship.models.lowspeed.yoshimura_twin_rudder` near zero speed.

    **Asymmetry** (``asymmetry=True``): a single-screw ship is not port/starboard symmetric. The
    extended variant adds the parameters of :data:`MMG_ASYMMETRY_PARAMS`, all zero by default so
    that the published model is unchanged: a rudder neutral angle ``delta_0`` (``alpha_R = delta -
    delta_0 - atan(v_R / u_R)``; the propeller swirl at the rudder) and a propeller-induced side force
    and yaw moment that scale with the propeller loading, ``Y_P = Y'_0 T``, ``N_P = N'_0 L T`` with
    the thrust ``T = rho n^2 D^4 K_T(J_P)``.

    **Rudder inflow** (``rudder_inflow``): ``"published"`` is Eq. 24 above, where the wake ratio
    ``epsilon`` multiplies the propeller race as well as the wake. With ``"race-additive"`` it
    scales the wake only and the race adds the increment of momentum theory, ``u_inf - u_P`` with
    ``u_inf = sqrt(u_P^2 + 8 n^2 D^2 K_T / pi)`` (the far-race speed, a function of the thrust
    loading alone): ``u_R = sqrt(eta (epsilon u_P + kappa (u_inf - u_P))^2 + (1 - eta) (epsilon u_P)^2)``.
    The two agree for ``epsilon = 1``; they differ in how a change of the wake (``w_P0``,
    ``epsilon``) carries over to a heavily loaded propeller (a tight turn, where the race
    dominates): with the published form the race at the rudder follows the wake ratio, with the
    additive one it follows the thrust.

    **Rudder lift** (``rudder_lift``): the published normal force ``f_alpha sin(alpha_R)`` keeps its
    lift slope up to any angle. Real rudders, behind the hull and in the propeller race as well, lose
    lift slope towards stall at the effective angles of a hard-over turn (rudder lift curves, e.g.
    Molland & Turnock 2007). With ``"cubic"`` the normal force is ``F_N = 0.5 rho A_R U_R^2 f_alpha
    (sin(alpha_R) - c_alpha3 sin(alpha_R)^3)``: the next odd term of the expansion in the angle, as
    in the cubic rudder derivatives ``Y_ddd``, ``N_ddd`` of Abkowitz-type models (the Mariner of
    Chislett & Strøm-Tejsen 1965: ``Y_ddd / Y_d = N_ddd / N_d = -0.32``, about ``c_alpha3 = 0.19`` in
    this form at 35 deg). ``c_alpha3 = 0`` (its default) is the published model; a positive value
    weakens the rudder by the fraction ``c_alpha3 sin^2(alpha_R)`` (``0.33 c_alpha3`` at 35 deg,
    ``0.03 c_alpha3`` at 10 deg), a negative one strengthens it (the cross-flow lift of a low-aspect-ratio foil).
    The bounds ``[-1, 1]`` keep the force rising up to 35 deg.

    **Rudder lever** (``rudder_lever``): the published model holds the hull's share of the rudder
    force (``a_H``) at one point ``x'_H``. In captive tests the yaw moment per rudder force changes
    with the propeller loading (the KVLCC2's HMRI static rudder tests at reduced speed and constant
    rps: ``dN'/dRY'`` linear in ``J/J_0``, see ``docs/identification.md``, "What the captive tests
    say about hard-over"; the MMG literature reports ``a_H`` and ``x_H`` varying with the loading).
    With ``"loading"`` the point moves linearly with the propeller advance ratio,
    ``x'_H + x'_HJ J_P`` with ``J_P = u_P n D / (n^2 D^2 + 10^-6)`` (finite at ``n = 0``);
    ``x'_HJ = 0`` (its default) is the published model.

    **Smooth sign switches** (``smooth=True``): the published wake and flow-straightening terms switch
    on the signs of ``beta_P`` and ``beta_R`` (``C_2``, ``gamma_R``) and use ``|beta_P|``; their
    derivatives jump at zero drift, which makes an identification cost non-smooth (a Newton-type
    solver stalls on the kinks). With ``smooth=True`` the switches are ``C_2 = C_2_minus +
    (C_2_plus - C_2_minus) s(beta_P)``, ``gamma_R = gamma_R_minus + (gamma_R_plus - gamma_R_minus)
    s(beta_R)`` with ``s`` = :func:`smooth_step` and ``|beta_P|`` = :func:`smooth_abs`, both of width
    :data:`SMOOTH_WIDTH` (0.01 rad = 0.57 deg). The wake fraction then differs from the published one
    by less than 0.007 (absolute) anywhere; manoeuvre indices of the KVLCC2 change by less than 1 %
    (tested in ``tests/test_mmg.py``).

    Parameters
    ----------
    values : mapping
        A value for every name in :data:`MMG_PARAMS`.
    name, doc : str
        Model name and description.
    sources : mapping, optional
        Parameter name -> source string (stored with each parameter).
    vessel : Vessel, optional
        The ship (particulars, approach condition, parameter set). Its ``rudders`` and
        ``propellers`` are set to the model's inputs; the rudder and propeller inputs and the surge
        velocity get validity limits from it (rudder stop, propeller ahead up to twice the approach
        rate, ahead motion up to twice the approach speed).
    rudder_actuator : bool
        If True, ``delta`` becomes a state driven by the input ``delta_cmd`` through
        :func:`add_rudder_actuator` (first order, smooth rate limit ``rudder_rate_max`` [rad/s]).
    rudder_time_constant, rudder_rate_max, rudder_max : float
        Actuator settings (only with ``rudder_actuator``).
    asymmetry : bool
        Add the asymmetry parameters ``delta_0``, ``Y_0_dash``, ``N_0_dash`` (zero unless ``values``
        gives them).
    smooth : bool
        Smooth sign switches of ``C_2`` and ``gamma_R`` (see above).
    rudder_inflow : str
        ``"published"`` (Yasukawa & Yoshimura 2015, Eq. 24) or ``"race-additive"`` (see above).
    rudder_lift : str
        ``"sine"`` (published) or ``"cubic"``: adds the parameter ``c_alpha3`` (zero unless ``values``
        gives it; see above).
    rudder_lever : str
        ``"constant"`` (published) or ``"loading"``: adds the parameter ``x_HJ_dash`` (zero unless
        ``values`` gives it; see above).
    meta : mapping, optional
        Entries for ``model.meta`` (a preset records its build options under ``"options"`` there,
        so that a fit file rebuilds the same variant).

    Returns
    -------
    Model
    """
    if rudder_inflow not in RUDDER_INFLOWS:
        raise InputError(f"rudder_inflow must be one of {RUDDER_INFLOWS}, got {rudder_inflow!r}")
    if rudder_lift not in RUDDER_LIFTS:
        raise InputError(f"rudder_lift must be one of {RUDDER_LIFTS}, got {rudder_lift!r}")
    if rudder_lever not in RUDDER_LEVERS:
        raise InputError(f"rudder_lever must be one of {RUDDER_LEVERS}, got {rudder_lever!r}")
    cubic, loading = rudder_lift == "cubic", rudder_lever == "loading"
    sources = {"c_alpha3": "rudder-lift variant; 0 gives the published model",
               "x_HJ_dash": "rudder-lever variant; 0 gives the published model", **(sources or {})}
    known = {**MMG_PARAMS, **(MMG_ASYMMETRY_PARAMS if asymmetry else {}), **(MMG_RUDDER_LIFT_PARAMS if cubic else {}),
             **(MMG_RUDDER_LEVER_PARAMS if loading else {})}
    unknown = set(values) - set(known)
    if unknown:
        hint = (" (the asymmetry terms need asymmetry=True)" if unknown & set(MMG_ASYMMETRY_PARAMS) else
                " (c_alpha3 needs rudder_lift='cubic')" if unknown & set(MMG_RUDDER_LIFT_PARAMS) else
                " (x_HJ_dash needs rudder_lever='loading')" if unknown & set(MMG_RUDDER_LEVER_PARAMS) else "")
        raise InputError(f"unknown MMG parameter(s) {sorted(unknown)}{hint}; known: {list(known)}")
    b = ModelBuilder(name, doc or "MMG standard method (Yasukawa & Yoshimura 2015)")
    P = {k: _param(b, k, values, sources, MMG_PARAMS) for k in MMG_PARAMS}
    if asymmetry:
        P.update({k: _param(b, k, values, sources, MMG_ASYMMETRY_PARAMS, default=0.0) for k in MMG_ASYMMETRY_PARAMS})
    if cubic:
        P["c_alpha3"] = _param(b, "c_alpha3", values, sources, MMG_RUDDER_LIFT_PARAMS, default=0.0)
    if loading:
        P["x_HJ_dash"] = _param(b, "x_HJ_dash", values, sources, MMG_RUDDER_LEVER_PARAMS, default=0.0)
    b.meta.update(dict(meta or {}))
    if asymmetry:          # port/starboard terms: identified only from mirrored evidence (casship.identify.asymmetry)
        b.meta["asymmetric"] = list(MMG_ASYMMETRY_PARAMS)
    states = declare_ship_states(b)
    u, v, r = states[:3]
    if rudder_actuator:
        delta = add_rudder_actuator(b, ("delta",), rudder_time_constant, rudder_rate_max, rudder_max)["delta"]
    else:
        delta = b.input("delta", unit="rad", doc="rudder angle, positive turns to starboard")
    n = b.input("n", unit="1/s", doc="propeller revolutions per second")
    force = mmg_forces(P, u, v, r, delta, n, smooth=SMOOTH_WIDTH if smooth else None, rudder_inflow=rudder_inflow)
    rho, L, d = P["rho"], P["L_pp"], P["d"]
    m = rho * P["nabla"]
    m_x = P["m_x_dash"] * 0.5 * rho * L**2 * d
    m_y = P["m_y_dash"] * 0.5 * rho * L**2 * d
    J_z = P["J_z_dash"] * 0.5 * rho * L**4 * d
    I_zG = m * (P["k_zz"] * L) ** 2
    rigid_body_3dof(b, force, m=m, m_x=m_x, m_y=m_y, I_zG=I_zG, J_z=J_z, x_G=P["x_G"], states=states)
    if vessel is not None:
        rudder = "delta_cmd" if rudder_actuator else "delta"
        b.vessel = vessel.replace(rudders=(rudder,), propellers=("n",))
        declare_ship_limits(b, b.vessel)
    return b.build()


def declare_ship_limits(b: ModelBuilder, vessel: Vessel) -> None:
    """Validity ranges of a conventional ship model from its vessel: rudder stop on every rudder
    input, propeller rates in ``vessel.propeller_range`` and ahead motion ``0 <= u <= 2 U0``.

    Parameters
    ----------
    b : ModelBuilder
        The builder (its declared inputs and states get the limits).
    vessel : Vessel
        The ship, with its rudder and propeller inputs.
    """
    if vessel.rudder_max is not None:
        for name in vessel.rudders:
            b.limit(name, -vessel.rudder_max, vessel.rudder_max, why="rudder stop")
    if vessel.propeller_range is not None:
        for name in vessel.propellers:
            b.limit(name, *vessel.propeller_range, why="propeller rates the model is valid for")
    if vessel.U0 is not None and b.has("u"):
        b.limit("u", 0.0, 2.0 * vessel.U0, why="ahead motion up to twice the approach speed")


def mmg_propeller(P: Mapping[str, ca.SX], u, v, r, n, smooth: float | None = None):
    """Propeller thrust ``T`` [N] of the MMG standard method, its inflow ``u_P`` and ``n^2 D^2 K_T``.

    The wake ``1 - w_P = (1 - w_P0) [1 + (1 - exp(-C_1 |beta_P|)) (C_2 - 1)]`` with
    ``beta_P = beta - x'_P r'``, ``u_P = u (1 - w_P)``, ``T = rho n^2 D^4 K_T(J_P)`` (written to stay
    finite at ``n = 0``).

    Parameters
    ----------
    P : mapping
        Parameter name -> symbol or value (the names of :data:`MMG_PARAMS`).
    u, v, r : SX, MX or float
        Surge and sway velocity at midship [m/s], yaw rate [rad/s].
    n : SX, MX or float
        Propeller rate [1/s].
    smooth : float, optional
        Width of the smooth sign switches [rad] (``None``: the published ``if_else`` switches).

    Returns
    -------
    (T, u_P, n2KT)
        Thrust [N], propeller inflow speed [m/s] and ``n^2 D^2 K_T`` [m^2/s^2].
    """
    L = P["L_pp"]
    U = ca.sqrt(u**2 + v**2 + 1e-12)
    beta_P = ca.atan2(-v, u) - P["x_P_dash"] * r * L / U
    if smooth is None:
        C_2 = ca.if_else(beta_P > 0, P["C_2_plus"], P["C_2_minus"])
        abs_beta_P = ca.fabs(beta_P)
    else:
        C_2 = P["C_2_minus"] + (P["C_2_plus"] - P["C_2_minus"]) * smooth_step(beta_P, smooth)
        abs_beta_P = smooth_abs(beta_P, smooth)
    one_minus_wP = (1 - P["w_P0"]) * (1 + (1 - ca.exp(-P["C_1"] * abs_beta_P)) * (C_2 - 1))
    u_P = u * one_minus_wP
    D = P["D_p"]
    n2KT = P["k_0"] * n**2 * D**2 + P["k_1"] * n * D * u_P + P["k_2"] * u_P**2   # n^2 D^2 K_T
    return P["rho"] * D**2 * n2KT, u_P, n2KT


def mmg_forces(P: Mapping[str, ca.SX], u, v, r, delta, n, smooth: float | None = None,
               rudder_inflow: str = "published"):
    """Hull + propeller + rudder force ``(X, Y, N)`` at midship of the MMG standard method.

    ``P`` may hold the asymmetry terms of :data:`MMG_ASYMMETRY_PARAMS` and the rudder-lift term of
    :data:`MMG_RUDDER_LIFT_PARAMS` (absent: the published sine); ``smooth`` is the width of
    the smooth sign switches (``None``: the published ``if_else`` switches); ``rudder_inflow`` one of
    :data:`RUDDER_INFLOWS` (see :func:`mmg_standard`).
    """
    parts = mmg_force_parts(P, u, v, r, delta, n, smooth, rudder_inflow)
    return parts["X"], parts["Y"], parts["N"]


def mmg_force_parts(P: Mapping[str, ca.SX], u, v, r, delta, n, smooth: float | None = None,
                    rudder_inflow: str = "published") -> dict:
    """The MMG force of :func:`mmg_forces` with the parts a captive test measures on their own.

    Parameters
    ----------
    P : mapping
        Parameter name -> symbol or value (as for :func:`mmg_forces`).
    u, v, r : SX, MX or float
        Surge and sway velocity at midship [m/s], yaw rate [rad/s].
    delta, n : SX, MX or float
        Rudder angle [rad] and propeller rate [1/s].
    smooth : float, optional
        Width of the smooth sign switches [rad] (``None``: the published switches).
    rudder_inflow : str
        One of :data:`RUDDER_INFLOWS`.

    Returns
    -------
    dict
        ``X, Y, N`` (the total at midship [N, N, N m]), ``T`` (propeller thrust [N]) and the rudder
        force on the rudder stock ``RX = -F_N sin(delta)``, ``RY = -F_N cos(delta)`` [N] (without the
        hull's share ``a_H``).
    """
    rho, L, d = P["rho"], P["L_pp"], P["d"]
    U = ca.sqrt(u**2 + v**2 + 1e-12)
    rL = r * L
    # hull (dimensional form of the polynomials; v' = v/U, r' = rL/U)
    X_H = 0.5 * rho * L * d * (-P["R_0_dash"] * U**2 + P["X_vv_dash"] * v**2 + P["X_vr_dash"] * v * rL
                                + P["X_rr_dash"] * rL**2 + P["X_vvvv_dash"] * v**4 / U**2)
    Y_H = 0.5 * rho * L * d * (P["Y_v_dash"] * v * U + P["Y_r_dash"] * rL * U
                                + (P["Y_vvv_dash"] * v**3 + P["Y_vvr_dash"] * v**2 * rL
                                   + P["Y_vrr_dash"] * v * rL**2 + P["Y_rrr_dash"] * rL**3) / U)
    N_H = 0.5 * rho * L**2 * d * (P["N_v_dash"] * v * U + P["N_r_dash"] * rL * U
                                   + (P["N_vvv_dash"] * v**3 + P["N_vvr_dash"] * v**2 * rL
                                      + P["N_vrr_dash"] * v * rL**2 + P["N_rrr_dash"] * rL**3) / U)
    # propeller
    beta = ca.atan2(-v, u)
    r_dash = rL / U
    T, u_P, n2KT = mmg_propeller(P, u, v, r, n, smooth)
    D = P["D_p"]
    X_P = (1 - P["t_P"]) * T
    # rudder
    eta = D / P["H_R"]
    race = ca.sqrt(ca.fmax(u_P**2 + 8 * n2KT / np.pi, 0.0))                        # u_P sqrt(1 + 8KT/(pi J^2))
    if rudder_inflow == "published":
        u_R = P["epsilon"] * ca.sqrt(eta * (u_P + P["kappa"] * (race - u_P)) ** 2 + (1 - eta) * u_P**2 + 1e-12)
    else:                       # the wake ratio scales the wake, the race adds its momentum-theory increment
        wake = P["epsilon"] * u_P
        u_R = ca.sqrt(eta * (wake + P["kappa"] * (race - u_P)) ** 2 + (1 - eta) * wake**2 + 1e-12)
    beta_R = beta - P["l_R_dash"] * r_dash
    if smooth is None:
        gamma_R = ca.if_else(beta_R < 0, P["gamma_R_minus"], P["gamma_R_plus"])
    else:
        gamma_R = P["gamma_R_minus"] + (P["gamma_R_plus"] - P["gamma_R_minus"]) * smooth_step(beta_R, smooth)
    v_R = U * gamma_R * beta_R
    alpha_R = delta - P.get("delta_0", 0.0) - ca.atan2(v_R, u_R)
    U_R2 = u_R**2 + v_R**2
    lift = ca.sin(alpha_R)
    if "c_alpha3" in P:         # loss of lift slope at large effective angle (option rudder_lift="cubic")
        lift = lift - P["c_alpha3"] * lift**3
    F_N = 0.5 * rho * P["A_R"] * U_R2 * P["f_alpha"] * lift
    x_R, x_H = P["x_R_dash"] * L, P["x_H_dash"] * L
    if "x_HJ_dash" in P:        # the hull's share moves with the propeller loading (option rudder_lever="loading")
        x_H = x_H + P["x_HJ_dash"] * L * u_P * n * D / (n**2 * D**2 + 1e-6)
    X_R = -(1 - P["t_R"]) * F_N * ca.sin(delta)
    Y_R = -(1 + P["a_H"]) * F_N * ca.cos(delta)
    N_R = -(x_R + P["a_H"] * x_H) * F_N * ca.cos(delta)
    Y_P = P.get("Y_0_dash", 0.0) * T               # propeller-induced side force and yaw moment
    N_P = P.get("N_0_dash", 0.0) * L * T
    return {"X": X_H + X_P + X_R, "Y": Y_H + Y_P + Y_R, "N": N_H + N_P + N_R, "T": T,
            "RX": -F_N * ca.sin(delta), "RY": -F_N * ca.cos(delta)}
