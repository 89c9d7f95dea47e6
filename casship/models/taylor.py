"""Second-order Taylor response model of Shi, Zhao, Peng & Shen (2009), their Eq. 2."""
from __future__ import annotations


from ..frames import body_to_ned
from ..builder import ModelBuilder
from ..model import Model
from ..vessel import Vessel
from ..errors import InputError

__all__ = ["shi_taylor", "shi_taylor_preset", "SHI_PARAM_NAMES", "SHI_DEFAULTS", "SHI_ILLUSTRATIVE_VESSEL"]

SHI_PARAM_NAMES = ("a1", "a2", "a3", "a4", "a5", "a6", "a7", "a8", "a9",
                   "b1", "b2", "b3", "b4", "c1", "c2", "c3")

# An illustrative set for a ship of about 8 m/s at n = 1.5 rps (equilibrium u0 = 8 m/s, surge time
# constant 10 s, K ~ 0.07 1/s, T ~ 33 s). Like many full-form ships it is slightly directionally
# unstable on a straight run: the sway-yaw linearisation at u0 = 8 m/s has eigenvalues +0.01 and
# -0.09 1/s (stable for c1 > -0.000625). NOT the paper's Table 1, which has no real straight-run
# equilibrium; studies identify their own truth sets (see problems/shi2009).
SHI_DEFAULTS = {"a1": -0.003125, "a2": 0.0, "a3": -0.5, "a4": -0.005, "a5": 0.0, "a6": 0.0, "a7": 0.0,
                "a8": 0.0, "a9": 0.0889, "b1": -0.05, "b2": 0.0, "b3": 0.05, "b4": -0.3,
                "c1": -0.001, "c2": -0.03, "c3": 0.002}


#: The ship :data:`SHI_DEFAULTS` stand for: illustrative, not a published vessel (the length is an
#: assumption used to scale manoeuvre metrics; 8 m/s at 1.5 rps as above).
SHI_ILLUSTRATIVE_VESSEL = Vessel("illustrative ship (Shi et al. 2009 model form)", L_pp=100.0, U0=8.0, n0=1.5,
                                 rudder_max=0.6108652381980153, param_set="shi-taylor/illustrative",
                                 source="casship illustrative set (assumed L_pp = 100 m), not the paper's Table 1")


def shi_taylor_preset(params: dict | None = None, *, kinematics: bool = True) -> Model:
    """:func:`shi_taylor` with :data:`SHI_DEFAULTS` on the illustrative vessel (registered as ``shi-taylor``).

    The vessel is :data:`SHI_ILLUSTRATIVE_VESSEL` (an assumed 100 m ship at 8 m/s and 1.5 rps), so
    manoeuvres and autopilot tools find a length, an approach speed and a rudder limit.

    Parameters
    ----------
    params : dict, optional
        Overrides of the nominal values :data:`SHI_DEFAULTS` (names of :data:`SHI_PARAM_NAMES`).
    kinematics : bool
        Add the earth-fixed states ``x`` [m], ``y`` [m], ``psi`` [rad].

    Returns
    -------
    Model
        Named ``shi-taylor``: states ``u, v`` [m/s], ``r`` [rad/s] (+ ``x, y, psi``), inputs
        ``delta`` [rad] and ``n`` [1/s], outputs ``u, v, r``.

    Examples
    --------
    >>> m = shi_taylor_preset({"c1": 0.001}, kinematics=False)
    >>> m.state_names, m.vessel.L_pp, m.param_dict()["c1"]
    (('u', 'v', 'r'), 100.0, 0.001)
    """
    return shi_taylor(params, kinematics=kinematics, vessel=SHI_ILLUSTRATIVE_VESSEL)


def shi_taylor(params: dict | None = None, *, kinematics: bool = True, vessel: Vessel | None = None) -> Model:
    """Shi et al. (2009) 3-DOF response model, 16 parameters.

    ``u' = a1 u^2 + a2 v^2 + a3 r^2 + a4 delta^2 + a5 v r + a6 v delta + a7 r delta + a8 u n + a9 n^2``,
    ``v' = b1 v + b2 r + b3 delta + b4 u r``, ``r' = c1 v + c2 r + c3 delta``.

    Parameters
    ----------
    params : dict, optional
        Overrides of the nominal values (``SHI_DEFAULTS``, an illustrative set, slightly
        directionally unstable on a straight run; ``{"c1": 0.001}`` makes it stable).
    kinematics : bool
        Add earth-fixed ``x, y, psi`` states (for manoeuvre validation); outputs stay ``u, v, r``
        as in the paper (``H = [I3 0]``).
    vessel : Vessel, optional
        The ship the parameters describe (for manoeuvres: length, approach speed, rudder limit);
        its rudder and propeller inputs become ``delta`` and ``n``.
    """
    values = dict(SHI_DEFAULTS)
    for k, v in (params or {}).items():
        if k not in values:
            raise InputError(f"unknown Shi et al. parameter {k!r}; known: {list(SHI_PARAM_NAMES)}")
        values[k] = v
    b = ModelBuilder("shi-taylor", "3-DOF second-order Taylor response model (Shi et al. 2009, Eq. 2)")
    u, v, r = b.state("u", unit="m/s"), b.state("v", unit="m/s"), b.state("r", unit="rad/s")
    delta, n = b.input("delta", unit="rad"), b.input("n", unit="1/s")
    a = [b.param(f"a{i}", values[f"a{i}"]) for i in range(1, 10)]
    bb = [b.param(f"b{i}", values[f"b{i}"]) for i in range(1, 5)]
    c = [b.param(f"c{i}", values[f"c{i}"]) for i in range(1, 4)]
    du = (a[0] * u**2 + a[1] * v**2 + a[2] * r**2 + a[3] * delta**2 + a[4] * v * r + a[5] * v * delta
          + a[6] * r * delta + a[7] * u * n + a[8] * n**2)
    dv = bb[0] * v + bb[1] * r + bb[2] * delta + bb[3] * u * r
    dr = c[0] * v + c[1] * r + c[2] * delta
    b.ode(u=du + b.noise("w_u"), v=dv + b.noise("w_v"), r=dr + b.noise("w_r"))
    if kinematics:
        b.state("x", unit="m")
        b.state("y", unit="m")
        psi = b.state("psi", unit="rad", angle=True)
        xd, yd, psid = body_to_ned(u, v, r, psi)
        b.ode(x=xd, y=yd, psi=psid)
    for name in ("u", "v", "r"):
        b.output(name, b.sym(name))
    if vessel is not None:
        b.vessel = vessel.replace(rudders=("delta",), propellers=("n",))
    return b.build()
