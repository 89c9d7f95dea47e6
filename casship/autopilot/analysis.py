"""Linear analysis of a course loop with python-control: the labelled plant, the loop and the closed
loop by ``control.interconnect``, margins as python-control reports them with casship's reading
beside them, and the Bode plot by ``control.bode_plot``.

Gain margins of autopilot loops. With integral action the loop ``L(s)`` behaves like ``1/s^2`` (or
worse) at low frequency, so its phase lies below -180 deg there: the Nyquist curve crosses the
negative real axis once at low frequency with ``|L| > 1`` and once at high frequency with ``|L| < 1``.
The loop is *conditionally stable*: it goes unstable if its gain grows by the upper margin or
shrinks by the lower margin. ``control.margin`` / ``control.stability_margins`` return one of them,
the one closest to 0 dB on a log scale (the lower one, negative in dB, when the loop has more
margin upwards). casship reports that value as ``gain_margin_db`` and both readings,
``upper_gain_margin_db`` and ``lower_gain_margin_db``, from
``control.stability_margins(L, returnall=True)``.
"""
from __future__ import annotations

import control
import numpy as np

from ..linear import linearize
from .law import Actuator, PIDGains
from .plants import SteeringPlant
from .reference import ReferenceModel
from ..errors import InputError

__all__ = ["course_linearization", "loop_systems", "loop_transfer", "closed_loop_tf", "margins",
           "course_change_demand"]


def course_linearization(plant: SteeringPlant, x0=None) -> control.StateSpace:
    """Exact linearisation of the plant at ``x0`` from the steering input to ``chi, psi, r``.

    Parameters
    ----------
    plant : SteeringPlant
        The ship with its other inputs bound.
    x0 : array, optional
        Operating point (default: ``plant.x0``, the trim state).

    Returns
    -------
    control.StateSpace
        A labelled :class:`control.StateSpace` (:func:`casship.linearize`) whose course-over-ground
    output ``chi = atan2(y', x')`` is linearised exactly from the position rows of ``A`` and ``B``;
    states that no output sees (the positions) are left out.
    """
    m = plant.model
    x0 = np.asarray(x0 if x0 is not None else (plant.x0 if plant.x0 is not None else m.states()), float)
    u0 = plant.input_vector(0.0)
    full = linearize(m, x0, u0, plant.pvec, outputs=[plant.heading, plant.yaw_rate])
    A, B, C = np.asarray(full.A), np.asarray(full.B), np.asarray(full.C)
    xd = full.operating_point["xdot"]
    ix, iy = m.index(plant.north), m.index(plant.east)
    U2 = xd[ix] ** 2 + xd[iy] ** 2
    if U2 <= 0:
        raise InputError(f"the course over ground is undefined at zero speed ({m.name!r} at rest)")
    js = m.index(plant.steer, "input")
    c_chi = (xd[ix] * A[iy] - xd[iy] * A[ix]) / U2
    d_chi = (xd[ix] * B[iy, js] - xd[iy] * B[ix, js]) / U2
    Cs = np.vstack([c_chi, C])
    Ds = np.array([[d_chi], [0.0], [0.0]])
    # keep the states some output sees (directly or through the dynamics)
    seen = np.abs(Cs).sum(axis=0) > 0
    for _ in range(m.nx):
        seen = seen | (np.abs(A[seen]).sum(axis=0) > 0)
    keep = np.flatnonzero(seen)
    labels = [m.state_names[i] for i in keep]
    return control.ss(A[np.ix_(keep, keep)], B[keep][:, [js]], Cs[:, keep], Ds, states=labels,
                      inputs=[plant.steer], outputs=["chi", "psi", "r"], name=m.c_name)


def _actuator_system(actuator: Actuator, delay: float, steer: str) -> control.StateSpace:
    """Servo (and a first-order Pade delay) from ``<steer>_c`` to ``<steer>`` as a labelled system."""
    G = actuator.tf()
    if delay > 0:
        num, den = control.pade(delay, 1)
        G = G * control.tf(num, den)
    return control.ss(G, inputs=[f"{steer}_c"], outputs=[steer], name="steering_gear")


