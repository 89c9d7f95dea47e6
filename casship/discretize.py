"""Discretisation of a continuous :class:`~casship.model.Model` into a :class:`DiscreteModel`.

The step ``F(x, u, p, w, dt) -> xf`` advances the state over ``dt`` with the input ``u`` and the
process noise ``w`` held constant (zero-order hold). ``dt`` is an argument so that irregular time
stamps and multi-rate records need no re-building; ``F_nominal`` binds it to the nominal step.
Jacobians of the step are exact (CasADi algorithmic differentiation through the integrator).
"""
from __future__ import annotations

import casadi as ca
import numpy as np
import scipy.linalg

from .model import Model
from .errors import InputError

__all__ = ["DiscreteModel", "discretize", "van_loan", "rk4"]

METHODS = ("euler", "rk4", "cvodes")


def rk4(rhs, z: tuple, h) -> tuple:
    """One classical Runge-Kutta step of ``dz/dt = rhs(*z)`` for a tuple of (symbolic) arrays ``z``.

    The one RK4 of casship (the explicit discretisation, the continuous-discrete EKF covariance,
    the Kalman-Bucy filter).

    Parameters
    ----------
    rhs : callable
        ``rhs(*z)`` returns a tuple shaped like ``z``.
    z : tuple
        The state at the start of the step.
    h : float or symbolic
        Step length.
    """
    k1 = rhs(*z)
    k2 = rhs(*(a + h / 2 * k for a, k in zip(z, k1)))
    k3 = rhs(*(a + h / 2 * k for a, k in zip(z, k2)))
    k4 = rhs(*(a + h * k for a, k in zip(z, k3)))
    return tuple(a + h / 6 * (p + 2 * q + 2 * r + s) for a, p, q, r, s in zip(z, k1, k2, k3, k4))


