"""Shi, Zhao, Peng & Shen (2009): identification of a ship manoeuvring model with EKFs, end to end.

Pipeline (seed 000):

1. **Truth.** The paper's printed parameters have no stable straight run, so the target ship is the
   16-parameter Taylor response model (:func:`casship.models.shi_taylor`) fitted by equation-error least
   squares to simulations of the KVLCC2 MMG model (:func:`casship.models.kvlcc2`: 20/20 and 10/10
   zig-zags, 35/20/10 deg turning circles, random rudder; exact state derivatives from the model).
2. **Raw data.** 20/20 zig-zag and 35 deg turning circle of the truth at its straight-run speed,
   sampled at T = 2 s as positions (sigma 1 m) and heading (sigma 0.2 deg), with rudder and propeller.
3. **Pre-processing (Section 4.1).** Per axis (x, y, heading) a constant-acceleration Kalman filter
   (Eq. 6-7: continuous white jerk, whose discretisation is exactly the paper's Q matrix; initial state
   and covariance of Eq. 7) and the fixed-interval RTS smoother (Eq. 8). The jerk intensity
   ``alpha sigma_a^2`` of each axis is estimated by maximum likelihood through the same Kalman filter.
   Then U, course, drift ``beta = course - heading``, ``u = U cos beta``, ``v = U sin beta``, ``r``.
4. **Identification.** (a) the paper's augmented-state EKF (all 16 parameters as random-walk states,
   Euler at T, parameters start at 0 with variance 1e5), run over the zig-zag and then the turning
   circle; (b) maximum likelihood through an EKF (:class:`casship.MLEProblem`) on both records, started
   from the augmented-EKF estimates, with the process-noise variances estimated too (quick mode: the
   seven sway and yaw parameters only, surge parameters at the augmented-EKF values).
5. **Validation.** 20/20 zig-zag and 35 deg turning circle of the identified models against the truth;
   Table 2 style errors (advance, transfer, tactical diameter) and zig-zag overshoots.

Outputs: ``table2.md``, ``parameters.md``, ``fig_rate_of_turn.png`` (paper Fig. 2-3),
``fig_convergence.png`` (Fig. 4-6), ``fig_zigzag.png`` (Fig. 7-8), ``fig_turning.png`` (Fig. 9),
``fit_mle.json``, ``summary.json``.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

import casship as cs
from casship.maneuvers import run_maneuver
from casship.models import SHI_PARAM_NAMES
from casship.progress import progress

from . import Study

T = 2.0                                # sampling period of the raw data (paper)
POS_STD, PSI_STD = 1.0, np.radians(0.2)
TRUTH_MANEUVERS = [("zigzag", 20, 20), ("zigzag", -10, -10), ("turning", 35, None), ("turning", -20, None),
                   ("turning", 10, None), ("random", 20, None)]
TABLE2 = ("advance_m", "transfer_m", "tactical_diameter_m")
ZIGZAG = ("overshoot_1_deg", "overshoot_2_deg", "initial_turning_time_s", "period_s")


def _target_vessel() -> cs.Vessel:
    """The ship the Taylor models stand for: KVLCC2 at full scale (its truth parameters come from it)."""
    return cs.models.get_model("kvlcc2").vessel.replace(param_set="shi-taylor/fitted-to-kvlcc2")


def truth_params(dt: float = 2.0) -> dict:
    """Taylor-model parameters by equation-error least squares on KVLCC2 MMG simulations."""
    k = cs.models.get_model("kvlcc2")
    rows = {"a": [], "b": [], "c": []}
    rhs = {"a": [], "b": [], "c": []}
    for kind, rudder, heading in TRUTH_MANEUVERS:
        tr = run_maneuver(k, kind, rudder_deg=rudder, heading_deg=heading, dt=dt,
                          duration=1200 if kind == "zigzag" else 1500, seed=1).trajectory
        xd = np.asarray(k.f.map(len(tr))(tr.x.T, tr.u.T, k.params(), np.zeros((k.nw, 1)))).T
        u, v, r, d, n = tr["u"], tr["v"], tr["r"], tr["delta"], tr["n"]
        rows["a"].append(np.column_stack([u * u, v * v, r * r, d * d, v * r, v * d, r * d, u * n, n * n]))
        rows["b"].append(np.column_stack([v, r, d, u * r]))
        rows["c"].append(np.column_stack([v, r, d]))
        for key, col in (("a", 0), ("b", 1), ("c", 2)):
            rhs[key].append(xd[:, col])
    out = {}
    for key in ("a", "b", "c"):
        coef = np.linalg.lstsq(np.vstack(rows[key]), np.concatenate(rhs[key]), rcond=None)[0]
        out.update({f"{key}{i + 1}": float(c) for i, c in enumerate(coef)})
    return out


def straight_speed(p: dict, n: float) -> float:
    """Straight-run speed of the Taylor model at propeller rate ``n`` (root of the surge equation)."""
    roots = np.roots([p["a1"], p["a8"] * n, p["a9"] * n * n])
    real = roots[np.isreal(roots)].real
    real = real[real > 0]
    if real.size == 0:
        raise ValueError("the Taylor model has no positive straight-run speed at this propeller rate")
    return float(real.min())


def raw_records(truth: cs.Model, u0: float, n0: float, seed: int, duration: float) -> list[cs.Dataset]:
    """Noisy positions and heading at T = 2 s of the 20/20 zig-zag and the 35 deg turning circle."""
    rng = np.random.default_rng(seed)
    out = []
    for kind, rudder in (("zigzag", 20.0), ("turning", 35.0)):
        tr = run_maneuver(truth, kind, rudder_deg=rudder, speed=u0, n=n0, dt=0.5, duration=duration,
                          t_exec=10.0).trajectory
        idx = np.arange(0, len(tr), int(round(T / 0.5)))
        m = idx.size
        cols = {"x": tr["x"][idx] + POS_STD * rng.standard_normal(m),
                "y": tr["y"][idx] + POS_STD * rng.standard_normal(m),
                "psi": cs.wrap(tr["psi"][idx] + PSI_STD * rng.standard_normal(m)),
                "delta": tr["delta"][idx], "n": tr["n"][idx]}
        cols.update({f"true_{s}": tr[s][idx] for s in ("u", "v", "r")})
        out.append(cs.Dataset(tr.t[idx], cols, meta={"name": f"{kind} {rudder:g} deg"}))
    return out


def smooth_axis(t, z, r_var):
    """Constant-acceleration KF + RTS smoother of one coordinate (paper Eq. 6-8), jerk PSD by ML.

    Returns the smoothed FilterResult (from the second sample on, as the paper's initialisation) and
    the estimated jerk intensity.
    """
    model = cs.models.constant_acceleration("s")
    # Q is the covariance over a step T (casship's one meaning); the jerk PSD is Q T
    kf = cs.KF(cs.discretize(model, T), Q=1e-6 / T, R=r_var, options={"covariance": "continuous", "substeps": 8})
    data = cs.Dataset(t, {"s": z}).slice(1)
    prior = cs.Gaussian([z[1], (z[1] - z[0]) / T, 0.0],
                        np.array([[r_var, r_var / T, 0.0], [r_var / T, 2 * r_var / T**2, 0.0], [0.0, 0.0, 0.0]]))
    q = cs.MLEProblem(kf, data, noise={"Q": True}, x0=prior).solve(hessian="fisher").noise["Q"]["w_s"]
    kf = cs.KF(cs.discretize(model, T), Q=q, R=r_var, options={"covariance": "continuous", "substeps": 8})
    return kf.smooth(data, prior), q * T


def preprocess(raw: cs.Dataset) -> tuple[cs.Dataset, dict]:
    """Smoothed u, v, r (body velocities) from raw positions and heading (paper Section 4.1)."""
    sx, qx = smooth_axis(raw.t, raw["x"], POS_STD**2)
    sy, qy = smooth_axis(raw.t, raw["y"], POS_STD**2)
    sp, qp = smooth_axis(raw.t, np.unwrap(raw["psi"]), PSI_STD**2)
    U = np.hypot(sx["s_v"], sy["s_v"])
    beta = cs.wrap(np.arctan2(sy["s_v"], sx["s_v"]) - sp["s"])
    d = raw.slice(1)
    cols = {"u": U * np.cos(beta), "v": U * np.sin(beta), "r": sp["s_v"], "delta": d["delta"], "n": d["n"]}
    cols.update({k: d[k] for k in ("true_u", "true_v", "true_r")})
    rmse = {s: float(np.sqrt(np.mean((cols[s] - d[f"true_{s}"]) ** 2))) for s in ("u", "v", "r")}
    return cs.Dataset(d.t, cols, meta=raw.meta), {"rmse": rmse, "jerk_psd": {"x": qx, "y": qy, "psi": qp}}


def augmented_identification(records, R, model) -> tuple[dict, list]:
    """Seed 000's augmented-state EKF, over the records one after the other."""
    names = list(SHI_PARAM_NAMES)
    guess, p0 = {n: 0.0 for n in names}, 1e5
    runs = []
    for rec in records:
        prior = cs.Gaussian([rec["u"][0], rec["v"][0], rec["r"][0]], R)
        res = cs.estimators.augmented_ekf(model, names, rec, dt=T, Q=1e-10, R=R, q_params=0.0, prior=prior,
                                          guess=guess, p0_params=p0)
        runs.append(res)
        guess = res.final
        p0 = {n: max(s**2, 1e-30) for n, s in res.final_std.items()}
    return guess, runs


def validate(params: dict | None, u0: float, n0: float, duration: float) -> dict:
    """Zig-zag 20/20 and 35 deg turning metrics of a Taylor model (NaN where it fails)."""
    out = {"zigzag": {}, "turning": {}, "traj": {}}
    try:
        model = cs.models.shi_taylor(params, vessel=_target_vessel())
    except ValueError:
        return out
    for kind in ("zigzag", "turning"):
        try:
            res = run_maneuver(model, kind, rudder_deg=20.0 if kind == "zigzag" else 35.0, speed=u0, n=n0,
                               dt=1.0, duration=duration, t_exec=10.0)
            out[kind] = {k: float(v) for k, v in res.metrics.items() if isinstance(v, (int, float))}
            out["traj"][kind] = res.trajectory
        except (FloatingPointError, ValueError, RuntimeError) as exc:
            out[kind] = {"error": str(exc)}
    return out


def _err(meas, sim):
    return 100.0 * (sim - meas) / meas if meas and np.isfinite(sim) else float("nan")


def _plots(out: Path, raw, smoothed, aug_runs, checks):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rec, sm = raw[0], smoothed[0]
    fig, ax = plt.subplots(1, 2, figsize=(11, 3.8), sharey=True)
    ax[0].plot(rec.t[1:], np.degrees(np.diff(np.unwrap(rec["psi"])) / T), lw=0.7)
    ax[0].set_title("rate of turn from raw heading (Fig. 2)")
    ax[1].plot(sm.t, np.degrees(sm["r"]), lw=1, label="smoothed")
    ax[1].plot(sm.t, np.degrees(sm["true_r"]), "k--", lw=0.8, label="truth")
    ax[1].set_title("smoothed rate of turn (Fig. 3)")
    ax[1].legend(fontsize=8)
    for a in ax:
        a.set_xlabel("t [s]")
    ax[0].set_ylabel("r [deg/s]")
    fig.tight_layout()
    fig.savefig(out / "fig_rate_of_turn.png", dpi=110)
    plt.close(fig)

    fig, ax = plt.subplots(1, 3, figsize=(12, 3.5))
    t0 = 0.0
    for run in aug_runs:
        t = run.result.t + t0
        for a, name in zip(ax, ("a1", "b2", "c1")):
            a.plot(t, run.trajectory(name), "C0", lw=1)
            a.set_title(f"convergence of {name} (Fig. 4-6)")
            a.set_xlabel("t [s] (zig-zag, then turning circle)")
        t0 = t[-1] + T
    for a, name in zip(ax, ("a1", "b2", "c1")):
        a.axhline(checks["truth_params"][name], color="k", ls="--", lw=0.8)
        a.set_ylim(*np.sort([checks["truth_params"][name] * s for s in (-3, 5)]))
    fig.tight_layout()
    fig.savefig(out / "fig_convergence.png", dpi=110)
    plt.close(fig)

    styles = {"truth": ("k-", "target ship (truth)"), "aekf": ("C1--", "augmented EKF"), "mle": ("C0-", "ML (EKF)")}
    fig, ax = plt.subplots(1, 2, figsize=(11, 3.8))
    for key, (st, label) in styles.items():
        tr = checks["validation"][key]["traj"].get("zigzag")
        if tr is not None:
            ax[0].plot(tr.t, np.degrees(tr["psi"]), st, lw=1, label=label)
            ax[1].plot(tr.t, np.hypot(tr["u"], tr["v"]), st, lw=1, label=label)
    ax[0].set_ylabel("heading [deg] (Fig. 7)")
    ax[1].set_ylabel("speed [m/s] (Fig. 8)")
    for a in ax:
        a.set_xlabel("t [s]")
        a.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "fig_zigzag.png", dpi=110)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(5.5, 5.5))
    for key, (st, label) in styles.items():
        tr = checks["validation"][key]["traj"].get("turning")
        if tr is not None:
            ax.plot(tr["y"], tr["x"], st, lw=1, label=label)
    ax.set_xlabel("East y [m]")
    ax.set_ylabel("North x [m]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_title("35 deg turning circle (Fig. 9)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "fig_turning.png", dpi=110)
    plt.close(fig)


