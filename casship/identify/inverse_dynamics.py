"""Inverse dynamics: smooth a trial, then regress the coefficients the model is linear in.

Two steps, each usable alone (Alexandersson et al. 2022 use the same two steps; here the smoother
runs casship's EKF + RTS with exact Jacobians and the regression is built from the model itself):

1. :func:`smooth_trial` -- an EKF (continuous-discrete) and RTS smoother on the measured positions
   and heading (and, if wanted, the measured surge speed and yaw rate) with a body-frame kinematic
   model whose accelerations are driven by white jerk noise (:func:`rates_model`). It knows no
   hydrodynamics, so the smoothed velocities ``u, v, r`` and accelerations ``u_dot, v_dot, r_dot``
   are not biased towards any parameter set.
2. :func:`inverse_dynamics` -- with the smoothed states and accelerations, the equations of motion
   ``xdot = f(x, u, p)`` of a ship model are linear in many of its coefficients (hull derivatives,
   resistance, thrust deduction, the rudder lift gradient, propeller-induced forces: everything
   that multiplies a force term while the mass matrix is fixed). The regression matrix is built
   symbolically from the model's ``f`` (nothing is written per model), the linearity is checked
   (a parameter that enters non-linearly is an error naming it), and the coefficients follow from a
   (regularised) weighted least-squares problem. The result is a :class:`FitResult` whose estimates
   are the starting point of an output-error or maximum-likelihood refinement.
"""
from __future__ import annotations

import time
from typing import Mapping, Sequence

import casadi as ca
import numpy as np

from ..angles import wrap
from ..data import Dataset
from ..gaussian import Gaussian
from ..discretize import discretize
from ..frames import body_to_ned
from ..builder import ModelBuilder
from ..model import Model
from .result import FitResult
from .records import record_label
from .uncertainty import covariance_from_information, effective_samples, whiteness
from ..errors import InputError

__all__ = ["rates_model", "smooth_trial", "inverse_dynamics", "linear_in"]

_BODY = ("u", "v", "r")


def rates_model() -> Model:
    """Body-frame kinematics with accelerations driven by white jerk noise (for smoothing trials).

    States ``x, y, psi`` (NED pose of the reference point), ``u, v, r`` (body velocities) and
    ``u_dot, v_dot, r_dot``; ``x' = u cos psi - v sin psi``, ``y' = u sin psi + v cos psi``,
    ``psi' = r``, ``u' = u_dot`` (and so on), ``u_dot' = w_u`` (and so on). Outputs ``x, y, psi, u,
    v, r``.
    """
    b = ModelBuilder("body-rates", "3-DOF body kinematics with white-jerk accelerations (trial smoothing)")
    x, y = b.state("x", unit="m"), b.state("y", unit="m")
    psi = b.state("psi", unit="rad", angle=True)
    vel = [b.state(s, unit=unit) for s, unit in zip(_BODY, ("m/s", "m/s", "rad/s"))]
    acc = [b.state(f"{s}_dot", unit=unit) for s, unit in zip(_BODY, ("m/s^2", "m/s^2", "rad/s^2"))]
    xd, yd, psid = body_to_ned(*vel, psi)
    b.ode(x=xd, y=yd, psi=psid, **{s: a for s, a in zip(_BODY, acc)},
          **{f"{s}_dot": b.noise(f"w_{s}", unit="jerk") for s in _BODY})
    for name, sym in zip(("x", "y", "psi", *_BODY), (x, y, psi, *vel)):
        b.output(name, sym)
    return b.build()


