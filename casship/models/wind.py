"""Wind loads (Fujiwara regression) and uniform current as terms added to any 3-DOF ship model.

Both extend a model built on :func:`casship.models.mmg.rigid_body_3dof` (states ``u, v, r, x, y,
psi`` and the port ``tau``) through :meth:`casship.Model.extend`:

* :func:`add_wind` adds inputs ``wind_speed`` [m/s] and ``wind_dir`` [rad] (true wind, the direction
  the wind comes *from*, clockwise from North) and feeds the Fujiwara force ``[X_A, Y_A, N_A]`` into
  ``tau``. Inputs can be constants or time series (any input form :func:`casship.simulate` takes),
  so a measured wind record is simply two input columns.
* :func:`add_current` adds inputs ``current_speed`` [m/s] and ``current_dir`` [rad] (the direction the
  current flows *towards*, clockwise from North). For a uniform, steady current the hydrodynamics
  depend on the velocity through the water, so ``u, v`` stay water-relative and the current is
  added to the earth-fixed kinematics ``x', y'``; wind added to such a model uses the velocity
  over ground (water-relative plus current).

Fujiwara, Ueno & Nimura (1998) / Fujiwara, Ueno & Ikeda (2005), in the form of the project's
reference table (section 3), with ``theta = |gamma_A|`` the relative wind angle off the bow
(0 = head wind) and the force to the lee side::

    C_X = C_LF cos(th) + C_XLI (sin th - sin th cos^2 th / 2) sin th cos th + C_ALF sin th cos^3 th
    C_Y = C_CF sin^2 th + C_YLI (cos th + sin^2 th cos th / 2) sin th cos th
    C_N = C_Y (0.927 C / L_OA - 0.149 (th - pi/2))
    X_A = q A_F C_X,   Y_A = -s q A_L C_Y,   N_A = -s q A_L L_OA C_N,   q = rho_air U_A^2 / 2

where ``s = sign(gamma_A)`` (+1 for wind from starboard, which pushes the ship to port, ``Y < 0``) and
the regression coefficients switch at ``theta = 90 deg`` (where every switched term is multiplied
by ``cos theta = 0``, so the loads stay continuous). The ``90-180 deg`` ``C_YLI`` uses ``A_OD/L^2``
(the reference marks ``A_OD`` vs ``A_F`` as uncertain; ``A_OD`` follows the ISO 15016 form).
"""
from __future__ import annotations

from typing import Mapping

import casadi as ca
import numpy as np

from ..builder import ModelBuilder
from ..model import Model
from ..errors import InputError

__all__ = ["add_wind", "add_current", "fujiwara_coefficients", "fujiwara_loads", "relative_wind", "wind_term_model",
           "WIND_GEOMETRY_NAMES"]

#: Geometry of the above-water hull: frontal/lateral projected areas, length overall, breadth,
#: lateral area of superstructure, height of the top of the bridge and of the centroid of A_L above
#: the waterline, and the centroid of A_L forward of midship.
WIND_GEOMETRY_NAMES = ("A_F", "A_L", "L_OA", "B", "A_OD", "H_BR", "H_C", "C")
_UNITS = {"A_F": "m^2", "A_L": "m^2", "L_OA": "m", "B": "m", "A_OD": "m^2", "H_BR": "m", "H_C": "m", "C": "m"}


def _lib(*values):
    return ca if any(isinstance(v, (ca.SX, ca.MX, ca.DM)) for v in values) else np


def _where(lib, cond, a, b):
    return ca.if_else(cond, a, b) if lib is ca else np.where(cond, a, b)


