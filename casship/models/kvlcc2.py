"""KVLCC2 tanker presets for the MMG standard method (Yasukawa & Yoshimura 2015).

Every constant carries its source (short names as in the project's reference table):

* YY2015 — Yasukawa & Yoshimura (2015), J Mar Sci Technol 20:37-52, doi:10.1007/s00773-014-0293-y,
  as typed identically in ShipMMG/shipmmg ``tests/test_mmg_3dof.py`` (SM-py), ShipMMG.jl (SM-jl),
  Mesratya/BE_MAN ``ship_params.py`` (BEMAN), wjchoi91/BalancedPathFollowing ``ZigzagTest.m`` (WJC),
  nikpau/mmgdynamics ``calibrated_vessels.py`` (MMGD).
* S2020 — SIMMAN 2020 KVLCC2 case 1.2 test conditions (Fn 0.142, rudder rate 2.32 deg/s full scale).
* MLA — martinlarsalbert/System-identification-of-Vessel-Manoeuvring-Models ``ship_data.yml``.

Choices where the sources disagree (each is a parameter, so it can be changed or identified):

* ``x_G`` full scale: 11.2 m (WJC, MMGD) rather than 11.1 m (BEMAN, XDYN).
* ``w_P0``: 0.40 at model scale (SM-py, SM-jl, MLA, MMGD-L7); 0.35 at full scale (BEMAN, WJC, MMGD).
* ``x_P_dash``: -0.48 (BEMAN, WJC, MLA -3.386/7) rather than -0.690 (SM-py, SM-jl).
* ``k_2``: -0.1385 (SM-py, SM-jl; BEMAN/WJC -0.139 rounded) rather than -0.1359 (MMGD).
* ``k_zz``: 0.25 L (all implementations) rather than 0.24 L in air (S2020).
* ``rho``: 1025 kg/m^3 at both scales (implementations), although model basins use fresh water.
* Rudder rate: 2.32 deg/s full scale (S2020), Froude-scaled 2.32 * sqrt(45.7) = 15.68 deg/s model.
* Model-scale propeller rate: not agreed (17.95 rps SM-py, 13.4 rps MMGD); the presets store no
  fixed ``n0`` at model scale — solve it for the wanted speed with
  :func:`casship.maneuvers.propeller_rate_for_speed`.

The non-dimensional hull coefficients are model-scale values; using them at full scale (as all the
implementations above do) ignores scale effects on resistance and wake.
"""
from __future__ import annotations

import inspect
import math
from typing import Mapping

import numpy as np

from ..model import Model
from ..vessel import Vessel
from .mmg import MMG_ASYMMETRY_PARAMS, MMG_PARAMS, MMG_RUDDER_LEVER_PARAMS, MMG_RUDDER_LIFT_PARAMS, mmg_standard
from ..errors import InputError

__all__ = ["kvlcc2", "kvlcc2_l7", "KVLCC2_COMMON", "KVLCC2_FULL", "KVLCC2_L7", "KVLCC2_SOURCES"]

_ALL = "YY2015 (SM-py, SM-jl, BEMAN, WJC, MMGD identical)"

#: Non-dimensional coefficients shared by both scales, with their sources.
KVLCC2_COMMON: dict[str, float] = {
    "k_zz": 0.25,
    "m_x_dash": 0.022, "m_y_dash": 0.223, "J_z_dash": 0.011,
    "R_0_dash": 0.022, "X_vv_dash": -0.040, "X_vr_dash": 0.002, "X_rr_dash": 0.011, "X_vvvv_dash": 0.771,
    "Y_v_dash": -0.315, "Y_r_dash": 0.083, "Y_vvv_dash": -1.607, "Y_vvr_dash": 0.379,
    "Y_vrr_dash": -0.391, "Y_rrr_dash": 0.008,
    "N_v_dash": -0.137, "N_r_dash": -0.049, "N_vvv_dash": -0.030, "N_vvr_dash": -0.294,
    "N_vrr_dash": 0.055, "N_rrr_dash": -0.013,
    "t_P": 0.220, "x_P_dash": -0.48, "k_0": 0.2931, "k_1": -0.2753, "k_2": -0.1385,
    "C_1": 2.0, "C_2_plus": 1.6, "C_2_minus": 1.1,
    "t_R": 0.387, "a_H": 0.312, "x_H_dash": -0.464, "x_R_dash": -0.5,
    "gamma_R_minus": 0.395, "gamma_R_plus": 0.640, "l_R_dash": -0.710,
    "epsilon": 1.09, "kappa": 0.50, "f_alpha": 2.747,
    "rho": 1025.0,
}

