"""Kinematic models: double integrator (Tomera 2011), constant acceleration (Shi et al. 2009) and the
five-state SOG/COG/course-rate model of Fossen & Fossen (2021) in North-East and lat/lon form."""
from __future__ import annotations

import casadi as ca

from ..frames import body_to_ned, wgs84_radii
from ..builder import ModelBuilder
from ..model import Model

__all__ = ["double_integrator", "tomera_kinematic", "constant_acceleration", "sog_cog", "sog_cog_latlon",
           "body_kinematics"]


def _add_double_integrator(b: ModelBuilder, pos: str, vel: str, g: tuple[float, float], angle: bool) -> None:
    p = b.state(pos, unit="rad" if angle else "m", angle=angle)
    v = b.state(vel, unit="rad/s" if angle else "m/s")
    g1 = b.param(f"g1_{pos}", g[0], doc="process-noise gain on the position equation")
    g2 = b.param(f"g2_{pos}", g[1], doc="process-noise gain on the velocity equation")
    w1, w2 = b.noise(f"w1_{pos}"), b.noise(f"w2_{pos}")
    b.ode(**{pos: v + g1 * w1, vel: g2 * w2})
    b.output(pos, p)


def double_integrator(pos: str = "x", vel: str = "vx", g: tuple[float, float] = (1.0, 0.01),
                      angle: bool = False) -> Model:
    """One degree of freedom as a double integrator, ``x' = A x + G w``, ``y = C x``.

    Tomera (2011), Eq. 56-58: ``A = [[0, 1], [0, 0]]``, ``C = [1, 0]``, ``G = diag(g)``, with the
    position measured. The gains ``g1_<pos>``, ``g2_<pos>`` are parameters (the paper's G matrix is
    read as ``diag(1, 0.01)`` for x and y and ``diag(0.2, 0.01)`` for psi; see the Tomera study).

    Parameters
    ----------
    pos : str
        Name of the position state (also the output and the suffix of the parameter and noise
        names); a valid identifier.
    vel : str
        Name of the velocity state.
    g : (float, float)
        Nominal process-noise gains ``(g1, g2)`` on the position and the velocity equation,
        parameters ``g1_<pos>`` and ``g2_<pos>`` (they multiply the white noises ``w1_<pos>`` and
        ``w2_<pos>``).
    angle : bool
        The coordinate is an angle: position in [rad] (wrapped in residuals) and velocity in
        [rad/s]; otherwise [m] and [m/s].

    Returns
    -------
    Model
        Named ``double_integrator_<pos>``; states ``<pos>, <vel>``, no inputs, parameters
        ``g1_<pos>, g2_<pos>``, noises ``w1_<pos>, w2_<pos>``, output ``<pos>``.

    Examples
    --------
    >>> m = double_integrator("psi", "r", g=(0.2, 0.01), angle=True)
    >>> m.name, m.state_names, m.param_dict()
    ('double_integrator_psi', ('psi', 'r'), {'g1_psi': 0.2, 'g2_psi': 0.01})
    """
    b = ModelBuilder(f"double_integrator_{pos}", "per-axis double integrator (Tomera 2011, Eq. 56-58)")
    _add_double_integrator(b, pos, vel, g, angle)
    return b.build()