def fujiwara_coefficients(gamma, g: Mapping):
    """Fujiwara coefficients ``(C_X, C_Y, C_N)`` for the relative wind angle ``gamma`` [rad].

    ``gamma`` is measured from the bow, positive for wind from starboard, in ``[-pi, pi]``; the
    returned ``C_Y`` and ``C_N`` are signed so that ``Y = q A_L C_Y`` and ``N = q A_L L_OA C_N`` in
    body axes (y to starboard). Works on numbers (numpy) and CasADi symbols.

    Parameters
    ----------
    gamma : float, array or SX
    g : mapping
        Geometry with the keys of :data:`WIND_GEOMETRY_NAMES` (values or symbols).
    """
    lib = _lib(gamma, *g.values())
    A_F, A_L, L, B = g["A_F"], g["A_L"], g["L_OA"], g["B"]
    A_OD, H_BR, H_C, C = g["A_OD"], g["H_BR"], g["H_C"], g["C"]
    th = lib.fabs(gamma) if lib is ca else np.abs(gamma)
    head = th < np.pi / 2
    C_LF = _where(lib, head, -0.922 + 0.507 * A_L / (L * B) + 1.162 * C / L,
                  0.018 - 5.091 * B / L + 10.367 * H_C / L - 3.011 * A_OD / L**2 - 0.341 * A_F / B**2)
    C_XLI = _where(lib, head, 0.458 + 3.245 * A_L / (L * H_BR) - 2.313 * A_F / (B * H_BR),
                   -1.901 + 12.727 * A_L / (L * H_BR) + 24.407 * A_F / A_L - 40.310 * B / L
                   - 5.481 * A_F / (B * H_BR))
    C_ALF = _where(lib, head, -0.585 - 0.906 * A_OD / A_L + 3.239 * B / L, -0.314 - 1.117 * A_OD / A_L)
    C_CF = 0.404 + 0.368 * A_F / (B * H_BR) + 0.902 * H_BR / L
    C_YLI = _where(lib, head, np.pi * A_L / L**2 + 0.116 + 3.345 * A_F / (L * B),
                   np.pi * A_L / L**2 + 0.446 + 2.192 * A_OD / L**2)
    s, c = lib.sin(th), lib.cos(th)
    C_X = C_LF * c + C_XLI * (s - 0.5 * s * c**2) * s * c + C_ALF * s * c**3
    C_Y = C_CF * s**2 + C_YLI * (c + 0.5 * s**2 * c) * s * c
    C_N = C_Y * (0.927 * C / L - 0.149 * (th - np.pi / 2))
    sign = _where(lib, gamma >= 0, 1.0, -1.0)
    return C_X, -sign * C_Y, -sign * C_N


def relative_wind(u_g, v_g, psi, wind_speed, wind_dir):
    """Apparent wind speed ``U_A`` and angle ``gamma_A`` (off the bow, + from starboard).

    ``u_g, v_g`` is the ship's velocity over ground in body axes, ``wind_dir`` the true direction
    the wind comes from (clockwise from North). Works on numbers (numpy) and CasADi symbols.

    Parameters
    ----------
    u_g, v_g : float, array_like or casadi.SX/MX
        Surge and sway velocity over ground in body axes [m/s] (through the water plus current).
    psi : float, array_like or casadi.SX/MX
        Heading from North, clockwise positive [rad].
    wind_speed : float, array_like or casadi.SX/MX
        True wind speed [m/s].
    wind_dir : float, array_like or casadi.SX/MX
        True wind direction [rad]: where the wind comes *from*, clockwise from North.

    Returns
    -------
    U_A : same type as the inputs
        Apparent wind speed [m/s].
    gamma_A : same type as the inputs
        Apparent wind angle off the bow in [-pi, pi] [rad]: 0 for a head wind, positive for wind
        from starboard.

    Examples
    --------
    >>> U_A, gamma = relative_wind(0.0, 0.0, 0.0, 10.0, np.pi / 2)   # at rest, wind from the East
    >>> float(U_A), float(gamma)
    (10.0, 1.5707963267948966)
    >>> U_A, gamma = relative_wind(5.0, 0.0, 0.0, 10.0, 0.0)          # 5 m/s into a northerly
    >>> float(U_A), float(gamma)
    (15.0, 0.0)
    """
    lib = _lib(u_g, v_g, psi, wind_speed, wind_dir)
    rel = wind_dir - psi
    # air velocity relative to the ship in body axes (the wind blows towards wind_dir + pi)
    u_a = -wind_speed * lib.cos(rel) - u_g
    v_a = -wind_speed * lib.sin(rel) - v_g
    U_A = lib.sqrt(u_a**2 + v_a**2)
    gamma = lib.arctan2(-v_a, -u_a) if lib is np else ca.atan2(-v_a, -u_a)
    return U_A, gamma


