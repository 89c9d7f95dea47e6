"""MHE construction: casship's build time against do-mpc's, and the rule that decides expansion.

Two parts.

1. **do-mpc's own example.** The rotating oscillating masses of do-mpc's MHE example (three discs
   coupled by springs, two stepper motors with a first-order lag tau = 0.01 s as inputs; 8 states,
   the inertia ``Theta_1`` estimated with bounds [1e-5, 1e-3], the three disc angles measured,
   dt = 0.1 s, horizon N = 10), posed in casship from the paper equations: ``ModelBuilder`` with
   the same right-hand side, RK4 with 10 sub-steps per sample (tau / h = 1 keeps the motor lag
   inside RK4's stability region), ``estimate={"Theta_1": ...}``, solver ``"sqp"`` (IPOPT stops
   with ``Error_In_Step_Computation`` after 14 samples on this badly scaled problem, ``Theta_1``
   about 2e-4 beside angles of 10 rad, and says so). do-mpc builds its own collocation NLP
   (``MHE.setup``) for IPOPT. Timed: the construction a user waits for before the first
   estimate, CPU time, one run each: do-mpc ``Model`` + ``MHE`` + ``setup()`` + its first
   ``make_step``; casship ``MHE(...)`` + ``online(prior)`` + the first ``update`` (which builds the
   window NLP and its warm start). The estimate of ``Theta_1`` after 10 s of data is printed for both (true
   2.25e-4, both start from 1e-4).

2. **When expansion pays.** Expanding the window NLP to scalar expressions (CasADi ``expand``)
   makes each solve faster but costs build time that grows with the size of the expanded problem,
   ``N x`` (scalar operations of one stage). For ship models of increasing stage size and horizons
   10 .. 200 this measures, expanded and not: the construction (as above) and the median time of
   a window solve (IPOPT, warm-started) over 20 full windows. casship expands when the count is at
   most ``casship.estimators.mhe.problem.EXPAND_NODES`` (option ``expand=None``); the table shows
   where that lands.

Run ``python -m benchmarks.bench_mhe_build [--quick]``. Times on a loaded machine are indicative;
the rule is stated in operation counts, not seconds.
"""
from __future__ import annotations

import contextlib
import io
import sys
import time
import warnings

import numpy as np

import casship as cs
from benchmarks import format_table, row, skipped_row
from casship.estimators.mhe.problem import EXPAND_NODES, stage_nodes

CLOCK = time.process_time
DT = 0.1
C_SPRING = np.array([2.697, 2.66, 3.05, 2.86]) * 1e-3
D_DAMP = np.array([6.78, 8.01, 8.82]) * 1e-5
TAU, THETA = 1e-2, 2.25e-4
X0 = np.pi * np.array([1, 1, -1.5, 1, -5, 5, 0, 0])


def masses_model():
    """do-mpc's rotating oscillating masses with additive noise on the disc accelerations."""
    b = cs.ModelBuilder("rotating-masses", "three discs and two stepper motors (do-mpc's MHE example)")
    phi = [b.state(f"phi_{i}", unit="rad") for i in (1, 2, 3)]
    dphi = [b.state(f"dphi_{i}", unit="rad/s") for i in (1, 2, 3)]
    motor = [b.state(f"phi_m_{i}", unit="rad") for i in (1, 2)]
    sets = [b.input(f"phi_m_set_{i}", unit="rad") for i in (1, 2)]
    th = [b.param(f"Theta_{i}", THETA) for i in (1, 2, 3)]
    c, d = C_SPRING, D_DAMP
    left = [motor[0], phi[0], phi[1]]
    right = [phi[1], phi[2], motor[1]]
    acc = {f"dphi_{i + 1}": (-c[i] * (phi[i] - left[i]) - c[i + 1] * (phi[i] - right[i]) - d[i] * dphi[i]) / th[i]
           + b.noise(f"w_{i + 1}") for i in range(3)}
    b.ode(**{f"phi_{i + 1}": dphi[i] for i in range(3)}, **acc,
          **{f"phi_m_{i + 1}": (sets[i] - motor[i]) / TAU for i in range(2)})
    for i in range(3):
        b.output(f"phi_{i + 1}_meas", phi[i])
    return b.build()


