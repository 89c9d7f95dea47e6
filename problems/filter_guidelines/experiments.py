"""Koike et al.'s (2023) experiments: every filter on noisy records (Monte Carlo cases), timing and the MHE column.

Every estimator is used through the one estimator contract (``filter(data, prior, seed=...)``,
``online(prior, seed=...).update(...)``): no case depends on which filter it is.
"""
from __future__ import annotations

import time

import numpy as np

import casship as cs

from .scenario import (DATA_STD, DATA_STD_ALT, DT, FILTERS, KAPPA, MEMBERS, NOISE_STDS, Q_TUNED, R_FILTER, STATES,
                       WIND_MEANS, Config, filter_model, noisy, prior, q_channels, rmse, ship_models, truth_record)

_CACHE: dict = {}


def filters(q_kf: dict) -> dict:
    """The estimators by column name, built once per process (CasADi functions are reused)."""
    key = ("filters", tuple(sorted(q_kf.items())))
    if key not in _CACHE:
        _, ship = ship_models()
        fm = filter_model(ship)
        dm = cs.discretize(fm, DT, "euler")
        R = np.full(6, R_FILTER)
        zero = np.zeros(fm.nw)
        ukf = {"kappa": KAPPA}
        enkf = {"members": MEMBERS}
        est = {
            "UKF Q=0": cs.UKF(dm, zero, R, measured=list(STATES), options=ukf),
            "UKF tuned": cs.UKF(dm, q_channels(fm, Q_TUNED["UKF"]), R, measured=list(STATES), options=ukf),
            "EnKF Q=0": cs.EnKF(dm, zero, R, measured=list(STATES), options=enkf),
            "EnKF tuned": cs.EnKF(dm, q_channels(fm, Q_TUNED["EnKF"]), R, measured=list(STATES), options=enkf),
            "EnKF Q=1e-4": cs.EnKF(dm, q_channels(fm, Q_TUNED["UKF"]), R, measured=list(STATES), options=enkf),
            "EKF Q=0": cs.EKF(dm, zero, R, measured=list(STATES)),
            "EKF tuned": cs.EKF(dm, q_channels(fm, Q_TUNED["EKF"]), R, measured=list(STATES)),
        }
        pm = cs.persistence_model(STATES)
        est["KF"] = cs.KF(cs.discretize(pm, DT, "euler"), [q_kf[s] / DT**2 for s in STATES], R)
        _CACHE[key] = est
    return _CACHE[key]


def truth(kind: str, wind: float, duration: float, wind_form: str = "eq34"):
    """Noise-free record (cached per process)."""
    key = ("truth", kind, wind, duration, wind_form)
    if key not in _CACHE:
        windy, ship = ship_models(wind_form)
        _CACHE[key] = truth_record(windy, ship, kind, wind, duration)
    return _CACHE[key]


def run_case(case: dict) -> dict:
    """Every filter on one noisy record (``case``: kind, wind, std, seed, duration, q_kf, wind_form)."""
    est = filters(case["q_kf"])
    _, ship = ship_models()
    tr = truth(case["kind"], case["wind"], case["duration"], case.get("wind_form", "eq34"))
    data = noisy(tr, ship, case["std"], case["seed"])
    out = {}
    for name in FILTERS:
        e = est[name]
        try:
            out[name] = rmse(e.filter(data, prior(data, e.model), seed=case["seed"]), tr)
        except (RuntimeError, ValueError, np.linalg.LinAlgError) as exc:   # a diverged filter is a result
            out[name] = {s: float("nan") for s in STATES} | {"error": str(exc)[:200]}
    return {**{k: case[k] for k in ("experiment", "condition", "seed")}, "rmse": out}


def tune_kf(duration: float) -> dict:
    """Per-state Q of the persistence KF minimising RMSE on a tuning record (seed 0, not used later).

    With A = C = I and diagonal Q, R the KF decouples into six scalar filters, so each state's Q is
    tuned on its own over a grid (the paper tuned it "by trial and error").
    """
    windy, ship = ship_models()
    tr = truth_record(windy, ship, "zigzag", 0.0, duration)
    data = noisy(tr, ship, DATA_STD, seed=0)
    grid = 10.0 ** np.arange(-8.0, 0.5, 0.5)
    best = {}
    for s in STATES:
        dm = cs.discretize(cs.persistence_model([s]), DT, "euler")
        scores = []
        for q in grid:
            res = cs.KF(dm, q / DT**2, R_FILTER).filter(data.select([s]), cs.Gaussian([data[s][0]], 1.0))
            err = res[s] - tr[s]
            scores.append(np.sqrt(np.mean((cs.wrap(err) if s == "psi" else err) ** 2)))
        best[s] = float(grid[int(np.argmin(scores))])
    return best


