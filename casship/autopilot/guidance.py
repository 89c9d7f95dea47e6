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
the segment's end, or passes the end along the track; the ILOS integral restarts there.
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..angles import wrap_sym
from ..data import Dataset

__all__ = ["Waypoints", "LOSGuidance", "cross_track_metrics"]


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
            raise ValueError(f"waypoints need at least two North/East pairs of equal length, got {n.size} and {e.size}")
        if not (np.all(np.isfinite(n)) and np.all(np.isfinite(e))):
            raise ValueError("waypoint coordinates must be finite")
        lengths = np.hypot(np.diff(n), np.diff(e))
        if np.any(lengths <= 0):
            raise ValueError(f"waypoint {int(np.argmin(lengths)) + 1} repeats the one before it")
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
    """

    waypoints: Waypoints
    lookahead: float
    acceptance: float
    kappa: float = 0.0

    #: Logged signals (closed-loop record columns).
    LOG = ("cross_track", "along_track", "segment", "y_int")
    memory_size = 2          # segment index, ILOS integral

    def __post_init__(self):
        for name in ("lookahead", "acceptance"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"LOS {name} must be positive, got {v}")
        if not (np.isfinite(self.kappa) and self.kappa >= 0):
            raise ValueError(f"ILOS kappa must be >= 0, got {self.kappa}")

    @classmethod
    def for_design(cls, waypoints: Waypoints, design, *, integral: bool = False) -> "LOSGuidance":
        """Defaults from an autopilot design: the path loop five times slower than the course loop's
        reference model, ``Delta = max(5 U / wn_ref, 2 L)`` (MSS uses ``Delta = 500 m`` = 3.1 L for the
        Mariner), acceptance radius ``R = Delta``; with ``integral`` the ILOS gain ``kappa = U / 4``
        [m/s], which makes the linearised cross-track dynamics ``s^2 + (U/Delta) s + U kappa/Delta^2``
        critically damped (the course loop's lag takes damping away; ``kappa = U/2`` oscillates).

        Parameters
        ----------
        waypoints : Waypoints
        design : Design
            The autopilot (its speed and reference-model bandwidth).
        integral : bool
            Integral LOS.
        """
        s = design.settings
        v = design.plant.model.vessel
        L = v.L_pp if v is not None else 0.0
        Delta = max(5.0 * s.speed / s.wn_ref, 2.0 * L)
        return cls(waypoints, Delta, Delta, s.speed / 4 if integral else 0.0)

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
        y_int_next = y_int + dt * Delta * y_e / (Delta**2 + (y_e + kappa * y_int) ** 2) if kappa > 0 else y_int
        reached = ca.logic_or((north - n1) ** 2 + (east - e1) ** 2 < self.acceptance**2, s > length)
        switch = ca.logic_and(reached, k < n_seg - 1)
        k_next = ca.if_else(switch, k + 1, k)
        y_int_next = ca.if_else(switch, 0.0, y_int_next)       # a new leg starts without the old integral
        return {"memory": ca.vertcat(k_next, y_int_next), "chi_ref": chi, "cross_track": y_e, "along_track": s,
                "segment": k, "y_int": y_int}

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
        raise ValueError(f"fewer than 3 samples between t = {start:g} s and {end} s")
    y = data["cross_track"][sel]
    return {"cross_track_rms_m": float(np.sqrt(np.mean(y**2))), "cross_track_max_m": float(np.max(np.abs(y))),
            "cross_track_mean_m": float(np.mean(y)), "cross_track_final_m": float(y[-1])}
