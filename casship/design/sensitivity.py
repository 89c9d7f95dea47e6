"""A manoeuvre simulated symbolically on a fixed grid, and its exact parameter sensitivities.

:class:`ManoeuvreFold` folds the model's discrete step (:func:`casship.discretize`, RK4 by default)
over a grid of ``n`` steps of ``dt`` with ``mapaccum``. The uncertain parameters ``theta`` (named)
replace their entries of the parameter vector; the inputs are a CasADi expression, so that a rudder
sequence, or the switching time of a closed-loop rudder law, can itself be a symbol. Sensitivities
are CasADi Jacobians of the fold (forward mode over the few parameters), never finite differences.
"""
from __future__ import annotations

from typing import Sequence

import casadi as ca
import numpy as np

from ..discretize import discretize
from ..model import Model
from ..errors import InputError

__all__ = ["ManoeuvreFold"]


class ManoeuvreFold:
    """Symbolic simulation of one record of ``n`` steps of ``dt`` from a fixed initial state.

    Parameters
    ----------
    model : Model
        A continuous model.
    names : sequence of str
        The uncertain parameters (``theta``), model parameter names.
    p : array_like
        The full parameter vector (values of the parameters not in ``names``, and the point).
    dt : float
        Step [s].
    n : int
        Number of steps (the record has ``n + 1`` samples).
    x0 : array_like (nx,)
        Initial state (fixed: it does not depend on ``theta``).
    method : str
        Discretisation (see :func:`casship.discretize`).
    """

    def __init__(self, model: Model, names: Sequence[str], p, dt: float, n: int, x0, method: str = "rk4"):
        unknown = [q for q in names if q not in model.param_names]
        if unknown:
            raise InputError(f"model {model.name!r} has no parameter(s) {unknown}")
        if n < 1:
            raise InputError(f"a manoeuvre needs at least one step, got n = {n}")
        self.model, self.names, self.dt, self.n = model, tuple(names), float(dt), int(n)
        self.p = np.asarray(model.params(p), dtype=float)
        self.x0 = np.asarray(x0, dtype=float).reshape(-1)
        self.index = model.indices(self.names, "param")
        self.dmodel = discretize(model, self.dt, method=method)
        self._fold = self.dmodel.F.mapaccum(self.n)

    @property
    def theta0(self) -> np.ndarray:
        """The uncertain parameters' values in ``p``."""
        return self.p[self.index]

    def t(self) -> np.ndarray:
        """The sample times ``0, dt, ..., n dt``."""
        return np.arange(self.n + 1) * self.dt

    def param_vector(self, theta):
        """The full parameter vector with ``theta`` in place (symbolic if ``theta`` is).

        Parameters
        ----------
        theta : casadi.MX or array_like (k,)
        """
        P = ca.MX(ca.DM(self.p)) if isinstance(theta, ca.MX) else ca.DM(self.p)
        for j, i in enumerate(self.index):
            P[i] = theta[j]
        return P

    def states(self, theta, U):
        """States ``(nx, n + 1)`` for parameters ``theta`` and inputs ``U`` (``nu x n``, held per step).

        Parameters
        ----------
        theta : casadi.MX or array_like (k,)
        U : casadi.MX or array (nu, n)
        """
        X = self._fold(self.x0, U, self.param_vector(theta), ca.DM.zeros(self.model.nw, 1), self.dt)
        return ca.horzcat(ca.DM(self.x0), X)

    def outputs(self, theta, U, X, measured: Sequence[str]):
        """Measured outputs ``(len(measured), n + 1)`` of the states ``X`` (inputs held: the last
        step's input is used at the last sample).

        Parameters
        ----------
        theta : casadi.MX or array_like (k,)
        U : casadi.MX or array (nu, n)
        X : casadi.MX (nx, n + 1)
            From :meth:`states`.
        measured : sequence of str
            Output names.
        """
        rows = self.model.indices(measured, "output")
        Ufull = ca.horzcat(U, U[:, -1])
        Y = self.model.h.map(self.n + 1)(X, Ufull, self.param_vector(theta))
        return ca.vertcat(*[Y[i, :] for i in rows])

    def sensitivities(self, U_of, tau0: Sequence[float] = ()) -> tuple[np.ndarray, np.ndarray]:
        """States and their exact derivatives with respect to ``theta`` and the input timings ``tau``.

        Parameters
        ----------
        U_of : callable
            ``U_of(tau) -> (nu, n)`` CasADi expression of the inputs in the timing symbols ``tau``
            (an MX column; ignore it when the inputs do not depend on timings).
        tau0 : sequence of float
            Values of the timings.

        Returns
        -------
        X : (n + 1, nx) array
        dX : (n + 1, nx, k + len(tau0)) array
            ``d x_i(t_j) / d (theta, tau)``.
        """
        k = len(self.names)
        th = ca.MX.sym("theta", k)
        tau = ca.MX.sym("tau", len(tau0))
        X = self.states(th, U_of(tau))
        f = ca.Function("manoeuvre_sens", [th, tau], [X, ca.jacobian(ca.vec(X), ca.vertcat(th, tau))])
        Xv, J = f(self.theta0, np.asarray(tau0, dtype=float))
        nx = self.model.nx
        Xv = np.asarray(Xv).T
        J = np.asarray(J).reshape(self.n + 1, nx, k + len(tau0))     # vec stacks columns (samples)
        return Xv, J


