"""Seed 002: guidelines for UKF and EnKF in ship state estimation (automatic berthing), reproduced.

The system: a single-propeller, twin-rudder ship with Yoshimura's low-speed hull model (MMG form,
seed 002 Eq. 20-22), Euler-discretised at dt = 0.1 s (Eq. 25), every state measured (H = I6).
The filters: UKF (2n+1 sigma points, kappa = 3), EnKF (N = 100, perturbed observations) and the
linear KF on the persistence model (A = I) as baseline, each with Q = 0 and with tuned Q
(UKF diag(1e-4), EnKF diag(1e-2) as in the paper; the KF's Q tuned per state on a separate
record), R = diag(5e-2), P(0) = I, x(0) = y(0). casship's EKF and MHE are extra columns.

Experiments (RMSE of the filtered states against the noise-free truth, Monte Carlo over noise seeds):

1. modelling error: a gusty Fujiwara wind acts on the ship in the data but is absent from the
   filter model; mean wind speed 0, 0.82 and 1.64 m/s (one gust record scaled by 0, 0.5, 1);
2. observation noise in the data: R = 0.05^2, 0.10^2, 0.20^2 (the filters keep their R);
3. zig-zag versus random rudder (delta_s uniform in [-35, 105] deg, delta_p in [-105, 35] deg);
4. computation time per 0.1 s step, batch (compiled fold) and online (one call per sample).

Run: ``casship study filter-guidelines [--quick] [--workers N] [--scheduler tcp://...]``.
"""
from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import casship as cs
from casship.maneuvers import propeller_rate_for_speed
from casship.parallel import run_cases
from casship.progress import progress

from . import Study

DT = 0.1
R_FILTER = 5e-2                     # seed 002 Eq. 30 (variance, every state)
Q_TUNED = {"UKF": 1e-4, "EnKF": 1e-2, "EKF": 1e-4}   # seed 002 Sect. 5.1 (EKF: same as the UKF)
KAPPA, MEMBERS = 3.0, 100
WIND_MEANS = (0.0, 0.82, 1.64)      # m/s
NOISE_STDS = (0.05, 0.10, 0.20)
DATA_STD = 0.05                     # observation noise of the data in experiments 1 and 3
STATES = ("x", "u", "y", "v", "psi", "r")      # seed 002 order
FILTERS = ("UKF Q=0", "UKF tuned", "EnKF Q=0", "EnKF tuned", "KF", "EKF Q=0", "EKF tuned", "EnKF Q=1e-4")
# "EnKF Q=1e-4": the EnKF with the UKF's tuned Q, to separate the filter from the choice of Q


@dataclass(frozen=True)
class Config:
    duration: float
    seeds: int
    mhe_horizon: int
    mhe_duration: float
    timing_steps: int

    @classmethod
    def make(cls, quick: bool) -> "Config":
        if quick:
            return cls(duration=40.0, seeds=2, mhe_horizon=10, mhe_duration=8.0, timing_steps=50)
        return cls(duration=200.0, seeds=10, mhe_horizon=20, mhe_duration=60.0, timing_steps=300)


# -- the ship ----------------------------------------------------------------------------------------------
def ship_models():
    """``(truth, ship)``: the twin-rudder low-speed ship with Fujiwara wind (truth) and without (filter).

    casship's preset for seed 002 (Esso Osaka 3 m hull coefficients, Yoshimura's low-speed model,
    one propeller, twin rudders); the wind geometry is the preset's estimate for a 3 m tanker model.
    """
    from casship.models.wind import add_wind

    ship = cs.models.esso_osaka_twin()
    return add_wind(ship), ship


def propeller_rate(ship) -> float:
    """Propeller rate [1/s] that holds the preset's speed ``U0`` in a straight run (exact trim)."""
    return propeller_rate_for_speed(ship, ship.vessel.U0, guess=10.0)


def filter_model(ship):
    """The filter's model: the ship plus additive noise on every state, ``x[k+1] = f(x[k]) + v``.

    The ship's own noise channels act on the accelerations; noise on ``x, y, psi`` is added here so
    that ``Q`` is a 6 x 6 state covariance as in the paper (channel variance = Q / dt^2 with Euler).
    """
    b = ship.builder(f"{ship.name}+state_noise")
    for s in ("x", "y", "psi"):
        b.add_to_ode(**{s: b.noise(f"w_{s}")})
    return b.build()


def _q_channels(model, q_state: float) -> np.ndarray:
    """Variances of the model's noise channels that give state-noise variance ``q_state`` per step."""
    order = {"w_u": "u", "w_v": "v", "w_r": "r", "w_x": "x", "w_y": "y", "w_psi": "psi"}
    missing = set(model.noise_names) - set(order)
    if missing:
        raise ValueError(f"unexpected noise channels {sorted(missing)} in {model.name!r}")
    return np.full(model.nw, q_state / DT**2)