def masses_record(model, duration=10.0, seed=0):
    t = np.arange(0.0, duration, DT)
    rng = np.random.default_rng(seed)
    u = rng.uniform(-0.5 * np.pi, 0.5 * np.pi, (t.size, 2))
    traj = cs.simulate(model, X0, t, {"phi_m_set_1": u[:, 0], "phi_m_set_2": u[:, 1]}, method="cvodes")
    return cs.measure(traj, model, {f"phi_{i}_meas": 1e-2 for i in (1, 2, 3)}, seed=rng), u


def casship_masses(model, data, u, N=10, expand=None):
    """Construction time and the Theta_1 estimate after the record."""
    Y = data.matrix([f"phi_{i}_meas" for i in (1, 2, 3)])
    t0 = CLOCK()
    mhe = cs.MHE(cs.discretize(model, DT, "rk4", substeps=10), [1e-2, 1e-2, 1e-2], 1e-4,
                 options={"horizon": N, "solver": "sqp", "expand": expand, "estimate": {"Theta_1": 1e-4},
                          "bounds": {"Theta_1": (1e-5, 1e-3)}})
    run = mhe.online(cs.Gaussian(X0, np.eye(8)), p={"Theta_1": 1e-4}, u=u[0])
    run.update(Y[0], 0.0, u_prev=u[0], u=u[0])
    build = CLOCK() - t0
    for k in range(1, len(data)):
        run.update(Y[k], DT, u_prev=u[k - 1], u=u[k])
    return build, float(run.x[-1])


def dompc_masses(data, u, N=10):
    """do-mpc's example set-up (its objective and bounds); construction time and Theta_1 estimate."""
    import casadi as ca
    import do_mpc

    t0 = CLOCK()
    model = do_mpc.model.Model("continuous")
    phi = model.set_variable("_x", "phi", shape=(3, 1))
    dphi = model.set_variable("_x", "dphi", shape=(3, 1))
    phi_m_set = model.set_variable("_u", "phi_m_set", shape=(2, 1))
    phi_m = model.set_variable("_x", "phi_m", shape=(2, 1))
    model.set_meas("phi_1_meas", phi)
    model.set_meas("phi_m_set_meas", phi_m_set)
    th = [model.set_variable("parameter", f"Theta_{i}") for i in (1, 2, 3)]
    c, d = C_SPRING, D_DAMP
    model.set_rhs("phi", dphi)
    model.set_rhs("dphi", ca.vertcat(
        (-c[0] * (phi[0] - phi_m[0]) - c[1] * (phi[0] - phi[1]) - d[0] * dphi[0]) / th[0],
        (-c[1] * (phi[1] - phi[0]) - c[2] * (phi[1] - phi[2]) - d[1] * dphi[1]) / th[1],
        (-c[2] * (phi[2] - phi[1]) - c[3] * (phi[2] - phi_m[1]) - d[2] * dphi[2]) / th[2]))
    model.set_rhs("phi_m", (phi_m_set - phi_m) / TAU)
    model.setup()
    mhe = do_mpc.estimator.MHE(model, ["Theta_1"])
    mhe.settings.n_horizon = N
    mhe.settings.t_step = DT
    mhe.settings.meas_from_data = True
    mhe.settings.store_full_solution = False
    mhe.settings.supress_ipopt_output()
    # the example's weights: measurements (angles, motor set points) 1, 1, 1, 20, 20, arrival 1e-4
    mhe.set_default_objective(P_x=1e-4 * np.eye(8), P_v=np.diag([1.0, 1, 1, 20, 20]), P_p=1e-4 * np.eye(1))
    p_template = mhe.get_p_template()
    p_template["Theta_2"] = p_template["Theta_3"] = THETA
    mhe.set_p_fun(lambda t_now: p_template)
    mhe.bounds["lower", "_u", "phi_m_set"] = -2 * np.pi
    mhe.bounds["upper", "_u", "phi_m_set"] = 2 * np.pi
    mhe.bounds["lower", "_p_est", "Theta_1"] = 1e-5
    mhe.bounds["upper", "_p_est", "Theta_1"] = 1e-3
    mhe.setup()
    mhe.x0 = X0
    mhe.p_est0 = np.array([1e-4])
    mhe.set_initial_guess()
    Y = data.matrix([f"phi_{i}_meas" for i in (1, 2, 3)])
    mhe.make_step(np.concatenate([Y[0], u[0]]).reshape(-1, 1))
    build = CLOCK() - t0
    for k in range(1, len(data)):
        mhe.make_step(np.concatenate([Y[k], u[k]]).reshape(-1, 1))
    return build, float(np.asarray(mhe.opt_x_num["_p_est"]).ravel()[0])


