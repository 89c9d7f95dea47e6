"""Side-by-side speed comparisons of casship with peer libraries.

Each module ``benchmarks/bench_<topic>.py`` defines ``main(quick: bool = False) -> list[dict]``
returning one row per comparison::

    {"benchmark": str, "casship_s": float, "peer": str, "peer_s": float | None,
     "ratio": float | None,            # peer_s / casship_s (> 1: casship is faster)
     "accuracy_check": str}            # how the two results were checked to agree

Times are medians of repeated runs (:func:`median_time`, CPU time of the process by default). A peer that is not installed gives a row
with ``peer_s = None`` and ``skipped`` naming the reason (:func:`skipped_row`), never an error.
``python -m benchmarks`` (or ``casship bench``) runs every module and prints one table.
"""
from __future__ import annotations

import time
from typing import Callable

import numpy as np

__all__ = ["median_time", "compare", "compared_row", "row", "skipped_row", "format_table", "TARGETS",
           "format_targets"]

# The speed targets (peer / casship ratios measured in one run): key -> (what, target,
# the ratio measured before the work on them, on an independent harness). A row carries its key
# as ``target``; the EnKF row also carries ``first_call_s`` (target <= 5 s).
TARGETS = {
    "ekf_batch": ("EKF batch, compiled, vs filterpy EKF", 50, "31"),
    "ekf_online": ("EKF online update, compiled, vs filterpy", 12, "14"),
    "ukf_batch": ("UKF batch, compiled, vs filterpy UKF", 150, "143"),
    "enkf_batch": ("EnKF (100 members) batch, compiled, vs filterpy EnKF", 40, "29"),
    "rts_cv": ("RTS (CV model) vs pykalman smooth", 150, "165"),
    "ship_rts": ("ship EKF-RTS vs a NumPy loop", 30, "15"),
    "mhe_ipopt": ("MHE N=20, IPOPT, vs do-mpc", 10, "3.6"),
    "mhe_rti": ("MHE N=20, RTI, vs do-mpc", 50, "32"),
    "ml_fit_3": ("ML fit, 3 free parameters, vs scipy L-BFGS-B + finite differences", 10, "1.5"),
    "ml_fit_7": ("ML fit, 7 free parameters, vs scipy L-BFGS-B + finite differences", 10, "1.1"),
}
ENKF_FIRST_CALL_S = 5.0


def median_time(func: Callable[[], object], repeat: int = 5, warmup: int = 1,
                clock: Callable[[], float] = time.process_time) -> float:
    """Median time [s] of ``func()`` over ``repeat`` runs after ``warmup`` untimed runs.

    The default clock is the CPU time of the process: the compared codes are single-threaded, and
    CPU time is not inflated by other jobs on a shared machine as wall-clock time is. Pass
    ``clock=time.perf_counter`` for wall-clock time.
    """
    if repeat < 1:
        raise ValueError(f"repeat must be >= 1, got {repeat}")
    for _ in range(warmup):
        func()
    times = []
    for _ in range(repeat):
        t0 = clock()
        func()
        times.append(clock() - t0)
    times.sort()
    mid = len(times) // 2
    return times[mid] if len(times) % 2 else 0.5 * (times[mid - 1] + times[mid])


def compare(casship: Callable[[], object], peer: Callable[[], object], repeat: int = 7, warmup: int = 1,
            clock: Callable[[], float] = time.process_time) -> dict:
    """Time ``casship()`` and ``peer()`` interleaved (peer, casship, peer, casship, ...) and give the
    medians and the spread of the ratio.

    Interleaving puts both under the same load at the same moments, so the ratio of each pair is
    fair on a shared machine even when the absolute times drift. Each timed call is preceded by
    ``warmup`` untimed calls of both.

    Returns
    -------
    dict
        ``casship_s``, ``peer_s`` (medians), ``ratio`` (median of the per-pair ratios
        ``peer / casship``), ``ratio_min``, ``ratio_max`` and ``repeats``.
    """
    if repeat < 1:
        raise ValueError(f"repeat must be >= 1, got {repeat}")
    for _ in range(warmup):
        peer()
        casship()
    tc, tp = [], []
    for _ in range(repeat):
        t0 = clock()
        peer()
        t1 = clock()
        casship()
        t2 = clock()
        tp.append(t1 - t0)
        tc.append(t2 - t1)
    ratios = sorted(p / c for p, c in zip(tp, tc) if c > 0)
    med = lambda v: float(np.median(v)) if len(v) else None  # noqa: E731
    return {"casship_s": med(tc), "peer_s": med(tp), "ratio": med(ratios),
            "ratio_min": ratios[0] if ratios else None, "ratio_max": ratios[-1] if ratios else None,
            "repeats": repeat}


