"""The autopilot's defaults, in one place, derived from the ship (used by the Python API and the CLI).

Every setting of :func:`casship.autopilot.design_autopilot` and of its closed loop has a rule in
:data:`RULES` (shown by ``casship autopilot --help`` and in ``docs/autopilots.md``);
:func:`derive_settings` applies them to a ship: its :class:`~casship.vessel.Vessel` (speed ``U0``,
length ``L_pp``, ``rudder_max``, ``rudder_rate``), the time constants of its exact linearisation
and the sensor noise. A value given by the caller replaces the rule; the resolved values and where
each came from are in :class:`AutopilotSettings`.

The bandwidth accounts for the steering gear: the closed-loop natural frequency ``wn`` starts at
the ship's own ``U/L`` and is lowered (in steps of 2^(1/4)) until the loop on the linearised ship,
with the servo and the sensor delay, has a phase margin of 45 deg and an upper gain margin of
6 dB; the reference model's ``wn_ref`` starts at ``wn`` and is lowered until the standard course
change (20 deg) asks the linear loop for at most half the steering limit and half the rate limit,
so that the rate limit is left for disturbances and noise.
"""
from __future__ import annotations

import warnings
from types import SimpleNamespace
from dataclasses import asdict, dataclass, field, fields
from typing import Mapping

import numpy as np

from .analysis import course_change_demand, loop_systems, margins
from .designs import lqr_design, pid_pole_placement
from .estimation import linear_estimator, observer_damping, settings_wave, tune_course_q, tune_heading_q
from .law import Actuator
from .nomoto import Nomoto
from .plants import SteeringPlant, steering_feedforward, twin_propeller_yaw_limit
from .reference import ReferenceModel
from ..errors import InputError

__all__ = ["AutopilotSettings", "RULES", "derive_settings", "STANDARD_CHANGE_DEG", "WaveBudgetWarning"]


class WaveBudgetWarning(UserWarning):
    """No bandwidth keeps the steering noise of the design's sea state within the budget."""

#: The standard course change the bandwidth is chosen for [deg] (and back: scenario ``course-20``).
STANDARD_CHANGE_DEG = 20.0
_PM_MIN, _GM_MIN, _DEMAND, _OVERSHOOT = 45.0, 6.0, 0.5, 5.0
_NOISE_RATE, _NOISE_STEER = 0.5, 0.05       # steering-noise budget: rate_max * T / 2 and steer_max / 20
_SEARCH_STEPS = 17                           # wn and wn_ref searched down to 1/16 of their start
_SOLAS_RATE = np.radians(35.0 + 30.0) / 28.0      # SOLAS II-1/29.3.2: 35 deg one side to 30 deg other in 28 s


@dataclass(frozen=True)
class AutopilotSettings:
    """Resolved settings of an autopilot design and its closed loop (SI units, radians).

    Parameters
    ----------
    speed, method, mode, rate, wn, zeta, integral, wn_ref, zeta_ref, r_max, steer_max, steer_rate_max, actuator_T, filter_T, dt, delay, gnss_rate, gnss_std, compass_rate, compass_std, gyro_std, ekf_alpha, ekf_q, observer_q, segment, feedforward, turn_rate_top, lqr_weights, wave_w0, wave_std, wave_filter
        The settings, each with its unit and rule in :data:`RULES`.
    sources : dict
        Name -> ``"given"`` or the rule that produced the value.
    steering : SteeringFeedforward, optional
        The steady-steering table of the ship (:func:`~casship.autopilot.plants.steering_feedforward`).
    """

    speed: float
    method: str
    mode: str
    rate: str
    wn: float
    zeta: float
    integral: str | None
    wn_ref: float
    zeta_ref: float
    r_max: float
    steer_max: float
    steer_rate_max: float
    actuator_T: float
    filter_T: float
    dt: float
    delay: float
    gnss_rate: float
    gnss_std: float
    compass_rate: float
    compass_std: float
    gyro_std: float
    ekf_alpha: tuple
    ekf_q: tuple
    observer_q: tuple
    segment: float
    feedforward: str = "nonlinear"
    wave_w0: float = 0.0
    wave_std: float = 0.0
    wave_filter: bool = False
    turn_rate_top: float = float("nan")
    lqr_weights: dict = field(default_factory=dict)
    sources: dict = field(default_factory=dict, compare=False)
    steering: object = field(default=None, compare=False, repr=False)

    def as_dict(self) -> dict:
        """Values (tuples as lists), without the sources and the steering table."""
        out = asdict(self)
        out.pop("sources")
        out.pop("steering")
        return {k: list(v) if isinstance(v, tuple) else v for k, v in out.items()}


