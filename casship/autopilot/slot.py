"""A controller slot of the compiled closed loop: any linear python-control controller.

:class:`LinearController` takes a :class:`control.StateSpace` or :class:`control.TransferFunction`
(continuous, sampled at the loop period by ``control.sample_system``; or discrete at the loop
period) whose inputs are named among :data:`SIGNALS` and whose one output is the steering command,
and runs it inside the compiled loop in place of the PID law: the reference model gives ``chi_d,
r_d, a_d``, the loop's estimator (or sensors) ``chi, r``. The measured angle enters as ``chi_d +
wrap(chi - chi_d)``, so the linear controller sees a continuous course error across +-180 deg.

Anti-windup against the steering gear (the observer form, Astrom & Wittenmark 1997, Sec. 9.4):
the controller's state is driven by the steering the gear can follow, ::

    u = C x + D y,   x+ = A x + B y + L (u_gear - u),

where ``u_gear`` is the command clipped at the steering limit and, when the gear's rate limit
binds this sample, the command the gear's servo would follow unlimited to the same change; ``L``
makes ``A - L C`` stable (``control.dlqr`` on the dual system). Without saturation ``u_gear = u``
and the controller is exactly the discretised linear system.
"""
from __future__ import annotations

import casadi as ca
import control
import numpy as np

from ..angles import wrap_sym
from .law import Actuator, law_function
from .reference import ReferenceModel
from ..errors import InputError, InputTypeError

__all__ = ["LinearController", "SIGNALS"]

#: Input names a slotted controller may use: the reference model's ``chi_d, r_d, a_d``, the fed-back
#: angle and rate ``chi, r`` (also under the sensor names ``psi_m, r_m``) and the wrapped error ``e``.
SIGNALS = ("chi_d", "r_d", "a_d", "chi", "r", "psi_m", "r_m", "e")


