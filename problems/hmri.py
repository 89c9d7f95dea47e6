"""The HMRI captive model of the KVLCC2 (model T530) and the captive problem the studies share.

Used by :mod:`.kvlcc2_captive` (the captive tests alone) and :mod:`.kvlcc2_marin` (the captive tests
joined with the free-running runs); see :mod:`.kvlcc2_captive` for the rule behind the free set,
the channels and the noise.
"""
from __future__ import annotations


from casship.identify.rig import (CAPTIVE_CHANNELS, CAPTIVE_HULL, CAPTIVE_INTERACTION, CAPTIVE_OWN, captive_free_set,
                                 read_rig)

__all__ = ["FACILITY", "HMRI", "CHANNELS", "HULL", "INTERACTION", "OWN", "FREE", "LEVER", "KINDS", "WATCH", "RHO", "L_HMRI", "MASS",
           "IZ_MIDSHIP", "X_G", "RIG", "hmri_model", "captive_problem", "shared_estimates"]

#: HMRI model T530 (README of kvlcc2_hmri_captive): casship's rig ``hmri-t530``.
RIG = read_rig("hmri-t530")
FACILITY = RIG.facility
#: HMRI model T530 particulars; the rest of the MMG constants published.
HMRI = dict(RIG.particulars)
RHO = HMRI["rho"]                 # kg/m^3, fresh water at 18.6 deg C (README: water temperature)
L_HMRI = HMRI["L_pp"]
MASS = 3123.0                     # kg
IZ_MIDSHIP = 9516.0               # kg m^2, the pure-yaw sheet's yaw inertia (about midship: m (0.253 L)^2 + m x_G^2)
X_G = HMRI["x_G"]                 # LCG 3.50 % L_pp forward of midship
CHANNELS = CAPTIVE_CHANNELS
HULL, INTERACTION, OWN = CAPTIVE_HULL, CAPTIVE_INTERACTION, CAPTIVE_OWN
FREE = HULL + INTERACTION + OWN
#: The rudder-lever structure the captive tests were read for (``rudder_lever="loading"``): its one extra coefficient.
LEVER = ("x_HJ_dash",)
KINDS = ("static_rudder", "static_drift", "drift_rudder", "pure_sway", "pure_yaw", "yaw_drift")
WATCH = ("N_vvr_dash", "m_y_dash", "Y_vvv_dash", "N_rrr_dash", "N_vrr_dash", "x_H_dash", "t_R", "a_H")


def hmri_model(tests, rudder_lever: str = "constant"):
    """The KVLCC2 L7 MMG model with HMRI's particulars, its open-water K_T and its resistance ``R'_0``
    (:meth:`casship.identify.rig.Rig.model`; ``rudder_lever``: as for :func:`casship.models.kvlcc2`)."""
    return RIG.model(tests, "kvlcc2-l7", rudder_lever=rudder_lever)


def captive_problem(tests, model=None):
    """The study's captive problem (the free set, channels and noise rule of :mod:`casship.identify.rig`;
    with a ``rudder_lever="loading"`` model also :data:`LEVER`)."""
    from casship.identify.captive import CaptiveProblem

    model = model or hmri_model(tests)
    return CaptiveProblem(model, tests, captive_free_set(model), facility=FACILITY, channels=CHANNELS)


def shared_estimates(fit) -> dict:
    """The captive estimates that carry to another ship model: hull and interaction (not ``@HMRI``)."""
    return {n: v for n, v in fit.estimates.items() if "@" not in n}
