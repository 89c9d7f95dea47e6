"""Shi et al. (2009) pipeline: truth, raw data, smoothing (Sect. 4.1), augmented-EKF and ML
identification (Sect. 3, 4.2), manoeuvre validation (Sect. 4.3), and the convergence criterion.

Every choice the paper leaves open is an argument here (:class:`Reading`), so the study can run the
paper's reading and the other ones on the same records.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

import casship as cs
from casship.maneuvers import run_maneuver
from casship.models import SHI_PARAM_NAMES
from casship.errors import InputError

T = 2.0                                # sampling period of the raw data (paper)
POS_STD, PSI_STD = 1.0, np.radians(0.2)
P0_PAPER = 1e5                         # P(0) = 1e5 I (19 x 19), the paper's Sect. 4.2
TRUTH_MANEUVERS = [("zigzag", 20, 20), ("zigzag", -10, -10), ("turning", 35, None), ("turning", -20, None),
                   ("turning", 10, None), ("random", 20, None)]
TABLE2 = ("advance_m", "transfer_m", "tactical_diameter_m")
ZIGZAG = ("overshoot_1_deg", "overshoot_2_deg", "initial_turning_time_s", "period_s")
CONVERGED_WITHIN = 0.10                # convergence criterion: stays within 10 % of the reference


@dataclass(frozen=True)
class Reading:
    """The choices the paper leaves open or states, as one value.

    Parameters
    ----------
    inputs : {"average", "hold"}
        Input over a step: the mean of the samples at k and k+1 (the paper's Eq. 4, ``s_m(k)``) or
        the sample at k held (zero-order hold).
    p0_states : float or None
        Initial variance of u, v, r in the augmented EKF: the paper's ``1e5`` (None: the
        measurement variance R, the study's earlier choice).
    r_from : {"smoother", "truth"}
        Measurement variance R of u, v, r: the RTS smoother's own mean variance, or the RMS error of
        the smoothed velocities against the truth (which needs the truth).
    """

    inputs: str = "average"
    p0_states: float | None = P0_PAPER
    r_from: str = "smoother"

    def __post_init__(self):
        if self.inputs not in ("average", "hold"):
            raise InputError(f"Reading.inputs must be 'average' or 'hold', got {self.inputs!r}")
        if self.r_from not in ("smoother", "truth"):
            raise InputError(f"Reading.r_from must be 'smoother' or 'truth', got {self.r_from!r}")


PAPER = Reading()
OTHER_READINGS = {"input held over the step": replace(PAPER, inputs="hold"),
                  "P(0) of u, v, r = R": replace(PAPER, p0_states=None),
                  "R from the smoothed-vs-true error": replace(PAPER, r_from="truth")}


def target_vessel() -> cs.Vessel:
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
        raise InputError("the Taylor model has no positive straight-run speed at this propeller rate")
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
    """Smoothed u, v, r (body velocities) from raw positions and heading (paper Section 4.1).

    The info holds the RMS error against the truth (for the report) and the smoother's own mean
    variance of u, v, r (``smoother_var``, what an analyst without the truth knows).
    """
    sx, qx = smooth_axis(raw.t, raw["x"], POS_STD**2)
    sy, qy = smooth_axis(raw.t, raw["y"], POS_STD**2)
    sp, qp = smooth_axis(raw.t, np.unwrap(raw["psi"]), PSI_STD**2)
    U = np.hypot(sx["s_v"], sy["s_v"])
    beta = cs.wrap(np.arctan2(sy["s_v"], sx["s_v"]) - sp["s"])
    d = raw.slice(1)
    cols = {"u": U * np.cos(beta), "v": U * np.sin(beta), "r": sp["s_v"], "delta": d["delta"], "n": d["n"]}
    cols.update({k: d[k] for k in ("true_u", "true_v", "true_r")})
    rmse = {s: float(np.sqrt(np.mean((cols[s] - d[f"true_{s}"]) ** 2))) for s in ("u", "v", "r")}
    iv = sx.state_names.index("s_v")
    var_uv = float(np.mean(0.5 * (sx.std[:, iv] ** 2 + sy.std[:, iv] ** 2)))
    var = {"u": var_uv, "v": var_uv, "r": float(np.mean(sp.std[:, iv] ** 2))}
    return cs.Dataset(d.t, cols, meta=raw.meta), {"rmse": rmse, "smoother_var": var,
                                                  "jerk_psd": {"x": qx, "y": qy, "psi": qp}}


def with_inputs(rec: cs.Dataset, how: str) -> cs.Dataset:
    """``rec`` with the rudder and propeller as the filter sees them over each step: held (as
    sampled) or averaged over the step (row k holds the mean of the samples k and k+1, Eq. 4)."""
    if how == "hold":
        return rec
    cols = {}
    for name in ("delta", "n"):
        v = rec[name]
        cols[name] = np.concatenate([0.5 * (v[:-1] + v[1:]), v[-1:]])
    return rec.with_columns(**cols)


def measurement_var(pre: list, reading: Reading) -> np.ndarray:
    """R of u, v, r for the identification (see :class:`Reading`), from the first record."""
    info = pre[0][1]
    if reading.r_from == "truth":
        return np.array([max(info["rmse"][s], 1e-6) for s in ("u", "v", "r")]) ** 2
    return np.array([info["smoother_var"][s] for s in ("u", "v", "r")])


def augmented_identification(records, R, model, reading: Reading) -> tuple[dict, list]:
    """Shi et al.'s (2009) augmented-state EKF, over the records one after the other (the estimates and
    their variances carried from one record to the next)."""
    names = list(SHI_PARAM_NAMES)
    guess, p0 = {n: 0.0 for n in names}, P0_PAPER
    runs = []
    for rec in records:
        rec = with_inputs(rec, reading.inputs)
        cov = R if reading.p0_states is None else np.full(3, reading.p0_states)
        prior = cs.Gaussian([rec["u"][0], rec["v"][0], rec["r"][0]], cov)
        res = cs.estimators.augmented_ekf(model, names, rec, dt=T, Q=1e-10, R=R, q_params=0.0, prior=prior,
                                          guess=guess, p0_params=p0)
        runs.append(res)
        guess = res.final
        p0 = {n: max(s**2, 1e-30) for n, s in res.final_std.items()}
    return guess, runs


def ml_identification(records, R, model, start: dict, reading: Reading, free):
    """Maximum likelihood through an EKF on all records, from the augmented-EKF estimates."""
    ekf = cs.EKF(cs.discretize(model, T, method="euler"), Q=[1e-6, 1e-6, 1e-8], R=R)
    data = [with_inputs(rec, reading.inputs) for rec in records]
    return cs.MLEProblem(ekf, data, free=list(free), noise={"Q": True}, params=start).solve(
        guess={k: start[k] for k in free}, hessian="fisher")


def validate(model_or_params, u0: float, n0: float, duration: float) -> dict:
    """Zig-zag 20/20 and 35 deg turning metrics of a Taylor model (parameters) or of a ship model."""
    out = {"zigzag": {}, "turning": {}, "traj": {}}
    if isinstance(model_or_params, cs.Model):
        model = model_or_params
    else:
        try:
            model = cs.models.shi_taylor(model_or_params, vessel=target_vessel())
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


def pct(reference: float, value: float) -> float:
    """Error of ``value`` against ``reference`` in per cent (NaN when either is missing)."""
    return 100.0 * (value - reference) / reference if reference and np.isfinite(value) else float("nan")


def convergence_step(trajectory, reference: float, within: float = CONVERGED_WITHIN) -> int | None:
    """First recursive step from which the estimate stays within ``within`` (relative) of ``reference``.

    Returns the step number (1 = after the first update), or None when the estimate is outside the band
    at the end.
    """
    traj = np.asarray(trajectory, dtype=float)
    tol = within * abs(reference)
    outside = np.flatnonzero(~(np.abs(traj - reference) <= tol))
    if outside.size and outside[-1] == traj.size - 1:
        return None
    return int(outside[-1] + 2) if outside.size else 1


def convergence(runs, truth: dict | None) -> dict:
    """Per parameter: the step from which the augmented EKF's estimate stays within 10 % of its own
    final value (``settled``) and of the truth (``to_truth``; Taylor truth only), counted over the
    records in order (zig-zag then turning circle)."""
    out = {}
    for name in SHI_PARAM_NAMES:
        traj = np.concatenate([run.trajectory(name) for run in runs])
        row = {"final": float(traj[-1]), "settled": convergence_step(traj, traj[-1])}
        if truth is not None:
            row["to_truth"] = convergence_step(traj, truth[name])
        out[name] = row
    return out