#: name -> (unit, rule). The rule is what ``--help`` and the docs show.
RULES: dict[str, tuple[str, str]] = {
    "speed": ("m/s", "the vessel's approach speed vessel.U0"),
    "method": ("", "'pid' (Fossen's pole placement); 'lqr' (integral LQR, control.lqr)"),
    "mode": ("", "'heading' (compass and rate gyro into the heading observer: a heading control system, IMO "
                 "A.342(IX)); 'course' (GNSS into the SOG/COG EKF, Fossen & Fossen 2021)"),
    "rate": ("", "'estimator' (the estimator's course or yaw rate, Fossen & Fossen 2021); in course mode on a "
                 "course-unstable ship (Nomoto T < 0) 'gyro' (the rate gyro as read: the course rate from GNSS "
                 "lags too much to hold the ship's own unstable pole)"),
    "wn": ("rad/s", "U/L, lowered in steps of 2^(1/4) (down to U/16L) until the loop on the linearised ship with the servo, the "
                    "sensor delay and the estimator (its steady-state Kalman filter) has PM >= 45 deg and upper GM "
                    ">= 6 dB within the steering-noise budget (else the best PM found, with a warning)"),
    "zeta": ("", "1 (critically damped)"),
    "integral": ("", "'fossen' (Ki = wn/10 Kp); 'exact' places the integrator pole at wn/10; 'none'"),
    "wn_ref": ("rad/s", "wn, lowered in steps of 2^(1/4) until a 20 deg course change asks the linear loop for at "
                        "most half the steering limit and half its rate limit"),
    "zeta_ref": ("", "1"),
    "r_max": ("rad/s", "0.3 U/L (a preset rate of turn), at most the rate the ship turns steadily with half its "
                       "steering limit at this speed (IMO A.342(IX) 3.2: within the ship's turning ability)"),
    "feedforward": ("", "'nonlinear': m a_d + s(r_d) with s the steady steering of the nonlinear ship at this speed "
                        "(a reverse spiral by trim); 'linear': m a_d + d r_d of the Nomoto model"),
    "wave_w0": ("rad/s", "0 (calm water); the encounter frequency of the first-order wave yaw the design is for: its "
                         "spectrum (relative damping 0.1, standard deviation wave_std) enters the steering-noise budget "
                         "of the estimator tuning, and so the bandwidth search"),
    "wave_std": ("rad", "0 (calm water); standard deviation of the first-order wave yaw on compass and gyro"),
    "wave_filter": ("", "'off'; 'on': the heading observer holds the wave model (Fossen's wave filter) and the "
                        "margins are those of the loop with it"),
    "turn_rate_top": ("rad/s", "the rate of turn the ship reaches steadily with its full steering at this speed "
                               "(reported; the check of r_max)"),
    "steer_max": ("rad or N m", "vessel.rudder_max; two-propeller craft: the yaw moment both propellers give at the "
                                "trim surge force"),
    "steer_rate_max": ("rad/s or N m/s", "vessel.rudder_rate, else 2.32 deg/s (SOLAS II-1/29.3.2); two-propeller "
                                         "craft: steer_max per propeller time constant"),
    "actuator_T": ("s", "1 s steering servo (MSS Mariner); two-propeller craft: the propeller time constant 0.1 s"),
    "filter_T": ("s", "0 (no command low-pass; the estimator does the filtering)"),
    "dt": ("s", "the largest of 0.2, 0.1, 0.05, 0.02 s not above L/U / 200 and actuator_T / 5 (at least 0.02 s)"),
    "delay": ("s", "half the GNSS (course mode) or compass (heading mode) period plus one loop period, in the margins"),
    "gnss_rate": ("Hz", "5 (Fossen & Fossen 2021)"),
    "gnss_std": ("m", "min(0.5, L/100): the course over ground from GNSS needs position noise small against the "
                      "ship's length (RTK class, 2 cm, for a 2 m craft; 0.5 m for ships above 50 m)"),
    "compass_rate": ("Hz", "10"),
    "compass_std": ("rad", "0.5 deg"),
    "gyro_std": ("rad/s", "0.02 deg/s"),
    "ekf_alpha": ("1/s", "speed: 1/T_surge of the linearisation; course rate: wn"),
    "ekf_q": ("(m/s^2)^2, (rad/s^2)^2", "speed: 2 alpha1 (0.05 U)^2 / dt; course rate: the largest value up to "
                                         "2 alpha2 r_max^2 / dt (in steps of 10^(1/4)) for which the steady-state "
                                         "filter (control.dlqe) puts at most min(rate_max actuator_T / 2, "
                                         "steer_max / 20) of sensor noise on the steering command"),
    "observer_q": ("spectral densities", "yaw acceleration: the largest value up to 2 (0.1 r_max)^2 / |T| (a yaw-rate "
                                         "disturbance of 10 % of the preset turn rate over the time constant) meeting the same "
                                         "noise budget; rudder bias: (0.05 steer_max)^2 / (10 L/U)"),
    "segment": ("s", "40 / wn_ref per course change (scenario course-20 lasts two segments), at least the time a "
                     "90 deg change takes at r_max plus 20 / wn_ref"),
    "lqr_weights": ("", "q_e = 1, q_int = (wn/10)^2, q_r = 1/wn^2, r_delta = (1/(m wn^2))^2 (Bryson's rule at the "
                        "pole-placement gains)"),
}