def tomera_kinematic(g_xy: tuple[float, float] = (1.0, 0.01), g_psi: tuple[float, float] = (0.2, 0.01)) -> Model:
    """The three decoupled double integrators (x, y, psi) of Tomera (2011), earth-fixed velocities.

    States ``x, vx, y, vy, psi, r``; outputs ``x, y`` (DGPS) and ``psi`` (gyro-compass).

    Parameters
    ----------
    g_xy : (float, float)
        Process-noise gains ``(g1, g2)`` of the x and the y axis (parameters ``g1_x, g2_x, g1_y,
        g2_y``; see :func:`double_integrator`).
    g_psi : (float, float)
        Process-noise gains of the heading axis (parameters ``g1_psi, g2_psi``).

    Returns
    -------
    Model
        Named ``tomera-kinematic``: ``x, y`` [m], ``vx, vy`` [m/s] (earth-fixed), ``psi`` [rad]
        (an angle), ``r`` [rad/s]; no inputs; noises ``w1_<axis>, w2_<axis>``.

    Examples
    --------
    >>> m = tomera_kinematic()
    >>> m.state_names, m.output_names
    (('x', 'vx', 'y', 'vy', 'psi', 'r'), ('x', 'y', 'psi'))
    """
    b = ModelBuilder("tomera-kinematic", "x, y, psi double integrators (Tomera 2011, Eq. 56-62)")
    _add_double_integrator(b, "x", "vx", g_xy, False)
    _add_double_integrator(b, "y", "vy", g_xy, False)
    _add_double_integrator(b, "psi", "r", g_psi, True)
    return b.build()


def constant_acceleration(name: str = "s") -> Model:
    """Constant-acceleration model of one coordinate (Shi et al. 2009, Eq. 6).

    States ``<name>`` (position), ``<name>_v`` (velocity), ``<name>_a`` (acceleration); white
    noise ``w_<name>`` drives the acceleration (jerk noise); output the position.

    Parameters
    ----------
    name : str
        Name of the coordinate (a valid identifier): the position state and output, the prefix of
        the other states and the suffix of the noise and of the model name.

    Returns
    -------
    Model
        Named ``constant_acceleration_<name>``; states ``<name>`` [m], ``<name>_v`` [m/s],
        ``<name>_a`` [m/s^2]; no inputs or parameters; noise ``w_<name>`` [m/s^3]; output ``<name>``.

    Examples
    --------
    >>> m = constant_acceleration("x")
    >>> m.state_names, m.noise_names, m.output_names
    (('x', 'x_v', 'x_a'), ('w_x',), ('x',))
    """
    b = ModelBuilder(f"constant_acceleration_{name}", "constant-acceleration kinematics (Shi et al. 2009, Eq. 6)")
    s = b.state(name, unit="m")
    v = b.state(f"{name}_v", unit="m/s")
    a = b.state(f"{name}_a", unit="m/s^2")
    b.ode(**{name: v, f"{name}_v": a, f"{name}_a": b.noise(f"w_{name}")})
    b.output(name, s)
    return b.build()


def sog_cog(alpha1: float = 0.01, alpha2: float = 0.1) -> Model:
    """Five-state SOG/COG/course-rate model in North-East coordinates (Fossen & Fossen 2021).

    ``x_n' = U cos chi``, ``y_n' = U sin chi``, ``U' = -alpha1 U + w_U``, ``chi' = omega_chi``,
    ``omega_chi' = -alpha2 omega_chi + w_chi``; outputs the GNSS position ``x_n, y_n``.

    Parameters
    ----------
    alpha1 : float
        Singer constant of the speed over ground [1/s] (the inverse of its correlation time),
        parameter ``alpha1`` with bounds ``[0, 10]``.
    alpha2 : float
        Singer constant of the course rate [1/s], parameter ``alpha2`` with bounds ``[0, 10]``.

    Returns
    -------
    Model
        Named ``sog-cog`` (registered under that name); states ``x_n, y_n`` [m], ``U`` [m/s],
        ``chi`` [rad] (an angle), ``omega_chi`` [rad/s]; no inputs; noises ``w_U, w_chi``.

    Examples
    --------
    >>> m = sog_cog(alpha1=0.02)
    >>> m.state_names, m.param_dict()
    (('x_n', 'y_n', 'U', 'chi', 'omega_chi'), {'alpha1': 0.02, 'alpha2': 0.1})
    """
    b = ModelBuilder("sog-cog", "5-state SOG/COG EKF model, North-East (Fossen & Fossen 2021)")
    xn, yn = b.state("x_n", unit="m"), b.state("y_n", unit="m")
    _add_speed_course(b, alpha1, alpha2)
    U, chi = b.sym("U"), b.sym("chi")
    b.ode(x_n=U * ca.cos(chi), y_n=U * ca.sin(chi))
    b.output("x_n", xn)
    b.output("y_n", yn)
    return b.build()