def smooth_trial(data: Dataset, sigma: Mapping[str, float], jerk: Mapping[str, float], *,
                 measured: Sequence[str] | None = None, P0: Mapping[str, float] | None = None) -> Dataset:
    """EKF + RTS smoothing of a trial's pose (and speeds) into body velocities and accelerations.

    Parameters
    ----------
    data : Dataset
        A record with at least ``x, y, psi`` (psi may be continuous; it is wrapped for the filter).
    sigma : mapping output -> float
        Measurement standard deviation of every measured channel (m, rad, m/s, rad/s).
    jerk : mapping {"u", "v", "r"} -> float
        Square roots of the power spectral densities of the jerk noise (m/s^3/sqrt(Hz) for u and v,
        rad/s^3/sqrt(Hz) for r): how fast the accelerations may change. Larger values follow the
        data more closely (noisier accelerations).
    measured : sequence of str, optional
        Channels used (default ``x, y, psi``; ``u``, ``v``, ``r`` may be added when the record holds
        trusted columns).
    P0 : mapping state -> float, optional
        Prior standard deviations of the first state (defaults: the measurement sigma for measured
        channels, 1 m/s, 1 m/s, 0.01 rad/s for unmeasured velocities, 0.01 m/s^2, 0.01 m/s^2,
        1e-4 rad/s^2 for the accelerations).

    Returns
    -------
    Dataset
        The record's columns, with ``u, v, r, x, y, psi`` replaced by the smoothed values (``psi``
        continuous), plus ``u_dot, v_dot, r_dot`` and the smoothed standard deviations
        ``<name>_std`` of the velocities and accelerations. ``meta["smoother"]`` records the
        settings.

    Examples
    --------
    >>> s = smooth_trial(data, sigma={"x": 1.0, "y": 1.0, "psi": 0.002},
    ...                  jerk={"u": 1e-3, "v": 1e-3, "r": 1e-5})           # doctest: +SKIP
    >>> s["r_dot"]                                                          # doctest: +SKIP
    """
    from ..estimators import EKF

    m = rates_model()
    measured = tuple(measured or ("x", "y", "psi"))
    unknown = [c for c in measured if c not in m.output_names]
    if unknown:
        raise InputError(f"smooth_trial: cannot measure {unknown}; choose from {list(m.output_names)}")
    missing = [c for c in measured if c not in data]
    if missing:
        raise InputError(f"smooth_trial: the record has no column(s) {missing}")
    for what, given, need in (("sigma", sigma, measured), ("jerk", jerk, _BODY)):
        lacking = [c for c in need if c not in given]
        extra = sorted(set(given) - set(need))
        if lacking or extra:
            raise InputError(f"smooth_trial: {what} must give exactly {list(need)}; "
                             f"missing {lacking}, not used {extra}")
        bad = [c for c in need if not (np.isfinite(given[c]) and given[c] > 0)]
        if bad:
            raise InputError(f"smooth_trial: {what} of {bad} must be positive")
    psi_cont = np.unwrap(np.asarray(data["psi"], dtype=float))
    cols = {c: np.asarray(data[c], dtype=float) for c in measured}
    cols["psi"] = wrap(psi_cont) if "psi" in cols else None
    rec = Dataset(data.t, {c: v for c, v in cols.items() if v is not None})
    dt = float(np.median(np.diff(data.t)))
    ekf = EKF(discretize(m, dt), Q=np.diag([jerk[s] ** 2 for s in _BODY]), R=[sigma[c] ** 2 for c in measured],
              measured=measured, options={"covariance": "continuous"})
    first = _first_state(data, psi_cont)
    spread = {"x": 1.0, "y": 1.0, "psi": 0.01, "u": 1.0, "v": 1.0, "r": 0.01, "u_dot": 0.01, "v_dot": 0.01,
              "r_dot": 1e-4}
    spread.update({c: sigma[c] for c in measured})
    spread.update(dict(P0 or {}))
    prior = Gaussian(m.states(**first), np.diag([spread[s] ** 2 for s in m.state_names]))
    sm = ekf.smooth(rec, prior)
    std = sm.std
    out = {name: np.asarray(data[name]) for name in data.names}
    for i, s in enumerate(m.state_names):
        out[s] = sm.x[:, i]
        if s not in ("x", "y", "psi"):
            out[f"{s}_std"] = std[:, i]
    # continuous heading, following the record's turns
    out["psi"] = psi_cont + wrap(sm["psi"] - psi_cont)
    units = dict(data.units)
    units.update({f"{s}_dot": u for s, u in zip(_BODY, ("m/s^2", "m/s^2", "rad/s^2"))})
    meta = dict(data.meta)
    meta["smoother"] = {"method": "EKF (continuous-discrete) + RTS, body-rates model", "measured": list(measured),
                        "sigma": dict(sigma), "jerk": dict(jerk)}
    return Dataset(data.t, out, units, meta)


