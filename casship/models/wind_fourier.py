"""Wind loads in Fujiwara's Fourier form (Koike et al. 2023, Eq. 34; Fujiwara, Ueno & Nimura 1998).

Koike et al. (2023; UKF/EnKF guidelines for automatic berthing) write the wind loads as truncated Fourier
series of the relative wind angle, with coefficients from Fujiwara's regression on wind-tunnel tests
of many ship models (Fujiwara, Ueno & Nimura 1998, J. Soc. Naval Archit. Japan 183, 77-90)::

    C_X = X0 + X1 cos a + X3 cos 3a + X5 cos 5a
    C_Y = Y1 sin a + Y3 sin 3a + Y5 sin 5a              a = 2 pi - gamma_A
    C_N = N1 sin a + N2 sin 2a + N3 sin 3a
    X_A = q A_F C_X,   Y_A = q A_L C_Y,   N_A = q A_L L_OA C_N,   q = rho_air U_A^2 / 2

``gamma_A`` is the apparent wind angle off the bow, positive for wind from starboard (as returned by
:func:`casship.models.wind.relative_wind`); with ``a = 2 pi - gamma_A`` a head wind gives drag
(``X_A < 0``), a wind from starboard pushes the ship to port (``Y_A < 0``), and a ship with its
superstructure aft turns its bow into the wind. Each Fourier coefficient is a linear regression on
ratios of the above-water geometry (:data:`REGRESSION`).

Sources of the regression constants: the paper itself is not available here; its constants are read
from two independent public implementations of it (a MATLAB wind model of the Esso Osaka 3 m model
and a Fortran MMG low-speed model of the same ship; they agree to the last digit), with one
difference: the last term of ``Y5`` is ``C H_C / A_L`` in the Fortran and ``L H_C / A_L`` in the
MATLAB version; the Fortran reading is used (its contribution to ``C_Y`` is below 0.02 either way for
the Esso Osaka geometry). As a cross-check, for the Esso Osaka 3 m geometry the head-wind ``C_X`` and
beam-wind ``C_Y`` agree within 5 % with the independent 2005 regression in
:mod:`casship.models.wind` (tested).
"""
from __future__ import annotations

from typing import Mapping

import numpy as np

from ..model import Model
from .wind import _lib, wind_term_model
from ..errors import InputError

__all__ = ["FOURIER_GEOMETRY_NAMES", "REGRESSION", "ESSO_OSAKA_3M_WIND", "fujiwara1998_coefficients",
           "fourier_wind_coefficients", "fourier_wind_loads", "add_fourier_wind"]

#: Above-water geometry: frontal and lateral projected areas A_F (= A_T) and A_L [m^2], length overall
#: L_OA and breadth B [m], lateral area of the superstructure A_OD [m^2], height of the bridge top
#: H_BR and of the centroid of A_L above the waterline H_C [m], centroid of A_L (C) and of A_OD (C_BR)
#: forward of midship [m].
FOURIER_GEOMETRY_NAMES = ("A_F", "A_L", "L_OA", "B", "A_OD", "H_BR", "H_C", "C", "C_BR")
_UNITS = {"A_F": "m^2", "A_L": "m^2", "A_OD": "m^2"}

#: Explanatory ratios of the regression, by name.
_RATIOS = {
    "B H_BR/A_F": lambda g: g["B"] * g["H_BR"] / g["A_F"],
    "C/H_C": lambda g: g["C"] / g["H_C"],
    "A_OD/L^2": lambda g: g["A_OD"] / g["L_OA"] ** 2,
    "A_L/(L B)": lambda g: g["A_L"] / (g["L_OA"] * g["B"]),
    "L H_C/A_L": lambda g: g["L_OA"] * g["H_C"] / g["A_L"],
    "L H_BR/A_L": lambda g: g["L_OA"] * g["H_BR"] / g["A_L"],
    "A_OD/A_L": lambda g: g["A_OD"] / g["A_L"],
    "A_F/(L B)": lambda g: g["A_F"] / (g["L_OA"] * g["B"]),
    "L^2/A_F": lambda g: g["L_OA"] ** 2 / g["A_F"],
    "L/H_C": lambda g: g["L_OA"] / g["H_C"],
    "A_L/(L H_BR)": lambda g: g["A_L"] / (g["L_OA"] * g["H_BR"]),
    "A_L/A_F": lambda g: g["A_L"] / g["A_F"],
    "C_BR/L": lambda g: g["C_BR"] / g["L_OA"],
    "A_L/A_OD": lambda g: g["A_L"] / g["A_OD"],
    "C/L": lambda g: g["C"] / g["L_OA"],
    "A_F/(B H_BR)": lambda g: g["A_F"] / (g["B"] * g["H_BR"]),
    "B/H_BR": lambda g: g["B"] / g["H_BR"],
    "L/H_BR": lambda g: g["L_OA"] / g["H_BR"],
    "B^2/A_F": lambda g: g["B"] ** 2 / g["A_F"],
    "C H_C/A_L": lambda g: g["C"] * g["H_C"] / g["A_L"],
    "A_F/A_L": lambda g: g["A_F"] / g["A_L"],
    "A_F/L^2": lambda g: g["A_F"] / g["L_OA"] ** 2,
    "A_F/B^2": lambda g: g["A_F"] / g["B"] ** 2,
    "A_L/L^2": lambda g: g["A_L"] / g["L_OA"] ** 2,
}

