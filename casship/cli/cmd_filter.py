"""``casship filter DATA.csv``: run a state estimator (and optionally the RTS smoother) over a record.

Examples::

    casship filter ../shared/data/usv_fuzhou_gnss/zigzag_30_inter_xy.csv --preset usv-gnss \\
        --model sog-cog --estimator ekf --smooth --out est.csv --plot est.png
    casship filter trial.csv --model nomoto1 --estimator ukf --measured psi --R psi=1e-4 --Q 1e-8 \\
        --columns psi=heading:deg,delta=rudder:deg --time time:s --out est.csv

Estimators are looked up by name in :data:`casship.estimators.ESTIMATORS` (``kf``, ``ekf``,
``ukf``, ``enkf``, ``kalman-bucy``, and any that other modules register there).
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from ._common import add_limits_option, add_model_option, add_overwrite_option, load_model, require

PRESETS = {
    "usv-gnss": {
        "doc": "USV GNSS logs (time [s], lat/lon [deg]): lat/lon in rad and local x_n, y_n [m]; "
               "the log's own speed/heading kept as log_speed, log_heading for comparison",
        "time": "time:s",
        "columns": {"lat": "lat:deg", "lon": "lon:deg", "log_speed": "speed:kn", "log_heading": "heading:deg"},
        "latlon": ("lat", "lon"),
        # chosen so that the NIS per measurement is about 1 on the 30 deg zig-zag log (resampled 2 Hz,
        # 1e-6 deg position resolution); the log's 'speed' column is in knots (it matches the
        # speed over ground of the positions only as kn)
        "gnss_std_m": 0.1,
        "Q": {"w_U": 0.004, "w_chi": 0.001},
    },
}


#: One-line description (the command list of ``casship --help``).
HELP = "run a state estimator (and smoother) over a record"


def _positive(text: str) -> float:
    """argparse type: a positive finite number."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not np.isfinite(value) or value <= 0:
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text}")
    return value


def register(sub) -> None:
    p = sub.add_parser("filter", help=HELP,
                       description="Estimate the states of a registered model from a record (CSV, MARIN .dat, "
                                   "NMEA log) with a KF, EKF, UKF, EnKF, Kalman-Bucy filter or MHE; write "
                                   "estimates and standard deviations (CSV) and a plot.\n\n"
                                   + __doc__.split("\n\n", 1)[1].split("\n\nEstimators")[0])
    p.add_argument("data", nargs="?", default=None,
                   help="record: CSV with a header row, MARIN .dat, NMEA log (see casship.io.read_record)")
    add_model_option(p)
    p.add_argument("--estimator", default="ekf", help="estimator name (see --list)")
    p.add_argument("--list", action="store_true", help="list the estimators and presets and exit")
    p.add_argument("--smooth", action="store_true",
                   help="smooth instead of filter (est.smooth: RTS for the Kalman filters, full information for mhe)")
    p.add_argument("--preset", default=None, choices=sorted(PRESETS), help="column/noise preset")
    p.add_argument("--columns", default=None,
                   help="NEW=SOURCE[:UNIT],... CSV columns to read and convert to SI (e.g. psi=heading:deg); "
                        "default: all columns as they are")
    p.add_argument("--time", default=None, help="CSV time column and unit (default t:s, or the preset's)")
    p.add_argument("--latlon", default=None, help="LAT,LON: geodetic columns (rad after conversion) that "
                                                  "also give local x_n, y_n [m]")
    p.add_argument("--measured", default=None, help="measured outputs a,b (default: outputs present in the data)")
    p.add_argument("--R", default=None, help="measurement variances: scalar or name=value,... (SI units); "
                                             "required unless --R-std or a preset gives them")
    p.add_argument("--R-std", dest="R_std", default=None, help="measurement standard deviations, as --R")
    p.add_argument("--Q", default=None, help="process-noise variances: scalar or name=value,...; required "
                                             "unless a preset gives them or the model has no noise channels")
    p.add_argument("--x0", default=None, help="initial state name=value,... (default: first measurement of "
                                              "directly measured states, else 0)")
    p.add_argument("--P0", default=None, help="initial variances: scalar or name=value,... (default 1, R for "
                                              "measured states)")
    p.add_argument("--dt", type=_positive, default=None,
                   help="nominal filter step [s] (default: median data step)")
    p.add_argument("--rate", type=_positive, default=None,
                   help="run the filter at RATE Hz (not below the data rate), inserting prediction-only rows "
                        "between the samples (Dataset.resample)")
    p.add_argument("--method", default="euler", choices=("euler", "rk4"), help="discretisation")
    p.add_argument("--options", default=None, help="estimator options key=value,... (e.g. gate=0.999,members=100)")
    p.add_argument("--seed", type=int, default=0, help="seed of stochastic estimators (EnKF)")
    p.add_argument("--out", default=None, help="CSV of estimates and standard deviations")
    p.add_argument("--plot", default=None, help="PNG plot of the estimates with 2-sigma bands")
    p.add_argument("--json", action="store_true", help="print a JSON summary")
    add_overwrite_option(p)
    add_limits_option(p)
    p.set_defaults(func=run, parser=p)


