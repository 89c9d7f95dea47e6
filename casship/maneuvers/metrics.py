"""IMO/ITTC manoeuvre metrics from any record (simulated or measured) with columns ``x, y, psi``.

:func:`turning_metrics` (advance, transfer, tactical diameter, steady diameter and speed, times to
90/180 deg), :func:`zigzag_metrics` (overshoot angles, their times, period, initial turning time and
distance), :func:`execute_time`, and :func:`imo_check` (IMO MSC.137(76) criteria, pass/fail rows)
with :func:`imo_table` (Markdown).
"""
from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np

from ..angles import unwrap
from ..data import Dataset
from ..errors import InputError

__all__ = ["execute_time", "turning_metrics", "zigzag_metrics", "imo_check", "imo_table"]


# -- metrics --------------------------------------------------------------------------------------------
def execute_time(data: Dataset, rudder: str = "delta", threshold_deg: float = 1.0) -> float:
    """Time of the execute: first sample where ``|delta - delta(0)| > threshold_deg``.

    Parameters
    ----------
    data : Dataset
        Record with a rudder column.
    rudder : str
        Name of the rudder column [rad].
    threshold_deg : float
        Rudder movement that counts as the execute [deg].

    Returns
    -------
    float
        Time of the execute [s].

    Raises
    ------
    ValueError
        No rudder column, or the rudder never moves by the threshold.
    """
    if rudder not in data:
        raise InputError(f"no rudder column {rudder!r} to find the execute time; give t_exec")
    d = np.asarray(data[rudder])
    moved = np.flatnonzero(np.abs(d - d[0]) > np.radians(threshold_deg))
    if moved.size == 0:
        raise InputError(f"rudder column {rudder!r} never moves by more than {threshold_deg} deg")
    return float(data.t[moved[0]])


def _crossing(t, s, level, start=0):
    """First fractional time (linear interpolation) at or after index ``start`` where s >= level."""
    idx = np.flatnonzero(s[start:] >= level)
    if idx.size == 0:
        return None, None
    k = start + idx[0]
    if k == 0 or s[k - 1] >= level:
        return float(t[k]), k
    frac = (level - s[k - 1]) / (s[k] - s[k - 1])
    return float(t[k - 1] + frac * (t[k] - t[k - 1])), k


def _interp_at(t, values, t_star, k):
    if k == 0:
        return values[0]
    return float(np.interp(t_star, t[k - 1:k + 1], values[k - 1:k + 1]))


def _fit_circle(x, y):
    A = np.column_stack([2 * x, 2 * y, np.ones_like(x)])
    sol, *_ = np.linalg.lstsq(A, x**2 + y**2, rcond=None)
    a, b, c = sol
    return float(np.sqrt(c + a * a + b * b)), (float(a), float(b))


