"""Simulate one hour of a 6-state ship model at 10 Hz: casship vs ``scipy.integrate.solve_ivp``.

The model is the Shi et al. (2009) Taylor response model with earth-fixed kinematics (states
``u, v, r, x, y, psi``), with ``c1 = 0.001`` so that straight running is stable over an hour
(the library's illustrative defaults are slightly directionally unstable), n = 1.5 rps and u = 6 m/s
at the start. Two input cases:

* ``constant``: a constant 5 deg rudder (surge transient, then a steady turn), where an adaptive
  solver can take long steps and interpolate onto the grid;
* ``sampled``: a rudder signal sampled at 10 Hz and held over each sample (zero-order hold, as
  with recorded inputs or a digital autopilot); the same problem for ``solve_ivp`` means one solve per
  0.1 s interval (the input is discontinuous at every sample).

* casship: ``casship.simulate`` (classical RK4, one step per 0.1 s sample, the whole record through
  CasADi ``mapaccum`` folds), timed end to end (the fold is built on the first call and cached);
  for the constant-rudder case also ``method="cvodes"`` (one adaptive CVODES run with outputs on
  the grid), adaptive against adaptive.
* peer: ``scipy.integrate.solve_ivp`` (RK45, rtol = atol = 1e-9, ``t_eval`` on the same grid) on the
  same right-hand side, once written in NumPy and once as the model's CasADi Function ``f``.

Run ``python -m benchmarks.bench_simulate [--quick]``.
"""
from __future__ import annotations

import sys

import numpy as np
from scipy.integrate import solve_ivp

import casship as cs
from benchmarks import format_table, median_time, row, solve_ivp_held

PARAMS = {"c1": 0.001}
DELTA, N_PROP = np.radians(5.0), 1.5


def _numpy_rhs(p: dict, delta=lambda t: DELTA):
    a = [p[f"a{i}"] for i in range(1, 10)]
    b = [p[f"b{i}"] for i in range(1, 5)]
    c = [p[f"c{i}"] for i in range(1, 4)]
    n = N_PROP

    def rhs(t, s):
        u, v, r, _, _, psi = s
        d = delta(t)
        du = (a[0] * u * u + a[1] * v * v + a[2] * r * r + a[3] * d * d + a[4] * v * r + a[5] * v * d
              + a[6] * r * d + a[7] * u * n + a[8] * n * n)
        dv = b[0] * v + b[1] * r + b[2] * d + b[3] * u * r
        dr = c[0] * v + c[1] * r + c[2] * d
        cp, sp = np.cos(psi), np.sin(psi)
        return [du, dv, dr, u * cp - v * sp, u * sp + v * cp, r]

    return rhs


def main(quick: bool = False) -> list[dict]:
    model = cs.models.shi_taylor(PARAMS)
    duration = 360.0 if quick else 3600.0
    t = np.arange(0.0, duration + 1e-9, 0.1)
    x0 = model.states(u=6.0)
    inputs = {"delta": DELTA, "n": N_PROP}
    p = model.params()
    rhs = _numpy_rhs(model.param_dict())
    u_const = np.array([DELTA, N_PROP])
    w0 = np.zeros(model.nw)

    def casadi_rhs(_t, s):
        return np.asarray(model.f(s, u_const, p, w0)).ravel()

    probe = np.array([6.0, 0.3, 0.01, 10.0, -5.0, 0.7])
    rhs_gap = float(np.max(np.abs(np.asarray(rhs(0.0, probe)) - casadi_rhs(0.0, probe))))
    if rhs_gap > 1e-12:
        raise RuntimeError(f"NumPy right-hand side differs from the model's f by {rhs_gap:.3g}")

    def run_casship():
        return cs.simulate(model, x0, t, inputs)

    def run_scipy(fun):
        return lambda: solve_ivp(fun, (t[0], t[-1]), x0, method="RK45", t_eval=t, rtol=1e-9, atol=1e-9)

    repeat = 3 if quick else 5
    traj = run_casship()
    ref = run_scipy(rhs)()
    if not ref.success:
        raise RuntimeError(f"solve_ivp failed: {ref.message}")
    err = np.abs(traj.x - ref.y.T).max(axis=0)
    check = (f"max abs diff u,v,r = {err[:3].max():.1e}, x,y = {err[3:5].max():.1e} m, "
             f"psi = {err[5]:.1e} rad over {t.size} samples")
    t_cs = median_time(run_casship, repeat=repeat)
    t_np = median_time(run_scipy(rhs), repeat=repeat)
    t_ca = median_time(run_scipy(casadi_rhs), repeat=max(1, repeat // 2), warmup=0)
    name = f"simulate {duration / 3600:.2g} h, 6 states, 10 Hz, constant rudder"
    rows = [row(name, t_cs, "scipy solve_ivp RK45 (NumPy rhs)", t_np, check, samples=int(t.size)),
            row(name, t_cs, "scipy solve_ivp RK45 (CasADi f rhs)", t_ca, check, samples=int(t.size))]
    # adaptive against adaptive: casship's CVODES with outputs on the grid (constant inputs: one run)
    adaptive = lambda: cs.simulate(model, x0, t, inputs, method="cvodes",  # noqa: E731
                                   options={"abstol": 1e-9, "reltol": 1e-9})
    err = np.abs(adaptive().x - ref.y.T).max(axis=0)
    check = (f"max abs diff u,v,r = {err[:3].max():.1e}, x,y = {err[3:5].max():.1e} m, "
             f"psi = {err[5]:.1e} rad (both tolerances 1e-9)")
    rows.append(row(name + ", casship cvodes", median_time(adaptive, repeat=repeat),
                    "scipy solve_ivp RK45 (NumPy rhs)", t_np, check, samples=int(t.size)))
    return rows + _sampled_case(model, t if not quick else t[:601], repeat)


def _sampled_case(model, t, repeat) -> list[dict]:
    """Rudder sampled at 10 Hz (zero-order hold): one solve_ivp call per interval vs one fold."""
    x0 = model.states(u=6.0)
    delta = np.radians(10.0) * np.sin(2 * np.pi * t / 300.0) * np.cos(2 * np.pi * t / 47.0)
    inputs = {"delta": delta, "n": N_PROP}
    held = {"value": 0.0}
    rhs = _numpy_rhs(model.param_dict(), delta=lambda _t: held["value"])

    def run_casship():
        return cs.simulate(model, x0, t, inputs)

    def rhs_at(k):
        held["value"] = delta[k]
        return rhs

    def run_scipy():
        return solve_ivp_held(rhs_at, t, x0)

    err = np.abs(run_casship().x - run_scipy()).max(axis=0)
    check = (f"max abs diff u,v,r = {err[:3].max():.1e}, x,y = {err[3:5].max():.1e} m, "
             f"psi = {err[5]:.1e} rad over {t.size} samples")
    t_cs = median_time(run_casship, repeat=repeat)
    t_sp = median_time(run_scipy, repeat=1, warmup=0)
    name = f"simulate {(t[-1] - t[0]) / 3600:.2g} h, 6 states, 10 Hz, sampled rudder (ZOH)"
    return [row(name, t_cs, "scipy solve_ivp RK45 per interval (NumPy rhs)", t_sp, check, samples=int(t.size))]


if __name__ == "__main__":
    print(format_table(main(quick="--quick" in sys.argv)))