def run(out: Path, quick: bool = False, workers=None, scheduler=None, seed: int = 0, hessian: str = "fisher") -> dict:
    out = Path(out)
    duration = 500.0 if quick else 1200.0
    stages = ["truth model", "raw data", "smoothing", "augmented EKF", "maximum likelihood", "validation"]
    steps = progress(stages, "shi2009")
    next(steps)
    truth_p = truth_params()
    n0 = float(cs.models.get_model("kvlcc2").vessel.n0)
    u0 = straight_speed(truth_p, n0)
    truth = cs.models.shi_taylor(truth_p, vessel=_target_vessel())
    next(steps)
    raw = raw_records(truth, u0, n0, seed, duration)
    next(steps)
    pre = [preprocess(r) for r in raw]
    smoothed = [p[0] for p in pre]
    model3 = cs.models.shi_taylor(kinematics=False)
    R = np.array([max(pre[0][1]["rmse"][s], 1e-6) for s in ("u", "v", "r")]) ** 2
    next(steps)
    aekf, aug_runs = augmented_identification(smoothed, R, model3)
    next(steps)
    ekf = cs.EKF(cs.discretize(model3, T, method="euler"), Q=[1e-6, 1e-6, 1e-8], R=R)
    # quick mode: the sway and yaw parameters only (surge parameters kept at the augmented-EKF values)
    free = [k for k in SHI_PARAM_NAMES if not quick or k[0] in "bc"]
    fit = cs.MLEProblem(ekf, smoothed, free=free, noise={"Q": True}, params=aekf).solve(
        guess={k: aekf[k] for k in free}, hessian=hessian)
    fit.to_json(out / "fit_mle.json")
    next(steps)
    mle = {k: fit.params[k] for k in SHI_PARAM_NAMES}
    checks = {"truth_params": truth_p,
              "validation": {"truth": validate(truth_p, u0, n0, 1500.0), "aekf": validate(aekf, u0, n0, 1500.0),
                             "mle": validate(mle, u0, n0, 1500.0)}}
    next(steps, None)
    _plots(out, raw, smoothed, aug_runs, checks)

    val = checks["validation"]
    lines = ["# Shi et al. (2009) pipeline: smoothing, augmented-EKF and ML identification", "",
             f"Truth: Taylor model fitted to KVLCC2 MMG simulations; straight-run speed {u0:.3f} m/s at "
             f"n = {n0:.3f} 1/s. Raw data at T = {T:g} s ({duration:g} s per manoeuvre), position sigma "
             f"{POS_STD:g} m, heading sigma {np.degrees(PSI_STD):g} deg.", "",
             "Smoothed velocities against the truth (RMS):", "",
             "| record | u [m/s] | v [m/s] | r [deg/s] | jerk PSD x, y, psi |", "|---|---:|---:|---:|---|"]
    for rec, (_, info) in zip(smoothed, pre):
        e, q = info["rmse"], info["jerk_psd"]
        lines.append(f"| {rec.meta['name']} | {e['u']:.3g} | {e['v']:.3g} | {np.degrees(e['r']):.3g} | "
                     f"{q['x']:.2g}, {q['y']:.2g}, {q['psi']:.2g} |")
    lines += ["", "## Table 2: turning circle (35 deg)", "",
              "| item | target [m] | augmented EKF [m] | error % | ML [m] | error % |", "|---|---:|---:|---:|---:|---:|"]
    table2 = {}
    for key in TABLE2:
        t_v = val["truth"]["turning"].get(key, np.nan)
        a_v = val["aekf"]["turning"].get(key, np.nan)
        m_v = val["mle"]["turning"].get(key, np.nan)
        table2[key] = {"truth": t_v, "aekf": a_v, "aekf_error_pct": _err(t_v, a_v), "mle": m_v,
                       "mle_error_pct": _err(t_v, m_v)}
        lines.append(f"| {key.replace('_m', '').replace('_', ' ')} | {t_v:.1f} | {a_v:.1f} | {_err(t_v, a_v):+.2f} | "
                     f"{m_v:.1f} | {_err(t_v, m_v):+.2f} |")
    lines += ["", "## 20/20 zig-zag", "", "| item | target | augmented EKF | ML |", "|---|---:|---:|---:|"]
    zz = {}
    for key in ZIGZAG:
        vals = [val[k]["zigzag"].get(key, np.nan) for k in ("truth", "aekf", "mle")]
        zz[key] = dict(zip(("truth", "aekf", "mle"), vals))
        lines.append(f"| {key} | " + " | ".join(f"{v:.2f}" for v in vals) + " |")
    for k in ("aekf", "mle"):
        for kind in ("zigzag", "turning"):
            if "error" in val[k][kind]:
                lines.append(f"\n{k} {kind} failed: {val[k][kind]['error']}")
    (out / "table2.md").write_text("\n".join(lines) + "\n")

    plines = ["# Identified parameters", "", f"ML estimated: {', '.join(free)} (others at the augmented-EKF values)", "",
              "| parameter | truth | augmented EKF | ML | ML std error |",
              "|---|---:|---:|---:|---:|"]
    for k in SHI_PARAM_NAMES:
        se = fit.std_errors.get(k, float("nan"))
        plines.append(f"| {k} | {truth_p[k]:.4g} | {aekf[k]:.4g} | {mle[k]:.4g} | {se:.2g} |")
    plines += ["", "ML fit warnings:", ""] + [f"- {w}" for w in fit.warnings]
    (out / "parameters.md").write_text("\n".join(plines) + "\n")
    z = {k: (mle[k] - truth_p[k]) / fit.std_errors[k] for k in free}
    return {"study": "shi2009", "quick": quick, "u0": u0, "n0": n0, "truth_params": truth_p, "aekf_params": aekf,
            "mle_params": mle, "mle_free": free, "mle_std_errors": {k: fit.std_errors[k] for k in free},
            "mle_z_scores": z, "mle_iterations": fit.iterations, "mle_solve_time_s": fit.solve_time_s,
            "smoothing": [info for _, info in pre], "table2": table2, "zigzag": zz,
            "errors": {k: {kind: val[k][kind].get("error") for kind in ("zigzag", "turning")} for k in ("aekf", "mle")}}


STUDY = Study("shi2009", "Shi et al. (2009): smoothing, augmented-EKF and ML identification, manoeuvre validation", run)