def _check_given(given: Mapping) -> dict:
    names = {f.name for f in fields(AutopilotSettings)} - {"sources"}
    unknown = sorted(set(given) - names)
    if unknown:
        raise InputError(f"unknown autopilot setting(s) {unknown}; known: {sorted(names)}")
    given = {k: v for k, v in given.items() if v is not None}
    for k, v in given.items():
        unit = RULES.get(k, ("", ""))[0]
        if isinstance(v, str) or k in ("lqr_weights",):
            continue
        values = np.atleast_1d(np.asarray(v, dtype=float))
        finite = np.isfinite(values) | ((values == np.inf) & (k in _UNBOUNDED))
        low = np.any(values < 0) if k in _NON_NEGATIVE else np.any(values <= 0)
        if not np.all(finite) or low:
            need = ">= 0" if k in _NON_NEGATIVE else "positive"
            what = "finite (or inf: no limit)" if k in _UNBOUNDED else "finite"
            raise InputError(f"autopilot setting {k} = {v} [{unit}] must be {what} and {need}")
    return given


#: Settings that may be zero (the others must be positive), and limits that may be inf (no limit).
_NON_NEGATIVE = ("delay", "filter_T", "actuator_T", "zeta", "zeta_ref", "gyro_std", "compass_std", "gnss_std",
                 "wave_w0", "wave_std", "wave_filter")
_UNBOUNDED = ("steer_max", "steer_rate_max", "r_max")


def _vessel(plant: SteeringPlant, key: str):
    v = plant.model.vessel
    return getattr(v, key, None) if v is not None else None


def _twin_propeller(plant: SteeringPlant) -> bool:
    return plant.steer == "tau_N" and "tau_X" in plant.inputs


def _gains(method, nom, wn, zeta, integral, weights):
    if method == "pid":
        return pid_pole_placement(nom, wn, zeta, integral=integral)
    return lqr_design(nom, **weights)


def default_lqr_weights(nom: Nomoto, wn: float) -> dict:
    """Bryson-style LQR weights at the pole-placement gains (see :data:`RULES`)."""
    return {"q_int": (wn / 10) ** 2, "q_e": 1.0, "q_r": 1.0 / wn**2, "r_delta": (1.0 / (abs(nom.m) * wn**2)) ** 2}


