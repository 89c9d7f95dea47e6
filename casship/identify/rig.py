"""A captive-test rig: the facility's model of the ship, and what its tests carry to another ship.

A captive (PMM) test measures the forces on *one* model in *one* tank: its particulars, propeller,
rudder and water are the facility's. :class:`Rig` holds those particulars (as MMG parameter
values), the running speed at which the facility's resistance sets ``R'_0``, and the facility's
name; with the tests of :func:`casship.io.read_captive` it builds the rig's model (its propeller's
``K_T`` from the open-water curve of the folder, ``R'_0`` from its resistance test) and the
:class:`~casship.identify.captive.CaptiveProblem` of the classical route.

The free set is a rule, fixed for every rig (:func:`captive_free_set`): every hull coefficient the
tests are designed to measure, the hull-rudder and hull-propeller interaction, and the facility's
own propeller, rudder and neutral angle. ``R'_0`` (the resistance test), ``K_T`` (the open-water
test), ``epsilon`` and ``kappa`` (``epsilon`` cannot be separated from ``f_alpha`` by these tests),
``C_1`` and ``x'_P`` keep their values. Every measured channel the MMG models is fitted (hull
``X, Y, N``, the rudder's normal force ``RY`` and thrust ``T``), each group's noise level
estimated with the coefficients (concentrated likelihood).

:func:`carried` keeps what carries to another ship of the same hull form: the hull and interaction
estimates (no ``name@facility`` quantity) with their robust covariance, as a
:class:`~casship.identify.belief.ParameterBelief` over the other ship's parameters.

A rig file is JSON::

    {"facility": "HMRI", "nominal_speed_mps": 1.1702,
     "particulars": {"L_pp": 6.8279, "B": 1.249, "d": 0.448, ...},
     "source": "where the numbers come from"}

``particulars`` are parameter values of the ship model (``L_pp, B, d, nabla, x_G, rho, k_zz, D_p,
A_R, H_R, w_P0, t_P``...); the ones not given keep the model's. :data:`RIGS` holds the rigs casship
knows by name (``hmri-t530``); :func:`read_rig` reads either.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping

import numpy as np

from ..errors import InputError

__all__ = ["Rig", "RIGS", "CAPTIVE_HULL", "CAPTIVE_INTERACTION", "CAPTIVE_OWN", "CAPTIVE_CHANNELS", "CAPTIVE_OPTIONS",
           "captive_free_set", "carried", "classical_derivatives", "read_rig", "unpinned_on_ship", "write_carried"]

#: Hull coefficients a PMM series is designed to measure (static drift, pure sway, pure yaw, yaw with drift).
CAPTIVE_HULL = ("X_vv_dash", "X_vr_dash", "X_rr_dash", "X_vvvv_dash", "Y_v_dash", "Y_r_dash", "Y_vvv_dash",
                "Y_vvr_dash", "Y_vrr_dash", "Y_rrr_dash", "N_v_dash", "N_r_dash", "N_vvv_dash", "N_vvr_dash",
                "N_vrr_dash", "N_rrr_dash", "m_x_dash", "m_y_dash", "J_z_dash")
#: Hull-rudder and hull-propeller interaction (static rudder, drift with counter-rudder).
CAPTIVE_INTERACTION = ("t_R", "a_H", "x_H_dash", "gamma_R_minus", "gamma_R_plus", "l_R_dash", "C_2_plus", "C_2_minus")
#: The facility's own propeller, wake, rudder and neutral angle (named ``name@facility`` in a fit).
CAPTIVE_OWN = ("t_P", "w_P0", "f_alpha", "delta_0")
#: Force channels the MMG models: hull X, Y, N, the rudder's normal force on the stock, thrust.
CAPTIVE_CHANNELS = ("X", "Y", "N", "RY", "T")
#: Model options of the rig's model: the neutral angle and smooth sign switches (the static drift
#: and counter-rudder tests cross zero drift and zero rudder inflow, where a hard switch has no slope).
CAPTIVE_OPTIONS = {"asymmetry": True, "smooth": True}


def captive_free_set(model) -> list[str]:
    """The rule's free set for ``model``: :data:`CAPTIVE_HULL`, :data:`CAPTIVE_INTERACTION`,
    :data:`CAPTIVE_OWN` and a loading-dependent rudder lever ``x_HJ_dash`` where the model has them.

    Parameters
    ----------
    model : Model
        The rig's model.

    Returns
    -------
    list of str
    """
    have = set(model.param_names)
    return [n for n in CAPTIVE_HULL + CAPTIVE_INTERACTION + CAPTIVE_OWN + ("x_HJ_dash",) if n in have]


@dataclass(frozen=True)
class Rig:
    """A captive-test facility's ship model: its name, particulars and running speed.

    Parameters
    ----------
    facility : str
        Name of the facility (the suffix of its own quantities: ``w_P0@HMRI``).
    particulars : mapping name -> float
        Parameter values of the model in the tank (length, breadth, draught, displacement, centre of
        gravity, water density, yaw radius of gyration, propeller diameter, rudder, wake, thrust
        deduction); SI units, as the model's parameters.
    nominal_speed : float
        Running speed of the tests [m/s]: ``R'_0`` is the resistance test there.
    source : str
        Where the numbers come from.
    """

    facility: str
    particulars: Mapping[str, float]
    nominal_speed: float
    source: str = ""

    def __post_init__(self):
        if not str(self.facility) or "@" in str(self.facility):
            raise InputError(f"rig: facility must be a name without '@', got {self.facility!r}")
        if not (np.isfinite(self.nominal_speed) and self.nominal_speed > 0):
            raise InputError(f"rig {self.facility}: nominal_speed_mps must be a positive speed, got {self.nominal_speed!r}")
        bad = sorted(k for k, v in self.particulars.items() if not np.isfinite(v))
        if bad:
            raise InputError(f"rig {self.facility}: particulars {bad} are not finite numbers")

    def values(self, tests) -> dict:
        """The rig model's parameter values: :attr:`particulars`, the propeller's ``K_T = k_0 + k_1 J
        + k_2 J^2`` (least squares on the folder's open-water curve) and ``R'_0 = R / (rho/2 U^2 L d)``
        at :attr:`nominal_speed` (the folder's resistance test, interpolated).

        Parameters
        ----------
        tests : CaptiveTests
            The rig's tests (:func:`casship.io.read_captive`) with ``open_water`` and ``resistance``.

        Returns
        -------
        dict

        Raises
        ------
        InputError
            When the tests lack the open-water or resistance table, or the nominal speed lies
            outside the resistance test's speeds.
        """
        where = f"rig {self.facility}"
        if tests.open_water is None or tests.resistance is None:
            missing = [n for n, v in (("open_water.csv", tests.open_water), ("resistance.csv", tests.resistance))
                       if v is None]
            raise InputError(f"{where}: the captive folder {tests.source} lacks {missing} (the propeller curve and "
                             "the resistance of the rig's model)")
        J = np.asarray(tests.open_water["J"], float)
        k = np.linalg.lstsq(np.vstack([np.ones_like(J), J, J**2]).T, np.asarray(tests.open_water["K_T"], float),
                            rcond=None)[0]
        speed = np.asarray(tests.resistance["speed"], float)
        U0 = float(self.nominal_speed)
        if not speed.min() <= U0 <= speed.max():
            raise InputError(f"{where}: nominal_speed_mps {U0} lies outside the resistance test's speeds "
                             f"{speed.min():g}..{speed.max():g} m/s")
        R = float(np.interp(U0, speed, tests.resistance["resistance"]))
        p = dict(self.particulars)
        for name in ("rho", "L_pp", "d"):
            if name not in p:
                raise InputError(f"{where}: particulars lack {name!r} (needed for R'_0)")
        return {**p, "k_0": float(k[0]), "k_1": float(k[1]), "k_2": float(k[2]),
                "R_0_dash": R / (0.5 * p["rho"] * U0**2 * p["L_pp"] * p["d"])}

    def model(self, tests, name: str = "kvlcc2", **options):
        """The ship model ``name`` with this rig's values (:meth:`values`) and :data:`CAPTIVE_OPTIONS`.

        Parameters
        ----------
        tests : CaptiveTests
        name : str
            A registered MMG model whose factory takes ``params`` and the options (``kvlcc2``,
            ``kvlcc2-l7``).
        **options
            More factory options (``rudder_lever="loading"``).

        Raises
        ------
        InputError
            When the model lacks a particular of the rig, or its factory lacks the captive options.
        """
        from ..models import get_model

        values = self.values(tests)
        try:
            model = get_model(name, params=values, **CAPTIVE_OPTIONS, **options)
        except TypeError as exc:
            raise InputError(f"rig {self.facility}: model {name!r} cannot be a captive rig's model (its factory "
                             f"takes no params= and {sorted(CAPTIVE_OPTIONS)}: {exc}); use an MMG model such as "
                             "kvlcc2") from None
        except InputError as exc:
            raise InputError(f"rig {self.facility}: {exc}") from None
        unknown = sorted(set(values) - set(model.param_names))
        if unknown:
            raise InputError(f"rig {self.facility}: particulars {unknown} are not parameters of {name!r}")
        return model

    def problem(self, tests, name: str = "kvlcc2", *, free=None, prior=None, **options):
        """The captive problem of the classical route on this rig.

        Parameters
        ----------
        tests : CaptiveTests
        name : str
            Model name (see :meth:`model`).
        free : sequence of str, optional
            Default: :func:`captive_free_set` of the model.
        prior : Prior or mapping, optional
            As for :class:`~casship.identify.captive.CaptiveProblem` (the rule uses none).
        **options
            Model options (see :meth:`model`).

        Returns
        -------
        CaptiveProblem
            All of :data:`CAPTIVE_CHANNELS`, facility :attr:`facility`.
        """
        from .captive import CaptiveProblem

        model = self.model(tests, name, **options)
        return CaptiveProblem(model, tests, list(free) if free is not None else captive_free_set(model),
                              prior=prior, facility=self.facility, channels=CAPTIVE_CHANNELS)

    def to_dict(self) -> dict:
        """The rig as the JSON object :func:`read_rig` reads."""
        return {"facility": self.facility, "nominal_speed_mps": float(self.nominal_speed),
                "particulars": {k: float(v) for k, v in self.particulars.items()}, "source": self.source}


def _hmri_t530() -> Rig:
    # HMRI model T530 (README of the HMRI captive folder, test specification "KVLCC2 PMM deep, ver 1 - 2012").
    rho, L, mass = 998.5, 6.8279, 3123.0              # fresh water at 18.6 deg C; kg
    iz_midship, x_g = 9516.0, 0.035 * L               # pure-yaw sheet's yaw inertia about midship; LCG 3.5 % L fwd
    return Rig("HMRI", {"L_pp": L, "B": 1.249, "d": 0.448, "nabla": mass / rho, "x_G": x_g, "rho": rho,
                        "k_zz": float(np.sqrt((iz_midship - mass * x_g**2) / mass) / L), "D_p": 0.2124,
                        "A_R": 0.0523, "H_R": 0.345 * L / 7.0, "w_P0": 0.428, "t_P": 0.233},
               nominal_speed=1.1702,
               source="HMRI KVLCC2 model T530, scale 1:46.426 (SIMMAN 2012 PMM specification): L_pp, B, T, mass "
                      "3123 kg in water at 18.6 deg C, LCG 3.50 % L_pp forward, k_zz from the yaw inertia 9516 kg m^2 "
                      "about midship, propeller HP801 (D 0.2124 m), movable rudder area 0.0523 m^2 (span scaled from "
                      "the L7), wake 0.428 and thrust deduction 0.233 of the resistance sheet; U0 1.1702 m/s")


#: Rigs casship knows by name.
RIGS = {"hmri-t530": _hmri_t530}


def read_rig(source) -> Rig:
    """A rig by name (:data:`RIGS`) or from a JSON file (see the module text).

    Parameters
    ----------
    source : str, Path or Rig
        A known rig's name, a rig file, or a rig (returned as it is).

    Returns
    -------
    Rig

    Raises
    ------
    InputError
        An unknown name, a missing file, bad JSON, or a missing or wrong entry (named).
    """
    if isinstance(source, Rig):
        return source
    text = str(source)
    if text in RIGS:
        return RIGS[text]()
    path = Path(text)
    if not path.is_file():
        raise InputError(f"rig {text!r}: neither a known rig {sorted(RIGS)} nor a file")
    try:
        obj = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise InputError(f"rig file {path}: not JSON ({exc})") from None
    if not isinstance(obj, dict):
        raise InputError(f"rig file {path}: expected a JSON object")
    unknown = sorted(set(obj) - {"facility", "nominal_speed_mps", "particulars", "source"})
    if unknown:
        raise InputError(f"rig file {path}: unknown entries {unknown} (facility, nominal_speed_mps, particulars, "
                         "source)")
    for key in ("facility", "nominal_speed_mps", "particulars"):
        if key not in obj:
            raise InputError(f"rig file {path}: missing {key!r}")
    parts = obj["particulars"]
    if not isinstance(parts, dict) or not parts:
        raise InputError(f"rig file {path}: particulars must be an object of name: value")
    bad = sorted(k for k, v in parts.items() if not isinstance(v, (int, float)) or isinstance(v, bool))
    if bad:
        raise InputError(f"rig file {path}: particulars {bad} are not numbers")
    speed = obj["nominal_speed_mps"]
    if not isinstance(speed, (int, float)) or isinstance(speed, bool):
        raise InputError(f"rig file {path}: nominal_speed_mps must be a number, got {speed!r}")
    return Rig(str(obj["facility"]), {k: float(v) for k, v in parts.items()}, float(speed),
               str(obj.get("source", "")))


def carried(fit, model):
    """The captive estimates that carry to ``model`` (another ship of the hull form) and their belief.

    The belief is what a record of the ship is replayed with, by the facility rule of the ship
    workflow (:mod:`casship.identify.workflow`): the hull and interaction estimates with their robust
    covariance; every facility quantity (the neutral angle, the rudder's own quantities, the rig's
    own propeller, wake and rudder, :data:`CAPTIVE_OWN`) at the ship's preset, the population value
    of a facility without a value of its own, with ``sqrt(prior^2 + spread^2)`` (its stated
    uncertainty both, :func:`~.shipfit.pool_facilities` with no facility); and the port/starboard
    terms at the preset with their prior standard deviation (no mirrored evidence). None of these is
    carried as exact from one facility to another.

    Parameters
    ----------
    fit : FitResult
        A captive fit (:meth:`CaptiveProblem.solve`).
    model : Model
        The ship they are carried to.

    Returns
    -------
    values : dict
        The hull and interaction estimates (no ``name@facility`` quantity) that are parameters of
        ``model``.
    belief : ParameterBelief
        Their robust covariance from the captive fit (``kind="robust"``), extended by the facility
        quantities and port/starboard terms of ``model`` at its preset values (independent).
    """
    from .belief import ParameterBelief

    belief = fit.uncertainty("robust")
    have = set(model.param_names)
    keep = [i for i, n in enumerate(belief.names) if n in have]     # a name@facility is no parameter of the ship
    names = [belief.names[i] for i in keep]
    values = {n: float(fit.estimates[n]) for n in names}
    facility = ", ".join(r.split(":", 1)[-1] for r in fit.records)
    hull = ParameterBelief.from_values(names, [values[n] for n in names], belief.cov[np.ix_(keep, keep)],
                                       f"captive-only fit of the {facility} captive tests (robust covariance)",
                                       kind="robust")
    beside = unpinned_on_ship(model, exclude=names)
    if not beside:
        return values, hull
    return values, hull.extended(beside, model.param_dict(),
                                 source=f"{hull.source}; {', '.join(beside)} at the preset with the facility rule's "
                                        "spread (population value of a new facility, or the prior of a "
                                        "port/starboard term)")


def unpinned_on_ship(model, exclude=()) -> dict:
    """Standard deviation of each quantity no captive test pins on a ship: a record of the ship is
    replayed with these at the preset values.

    Facility quantities (:data:`casship.identify.workflow.FACILITY`, ``RUDDER`` and
    :data:`CAPTIVE_OWN`) get ``sqrt(prior^2 + spread^2)``, the population value's uncertainty of a
    facility with no value of its own (prior and between-facility spread: the stated uncertainty,
    ``NEUTRAL_SPREAD`` for the neutral angle); port/starboard terms (``ASYMMETRY``) their prior.

    Parameters
    ----------
    model : Model
        The ship.
    exclude : sequence of str
        Names already covered (the carried estimates).

    Returns
    -------
    dict
        Name -> standard deviation, for the names ``model`` has.
    """
    from .shipfit import pool_facilities
    from .workflow import ASYMMETRY, FACILITY, NEUTRAL_SPREAD, RUDDER, preset_prior_std

    have, skip = set(model.param_names), set(exclude)
    facility = [n for n in dict.fromkeys((*FACILITY, *RUDDER, *CAPTIVE_OWN)) if n in have and n not in skip]
    ports = [n for n in ASYMMETRY if n in have and n not in skip]
    prior = preset_prior_std(model, facility + ports)
    out = {n: pool_facilities({}, spread=NEUTRAL_SPREAD if n in FACILITY else prior[n],
                              prior_std=prior[n])["new_facility_std"] for n in facility}
    out.update({n: prior[n] for n in ports})
    return out


def write_carried(path, model, values, belief, *, noise=None, method: str = "captive-only (captive tests), Gaussian ML",
                  extra=None):
    """The carried estimates (:func:`carried`) as a fit file of ``model``.

    Their robust covariance stands as the fit's, so that replays and trial design read the file as
    they read a fit (:func:`casship.identify.write_params_file`); ``noise`` is the free-running
    channels' noise where known (captive tests do not measure it).

    Parameters
    ----------
    path : str or Path
    model : Model
        The ship the values are carried to.
    values : mapping name -> float
    belief : ParameterBelief
        Their covariance (:func:`carried`).
    noise : mapping, optional
        The free-running channels' noise (a fit's ``noise`` block).
    method : str
        How the values were estimated (the file's ``method``).
    extra : mapping, optional
        More top-level entries.

    Returns
    -------
    Path
    """
    from .params_file import write_params_file

    names = list(values)         # the estimated ones; the belief may also hold quantities at the preset
    idx = [list(belief.names).index(n) for n in names]
    cov = np.asarray(belief.cov, float)[np.ix_(idx, idx)]
    sd = np.sqrt(np.diag(cov))
    fit = {"free": names, "estimates": dict(values), "std_errors": dict(zip(names, sd.tolist())),
           "std_errors_robust": dict(zip(names, sd.tolist())), "covariance": cov.tolist(),
           "covariance_robust": cov.tolist(), "correlation": (cov / np.outer(sd, sd)).tolist(), "method": method}
    if noise is not None:
        fit["noise"] = noise
    return write_params_file(path, model, values, belief, {**fit, "candidate": "captive-only", **(extra or {})})


def classical_derivatives(problem) -> dict:
    """The classical linear derivatives of a captive problem's tests (the naval architect's first check).

    :func:`~casship.identify.captive.linear_derivatives` on the rig's particulars as the problem's model
    holds them: length ``L_pp``, draught ``d``, mass ``rho nabla``, ``x_G`` and the yaw inertia about
    midship ``m ((k_zz L)^2 + x_G^2)``.

    Parameters
    ----------
    problem : CaptiveProblem
        The captive tests on their rig's model (:meth:`Rig.problem`).

    Returns
    -------
    dict
        As :func:`~casship.identify.captive.linear_derivatives` (``Y_v_dash``, ``N_v_dash``,
        ``N_r_dash``, ``m_y_dash``, ``J_z_dash``...).
    """
    from .captive import linear_derivatives

    p = problem.model.param_dict(problem.base)
    L, mass = p["L_pp"], p["rho"] * p["nabla"]
    return linear_derivatives(problem.tests, L=L, T=p["d"], mass=mass, rho=p["rho"], x_G=p["x_G"],
                              I_z=mass * ((p["k_zz"] * L) ** 2 + p["x_G"] ** 2))
