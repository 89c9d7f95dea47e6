"""Mariner-class cargo ship (Chislett & Strøm-Tejsen 1965, Hy-5), as in MSS ``mariner.m``.

L = 160.93 m, nominal speed U0 = 7.7175 m/s (15 kn). Non-dimensional (prime system with
``1/2 rho L^3``, ``1/2 rho L^2 U^2``, ``1/2 rho L^3 U^2``) cubic hydrodynamic model; the
coefficients are those of MSS ``VESSELS/SHIP/models/mariner.m`` (project reference table 2.3, all
scaled by 1e-5). States ``u, v, r, x, y, psi`` are the usual dimensional ones (``u`` is the total
surge speed; the model works internally with the perturbation ``u - U0``); input ``delta`` [rad]
positive turns the ship to starboard (MSS flips the sign of its input, ``delta_c = -ui``, for the
same reason). The ``tau`` port force is made non-dimensional with ``1/2 rho L^2 U^2`` (moment with
``L^3``) before it enters the equations.

With the asymmetric terms ``Y_0, Y_0u, Y_0uu, N_0, N_0u, N_0uu`` (propeller-induced side force)
the ship slowly turns with zero rudder, as in MSS; set them to zero for a symmetric ship.
"""
from __future__ import annotations

from typing import Mapping

import numpy as np

from ..frames import body_to_ned
from ..builder import ModelBuilder
from ..model import Model
from ..vessel import Vessel
from .mmg import add_rudder_actuator, declare_ship_limits, declare_ship_states
from ..errors import InputError

__all__ = ["mariner", "MARINER"]

#: Non-dimensional coefficients (x 1e-5 applied) and particulars; MSS mariner.m (Chislett & Strom-Tejsen 1965).
MARINER: dict[str, float] = {
    "m": 798.0, "Iz": 39.2, "xG": -0.023 / 1e-5,
    "Xudot": -42.0, "Xu": -184.0, "Xuu": -110.0, "Xuuu": -215.0, "Xvv": -899.0, "Xrr": 18.0, "Xdd": -95.0,
    "Xudd": -190.0, "Xrv": 798.0, "Xvd": 93.0, "Xuvd": 93.0,
    "Yvdot": -748.0, "Yrdot": -9.354, "Yv": -1160.0, "Yr": -499.0, "Yvvv": -8078.0, "Yvvr": 15356.0,
    "Yvu": -1160.0, "Yru": -499.0, "Yd": 278.0, "Yddd": -90.0, "Yud": 556.0, "Yuud": 278.0, "Yvdd": -4.0,
    "Yvvd": 1190.0, "Y0": -4.0, "Y0u": -8.0, "Y0uu": -4.0,
    "Nvdot": 4.646, "Nrdot": -43.8, "Nv": -264.0, "Nr": -166.0, "Nvvv": 1636.0, "Nvvr": -5483.0,
    "Nvu": -264.0, "Nru": -166.0, "Nd": -139.0, "Nddd": 45.0, "Nud": -278.0, "Nuud": -139.0, "Nvdd": 13.0,
    "Nvvd": -489.0, "N0": 3.0, "N0u": 6.0, "N0uu": 3.0,
}
L_MARINER = 160.93
U0_MARINER = 7.7175
_SOURCE = "MSS VESSELS/SHIP/models/mariner.m (Chislett & Strom-Tejsen 1965, Hy-5)"