# -- argument parsing helpers --------------------------------------------------------------------
def _pairs(text: str | None, what: str) -> dict[str, str]:
    if not text:
        return {}
    out = {}
    for item in text.split(","):
        key, sep, value = item.partition("=")
        if not sep or not key.strip() or not value.strip():
            raise ValueError(f"{what}: expected name=value items, got {item!r}")
        out[key.strip()] = value.strip()
    return out


def _number(value: str, what: str) -> float:
    try:
        return float(value)
    except ValueError:
        raise ValueError(f"{what}: {value!r} is not a number") from None


def _variances(text: str | None, names, what: str, default=None):
    """Scalar or name=value list -> a dict over ``names`` (missing names take ``default``)."""
    if text is None:
        return default
    text = text.strip()
    if "=" not in text:
        return _number(text, what)
    pairs = {k: _number(v, f"{what} {k}") for k, v in _pairs(text, what).items()}
    unknown = set(pairs) - set(names)
    if unknown:
        raise ValueError(f"{what}: unknown name(s) {sorted(unknown)}; known: {list(names)}")
    if isinstance(default, dict):
        return {**default, **pairs}
    missing = [n for n in names if n not in pairs]
    if missing:
        raise ValueError(f"{what}: no value for {missing}")
    return pairs


def _option_value(text: str):
    for conv in (int, float):
        try:
            return conv(text)
        except ValueError:
            pass
    return {"true": True, "false": False, "none": None}.get(text.lower(), text)


# -- the command ----------------------------------------------------------------------------------
def run(args) -> int:
    from ..estimators import ESTIMATORS
    from ..outdir import check_output_file

    if args.list:
        for name, cls in ESTIMATORS.items():
            print(f"{name:14s} {cls.__name__}")
        for name, preset in PRESETS.items():
            print(f"preset {name:8s} {preset['doc']}")
        return 0
    require(args.parser, args, {"DATA": args.data, "--model": args.model})
    model = load_model(args.model)
    preset = PRESETS.get(args.preset, {})
    missing = []
    if args.R is None and args.R_std is None and "gnss_std_m" not in preset:
        missing.append("--R (or --R-std)")
    if args.Q is None and model.nw and not set(preset.get("Q", {})) & set(model.noise_names):
        missing.append(f"--Q (for {', '.join(model.noise_names)})")
    require(args.parser, args, {name: None for name in missing})
    if args.estimator not in ESTIMATORS:
        raise ValueError(f"--estimator: unknown estimator {args.estimator!r}; known: {sorted(ESTIMATORS)}")
    for option, path in (("--out", args.out), ("--plot", args.plot)):
        if path:
            check_output_file(path, overwrite=args.overwrite, what=option)
    summary, result, data, meas = filter_file(args, model)
    if args.out:
        result.to_dataset().to_csv(args.out)
        summary["out"] = str(args.out)
    if args.plot:
        plot_result(result, data, meas, args.plot)
        summary["plot"] = str(args.plot)
    if args.json:
        print(json.dumps(summary, indent=2, default=float))
    else:
        for key, value in summary.items():
            print(f"{key}: {value}")
    return 0