def cases(cfg: Config, q_kf: dict) -> list[dict]:
    """The Monte Carlo cases of experiments 1-3 and of the other readings (wind form, data noise)."""
    base = {"duration": cfg.duration, "q_kf": q_kf}
    out = []
    for seed in range(1, cfg.seeds + 1):
        for w in WIND_MEANS:
            out.append({**base, "experiment": "wind", "condition": w, "kind": "zigzag", "wind": w,
                        "std": DATA_STD, "seed": seed})
        for std in NOISE_STDS:
            out.append({**base, "experiment": "noise", "condition": std, "kind": "zigzag", "wind": 0.0,
                        "std": std, "seed": seed})
        for kind in ("zigzag", "random"):
            out.append({**base, "experiment": "maneuver", "condition": kind, "kind": kind, "wind": 0.0,
                        "std": DATA_STD, "seed": seed})
        # the other readings, on experiment 1 (no wind and the strongest wind)
        out.append({**base, "experiment": "wind (Fujiwara 2005)", "condition": WIND_MEANS[-1], "kind": "zigzag",
                    "wind": WIND_MEANS[-1], "std": DATA_STD, "seed": seed, "wind_form": "fujiwara2005"})
        for w in (WIND_MEANS[0], WIND_MEANS[-1]):
            out.append({**base, "experiment": f"wind (data std {DATA_STD_ALT})", "condition": w, "kind": "zigzag",
                        "wind": w, "std": DATA_STD_ALT, "seed": seed})
    return out


def aggregate(results: list[dict]) -> dict:
    """experiment -> condition -> filter -> state -> {"mean", "std", "n", "failed"} over the seeds."""
    table: dict = {}
    for r in results:
        for name, vals in r["rmse"].items():
            cell = table.setdefault(r["experiment"], {}).setdefault(str(r["condition"]), {}).setdefault(name, {})
            for s in STATES:
                cell.setdefault(s, []).append(vals[s])
    for exp in table.values():
        for cond in exp.values():
            for cell in cond.values():
                for s, v in cell.items():
                    v = np.asarray(v, dtype=float)
                    ok = np.isfinite(v)
                    cell[s] = {"mean": float(v[ok].mean()) if ok.any() else float("nan"),
                               "std": float(v[ok].std(ddof=1)) if ok.sum() > 1 else 0.0,
                               "n": int(ok.sum()), "failed": int((~ok).sum())}
    return table


def timing(cfg: Config, q_kf: dict, repeats: int = 3) -> dict:
    """Seconds per 0.1 s step: batch (whole record in one compiled fold) and online (one ``update``
    call per sample through the estimator's online runner). Each figure is the best of ``repeats``."""
    est = filters(q_kf)
    _, ship = ship_models()
    data = noisy(truth("zigzag", 0.0, cfg.duration), ship, DATA_STD, 1)
    n = len(data)
    U = data.matrix(ship.input_names)
    Y = data.matrix(STATES)
    k = min(cfg.timing_steps, n - 1)
    out = {}
    for name in ("UKF tuned", "EnKF tuned", "KF", "EKF tuned"):
        e = est[name]
        p0 = prior(data, e.model)
        u_rows = U if e.model.nu else np.zeros((n, 0))
        e.filter(data, p0, seed=1)                           # compile/warm up
        batch, online = [], []
        for _ in range(repeats):
            t0 = time.perf_counter()
            e.filter(data, p0, seed=1)
            batch.append((time.perf_counter() - t0) / n)
            run = e.online(p0, seed=1, u=u_rows[0])
            run.update(Y[0], 0.0)
            t0 = time.perf_counter()
            for j in range(1, k + 1):
                run.update(Y[j], DT, u_prev=u_rows[j - 1])
            online.append((time.perf_counter() - t0) / k)
        out[name.split()[0]] = {"batch_s_per_step": min(batch), "online_s_per_step": min(online)}
    return out


def mhe_column(cfg: Config, q_kf: dict) -> dict:
    """casship's MHE (tuned Q) on the wind experiment, one seed, a shorter record (it is slower)."""
    est = filters(q_kf)
    _, ship = ship_models()
    fm = filter_model(ship)
    mhe = cs.MHE(cs.discretize(fm, DT, "euler"), q_channels(fm, Q_TUNED["UKF"]), np.full(6, R_FILTER),
                 measured=list(STATES), options={"horizon": cfg.mhe_horizon, "solver": "rti"})
    out = {}
    for w in WIND_MEANS:
        tr = truth("zigzag", w, cfg.duration)
        data = noisy(tr, ship, DATA_STD, 1).slice(0, int(round(cfg.mhe_duration / DT)))
        sub = tr.slice(0, len(data))
        t0 = time.perf_counter()
        try:
            res = mhe.filter(data, prior(data, fm))
            out[str(w)] = {"rmse": rmse(res, sub), "s_per_step": (time.perf_counter() - t0) / len(data)}
        except Exception as exc:  # noqa: BLE001 - report the failure in the table, do not hide it
            out[str(w)] = {"error": f"{type(exc).__name__}: {str(exc)[:200]}"}
        out[str(w)]["ukf_same_record"] = rmse(est["UKF tuned"].filter(data, prior(data, fm)), sub)
    return out
