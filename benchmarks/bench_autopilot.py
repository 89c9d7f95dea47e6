"""KVLCC2 course MPC (60-step horizon) inside the compiled closed loop, against the PID step and a
dense QP solver.

* loop step: the compiled closed loop (nonlinear KVLCC2 RK4 step, sensors, heading observer, law,
  steering gear) folded over 600 s at dt = 0.2 s, once with the PID law and once with the MPC
  solving its QP at *every* loop sample (MPC period = loop period, 60 steps): the per-step cost of
  the MPC against the PID step (target: at most 1 ms per MPC step on the 2-core machine).
* one QP solve: the MPC's quadratic program in optimal-control form, solved by HPIPM (the
  structure-exploiting interior point shipped with CasADi) against the same QP handed to qrqp
  (CasADi's dense active-set solver), with the plans compared.

Run ``python -m benchmarks.bench_autopilot [--quick]``; the times of a loaded machine are
indicative only (CPU time of the process, medians).
"""
from __future__ import annotations

import dataclasses
import sys
import warnings

import casadi as ca
import numpy as np

import casship as cs
from benchmarks import format_table, median_time, row
from casship import autopilot as ap


def _design():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return ap.design_autopilot(cs.models.get_model("kvlcc2"))


def _dense_twin(mpc):
    """The MPC with its QP handed to qrqp (CasADi's dense active-set solver) instead of HPIPM."""
    twin = dataclasses.replace(mpc)
    qpsol = ca.qpsol

    def with_qpoases(name, plugin, problem, options):
        return qpsol(name, "qrqp", problem, {"error_on_fail": False, "print_iter": False, "print_header": False,
                                             "print_info": False})

    ca.qpsol = with_qpoases
    try:
        twin._solver = twin._build()
    finally:
        ca.qpsol = qpsol
    return twin


def main(quick: bool = False) -> list[dict]:
    d = _design()
    s = d.settings
    repeat = 3 if quick else 7
    t_end = 120.0 if quick else 600.0
    change = np.radians(60.0)
    pid_loop = d.closed_loop_system()
    mpc = ap.mpc_for_design(d, steps=60)
    every_step = ap.MPCAutopilot(d.nomoto, s.dt, 60, s.steer_max, s.steer_rate_max, s.r_max, q_e=mpc.q_e, q_r=mpc.q_r,
                                 r_u=mpc.r_u, reference=mpc.reference)
    mpc_loop = d.closed_loop_system(controller=every_step)
    n = int(round(t_end / s.dt)) + 1
    t_pid = median_time(lambda: pid_loop.run(change, t_end), repeat=repeat) / n
    t_mpc = median_time(lambda: mpc_loop.run(change, t_end), repeat=repeat) / n
    data = mpc_loop.run(change, t_end)
    ok = bool(np.max(np.abs(data["steer_cmd"])) <= s.steer_max * (1 + 1e-7))
    rows = [row("KVLCC2 compiled loop, per step: MPC (HPIPM QP every sample, N = 60) vs PID law", t_mpc,
                "PID law in the same compiled loop", t_pid,
                f"MPC run within the steering limit: {ok}; {n} steps", mpc_step_ms=1e3 * t_mpc, target_ms=1.0)]
    # one QP solve, HPIPM vs qpOASES on the same problem (the design's MPC, period 12.6 s)
    rng = np.random.default_rng(0)
    sys2 = d.nomoto.system(2)
    cases = []
    for _ in range(20):          # course errors up to 90 deg, rates and steering as a loop meets them
        e, r, cmd, b = rng.uniform(-1.5, 1.5), rng.uniform(-0.5, 0.5) * s.r_max, rng.uniform(-0.5, 0.5) * s.steer_max, \
            rng.normal(scale=0.01)
        cases.append((np.array([e, r, -float(sys2.A[1, 1]) * r - float(sys2.B[1, 0]) * (cmd + b), cmd]), b))
    twin = _dense_twin(mpc)
    zeros, guess = np.zeros((2, 60)), np.zeros((1, 60))

    def solve(m):
        return lambda: [m._solver(x0, b, zeros, guess) for x0, b in cases]

    t_hp = median_time(solve(mpc), repeat=repeat) / len(cases)
    t_qo = median_time(solve(twin), repeat=repeat) / len(cases)

    def worst(m):
        """Largest excess of a plan over the rate, steering and turn-rate limits (<= 0: held)."""
        out = []
        for x0, b in cases:
            _, X, U = (np.asarray(v) for v in m._solver(x0, b, zeros, guess))
            out.append(max(np.max(np.abs(U)) - mpc.rate_max, np.max(np.abs(X[-1, 1:])) - mpc.steer_max,
                           np.max(np.abs(X[1, 1:])) - mpc.r_max))
        return max(out), sum(v > 1e-7 for v in out)

    (w_hp, n_hp), (w_qo, n_qo) = worst(mpc), worst(twin)
    rows.append(row("KVLCC2 course MPC QP (N = 60), one solve: HPIPM", t_hp, "qrqp (dense active set), same QP", t_qo,
                    f"plans over a limit: HPIPM {n_hp}/{len(cases)} (worst {w_hp:.1e}), qrqp {n_qo}/{len(cases)} "
                    f"(worst {w_qo:.1e})", solve_ms=1e3 * t_hp))
    return rows


if __name__ == "__main__":
    print(format_table(main(quick="--quick" in sys.argv)))