def load_data(args):
    """The record as a Dataset in SI units (any format of :func:`casship.io.read_record`; for CSV also
    the preset, ``--columns``, ``--time``, ``--latlon``)."""
    from ..io import read_csv, read_record

    path = Path(args.data)
    preset = {}
    if args.preset:
        if args.preset not in PRESETS:
            raise ValueError(f"unknown preset {args.preset!r}; known: {sorted(PRESETS)}")
        preset = PRESETS[args.preset]
    columns = dict(preset.get("columns", {}))
    columns.update(_pairs(args.columns, "--columns"))
    latlon = tuple(args.latlon.split(",")) if args.latlon else preset.get("latlon")
    if latlon is not None and len(latlon) != 2:
        raise ValueError(f"--latlon: expected LAT,LON, got {args.latlon!r}")
    time = args.time or preset.get("time")
    if not columns and time is None and latlon is None:
        return read_record(path), preset
    if not path.is_file():
        raise FileNotFoundError(f"data file {path}: no such file")
    return read_csv(path, columns or None, time=time or "t:s", latlon=latlon), preset


def _initial_velocity(data, names):
    """Speed and course from a straight-line fit of the first few seconds of positions."""
    xn, yn = data[names[0]], data[names[1]]
    ok = np.flatnonzero(np.isfinite(xn) & np.isfinite(yn))
    ok = ok[data.t[ok] <= data.t[ok[0]] + 5.0] if ok.size else ok
    if ok.size < 3:
        return 0.0, 0.0
    vx = np.polyfit(data.t[ok], xn[ok], 1)[0]
    vy = np.polyfit(data.t[ok], yn[ok], 1)[0]
    return float(np.hypot(vx, vy)), float(np.arctan2(vy, vx))


