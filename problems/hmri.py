"""The HMRI captive model of the KVLCC2 (model T530) and the captive problem the studies share.

Used by :mod:`.kvlcc2_captive` (the captive tests alone) and :mod:`.kvlcc2_marin` (the captive tests
joined with the free-running runs); see :mod:`.kvlcc2_captive` for the rule behind the free set,
the channels and the noise.
"""
from __future__ import annotations

import numpy as np

from casship.identify.captive import CaptiveProblem
from casship.models import kvlcc2_l7

__all__ = ["FACILITY", "HMRI", "CHANNELS", "HULL", "INTERACTION", "OWN", "FREE", "LEVER", "KINDS", "WATCH", "RHO", "L_HMRI", "MASS", "IZ_MIDSHIP", "X_G",
           "hmri_model", "captive_problem", "shared_estimates"]

FACILITY = "HMRI"
RHO = 998.5                       # kg/m^3, fresh water at 18.6 deg C (README: water temperature)
L_HMRI = 6.8279
MASS = 3123.0                     # kg
IZ_MIDSHIP = 9516.0               # kg m^2, the pure-yaw sheet's yaw inertia (about midship: m (0.253 L)^2 + m x_G^2)
X_G = 0.035 * L_HMRI              # LCG 3.50 % L_pp forward of midship
#: HMRI model T530 particulars (README of kvlcc2_hmri_captive); the rest of the MMG constants published.
HMRI = {"L_pp": L_HMRI, "B": 1.249, "d": 0.448, "nabla": MASS / RHO, "x_G": X_G, "rho": RHO,
        "k_zz": float(np.sqrt((IZ_MIDSHIP - MASS * X_G**2) / MASS) / L_HMRI), "D_p": 0.2124,
        "A_R": 0.0523, "H_R": 0.345 * L_HMRI / 7.0, "w_P0": 0.428, "t_P": 0.233}
CHANNELS = ("X", "Y", "N", "RY", "T")
HULL = ("X_vv_dash", "X_vr_dash", "X_rr_dash", "X_vvvv_dash", "Y_v_dash", "Y_r_dash", "Y_vvv_dash", "Y_vvr_dash",
        "Y_vrr_dash", "Y_rrr_dash", "N_v_dash", "N_r_dash", "N_vvv_dash", "N_vvr_dash", "N_vrr_dash", "N_rrr_dash",
        "m_x_dash", "m_y_dash", "J_z_dash")
INTERACTION = ("t_R", "a_H", "x_H_dash", "gamma_R_minus", "gamma_R_plus", "l_R_dash", "C_2_plus", "C_2_minus")
OWN = ("t_P", "w_P0", "f_alpha", "delta_0")
FREE = HULL + INTERACTION + OWN
#: The rudder-lever structure the captive tests were read for (``rudder_lever="loading"``): its one extra coefficient.
LEVER = ("x_HJ_dash",)
KINDS = ("static_rudder", "static_drift", "drift_rudder", "pure_sway", "pure_yaw", "yaw_drift")
WATCH = ("N_vvr_dash", "m_y_dash", "Y_vvv_dash", "N_rrr_dash", "N_vrr_dash", "x_H_dash", "t_R", "a_H")


def hmri_model(tests, rudder_lever: str = "constant", **overrides):
    """The KVLCC2 L7 MMG model with HMRI's particulars, its open-water K_T and its resistance ``R'_0``
    (``rudder_lever``: as for :func:`casship.models.kvlcc2`)."""
    ow = tests.open_water
    J = ow["J"]
    k = np.linalg.lstsq(np.vstack([np.ones_like(J), J, J**2]).T, ow["K_T"], rcond=None)[0]
    U0 = 1.1702
    R = float(np.interp(U0, tests.resistance["speed"], tests.resistance["resistance"]))
    values = dict(HMRI, k_0=float(k[0]), k_1=float(k[1]), k_2=float(k[2]),
                  R_0_dash=R / (0.5 * RHO * U0**2 * HMRI["L_pp"] * HMRI["d"]))
    values.update(overrides)
    return kvlcc2_l7(values, asymmetry=True, smooth=True, rudder_lever=rudder_lever)


def captive_problem(tests, model=None):
    """The study's captive problem (the free set, channels and noise rule of the module docstring; with
    a ``rudder_lever="loading"`` model also :data:`LEVER`)."""
    model = model or hmri_model(tests)
    free = list(FREE) + [n for n in LEVER if n in model.param_names]
    return CaptiveProblem(model, tests, free, facility=FACILITY, channels=CHANNELS)


def shared_estimates(fit) -> dict:
    """The captive estimates that carry to another ship model: hull and interaction (not ``@HMRI``)."""
    return {n: v for n, v in fit.estimates.items() if "@" not in n}