def _first_state(data: Dataset, psi_cont: np.ndarray) -> dict:
    """Initial guess from the first rows: pose, speeds (from the record or differenced positions)."""
    k = min(len(data) - 1, 5)
    dt = data.t[k] - data.t[0]
    xd = (data["x"][k] - data["x"][0]) / dt
    yd = (data["y"][k] - data["y"][0]) / dt
    psi0 = float(wrap(psi_cont[0]))
    guess = {"x": float(data["x"][0]), "y": float(data["y"][0]), "psi": psi0,
             "u": xd * np.cos(psi0) + yd * np.sin(psi0), "v": -xd * np.sin(psi0) + yd * np.cos(psi0),
             "r": (psi_cont[k] - psi_cont[0]) / dt}
    for s in _BODY:
        if s in data and np.isfinite(data[s][0]):
            guess[s] = float(data[s][0])
    return guess


def linear_in(model: Model, names: Sequence[str], states: Sequence[str] = _BODY) -> dict[str, bool]:
    """Whether the rates of ``states`` are affine in each parameter of ``names`` jointly.

    Parameters
    ----------
    model : Model
        The model whose right-hand side ``f`` is checked (symbolically).
    names : sequence of str
        Parameters taken free together.
    states : sequence of str
        States whose rate equations are checked (default ``u, v, r``).

    Returns
    -------
    dict
        ``name -> bool``: False when ``name`` appears non-linearly in ``f`` (also through a product
        with another parameter of ``names``), which rules it out of :func:`inverse_dynamics`.

    Examples
    --------
    >>> from casship.models import kvlcc2
    >>> linear_in(kvlcc2(), ["N_r_dash", "f_alpha", "a_H"])
    {'N_r_dash': True, 'f_alpha': False, 'a_H': False}
    """
    idx = model.indices(names, "param")
    rows = model.indices(states, "state")
    theta = ca.SX.sym("theta", len(idx))
    p = ca.SX(model.p)
    for j, i in enumerate(idx):
        p[i] = theta[j]
    fx = ca.substitute(model.xdot, model.p, p)
    f = ca.vertcat(*[fx[i] for i in rows])
    J = ca.jacobian(f, theta)
    return {n: not ca.depends_on(J[:, j], theta) for j, n in enumerate(names)}