class LinearController:
    """A python-control controller as the law of the compiled closed loop (see the module docstring).

    Parameters
    ----------
    sys : control.StateSpace or control.TransferFunction
        The controller; input labels among :data:`SIGNALS` (a single-input transfer function
        without labels is taken as acting on ``e``), one output (the steering command).
    dt : float
        Loop period [s]. A continuous ``sys`` is sampled at it; a discrete one must have it.
    reference : ReferenceModel
        The reference model in front of the controller.
    actuator : Actuator
        The steering gear (its limits for the anti-windup and the command limit).
    method : str
        ``control.sample_system`` method for a continuous controller (default ``"zoh"``).
    anti_windup : bool
        Drive the state by the steering the gear follows (observer form).

    Examples
    --------
    >>> import control
    >>> from casship.autopilot import Actuator, ReferenceModel
    >>> pi = control.tf([2.0, 0.1], [1.0, 0.0], inputs="e", outputs="delta_c")
    >>> ctrl = LinearController(-pi, 0.1, ReferenceModel(0.1), Actuator(0.6, 0.04, 1.0))
    >>> ctrl.A.shape, ctrl.inputs
    ((1, 1), ('e',))
    """

    def __init__(self, sys, dt: float, reference: ReferenceModel, actuator: Actuator, *, method: str = "zoh",
                 anti_windup: bool = True):
        if isinstance(sys, control.TransferFunction):
            labels = list(sys.input_labels)
            if sys.ninputs == 1 and labels[0] not in SIGNALS:
                labels = ["e"]
            sys = control.ss(sys, inputs=labels, outputs=list(sys.output_labels))
        if not isinstance(sys, control.StateSpace):
            raise InputTypeError(f"the controller must be a control.StateSpace or TransferFunction, got "
                                 f"{type(sys).__name__}")
        if not (np.isfinite(dt) and dt > 0):
            raise InputError(f"dt must be positive, got {dt}")
        if sys.noutputs != 1:
            raise InputError(f"the controller must have one output (the steering command), it has {sys.noutputs}: "
                             f"{list(sys.output_labels)}")
        unknown = [n for n in sys.input_labels if n not in SIGNALS]
        if unknown:
            raise InputError(f"controller input(s) {unknown} are not loop signals; use {list(SIGNALS)}")
        if sys.isctime():
            sys = control.sample_system(sys, dt, method=method)
        elif not np.isclose(float(sys.dt), dt, rtol=1e-9):
            raise InputError(f"the discrete controller's sample time {sys.dt} differs from the loop period {dt}")
        self.sys, self.dt, self.reference, self.actuator = sys, float(dt), reference, actuator
        self.A, self.B = np.asarray(sys.A, float), np.asarray(sys.B, float)
        self.C, self.D = np.asarray(sys.C, float), np.asarray(sys.D, float)
        self.inputs = tuple(sys.input_labels)
        self.anti_windup = bool(anti_windup)
        n = self.A.shape[0]
        self.L = np.zeros((n, 1))
        if anti_windup and n:
            try:
                K, _, _ = control.dlqr(self.A.T, self.C.T, np.eye(n), np.eye(1))
            except Exception as err:          # python-control raises several types here
                raise InputError(f"anti-windup needs (A, C) of the controller detectable: {err}") from None
            self.L = np.asarray(K, float).T
        self.MEMORY = ("chi_d", "r_d", "a_d") + tuple(f"x{i}" for i in range(n))

    def __repr__(self) -> str:
        return (f"LinearController(states={self.A.shape[0]}, inputs={list(self.inputs)}, dt={self.dt:g}, "
                f"anti_windup={self.anti_windup})")

    def memory0(self, chi0: float = 0.0) -> np.ndarray:
        """Reference model at rest at ``chi0``, controller state zero.

        Parameters
        ----------
        chi0 : float
            Initial course (or heading) [rad].
        """
        return np.concatenate([[chi0, 0.0, 0.0], np.zeros(self.A.shape[0])])

    def gear_command(self, u, steer, dt):
        """The command the steering gear follows this sample (``u`` clipped at the limit; where the
        rate limit binds, the command whose unlimited servo step equals the limited change).

        Parameters
        ----------
        u : casadi.SX
            Controller output.
        steer : casadi.SX
            Present steering.
        dt : float
            Sample period [s].
        """
        a = self.actuator
        cmd = ca.fmin(ca.fmax(u, -a.steer_max), a.steer_max) if np.isfinite(a.steer_max) else u
        if not np.isfinite(a.rate_max) or steer is None:
            return cmd
        gain = 1 - np.exp(-dt / a.T) if a.T > 0 else 1.0
        change = (cmd - steer) * gain
        step = a.rate_max * dt
        return ca.if_else(ca.fabs(change) > step, steer + ca.fmin(ca.fmax(change, -step), step) / gain, cmd)

    def symbolic_step(self, mem, ref, chi, r, dt, speed=None, steer=None, bias=None) -> dict:
        """One sample: reference model, controller output and state update (CasADi expressions).

        Parameters
        ----------
        mem, ref, chi, r, dt, speed, steer, bias
            As for :meth:`Autopilot.symbolic_step <casship.autopilot.law.Autopilot.symbolic_step>`, with
            ``mem`` as in :attr:`MEMORY`, ``dt`` the controller's period, ``steer`` driving the
            anti-windup against the rate limit; ``speed`` and ``bias`` are unused.
        """
        chi_d, r_d, a_d = mem[0], mem[1], mem[2]
        x = mem[3:]
        e = wrap_sym(chi - chi_d)
        values = {"chi_d": chi_d, "r_d": r_d, "a_d": a_d, "chi": chi_d + e, "r": r, "psi_m": chi_d + e, "r_m": r,
                  "e": e}
        y = ca.vertcat(*[values[n] for n in self.inputs])
        u = ca.mtimes(ca.DM(self.C), x) + ca.mtimes(ca.DM(self.D), y) if x.numel() else ca.mtimes(ca.DM(self.D), y)
        sat = self.gear_command(u, steer, self.dt) if np.isfinite(self.actuator.steer_max) else u
        cmd = self.gear_command(u, None, self.dt)          # the command clipped at the angle limit
        if x.numel():
            x_next = ca.mtimes(ca.DM(self.A), x) + ca.mtimes(ca.DM(self.B), y)
            if self.anti_windup:
                x_next = x_next + ca.mtimes(ca.DM(self.L), sat - u)
        else:
            x_next = x
        xd_next = self.reference.symbolic_step(mem[:3], ref, dt)
        return {"memory": ca.vertcat(xd_next, x_next), "steer": cmd, "chi_d": chi_d, "r_d": r_d, "a_d": a_d,
                "e": e, "raw": u}

    @property
    def function(self) -> ca.Function:
        """``controller(memory, ref, chi, r, dt, speed, steering, bias) -> (memory_next, steer, chi_d, r_d,
        a_d, e)``."""
        return law_function(self, "controller")