# -- inputs: manoeuvres and wind ---------------------------------------------------------------------------
def gust_record(duration: float, mean: float, seed: int = 2021):
    """A gusty wind record: speed with 30 % gusts (time scale 5 s), direction wandering +-15 deg.

    Scaled copies (factor ``mean / 1.64``) give the paper's three mean speeds from one record.
    """
    t = np.arange(0.0, duration, DT)
    rng = np.random.default_rng(seed)

    def ou(tau, sigma):
        a = np.exp(-DT / tau)
        z = np.empty(t.size)
        z[0] = rng.normal(0.0, sigma)
        e = rng.normal(0.0, sigma * np.sqrt(1 - a * a), t.size)
        for k in range(1, t.size):
            z[k] = a * z[k - 1] + e[k]
        return z

    gust = ou(5.0, 0.3)
    heading = ou(20.0, np.radians(15.0))
    base = 1.64 * np.maximum(0.0, 1.0 + gust)
    base *= 1.64 / base.mean()
    return t, base * (mean / 1.64), np.radians(60.0) + heading


def rudder_inputs(kind: str, t: np.ndarray, ship, n: float, seed: int = 7) -> dict:
    """Twin-rudder commands on the grid ``t``.

    ``"zigzag"``: a 20/20 zig-zag (both rudders together, switched on the heading by
    :class:`casship.maneuvers.ZigZag`) run on the wind-free ship; the same rudder record is then
    used in every wind condition, so the conditions differ only in the wind. ``"random"``: a new
    uniform draw every 5 s, delta_s in [-35, 105] deg and delta_p in [-105, 35] deg (seed 002).
    """
    if kind == "zigzag":
        from casship.maneuvers import ZigZag

        law = ZigZag(ship, np.radians(20.0), np.radians(20.0), n, t_exec=1.0)
        tr = cs.simulate(ship, ship.states(u=ship.vessel.U0), t, law, method="euler")
        return {"delta_s": tr["delta_s"], "delta_p": tr["delta_p"]}
    if kind == "random":
        from casship.maneuvers import random_rudder_inputs

        u = random_rudder_inputs(ship, t, n, hold=5.0, seed=seed)       # seed 002 ranges by default
        return {"delta_s": u["delta_s"], "delta_p": u["delta_p"]}
    raise ValueError(f"unknown manoeuvre {kind!r}; use 'zigzag' or 'random'")


def truth_record(truth, ship, kind: str, wind_mean: float, duration: float):
    """Noise-free trajectory of the ship with wind (the filters never see the wind)."""
    t, speed, direction = gust_record(duration, wind_mean)
    n = propeller_rate(ship)
    inputs = {"n": np.full(t.size, n), **rudder_inputs(kind, t, ship, n),
              "wind_speed": speed, "wind_dir": direction}
    x0 = ship.states(u=ship.vessel.U0)
    return cs.simulate(truth, x0, t, inputs, method="euler")


# -- one Monte Carlo case: every filter on one noisy record -------------------------------------------------
_CACHE: dict = {}


def _filters(q_kf: dict):
    """Estimators built once per process (CasADi functions are reused across cases)."""
    key = ("filters", tuple(sorted(q_kf.items())))
    if key not in _CACHE:
        truth, ship = ship_models()
        fm = filter_model(ship)
        dm = cs.discretize(fm, DT, "euler")
        R = np.full(6, R_FILTER)
        zero = np.zeros(fm.nw)
        est = {
            "UKF Q=0": cs.UKF(dm, zero, R, measured=list(STATES), options={"kappa": KAPPA}),
            "UKF tuned": cs.UKF(dm, _q_channels(fm, Q_TUNED["UKF"]), R, measured=list(STATES),
                                options={"kappa": KAPPA}),
            "EnKF Q=0": cs.EnKF(dm, zero, R, measured=list(STATES), options={"members": MEMBERS}),
            "EnKF tuned": cs.EnKF(dm, _q_channels(fm, Q_TUNED["EnKF"]), R, measured=list(STATES),
                                  options={"members": MEMBERS}),
            "EnKF Q=1e-4": cs.EnKF(dm, _q_channels(fm, Q_TUNED["UKF"]), R, measured=list(STATES),
                                   options={"members": MEMBERS}),
            "EKF Q=0": cs.EKF(dm, zero, R, measured=list(STATES)),
            "EKF tuned": cs.EKF(dm, _q_channels(fm, Q_TUNED["EKF"]), R, measured=list(STATES)),
        }
        pm = cs.persistence_model(STATES)
        est["KF"] = cs.KF(cs.discretize(pm, DT, "euler"), [q_kf[s] / DT**2 for s in STATES], R)
        _CACHE[key] = (truth, ship, fm, est)
    return _CACHE[key]


def _truth(kind: str, wind: float, duration: float):
    key = ("truth", kind, wind, duration)
    if key not in _CACHE:
        truth, ship = ship_models()
        _CACHE[key] = truth_record(truth, ship, kind, wind, duration)
    return _CACHE[key]