def mariner(params: Mapping[str, float] | None = None, *, U0: float = U0_MARINER,
            rudder_actuator: bool = False) -> Model:
    """Mariner-class cargo ship, 3 DOF (MSS ``mariner.m``).

    Parameters
    ----------
    params : mapping, optional
        Overrides of :data:`MARINER` (values in units of 1e-5, as printed in the source; ``xG``
        too, i.e. ``-0.023`` is ``-2300``), ``L`` [m], ``U0`` [m/s] or ``rho``.
    U0 : float
        Nominal speed [m/s] about which the surge force is expanded.
    rudder_actuator : bool
        Rudder angle as a state driven by ``delta_cmd``: ``d delta/dt = S(delta_cmd - delta)`` with
        a smooth rate limit of 5 deg/s and the command clipped to +-40 deg (MSS: 1 s lag).

    Returns
    -------
    Model
        States ``u, v, r, x, y, psi`` (+ ``delta``), input ``delta`` (or ``delta_cmd``);
        ``vessel``: ``L_pp``, ``U0``, ``rudder_rate`` (5 deg/s), ``rudder_max`` (40 deg).
    """
    values = dict(MARINER)
    values.update({"L": L_MARINER, "U0": U0, "rho": 1025.0})
    for key, val in (params or {}).items():
        if key not in values:
            raise InputError(f"unknown Mariner parameter {key!r}; known: {sorted(values)}")
        values[key] = float(val)
    b = ModelBuilder("mariner", "Mariner-class cargo ship (Chislett & Strom-Tejsen 1965; MSS mariner.m)")
    P = {}
    for key, val in values.items():
        unit = {"L": "m", "U0": "m/s", "rho": "kg/m^3"}.get(key, "1e-5")
        P[key] = b.param(key, val, unit=unit, source=_SOURCE if unit == "1e-5" else "MSS mariner.m",
                         doc="non-dimensional coefficient x 1e5" if unit == "1e-5" else "")
    states = declare_ship_states(b)
    u, v, r, _x, _y, psi = states
    if rudder_actuator:
        delta = add_rudder_actuator(b, ("delta",), 1.0, np.radians(5.0), np.radians(40.0))["delta"]
    else:
        delta = b.input("delta", unit="rad", doc="rudder angle, positive turns to starboard")
    s = 1e-5
    c = {k: P[k] * s for k in MARINER}
    L, U0s, rho = P["L"], P["U0"], P["rho"]
    U = (u**2 + v**2 + 1e-12) ** 0.5
    up, vp, rp = (u - U0s) / U, v / U, r * L / U
    d = -delta                                     # MSS sign: positive internal rudder -> negative yaw
    tau = b.port("tau", 3)
    qf = 0.5 * rho * L**2 * U**2
    X = (c["Xu"] * up + c["Xuu"] * up**2 + c["Xuuu"] * up**3 + c["Xvv"] * vp**2 + c["Xrr"] * rp**2
         + c["Xrv"] * rp * vp + c["Xdd"] * d**2 + c["Xudd"] * up * d**2 + c["Xvd"] * vp * d
         + c["Xuvd"] * up * vp * d) + tau[0] / qf
    Y = (c["Yv"] * vp + c["Yr"] * rp + c["Yvvv"] * vp**3 + c["Yvvr"] * vp**2 * rp + c["Yvu"] * vp * up
         + c["Yru"] * rp * up + c["Yd"] * d + c["Yddd"] * d**3 + c["Yud"] * up * d + c["Yuud"] * up**2 * d
         + c["Yvdd"] * vp * d**2 + c["Yvvd"] * vp**2 * d + (c["Y0"] + c["Y0u"] * up + c["Y0uu"] * up**2)) \
        + tau[1] / qf
    N = (c["Nv"] * vp + c["Nr"] * rp + c["Nvvv"] * vp**3 + c["Nvvr"] * vp**2 * rp + c["Nvu"] * vp * up
         + c["Nru"] * rp * up + c["Nd"] * d + c["Nddd"] * d**3 + c["Nud"] * up * d + c["Nuud"] * up**2 * d
         + c["Nvdd"] * vp * d**2 + c["Nvvd"] * vp**2 * d + (c["N0"] + c["N0u"] * up + c["N0uu"] * up**2)) \
        + tau[2] / (qf * L)
    m11 = c["m"] - c["Xudot"]
    m22 = c["m"] - c["Yvdot"]
    m23 = c["m"] * c["xG"] - c["Yrdot"]
    m32 = c["m"] * c["xG"] - c["Nvdot"]
    m33 = c["Iz"] - c["Nrdot"]
    det = m22 * m33 - m23 * m32
    du = X * (U**2 / L) / m11
    dv = -(-m33 * Y + m23 * N) * (U**2 / L) / det
    dr = (-m32 * Y + m22 * N) * (U**2 / L**2) / det
    xd, yd, psid = body_to_ned(u, v, r, psi)
    b.ode(u=du + b.noise("w_u", unit="m/s^2"), v=dv + b.noise("w_v", unit="m/s^2"),
          r=dr + b.noise("w_r", unit="rad/s^2"), x=xd, y=yd, psi=psid)
    for name in ("u", "v", "r", "x", "y", "psi"):
        b.output(name, b.sym(name))
    b.vessel = Vessel("Mariner-class cargo ship", L_pp=L_MARINER, U0=U0, rudder_rate=np.radians(5.0),
                      rudder_max=np.radians(40.0), rudders=("delta_cmd",) if rudder_actuator else ("delta",),
                      param_set="mariner/Chislett-Strom-Tejsen-1965", source=_SOURCE)
    declare_ship_limits(b, b.vessel)
    return b.build()
