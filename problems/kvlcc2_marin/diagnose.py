"""Why a turn goes wrong: the circle through the turn and the force balance of its steady part.

* :func:`through_the_turn` -- speed, drift angle and non-dimensional yaw rate ``r' = r L / U`` when
  the heading has changed by 15 ... 360 deg, measured and replayed (a fit file, the published
  constants): where a replay turns too tightly, and whether through speed loss or yaw rate.
* :func:`steady_turn_balance` -- the model's surge force and yaw moment at the *measured* mean state of
  the steady part of the turn (from a heading change of 360 deg until the rudder leaves its angle): hull (with the
  propeller-induced terms), propeller, rudder and the centripetal term ``(m + m_y) v r``, and the
  surge acceleration and the yaw moment they leave. At a steady measured state both should be near
  zero; a rudder moment that beats the hull's says the model turns too tightly there, a negative
  surge balance that it loses too much speed.
"""
from __future__ import annotations

import numpy as np

from casship.identify import read_params
from casship.identify import replay_file
from casship.models.mmg import SMOOTH_WIDTH, mmg_forces, mmg_propeller
from casship.maneuvers import replay

from .workflow import study_model

__all__ = ["HEADINGS_DEG", "through_the_turn", "steady_turn_balance"]

HEADINGS_DEG = (15, 30, 60, 90, 180, 270, 360)


def _at_headings(t, psi, u, v, r, L) -> dict:
    change = np.degrees(np.unwrap(psi) - psi[0])
    change = change * np.sign(change[np.argmax(np.abs(change))])
    out = {}
    for target in HEADINGS_DEG:
        k = np.flatnonzero(change >= target)
        if not k.size:
            continue
        k = k[0]
        U = float(np.hypot(u[k], v[k]))
        out[f"{target} deg"] = (f"t {t[k] - t[0]:.0f} s, U {U:.2f} m/s, beta {np.degrees(np.arctan2(-v[k], u[k])):.1f} deg, "
                                f"r' {r[k] * L / U:.3f}")
    return out


def through_the_turn(run, fit_files: dict, published) -> dict:
    """Rows ``measured``, ``published`` and one per fit file (label -> path) of :data:`HEADINGS_DEG`."""
    L = published.vessel.L_pp
    d = run.data
    rows = {"measured": _at_headings(d.t, d["psi"], d["u"], d["v"], d["r"], L)}
    trajectories = {"published": replay(published, d).trajectory}
    trajectories.update({label: replay_file(path, d, study_model(), samples=0).trajectory for label, path in fit_files.items()})
    for label, tr in trajectories.items():
        rows[label] = _at_headings(tr.t, tr["psi"], tr["u"], tr["v"], tr["r"], L)
    return rows


def _balance(P: dict, state: dict, options: dict) -> dict:
    u, v, r, delta, n = (state[c] for c in ("u", "v", "r", "delta", "n"))
    smooth = SMOOTH_WIDTH if options.get("smooth") else None
    inflow = options.get("rudder_inflow", "published")
    X, Y, N = (float(f) for f in mmg_forces(P, u, v, r, delta, n, smooth, inflow))
    X0, _, N0 = (float(f) for f in mmg_forces(dict(P, f_alpha=0.0), u, v, r, delta, n, smooth, inflow))
    T = float(mmg_propeller(P, u, v, r, n, smooth)[0])
    rho, L, d = P["rho"], P["L_pp"], P["d"]
    m = rho * P["nabla"]
    m_x, m_y = (P[k] * 0.5 * rho * L**2 * d for k in ("m_x_dash", "m_y_dash"))
    centripetal = (m + m_y) * v * r + P["x_G"] * m * r**2
    X_P = (1 - P["t_P"]) * T
    return {k: float(v) for k, v in {"X hull [kN]": (X0 - X_P) / 1e3, "X propeller [kN]": X_P / 1e3, "X rudder [kN]": (X - X0) / 1e3,
            "(m + m_y) v r [kN]": centripetal / 1e3, "du/dt left [mm/s^2]": 1e3 * (X + centripetal) / (m + m_x),
            "N rudder [MN m]": (N - N0) / 1e6, "N hull + propeller [MN m]": N0 / 1e6, "N left [MN m]": N / 1e6}.items()}


def steady_turn_balance(run, fit_files: dict, published) -> dict:
    """The balance (see the module text) at the measured mean state of the steady turn, for the published
    constants and each fit file (label -> path); with ``"state"``, the mean state and its time span."""
    d = run.data
    change = np.abs(np.degrees(np.unwrap(d["psi"]) - d["psi"][0]))
    start = int(np.flatnonzero(change >= min(360.0, 0.5 * change.max()))[0])
    moved = np.flatnonzero(np.abs(np.degrees(d["delta"][start:] - d["delta"][start])) > 1.0)
    end = start + int(moved[0]) if moved.size else len(d.t)         # until the rudder leaves its turning angle
    k = np.zeros(len(d.t), bool)
    k[start:end] = True
    state = {c: float(np.mean(d[c][k])) for c in ("u", "v", "r", "delta", "n")}
    rows = {"published": _balance(published.param_dict(), state, published.meta.get("options", {}))}
    for label, path in fit_files.items():
        model, p = read_params(path, "kvlcc2")
        rows[label] = _balance(dict(zip(model.param_names, np.asarray(p, dtype=float).ravel())), state,
                               model.meta.get("options", {}))
    span = (float(d.t[k][0] - d.t[0]), float(d.t[-1] - d.t[0]))
    return {"rows": rows, "state": state, "span_s": span}