#: Full-scale (L_pp = 320 m) particulars.
KVLCC2_FULL: dict[str, float] = {
    "L_pp": 320.0, "B": 58.0, "d": 20.8, "nabla": 312600.0, "x_G": 11.2,
    "D_p": 9.86, "H_R": 15.80, "A_R": 112.5, "w_P0": 0.35,
}

#: Model-scale (L7, 1/45.7) particulars.
KVLCC2_L7: dict[str, float] = {
    "L_pp": 7.00, "B": 1.27, "d": 0.46, "nabla": 3.27, "x_G": 0.25,
    "D_p": 0.216, "H_R": 0.345, "A_R": 0.0539, "w_P0": 0.40,
}

#: Source of every constant (parameter name -> source).
KVLCC2_SOURCES: dict[str, str] = {name: _ALL for name in KVLCC2_COMMON}
KVLCC2_SOURCES.update({
    "k_zz": "0.25 L used by SM-py, WJC, TUDRL (S2020: 0.24 L in air)",
    "x_P_dash": "BEMAN, WJC, MLA (-3.386 m / 7 m); SM-py/SM-jl use -0.690",
    "k_0": "SM-py, SM-jl (BEMAN/WJC 0.293)", "k_1": "SM-py, SM-jl (BEMAN/WJC -0.275)",
    "k_2": "SM-py, SM-jl (BEMAN/WJC -0.139); MMGD -0.1359",
    "C_1": "WJC, MMGD, MLA", "C_2_plus": "WJC, MMGD, MLA", "C_2_minus": "WJC, MMGD, MLA",
    "x_R_dash": "SM-py, BEMAN, MLA (x_r = -3.5 m of 7 m)",
    "rho": "implementations (SM-py, BEMAN); S2020/MLA model basin 1000",
    "L_pp": "all sources", "B": "all sources", "d": "all sources",
    "nabla": "WJC, MMGD, TUDRL (full 312600); SM-py (L7 3.27)",
    "x_G": "full: WJC, MMGD 11.2 (BEMAN/XDYN 11.1); L7: SM-py 0.25 (MLA 0.2436)",
    "D_p": "WJC, MMGD, BEMAN (full); SM-py (L7; MLA 0.204 for the MARIN propeller)",
    "H_R": "BEMAN, WJC; SM-py, MLA", "A_R": "BEMAN, WJC, MMGD; SM-py, MLA",
    "w_P0": "full 0.35: BEMAN, WJC, MMGD; L7 0.40: SM-py, SM-jl, MLA",
})

#: Approach speeds and propeller rates.
U0_FULL = 15.5 * 1852.0 / 3600.0        # 15.5 kn = 7.974 m/s (S2020, WJC 7.9732)
N0_FULL = 1.53                           # rps (BEMAN, WJC; MARIN runs 91.5-91.8 rpm)
U0_L7 = 1.18                             # m/s, Fn 0.142 (S2020)
SCALE_L7 = 45.7                          # MLA scale_factor; S2020 45.714
RUDDER_RATE_FULL = math.radians(2.32)    # rad/s (S2020)


def _variant(param_set: str, asymmetry: bool, smooth: bool, rudder_inflow: str = "published",
             rudder_lift: str = "sine", rudder_lever: str = "constant") -> str:
    """Parameter-set identity of a model variant (the extended variants carry other parameters)."""
    return (param_set + ("+asymmetry" if asymmetry else "") + ("+smooth" if smooth else "")
            + ("" if rudder_inflow == "published" else f"+{rudder_inflow}")
            + ("" if rudder_lift == "sine" else f"+{rudder_lift}-lift")
            + ("" if rudder_lever == "constant" else f"+{rudder_lever}-lever"))


def _options(factory, given: Mapping) -> dict:
    """The build options of a preset that differ from its defaults (recorded in ``model.meta``)."""
    defaults = {k: v.default for k, v in inspect.signature(factory).parameters.items()
                if v.kind is inspect.Parameter.KEYWORD_ONLY}
    return {k: v for k, v in given.items() if v != defaults[k]}


