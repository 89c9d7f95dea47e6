"""Third-order reference model with turn-rate saturation (MSS ``refModel.m``; Fossen 2021, Sec. 12.1).

The model turns a course (or heading) command into a smooth desired course ``chi_d``, rate ``r_d``
and acceleration ``a_d``, which the control law uses as set-point and feed-forward. Its linear part
is a labelled python-control system (:meth:`ReferenceModel.system`); the discrete step with the rate
saturation is a CasADi expression (:meth:`ReferenceModel.symbolic_step`) that the closed loop composes.
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import control
import numpy as np

from ..angles import wrap_sym
from ..errors import InputError

__all__ = ["ReferenceModel", "reference_step"]


def reference_step(xd, ref, dt, wn, zeta, r_max):
    """One Euler step of ``[chi_d, r_d, a_d]`` with numbers or CasADi expressions for ``wn, zeta,
    r_max`` (``r_max = inf``: no rate saturation); see :class:`ReferenceModel`.

    Parameters
    ----------
    xd : casadi.SX
        ``[chi_d, r_d, a_d]``.
    ref : casadi.SX
        Command [rad].
    dt : casadi.SX or float
        Step [s].
    wn, zeta, r_max : float or casadi.SX
        Natural frequency [rad/s], relative damping, rate limit [rad/s].
    """
    e = wrap_sym(ref - xd[0])
    jerk = wn**3 * e - (2 * zeta + 1) * wn**2 * xd[1] - (2 * zeta + 1) * wn * xd[2]
    r_next = xd[1] + dt * xd[2]
    a_next = xd[2] + dt * jerk
    if not (isinstance(r_max, float) and not np.isfinite(r_max)):
        # at the rate limit the acceleration pushing further out is held at 0: left to integrate (as
        # in MSS refModel) it winds up and its feed-forward m a_d drives the ship past the preset rate
        # and near the limit it is capped so that the rate approaches the limit smoothly (at the
        # model's own rate (2 zeta + 1) wn) instead of hitting it with full acceleration
        r_next = ca.fmin(ca.fmax(r_next, -r_max), r_max)
        k = (2 * zeta + 1) * wn
        a_next = ca.fmin(ca.fmax(a_next, -k * (r_max + r_next)), k * (r_max - r_next))
    return ca.vertcat(wrap_sym(xd[0] + dt * xd[1]), r_next, a_next)


@dataclass(frozen=True)
class ReferenceModel:
    """Third-order reference model with rate saturation.

    ``a_d' = wn^3 (ref - chi_d) - (2 zeta + 1) wn^2 r_d - (2 zeta + 1) wn a_d``, ``r_d`` saturated
    at ``r_max`` (Euler steps, as MSS). Unlike MSS, ``a_d`` is capped at ``(2 zeta + 1) wn (r_max -
    |r_d|)`` towards the limit, so the rate approaches the limit smoothly and ``a_d`` cannot wind up
    while ``r_d`` sits there (with MSS's clipping of the rate alone the acceleration keeps growing,
    and its feed-forward drives the ship past the preset rate). ``r_max = inf`` gives the linear filter
    ``wn^3 / ((s + wn)(s^2 + 2 zeta wn s + wn^2))``. The command error ``ref - chi_d`` is taken on
    the circle, so a command across +-180 deg turns the short way.

    Parameters
    ----------
    wn : float
        Natural frequency [rad/s].
    zeta : float
        Relative damping.
    r_max : float
        Turn-rate limit [rad/s] (a preset rate of turn).

    Examples
    --------
    >>> import numpy as np
    >>> ref = ReferenceModel(0.1, 1.0, np.radians(1.0))
    >>> X = ref.response(np.arange(0.0, 300.0, 0.1), np.radians(20))
    >>> round(float(np.degrees(X[-1, 0])), 3)
    20.0
    """

    wn: float
    zeta: float = 1.0
    r_max: float = float("inf")

    def __post_init__(self):
        if not (np.isfinite(self.wn) and self.wn > 0):
            raise InputError(f"reference model wn must be positive, got {self.wn}")
        if not (np.isfinite(self.zeta) and self.zeta > 0):
            raise InputError(f"reference model zeta must be positive, got {self.zeta}")
        if not self.r_max > 0:
            raise InputError(f"r_max must be positive, got {self.r_max}")

    def symbolic_step(self, xd, ref, dt):
        """One Euler step of ``[chi_d, r_d, a_d]`` (CasADi expressions) with this model's numbers.

        Parameters
        ----------
        xd, ref, dt
            As for :func:`reference_step`.
        """
        return reference_step(xd, ref, dt, self.wn, self.zeta, self.r_max)

    def system(self, name: str = "reference") -> control.StateSpace:
        """The linear model (no rate saturation) as a labelled :class:`control.StateSpace`: input
        ``chi_ref``, outputs (= states) ``chi_d, r_d, a_d``.

        Parameters
        ----------
        name : str
            System name.
        """
        wn, z = self.wn, self.zeta
        A = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0],
                      [-wn**3, -(2 * z + 1) * wn**2, -(2 * z + 1) * wn]])
        B = np.array([[0.0], [0.0], [wn**3]])
        labels = ["chi_d", "r_d", "a_d"]
        return control.ss(A, B, np.eye(3), np.zeros((3, 1)), states=labels, inputs=["chi_ref"], outputs=labels,
                          name=name)

    def tf(self) -> control.TransferFunction:
        """Transfer function ``chi_d / chi_ref``."""
        wn, z = self.wn, self.zeta
        return control.tf([wn**3], np.polymul([1, wn], [1, 2 * z * wn, wn**2]), inputs="chi_ref", outputs="chi_d")

    def response(self, t, ref, x0=(0.0, 0.0, 0.0)) -> np.ndarray:
        """``(N, 3)`` array of ``chi_d, r_d, a_d`` for the command ``ref`` on the uniform grid ``t``
        (one compiled fold).

        Parameters
        ----------
        t : array
            Uniform time grid [s].
        ref : float or array
            Command [rad].
        x0 : sequence of float
            Initial ``chi_d, r_d, a_d``.
        """
        t = np.asarray(t, dtype=float)
        if t.ndim != 1 or t.size < 2:
            raise InputError("response needs a time grid of at least 2 samples")
        dt = float(t[1] - t[0])
        xd, r, h = ca.SX.sym("xd", 3), ca.SX.sym("ref"), ca.SX.sym("dt")
        F = ca.Function("ref_step", [xd, r, h], [self.symbolic_step(xd, r, h)], ["xd", "ref", "dt"], ["xd_next"])
        refs = np.broadcast_to(np.asarray(ref, dtype=float), t.shape)
        X = np.asarray(F.mapaccum(t.size - 1)(np.asarray(x0, float), refs[:-1][None, :], dt))
        return np.vstack([np.asarray(x0, float), X.T])