#: Fujiwara, Ueno & Nimura (1998): each Fourier coefficient = constant + sum(coefficient * ratio).
REGRESSION: dict[str, tuple[float, tuple[tuple[float, str], ...]]] = {
    "X0": (-0.330, ((0.293, "B H_BR/A_F"), (0.0193, "C/H_C"), (0.682, "A_OD/L^2"))),
    "X1": (-1.353, ((1.700, "A_L/(L B)"), (2.870, "L H_C/A_L"), (-0.463, "L H_BR/A_L"), (-0.570, "A_OD/A_L"),
                    (-6.640, "A_F/(L B)"), (-0.0123, "L^2/A_F"), (0.0202, "L/H_C"))),
    "X3": (0.830, ((-0.413, "A_L/(L H_BR)"), (-0.0827, "A_L/A_F"), (-0.563, "L H_C/A_L"), (0.804, "A_OD/A_L"),
                   (-5.670, "A_OD/L^2"), (0.0401, "C/H_C"), (-0.132, "C_BR/L"))),
    "X5": (0.0372, ((-0.0075, "A_L/A_OD"), (-0.103, "C_BR/L"), (0.0921, "A_L/(L B)"))),
    "Y1": (0.684, ((0.717, "C_BR/L"), (-3.220, "C/L"), (0.0281, "A_L/A_OD"), (0.0661, "C/H_C"),
                   (0.298, "A_F/(B H_BR)"))),
    "Y3": (-0.400, ((0.282, "A_L/(L B)"), (0.307, "L H_C/A_L"), (0.0519, "C_BR/L"), (0.0526, "B/H_BR"),
                    (-0.0814, "A_OD/A_L"), (0.0582, "A_F/(B H_BR)"))),
    "Y5": (0.122, ((-0.166, "A_L/(L B)"), (-0.0054, "L/H_BR"), (-0.0481, "C_BR/L"), (-0.0136, "B^2/A_F"),
                   (0.0864, "C/L"), (-0.0297, "C H_C/A_L"))),
    "N1": (0.299, ((1.710, "C/L"), (0.183, "L H_C/A_L"), (-1.090, "A_F/A_L"), (-0.0442, "C/H_C"),
                   (-0.289, "A_L/(L B)"), (4.240, "A_F/L^2"), (-0.0646, "B^2/A_F"), (0.0306, "C_BR/L"))),
    "N2": (0.117, ((0.123, "C_BR/L"), (-0.323, "C/L"), (0.0041, "A_L/A_OD"), (-0.166, "A_F/B^2"),
                   (-0.0109, "L/H_BR"), (0.174, "A_F/(B H_BR)"), (0.214, "A_L/(L B)"), (-1.060, "A_L/L^2"))),
    "N3": (0.0230, ((0.0385, "C_BR/L"), (-0.0339, "A_F/(B H_BR)"), (0.0023, "A_L/A_F"))),
}

#: Above-water geometry of the Esso Osaka 3 m model (Osaka University's berthing test ship), as given
#: with a public MATLAB implementation of this regression (CGMRES_Autopilot_EssoOsaka, "values by
#: MYO"): the ship of Koike et al.'s (2023) kind, with its superstructure aft.
ESSO_OSAKA_3M_WIND = {"A_F": 0.1524, "A_L": 0.2917, "L_OA": 3.0, "B": 0.5, "A_OD": 0.1531, "H_BR": 0.3321,
                      "H_C": 0.04936, "C": 0.03339, "C_BR": -1.23339,
                      "source": "Esso Osaka 3 m model, public MATLAB wind model (values by MYO)"}


