"""Path following through waypoints: line-of-sight (LOS) and integral LOS (ILOS) guidance.

The path is a polyline of waypoints (North, East). On the segment from waypoint ``k`` to ``k + 1``
with path angle ``pi_k`` the along-track and cross-track errors are ::

    s   =  (N - N_k) cos pi_k + (E - E_k) sin pi_k
    y_e = -(N - N_k) sin pi_k + (E - E_k) cos pi_k          (positive: right of the path)

and the lookahead-based LOS law (Fossen 2021, Sec. 12.4) commands the course
``chi_d = pi_k - atan(y_e / Delta)``. Integral LOS adds an integral of the cross-track error,
``chi_d = pi_k - atan((y_e + kappa y_int) / Delta)`` with
``y_int' = Delta y_e / (Delta^2 + (y_e + kappa y_int)^2)`` (Borhaug, Pavlov & Pettersen 2008;
Fossen 2021, Sec. 12.4.3), which makes a *heading* autopilot hold the path in a current or a side
wind (crab-angle compensation); a course autopilot on the course over ground needs no integral.
The next segment is taken when the ship enters the circle of acceptance of radius ``R`` around
the segment's end, or passes the end along the track; the ILOS integral restarts there. With a
turn radius (track control as ships use it, IEC 62065) the next segment is taken instead at the
*wheel-over point*: ``R_t tan(|Delta chi| / 2)`` before the waypoint along the track, where a turn
of radius ``R_t`` (the speed over the preset rate of turn) starting on this leg ends tangent to the
next one.
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..angles import wrap_sym
from ..data import Dataset
from ..errors import InputError

__all__ = ["Waypoints", "LOSGuidance", "cross_track_metrics", "track_deviation"]


@dataclass(frozen=True)
class Waypoints:
    """A path through waypoints.

    Parameters
    ----------
    north, east : sequence of float
        Coordinates [m] (at least two points, no point repeating the one before).

    Examples
    --------
    >>> wp = Waypoints([0.0, 1000.0, 1000.0], [0.0, 0.0, 800.0])
    >>> [round(float(a), 4) for a in wp.angles]
    [0.0, 1.5708]
    """

    north: tuple
    east: tuple

    def __post_init__(self):
        n = np.asarray(self.north, dtype=float).reshape(-1)
        e = np.asarray(self.east, dtype=float).reshape(-1)
        if n.size != e.size or n.size < 2:
            raise InputError(f"waypoints need at least two North/East pairs of equal length, got {n.size} and {e.size}")
        if not (np.all(np.isfinite(n)) and np.all(np.isfinite(e))):
            raise InputError("waypoint coordinates must be finite")
        lengths = np.hypot(np.diff(n), np.diff(e))
        if np.any(lengths <= 0):
            raise InputError(f"waypoint {int(np.argmin(lengths)) + 1} repeats the one before it")
        object.__setattr__(self, "north", tuple(map(float, n)))
        object.__setattr__(self, "east", tuple(map(float, e)))

    @property
    def n_segments(self) -> int:
        """Number of legs."""
        return len(self.north) - 1

    @property
    def angles(self) -> np.ndarray:
        """Path angle of each segment [rad] (from North, clockwise)."""
        return np.arctan2(np.diff(self.east), np.diff(self.north))

    @property
    def lengths(self) -> np.ndarray:
        """Length of each segment [m]."""
        return np.hypot(np.diff(self.north), np.diff(self.east))

    def track(self, turn_radius: float | None = None, spacing: float | None = None,
              extend: float = 0.0) -> np.ndarray:
        """The intended track as ``(n, 2)`` North/East points: the legs, joined by arcs of
        ``turn_radius`` tangent to both legs (corners without one).

        Parameters
        ----------
        turn_radius : float, optional
            Radius of the turns [m].
        spacing : float, optional
            Largest distance between points [m] (default: 1/500 of the path length).
        extend : float
            Length [m] by which the last leg goes on past the last waypoint (guidance keeps to it).
        """
        n, e = np.asarray(self.north), np.asarray(self.east)
        a = self.angles
        spacing = spacing or float(np.sum(self.lengths)) / 500
        starts, ends = [np.array([n[0], e[0]])], []
        arcs = []
        for k in range(1, len(n) - 1):
            turn = float(np.angle(np.exp(1j * (a[k] - a[k - 1]))))
            d = (turn_radius or 0.0) * np.tan(abs(turn) / 2)
            p = np.array([n[k], e[k]])
            ends.append(p - d * np.array([np.cos(a[k - 1]), np.sin(a[k - 1])]))
            starts.append(p + d * np.array([np.cos(a[k]), np.sin(a[k])]))
            arcs.append((ends[-1], a[k - 1], turn))
        ends.append(np.array([n[-1], e[-1]]) + extend * np.array([np.cos(a[-1]), np.sin(a[-1])]))
        pts = []
        for k, (p0, p1) in enumerate(zip(starts, ends)):
            m = max(2, int(np.ceil(np.hypot(*(p1 - p0)) / spacing)) + 1)
            pts.append(p0 + np.linspace(0.0, 1.0, m)[:, None] * (p1 - p0))
            if k < len(arcs) and turn_radius:
                p, heading, turn = arcs[k]
                side = np.sign(turn)
                centre = p + side * turn_radius * np.array([-np.sin(heading), np.cos(heading)])
                steps = max(3, int(abs(turn) * turn_radius / spacing))
                phi = heading - side * np.pi / 2 + np.linspace(0.0, turn, steps)
                pts.append(centre + turn_radius * np.column_stack([np.cos(phi + np.pi), np.sin(phi + np.pi)]) * -1)
        return np.vstack(pts)

    def errors(self, north, east, segment: int):
        """Along-track and cross-track errors [m] of positions against a leg.

        Parameters
        ----------
        north, east : float or array
            Positions [m].
        segment : int
            Leg index.
        """
        a = self.angles[segment]
        dn, de = np.asarray(north) - self.north[segment], np.asarray(east) - self.east[segment]
        return dn * np.cos(a) + de * np.sin(a), -dn * np.sin(a) + de * np.cos(a)


@dataclass(frozen=True)
class LOSGuidance:
    """Lookahead-based LOS or integral LOS guidance through :class:`Waypoints`.

    Parameters
    ----------
    waypoints : Waypoints
    lookahead : float
        Lookahead distance ``Delta`` [m].
    acceptance : float
        Radius ``R`` of the circle of acceptance around each waypoint [m].
    kappa : float
        Integral gain of ILOS [m/s] (0: plain LOS); ``y_int`` is in seconds.
    turn_radius : float, optional
        Radius [m] of the turns between legs: the leg changes at the wheel-over point
        (:meth:`wheel_over`) instead of at the circle of acceptance.
    lead : float
        On a turn, the course command leads the path course by ``lead`` times its rate ``U / R``
        [s]: the ramp-following lag of the autopilot's reference model (``(2 zeta + 1) / wn`` for
        the third-order model), which would otherwise leave the ship that far behind the turn.
    at_switch : {"keep", "reset", "project"}
        What the ILOS integral does where one path element ends and the next begins: ``"keep"`` it
        (MSS ``ILOSpsi``), ``"reset"`` it to zero, or ``"project"`` it: scale it by the cosine of the
        change of path course, the share of the old leg's cross drift that lies across the new one
        (the drift of a current or a wind is fixed in the earth frame).
    integrate_within : float, optional
        Conditional integration: the ILOS integral moves only while the cross-track error is within
        this many lookahead distances (None: always), so that the large errors of a turn's
        transient do not wind it up.
    """

    waypoints: Waypoints
    lookahead: float
    acceptance: float
    kappa: float = 0.0
    turn_radius: float | None = None
    lead: float = 0.0
    at_switch: str = "project"
    integrate_within: float | None = 0.5

    #: Logged signals (closed-loop record columns; ``segment``: the leg, counted from its
    #: wheel-over point when the guidance turns).
    LOG = ("cross_track", "along_track", "segment", "y_int")
    memory_size = 2          # segment index, ILOS integral

    def __post_init__(self):
        for name in ("lookahead", "acceptance"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise InputError(f"LOS {name} must be positive, got {v}")
        if not (np.isfinite(self.kappa) and self.kappa >= 0):
            raise InputError(f"ILOS kappa must be >= 0, got {self.kappa}")
        if self.integrate_within is not None and not (np.isfinite(self.integrate_within) and self.integrate_within > 0):
            raise InputError(f"ILOS integrate_within must be positive, got {self.integrate_within}")
        if self.at_switch not in ("keep", "reset", "project"):
            raise InputError(f"ILOS at_switch must be 'keep', 'reset' or 'project', got {self.at_switch!r}")
        if self.turn_radius is not None and not (np.isfinite(self.turn_radius) and self.turn_radius > 0):
            raise InputError(f"turn_radius must be positive, got {self.turn_radius}")
        if self.turn_radius is not None:
            turns = np.abs(np.angle(np.exp(1j * np.diff(self.waypoints.angles))))
            if np.any(turns > np.radians(170.0)):
                raise InputError(f"turns of more than 170 deg at waypoint(s) "
                                 f"{[int(k) + 1 for k in np.flatnonzero(turns > np.radians(170.0))]}: no wheel-over "
                                 "point for them; give turn_radius=None")
            d, lengths = self.wheel_over(), self.waypoints.lengths
            short = [k for k in range(len(d)) if d[k] >= lengths[k] or (k + 1 < len(d) and d[k] + d[k + 1]
                                                                          >= lengths[k + 1])]
            if short:
                raise InputError(f"leg(s) {[k + 1 for k in short]} are too short for turns of radius "
                                 f"{self.turn_radius:.4g} m (wheel-over distances {np.round(d, 1).tolist()} m)")

    def wheel_over(self) -> np.ndarray:
        """Distance [m] before each inner waypoint at which the turn onto the next leg starts:
        ``turn_radius tan(|Delta chi| / 2)`` (zeros without a turn radius)."""
        turns = np.abs(np.angle(np.exp(1j * np.diff(self.waypoints.angles))))
        if self.turn_radius is None:
            return np.zeros(turns.size)
        return self.turn_radius * np.tan(turns / 2)

    @classmethod
    def for_design(cls, waypoints: Waypoints, design, *, integral: bool = False,
                   wheel_over: bool = True) -> "LOSGuidance":
        """Defaults from an autopilot design, sized by the ship: the lookahead ``Delta = max(2 L,
        3 U / wn_ref)`` (two ship lengths, Fossen 2021 recommends 1.5 to 2.5; longer where the path
        loop would otherwise be less than three times slower than the course loop's reference model;
        MSS uses ``Delta = 500 m`` = 3.1 L for the Mariner), acceptance radius ``R = Delta``; turns
        at 70 % of the preset rate of turn (the rest left to correct the track), ``turn_radius = U /
        (0.7 r_max)``, starting at the wheel-over points, the course command leading by the
        reference model's ramp lag ``(2 zeta_ref + 1) / wn_ref``; with
        ``integral`` the ILOS gain ``kappa = U / 4`` [m/s], which makes the linearised cross-track
        dynamics ``s^2 + (U/Delta) s + U kappa/Delta^2`` critically damped (the course loop's lag
        takes damping away; ``kappa = U/2`` oscillates).

        Parameters
        ----------
        waypoints : Waypoints
        design : Design
            The autopilot (its speed and reference-model bandwidth).
        integral : bool
            Integral LOS.
        wheel_over : bool
            Change legs at the wheel-over points (else at the circle of acceptance).
        """
        s = design.settings
        v = design.plant.model.vessel
        L = v.L_pp if v is not None else 0.0
        Delta = max(3.0 * s.speed / s.wn_ref, 2.0 * L)
        radius = s.speed / (0.7 * s.r_max) if wheel_over else None
        lead = (2 * s.zeta_ref + 1) / s.wn_ref if wheel_over else 0.0
        return cls(waypoints, Delta, Delta, s.speed / 4 if integral else 0.0, radius, lead)

    def memory0(self) -> np.ndarray:
        """Initial memory: first leg, no integral."""
        return np.zeros(2)

    def symbolic_step(self, mem, north, east, U, angle, dt) -> dict:
        """One sample on CasADi expressions: the course command and the next memory.

        Parameters
        ----------
        mem : casadi.SX
            Leg index and ILOS integral.
        north, east : casadi.SX
            Position [m].
        U : casadi.SX
            Speed [m/s] (unused by LOS; kept for speed-dependent laws).
        angle : casadi.SX
            Course or heading [rad] (unused by LOS).
        dt : float
            Sample period [s].
        """
        if self.turn_radius is not None:
            return self._track_step(mem, north, east, U, dt)
        wp = self.waypoints
        k, y_int = mem[0], mem[1]
        n_seg = wp.n_segments
        angles, lengths = wp.angles, wp.lengths

        def pick(values):
            return sum(ca.if_else(k == i, float(v), 0.0) for i, v in enumerate(values))

        a, length = pick(angles), pick(lengths)
        n0, e0 = pick(wp.north[:-1]), pick(wp.east[:-1])
        n1, e1 = pick(wp.north[1:]), pick(wp.east[1:])
        dn, de = north - n0, east - e0
        s = dn * ca.cos(a) + de * ca.sin(a)
        y_e = -dn * ca.sin(a) + de * ca.cos(a)
        Delta, kappa = self.lookahead, self.kappa
        chi = wrap_sym(a - ca.atan((y_e + kappa * y_int) / Delta))
        y_int_next = self._integrate(y_int, y_e, dt)
        reached = ca.logic_or((north - n1) ** 2 + (east - e1) ** 2 < self.acceptance**2, s > length)
        switch = ca.logic_and(reached, k < n_seg - 1)
        k_next = ca.if_else(switch, k + 1, k)
        y_int_next = self._integral_at_switch(switch, y_int_next, pick(np.cos(np.diff(angles)).tolist() + [1.0]))
        return {"memory": ca.vertcat(k_next, y_int_next), "chi_ref": chi, "cross_track": y_e, "along_track": s,
                "segment": k, "y_int": y_int}

    def _integrate(self, y_int, y_e, dt):
        """The ILOS integral one sample on (Borhaug et al. 2008), conditional on ``integrate_within``."""
        Delta, kappa = self.lookahead, self.kappa
        if kappa <= 0:
            return y_int
        step = dt * Delta * y_e / (Delta**2 + (y_e + kappa * y_int) ** 2)
        if self.integrate_within is not None:
            step = ca.if_else(ca.fabs(y_e) <= self.integrate_within * Delta, step, 0.0)
        return y_int + step

    def _integral_at_switch(self, switch, y_int, cos_turn):
        """The ILOS integral on the next path element (see ``at_switch``)."""
        if self.at_switch == "keep":
            return y_int
        return ca.if_else(switch, 0.0 if self.at_switch == "reset" else cos_turn * y_int, y_int)

    def elements(self) -> list[dict]:
        """The track as elements: legs (``kind="line"``, from the end of one turn to the next
        wheel-over point) and turns (``kind="arc"``: centre, start angle seen from the centre, turn
        angle, side ``+1`` for a turn to starboard), alternating, for :attr:`turn_radius`."""
        wp, R = self.waypoints, self.turn_radius
        a, n, e = wp.angles, np.asarray(wp.north), np.asarray(wp.east)
        d = self.wheel_over()
        out, start = [], np.array([n[0], e[0]])
        for k in range(wp.n_segments):
            fwd = np.array([np.cos(a[k]), np.sin(a[k])])
            end = np.array([n[k + 1], e[k + 1]]) - (d[k] if k < len(d) else 0.0) * fwd
            out.append({"kind": "line", "start": start, "angle": float(a[k]), "length": float(fwd @ (end - start))})
            if k < len(d):
                turn = float(np.angle(np.exp(1j * (a[k + 1] - a[k]))))
                side = 1.0 if turn >= 0 else -1.0
                centre = end + side * R * np.array([-np.sin(a[k]), np.cos(a[k])])
                phi0 = float(np.arctan2(end[1] - centre[1], end[0] - centre[0]))
                out.append({"kind": "arc", "centre": centre, "phi0": phi0, "turn": turn, "side": side})
                start = np.array([n[k + 1], e[k + 1]]) + d[k] * np.array([np.cos(a[k + 1]), np.sin(a[k + 1])])
        return out

    def _track_step(self, mem, north, east, U, dt) -> dict:
        """LOS along legs and turns: on a turn of radius ``R`` about ``c`` the path course is the
        tangent, ``phi + side pi/2`` with ``phi`` the ship's bearing from ``c``, and the cross-track
        error ``side (R - |p - c|)`` (positive to starboard of the path)."""
        k, y_int = mem[0], mem[1]
        R, Delta, kappa = self.turn_radius, self.lookahead, self.kappa
        chis, errs, along, done, legs = [], [], [], [], []
        elements = self.elements()
        for i, el in enumerate(elements):
            if el["kind"] == "line":
                a = el["angle"]
                dn, de = north - el["start"][0], east - el["start"][1]
                s_i = dn * np.cos(a) + de * np.sin(a)
                y_i = -dn * np.sin(a) + de * np.cos(a)
                path = a
                fin = s_i > el["length"]
                legs.append(i // 2)
            else:
                dn, de = north - el["centre"][0], east - el["centre"][1]
                phi = ca.atan2(de, dn)
                swept = el["side"] * wrap_sym(phi - el["phi0"])
                s_i = R * swept
                y_i = el["side"] * (R - ca.sqrt(dn**2 + de**2))
                path = phi + el["side"] * np.pi / 2 + el["side"] * self.lead * U / R
                fin = swept > abs(el["turn"])
                legs.append((i + 1) // 2)
            chis.append(wrap_sym(path - ca.atan((y_i + kappa * y_int) / Delta)))
            errs.append(y_i)
            along.append(s_i)
            done.append(fin)

        def pick(values):
            return sum(ca.if_else(k == i, v, 0.0) for i, v in enumerate(values))

        chi, y_e, s = pick(chis), pick(errs), pick(along)
        y_int_next = self._integrate(y_int, y_e, dt)
        switch = ca.logic_and(pick(done), k < len(elements) - 1)
        k_next = ca.if_else(switch, k + 1, k)
        turns = [np.cos(el["turn"]) if el["kind"] == "arc" else 1.0 for el in elements]
        # the path course turns along the arc: project once, when the arc ends
        y_int_next = self._integral_at_switch(switch, y_int_next, pick([float(v) for v in turns]))
        return {"memory": ca.vertcat(k_next, y_int_next), "chi_ref": chi, "cross_track": y_e, "along_track": s,
                "segment": pick([float(v) for v in legs]), "y_int": y_int}

    def function(self, dt: float) -> ca.Function:
        """``los(memory, north, east, U, angle) -> (memory_next, chi_ref, cross_track, along_track,
        segment, y_int)``.

        Parameters
        ----------
        dt : float
            Sample period [s].
        """
        mem = ca.SX.sym("memory", 2)
        n, e, U, ang = (ca.SX.sym(v) for v in ("north", "east", "U", "angle"))
        out = self.symbolic_step(mem, n, e, U, ang, dt)
        names = ["chi_ref", *self.LOG]
        return ca.Function("los", [mem, n, e, U, ang], [out["memory"]] + [out[k] for k in names],
                           ["memory", "north", "east", "U", "angle"], ["memory_next", *names])


def track_deviation(data: Dataset, guidance: "LOSGuidance") -> np.ndarray:
    """Distance [m] of the ship from the intended track (legs joined by the guidance's turns,
    :meth:`Waypoints.track`; the last leg continued past its waypoint, as the guidance does) at each
    sample of a record.

    Parameters
    ----------
    data : Dataset
        A closed-loop record (columns ``north``, ``east``).
    guidance : LOSGuidance
    """
    from scipy.spatial import cKDTree

    wp = guidance.waypoints
    beyond = float(np.max(np.hypot(data["north"] - wp.north[-1], data["east"] - wp.east[-1])))
    pts = wp.track(guidance.turn_radius, extend=beyond)
    dist, _ = cKDTree(pts).query(np.column_stack([data["north"], data["east"]]))
    return dist


def cross_track_metrics(data: Dataset, *, start: float = 0.0, end: float | None = None) -> dict:
    """Cross-track error measures of a path-following record [m]: RMS, maximum, mean (the steady
    offset a current leaves without integral action) and the final value.

    Parameters
    ----------
    data : Dataset
        A closed-loop record with guidance (column ``cross_track``).
    start, end : float
        Time window [s] (``end`` None: to the end).
    """
    sel = (data.t >= start) & (data.t <= (data.t[-1] if end is None else end))
    if sel.sum() < 3:
        raise InputError(f"fewer than 3 samples between t = {start:g} s and {end} s")
    y = data["cross_track"][sel]
    return {"cross_track_rms_m": float(np.sqrt(np.mean(y**2))), "cross_track_max_m": float(np.max(np.abs(y))),
            "cross_track_mean_m": float(np.mean(y)), "cross_track_final_m": float(y[-1])}