class DiscreteModel:
    """A discrete-time view of a model (build it with :func:`discretize`).

    Parameters
    ----------
    model : Model
    dt : float, optional
        Nominal step [s] (a discrete-time model's own by default).
    method : {"rk4", "euler", "cvodes"}, optional
        Integration method of a continuous model (default ``"rk4"``).
    substeps : int
        Sub-steps of the explicit methods.
    options : dict, optional
        CVODES options.

    Attributes
    ----------
    model : Model
        The continuous model (names, ``h``, parameters).
    dt : float
        Nominal sampling period [s].
    method : str
        ``"euler"``, ``"rk4"`` or ``"cvodes"``.
    F : casadi.Function
        ``F(x, u, p, w, dt) -> xf``.
    F_jac : casadi.Function
        ``F_jac(x, u, p, w, dt) -> (A, B, Fp, G)``, exact Jacobians of ``xf``.
    F_nominal : casadi.Function
        ``F_nominal(x, u, p, w) -> xf`` with ``dt`` bound to the nominal step.
    """

    def __init__(self, model: Model, dt: float | None = None, method: str | None = None, substeps: int = 1,
                 options: dict | None = None):
        if model.dt is not None:                      # a discrete-time model: its own step, exactly
            if dt is not None and not np.isclose(float(dt), model.dt, rtol=1e-12, atol=0.0):
                raise InputError(f"model {model.name!r} is discrete-time with dt = {model.dt:g} s; got dt = {dt}")
            if method not in (None, "discrete") or substeps != 1 or options:
                raise InputError(f"model {model.name!r} is discrete-time: it has its own step (no method, "
                                 f"substeps or integrator options), got method={method!r}")
            dt, method = model.dt, "discrete"
        else:
            method = "rk4" if method is None else method
            if method not in METHODS:
                raise InputError(f"unknown discretisation method {method!r}; use one of {METHODS}")
            if dt is None:
                raise InputError(f"model {model.name!r} is continuous-time: give the step dt")
        dt = float(dt)
        if not np.isfinite(dt) or dt <= 0:
            raise InputError(f"dt must be a positive finite number, got {dt}")
        substeps = int(substeps)
        if substeps < 1:
            raise InputError(f"substeps must be >= 1, got {substeps}")
        if options and method != "cvodes":
            raise InputError(f"integrator options {sorted(options)} apply to method 'cvodes' only, not {method!r}")
        self.model, self.dt, self.method, self.substeps = model, dt, method, substeps
        self._options = dict(options or {})
        self.symbolic = ca.MX if method == "cvodes" else ca.SX
        sym = self.symbolic
        x, u = sym.sym("x", model.nx), sym.sym("u", model.nu)
        p, w = sym.sym("p", model.np), sym.sym("w", model.nw)
        h = sym.sym("dt")
        if method == "cvodes":
            xf = self._cvodes(x, u, p, w, h, options or {})
        elif method == "discrete":
            # x[k+1] = x + dt f (f is the model's rate over its step); a step of length 0 is no step
            xf = ca.if_else(h > 0, x + dt * model.f(x, u, p, w), x)
        else:
            xf = x
            hs = h / substeps
            for _ in range(substeps):
                xf = self._explicit_step(xf, u, p, w, hs)
        args, names = [x, u, p, w, h], ["x", "u", "p", "w", "dt"]
        self.F = ca.Function("F", args, [xf], names, ["xf"])
        self.F_jac = ca.Function(
            "F_jac", args,
            [ca.jacobian(xf, x), ca.jacobian(xf, u), ca.jacobian(xf, p), ca.jacobian(xf, w)],
            names, ["A", "B", "Fp", "G"])
        self.F_nominal = ca.Function("F_nominal", args[:4], [self.F(x, u, p, w, dt)], names[:4], ["xf"])
        self._folds: dict[int, ca.Function] = {}

    def _explicit_step(self, x, u, p, w, h):
        f = self.model.f
        if self.method == "euler":
            return x + h * f(x, u, p, w)
        return rk4(lambda xi: (f(xi, u, p, w),), (x,), h)[0]

    def _cvodes(self, x, u, p, w, h, options):
        m = self.model
        xs = ca.MX.sym("xs", m.nx)
        theta = ca.MX.sym("theta", m.nu + m.np + m.nw + 1)
        us, ps = theta[:m.nu], theta[m.nu:m.nu + m.np]
        ws, hs = theta[m.nu + m.np:m.nu + m.np + m.nw], theta[-1]
        # Integrate over normalised time [0, 1] so that dt can stay symbolic.
        ode = {"x": xs, "p": theta, "ode": hs * m.f(xs, us, ps, ws)}
        opts = {"abstol": 1e-10, "reltol": 1e-10}
        opts.update(options)
        integ = ca.integrator(f"{m.c_name}_cvodes", "cvodes", ode, 0.0, 1.0, opts)
        return integ(x0=x, p=ca.vertcat(u, p, w, h))["xf"]

    def __reduce__(self):
        """Pickle as the recipe (model, dt, method, substeps, options); rebuilt on loading."""
        return DiscreteModel, (self.model, self.dt, self.method, self.substeps, self._options or None)

    @property
    def discrete(self) -> bool:
        """True for a model written in discrete time (:class:`~casship.ModelBuilder` with ``dt``)."""
        return self.method == "discrete"

    def require_continuous(self, what: str) -> None:
        """Raise ``ValueError`` if ``what`` needs a continuous-time model and this one is discrete-time.

        Parameters
        ----------
        what : str
            The feature that needs it, for the message.
        """
        if self.discrete:
            raise InputError(f"{what} needs a continuous-time model; {self.model.name!r} is discrete-time "
                             f"(dt = {self.dt:g} s)")

    def check_steps(self, dt, t=None) -> None:
        """Check the time steps of a record: any positive step for a discretised continuous model,
        the model's own step for a discrete-time one (``ValueError`` naming the row otherwise).

        Parameters
        ----------
        dt : array
            The steps between consecutive samples.
        t : array, optional
            The time stamps (for the message).
        """
        if not self.discrete:
            return
        dt = np.asarray(dt, dtype=float)
        bad = np.flatnonzero(~np.isclose(dt, self.dt, rtol=1e-6, atol=0.0))
        if bad.size:
            k = int(bad[0]) + 1
            when = f" (t = {t[k]:g} s)" if t is not None else ""
            raise InputError(f"discrete-time model {self.model.name!r} steps dt = {self.dt:g} s; row {k}{when} "
                             f"comes {dt[k - 1]:g} s after the previous one")

    # -- convenience ----------------------------------------------------------------------------------
    @property
    def name(self) -> str:
        """The model's name."""
        return self.model.name

    def __repr__(self) -> str:
        return f"DiscreteModel({self.model.name!r}, dt={self.dt:g}, method={self.method!r}, substeps={self.substeps})"

    def fold(self, n: int) -> ca.Function:
        """``F`` folded over ``n`` steps (``mapaccum``), cached per length.

        Parameters
        ----------
        n : int

        ``fold(x0, U, p, W, dt) -> X`` with ``U`` (nu, n), ``W`` (nw, n), ``dt`` (1, n) and ``X`` the
        (nx, n) states after each step; see :func:`casship.simulation.fold_steps` for records of any length.
        """
        n = int(n)
        if n < 1:
            raise InputError(f"fold length must be >= 1, got {n}")
        if n not in self._folds:
            self._folds[n] = self.F.mapaccum(n)
        return self._folds[n]

    def step(self, x, u, p=None, w=None, dt=None) -> np.ndarray:
        """One step numerically (convenience; batch work should use :func:`casship.simulate`).

        Parameters
        ----------
        x, u : array
            State and input held over the step.
        p, w : array, optional
            Parameters (nominal) and noise held over the step (zero).
        dt : float, optional
            Step length (the nominal one by default).
        """
        m = self.model
        p = m.params() if p is None else p
        w = np.zeros(m.nw) if w is None else w
        return np.asarray(self.F(x, u, p, w, self.dt if dt is None else dt)).reshape(-1)

    def linearize(self, x, u, p=None, dt=None):
        """Exact discrete Jacobians ``(A, B, G)`` at ``(x, u, p, w=0)``.

        Parameters
        ----------
        x, u : array
        p : array, optional
            Parameters (nominal by default).
        dt : float, optional
            Step length (the nominal one by default).
        """
        m = self.model
        p = m.params() if p is None else p
        A, B, _, G = self.F_jac(x, u, p, np.zeros(m.nw), self.dt if dt is None else dt)
        return np.array(A), np.array(B), np.array(G)

    def process_noise(self, Qc, x, u, p=None, dt=None) -> np.ndarray:
        """Discrete process-noise covariance for continuous white noise ``w`` of PSD ``Qc``.

        Uses Van Loan's method on the exact linearisation at ``(x, u, p)``; compare with the
        zero-order-hold convention ``G Qd G'`` that the filters use when ``w`` is held over a step.

        Parameters
        ----------
        Qc : array
            Power spectral density of ``w``.
        x, u : array
            Operating point.
        p : array, optional
        dt : float, optional
        """
        self.require_continuous("process_noise (continuous white noise)")
        m = self.model
        p = m.params() if p is None else p
        A, _, _, G = m.f_jac(x, u, p, np.zeros(m.nw))
        return van_loan(np.array(A), np.array(G), np.atleast_2d(Qc), self.dt if dt is None else dt)[1]