def inverse_dynamics(model: Model, data, free: Sequence[str], *, sigma: Mapping[str, float] | None = None,
                     prior: Mapping[str, float] | None = None, params=None, states: Sequence[str] = _BODY,
                     autocorrelation: bool = False) -> FitResult:
    """Least-squares regression of the coefficients ``free`` on smoothed accelerations.

    Minimises ``sum_k sum_s ((xdot_s,k - f_s(x_k, u_k, p)) / sigma_s)^2 + sum_i ((p_i - p0_i) /
    prior_i)^2`` over the ``free`` parameters, where ``f`` is the model's right-hand side, which
    must be affine in them (checked; see :func:`linear_in`), so the minimum is found in one linear
    solve.

    Parameters
    ----------
    model : Model
        A continuous model with states ``states`` whose values and rates are columns of the data.
    data : Dataset or sequence of Dataset
        Records with the model's inputs, its states (e.g. from :func:`smooth_trial`) and the rates
        ``<state>_dot``. Rows with a non-finite value are an error.
    free : sequence of str
        Parameters to regress.
    sigma : mapping state -> float, optional
        Standard deviation of each rate equation's error (default: the median of the record's
        ``<state>_dot_std`` column, or 1).
    prior : mapping name -> float, optional
        Standard deviations of a Gaussian prior around the values in ``params`` (ridge
        regularisation; a parameter left out is unregularised). With a prior the ``sigma`` are taken
        as stated (they set the weight of the data against the prior).
    params : array or mapping, optional
        Values of the fixed parameters and prior means (default nominal).
    states : sequence of str
        States whose rate equations are used (default ``u, v, r``).
    autocorrelation : bool
        Equation errors of smoothed trials are coloured (model-structure error, smoothing); with
        ``True`` each equation's ``sigma`` is set to ``rms * sqrt(tau)`` from the residuals of a
        first solve, ``tau`` the integrated autocorrelation time (initial positive sequence, Geyer
        1992), so that ``N`` correlated samples weigh as ``N / tau`` independent ones, and the
        regression is solved again.

    Returns
    -------
    FitResult
        ``method="inverse-dynamics"``; ``estimates``, ``std_errors`` (posterior with a prior; else
        from the weighted normal equations scaled by the mean squared weighted residual),
        ``params`` with the estimates, ``noise["sigma"]`` the equation weights used.

    Examples
    --------
    >>> guess = inverse_dynamics(ship, smoothed, ["N_r_dash", "N_v_dash"]).estimates  # doctest: +SKIP
    """
    t0 = time.perf_counter()
    records = [data] if isinstance(data, Dataset) else list(data)
    if not records:
        raise InputError("inverse_dynamics: no records")
    free, states = list(free), list(states)
    if not free:
        raise InputError("inverse_dynamics: no free parameters")
    model.indices(free, "param")
    linear = linear_in(model, free, states)
    bad = [n for n, ok in linear.items() if not ok]
    if bad:
        raise InputError(f"inverse_dynamics: the rates of {states} are not linear in {bad} (with the other free "
                         "parameters fixed); regress them by output error instead, or fix them")
    base = model.params() if params is None else model.params(params)
    prior = dict(prior or {})
    unknown = sorted(set(prior) - set(free))
    if unknown:
        raise InputError(f"inverse_dynamics: prior given for {unknown}, which are not free {free}")
    if any(not (np.isfinite(prior[n]) and prior[n] > 0) for n in prior):
        raise InputError("inverse_dynamics: prior standard deviations must be positive")
    A, y, sizes = _regression(model, records, free, states, base)
    sig = _equation_sigma(records, states, sigma)
    idx = model.indices(free, "param")
    p0 = base[idx]
    w_prior = np.array([1.0 / prior[n] if n in prior else 0.0 for n in free])
    scale = np.where(np.abs(p0) > 0, np.abs(p0), 1.0)          # column scaling for conditioning
    eq = np.tile(np.arange(len(states)), A.shape[0] // len(states))
    est, res = _solve(A, y, 1.0 / sig[eq], w_prior, p0, scale)
    if autocorrelation:
        per_record = _split(res, sizes, len(states))
        neff = effective_samples(per_record, list(states))
        tau = np.array([neff[st]["tau"] for st in states])
        rms = np.sqrt([np.mean(res[eq == j] ** 2) for j in range(len(states))])
        sig = rms * np.sqrt(tau)
        est, res = _solve(A, y, 1.0 / sig[eq], w_prior, p0, scale)
    w = 1.0 / sig[eq]
    wres = res * w
    n_obs = res.size
    s2 = 1.0 if prior else float(wres @ wres) / max(n_obs - len(free), 1)
    As = np.vstack([A * w[:, None] * scale, np.diag(w_prior * scale)])
    info = (As.T @ As) / s2
    cost = 0.5 * float(wres @ wres) + 0.5 * float(np.sum((w_prior * (est - p0)) ** 2))
    fitted = base.copy()
    fitted[idx] = est
    loglik = -0.5 * n_obs * (1 + np.log(2 * np.pi * s2)) - float(n_obs / len(states) * np.sum(np.log(sig)))
    return _fit_result(model=model, params=model.param_dict(fitted), names=free, values=est, info=info,
                  jac_nat=scale, scale=dict(zip(free, scale)), cost=cost, loglik=loglik, n_obs=n_obs,
                  residuals=[r / np.sqrt(s2) for r in _split(wres, sizes, len(states))],
                  output_names=[f"{s}_dot" for s in states], method="inverse-dynamics",
                  status="least-squares", iterations=0, solve_time_s=time.perf_counter() - t0,
                  noise={"sigma": {f"{s}_dot": float(v * np.sqrt(s2)) for s, v in zip(states, sig)},
                         "weight_scale": float(np.sqrt(s2)), "prior": dict(prior)},
                  x0=[], predictions=[], records=[record_label(d, k) for k, d in enumerate(records)])


def _fit_result(*, model: Model, params: dict, names, values, info, jac_nat, scale, cost, loglik, n_obs,
                residuals, output_names, method, status, iterations, solve_time_s, noise, x0, predictions,
                records):
    """The regression's :class:`FitResult`: covariance from the information matrix (delta method to
    natural units through ``jac_nat``), residual whiteness, and the model's identity."""
    del scale                                   # the covariance is already in natural units below
    names = list(names)
    cov_z, warn = covariance_from_information(info, names)
    with np.errstate(invalid="ignore"):
        cov = cov_z * np.outer(jac_nat, jac_nat)
        std = np.sqrt(np.diag(cov))
        corr = cov / np.outer(std, std)
    k = len(names)
    vessel = model.vessel
    return FitResult(model=model.name, params=dict(params), free=names,
                     estimates={n: float(v) for n, v in zip(names, values)},
                     std_errors={n: float(v) for n, v in zip(names, std)}, correlation=corr, covariance=cov,
                     cost=float(cost), loglik=float(loglik), n_obs=int(n_obs), aic=float(2 * k - 2 * loglik),
                     bic=float(k * np.log(max(n_obs, 1)) - 2 * loglik),
                     whiteness=whiteness(residuals, output_names), warnings=warn, method=method, status=status,
                     iterations=int(iterations), solve_time_s=float(solve_time_s), noise=noise, x0=x0,
                     predictions=predictions, records=list(records), model_options=dict(model.meta.get("options", {})),
                     param_set=vessel.param_set if vessel is not None else "", param_names=list(model.param_names))


def _regression(model: Model, records, free, states, base):
    """Rows ``y = A theta`` of every record (unweighted), one row per sample and rate equation."""
    rows = model.indices(states, "state")
    idx = model.indices(free, "param")
    # f(theta) = A theta + b per sample: A from the Jacobian, b from theta = 0
    theta = ca.SX.sym("theta", len(idx))
    p = ca.SX(base)
    for j, i in enumerate(idx):
        p[i] = theta[j]
    fx = model.f(model.x, model.u, p, ca.SX.zeros(model.nw))
    f = ca.vertcat(*[fx[i] for i in rows])
    reg = ca.Function("regressors", [model.x, model.u], [ca.jacobian(f, theta), ca.substitute(f, theta, 0)],
                      ["x", "u"], ["A", "b"])
    blocks_A, blocks_y, sizes = [], [], []
    for k, d in enumerate(records):
        X, U, Y = _record_arrays(model, d, states, k)
        n = X.shape[0]
        rows_n = reg.map(n)(x=X.T, u=U.T)
        A = np.asarray(rows_n["A"]).reshape(len(states), len(idx), n, order="F")     # (eq, param, sample)
        b = np.asarray(rows_n["b"]).reshape(len(states), n, order="F")
        blocks_A.append(np.transpose(A, (2, 0, 1)).reshape(n * len(states), len(idx)))
        blocks_y.append((Y - b.T).reshape(-1))
        sizes.append(n)
    return np.vstack(blocks_A), np.concatenate(blocks_y), sizes


def _solve(A, y, w, w_prior, p0, scale):
    """Weighted, regularised least squares in scaled columns: returns (estimates, residuals y - A est)."""
    As = np.vstack([A * w[:, None] * scale, np.diag(w_prior * scale)])
    ys = np.concatenate([y * w, w_prior * p0])
    z, *_ = np.linalg.lstsq(As, ys, rcond=None)
    est = z * scale
    return est, y - A @ est


def _split(res, sizes, n_eq):
    out, start = [], 0
    for n in sizes:
        out.append(res[start:start + n * n_eq].reshape(n, n_eq))
        start += n * n_eq
    return out


def _equation_sigma(records, states, sigma) -> np.ndarray:
    sigma = dict(sigma or {})
    unknown = sorted(set(sigma) - set(states))
    if unknown:
        raise InputError(f"inverse_dynamics: sigma given for {unknown}, not among the states {list(states)}")
    out = []
    for s in states:
        if s in sigma:
            v = float(sigma[s])
        else:
            cols = [np.asarray(d[f"{s}_dot_std"]) for d in records if f"{s}_dot_std" in d]
            v = float(np.median(np.concatenate(cols))) if cols else 1.0
        if not (np.isfinite(v) and v > 0):
            raise InputError(f"inverse_dynamics: sigma of {s!r} must be positive, got {v}")
        out.append(v)
    return np.array(out)


def _record_arrays(model: Model, d: Dataset, states, k: int):
    need = [*model.state_names, *model.input_names, *[f"{s}_dot" for s in states]]
    missing = [c for c in need if c not in d]
    if missing:
        raise InputError(f"inverse_dynamics: record {k} has no column(s) {missing} (smooth it with smooth_trial)")
    X = d.matrix(model.state_names)
    U = d.matrix(model.input_names, finite=True, what="input")
    Y = d.matrix([f"{s}_dot" for s in states])
    for name, M, names in (("state", X, model.state_names), ("rate", Y, [f"{s}_dot" for s in states])):
        bad = np.argwhere(~np.isfinite(M))
        if bad.size:
            raise InputError(f"inverse_dynamics: record {k}: {name} column {names[bad[0][1]]!r} is not finite "
                             f"at row {bad[0][0]}")
    return X, U, Y