# -- the expansion rule on ship models ----------------------------------------------------------------
SHIPS = {"shi-taylor": dict(x0={"u": 8.0}, u={"delta": 0.2, "n": 1.5}, dt=0.1),
         "mariner": dict(x0={"u": 7.7175}, u={"delta": 0.1}, dt=0.5),
         "mmg-twin-lowspeed": dict(x0={"u": 1.0}, u={"n": 10.0, "delta_s": 0.3, "delta_p": 0.3}, dt=0.5)}


def ship_case(name, n):
    spec = SHIPS[name]
    m = cs.models.get_model(name)
    t = np.arange(n) * spec["dt"]
    inputs = {k: v * (np.sign(np.sin(2 * np.pi * t / 60)) if k.startswith("delta") else 1.0)
              for k, v in spec["u"].items()}
    rng = np.random.default_rng(1)
    Qd = np.array([1e-5, 1e-5, 1e-8])
    traj = cs.simulate(m, m.states(**spec["x0"]), t, inputs, w=rng.standard_normal((n, 3)) * np.sqrt(Qd))
    std = {o: (0.01 if o in ("u", "v") else 1e-3 if o in ("r", "psi") else 1.0) for o in m.output_names}
    data = cs.measure(traj, m, std, seed=rng)
    prior = cs.Gaussian(m.states(**spec["x0"]), np.diag([1e-2, 1e-2, 1e-6, 1.0, 1.0, 1e-4]))
    return cs.discretize(m, spec["dt"], "rk4"), data, prior, Qd, {k: v ** 2 for k, v in std.items()}


def time_ship(name, N, expand, solves):
    dm, data, prior, Qd, R = ship_case(name, N + solves + 1)
    m = dm.model
    U, Y = data.matrix(m.input_names), data.matrix(m.output_names)
    t0 = CLOCK()
    mhe = cs.MHE(dm, Qd, R, options={"horizon": N, "expand": expand})
    run = mhe.online(prior, u=U[0])
    run.update(Y[0], 0.0, u_prev=U[0], u=U[0])
    build = CLOCK() - t0
    per = []
    for k in range(1, len(data)):
        t1 = CLOCK()
        run.update(Y[k], data.t[k] - data.t[k - 1], u_prev=U[k - 1], u=U[k])
        if k > N:
            per.append(CLOCK() - t1)
    return build, float(np.median(per)), stage_nodes(mhe)


def main(quick: bool = False) -> list[dict]:
    rows = []
    model = masses_model()
    data, u = masses_record(model)
    build_cs, theta_cs = casship_masses(model, data, u)
    try:
        with warnings.catch_warnings(), contextlib.redirect_stdout(io.StringIO()):
            warnings.simplefilter("ignore")
            build_dm, theta_dm = dompc_masses(data, u)
        rows.append(row("MHE construction, do-mpc's rotating masses (8 states, N = 10)", build_cs,
                        "do-mpc MHE.setup (its example)", build_dm,
                        f"Theta_1 after 10 s (true {THETA:g}, start 1e-4): casship {theta_cs:.4g}, do-mpc {theta_dm:.4g}"))
    except ImportError:
        rows.append(skipped_row("MHE construction, do-mpc's rotating masses (8 states, N = 10)",
                                "do-mpc MHE.setup", "do-mpc not installed (pip install do-mpc)", build_cs))
    horizons = (10, 200) if quick else (10, 20, 50, 100, 200)
    solves = 5 if quick else 20
    for name in SHIPS:
        for N in horizons:
            b0, s0, nodes = time_ship(name, N, False, solves)
            b1, s1, _ = time_ship(name, N, True, solves)
            auto = N * nodes <= EXPAND_NODES
            rows.append(row(f"MHE build {name} N = {N} ({N * nodes} expanded nodes): expanded", b1,
                            "not expanded", b0,
                            f"solve per window: expanded {s1 * 1e3:.3g} ms, not {s0 * 1e3:.3g} ms "
                            f"(x{s0 / s1:.2f}); the rule {'expands' if auto else 'does not expand'}",
                            expanded_nodes=N * nodes, solve_expanded_s=s1, solve_plain_s=s0, rule_expands=auto))
    return rows


if __name__ == "__main__":
    print(format_table(main(quick="--quick" in sys.argv[1:])))