def fujiwara_loads(U_A, gamma, g: Mapping, rho_air: float = 1.225):
    """Wind force ``(X, Y, N)`` [N, N, N m] in body axes for apparent wind ``U_A``, ``gamma``.

    ``X = q A_F C_X``, ``Y = q A_L C_Y``, ``N = q A_L L_OA C_N`` with ``q = rho_air U_A^2 / 2`` and the
    signed coefficients of :func:`fujiwara_coefficients`. Works on numbers and CasADi symbols.

    Parameters
    ----------
    U_A : float, array_like or casadi.SX/MX
        Apparent wind speed [m/s] (see :func:`relative_wind`).
    gamma : float, array_like or casadi.SX/MX
        Apparent wind angle off the bow [rad], positive for wind from starboard, in [-pi, pi].
    g : mapping
        Above-water geometry with the keys of :data:`WIND_GEOMETRY_NAMES` (areas [m^2], lengths
        [m]), e.g. ``model.vessel.wind``; other keys are ignored.
    rho_air : float or casadi.SX/MX
        Air density [kg/m^3].

    Returns
    -------
    X, Y, N : same type as ``U_A``
        Surge force [N], sway force [N] (to starboard) and yaw moment [N m] (clockwise seen from
        above) in body axes.

    Examples
    --------
    >>> from casship.models import kvlcc2
    >>> g = kvlcc2().vessel.wind
    >>> X, Y, N = fujiwara_loads(10.0, np.pi / 2, g)   # 10 m/s beam wind from starboard
    >>> round(float(Y))                                 # pushes the ship to port
    -227920
    """
    C_X, C_Y, C_N = fujiwara_coefficients(gamma, g)
    q = 0.5 * rho_air * U_A**2
    return q * g["A_F"] * C_X, q * g["A_L"] * C_Y, q * g["A_L"] * g["L_OA"] * C_N


def _check_ship(b: ModelBuilder, what: str) -> None:
    for name in ("u", "v", "psi", "x", "y"):
        if not b.has(name):
            raise InputError(f"{what}: the model has no state {name!r} (needs a 3-DOF ship model)")


def add_wind(model: Model, geometry: Mapping[str, float] | None = None, *, rho_air: float = 1.225,
             name: str | None = None) -> Model:
    """The ship ``model`` with Fujiwara wind loads fed into its ``tau`` port.

    Parameters
    ----------
    model : Model
        A 3-DOF ship with states ``u, v, r, x, y, psi`` and a port ``tau`` (all casship ships).
    geometry : mapping, optional
        Values for :data:`WIND_GEOMETRY_NAMES`; by default ``model.vessel.wind``. They become
        parameters ``wind_A_F, wind_A_L, ...`` (so they can be identified) plus ``rho_air``.
    rho_air : float
        Air density [kg/m^3].
    name : str, optional
        Name of the new model (default ``model.name + "+wind"``).

    Returns
    -------
    Model
        With new inputs ``wind_speed`` [m/s] and ``wind_dir`` [rad, from, clockwise from North].

    Examples
    --------
    >>> from casship.models import kvlcc2
    >>> from casship.models.wind import add_wind
    >>> ship = add_wind(kvlcc2())
    >>> ship.input_names
    ('delta', 'n', 'wind_speed', 'wind_dir')
    """
    return wind_term_model(model, geometry, WIND_GEOMETRY_NAMES, _UNITS, fujiwara_loads, rho_air=rho_air,
                           what="add_wind", label="Fujiwara", name=name or f"{model.name}+wind")