def _build(particulars: Mapping[str, float], overrides: Mapping[str, float] | None, name: str, doc: str,
           vessel: Vessel, *, asymmetry: bool, smooth: bool, rudder_inflow: str, rudder_lift: str,
           rudder_lever: str, options: Mapping, **actuator) -> Model:
    values = dict(KVLCC2_COMMON)
    values.update(particulars)
    known = {**MMG_PARAMS, **(MMG_ASYMMETRY_PARAMS if asymmetry else {}),
             **(MMG_RUDDER_LIFT_PARAMS if rudder_lift == "cubic" else {}),
             **(MMG_RUDDER_LEVER_PARAMS if rudder_lever == "loading" else {})}
    for key, val in (overrides or {}).items():
        if key not in known:
            hint = (" (an asymmetry term: build with asymmetry=True)" if key in MMG_ASYMMETRY_PARAMS else
                    " (build with rudder_lift='cubic')" if key in MMG_RUDDER_LIFT_PARAMS else
                    " (build with rudder_lever='loading')" if key in MMG_RUDDER_LEVER_PARAMS else "")
            raise InputError(f"unknown KVLCC2 parameter {key!r}{hint}; known: {list(known)}")
        values[key] = float(val)
    vessel = vessel.replace(param_set=_variant(vessel.param_set, asymmetry, smooth, rudder_inflow, rudder_lift,
                                               rudder_lever))
    return mmg_standard(values, name=name, doc=doc, sources=KVLCC2_SOURCES, vessel=vessel, asymmetry=asymmetry,
                        smooth=smooth, rudder_inflow=rudder_inflow, rudder_lift=rudder_lift, rudder_lever=rudder_lever,
                        meta={"options": dict(options)}, **actuator)


def kvlcc2(params: Mapping[str, float] | None = None, *, rudder_actuator: bool = False,
           rudder_time_constant: float = 1.0, rudder_rate_max: float = RUDDER_RATE_FULL,
           rudder_max: float | None = None, asymmetry: bool = False, smooth: bool = False,
           rudder_inflow: str = "published", rudder_lift: str = "sine",
           rudder_lever: str = "constant") -> Model:
    """KVLCC2 at full scale (L_pp = 320 m), MMG standard method.

    Parameters
    ----------
    params : mapping, optional
        Overrides of the nominal parameter values (names as in :data:`casship.models.mmg.MMG_PARAMS`,
        and :data:`~casship.models.mmg.MMG_ASYMMETRY_PARAMS` with ``asymmetry``).
    rudder_actuator : bool
        Add the rudder angle as a state driven by ``delta_cmd`` (first order with a smooth rate
        limit, 2.32 deg/s by default).
    rudder_time_constant, rudder_rate_max, rudder_max
        Actuator settings [s, rad/s, rad].
    asymmetry : bool
        Extended variant with a rudder neutral angle and a propeller-induced side force and yaw
        moment (``delta_0``, ``Y_0_dash``, ``N_0_dash``, zero by default: the published model).
    smooth : bool
        Smooth the sign switches of the wake and flow-straightening terms (for identification; see
        :func:`casship.models.mmg.mmg_standard`).
    rudder_inflow : str
        ``"published"`` or ``"race-additive"``: how the propeller race enters the rudder inflow
        (see :func:`casship.models.mmg.mmg_standard`).
    rudder_lift : str
        ``"sine"`` (published) or ``"cubic"``: the rudder normal force loses lift slope at large
        effective angle, ``sin(alpha_R) - c_alpha3 sin(alpha_R)^3`` (parameter ``c_alpha3``, 0 by
        default: the published force; see :func:`casship.models.mmg.mmg_standard`).
    rudder_lever : str
        ``"constant"`` (published) or ``"loading"``: the point of the hull's share of the rudder force
        moves with the propeller advance ratio, ``x'_H + x'_HJ J_P`` (parameter ``x_HJ_dash``, 0 by
        default: the published lever; see :func:`casship.models.mmg.mmg_standard`).

    Returns
    -------
    Model
        States ``u, v, r, x, y, psi`` (+ ``delta``), inputs ``delta`` (or ``delta_cmd``) and ``n``;
        ``vessel`` holds the particulars, the approach speed ``U0`` (15.5 kn) and rate ``n0``
        (1.53 rps), the rudder limits, the wind geometry and the parameter set
        (``kvlcc2/YY2015-full-scale``, with ``+asymmetry`` / ``+smooth`` / ... for the variants);
        ``meta["options"]`` records the build options that differ from the defaults (so that
        ``get_model("kvlcc2", **model.meta["options"])`` rebuilds the variant).

    Examples
    --------
    >>> from casship.models import kvlcc2
    >>> ship = kvlcc2()
    >>> ship.vessel.L_pp
    320.0
    """
    vessel = Vessel("KVLCC2", L_pp=320.0, B=58.0, draught=20.8, mass=1025.0 * KVLCC2_FULL["nabla"], scale=1.0,
                    U0=U0_FULL, n0=N0_FULL, rudder_max=math.radians(35.0), rudder_rate=RUDDER_RATE_FULL,
                    propeller_range=(0.0, 2.0 * N0_FULL), param_set="kvlcc2/YY2015-full-scale",
                    source="Yasukawa & Yoshimura (2015); SIMMAN 2020 test conditions", wind={"A_F": 1624.0, "A_L": 4910.0, "L_OA": 325.0, "B": 58.0, "A_OD": 750.0, "H_BR": 45.0,
                     "H_C": 10.0, "C": 0.0,
                     "source": "A_F (A_T), A_L, A_OD (A_SS) and C (centroid 160 m from the bow, about midship) "
                               "from BEMAN; L_OA, H_BR and H_C are estimates (not published)"})
    return _build(KVLCC2_FULL, params, "kvlcc2", "KVLCC2 full scale, MMG standard method (Yasukawa & "
                  "Yoshimura 2015)", vessel, rudder_actuator=rudder_actuator,
                  rudder_time_constant=rudder_time_constant, rudder_rate_max=rudder_rate_max, rudder_max=rudder_max,
                  asymmetry=asymmetry, smooth=smooth, rudder_inflow=rudder_inflow, rudder_lift=rudder_lift,
                  rudder_lever=rudder_lever, options=_options(kvlcc2, dict(
                      rudder_actuator=rudder_actuator, rudder_time_constant=rudder_time_constant,
                      rudder_rate_max=rudder_rate_max, rudder_max=rudder_max, asymmetry=asymmetry, smooth=smooth,
                      rudder_inflow=rudder_inflow, rudder_lift=rudder_lift, rudder_lever=rudder_lever)))