def loop_systems(plant_sys: control.StateSpace, gains: PIDGains, actuator: Actuator, *, delay: float = 0.0,
                 reference: ReferenceModel | None = None, controlled: str = "chi", filter_T: float = 0.0,
                 estimator: control.StateSpace | None = None, rate: str = "estimator"):
    """The open loop ``L`` (cut at the steering command) and the closed loop, by ``control.interconnect``.

    Parameters
    ----------
    plant_sys : control.StateSpace
        Labelled plant with input the steering and outputs including ``controlled`` and ``r``
        (:func:`course_linearization`, or :meth:`Nomoto.system <casship.autopilot.nomoto.Nomoto.system>`).
    gains : PIDGains
    actuator : Actuator
        Its servo time constant enters the loop (limits do not).
    delay : float
        Measurement delay [s] (first-order Pade), e.g. the GNSS period.
    reference : ReferenceModel, optional
        Included in the closed loop (input ``chi_ref``); without it the closed loop's inputs are
        ``chi_d, r_d, a_d``.
    controlled : str
        Plant output fed back as the course (``"chi"``, or ``"psi"`` for a heading autopilot).
    filter_T : float
        Command low-pass time constant of the autopilot [s].
    estimator : control.StateSpace, optional
        A labelled linear estimator between the ship and the law (outputs ``chi_hat, rate_hat``;
        inputs among the plant's outputs, the steering, and ``y_n``, the cross position
        ``int U chi dt`` of a course filter): see
        :func:`~casship.autopilot.estimation.course_filter_system` and
        :func:`~casship.autopilot.estimation.heading_filter_system`.
    rate : {"estimator", "gyro"}
        With an estimator: the rate fed back is its ``rate_hat`` or the plant's ``r``.

    Returns
    -------
    (L, closed) : control.StateSpace
        ``L`` from ``u`` (cut) to the loop return with the sign convention of ``control.margin``
        (closed loop ``L / (1 + L)``); ``closed`` with outputs ``chi, r, <steer>_c, <steer>``.
    """
    steer = plant_sys.input_labels[0]
    if controlled not in plant_sys.output_labels or "r" not in plant_sys.output_labels:
        raise InputError(f"plant outputs {plant_sys.output_labels} lack {controlled!r} or 'r'")
    ctrl = gains.controller(steer=steer, name="autopilot")
    if filter_T > 0:
        lp = control.ss(control.tf([1.0], [filter_T, 1.0]), inputs=[f"{steer}_raw"], outputs=[f"{steer}_c"],
                        name="command_filter")
        ctrl = control.interconnect([ctrl, lp], connections=[["command_filter." + f"{steer}_raw",
                                                              f"autopilot.{steer}_c"]],
                                    inplist=[f"autopilot.{k}" for k in ctrl.input_labels],
                                    inputs=list(ctrl.input_labels), outlist=[f"command_filter.{steer}_c"],
                                    outputs=[f"{steer}_c"], name="autopilot")
    gear = _actuator_system(actuator, delay, steer)
    plant = control.ss(plant_sys, name="ship")
    systems = [ctrl, gear, plant]
    fb = [[f"ship.{steer}", f"steering_gear.{steer}"]]
    used = {controlled, "r"} if estimator is None else ({"r"} if rate != "estimator" else set())
    if estimator is None:
        fb += [["autopilot.chi", f"ship.{controlled}"], ["autopilot.r", "ship.r"]]
    else:
        est = control.ss(estimator, name="estimator")
        systems.append(est)
        fb += [["autopilot.chi", "estimator.chi_hat"],
               ["autopilot.r", "estimator.rate_hat" if rate == "estimator" else "ship.r"]]
        for sig in est.input_labels:
            if sig == "y_n":             # cross position: the course integrated at the speed of the track
                speed = float(estimator.A[0, 1])
                track = control.ss(0.0, 1.0, speed, 0.0, inputs=["chi"], outputs=["y_n"], states=["y_n"],
                                   name="track")
                systems.append(track)
                fb += [["track.chi", "ship.chi"], ["estimator.y_n", "track.y_n"]]
                used.add("chi")
            elif sig == steer:
                fb.append([f"estimator.{steer}", f"steering_gear.{steer}"])
            elif sig in plant.output_labels:
                fb.append([f"estimator.{sig}", f"ship.{sig}"])
                used.add(sig)
            else:
                raise InputError(f"estimator input {sig!r} is neither a plant output, the steering, nor 'y_n'")
    unused = [o for o in plant.output_labels if o not in used]
    opened = control.interconnect(
        systems, connections=fb, inplist=[f"steering_gear.{steer}_c"], inputs=["u"],
        outlist=[f"autopilot.{steer}_c"], outputs=["y"],
        ignore_inputs=["autopilot.chi_d", "autopilot.r_d", "autopilot.a_d"],
        ignore_outputs=[f"ship.{o}" for o in unused] + (["estimator.rate_hat"] if estimator is not None
                                                         and rate != "estimator" else []), name="open_loop")
    L = control.ss(opened.A, opened.B, -opened.C, -opened.D, inputs=["u"], outputs=["L"],
                   states=opened.state_labels, name="loop")
    conns = fb + [[f"steering_gear.{steer}_c", f"autopilot.{steer}_c"]]
    if reference is not None:
        systems = systems + [reference.system(name="reference")]
        conns += [[f"autopilot.{k}", f"reference.{k}"] for k in ("chi_d", "r_d", "a_d")]
        inplist, inputs = ["reference.chi_ref"], ["chi_ref"]
    else:
        inplist, inputs = [f"autopilot.{k}" for k in ("chi_d", "r_d", "a_d")], ["chi_d", "r_d", "a_d"]
    closed = control.interconnect(
        systems, connections=conns, inplist=inplist, inputs=inputs,
        outlist=[f"ship.{controlled}", "ship.r", f"autopilot.{steer}_c", f"steering_gear.{steer}"],
        outputs=["chi", "r", f"{steer}_c", steer], check_unused=False, name="closed_loop")
    return L, closed