def compared_row(benchmark: str, timing: dict, peer: str, accuracy_check: str, **extra) -> dict:
    """A result row from :func:`compare` (ratio = median of the interleaved pairs, with its spread)."""
    r = row(benchmark, timing["casship_s"], peer, timing["peer_s"], accuracy_check, **extra)
    r.update(ratio=timing["ratio"], ratio_min=timing["ratio_min"], ratio_max=timing["ratio_max"],
             repeats=timing["repeats"])
    return r


def solve_ivp_held(rhs_at: Callable[[int], Callable], t, x0, rtol: float = 1e-9, atol: float = 1e-9):
    """What users do without a fold: one ``scipy.integrate.solve_ivp`` (RK45) call per sampling
    interval, the input held over it (``rhs_at(k)`` is the right-hand side on interval ``k``).
    Returns the (len(t), nx) states on the grid."""
    import numpy as np
    from scipy.integrate import solve_ivp

    X = np.empty((len(t), len(x0)))
    X[0] = x0
    for k in range(len(t) - 1):
        X[k + 1] = solve_ivp(rhs_at(k), (t[k], t[k + 1]), X[k], method="RK45", rtol=rtol, atol=atol).y[:, -1]
    return X


def row(benchmark: str, casship_s: float, peer: str, peer_s: float | None, accuracy_check: str,
        **extra) -> dict:
    """A result row; ``ratio = peer_s / casship_s`` (how many times faster casship is)."""
    ratio = None if peer_s is None or casship_s <= 0 else peer_s / casship_s
    return {"benchmark": benchmark, "casship_s": casship_s, "peer": peer, "peer_s": peer_s,
            "ratio": ratio, "accuracy_check": accuracy_check, **extra}


def skipped_row(benchmark: str, peer: str, reason: str, casship_s: float | None = None) -> dict:
    """A row for a comparison whose peer is unavailable (e.g. the ``bench`` extra not installed)."""
    return {"benchmark": benchmark, "casship_s": casship_s, "peer": peer, "peer_s": None, "ratio": None,
            "accuracy_check": "", "skipped": reason}


def _fmt(value, spec: str) -> str:
    return "-" if value is None else format(value, spec)


def _cell(text) -> str:
    """Table cell text: pipes escaped so that |x| notation does not split the Markdown row."""
    return str(text).replace("|", "\\|")


def _ratio(r: dict) -> str:
    """The ratio, with its range over interleaved repeats when there is one."""
    text = _fmt(r.get("ratio"), ".3g")
    if r.get("ratio_min") is not None and r.get("ratio_max") is not None:
        text += f" [{r['ratio_min']:.3g}-{r['ratio_max']:.3g}]"
    return text


def format_targets(rows: list[dict]) -> str:
    """Markdown table of the rows that carry a ``target`` key: ratio (median and range over the
    interleaved repeats), the target and whether it is met."""
    lines = ["| what | measured on | before | now: ratio [range] | target | met |", "|---|---|---:|---:|---:|---|"]
    by_key = {r["target"]: r for r in rows if r.get("target")}
    for key, (what, goal, before) in TARGETS.items():
        r = by_key.get(key)
        if r is None or r.get("ratio") is None:
            lines.append(f"| {what} | not measured in this run | {before}x | - | >= {goal}x | - |")
            continue
        spread = (f" [{r['ratio_min']:.3g}-{r['ratio_max']:.3g}]" if r.get("ratio_min") is not None else "")
        met = r["ratio"] >= goal
        extra = ""
        if key == "enkf_batch" and r.get("first_call_s") is not None:
            first_ok = r["first_call_s"] <= ENKF_FIRST_CALL_S
            extra = f"; first call {r['first_call_s']:.1f} s (target <= {ENKF_FIRST_CALL_S:g} s)"
            met = met and first_ok
        lines.append(f"| {what} | {_cell(r['benchmark'])} | {before}x | {r['ratio']:.3g}x{spread}{extra} | "
                     f">= {goal}x | {'yes' if met else 'NO'} |")
    return "\n".join(lines)


def format_table(rows: list[dict]) -> str:
    """Markdown table of result rows (medians in seconds, ratio = peer / casship)."""
    lines = ["| benchmark | casship [s] | peer | peer [s] | ratio | accuracy check |",
             "|---|---:|---|---:|---:|---|"]
    for r in rows:
        note = r.get("skipped") or r.get("error")
        check = f"skipped: {note}" if r.get("skipped") else (f"error: {note}" if r.get("error")
                                                               else r.get("accuracy_check", ""))
        lines.append(f"| {_cell(r.get('benchmark', '?'))} | {_fmt(r.get('casship_s'), '.4g')} | {_cell(r.get('peer', ''))} | "
                     f"{_fmt(r.get('peer_s'), '.4g')} | {_ratio(r)} | {_cell(check)} |")
    return "\n".join(lines)