def wind_term_model(model: Model, geometry: Mapping[str, float] | None, names, units: Mapping[str, str], loads, *,
                    rho_air: float, what: str, label: str, name: str) -> Model:
    """``model`` with wind loads ``loads(U_A, gamma, g, rho_air) -> (X, Y, N)`` fed into its ``tau`` port.

    The shared body of :func:`add_wind` and of the other wind-load forms (Koike et al. 2023, Eq. 34 in
    :mod:`casship.models.wind_fourier`): checks the geometry (``names``; by default
    ``model.vessel.wind``), makes it parameters ``wind_<name>`` (the centroid offsets ``C`` and
    ``C_BR`` may be negative), adds the inputs ``wind_speed`` and ``wind_dir`` and the parameter
    ``rho_air``, and uses the velocity over ground when the model has a current.

    Parameters
    ----------
    model : Model
    geometry : mapping or None
        Geometry values (None: ``model.vessel.wind``).
    names : sequence of str
        The geometry names the load form needs.
    units : mapping
        Unit of each geometry name (default ``"m"``).
    loads : callable
        ``loads(U_A, gamma, g, rho_air) -> (X, Y, N)`` on CasADi symbols.
    rho_air : float
        Air density [kg/m^3].
    what, label : str
        The calling function's name (for messages) and the load form's name (for parameter docs).
    name : str
        Name of the new model.

    Returns
    -------
    Model
    """
    default = model.vessel.wind if model.vessel is not None else None
    geometry = dict(geometry if geometry is not None else default or {})
    geometry.pop("source", None)
    missing = [k for k in names if k not in geometry]
    if missing:
        raise InputError(f"{what}: no value for wind geometry {missing} (model {model.name!r} has no "
                         "vessel wind geometry; pass geometry=...)")
    unknown = set(geometry) - set(names)
    if unknown:
        raise InputError(f"{what}: unknown wind geometry name(s) {sorted(unknown)}; known: {tuple(names)}")

    def term(b: ModelBuilder) -> None:
        _check_ship(b, what)
        g = {k: b.param(f"wind_{k}", geometry[k], unit=units.get(k, "m"), doc=f"wind geometry {k} ({label})",
                        bounds=(-np.inf, np.inf) if k in ("C", "C_BR") else (1e-9, np.inf)) for k in names}
        rho = b.param("rho_air", rho_air, unit="kg/m^3", doc="air density", bounds=(0.0, np.inf))
        speed = b.input("wind_speed", unit="m/s", doc="true wind speed")
        direction = b.input("wind_dir", unit="rad", angle=True, doc="true wind direction (from), clockwise from North")
        u, v, psi = b.sym("u"), b.sym("v"), b.sym("psi")
        if b.has("current_speed"):
            uc, vc = _current_body(b.sym("current_speed"), b.sym("current_dir"), psi)
            u, v = u + uc, v + vc
        U_A, gamma = relative_wind(u, v, psi, speed, direction)
        X, Y, N = loads(U_A, gamma, g, rho)
        b.feed("tau", ca.vertcat(X, Y, N))

    return model.extend(term, name)


def _current_body(speed, direction, psi):
    rel = direction - psi
    return speed * ca.cos(rel), speed * ca.sin(rel)


def add_current(model: Model, name: str | None = None) -> Model:
    """The ship ``model`` in a uniform, steady current (inputs ``current_speed``, ``current_dir``).

    ``u, v`` remain velocities through the water; the current (flowing *towards* ``current_dir``,
    clockwise from North) is added to ``x'`` and ``y'``. Add the current before the wind so that
    the wind sees the velocity over ground.

    Parameters
    ----------
    model : Model
        A 3-DOF ship with states ``u, v, x, y, psi`` (all casship ships).
    name : str, optional
        Name of the new model (default ``model.name + "+current"``).

    Returns
    -------
    Model
        With new inputs ``current_speed`` [m/s] and ``current_dir`` [rad, towards, clockwise from
        North] after the model's own inputs.

    Raises
    ------
    ValueError
        If the model lacks one of the states ``u, v, x, y, psi``.

    Examples
    --------
    >>> from casship.models import kvlcc2
    >>> ship = add_wind(add_current(kvlcc2()))   # current first: the wind sees the ground speed
    >>> ship.name, ship.input_names
    ('kvlcc2+current+wind', ('delta', 'n', 'current_speed', 'current_dir', 'wind_speed', 'wind_dir'))
    """
    def term(b: ModelBuilder) -> None:
        _check_ship(b, "add_current")
        speed = b.input("current_speed", unit="m/s", doc="current speed")
        direction = b.input("current_dir", unit="rad", angle=True, doc="current direction (towards), clockwise from North")
        b.add_to_ode(x=speed * ca.cos(direction), y=speed * ca.sin(direction))

    return model.extend(term, name or f"{model.name}+current")