def filter_file(args, model=None):
    """Run the command's estimation; returns ``(summary, result, data, measured)``."""
    from ..gaussian import Gaussian
    from ..discretize import discretize
    from ..estimators import ESTIMATORS
    from ..frames import wgs84_radii
    from ..validity import check_inputs, check_step

    data, preset = load_data(args)
    model = model if model is not None else load_model(args.model)
    if args.measured:
        meas = tuple(s.strip() for s in args.measured.split(","))
    else:
        meas = tuple(n for n in model.output_names if n in data)
        if not meas:
            raise ValueError(f"the data have none of the outputs {list(model.output_names)} of model "
                             f"{args.model!r}; columns: {list(data.names)} (use --columns or --measured)")
    missing = [n for n in (*model.input_names, *meas) if n not in data]
    if missing:
        raise ValueError(f"the data have no column(s) {missing} needed by model {args.model!r}; "
                         f"columns: {list(data.names)} (use --columns)")
    if args.rate:
        try:
            data = data.resample(args.rate, hold=model.input_names)
        except ValueError as exc:
            raise ValueError(f"--rate: {exc}") from None
    if len(data) < 2:
        raise ValueError(f"data {args.data}: {len(data)} row(s); a filter run needs at least two")
    dt = args.dt or float(np.median(np.diff(data.t)))
    dm = discretize(model, dt, method=args.method)

    # measurement covariance: --R / --R-std, else the preset's GNSS accuracy
    R = _variances(args.R, meas, "--R")
    if args.R_std is not None:
        if R is not None:
            raise ValueError("give --R or --R-std, not both")
        std = _variances(args.R_std, meas, "--R-std")
        R = {k: v**2 for k, v in std.items()} if isinstance(std, dict) else std**2
    if R is None and "gnss_std_m" in preset:
        s = preset["gnss_std_m"]
        lat0 = float(np.nanmedian(data["lat"])) if "lat" in data else 0.0
        r_n, r_m = wgs84_radii(lat0)
        per = {"x_n": s**2, "y_n": s**2, "lat": (s / r_m) ** 2, "lon": (s / (r_n * np.cos(lat0))) ** 2}
        if all(n in per for n in meas):
            R = {n: per[n] for n in meas}
    if R is None:
        raise ValueError("give the measurement variances with --R or --R-std")
    Q = _variances(args.Q, model.noise_names, "--Q")
    if Q is None:
        pq = preset.get("Q", {})
        Q = {n: pq.get(n, 0.0) for n in model.noise_names} if set(pq) & set(model.noise_names) else 0.0
        if Q == 0.0 and model.nw:
            raise ValueError(f"give the process-noise variances with --Q for {list(model.noise_names)}")
    options = {k: _option_value(v) for k, v in _pairs(args.options, "--options").items()}
    cls = ESTIMATORS[args.estimator]
    est = cls(dm, Q, R, measured=meas, options=options)

    # prior: directly measured states from the first sample, given values, else 0
    x0 = model.states()
    Rm = est.R
    P0 = np.ones(model.nx)
    for j, name in enumerate(meas):
        if name in model.state_names:
            col = data[name]
            ok = np.flatnonzero(np.isfinite(col))
            if ok.size:
                i = model.index(name)
                x0[i], P0[i] = col[ok[0]], Rm[j, j]
    if {"U", "chi"} <= set(model.state_names):
        pos = ("x_n", "y_n") if "x_n" in data else None
        if pos is not None:
            U0, chi0 = _initial_velocity(data, pos)
            x0[model.index("U")], x0[model.index("chi")] = U0, chi0
            P0[model.index("U")], P0[model.index("chi")] = 0.25, np.deg2rad(20.0) ** 2
    if "omega_chi" in model.state_names:
        P0[model.index("omega_chi")] = 0.01
    for k, v in _pairs(args.x0, "--x0").items():
        x0[model.index(k)] = _number(v, f"--x0 {k}")
    P0v = _variances(args.P0, model.state_names, "--P0", default=None)
    if isinstance(P0v, dict):
        for k, v in P0v.items():
            P0[model.index(k)] = v
    elif P0v is not None:
        P0[:] = P0v
    prior = Gaussian(x0, P0)
    if not args.allow_out_of_range:
        U = data.matrix(model.input_names, finite=True, what="input")
        check_inputs(model, U, data.t)
        k = int(np.argmax(data.dt))
        check_step(model, float(data.dt[k]), x0, U[0] if model.nu else np.zeros(0), model.params(),
                   args.method, where=f" (the data step from t = {data.t[k]:g} to {data.t[k + 1]:g} s)")
    result = (est.smooth if args.smooth else est.filter)(data, prior, seed=args.seed)
    health = result.health()
    summary = {"model": args.model, "estimator": result.estimator, "rows": len(data), "dt_s": dt,
               "measured": list(meas), "updates": int((result.n_measured > 0).sum()),
               "rejected": int(result.rejected.sum()), "loglik": result.loglik, "health_ok": health.ok}
    for name in ("U", "chi"):
        if name in model.state_names:
            summary[f"final_{name}"] = float(result[name][-1])
    if "log_speed" in data and "U" in model.state_names:
        ok = np.isfinite(data["log_speed"])
        summary["rmse_U_vs_log_speed"] = float(np.sqrt(np.mean((result["U"][ok] - data["log_speed"][ok]) ** 2)))
    return summary, result, data, meas


def plot_result(result, data, measured, path) -> Path:
    """Estimates with 2-sigma bands, one panel per state, measurements overlaid where they are states."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = result.state_names
    fig, axes = plt.subplots(len(names), 1, figsize=(8, 1.9 * len(names)), sharex=True, squeeze=False)
    std = result.std
    for i, (ax, name) in enumerate(zip(axes[:, 0], names)):
        x = result.x[:, i]
        if result.angle_states is not None and result.angle_states[i]:
            x = np.unwrap(x)
        ax.fill_between(result.t, x - 2 * std[:, i], x + 2 * std[:, i], color="C0", alpha=0.25, lw=0)
        ax.plot(result.t, x, "C0", lw=1.2, label=result.estimator)
        if name in measured:
            ax.plot(data.t, data[name], ".", color="C1", ms=2, label="measured")
        if name == "U" and "log_speed" in data:
            ax.plot(data.t, data["log_speed"], "C2", lw=0.8, label="log speed")
        if name == "chi" and "log_heading" in data:
            ax.plot(data.t, np.unwrap(data["log_heading"]), "C2", lw=0.8, label="log heading")
        ax.set_ylabel(name)
        ax.grid(alpha=0.3)
    axes[0, 0].legend(loc="best", fontsize=8)
    axes[-1, 0].set_xlabel("t [s]")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)