def loop_transfer(plant_sys, gains: PIDGains, *, actuator_T: float = 0.0, delay: float = 0.0,
                  filter_T: float = 0.0, controlled: str = "chi", order: int | None = None):
    """Open-loop transfer function ``L`` of the course loop cut at the steering command, reduced
    by ``control.minreal``.

    Parameters
    ----------
    plant_sys : control.StateSpace or Nomoto
        A labelled plant, or a :class:`~casship.autopilot.nomoto.Nomoto` model (its ``order`` 1 or
        2 system, heading fed back).
    gains : PIDGains
    actuator_T : float
        Steering servo time constant [s].
    delay : float
        Measurement delay [s] (first-order Pade).
    filter_T : float
        Command low-pass time constant [s].
    controlled : str
        Plant output fed back as the course.
    order : int, optional
        Order of the Nomoto system (default: 2 when known).

    Returns
    -------
    control.TransferFunction
    """
    from .nomoto import Nomoto

    if isinstance(plant_sys, Nomoto):
        plant_sys = plant_sys.system(order or (2 if plant_sys.second_order else 1))
        controlled = "psi"
    L, _ = loop_systems(plant_sys, gains, Actuator(T=actuator_T), delay=delay, controlled=controlled,
                        filter_T=filter_T)
    return control.minreal(control.ss2tf(L), verbose=False)


def closed_loop_tf(plant_sys, gains: PIDGains, **kw) -> control.TransferFunction:
    """Closed loop from the set-point to the course without feed-forward: ``L / (1 + L)``.

    Parameters
    ----------
    plant_sys : control.StateSpace or Nomoto
        As :func:`loop_transfer`.
    gains : PIDGains
    **kw
        Options of :func:`loop_transfer`.
    """
    return control.feedback(loop_transfer(plant_sys, gains, **kw), 1)


