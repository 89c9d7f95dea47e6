"""Nomoto steering models: the reduction of an exact linearisation and the fit to heading records.

A :class:`Nomoto` model ``r/delta = K (1 + T3 s) / ((1 + T1 s)(1 + T2 s))`` (first order:
``K / (1 + T s)``, ``T = T1 + T2 - T3``) is what the designs place their poles on. It comes from
the labelled :class:`control.StateSpace` of :func:`casship.linearize` (:func:`nomoto_from_linear`,
or :func:`nomoto_from_model` which linearises first) or from heading records such as zig-zags
(:func:`fit_nomoto`, maximum likelihood through the public :class:`casship.identify.MLEProblem`).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import control
import numpy as np

from ..data import Dataset

from ..gaussian import Gaussian
from ..discretize import discretize
from ..linear import linearize
from ..model import Model
from ..errors import InputError, InputTypeError

__all__ = ["Nomoto", "nomoto_from_linear", "nomoto_from_model", "fit_nomoto"]


@dataclass(frozen=True)
class Nomoto:
    """Nomoto steering model ``r/delta = K (1 + T3 s) / ((1 + T1 s)(1 + T2 s))``.

    The first-order model has ``T = T1 + T2 - T3``. ``m = T/K`` and ``d = 1/K`` are the inertia-
    and damping-like coefficients of ``m r' + d r = delta`` used by the designs (finite for a
    course-unstable ship, ``T < 0``).

    Parameters
    ----------
    K : float
        Gain [1/s] (or [1/(N m s)] for a yaw-moment input).
    T : float
        First-order time constant [s] (negative for a course-unstable ship).
    T1, T2, T3 : float
        Second-order time constants (NaN when only a first-order model is known).
    source : str
        Where the numbers came from.

    Examples
    --------
    >>> nom = Nomoto(K=0.185, T=107.3)
    >>> round(nom.m, 1), round(nom.d, 3)
    (580.0, 5.405)
    """

    K: float
    T: float
    T1: float = float("nan")
    T2: float = float("nan")
    T3: float = float("nan")
    source: str = ""

    def __post_init__(self):
        for name in ("K", "T"):
            v = getattr(self, name)
            if not np.isfinite(v) or v == 0:
                raise InputError(f"Nomoto {name} must be finite and non-zero, got {v}")

    @property
    def m(self) -> float:
        """Inertia-like coefficient ``T/K``."""
        return self.T / self.K

    @property
    def d(self) -> float:
        """Damping-like coefficient ``1/K``."""
        return 1.0 / self.K

    @property
    def second_order(self) -> bool:
        """True when ``T1, T2, T3`` are known."""
        return bool(np.isfinite(self.T1) and np.isfinite(self.T2) and np.isfinite(self.T3))

    def yaw_rate_tf(self, order: int = 1) -> control.TransferFunction:
        """Transfer function ``r/delta`` (order 1 or 2) with labelled input and output.

        Parameters
        ----------
        order : int
            1 or 2.
        """
        if order == 2:
            if not self.second_order:
                raise InputError("this Nomoto model has no second-order time constants")
            return control.tf([self.K * self.T3, self.K], np.polymul([self.T1, 1], [self.T2, 1]),
                              inputs="delta", outputs="r")
        if order != 1:
            raise InputError(f"order must be 1 or 2, got {order}")
        return control.tf([self.K], [self.T, 1], inputs="delta", outputs="r")

    def system(self, order: int = 1, *, steer: str = "delta", name: str = "nomoto") -> control.StateSpace:
        """The Nomoto model as a labelled :class:`control.StateSpace`: input ``steer``, outputs
        ``psi`` and ``r`` (heading and yaw rate; the course equals the heading in this model).

        Parameters
        ----------
        order : int
            1, or 2 (observer form with the state ``xi``).
        steer : str
            Input name.
        name : str
            System name.
        """
        if order == 1:
            A = np.array([[0.0, 1.0], [0.0, -1.0 / self.T]])
            B = np.array([[0.0], [self.K / self.T]])
            states = ["psi", "r"]
        else:
            if not self.second_order:
                raise InputError("this Nomoto model has no second-order time constants")
            T1, T2, T3 = self.T1, self.T2, self.T3
            # observer form of r/delta (as casship.models.nomoto_second_order)
            A = np.array([[0.0, 1.0, 0.0], [0.0, -(T1 + T2) / (T1 * T2), 1.0], [0.0, -1.0 / (T1 * T2), 0.0]])
            B = np.array([[0.0], [self.K * T3 / (T1 * T2)], [self.K / (T1 * T2)]])
            states = ["psi", "r", "xi"]
        C = np.zeros((2, len(states)))
        C[0, 0] = C[1, 1] = 1.0
        return control.ss(A, B, C, np.zeros((2, 1)), states=states, inputs=[steer], outputs=["psi", "r"],
                          name=name)

    def as_dict(self) -> dict:
        """The numbers as a plain dict."""
        return {"K": self.K, "T": self.T, "T1": self.T1, "T2": self.T2, "T3": self.T3, "source": self.source}


def nomoto_from_linear(sys: control.StateSpace, *, steer: str = "delta", yaw_rate: str = "r",
                       tol: float = 1e-6) -> Nomoto:
    """Nomoto model from a labelled linearisation (:func:`casship.linearize`).

    The transfer function from the input ``steer`` to the output ``yaw_rate`` is reduced to a
    minimal realisation (``control.minreal``: integrators of position and heading and a decoupled
    surge mode drop out); one remaining pole gives a first-order model, two real poles and at most
    one zero the second-order one (``K, T1, T2, T3`` with ``T = T1 + T2 - T3``), two complex poles
    the first-order equivalent from the coefficients.

    Parameters
    ----------
    sys : control.StateSpace
        Labelled linearisation.
    steer, yaw_rate : str
        Input and output labels.
    tol : float
        Tolerance of ``control.minreal``.

    Returns
    -------
    Nomoto

    Raises
    ------
    ValueError
        If ``sys`` lacks the labels, the reduced transfer function has more than two poles (e.g. a
        rudder actuator state: linearise with the actual rudder angle as input), or a zero gain.
    """
    if not isinstance(sys, control.StateSpace):
        raise InputTypeError(f"nomoto_from_linear needs a control.StateSpace, got {type(sys).__name__}")
    if steer not in sys.input_labels:
        raise InputError(f"the linearisation has no input {steer!r}; inputs: {sys.input_labels}")
    if yaw_rate not in sys.output_labels:
        raise InputError(f"the linearisation has no output {yaw_rate!r}; outputs: {sys.output_labels} "
                         f"(linearise with outputs=[{yaw_rate!r}, ...])")
    siso = sys[sys.output_labels.index(yaw_rate), sys.input_labels.index(steer)]
    tf = control.minreal(control.ss2tf(siso), tol=tol, verbose=False)
    num, den = np.ravel(tf.num[0][0]), np.ravel(tf.den[0][0])
    if not np.any(np.abs(num) > 0):
        raise InputError(f"{steer!r} does not move {yaw_rate!r} at this operating point")
    poles, zeros = np.real_if_close(tf.poles()), np.real_if_close(tf.zeros())
    K = float(num[-1] / den[-1]) if den[-1] != 0 else float("nan")
    source = f"linearisation of {sys.name}"
    if not (np.isfinite(K) and K != 0):
        # e.g. a ship at (nearly) zero speed: no hydrodynamic damping of the yaw rate, no steady turn rate
        raise InputError(f"the {steer!r} -> {yaw_rate!r} response of {sys.name!r} has no finite steady gain "
                         f"(K = {K:.4g}: the yaw rate is not damped at this operating point, e.g. a speed "
                         "near zero); no Nomoto model there")
    if poles.size == 1:
        return Nomoto(K=K, T=float(-1 / poles[0].real), source=source)
    if poles.size == 2 and zeros.size <= 1 and np.all(np.isreal(poles)):
        T1, T2 = sorted((float(-1 / pp.real) for pp in poles), key=abs, reverse=True)
        T3 = float(-1 / zeros[0].real) if zeros.size else 0.0
        return Nomoto(K=K, T=T1 + T2 - T3, T1=T1, T2=T2, T3=T3, source=source)
    if poles.size == 2 and zeros.size <= 1 and den[-1] != 0 and num[-1] != 0:
        a1, a0 = den[-2] / den[-3], den[-1] / den[-3]
        T3 = float(num[-2] / num[-1]) if num.size > 1 else 0.0
        return Nomoto(K=K, T=float(a1 / a0) - T3, T3=T3, source=source + " (complex poles)")
    raise InputError(f"the reduced {steer!r} -> {yaw_rate!r} transfer function of {sys.name!r} has poles "
                     f"{np.round(poles, 6).tolist()} and zeros {np.round(zeros, 6).tolist()}; a Nomoto model "
                     "needs one pole, or two poles and at most one zero")


def nomoto_from_model(model: Model, x=None, u=None, p=None, *, steer: str = "delta", yaw_rate: str = "r",
                      tol: float = 1e-6) -> Nomoto:
    """Nomoto model of ``model`` at the operating point ``(x, u, p)``: :func:`casship.linearize`
    then :func:`nomoto_from_linear`.

    Parameters
    ----------
    model : Model
    x, u, p : array or mapping, optional
        Operating point and parameters.
    steer, yaw_rate : str
        Input and output names.
    tol : float
        Tolerance of ``control.minreal``.

    Examples
    --------
    >>> import casship as cs
    >>> m = cs.models.nomoto_second_order(K=0.185, T1=118.0, T2=7.8, T3=18.5)
    >>> round(nomoto_from_model(m).T, 2)
    107.3
    """
    sys = linearize(model, x, u, p, outputs=[yaw_rate])
    return nomoto_from_linear(sys, steer=steer, yaw_rate=yaw_rate, tol=tol)


def fit_nomoto(data: Dataset | Sequence[Dataset], *, steer: str = "delta", heading: str = "psi",
               guess: Nomoto | None = None, heading_var: float = 1e-6, bias: bool = True):
    """First-order Nomoto model (K, T and a rudder bias) fitted to heading records, e.g. zig-zags.

    Maximum likelihood through an EKF on the first-order Nomoto model (the public
    :class:`casship.identify.MLEProblem`), with a tiny process noise so that the fit is close to
    output error. The records need columns ``steer`` (rad) and ``heading`` (rad; NaN = not
    measured) on a uniform grid; the yaw rate starts at zero (records start on a straight course).

    Parameters
    ----------
    data : Dataset or sequence of Dataset
        The records.
    steer, heading : str
        Column names.
    guess : Nomoto, optional
        Initial guess (default K = 0.1, T = 50 s).
    heading_var : float
        Heading measurement variance [rad^2].
    bias : bool
        Fit a rudder bias.

    Returns
    -------
    (Nomoto, FitResult)
    """
    from ..identify import MLEProblem
    from ..models import nomoto_first_order

    records = [data] if isinstance(data, Dataset) else list(data)
    if not records:
        raise InputError("fit_nomoto needs at least one record")
    renamed = []
    for rec in records:
        for col in (steer, heading):
            if col not in rec:
                raise InputError(f"record has no column {col!r}; columns: {list(rec.names)}")
        renamed.append(Dataset(rec.t, {"delta": rec[steer], "psi": rec[heading]}))
    g = guess or Nomoto(K=0.1, T=50.0)
    model = nomoto_first_order(K=g.K, T=g.T, rudder_bias=bias)
    dt = float(np.median(np.diff(renamed[0].t)))
    free = ["K", "T"] + (["delta_0"] if bias else [])
    x0 = [Gaussian(np.array([rec["psi"][np.isfinite(rec["psi"])][0], 0.0]), np.diag([heading_var, 1e-10]))
          for rec in renamed]
    problem = MLEProblem(discretize(model, dt, "rk4"), renamed, free=free, x0=x0, Q=1e-12, R=heading_var,
                         scale={"K": abs(g.K), "T": abs(g.T)})
    fit = problem.solve(guess={"K": g.K, "T": g.T})
    nom = Nomoto(K=fit.params["K"], T=fit.params["T"], source="fit to heading records (MLE through an EKF)")
    return nom, fit