def _noisy(tr, ship, std: float, seed: int) -> cs.Dataset:
    rng = np.random.default_rng(seed)
    cols = {n: tr[n] for n in ship.input_names}
    cols.update({s: tr[s] + rng.normal(0.0, std, len(tr)) for s in STATES})
    return cs.Dataset(tr.t, cols)


def _prior(data: cs.Dataset, model) -> cs.Gaussian:
    """x(0) = y(0), P(0) = I (seed 002 Eq. 27, 31)."""
    return cs.Gaussian(np.array([data[s][0] for s in model.state_names]), np.eye(model.nx))


def rmse(res, tr) -> dict:
    out = {}
    for s in STATES:
        err = res[s] - tr[s]
        if s == "psi":
            err = cs.wrap(err)
        out[s] = float(np.sqrt(np.mean(err**2)))
    return out


def run_case(case: dict) -> dict:
    """All filters on one noisy record (``case`` = kind, wind, std, seed, duration, q_kf)."""
    truth, ship, fm, est = _filters(case["q_kf"])
    tr = _truth(case["kind"], case["wind"], case["duration"])
    data = _noisy(tr, ship, case["std"], case["seed"])
    out = {}
    for name in FILTERS:
        e = est[name]
        prior = _prior(data, e.model)
        try:
            res = e.filter(data, prior, seed=case["seed"]) if name.startswith("EnKF") else e.filter(data, prior)
            out[name] = rmse(res, tr)
        except (RuntimeError, ValueError, np.linalg.LinAlgError) as exc:   # a diverged filter is a result
            out[name] = {s: float("nan") for s in STATES} | {"error": str(exc)[:200]}
    return {**{k: case[k] for k in ("experiment", "condition", "seed")}, "rmse": out}


def tune_kf(duration: float) -> dict:
    """Per-state Q of the persistence KF minimising RMSE on a tuning record (seed 0, not used later).

    With A = C = I and diagonal Q, R the KF decouples into six scalar filters, so each state's Q is
    tuned on its own over a grid (the paper tuned it "by trial and error").
    """
    truth, ship = ship_models()
    tr = truth_record(truth, ship, "zigzag", 0.0, duration)
    data = _noisy(tr, ship, DATA_STD, seed=0)
    grid = 10.0 ** np.arange(-8.0, 0.5, 0.5)
    best = {}
    for s in STATES:
        pm = cs.persistence_model([s])
        dm = cs.discretize(pm, DT, "euler")
        scores = []
        for q in grid:
            kf = cs.KF(dm, q / DT**2, R_FILTER)
            res = kf.filter(data.select([s]), cs.Gaussian([data[s][0]], 1.0))
            err = res[s] - tr[s]
            scores.append(np.sqrt(np.mean((cs.wrap(err) if s == "psi" else err) ** 2)))
        best[s] = float(grid[int(np.argmin(scores))])
    return best


# -- experiments ---------------------------------------------------------------------------------------------
def _cases(cfg: Config, q_kf: dict) -> list[dict]:
    base = {"duration": cfg.duration, "q_kf": q_kf}
    cases = []
    for seed in range(1, cfg.seeds + 1):
        for w in WIND_MEANS:
            cases.append({**base, "experiment": "wind", "condition": w, "kind": "zigzag", "wind": w,
                          "std": DATA_STD, "seed": seed})
        for std in NOISE_STDS:
            cases.append({**base, "experiment": "noise", "condition": std, "kind": "zigzag", "wind": 0.0,
                          "std": std, "seed": seed})
        for kind in ("zigzag", "random"):
            cases.append({**base, "experiment": "maneuver", "condition": kind, "kind": kind, "wind": 0.0,
                          "std": DATA_STD, "seed": seed})
    return cases


def aggregate(results: list[dict]) -> dict:
    """experiment -> condition -> filter -> state -> {"mean", "std", "n"} over the seeds."""
    table: dict = {}
    for r in results:
        for name, vals in r["rmse"].items():
            cell = table.setdefault(r["experiment"], {}).setdefault(str(r["condition"]), {}).setdefault(name, {})
            for s in STATES:
                cell.setdefault(s, []).append(vals[s])
    for exp in table.values():
        for cond in exp.values():
            for name, cell in cond.items():
                for s, v in cell.items():
                    v = np.asarray(v, dtype=float)
                    ok = np.isfinite(v)
                    cell[s] = {"mean": float(v[ok].mean()) if ok.any() else float("nan"),
                               "std": float(v[ok].std(ddof=1)) if ok.sum() > 1 else 0.0,
                               "n": int(ok.sum()), "failed": int((~ok).sum())}
    return table


