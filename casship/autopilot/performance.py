"""Performance checks of a closed-loop run: course changing and course keeping, reported against the
autopilot performance standards where they state a criterion.

IMO Resolution A.342(IX), as amended by MSC.64(67) Annex 3 ("Recommendation on performance
standards for heading control systems"), asks (sections as numbered in the resolution):

* 2.1 keep a preset heading "with minimum operation of the ship's steering gear" -> checked: the
  fraction of time the steering gear runs at its rate limit (:func:`performance_report`);
  reported beside it: the steering travel per hour (the sum of the steering's movements, e.g.
  deg/h: the wear the rate-limit figure does not show); reported by
  :func:`course_keeping_metrics`: mean and RMS steering, RMS steering rate, steering work;
* 3.2 turns "based either on a preset turning radius or a preset rate of turn" -> checked: the
  peak rate of turn the ship reaches against the preset rate (the reference model's turn-rate
  limit ``r_max``), at most 10 % above it; the preset rate itself is kept within the ship's
  turning ability by the design rules (:data:`~casship.autopilot.defaults.RULES`, ``r_max``);
* 3.3 rudder angle limitation, with an indication "when the angle of limitation has been commanded
  or reached" -> reported (no threshold): the fraction of time the command sits on the limit;
* 3.4 means "to prevent unnecessary activation of the rudder due to normal yaw motion" -> not a
  check here: the wave filter of the heading observer provides it, and the autopilot-waves study
  and the tests measure the rudder activity it saves;
* 3.6 "change to a preset heading without significant overshoot" -> checked: the overshoot of each
  course change, and that each change settles.

The resolution gives no numbers. ISO 11674:2019 (the test standard for MSC.64(67) Annex 3) states
its test methods and acceptance values with ship simulators; its numbers are not public and are not
used here. The thresholds casship reports against are therefore its own readings, stated with each
check (:data:`CRITERIA`): overshoot at most 10 % of the change, steady error at most 0.5 deg (or
2 % of the change), steering-gear rate limit active at most 10 % of the time, rate of turn at
most 10 % above the preset rate. Settling is reported per change (last entry into the band of 2 %
of the change or 1 deg) and checked: a change that has not settled by the end of its segment fails.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from ..angles import wrap
from ..data import Dataset
from ..errors import InputError

__all__ = ["step_metrics", "course_change_metrics", "course_keeping_metrics", "performance_report", "CRITERIA",
           "course_scenario"]

#: Checks and the thresholds casship applies (name -> (threshold, unit, source and reading)).
CRITERIA = {
    "overshoot_pct": (10.0, "% of the change",
                      "MSC.64(67) Annex 3, 3.6 'without significant overshoot' (casship reads: <= 10 %)"),
    "steady_state_error_deg": (0.5, "deg (or 2 % of the change, the larger)",
                               "course kept after the change (casship's reading of A.342(IX) 2.1)"),
    "rate_limited_fraction": (0.10, "of the time",
                              "steering gear not driven at its rate limit (casship's reading of 2.1 'minimum "
                              "operation of the steering gear')"),
    "turn_rate_ratio": (1.10, "of the preset rate of turn",
                        "MSC.64(67) Annex 3, 3.2 turns at a preset rate of turn (casship reads: the peak rate of "
                        "turn at most 10 % above it)"),
    "settled": (0.02, "of the change (or 1 deg)", "each change settles within its segment (casship's reading "
                "of 3.6)"),
    "at_limit_fraction": (0.0, "of the time (reported)", "MSC.64(67) Annex 3, 3.3 rudder angle limitation "
                          "commanded or reached (indication; no threshold)"),
}


def step_metrics(t, y, target: float, steer=None, *, band: float = 0.02, abs_band: float = 0.0,
                 ss_window: float = 0.1) -> dict:
    """Step-response metrics of ``y`` (angles, rad) moving from ``y[0]`` to ``target``.

    Returns rise time (10 % -> 90 % of the change) [s], overshoot [% of the change and deg],
    settling time (last entry into the band ``max(band * |change|, abs_band)``) [s], steady-state
    error (mean over the last ``ss_window`` fraction) [deg], IAE [deg s], and with ``steer`` the
    mean and maximum absolute steering and the RMS and maximum steering rate (per second). Times
    are measured from ``t[0]``; ``nan`` where not reached.

    Parameters
    ----------
    t : array
        Time [s].
    y : array
        Controlled angle [rad].
    target : float
        Commanded angle [rad].
    steer : array, optional
        Steering.
    band : float
        Settling band as a fraction of the change.
    abs_band : float
        Absolute settling band [rad] (the larger band counts).
    ss_window : float
        Fraction of the record at its end for the steady-state error.

    Examples
    --------
    >>> import numpy as np
    >>> t = np.linspace(0.0, 100.0, 1001)
    >>> round(step_metrics(t, 0.5 * (1 - np.exp(-t / 10)), 0.5)["rise_time_s"], 1)
    22.0
    """
    t = np.asarray(t, dtype=float)
    y = np.asarray(y, dtype=float)
    if t.size < 3:
        raise InputError("step_metrics needs at least 3 samples")
    y = y[0] + np.unwrap(wrap(y - y[0]))          # continuous around the start value
    change = float(wrap(target - y[0]))
    goal = y[0] + change
    err = y - goal
    out = {"target_deg": float(np.degrees(target)), "change_deg": float(np.degrees(change))}
    if abs(change) > 0:
        frac = (y - y[0]) / change
        i10 = np.flatnonzero(frac >= 0.1)
        i90 = np.flatnonzero(frac >= 0.9)
        out["rise_time_s"] = float(t[i90[0]] - t[i10[0]]) if i10.size and i90.size else float("nan")
        over = max(0.0, float(np.max(frac) - 1.0))
        out["overshoot_pct"] = 100 * over
        out["overshoot_deg"] = float(np.degrees(over * abs(change)))
        tol = max(band * abs(change), abs_band)
        outside = np.flatnonzero(np.abs(err) > tol)
        if outside.size == 0:
            out["settling_time_s"] = 0.0
        elif outside[-1] == t.size - 1:
            out["settling_time_s"] = float("nan")
        else:
            out["settling_time_s"] = float(t[outside[-1] + 1] - t[0])
    tail = t >= t[0] + (1 - ss_window) * (t[-1] - t[0])
    out["steady_state_error_deg"] = float(np.degrees(np.mean(err[tail])))
    out["iae_deg_s"] = float(np.degrees(np.trapezoid(np.abs(err), t)))
    if steer is not None:
        s = np.asarray(steer, dtype=float)
        rate = np.diff(s) / np.diff(t)
        out.update({"steer_mean_abs": float(np.mean(np.abs(s))), "steer_max_abs": float(np.max(np.abs(s))),
                    "steer_rate_rms": float(np.sqrt(np.mean(rate**2))),
                    "steer_rate_max": float(np.max(np.abs(rate)))})
    return out


def course_change_metrics(data: Dataset, step_times: Sequence[float], *, controlled: str = "chi",
                          settle_band: float = np.radians(1.0)) -> list[dict]:
    """:func:`step_metrics` for each command segment of a closed-loop record (command in ``ref``),
    plus the fraction of the segment with the steering-gear rate limit active.

    Parameters
    ----------
    data : Dataset
        Closed-loop record.
    step_times : sequence of float
        Times of the command changes [s].
    controlled : str
        Column of the controlled angle (``chi`` or ``psi``).
    settle_band : float
        Absolute settling band [rad].
    """
    t = data.t
    y = data[controlled]
    bounds = list(step_times) + [t[-1] + 1.0]
    out = []
    for t0, t1 in zip(bounds[:-1], bounds[1:]):
        sel = (t >= t0) & (t < t1)
        if sel.sum() < 3:
            raise InputError(f"command segment [{t0:g}, {t1:g}) s has fewer than 3 samples")
        target = float(data["ref"][sel][-1])
        mt = step_metrics(t[sel], y[sel], target, data["steer"][sel], abs_band=settle_band)
        if "rate_limited" in data:
            mt["rate_limited_fraction"] = float(np.mean(data["rate_limited"][sel] > 0.5))
        mt["steer_travel"] = float(np.sum(np.abs(np.diff(data["steer"][sel]))))
        mt["turn_rate_max"] = float(np.max(np.abs(data["r"][sel]))) if "r" in data else float("nan")
        out.append(mt)
    return out


def course_keeping_metrics(data: Dataset, *, controlled: str = "chi", start: float = 0.0) -> dict:
    """Course-keeping measures from ``start`` on: error RMS and maximum [deg] against the command,
    mean and RMS steering, RMS steering rate [unit/s], steering work ``int |d steer|`` [unit], and
    the fraction of time with the steering-gear rate limit active.

    Parameters
    ----------
    data : Dataset
        Closed-loop record.
    controlled : str
        Column of the controlled angle.
    start : float
        Start of the window [s].
    """
    t = data.t
    sel = t >= start
    if sel.sum() < 3:
        raise InputError(f"fewer than 3 samples after t = {start:g} s")
    err = wrap(data[controlled][sel] - data["ref"][sel])
    s = data["steer"][sel]
    rate = np.diff(s) / np.diff(t[sel])
    out = {"error_rms_deg": float(np.degrees(np.sqrt(np.mean(err**2)))),
           "error_max_deg": float(np.degrees(np.max(np.abs(err)))),
           "steer_mean": float(np.mean(s)), "steer_rms": float(np.sqrt(np.mean(s**2))),
           "steer_rate_rms": float(np.sqrt(np.mean(rate**2))), "steer_travel": float(np.sum(np.abs(np.diff(s))))}
    if "rate_limited" in data:
        out["rate_limited_fraction"] = float(np.mean(data["rate_limited"][sel] > 0.5))
    return out


def performance_report(data: Dataset, steps: list[dict], *, steer_max: float, controlled: str = "chi",
                       r_max: float | None = None) -> dict:
    """The checks of :data:`CRITERIA` on a run: per course change (overshoot, settling, steady
    error) and over the whole run (rate limit active, with the steering travel per hour beside it;
    peak rate of turn against the preset ``r_max``; command at its limit), each with its threshold
    and a pass flag.

    Parameters
    ----------
    data : Dataset
        Closed-loop record.
    steps : list of dict
        From :func:`course_change_metrics`.
    steer_max : float
        Steering limit.
    controlled : str
        Column of the controlled angle.
    r_max : float, optional
        The preset rate of turn [rad/s] (section 3.2 is checked when given).
    """
    checks = []
    for k, mt in enumerate(steps):
        if "overshoot_pct" in mt:
            checks.append({"check": f"overshoot, change {k + 1}", "value": mt["overshoot_pct"],
                           "threshold": CRITERIA["overshoot_pct"][0], "unit": "%",
                           "ok": bool(mt["overshoot_pct"] <= CRITERIA["overshoot_pct"][0])})
        if "settling_time_s" in mt:
            checks.append({"check": f"settled, change {k + 1}", "value": mt["settling_time_s"], "threshold": None,
                           "unit": "s", "ok": bool(np.isfinite(mt["settling_time_s"]))})
        lim = max(CRITERIA["steady_state_error_deg"][0], 0.02 * abs(mt.get("change_deg", 0.0)))
        checks.append({"check": f"steady error, change {k + 1}", "value": mt["steady_state_error_deg"],
                       "threshold": lim, "unit": "deg", "ok": bool(abs(mt["steady_state_error_deg"]) <= lim)})
    frac = float(np.mean(data["rate_limited"] > 0.5)) if "rate_limited" in data else float("nan")
    at_limit = float(np.mean(np.abs(data["steer_cmd"]) >= steer_max * (1 - 1e-9))) if "steer_cmd" in data \
        else float("nan")
    checks.append({"check": "steering-gear rate limit active", "value": frac,
                   "threshold": CRITERIA["rate_limited_fraction"][0], "unit": "fraction of time",
                   "ok": bool(frac < CRITERIA["rate_limited_fraction"][0])})
    duration = float(data.t[-1] - data.t[0])
    travel = float(np.sum(np.abs(np.diff(data["steer"])))) * 3600.0 / duration if duration > 0 else float("nan")
    checks.append({"check": "steering travel per hour", "value": travel, "threshold": None,
                   "unit": "rad/h of rudder (N m/h of yaw moment)", "ok": None})
    out = {"rate_limited_fraction": frac, "at_limit_fraction": at_limit, "steer_travel_per_hour": travel}
    if r_max is not None and "r" in data:
        ratio = float(np.max(np.abs(data["r"])) / r_max)
        checks.append({"check": "peak rate of turn / preset rate (3.2)", "value": ratio,
                       "threshold": CRITERIA["turn_rate_ratio"][0], "unit": "",
                       "ok": bool(ratio <= CRITERIA["turn_rate_ratio"][0])})
        out["turn_rate_ratio"] = ratio
    checks.append({"check": "steering command at its limit", "value": at_limit, "threshold": None,
                   "unit": "fraction of time", "ok": None})
    out.update(checks=checks, all_ok=all(c["ok"] for c in checks if c["ok"] is not None))
    return out


def course_scenario(name: str, t_end: float | None = None, *, segment: float | None = None):
    """A named course-change scenario.

    ``course-A``: A deg at t = 0, back to 0 at half the run (the two standard course changes;
    ``course-20`` is Fossen & Fossen 2021's); ``step-A``: A deg at t = 0, held; ``rot-R``: a turn at
    the rate of turn R deg/min (the rate-of-turn mode of a heading control system: the course
    command moves at that rate) for half the run, then the course held. The run lasts ``t_end``
    seconds, or two (one) ``segment`` lengths, or 40 s.

    Parameters
    ----------
    name : str
        Scenario name.
    t_end : float, optional
        Duration [s].
    segment : float, optional
        Length of one course change [s] when ``t_end`` is not given.

    Returns ``(command(t) -> rad, t_end, step_times)``.

    Examples
    --------
    >>> command, t_end, steps = course_scenario("course-20", 40.0)
    >>> round(float(command(5.0)), 4), t_end, steps
    (0.3491, 40.0, [0.0, 20.0])
    """
    try:
        kind, angle = name.rsplit("-", 1)
        a = float(np.radians(float(angle)))
    except ValueError:
        raise InputError(f"unknown scenario {name!r}; use course-A, step-A (A in degrees) or rot-R (R in "
                         "deg/min)") from None
    if kind not in ("course", "step", "rot"):
        raise InputError(f"unknown scenario {name!r}; use course-A, step-A (A in degrees) or rot-R (R in deg/min)")
    if kind != "rot" and not (np.isfinite(a) and 0 < abs(a) <= np.pi):
        raise InputError(f"scenario {name!r}: the course change {angle} deg must be non-zero and within +-180 deg "
                         "(a course is an angle: a larger change wraps to a smaller one)")
    if kind == "rot" and not (np.isfinite(a) and a != 0):
        raise InputError(f"scenario {name!r}: the rate of turn {angle} deg/min must be non-zero and finite")
    if t_end is None:
        t_end = (2 * segment if kind in ("course", "rot") else segment) if segment is not None else 40.0
    t_end = float(t_end)
    if not t_end > 0:
        raise InputError(f"t_end must be positive, got {t_end}")
    if kind == "rot":
        rate, stop = a / 60.0, t_end / 2
        return (lambda t: float(np.angle(np.exp(1j * rate * min(t, stop))))), t_end, [0.0, stop]
    if kind == "course":
        back = t_end / 2
        return (lambda t: a if t < back else 0.0), t_end, [0.0, back]
    return (lambda t: a), t_end, [0.0]
