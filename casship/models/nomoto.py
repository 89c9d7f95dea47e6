"""Nomoto steering models (first and second order) with heading kinematics."""
from __future__ import annotations

from ..builder import ModelBuilder
from ..model import Model

__all__ = ["nomoto_first_order", "nomoto_second_order"]


def nomoto_first_order(K: float = 0.185, T: float = 107.3, *, rudder_bias: bool = False) -> Model:
    """First-order Nomoto model ``T r' + r = K (delta + delta_0)``, ``psi' = r``.

    Defaults are the Mariner values from MSS ``SIMmariner.m`` (K = 0.185 1/s, T = 107.3 s).
    States ``psi, r``; input ``delta``; noise ``w_r`` on the yaw acceleration; output ``psi``.
    With ``rudder_bias`` a constant rudder offset ``delta_0`` is a parameter.

    Parameters
    ----------
    K : float
        Rudder gain [1/s]: the steady yaw rate per radian of rudder. Parameter ``K``.
    T : float
        Time constant [s] (negative for a directionally unstable ship). Parameter ``T`` with bounds
        ``[-1e4, 1e4]``.
    rudder_bias : bool
        Add the parameter ``delta_0`` [rad] (nominal 0), a constant rudder offset to be estimated
        (e.g. from an asymmetric hull or a wind moment).

    Returns
    -------
    Model
        Named ``nomoto1`` (registered under that name): states ``psi`` [rad] (an angle) and ``r``
        [rad/s], input ``delta`` [rad], noise ``w_r``, output ``psi``.

    Examples
    --------
    >>> m = nomoto_first_order(rudder_bias=True)
    >>> m.state_names, m.input_names, m.param_dict()
    (('psi', 'r'), ('delta',), {'K': 0.185, 'T': 107.3, 'delta_0': 0.0})
    """
    b = ModelBuilder("nomoto1", "first-order Nomoto model (Nomoto 1957; Fossen 2021 Sec. 7.2)")
    psi = b.state("psi", unit="rad", angle=True)
    r = b.state("r", unit="rad/s")
    delta = b.input("delta", unit="rad")
    K_ = b.param("K", K, unit="1/s", doc="rudder gain")
    T_ = b.param("T", T, bounds=(-1e4, 1e4), unit="s", doc="time constant")
    d0 = b.param("delta_0", 0.0, unit="rad", doc="rudder bias") if rudder_bias else 0.0
    b.ode(psi=r, r=(K_ * (delta + d0) - r) / T_ + b.noise("w_r"))
    b.output("psi", psi)
    return b.build()


def nomoto_second_order(K: float = 0.185, T1: float = 118.0, T2: float = 7.8, T3: float = 18.5) -> Model:
    """Second-order Nomoto model ``r/delta = K (1 + T3 s) / ((1 + T1 s)(1 + T2 s))``.

    Realised in observer form with states ``psi, r, xi``:
    ``r' = -a1 r + xi + b1 delta``, ``xi' = -a0 r + b0 delta`` with ``a1 = (T1 + T2)/(T1 T2)``,
    ``a0 = 1/(T1 T2)``, ``b1 = K T3/(T1 T2)``, ``b0 = K/(T1 T2)``. Defaults: Mariner (MSS ``exNomoto.m``).

    Parameters
    ----------
    K : float
        Rudder gain [1/s] (steady yaw rate per radian of rudder). Parameter ``K``.
    T1, T2 : float
        Time constants of the two poles [s]. Parameters ``T1``, ``T2``.
    T3 : float
        Time constant of the zero [s]. Parameter ``T3``.

    Returns
    -------
    Model
        Named ``nomoto2`` (registered under that name): states ``psi`` [rad] (an angle), ``r``
        [rad/s] and ``xi`` [rad/s^2], input ``delta`` [rad], noise ``w_r`` on ``r'``, output ``psi``.

    Examples
    --------
    The steady yaw rate is ``K delta``: there ``r' = xi' = 0`` with ``xi = a1 r - b1 delta``.

    >>> import numpy as np
    >>> m = nomoto_second_order()
    >>> K, T1, T2, T3, delta = 0.185, 118.0, 7.8, 18.5, 0.1
    >>> r = K * delta
    >>> xi = (T1 + T2) / (T1 * T2) * r - K * T3 / (T1 * T2) * delta
    >>> xdot = m.f(x=[0.0, r, xi], u=delta, p=m.params(), w=0)["xdot"]
    >>> bool(np.allclose(xdot.full().ravel(), [r, 0.0, 0.0], rtol=0.0, atol=1e-15))
    True
    """
    b = ModelBuilder("nomoto2", "second-order Nomoto model (Nomoto 1957; Fossen 2021 Sec. 7.2)")
    psi = b.state("psi", unit="rad", angle=True)
    r = b.state("r", unit="rad/s")
    xi = b.state("xi", unit="rad/s^2", doc="internal state of the observer-form realisation")
    delta = b.input("delta", unit="rad")
    K_ = b.param("K", K, unit="1/s")
    T1_, T2_, T3_ = b.param("T1", T1, unit="s"), b.param("T2", T2, unit="s"), b.param("T3", T3, unit="s")
    a1, a0 = (T1_ + T2_) / (T1_ * T2_), 1 / (T1_ * T2_)
    b1, b0 = K_ * T3_ / (T1_ * T2_), K_ / (T1_ * T2_)
    b.ode(psi=r, r=-a1 * r + xi + b1 * delta + b.noise("w_r"), xi=-a0 * r + b0 * delta)
    b.output("psi", psi)
    return b.build()
