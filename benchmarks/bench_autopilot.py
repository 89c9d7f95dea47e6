"""KVLCC2 course MPC (60-step horizon) inside the compiled closed loop, against the PID step and a
dense QP solver.

* MPC step: the compiled closed loop (nonlinear KVLCC2 RK4 step, sensors, heading observer, law,
  steering gear) folded over an hour of 60 deg course changes at dt = 0.2 s, once with the PID law
  and once with the design's MPC (60-step horizon, a QP per re-planning interval); the difference of the two
  runs per QP solve is the cost of one MPC step, set against one PID loop step (target: at most
  1 ms per MPC step on the 2-core machine).
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
    t_end = 1200.0 if quick else 3600.0
    change = np.radians(60.0)

    def command(t):          # course changes of 60 deg every 600 s: the MPC keeps planning turns
        return change if int(t // 600.0) % 2 == 0 else 0.0

    pid_loop = d.closed_loop_system()
    mpc = ap.mpc_for_design(d, steps=60)
    mpc_loop = d.closed_loop_system(controller=mpc)
    n = int(round(t_end / s.dt)) + 1
    solves = -(-n // mpc.law(s.dt).every)
    t_pid = median_time(lambda: pid_loop.run(command, t_end), repeat=repeat)
    t_mpc = median_time(lambda: mpc_loop.run(command, t_end), repeat=repeat)
    per_mpc_step = max(t_mpc - t_pid, 0.0) / solves
    data = mpc_loop.run(command, t_end)
    ok = bool(np.max(np.abs(data["steer_cmd"])) <= s.steer_max * (1 + 1e-7))
    rows = [row(f"KVLCC2 course MPC (N = 60, step {mpc.period:.3g} s, re-planned every {mpc.replan:.3g} s) in the "
                "compiled loop: per MPC step (QP + law)",
                per_mpc_step, "one PID loop step (ship, sensors, observer, law, gear)", t_pid / n,
                f"{solves} QP solves in {n} loop steps; steering within its limit: {ok}",
                mpc_step_ms=1e3 * per_mpc_step, target_ms=1.0, loop_step_mpc_s=t_mpc / n, loop_step_pid_s=t_pid / n)]
    # one QP solve, HPIPM vs a dense active-set solver on the same problem (the design's MPC)
    rng = np.random.default_rng(0)
    sys2 = d.nomoto.system(2)
    cases = []
    for _ in range(20):          # course errors up to 90 deg, rates and steering as a loop meets them
        e, r, cmd, b = rng.uniform(-1.5, 1.5), rng.uniform(-0.5, 0.5) * s.r_max, rng.uniform(-0.5, 0.5) * s.steer_max, \
            rng.normal(scale=0.01)
        cases.append((np.array([e, r, -float(sys2.A[1, 1]) * r - float(sys2.B[1, 0]) * (cmd + b), cmd]), b))
    twin = _dense_twin(mpc)
    zeros, guess = np.zeros((2, 60)), np.zeros((1, 60))

    def solve(m):    # inputs: x0, b, target, U_guess, u_ref, steer_ref (no reference: a regulation plan)
        return lambda: [m._solver(x0, b, zeros, guess, guess, guess) for x0, b in cases]

    t_hp = median_time(solve(mpc), repeat=repeat) / len(cases)
    t_qo = median_time(solve(twin), repeat=repeat) / len(cases)

    def worst(m):
        """Largest excess of a plan over the rate, steering and turn-rate limits (<= 0: held)."""
        out = []
        for x0, b in cases:
            _, X, U = (np.asarray(v) for v in m._solver(x0, b, zeros, guess, guess, guess))
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