def margins(L) -> dict:
    """Stability margins of the loop ``L`` as python-control reports them, with casship's reading.

    Parameters
    ----------
    L : control.StateSpace or control.TransferFunction
        The open loop (closed loop ``L / (1 + L)``).

    Returns
    -------
    dict
        ``gain_margin_db``, ``phase_margin_deg``, ``stability_margin``, ``phase_crossover_rad_s``,
        ``gain_crossover_rad_s``: ``control.stability_margins(L)`` (the gain margin in dB is
        ``20 log10`` of python-control's ratio); ``gain_margin_side``: which of the two readings
        that is (``"upper"``/``"lower"``); ``upper_gain_margin_db`` (how much the loop gain may grow,
        ``inf`` if unbounded) and ``lower_gain_margin_db`` (how much it may shrink, ``-inf`` if
        unbounded) from all crossings; ``closed_loop_stable`` from the poles of ``L / (1 + L)``.
    """
    gm, pm, sm, wpc, wgc, _ = control.stability_margins(L)
    gms, _, _, wgs, _, _ = control.stability_margins(L, returnall=True)
    gms, wgs = np.asarray(gms, dtype=float), np.asarray(wgs, dtype=float)
    up, lo = gms > 1, (gms < 1) & (gms > 0)
    gm_db = float(20 * np.log10(gm)) if np.isfinite(gm) and gm > 0 else float("inf")
    upper = float(20 * np.log10(gms[up].min())) if up.any() else float("inf")
    lower = float(20 * np.log10(gms[lo].max())) if lo.any() else float("-inf")
    return {"gain_margin_db": gm_db, "gain_margin_side": "lower" if gm_db < 0 else "upper",
            "phase_margin_deg": float(pm), "stability_margin": float(sm),
            "phase_crossover_rad_s": float(wpc), "gain_crossover_rad_s": float(wgc),
            "upper_gain_margin_db": upper, "lower_gain_margin_db": lower,
            "upper_crossover_rad_s": float(wgs[up][np.argmin(gms[up])]) if up.any() else float("nan"),
            "lower_crossover_rad_s": float(wgs[lo][np.argmax(gms[lo])]) if lo.any() else float("nan"),
            "closed_loop_stable": bool(np.all(np.real(_loop_poles(control.feedback(L, 1))) < 0))}


def _loop_poles(cl) -> np.ndarray:
    """Poles of the closed loop without the modes it neither moves nor sees (positions): the
    Popov-Belevitch-Hautus test on the state-space form (no transfer function, whose polynomial
    coefficients are badly conditioned for a ship loop)."""
    cl = control.ss(cl)
    A, B, C = (np.asarray(m, dtype=float) for m in (cl.A, cl.B, cl.C))
    n = A.shape[0]
    lam = np.linalg.eigvals(A)
    keep = []
    for z in lam:
        M = A - z * np.eye(n)
        tol = 1e-9 * max(1.0, np.linalg.norm(A))
        moved = np.linalg.matrix_rank(np.hstack([M, B]), tol) == n
        seen = np.linalg.matrix_rank(np.vstack([M, C]), tol) == n
        keep.append(moved and seen)
    return lam[np.array(keep, dtype=bool)] if n else lam


def course_change_demand(closed: control.StateSpace, change: float, t_end: float, *, actuator: Actuator,
                         n: int = 2000) -> dict:
    """Peak steering and steering-gear rate demanded by a course change on the linear closed loop.

    Parameters
    ----------
    closed : control.StateSpace
        Closed loop with the reference model (input ``chi_ref``; outputs ``chi, r, <steer>_c,
        <steer>``), e.g. from :func:`loop_systems`.
    change : float
        Course change [rad].
    t_end : float
        Simulated time [s].
    actuator : Actuator
        The steering gear; the rate is the servo's demand ``(command - steering)/T`` (or the
        command's rate for ``T = 0``).
    n : int
        Samples.

    Returns
    -------
    dict
        ``steer_max``, ``rate_max`` (peak demands) and ``overshoot_pct`` of the linear response.
    """
    steer = closed.output_labels[3]
    t = np.linspace(0.0, t_end, n)
    resp = control.forced_response(closed, t, np.full(t.size, change))
    out = dict(zip(closed.output_labels, np.atleast_2d(resp.outputs)))
    cmd, s = out[f"{steer}_c"], out[steer]
    rate = (cmd - s) / actuator.T if actuator.T > 0 else np.gradient(cmd, t)
    chi = out["chi"]
    return {"steer_max": float(np.max(np.abs(cmd))), "rate_max": float(np.max(np.abs(rate))),
            "overshoot_pct": float(100 * max(0.0, np.max(chi / change) - 1.0))}