def discretize(model: Model, dt: float | None = None, method: str | None = None, substeps: int = 1,
               options: dict | None = None) -> DiscreteModel:
    """Discretise ``model`` with step ``dt`` (a discrete-time model: its own step).

    Parameters
    ----------
    model : Model
    dt : float
        Nominal step [s]. The step Function also accepts other ``dt`` values. For a discrete-time
        model (``ModelBuilder(name, dt=...)``) it may be left out and must equal the model's.
    method : {"rk4", "euler", "cvodes"}
        Classical RK4 with ``substeps`` sub-steps (default), explicit Euler (as in Shi et al. 2009,
        Koike et al. 2023 and Fossen & Fossen 2021) or CasADi's adaptive CVODES integrator (tolerances 1e-10 unless ``options`` say otherwise).
        A discrete-time model takes none (its method is ``"discrete"``).
    substeps : int
        Number of equal sub-steps for the explicit methods.
    options : dict, optional
        Integrator options for ``"cvodes"``.

    Examples
    --------
    >>> from casship.models import nomoto_first_order
    >>> dm = discretize(nomoto_first_order(), dt=0.1, method="rk4")
    >>> dm.F
    Function(F:(x[2],u,p[2],w,dt)->(xf[2]) SXFunction)
    """
    return DiscreteModel(model, dt, method, substeps, options)


def van_loan(A, G, Qc, dt):
    """Van Loan's method: exact ``Ad = exp(A dt)`` and ``Qd = int_0^dt e^{A s} G Qc G' e^{A' s} ds``.

    Parameters
    ----------
    A : (n, n) array
    G : (n, m) array
    Qc : (m, m) array, power spectral density of the white noise
    dt : float
    """
    A, G, Qc = np.atleast_2d(A), np.atleast_2d(G), np.atleast_2d(Qc)
    n = A.shape[0]
    M = np.zeros((2 * n, 2 * n))
    M[:n, :n] = -A
    M[:n, n:] = G @ Qc @ G.T
    M[n:, n:] = A.T
    E = scipy.linalg.expm(M * dt)
    Ad = E[n:, n:].T
    Qd = Ad @ E[:n, n:]
    return Ad, 0.5 * (Qd + Qd.T)