class Approach:
    """The straight approach every manoeuvre of a design starts from, and the design's time step.

    The propeller rate is the one that holds ``speed`` with the parameters ``p`` (the current
    estimate) and stays fixed: a tank or a ship runs a trial at a set rate, so the rate does not
    move with the uncertain parameters.

    Parameters
    ----------
    model : Model
        A ship model (vessel with rudder and propeller inputs; states ``u, v, r, x, y, psi``).
    p : array_like or mapping
        Parameters (the current estimate).
    speed : float, optional
        Approach speed [m/s] (default ``model.vessel.U0``).
    dt : float, optional
        Step of the design's simulations [s] (default ``L/U / 40`` rounded down to 1, 2 or 5 x 10^k).
    n : float, optional
        Propeller rate (default: the rate that holds ``speed`` with ``p``), e.g. the rate a trial was
        designed with, to run it on another ship.
    """

    def __init__(self, model: Model, p, *, speed: float | None = None, dt: float | None = None,
                 n: float | None = None):
        from ..maneuvers import propeller_inputs, propeller_rate_for_speed, rudder_inputs, straight_run_state, vessel_of
        from ..maneuvers.runners import nice_step

        vessel = vessel_of(model)
        self.rudders, self.propellers = rudder_inputs(model), propeller_inputs(model)
        speed = vessel.U0 if speed is None else speed
        if speed is None or not np.isfinite(speed) or speed <= 0:
            raise InputError(f"approach speed must be a positive number [m/s], got {speed}")
        self.model, self.speed = model, float(speed)
        self.p = np.asarray(model.params(p), dtype=float)
        self.L = float(vessel.L_pp)
        self.time_scale = self.L / self.speed
        self.dt = float(dt) if dt is not None else nice_step(self.time_scale / 40)
        if not (np.isfinite(self.dt) and self.dt > 0):
            raise InputError(f"dt must be a positive number [s], got {dt}")
        if n is not None and not (np.isfinite(n) and self.propellers):
            raise InputError(f"n = {n}: a finite propeller rate for a model with a propeller input")
        self.n = None if not self.propellers else (float(n) if n is not None else
                                                  propeller_rate_for_speed(model, self.speed, self.p))
        self.x0 = straight_run_state(model, self.speed)
        self.rudder_max = vessel.rudder_max
        self.rudder_rate = vessel.rudder_rate
        self.dmodel = discretize(model, self.dt, method="rk4")

    def inputs(self, rudder) -> "ca.MX | np.ndarray":
        """Input matrix ``(nu, n)`` from a rudder row (array or CasADi row), the propellers at the set rate."""
        m = self.model
        rows = []
        symbolic = isinstance(rudder, (ca.MX, ca.SX))
        n = rudder.shape[1] if symbolic else np.asarray(rudder).size
        for name in m.input_names:
            if name in self.rudders:
                rows.append(rudder if symbolic else np.asarray(rudder, dtype=float).reshape(1, -1))
            elif name in self.propellers:
                rows.append(np.full((1, n), self.n))
            else:
                rows.append(np.zeros((1, n)))
        return ca.vertcat(*[ca.MX(ca.DM(r)) if not isinstance(r, (ca.MX, ca.SX)) else r for r in rows]) \
            if symbolic else np.vstack(rows)

    def midpoints(self, n: int) -> np.ndarray:
        """Mid-step times of ``n`` steps: a rudder law sampled there and held over each step follows a
        rate-limited ramp to second order in ``dt``."""
        return (np.arange(n) + 0.5) * self.dt

    def fold(self, names: Sequence[str], n: int) -> ManoeuvreFold:
        """A :class:`ManoeuvreFold` of ``n`` steps from this approach."""
        return ManoeuvreFold(self.model, names, self.p, self.dt, n, self.x0)
