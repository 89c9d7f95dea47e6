"""Koike et al.'s (2023) scenario: the ship, the wind in the data, the manoeuvres and the noisy records.

The ship is casship's single-propeller, twin-rudder preset with Yoshimura's low-speed hull (Koike et al. 2023,
Eq. 20-22), Euler-discretised at dt = 0.1 s (Eq. 25), every state measured (H = I6). The data carry a
gusty wind that the filters' model lacks (the modelling error of Sect. 5.1), computed by the paper's
Eq. 34 (Fujiwara's Fourier form) or, as the other reading, by Fujiwara's 2005 regression, both on the
public above-water geometry of the Esso Osaka 3 m model.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

import casship as cs
from casship.maneuvers import propeller_rate_for_speed
from casship.models.wind import add_wind
from casship.models.wind_fourier import ESSO_OSAKA_3M_WIND, add_fourier_wind
from casship.errors import InputError

DT = 0.1
R_FILTER = 5e-2                     # Koike et al. (2023) Eq. 30: R = diag(5e-2) (a variance), every state
Q_TUNED = {"UKF": 1e-4, "EnKF": 1e-2, "EKF": 1e-4}   # Koike et al. (2023) Sect. 5.1 (EKF: same as the UKF)
KAPPA, MEMBERS = 3.0, 100
WIND_MEANS = (0.0, 0.82, 1.64)      # m/s
NOISE_STDS = (0.05, 0.10, 0.20)     # data noise of experiment 2
DATA_STD = float(np.sqrt(R_FILTER))  # data noise of experiments 1 and 3: w ~ N(0, R), the paper's text
DATA_STD_ALT = 0.05                 # the other reading: the smallest level of experiment 2
WIND_FORMS = ("eq34", "fujiwara2005")
STATES = ("x", "u", "y", "v", "psi", "r")      # Koike et al. (2023) order
UNITS = {"x": "m", "u": "m/s", "y": "m", "v": "m/s", "psi": "rad", "r": "rad/s"}
FILTERS = ("UKF Q=0", "UKF tuned", "EnKF Q=0", "EnKF tuned", "KF", "EKF Q=0", "EKF tuned", "EnKF Q=1e-4")
# "EnKF Q=1e-4": the EnKF with the UKF's tuned Q, to separate the filter from the choice of Q


@dataclass(frozen=True)
class Config:
    """Record length, noise seeds and the sizes of the extra runs (quick or full)."""

    duration: float
    seeds: int
    mhe_horizon: int
    mhe_duration: float
    timing_steps: int

    @classmethod
    def make(cls, quick: bool) -> "Config":
        if quick:
            return cls(duration=40.0, seeds=2, mhe_horizon=10, mhe_duration=8.0, timing_steps=50)
        return cls(duration=200.0, seeds=10, mhe_horizon=20, mhe_duration=60.0, timing_steps=300)


def ship_models(wind_form: str = "eq34"):
    """``(truth, ship)``: the twin-rudder low-speed ship with wind (truth) and without (the filters').

    ``wind_form`` is ``"eq34"`` (the paper's Fourier form, :mod:`casship.models.wind_fourier`) or
    ``"fujiwara2005"`` (:func:`casship.models.wind.add_wind`); both use the Esso Osaka 3 m geometry.
    """
    ship = cs.models.esso_osaka_twin()
    if wind_form == "eq34":
        return add_fourier_wind(ship, ESSO_OSAKA_3M_WIND), ship
    if wind_form == "fujiwara2005":
        geometry = {k: v for k, v in ESSO_OSAKA_3M_WIND.items() if k not in ("C_BR", "source")}
        return add_wind(ship, geometry), ship
    raise InputError(f"unknown wind form {wind_form!r}; use one of {WIND_FORMS}")


def propeller_rate(ship) -> float:
    """Propeller rate [1/s] that holds the preset's speed ``U0`` in a straight run (exact trim)."""
    return propeller_rate_for_speed(ship, ship.vessel.U0, guess=10.0)


def filter_model(ship):
    """The filter's model: the ship plus additive noise on every state, ``x[k+1] = f(x[k]) + v``.

    The ship's own noise channels act on the accelerations; noise on ``x, y, psi`` is added here so
    that ``Q`` is a 6 x 6 state covariance as in the paper (channel variance = Q / dt^2 with Euler).
    """
    b = ship.builder(f"{ship.name}+state_noise")
    for s in ("x", "y", "psi"):
        b.add_to_ode(**{s: b.noise(f"w_{s}")})
    return b.build()


def q_channels(model, q_state: float) -> np.ndarray:
    """Variances of the model's noise channels that give state-noise variance ``q_state`` per step."""
    order = {"w_u": "u", "w_v": "v", "w_r": "r", "w_x": "x", "w_y": "y", "w_psi": "psi"}
    missing = set(model.noise_names) - set(order)
    if missing:
        raise ValueError(f"unexpected noise channels {sorted(missing)} in {model.name!r}")
    return np.full(model.nw, q_state / DT**2)


def gust_record(duration: float, mean: float, seed: int = 2021):
    """A gusty wind record: speed with 30 % gusts (time scale 5 s), direction wandering +-15 deg.

    Scaled copies (factor ``mean / 1.64``) give the paper's three mean speeds from one record.
    """
    t = np.arange(0.0, duration, DT)
    rng = np.random.default_rng(seed)

    def ou(tau, sigma):
        a = np.exp(-DT / tau)
        z = np.empty(t.size)
        z[0] = rng.normal(0.0, sigma)
        e = rng.normal(0.0, sigma * np.sqrt(1 - a * a), t.size)
        for k in range(1, t.size):
            z[k] = a * z[k - 1] + e[k]
        return z

    gust = ou(5.0, 0.3)
    heading = ou(20.0, np.radians(15.0))
    base = 1.64 * np.maximum(0.0, 1.0 + gust)
    base *= 1.64 / base.mean()
    return t, base * (mean / 1.64), np.radians(60.0) + heading


def rudder_inputs(kind: str, t: np.ndarray, ship, n: float, seed: int = 7) -> dict:
    """Twin-rudder commands on the grid ``t``.

    ``"zigzag"``: a 20/20 zig-zag (both rudders together, switched on the heading by
    :class:`casship.maneuvers.ZigZag`) run on the wind-free ship; the same rudder record is then
    used in every wind condition, so the conditions differ only in the wind. ``"random"``: a new
    uniform draw every 5 s, delta_s in [-35, 105] deg and delta_p in [-105, 35] deg (Koike et al. 2023).
    """
    if kind == "zigzag":
        from casship.maneuvers import ZigZag

        law = ZigZag(ship, np.radians(20.0), np.radians(20.0), n, t_exec=1.0)
        tr = cs.simulate(ship, ship.states(u=ship.vessel.U0), t, law, method="euler")
        return {"delta_s": tr["delta_s"], "delta_p": tr["delta_p"]}
    if kind == "random":
        from casship.maneuvers import random_rudder_inputs

        u = random_rudder_inputs(ship, t, n, hold=5.0, seed=seed)       # Koike et al. (2023) ranges by default
        return {"delta_s": u["delta_s"], "delta_p": u["delta_p"]}
    raise InputError(f"unknown manoeuvre {kind!r}; use 'zigzag' or 'random'")


def truth_record(truth, ship, kind: str, wind_mean: float, duration: float):
    """Noise-free trajectory of the ship with wind (the filters never see the wind)."""
    t, speed, direction = gust_record(duration, wind_mean)
    n = propeller_rate(ship)
    inputs = {"n": np.full(t.size, n), **rudder_inputs(kind, t, ship, n),
              "wind_speed": speed, "wind_dir": direction}
    return cs.simulate(truth, ship.states(u=ship.vessel.U0), t, inputs, method="euler")


def noisy(tr, ship, std: float, seed: int) -> cs.Dataset:
    """The measured record: every state of ``tr`` plus white noise of standard deviation ``std``."""
    rng = np.random.default_rng(seed)
    cols = {n: tr[n] for n in ship.input_names}
    cols.update({s: tr[s] + rng.normal(0.0, std, len(tr)) for s in STATES})
    return cs.Dataset(tr.t, cols)


def prior(data: cs.Dataset, model) -> cs.Gaussian:
    """x(0) = y(0), P(0) = I (Koike et al. 2023, Eq. 27, 31): :func:`casship.prior_from_data` with unit variances."""
    return cs.prior_from_data(model, data, var=1.0)


def rmse(res, tr) -> dict:
    """RMSE of each state of a filter result against the noise-free truth (heading on the circle)."""
    out = {}
    for s in STATES:
        err = res[s] - tr[s]
        if s == "psi":
            err = cs.wrap(err)
        out[s] = float(np.sqrt(np.mean(err**2)))
    return out