def turning_metrics(data: Dataset, *, t_exec: float | None = None, L: float | None = None,
                    rudder: str = "delta", steady_from_deg: float = 360.0) -> dict:
    """Turning-circle metrics from a record with columns ``x, y, psi`` (and ``delta`` or ``t_exec``).

    Distances are measured from the position at the execute, in the frame of the heading at the
    execute: *advance* is the distance along the original heading when the heading has changed
    by 90 deg, *transfer* the lateral distance then, *tactical diameter* the lateral distance at a
    180 deg change. The *steady diameter* is a least-squares circle through the positions from
    ``steady_from_deg`` heading change (180 deg if the record turns less) to the end of the record
    or, with a rudder column, until the rudder leaves its turning angle (pull-out). The steady speed
    is the mean of ``hypot(u, v)`` (or of the position rates) over the same part.

    Parameters
    ----------
    data : Dataset
        Record with columns ``x, y, psi`` [m, m, rad] (``u, v`` optional).
    t_exec : float, optional
        Execute time [s]; by default from the rudder column (:func:`execute_time`).
    L : float, optional
        Ship length [m], for the ``*_L`` ratios.
    rudder : str
        Name of the rudder column.
    steady_from_deg : float
        Heading change from which the turn counts as steady [deg].

    Returns
    -------
    dict
        ``advance_m, transfer_m, tactical_diameter_m, steady_diameter_m, steady_speed_mps,
        time_to_90_s, time_to_180_s, turn_direction`` (+1 starboard, -1 port) and, with ``L``,
        the ``*_L`` ratios. Keys of quantities the record does not reach are absent.
    """
    t = data.t
    if t_exec is None:
        t_exec = execute_time(data, rudder)
    k0 = int(np.searchsorted(t, t_exec))
    if k0 >= t.size - 2:
        raise InputError(f"execute time {t_exec} s is at the end of the record")
    x, y = np.asarray(data["x"], dtype=float), np.asarray(data["y"], dtype=float)
    psi = unwrap(np.asarray(data["psi"], dtype=float))
    psi0 = float(np.interp(t_exec, t, psi))
    x0, y0 = float(np.interp(t_exec, t, x)), float(np.interp(t_exec, t, y))
    along = (x - x0) * np.cos(psi0) + (y - y0) * np.sin(psi0)
    lateral = -(x - x0) * np.sin(psi0) + (y - y0) * np.cos(psi0)
    change = psi - psi0
    sub = change[k0:]
    direction = 1.0 if sub[np.argmax(np.abs(sub))] >= 0 else -1.0
    s = direction * change
    out = {"turn_direction": int(direction), "t_exec_s": float(t_exec)}
    for angle, key in ((90.0, "90"), (180.0, "180")):
        tc, k = _crossing(t, s, np.radians(angle), k0)
        if tc is None:
            continue
        out[f"time_to_{key}_s"] = tc - t_exec
        if angle == 90.0:
            out["advance_m"] = _interp_at(t, along, tc, k)
            out["transfer_m"] = direction * _interp_at(t, lateral, tc, k)
        else:
            out["tactical_diameter_m"] = direction * _interp_at(t, lateral, tc, k)
    # steady part
    end = t.size
    if rudder in data:
        d = np.asarray(data[rudder])
        k_hold = int(np.searchsorted(t, t_exec + out.get("time_to_90_s", 0.0)))
        if k_hold < t.size:
            left = np.flatnonzero(np.abs(d[k_hold:] - d[k_hold]) > np.radians(1.0))
            if left.size:
                end = k_hold + left[0]
    s_end = s[:end]
    start_deg = steady_from_deg if s_end.max(initial=-np.inf) >= np.radians(steady_from_deg + 90) else 180.0
    steady = np.flatnonzero(s_end >= np.radians(start_deg))
    if steady.size >= 10 and s_end[steady[-1]] - s_end[steady[0]] >= np.radians(60):
        seg = slice(steady[0], steady[-1] + 1)
        out["steady_diameter_m"] = 2 * _fit_circle(x[seg], y[seg])[0]
        if "u" in data and "v" in data:
            speed = np.hypot(data["u"][seg], data["v"][seg])
        else:
            speed = np.hypot(np.gradient(x[seg], t[seg]), np.gradient(y[seg], t[seg]))
        out["steady_speed_mps"] = float(np.mean(speed))
        out["steady_from_deg"] = float(start_deg)
    if L:
        for key in ("advance_m", "transfer_m", "tactical_diameter_m", "steady_diameter_m"):
            if key in out:
                out[key[:-2] + "_L"] = out[key] / L
    return out


def zigzag_metrics(data: Dataset, heading_deg: float, *, t_exec: float | None = None, rudder: str = "delta",
                   L: float | None = None) -> dict:
    """Zig-zag metrics from a record with ``psi`` (and ``delta`` or ``t_exec``; ``x, y`` optional).

    With ``dpsi`` the heading change from the execute and ``s`` the first side (+1 starboard; from
    the first crossing of ``+-heading_deg``), the reversals happen where ``s dpsi`` reaches
    ``+heading``, ``-heading``, ``+heading`` ...; the *k-th overshoot* is the largest excess of
    ``|dpsi|`` over the switch angle between reversal k and k+1.

    Parameters
    ----------
    data : Dataset
        Record with a column ``psi`` [rad] (``x, y`` optional).
    heading_deg : float
        Switch heading [deg] (> 0).
    t_exec : float, optional
        Execute time [s]; by default from the rudder column.
    rudder : str
        Name of the rudder column.
    L : float, optional
        Ship length [m], for ``initial_turning_distance_L``.

    Returns
    -------
    dict
        ``overshoot_1_deg, overshoot_2_deg`` (and ``_3``), ``overshoot_k_time_s`` (time of the
        peak after the execute), ``initial_turning_time_s`` (execute -> first reversal),
        ``period_s`` (first -> third reversal), ``first_side`` (+1/-1), with ``x, y``
        ``initial_turning_distance_m`` (track length to the first reversal) and, with ``L``,
        ``initial_turning_distance_L``. Quantities not reached are absent.
    """
    heading = np.radians(float(heading_deg))
    if not heading > 0:
        raise InputError(f"heading_deg must be positive, got {heading_deg}")
    t = data.t
    if t_exec is None:
        t_exec = execute_time(data, rudder)
    k0 = int(np.searchsorted(t, t_exec))
    psi = unwrap(np.asarray(data["psi"], dtype=float))
    change = psi - float(np.interp(t_exec, t, psi))
    up, ku = _crossing(t, change, heading, k0)
    down, kd = _crossing(t, -change, heading, k0)
    if up is None and down is None:
        raise InputError(f"the heading never changes by {heading_deg} deg after the execute")
    side = 1.0 if down is None or (up is not None and up <= down) else -1.0
    out = {"first_side": int(side), "t_exec_s": float(t_exec)}
    reversals, k = [], k0
    sign = side
    while True:
        tc, k_new = _crossing(t, sign * change, heading, k)
        if tc is None:
            break
        reversals.append((tc, k_new))
        k, sign = k_new, -sign
    if not reversals:
        return out
    out["initial_turning_time_s"] = reversals[0][0] - t_exec
    sign = side
    for i in range(min(3, len(reversals))):
        k_a = reversals[i][1]
        k_b = reversals[i + 1][1] if i + 1 < len(reversals) else None
        if k_b is None:
            # the peak counts only if the heading has turned back after it
            seg = sign * change[k_a:]
            j = int(np.argmax(seg))
            if j >= seg.size - 1 or seg[-1] > seg[j] - np.radians(0.5):
                break
        else:
            seg = sign * change[k_a:k_b]
            j = int(np.argmax(seg))
        out[f"overshoot_{i + 1}_deg"] = float(np.degrees(seg[j] - heading))
        out[f"overshoot_{i + 1}_time_s"] = float(t[k_a + j] - t_exec)
        sign = -sign
    if len(reversals) >= 3:
        out["period_s"] = reversals[2][0] - reversals[0][0]
    if "x" in data and "y" in data:
        k1 = reversals[0][1]
        track = np.hypot(np.diff(data["x"][k0:k1 + 1]), np.diff(data["y"][k0:k1 + 1])).sum()
        out["initial_turning_distance_m"] = float(track)
        if L:
            out["initial_turning_distance_L"] = float(track / L)
    return out