def fujiwara1998_coefficients(g: Mapping) -> dict:
    """The ten Fourier coefficients ``X0, X1, X3, X5, Y1, Y3, Y5, N1, N2, N3`` for geometry ``g``.

    Parameters
    ----------
    g : mapping
        Values (numbers or CasADi symbols) for :data:`FOURIER_GEOMETRY_NAMES`.

    Examples
    --------
    >>> from casship.models.wind_fourier import ESSO_OSAKA_3M_WIND, fujiwara1998_coefficients
    >>> round(fujiwara1998_coefficients(ESSO_OSAKA_3M_WIND)["Y1"], 3)
    0.725
    """
    missing = [k for k in FOURIER_GEOMETRY_NAMES if k not in g]
    if missing:
        raise InputError(f"Fourier wind: no value for geometry {missing}")
    return {name: const + sum(c * _RATIOS[ratio](g) for c, ratio in terms)
            for name, (const, terms) in REGRESSION.items()}


def fourier_wind_coefficients(gamma, coeffs: Mapping):
    """``(C_X, C_Y, C_N)`` of Eq. 34 in body axes (x forward, y to starboard, N clockwise from above).

    Parameters
    ----------
    gamma : float, array or CasADi symbol
        Apparent wind angle [rad] off the bow, positive for wind from starboard.
    coeffs : mapping
        The Fourier coefficients (:func:`fujiwara1998_coefficients`).

    Returns
    -------
    tuple
        ``C_X, C_Y, C_N``.
    """
    lib = _lib(gamma, *coeffs.values())
    a = 2.0 * np.pi - gamma
    c = coeffs
    C_X = c["X0"] + c["X1"] * lib.cos(a) + c["X3"] * lib.cos(3 * a) + c["X5"] * lib.cos(5 * a)
    C_Y = c["Y1"] * lib.sin(a) + c["Y3"] * lib.sin(3 * a) + c["Y5"] * lib.sin(5 * a)
    C_N = c["N1"] * lib.sin(a) + c["N2"] * lib.sin(2 * a) + c["N3"] * lib.sin(3 * a)
    return C_X, C_Y, C_N


def fourier_wind_loads(U_A, gamma, g: Mapping, rho_air: float = 1.225):
    """Wind force ``(X, Y, N)`` [N, N, N m] in body axes by Eq. 34.

    Parameters
    ----------
    U_A : float, array or CasADi symbol
        Apparent wind speed [m/s].
    gamma : float, array or CasADi symbol
        Apparent wind angle [rad] off the bow, positive for wind from starboard.
    g : mapping
        Geometry (:data:`FOURIER_GEOMETRY_NAMES`).
    rho_air : float
        Air density [kg/m^3].

    Returns
    -------
    tuple
        ``X, Y, N``.
    """
    C_X, C_Y, C_N = fourier_wind_coefficients(gamma, fujiwara1998_coefficients(g))
    q = 0.5 * rho_air * U_A**2
    return q * g["A_F"] * C_X, q * g["A_L"] * C_Y, q * g["A_L"] * g["L_OA"] * C_N


def add_fourier_wind(model: Model, geometry: Mapping[str, float] | None = None, *, rho_air: float = 1.225,
                     name: str | None = None) -> Model:
    """The ship ``model`` with the wind loads of Koike et al.'s (2023) Eq. 34 fed into its ``tau`` port.

    Same inputs as :func:`casship.models.wind.add_wind` (``wind_speed`` [m/s], ``wind_dir`` [rad, the
    direction the true wind comes from, clockwise from North]); the loads follow the Fourier form above.

    Parameters
    ----------
    model : Model
        A 3-DOF ship with states ``u, v, r, x, y, psi`` and a port ``tau``.
    geometry : mapping, optional
        Values for :data:`FOURIER_GEOMETRY_NAMES` (by default ``model.vessel.wind``, which must then
        hold ``C_BR`` too). They become parameters ``wind_A_F, ...`` plus ``rho_air``.
    rho_air : float
        Air density [kg/m^3].
    name : str, optional
        Name of the new model (default ``model.name + "+wind34"``).

    Returns
    -------
    Model

    Examples
    --------
    >>> from casship.models import esso_osaka_twin
    >>> from casship.models.wind_fourier import ESSO_OSAKA_3M_WIND, add_fourier_wind
    >>> ship = add_fourier_wind(esso_osaka_twin(), ESSO_OSAKA_3M_WIND)
    >>> ship.input_names[-2:]
    ('wind_speed', 'wind_dir')
    """
    return wind_term_model(model, geometry, FOURIER_GEOMETRY_NAMES, _UNITS, fourier_wind_loads, rho_air=rho_air,
                           what="add_fourier_wind", label="Eq. 34", name=name or f"{model.name}+wind34")