def timing(cfg: Config, q_kf: dict, repeats: int = 3) -> dict:
    """Seconds per 0.1 s step: batch (whole record in one compiled fold) and online (``run.update`` calls).

    Each figure is the best of ``repeats`` runs, so that other load on the machine inflates it less.
    """
    truth, ship, fm, est = _filters(q_kf)
    tr = _truth("zigzag", 0.0, cfg.duration)
    data = _noisy(tr, ship, DATA_STD, 1)
    n = len(data)
    U = data.matrix(ship.input_names)
    Y = data.matrix(STATES)
    k = min(cfg.timing_steps, n - 1)
    out = {}
    for name in ("UKF tuned", "EnKF tuned", "KF", "EKF tuned"):
        e = est[name]
        prior = _prior(data, e.model)
        kw = {"seed": 1} if name.startswith("EnKF") else {}
        u_rows = U if e.model.nu else np.zeros((n, 0))
        e.filter(data, prior, **kw)                         # compile/warm up
        batch, online = [], []
        for _ in range(repeats):
            t0 = time.perf_counter()
            e.filter(data, prior, **kw)
            batch.append((time.perf_counter() - t0) / n)
            run = e.online(prior, seed=1, u=u_rows[0])
            t0 = time.perf_counter()
            for j in range(1, k + 1):
                run.update(Y[j], DT, u_prev=u_rows[j - 1])
            online.append((time.perf_counter() - t0) / k)
        out[name.split()[0]] = {"batch_s_per_step": min(batch), "online_s_per_step": min(online)}
    return out


def mhe_column(cfg: Config, q_kf: dict) -> dict | None:
    """casship's MHE (tuned Q) on the wind experiment, one seed, a shorter record (it is slower)."""
    if not hasattr(cs, "MHE"):
        return None
    truth, ship, fm, est = _filters(q_kf)
    dm = cs.discretize(fm, DT, "euler")
    mhe = cs.MHE(dm, _q_channels(fm, Q_TUNED["UKF"]), np.full(6, R_FILTER), measured=list(STATES),
                 options={"horizon": cfg.mhe_horizon, "solver": "rti"})
    out = {}
    for w in WIND_MEANS:
        tr = _truth("zigzag", w, cfg.duration)
        data = _noisy(tr, ship, DATA_STD, 1).slice(0, int(round(cfg.mhe_duration / DT)))
        sub = tr.slice(0, len(data))
        t0 = time.perf_counter()
        try:
            res = mhe.filter(data, _prior(data, fm))
            out[str(w)] = {"rmse": rmse(res, sub), "s_per_step": (time.perf_counter() - t0) / len(data)}
        except Exception as exc:  # noqa: BLE001 - report the failure in the table, do not hide it
            out[str(w)] = {"error": f"{type(exc).__name__}: {str(exc)[:200]}"}
        ref = est["UKF tuned"].filter(data, _prior(data, fm))
        out[str(w)]["ukf_same_record"] = rmse(ref, sub)
    return out


# -- figures -------------------------------------------------------------------------------------------------
def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


_UNITS = {"x": "m", "u": "m/s", "y": "m", "v": "m/s", "psi": "rad", "r": "rad/s"}


