"""Nomoto steering models (first and second order) with heading kinematics."""
from __future__ import annotations

from ..model import Model, ModelBuilder

__all__ = ["nomoto_first_order", "nomoto_second_order"]


def nomoto_first_order(K: float = 0.185, T: float = 107.3, *, rudder_bias: bool = False) -> Model:
    """First-order Nomoto model ``T r' + r = K (delta + delta_0)``, ``psi' = r``.

    Defaults are the Mariner values from MSS ``SIMmariner.m`` (K = 0.185 1/s, T = 107.3 s).
    States ``psi, r``; input ``delta``; noise ``w_r`` on the yaw acceleration; output ``psi``.
    With ``rudder_bias`` a constant rudder offset ``delta_0`` is a parameter.
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