def kvlcc2_l7(params: Mapping[str, float] | None = None, *, rudder_actuator: bool = False,
              rudder_time_constant: float = 0.1, rudder_rate_max: float = RUDDER_RATE_FULL * np.sqrt(SCALE_L7),
              rudder_max: float | None = None, asymmetry: bool = False, smooth: bool = False,
              rudder_inflow: str = "published", rudder_lift: str = "sine",
           rudder_lever: str = "constant") -> Model:
    """KVLCC2 model L7 (L_pp = 7 m, scale 1/45.7), MMG standard method.

    ``vessel.U0`` is 1.18 m/s (Fn 0.142, S2020); ``vessel.n0`` is not given (sources disagree); the
    valid propeller range is the Froude-scaled full-scale one.

    Parameters
    ----------
    params : mapping, optional
        Overrides of the nominal parameter values (as in :func:`kvlcc2`).
    rudder_actuator : bool
        Add the rudder angle as a state driven by ``delta_cmd``.
    rudder_time_constant, rudder_rate_max, rudder_max : float
        Actuator settings [s, rad/s, rad]; the default rate is the Froude-scaled 15.68 deg/s.
    asymmetry, smooth : bool
        The extended variant and the smooth sign switches (as in :func:`kvlcc2`).
    rudder_inflow, rudder_lift, rudder_lever : str
        Form of the rudder inflow, the rudder lift and the rudder lever (as in :func:`kvlcc2`).

    Returns
    -------
    Model
    """
    n_full_scaled = N0_FULL * np.sqrt(SCALE_L7)
    vessel = Vessel("KVLCC2 model L7", L_pp=7.0, B=1.27, draught=0.46, mass=1025.0 * KVLCC2_L7["nabla"],
                    scale=SCALE_L7, U0=U0_L7, rudder_max=math.radians(35.0),
                    rudder_rate=RUDDER_RATE_FULL * np.sqrt(SCALE_L7), propeller_range=(0.0, 2.0 * n_full_scaled),
                    param_set="kvlcc2/YY2015-L7", source="Yasukawa & Yoshimura (2015); SIMMAN 2020 test conditions")
    return _build(KVLCC2_L7, params, "kvlcc2-l7", "KVLCC2 model L7 (1/45.7), MMG standard method "
                  "(Yasukawa & Yoshimura 2015)", vessel, rudder_actuator=rudder_actuator,
                  rudder_time_constant=rudder_time_constant, rudder_rate_max=rudder_rate_max, rudder_max=rudder_max,
                  asymmetry=asymmetry, smooth=smooth, rudder_inflow=rudder_inflow, rudder_lift=rudder_lift,
                  rudder_lever=rudder_lever, options=_options(kvlcc2_l7, dict(
                      rudder_actuator=rudder_actuator, rudder_time_constant=rudder_time_constant,
                      rudder_rate_max=rudder_rate_max, rudder_max=rudder_max, asymmetry=asymmetry, smooth=smooth,
                      rudder_inflow=rudder_inflow, rudder_lift=rudder_lift, rudder_lever=rudder_lever)))