def _bars(path: Path, exp: dict, filters, conditions, labels, title: str) -> None:
    plt = _plt()
    fig, axes = plt.subplots(len(filters), 1, figsize=(9, 2.6 * len(filters)), sharex=True, squeeze=False)
    width = 0.8 / len(conditions)
    for ax, name in zip(axes[:, 0], filters):
        for i, (cond, label) in enumerate(zip(conditions, labels)):
            cell = exp[str(cond)][name]
            mean = [cell[s]["mean"] for s in STATES]
            std = [cell[s]["std"] for s in STATES]
            ax.bar(np.arange(6) + (i - (len(conditions) - 1) / 2) * width, mean, width, yerr=std, capsize=2,
                   label=label)
        ax.set_yscale("log")
        ax.set_ylabel(f"RMSE\n{name}")
        ax.grid(axis="y", alpha=0.3)
    axes[0, 0].legend(fontsize=8, ncol=len(conditions))
    axes[-1, 0].set_xticks(np.arange(6), [f"{s} [{_UNITS[s]}]" for s in STATES])
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _fig_wind(path: Path, duration: float) -> None:
    plt = _plt()
    fig, axes = plt.subplots(2, 1, figsize=(8, 5), sharex=True)
    for w in WIND_MEANS[1:]:
        t, speed, direction = gust_record(duration, w)
        axes[0].plot(t, speed, lw=0.8, label=f"mean {w:g} m/s")
        axes[1].plot(t, np.degrees(direction), lw=0.8)
    axes[0].set_ylabel("U_T [m/s]")
    axes[1].set_ylabel("gamma_T [deg]")
    axes[1].set_xlabel("t [s]")
    axes[0].legend(fontsize=8)
    fig.suptitle("Gusty wind records (one record scaled by 0, 0.5, 1)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _fig_wind_effect(path: Path, duration: float) -> None:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6, 6))
    for w, style in zip(WIND_MEANS[::-1], ("C3-", "C1-", "k--")):
        tr = _truth("zigzag", w, duration)
        ax.plot(tr["y"], tr["x"], style, lw=1, label=f"wind {w:g} m/s" if w else "without wind")
    ax.set_xlabel("y (East) [m]")
    ax.set_ylabel("x (North) [m]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend(fontsize=8)
    ax.set_title("Zig-zag with and without wind (the filters' model has none)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _fig_maneuvers(path: Path, duration: float) -> None:
    plt = _plt()
    fig, axes = plt.subplots(2, 2, figsize=(10, 7))
    for col, kind in enumerate(("zigzag", "random")):
        tr = _truth(kind, 0.0, duration)
        for name in (n for n in tr.input_names if n.startswith("delta")):
            axes[0, col].plot(tr.t, np.degrees(tr[name]), lw=0.8, label=name)
        axes[0, col].set_xlabel("t [s]")
        axes[0, col].set_ylabel("rudder [deg]")
        axes[0, col].set_title(kind)
        axes[0, col].legend(fontsize=8)
        axes[1, col].plot(tr["y"], tr["x"], "k", lw=1)
        axes[1, col].set_xlabel("y (East) [m]")
        axes[1, col].set_ylabel("x (North) [m]")
        axes[1, col].set_aspect("equal", adjustable="datalim")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _fig_time(path: Path, times: dict) -> None:
    plt = _plt()
    names = list(times)
    fig, ax = plt.subplots(figsize=(7, 4))
    x = np.arange(len(names))
    ax.bar(x - 0.2, [times[n]["batch_s_per_step"] for n in names], 0.4, label="batch (compiled fold)")
    ax.bar(x + 0.2, [times[n]["online_s_per_step"] for n in names], 0.4, label="online (step calls)")
    ax.axhline(DT, color="k", ls="--", lw=0.8, label="real time (0.1 s)")
    ax.set_yscale("log")
    ax.set_xticks(x, names)
    ax.set_ylabel("seconds per 0.1 s step")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# -- tables and the written comparison -------------------------------------------------------------------------
def _table(exp: dict, filters, conditions, label: str) -> str:
    head = f"| filter | {label} | " + " | ".join(f"{s} [{_UNITS[s]}]" for s in STATES) + " |"
    lines = [head, "|" + "---|" * (2 + len(STATES))]
    for name in filters:
        for cond in conditions:
            cell = exp[str(cond)][name]
            vals = []
            for s in STATES:
                c = cell[s]
                txt = f"{c['mean']:.3g} ± {c['std']:.2g}" if np.isfinite(c["mean"]) else "diverged"
                if c["failed"]:
                    txt += f" ({c['failed']} failed)"
                vals.append(txt)
            lines.append(f"| {name} | {cond} | " + " | ".join(vals) + " |")
    return "\n".join(lines)


def _mean_over_states(cell: dict) -> float:
    """Geometric mean of the per-state RMSE (states have different units)."""
    v = np.array([cell[s]["mean"] for s in STATES])
    return float(np.exp(np.mean(np.log(v)))) if np.all(np.isfinite(v) & (v > 0)) else float("nan")


def findings(table: dict, times: dict) -> dict:
    """The paper's claims, each measured on our numbers (ratios of mean RMSE)."""
    W, N, M = table["wind"], table["noise"], table["maneuver"]
    w0, w2 = str(WIND_MEANS[0]), str(WIND_MEANS[-1])
    f = {}
    for name in FILTERS:
        f[f"wind growth {name}"] = _mean_over_states(W[w2][name]) / _mean_over_states(W[w0][name])
    for name in ("UKF", "EnKF", "EKF"):
        q0, tuned = W[w2][f"{name} Q=0"], W[w2][f"{name} tuned"]
        gains = {s: q0[s]["mean"] / tuned[s]["mean"] for s in STATES}
        f[f"tuned Q gain {name}"] = _mean_over_states(q0) / _mean_over_states(tuned)
        f[f"tuned Q states improved {name}"] = int(sum(g > 1 for g in gains.values()))
        f[f"tuned Q best gain {name}"] = float(max(gains.values()))
    q0, alt = W[w2]["EnKF Q=0"], W[w2]["EnKF Q=1e-4"]
    f["tuned Q gain EnKF with Q=1e-4"] = _mean_over_states(q0) / _mean_over_states(alt)
    f["tuned Q states improved EnKF with Q=1e-4"] = int(sum(q0[s]["mean"] > alt[s]["mean"] for s in STATES))
    for name in ("UKF Q=0", "EnKF Q=0", "KF"):
        f[f"noise growth {name}"] = _mean_over_states(N[str(NOISE_STDS[-1])][name]) / \
            _mean_over_states(N[str(NOISE_STDS[0])][name])
        f[f"random/zigzag {name}"] = _mean_over_states(M["random"][name]) / _mean_over_states(M["zigzag"][name])
    f["KF beats UKF Q=0 at max wind (states)"] = int(sum(W[w2]["KF"][s]["mean"] < W[w2]["UKF Q=0"][s]["mean"]
                                                        for s in STATES))
    f["KF beats EnKF Q=0 at max wind (states)"] = int(sum(W[w2]["KF"][s]["mean"] < W[w2]["EnKF Q=0"][s]["mean"]
                                                         for s in STATES))
    f["KF beats UKF tuned at no wind (states)"] = int(sum(W[w0]["KF"][s]["mean"] < W[w0]["UKF tuned"][s]["mean"]
                                                         for s in STATES))
    f["EnKF/UKF time batch"] = times["EnKF"]["batch_s_per_step"] / times["UKF"]["batch_s_per_step"]
    f["EnKF/UKF time online"] = times["EnKF"]["online_s_per_step"] / times["UKF"]["online_s_per_step"]
    f["all real time (online < 0.1 s)"] = bool(all(v["online_s_per_step"] < DT for v in times.values()))
    return f


def verdicts(f: dict) -> list[tuple[str, str, bool, str]]:
    """``(paper's claim, our numbers, agrees, why it differs)`` for each conclusion of seed 002."""
    w = WIND_MEANS[-1]
    out = [
        ("RMSE grows with the wind modelling error for UKF and EnKF (Q = 0)",
         f"UKF x{f['wind growth UKF Q=0']:.2f}, EnKF x{f['wind growth EnKF Q=0']:.2f} from 0 to {w} m/s",
         f["wind growth UKF Q=0"] > 1.1 and f["wind growth EnKF Q=0"] > 1.1,
         "With a short record the wind has little time to push the ship off the model's track."),
        ("EnKF is hit harder by the modelling error than UKF",
         f"EnKF x{f['wind growth EnKF Q=0']:.2f} vs UKF x{f['wind growth UKF Q=0']:.2f}",
         f["wind growth EnKF Q=0"] > 1.1 * f["wind growth UKF Q=0"],
         "With Q = 0 both filters trust the wind-free model equally: the EnKF's ensemble collapses towards "
         "the model trajectory just as the UKF's covariance does, and the perturbed observations keep only a "
         "little extra spread, so the two grow by similar factors (row above). The paper's stronger EnKF "
         "degradation is not reproduced on this ship."),
        ("Tuned Q improves both filters, the EnKF remarkably, the UKF less",
         f"states improved at {w} m/s: EnKF {f['tuned Q states improved EnKF']}/6 (best x"
         f"{f['tuned Q best gain EnKF']:.1f}), UKF {f['tuned Q states improved UKF']}/6 (best x"
         f"{f['tuned Q best gain UKF']:.1f})",
         f["tuned Q states improved EnKF"] >= 1 and f["tuned Q best gain EnKF"] > f["tuned Q best gain UKF"],
         "The paper's EnKF Q (1e-2 on every state, 100 times the UKF's) lets the ensemble follow the "
         "measurements, which helps where the wind error accumulates (positions, heading) and makes the "
         "velocities nearly as noisy as the raw data. The UKF's much smaller Q (1e-4) absorbs the wind drift "
         "without that cost. Given the UKF's Q, the EnKF improves "
         f"{f['tuned Q states improved EnKF with Q=1e-4']}/6 states (x{f['tuned Q gain EnKF with Q=1e-4']:.2f} "
         "overall, column 'EnKF Q=1e-4'): the difference lies in the choice of Q, not in the filter. The "
         "paper's conclusion that the UKF depends more on an accurate model is not supported by our numbers."),
        ("Observation noise matters less than modelling error",
         f"data noise std 0.05 -> 0.20: UKF x{f['noise growth UKF Q=0']:.2f}, EnKF x{f['noise growth EnKF Q=0']:.2f}; "
         f"wind 0 -> {w} m/s: UKF x{f['wind growth UKF Q=0']:.2f}",
         f["noise growth UKF Q=0"] < f["wind growth UKF Q=0"],
         "The size of the wind error depends on the ship's above-water area and the record length; on a short "
         "record or a ship with little windage the noise dominates."),
        ("Zig-zag or random rudder makes no significant difference",
         f"random / zig-zag: UKF {f['random/zigzag UKF Q=0']:.2f}, EnKF {f['random/zigzag EnKF Q=0']:.2f}, "
         f"KF {f['random/zigzag KF']:.2f}",
         all(0.67 < f[f"random/zigzag {n}"] < 1.5 for n in ("UKF Q=0", "EnKF Q=0")),
         "The random rudder sequence drives the ship to larger rates and drift angles than the zig-zag."),
        ("The KF can beat UKF/EnKF when the modelling error is large, but not otherwise",
         f"KF better than UKF (Q=0) in {f['KF beats UKF Q=0 at max wind (states)']}/6 and than EnKF (Q=0) in "
         f"{f['KF beats EnKF Q=0 at max wind (states)']}/6 states at {w} m/s; better than the tuned UKF in "
         f"{f['KF beats UKF tuned at no wind (states)']}/6 states without wind",
         f["KF beats UKF Q=0 at max wind (states)"] >= 1 and f["KF beats UKF tuned at no wind (states)"] == 0,
         "The persistence KF has no ship model, so it only wins where the model-based filters drift; on a "
         "short record (quick mode) the wind has not yet pushed the ship far enough from the model's track."),
        ("The EnKF (N = 100) takes about four times the UKF's time per step",
         f"batch x{f['EnKF/UKF time batch']:.1f}, online x{f['EnKF/UKF time online']:.1f}",
         2.0 <= f["EnKF/UKF time online"] <= 6.0,
         "casship compiles each filter step into one CasADi function, so the cost follows the number of model "
         "evaluations: 100 ensemble members against 2n + 1 = 13 sigma points (a factor of 7.7) plus the "
         "ensemble's larger covariance products. The paper's factor 4 reflects its own implementation, whose "
         "fixed per-step overhead weighs more."),
        ("All filters run in real time (< 0.1 s per 0.1 s step)",
         f"{'yes' if f['all real time (online < 0.1 s)'] else 'no'}",
         f["all real time (online < 0.1 s)"], "A slow machine or a much larger ensemble."),
    ]
    return out


def _comparison(f: dict) -> str:
    rows = verdicts(f)
    lines = ["## Comparison with the paper's conclusions", "",
             "Ratios are geometric means over the six states of the mean RMSE over the noise seeds (states have "
             "different units), unless a state count is given.", "",
             "| paper (seed 002) | ours | verdict |", "|---|---|---|"]
    lines += [f"| {claim} | {ours} | {'agrees' if ok else 'differs'} |" for claim, ours, ok, _ in rows]
    lines += ["", "### Where ours differ, and why", ""]
    differ = [(claim, why) for claim, _, ok, why in rows if not ok]
    lines += [f"* **{claim}.** {why}" for claim, why in differ] or ["* Nowhere on this run."]
    return "\n".join(lines)


# -- the study -----------------------------------------------------------------------------------------------
def run(out: Path, quick: bool = False, workers=None, scheduler=None) -> dict:
    """Run every experiment, write figures (PNG), tables and ``report.md`` into ``out``."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    cfg = Config.make(quick)
    stages = ["tune the persistence KF", "Monte Carlo (wind, noise, manoeuvre)", "computation time", "MHE column",
              "figures and report"]
    steps = progress(stages, "filter-guidelines")
    t_start = time.perf_counter()

    next(steps)
    q_kf = tune_kf(cfg.duration)

    next(steps)
    cases = _cases(cfg, q_kf)
    results = run_cases(run_case, cases, workers=workers, scheduler=scheduler)
    table = aggregate(results)

    next(steps)
    times = timing(cfg, q_kf)

    next(steps)
    mhe = mhe_column(cfg, q_kf)

    next(steps)
    _fig_wind(out / "fig02_wind.png", cfg.duration)
    _fig_wind_effect(out / "fig03_wind_effect.png", cfg.duration)
    _bars(out / "fig04_rmse_wind.png", table["wind"], ("UKF Q=0", "EnKF Q=0", "KF"), WIND_MEANS,
          [f"{w:g} m/s" for w in WIND_MEANS], "RMSE vs mean wind speed (modelling error), Q = 0")
    _fig_q(out / "fig05_rmse_tuned_q.png", table["wind"][str(WIND_MEANS[-1])])
    _bars(out / "fig06_rmse_noise.png", table["noise"], ("UKF Q=0", "EnKF Q=0", "KF"), NOISE_STDS,
          [f"std {s:g}" for s in NOISE_STDS], "RMSE vs observation noise of the data")
    _fig_maneuvers(out / "fig07_08_maneuvers.png", cfg.duration)
    _bars(out / "fig09_rmse_maneuver.png", table["maneuver"], ("UKF Q=0", "EnKF Q=0", "KF"), ("zigzag", "random"),
          ["zig-zag", "random"], "RMSE for periodic (zig-zag) and aperiodic (random) rudder")
    _bars(out / "fig_extra_ekf.png", table["wind"], ("EKF Q=0", "EKF tuned"), WIND_MEANS,
          [f"{w:g} m/s" for w in WIND_MEANS], "casship EKF (extra column): RMSE vs mean wind speed")
    _fig_time(out / "fig10_time.png", times)
    found = findings(table, times)
    tables = {
        "wind": _table(table["wind"], FILTERS, WIND_MEANS, "mean wind [m/s]"),
        "noise": _table(table["noise"], FILTERS, NOISE_STDS, "noise std"),
        "maneuver": _table(table["maneuver"], FILTERS, ("zigzag", "random"), "rudder"),
    }
    for name, text in tables.items():
        (out / f"table_{name}.md").write_text(text + "\n")
    summary = {"config": cfg.__dict__, "q_kf_tuned": q_kf, "rmse": table, "time_per_step": times, "mhe": mhe,
               "findings": found, "seconds": time.perf_counter() - t_start,
               "verdicts": [{"claim": c, "ours": o, "agrees": bool(ok)} for c, o, ok, _ in verdicts(found)],
               "figures": sorted(p.name for p in out.glob("*.png"))}
    (out / "report.md").write_text(_report(cfg, q_kf, tables, times, mhe, found, summary["seconds"], quick))
    next(steps, None)
    return json.loads(json.dumps(summary, default=float))


def _fig_q(path: Path, cell: dict) -> None:
    _bars(path, {"Q=0": {n: cell[f"{n} Q=0"] for n in ("UKF", "EnKF")},
                 "tuned": {n: cell[f"{n} tuned"] for n in ("UKF", "EnKF")}},
          ("UKF", "EnKF"), ("Q=0", "tuned"), ["Q = 0", "tuned Q"],
          f"RMSE at mean wind {WIND_MEANS[-1]} m/s: Q = 0 vs tuned Q")


def _report(cfg, q_kf, tables, times, mhe, found, seconds, quick) -> str:
    time_rows = "\n".join(f"| {n} | {1e3 * v['batch_s_per_step']:.3f} | {1e3 * v['online_s_per_step']:.3f} |"
                          for n, v in times.items())
    parts = [
        "# Seed 002 reproduced: guidelines for UKF and EnKF in ship state estimation", "",
        __doc__.split("\n\n", 1)[1].split("Run:")[0].strip(), "",
        f"Records of {cfg.duration:g} s at dt = {DT} s; {cfg.seeds} noise seeds per condition"
        + (" (quick mode: numbers are indicative only)." if quick else "."),
        f"Data noise in experiments 1 and 3: std {DATA_STD} on every state; the filters use R = diag({R_FILTER}). "
        "The paper lists R = diag(5e-2) for the filter and 0.05^2 ... 0.20^2 for the data of experiment 2; "
        "it does not say which noise the data of experiments 1 and 3 carry, we take the smallest level.",
        "Persistence KF, Q per state tuned on a separate record: "
        + ", ".join(f"{s}: {q:.1e}" for s, q in q_kf.items()) + ".", "",
        "## 1. Modelling error (wind in the data, not in the filter model)", "",
        "![wind](fig02_wind.png)", "", "![effect](fig03_wind_effect.png)", "",
        tables["wind"], "", "![rmse wind](fig04_rmse_wind.png)", "", "![tuned Q](fig05_rmse_tuned_q.png)", "",
        "![EKF](fig_extra_ekf.png)", "",
        "## 2. Observation noise", "", tables["noise"], "", "![rmse noise](fig06_rmse_noise.png)", "",
        "## 3. Zig-zag vs random rudder", "", "![manoeuvres](fig07_08_maneuvers.png)", "",
        tables["maneuver"], "", "![rmse manoeuvre](fig09_rmse_maneuver.png)", "",
        "## 4. Computation time per 0.1 s step", "",
        "| filter | batch [ms/step] | online [ms/step] |", "|---|---|---|", time_rows, "",
        "![time](fig10_time.png)", "",
    ]
    if mhe:
        parts += ["## Extra column: moving-horizon estimation (MHE, real-time iteration)", "",
                  f"One seed, first {cfg.mhe_duration:g} s of the wind records, horizon {cfg.mhe_horizon} steps, "
                  "tuned Q; the UKF (tuned) on the same shortened record for reference.", "",
                  "| mean wind [m/s] | MHE RMSE x, u, y, v, psi, r | UKF tuned, same record | MHE ms/step |",
                  "|---|---|---|---|"]
        for w, r in mhe.items():
            if "error" in r:
                parts.append(f"| {w} | failed: {r['error']} | - | - |")
                continue
            fmt = lambda d: ", ".join(f"{d[s]:.3g}" for s in STATES)  # noqa: E731
            parts.append(f"| {w} | {fmt(r['rmse'])} | {fmt(r['ukf_same_record'])} | {1e3 * r['s_per_step']:.1f} |")
        parts.append("")
    parts += [_comparison(found), "", WHY, "", f"Run time: {seconds:.0f} s.", ""]
    return "\n".join(parts)


WHY = """### What is not the paper's

* **The ship and the wind record.** The paper's ship particulars, hull coefficients and its measured
  wind record (Inukai Pond, 10 June 2021) are not in the text; we use casship's twin-rudder low-speed
  preset (Esso Osaka 3 m hull coefficients, assumed propeller, rudder and above-water geometry) and a
  synthetic gust record with the paper's mean speeds. Every wind-related ratio depends on the ratio of
  wind to hydrodynamic forces of the particular ship, and on the record length.
* **Q = 0 without wind is an exact model**: the filter model is the data-generating model, so the UKF,
  EnKF and EKF converge on the true trajectory and their RMSE falls well below the measurement noise;
  the persistence KF cannot do that.
* **The data noise of experiments 1 and 3** is not stated in the paper; we use the smallest level of
  experiment 2 (std 0.05) and keep the filters' R = diag(5e-2) of the paper throughout."""


STUDY = Study("filter-guidelines", "Seed 002: UKF/EnKF/KF guidelines (modelling error, noise, manoeuvre, time)",
              run)