# -- IMO MSC.137(76) ----------------------------------------------------------------------------------------
def _zz10_limits(L_over_V: float) -> tuple[float, float]:
    """First and second overshoot limits [deg] of the 10/10 zig-zag, MSC.137(76) Annex 5.3.3.1-2."""
    if L_over_V < 10:
        return 10.0, 25.0
    if L_over_V < 30:
        return 5.0 + 0.5 * L_over_V, 17.5 + 0.75 * L_over_V
    return 20.0, 40.0


def imo_check(L: float, V: float, *, turning: Mapping | None = None, zz10: Mapping | None = None,
              zz20: Mapping | None = None) -> list[dict]:
    """Check metrics against the IMO Standards for Ship Manoeuvrability (MSC.137(76), 2002).

    Criteria: advance <= 4.5 L and tactical diameter <= 5 L (35 deg turning circle); distance
    travelled before a 10 deg heading change with 10 deg rudder <= 2.5 L (from the 10/10
    zig-zag); 10/10 first overshoot <= 10 deg if L/V < 10 s, <= 20 deg if L/V >= 30 s, else
    5 + 0.5 L/V deg; 10/10 second overshoot <= 25 deg if L/V < 10 s, <= 40 deg if L/V >= 30 s, else
    17.5 + 0.75 L/V deg; 20/20 first overshoot <= 25 deg.
    (Stopping ability is not checked.)

    Parameters
    ----------
    L : float
        Length between perpendiculars [m].
    V : float
        Approach speed [m/s].
    turning, zz10, zz20 : mapping, optional
        Outputs of :func:`turning_metrics` / :func:`zigzag_metrics`; missing ones are skipped.

    Returns
    -------
    list of dict
        Rows ``{"criterion", "value", "limit", "unit", "pass"}``.
    """
    if not (L > 0 and V > 0):
        raise InputError(f"L and V must be positive, got {L}, {V}")
    L_over_V = L / V
    first, second = _zz10_limits(L_over_V)
    rows = []

    def add(name, source, key, limit, unit, scale=1.0):
        if source is not None and key in source:
            value = float(source[key]) * scale
            rows.append({"criterion": name, "value": value, "limit": limit, "unit": unit, "pass": value <= limit})

    add("advance / L (35 deg turning)", turning, "advance_m", 4.5, "-", 1 / L)
    add("tactical diameter / L (35 deg turning)", turning, "tactical_diameter_m", 5.0, "-", 1 / L)
    add("initial turning distance / L (10/10)", zz10, "initial_turning_distance_m", 2.5, "-", 1 / L)
    add(f"10/10 first overshoot (L/V = {L_over_V:.1f} s)", zz10, "overshoot_1_deg", first, "deg")
    add(f"10/10 second overshoot (L/V = {L_over_V:.1f} s)", zz10, "overshoot_2_deg", second, "deg")
    add("20/20 first overshoot", zz20, "overshoot_1_deg", 25.0, "deg")
    return rows


def imo_table(rows: Sequence[Mapping]) -> str:
    """Markdown table of :func:`imo_check` rows.

    Parameters
    ----------
    rows : sequence of mapping
        Rows from :func:`imo_check`.

    Returns
    -------
    str
    """
    lines = ["| criterion | value | limit | result |", "|---|---|---|---|"]
    for row in rows:
        lines.append(f"| {row['criterion']} | {row['value']:.2f} | {row['limit']:.2f} | "
                     f"{'pass' if row['pass'] else 'FAIL'} |")
    return "\n".join(lines)