def derive_settings(plant: SteeringPlant, lin, nom: Nomoto, given: Mapping | None = None) -> AutopilotSettings:
    """Apply :data:`RULES` to a ship; values in ``given`` replace the rules.

    Parameters
    ----------
    plant : SteeringPlant
        The ship at its trim point.
    lin : control.StateSpace
        Its labelled course linearisation.
    nom : Nomoto
        The design model.
    given : mapping, optional
        Settings given by the caller.

    Returns
    -------
    AutopilotSettings

    Raises
    ------
    ValueError
        Naming an unknown setting, or when no bandwidth stabilises the ship within the noise budget.
    """
    given = dict(given or {})
    if isinstance(given.get("wave_filter"), str):
        if given["wave_filter"] not in ("on", "off"):
            raise InputError(f"autopilot setting wave_filter must be 'on' or 'off', got {given['wave_filter']!r}")
        given["wave_filter"] = given["wave_filter"] == "on"
    g = _check_given(given)
    src = {k: "given" for k in g}
    val = dict(g)

    def rule(name, make):
        if name not in val:
            val[name] = make()
            src[name] = RULES[name][1]
        return val[name]

    twin = _twin_propeller(plant)
    L = _vessel(plant, "L_pp")
    m = plant.model
    x0 = plant.x0 if plant.x0 is not None else m.states()
    speed = rule("speed", lambda: float(np.hypot(x0[m.index("u")], x0[m.index("v")]) if "u" in m.state_names
                                        else _vessel(plant, "U0")))
    if L is None and not ({"wn", "r_max", "dt", "segment"} <= set(val)):
        raise InputError(f"model {m.name!r} has no vessel length L_pp: give wn, r_max, dt and segment")
    LU = float(L) / speed if L is not None else None
    method = rule("method", lambda: "pid")
    if method not in ("pid", "lqr"):
        raise InputError(f"method must be 'pid' or 'lqr', got {method!r}")
    mode = rule("mode", lambda: "heading")
    rule("rate", lambda: "gyro" if mode == "course" and nom.T < 0 else "estimator")
    zeta = rule("zeta", lambda: 1.0)
    integral = rule("integral", lambda: "fossen")
    if integral == "none":
        val["integral"] = integral = None
    rule("zeta_ref", lambda: 1.0)
    feedforward = rule("feedforward", lambda: "nonlinear")
    if feedforward not in ("nonlinear", "linear"):
        raise InputError(f"feedforward must be 'nonlinear' or 'linear', got {feedforward!r}")
    if twin:
        t_n = float(plant.model.param_dict(plant.pvec).get("T_n", 0.1))
        steer_max = rule("steer_max", lambda: twin_propeller_yaw_limit(plant.model, plant.inputs["tau_X"], plant.pvec))
        rule("steer_rate_max", lambda: steer_max / t_n)
        rule("actuator_T", lambda: t_n)
    else:
        rule("steer_max", lambda: float(_vessel(plant, "rudder_max") or np.radians(35.0)))
        rule("steer_rate_max", lambda: float(_vessel(plant, "rudder_rate") or _SOLAS_RATE))
        rule("actuator_T", lambda: 1.0)
    limit = m.limits.get(plant.steer)
    if limit is not None and val["steer_max"] > max(abs(limit.lower), abs(limit.upper)) * (1 + 1e-9):
        from ..simulation import describe_limit

        v = val["steer_max"]
        shown = f"{v:g} N m" if twin else f"{v:g} rad ({np.degrees(v):.4g} deg)"
        raise InputError(f"autopilot setting steer_max = {shown} is beyond the valid range "
                         f"{describe_limit(m, plant.steer)} of {plant.steer!r} of model {m.name!r}")
    if LU is not None and np.isfinite(val["steer_max"]) and val["steer_max"] / val["steer_rate_max"] > 10 * LU:
        unit = "N m/s" if twin else "rad/s"
        raise InputError(f"autopilot setting steer_rate_max = {val['steer_rate_max']:g} {unit}: the steering gear would "
                         f"take {val['steer_max'] / val['steer_rate_max']:.3g} s from zero to its limit "
                         f"{val['steer_max']:.4g}, more than 10 L/U = {10 * LU:.3g} s (ten ship lengths of sailing): "
                         f"the ship could not be turned within a course change; give at least "
                         f"{val['steer_max'] / (10 * LU):.3g} {unit}")
    steering = None
    if "u" in m.state_names and "v" in m.state_names:
        try:
            steering = steering_feedforward(plant, val["steer_max"])
        except ValueError as err:         # no steady turn reaches the limit: the linear feed-forward
            if g.get("feedforward") == "nonlinear":
                raise
            src["feedforward"] = f"'linear' ({err})"
            val["feedforward"] = feedforward = "linear"
    rule("turn_rate_top", lambda: steering.r_top if steering is not None else float("nan"))
    rule("r_max", lambda: min(0.3 / LU, steering.rate_for(0.5)) if steering is not None else 0.3 / LU)
    if feedforward == "nonlinear" and steering is None and g.get("feedforward") != "nonlinear":
        val["feedforward"] = feedforward = "linear"
        src["feedforward"] = "'linear' (the model has no sway state for the steady turns)"
    if feedforward == "nonlinear" and steering is None:
        raise InputError(f"model {m.name!r} has no sway/surge states for the nonlinear feed-forward; use "
                         "feedforward='linear'")
    rule("filter_T", lambda: 0.0)
    rule("wave_w0", lambda: 0.0)
    rule("wave_std", lambda: 0.0)
    rule("wave_filter", lambda: False)
    val["wave_filter"] = bool(val["wave_filter"])
    wave = settings_wave(SimpleNamespace(**val))
    if (val["wave_w0"] > 0) != (val["wave_std"] > 0):
        raise InputError(f"autopilot settings wave_w0 = {val['wave_w0']:g} rad/s and wave_std = {val['wave_std']:g} rad "
                         "are given together (both positive: a sea state) or not at all")
    if val["wave_filter"] and wave is None:
        raise InputError("autopilot setting wave_filter needs the sea state: give wave_w0 and wave_std")
    if val["wave_filter"] and mode == "course":
        raise InputError("autopilot setting wave_filter is the heading observer's; mode 'course' has none")
    rule("dt", lambda: _loop_period(LU, val["actuator_T"]))
    rule("gnss_rate", lambda: 5.0)
    rule("gnss_std", lambda: min(0.5, float(L) / 100.0) if L is not None else 0.5)
    rule("compass_rate", lambda: 10.0)
    rule("compass_std", lambda: float(np.radians(0.5)))
    rule("gyro_std", lambda: float(np.radians(0.02)))
    rule("delay", lambda: 0.5 / (val["gnss_rate"] if mode == "course" else val["compass_rate"]) + val["dt"])
    actuator = Actuator(val["steer_max"], val["steer_rate_max"], val["actuator_T"])
    controlled = "chi" if mode == "course" else "psi"
    dt = val["dt"]
    budget = min(_NOISE_RATE * actuator.rate_max * max(actuator.T, dt), _NOISE_STEER * actuator.steer_max)
    a1 = float(val["ekf_alpha"][0]) if "ekf_alpha" in val else _surge_pole(plant)
    q_b = (0.05 * val["steer_max"]) ** 2 / (10 * (LU if LU else 1.0 / val.get("wn", 1.0)))

    budget_wave = [wave]            # the sea state the noise budget counts (dropped when no bandwidth meets it)
    # with the wave filter the observer damps on the steady steering (section 8, rule 1): the noise budget
    # and the margins analyse that observer, linearised on a straight course (Nomoto K / kappa, T / kappa)
    kappa = (observer_damping(SimpleNamespace(steering=steering, feedforward=val["feedforward"]), nom)
             if val["wave_filter"] else 1.0)

    def candidate(wn, wn_ref=None):
        """Gains, estimator tuning and the linear loop (with the estimator) at bandwidth ``wn``."""
        weights = {**default_lqr_weights(nom, wn), **val.get("lqr_weights", {})}
        gains = _gains(method, nom, wn, zeta, integral, weights)
        a2 = float(val["ekf_alpha"][1]) if "ekf_alpha" in val else wn
        Kd_est = gains.Kd if val["rate"] == "estimator" else 0.0
        gyro_noise = 0.0 if val["rate"] == "estimator" else abs(gains.Kd) * val["gyro_std"]
        room = float(np.sqrt(max(budget**2 - gyro_noise**2, (0.1 * budget) ** 2)))
        tuned = {"_quiet": gyro_noise <= budget}
        if mode == "course":
            q_U = 2 * a1 * (0.05 * speed) ** 2 / dt
            if "ekf_q" in val:
                q_U, q_chi = val["ekf_q"]
            else:
                q_chi, _ = tune_course_q(speed=speed, alpha=(a1, a2), q_U=q_U, q_chi_max=2 * a2 * val["r_max"] ** 2 / dt,
                                         dt=dt, gnss_every=max(1, int(round(1 / (val["gnss_rate"] * dt)))),
                                         gnss_std=val["gnss_std"], Kp=gains.Kp, Kd=Kd_est, budget=room)
            tuned.update(ekf_alpha=(a1, a2), ekf_q=(q_U, q_chi))
        else:
            if "observer_q" in val:
                q_r, qb = val["observer_q"]
            else:
                qb = q_b
                k = kappa if budget_wave[0] is not None else 1.0     # the filter is on only with the sea counted
                q_r, noise = tune_heading_q(K=nom.K / k, T=nom.T / k, q_r_max=2 * (0.1 * val["r_max"]) ** 2 / abs(nom.T),
                                        q_b=qb, dt=dt,
                                        compass_every=max(1, int(round(1 / (val["compass_rate"] * dt)))),
                                        compass_std=val["compass_std"], gyro_std=val["gyro_std"], Kp=gains.Kp,
                                        Kd=Kd_est, budget=room, wave=budget_wave[0],
                                        wave_filter=val["wave_filter"])
                tuned["_quiet"] = tuned["_quiet"] and noise <= room * (1 + 1e-9)
                tuned["_command_noise"] = noise
            tuned.update(observer_q=(q_r, qb))
        est = linear_estimator(SimpleNamespace(**{**val, **tuned, "steering": steering, "wave_filter": val["wave_filter"]
                                                  and budget_wave[0] is not None}), nom, plant.steer)
        ref = ReferenceModel(wn_ref, val["zeta_ref"]) if wn_ref else None
        L, closed = loop_systems(lin, gains, actuator, delay=val["delay"], reference=ref, controlled=controlled,
                                 filter_T=val["filter_T"], estimator=est, rate=val["rate"])
        return L, closed, tuned

    if "wn" not in val:

        def search():
            wn, best = 1.0 / LU, None
            for _ in range(_SEARCH_STEPS):
                L_, _, tuned = candidate(wn)
                mg = margins(L_)
                if mg["closed_loop_stable"] and tuned["_quiet"]:
                    if mg["phase_margin_deg"] >= _PM_MIN and mg["upper_gain_margin_db"] >= _GM_MIN:
                        return wn, None
                    if best is None or mg["phase_margin_deg"] > best[1]:
                        best = (wn, mg["phase_margin_deg"], mg["upper_gain_margin_db"])
                wn /= 2 ** 0.25
            return (None, None) if best is None else (best[0], best)

        wn, best = search()
        if wn is None and wave is not None:
            # the sea is beyond what a loop on compass and gyro can keep out of the steering: say why, design
            # for calm water (the wave filter, when on, stays in the estimator and in the margins)
            t_unstable = nom.T1 if nom.second_order and nom.T1 < 0 else nom.T
            p_unstable = 1.0 / abs(t_unstable) if t_unstable < 0 else 0.0
            why = (f"its unstable yaw pole at {p_unstable:.3g} rad/s needs a loop crossover of at least "
                   f"{2 * p_unstable:.3g} rad/s, within a factor 3 of the wave encounter frequency "
                   f"{wave.w0:.3g} rad/s (the rule: w0 >= 6 / |T|)" if p_unstable > 0 and wave.w0 < 6 * p_unstable
                   else "the wave yaw's steering noise exceeds the budget at every bandwidth")
            floor = _heading_floor(plant, lin, val, wave)
            warnings.warn(f"{m.name}: no bandwidth keeps the steering noise of the wave yaw ({np.degrees(val['wave_std']):.3g} "
                          f"deg at {wave.w0:.3g} rad/s) within the budget of {budget:.3g} "
                          f"{'N m' if twin else 'rad'}: {why}; the bandwidth is chosen for calm water (the margins "
                          "reported are those of the loop with the wave filter when it is on). No autopilot on compass "
                          f"and gyro holds this ship's heading better than {np.degrees(floor):.3g} deg RMS in this sea "
                          "(casship.autopilot.heading_error_floor)", WaveBudgetWarning, stacklevel=3)
            budget_wave[0] = None
            wn, best = search()
        if wn is None:
            raise InputError(f"no bandwidth below U/L = {1 / LU:.3g} rad/s stabilises {m.name!r} within the "
                             "steering-noise budget; give wn")
        if best is not None:
            warnings.warn(f"{m.name}: no bandwidth below U/L gives PM >= {_PM_MIN} deg and GM >= {_GM_MIN} dB with "
                          f"the {mode} estimator in the loop; using wn = {wn:.3g} rad/s (PM {best[1]:.1f} deg, GM "
                          f"{best[2]:.1f} dB)", stacklevel=3)
        val["wn"], src["wn"] = wn, RULES["wn"][1]
    wn = val["wn"]
    if "wn_ref" not in val:
        wr = wn
        change = np.radians(STANDARD_CHANGE_DEG)
        for _ in range(_SEARCH_STEPS):
            dem = course_change_demand(candidate(wn, wr)[1], change, 20.0 / wr, actuator=actuator)
            if dem["steer_max"] <= _DEMAND * actuator.steer_max and dem["rate_max"] <= _DEMAND * actuator.rate_max \
                    and dem["overshoot_pct"] <= _OVERSHOOT:
                break
            wr /= 2 ** 0.25
        val["wn_ref"], src["wn_ref"] = wr, RULES["wn_ref"][1]
    wr = val["wn_ref"]
    for key, value in candidate(wn)[2].items():
        if key not in val and not key.startswith("_"):
            val[key], src[key] = value, RULES[key][1]
    rule("ekf_alpha", lambda: (a1, wn))
    rule("ekf_q", lambda: (2 * a1 * (0.05 * speed) ** 2 / dt, 2 * wn * val["r_max"] ** 2 / dt))
    rule("observer_q", lambda: (2 * (0.1 * val["r_max"]) ** 2 / abs(nom.T), q_b))
    rule("lqr_weights", lambda: default_lqr_weights(nom, wn) if method == "lqr" else {})
    rule("segment", lambda: max(40.0 / wr, np.radians(90.0) / val["r_max"] + 20.0 / wr))
    for key in ("ekf_alpha", "ekf_q", "observer_q"):
        val[key] = tuple(float(v) for v in val[key])
    return AutopilotSettings(**val, sources=src, steering=steering)


def _heading_floor(plant: SteeringPlant, lin, val: dict, wave) -> float:
    """:func:`~casship.autopilot.wave_limit.heading_error_floor` from the settings resolved so far [rad]."""
    from .wave_limit import heading_error_floor

    design = SimpleNamespace(linearization=lin, plant=plant, settings=SimpleNamespace(**val))
    return heading_error_floor(design, wave)


def _surge_pole(plant: SteeringPlant) -> float:
    """``1/T_surge``: minus the surge entry of the linearisation's A (1/100 s without a surge state)."""
    from ..linear import linearize

    m = plant.model
    if "u" not in m.state_names:
        return 0.01
    x0 = plant.x0 if plant.x0 is not None else m.states()
    A = np.asarray(linearize(m, x0, plant.input_vector(0.0), plant.pvec, outputs=["u"]).A)
    iu = m.index("u")
    return float(max(-A[iu, iu], 1e-4))


def _loop_period(LU, actuator_T) -> float:
    limit = min(LU / 200.0 if LU else 0.02, actuator_T / 5 if actuator_T > 0 else np.inf)
    for dt in (0.2, 0.1, 0.05, 0.02):
        if dt <= limit:
            return dt
    return 0.02