def sog_cog_latlon(alpha1: float = 0.01, alpha2: float = 0.1) -> Model:
    """Five-state SOG/COG/course-rate model in latitude/longitude (rad) with WGS-84 radii.

    ``lat' = U cos chi / R_M``, ``lon' = U sin chi / (R_N cos lat)``; outputs ``lat, lon`` (rad).

    The radii of curvature ``R_N, R_M`` are those of :func:`casship.frames.wgs84_radii` at the
    current latitude; speed and course obey the same equations as in :func:`sog_cog`.

    Parameters
    ----------
    alpha1 : float
        Singer constant of the speed over ground [1/s], parameter ``alpha1`` (bounds ``[0, 10]``).
    alpha2 : float
        Singer constant of the course rate [1/s], parameter ``alpha2`` (bounds ``[0, 10]``).

    Returns
    -------
    Model
        Named ``sog-cog-latlon`` (registered under that name); states ``lat, lon`` [rad] (angles),
        ``U`` [m/s], ``chi`` [rad], ``omega_chi`` [rad/s]; no inputs; noises ``w_U, w_chi``.

    Examples
    --------
    >>> m = sog_cog_latlon()
    >>> m.state_names, m.output_names
    (('lat', 'lon', 'U', 'chi', 'omega_chi'), ('lat', 'lon'))
    """
    b = ModelBuilder("sog-cog-latlon", "5-state SOG/COG EKF model, latitude/longitude (Fossen & Fossen 2021)")
    lat = b.state("lat", unit="rad", angle=True)
    lon = b.state("lon", unit="rad", angle=True)
    _add_speed_course(b, alpha1, alpha2)
    U, chi = b.sym("U"), b.sym("chi")
    r_n, r_m = wgs84_radii(lat)
    b.ode(lat=U * ca.cos(chi) / r_m, lon=U * ca.sin(chi) / (r_n * ca.cos(lat)))
    b.output("lat", lat)
    b.output("lon", lon)
    return b.build()


def body_kinematics() -> Model:
    """3-DOF rigid-body kinematics: earth-fixed pose driven by body velocities (Tomera 2011, Eq. 60).

    ``x' = u cos psi - v sin psi``, ``y' = u sin psi + v cos psi``, ``psi' = r`` with the body
    velocities ``u, v, r`` as inputs (e.g. from a log or from a manoeuvring model) and noise
    channels ``w_x, w_y, w_psi`` on the rates; outputs the pose ``x, y, psi``.
    """
    b = ModelBuilder("body-kinematics", "3-DOF NED pose from body velocities (Fossen 2021; Tomera 2011, Eq. 60)")
    x, y = b.state("x", unit="m"), b.state("y", unit="m")
    psi = b.state("psi", unit="rad", angle=True)
    u, v, r = b.input("u", unit="m/s"), b.input("v", unit="m/s"), b.input("r", unit="rad/s")
    xd, yd, psid = body_to_ned(u, v, r, psi)
    b.ode(x=xd + b.noise("w_x"), y=yd + b.noise("w_y"), psi=psid + b.noise("w_psi"))
    for name, sym in (("x", x), ("y", y), ("psi", psi)):
        b.output(name, sym)
    return b.build()


def _add_speed_course(b: ModelBuilder, alpha1: float, alpha2: float) -> None:
    U = b.state("U", unit="m/s", doc="speed over ground")
    b.state("chi", unit="rad", angle=True, doc="course over ground")
    om = b.state("omega_chi", unit="rad/s", doc="course rate")
    a1 = b.param("alpha1", alpha1, bounds=(0.0, 10.0), unit="1/s", doc="speed Singer constant")
    a2 = b.param("alpha2", alpha2, bounds=(0.0, 10.0), unit="1/s", doc="course-rate Singer constant")
    b.ode(U=-a1 * U + b.noise("w_U"), chi=om, omega_chi=-a2 * om + b.noise("w_chi"))
