"""``casship filter DATA --model NAME``: run a state estimator (and optionally the RTS smoother) over a record.

Examples::

    casship filter ../shared/data/kvlcc2_marin_free/MARIN_FREE_KVLCC2_zz_10_m.dat --model kvlcc2 --measured x,y,psi
    casship identify ../shared/data/usv_fuzhou_gnss/zigzag_30_inter_xy.csv --preset usv-gnss \\
        --model sog-cog-latlon --free alpha1,alpha2 --estimate-noise Q --out usv.json
    casship filter ../shared/data/usv_fuzhou_gnss/zigzag_30_inter_xy.csv --preset usv-gnss \\
        --model sog-cog-latlon --params usv.json --smooth --out est.csv --plot est.png
    casship filter trial.csv --model nomoto1 --estimator ukf --measured psi --R psi=1e-4 --Q 1e-8 \\
        --columns psi=heading:deg,delta=rudder:deg --time time:s --out est.csv

What is not given is taken from the record (or the ``--params`` fit file), and the output says
where each value came from: the measurement variances ``R`` estimated from the record
(:func:`casship.identify.noise_std`), the starting state by :func:`casship.prior_from_data` (first
samples, speed and course from the track), ``Q`` at :data:`DEFAULT_Q` per noise channel (a default,
not a tuning: compare the NIS per measurement in the output with 1). The first example says so
itself: with the default ``Q`` the published KVLCC2 model's error over the measured 10/10 zig-zag is
far larger than the process noise allows (NIS per measurement about 180, a warning that the
estimates are not to be trusted; ``--Q w_u=1e-4,w_v=1e-4,w_r=1e-8`` brings it to about 2). The USV
example shows the remedy: without ``--params`` its NIS per measurement is about 1400 (the default ``Q`` is far too
small for a small craft's manoeuvres; the output says the estimates are not to be trusted);
``identify --estimate-noise Q`` on the same log (the same record options) estimates ``Q`` (R stays
at the record's estimate, as here), and the filter with that fit file has a NIS per measurement
near 1. A run that diverges (a non-finite estimate or log-likelihood) is an error.

Estimators are looked up by name in :data:`casship.estimators.ESTIMATORS` (``kf``, ``ekf``,
``ukf``, ``enkf``, ``kalman-bucy``, ``mhe``, and any that other modules register there).
"""
from __future__ import annotations

import warnings

from ._vocabulary import add_deprecated_alias
from ._common import (RECORD_PRESETS, add_limits_option, add_model_option, add_overwrite_option, add_record_options,
                      check_outputs, load_model, parse_items, parse_pairs, positive, print_json, read_records, require,
                      seed, write_output)

#: Variance of each process-noise channel when ``--Q`` is not given (in the channel's units squared).
DEFAULT_Q = 1e-8

#: The column presets of ``--preset`` (shared by every command that reads records).
PRESETS = RECORD_PRESETS

#: One-line description (the command list of ``casship --help``).
HELP = "run a state estimator (and smoother) over a record"


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
    add_record_options(p)
    p.add_argument("--params", default=None,
                   help="fit file (casship identify): its model variant and parameters, and its noise variances Q "
                        "and R where --Q / --R are not given")
    p.add_argument("--measured", default=None, help="measured outputs a,b (default: outputs present in the data)")
    p.add_argument("--R", default=None, help="measurement variances: scalar or name=value,... (SI units); "
                                             "channels not given: from --params, else estimated from the record")
    p.add_argument("--R-std", dest="R_std", default=None, help="measurement standard deviations, as --R")
    p.add_argument("--Q", default=None, help=f"process-noise variances: scalar or name=value,... (channels not "
                                             f"given: from --params, else {DEFAULT_Q:g})")
    p.add_argument("--x0", default=None, help="initial state name=value,... (default: from the record, see "
                                              "casship.prior_from_data)")
    p.add_argument("--P0", default=None, help="initial variances: scalar or name=value,... (default 1, R for "
                                              "measured states)")
    p.add_argument("--dt", type=positive, default=None,
                   help="nominal step [s] of the continuous-time kalman-bucy filter (Qc = Q dt; default: the "
                        "median data step); the other estimators step at the record's time stamps")
    p.add_argument("--rate", type=positive, default=None,
                   help="run the filter at RATE Hz (not below the data rate), inserting prediction-only rows "
                        "between the samples (Dataset.resample)")
    p.add_argument("--integrator", dest="method", default="euler", choices=("euler", "rk4"),
                   help="how the model's equations are integrated in time (the filter's discretisation)")
    add_deprecated_alias(p, "--method", "--integrator", dest="method", choices=("euler", "rk4"))
    p.add_argument("--options", default=None, help="estimator options key=value,... (e.g. gate=0.999,members=100)")
    p.add_argument("--seed", type=seed, default=0, help="seed of stochastic estimators (EnKF)")
    p.add_argument("--out", default=None, help="CSV of estimates and standard deviations")
    p.add_argument("--plot", default=None, help="figure (.png, .pdf or .svg) of the estimates with 2-sigma bands")
    p.add_argument("--json", action="store_true", help="print a JSON summary")
    add_overwrite_option(p)
    add_limits_option(p)
    p.set_defaults(func=run, parser=p)


# -- argument parsing helpers --------------------------------------------------------------------
def _variances(text: str | None, names, what: str, *, every: bool = True):
    """Scalar or name=value list -> a number or a dict over ``names`` (with ``every``, every name needs a value)."""
    from ._common import number

    if text is None:
        return None
    text = text.strip()
    if "=" not in text:
        return number(text, what)
    pairs = parse_pairs(text, what, names=names)
    missing = [n for n in names if n not in pairs]
    if missing and every:
        from ..errors import InputError

        raise InputError(f"{what}: no value for {missing}")
    return pairs


def record_noise(model, data, names, option: str = "--R NAME=VARIANCE (or --R-std NAME=STD)"):
    """:func:`casship.estimators.noise_from_data` channel by channel, an error naming the channel, the option that
    gives its noise instead and the remedy of leaving it unmeasured.

    Parameters
    ----------
    model : Model
    data : Dataset
    names : sequence of str
        The measured channels.
    option : str
        How the command takes a channel's noise (``NAME`` is replaced by the channel).

    Returns
    -------
    (dict, dict)
        Channel -> variance, channel -> how it was found.
    """
    from ..errors import InputError
    from ..estimators import noise_from_data

    R, how = {}, {}
    for n in names:
        try:
            var, text = noise_from_data(model, data, [n])
        except InputError as exc:
            if n not in data or n not in model.output_names:       # its own message names the unknown column
                raise
            raise InputError(f"{exc} with {option.replace('NAME', n)}, or leave {n!r} out of --measured") from None
        R[n], how[n] = var[n], text[n]
    return R, how


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

    if args.list:
        for name, cls in ESTIMATORS.items():
            print(f"{name:14s} {cls.__name__}")
        for name, preset in PRESETS.items():
            print(f"preset {name:8s} {preset['doc']}")
        return 0
    require(args.parser, args, {"DATA": args.data, "--model": args.model})
    if args.dt is not None and args.estimator != "kalman-bucy":
        args.parser.error("--dt would have no effect: the filter steps at the record's time stamps (use --rate to "
                          "run it faster); --dt is the nominal step of --estimator kalman-bucy")
    if args.estimator not in ESTIMATORS:
        from ..errors import InputError

        raise InputError(f"--estimator: unknown estimator {args.estimator!r}; known: {sorted(ESTIMATORS)}")
    if args.R is not None and args.R_std is not None:
        args.parser.error("give --R or --R-std, not both")
    stamps = check_outputs({"--out": args.out, "--plot": args.plot}, overwrite=args.overwrite)
    model = load_model(args.model)
    summary, result, data, meas = filter_file(args, model)
    if args.out:
        write_output(args.out, lambda tmp: result.to_dataset().to_csv(tmp), option="--out",
                     overwrite=args.overwrite, stamps=stamps)
        summary["out"] = str(args.out)
    if args.plot:
        overlay = {n: data[n] for n in meas if n in result.state_names}
        write_output(args.plot, lambda tmp: result.plot(tmp, measured=overlay, t_measured=data.t), option="--plot",
                     overwrite=args.overwrite, stamps=stamps)
        summary["plot"] = str(args.plot)
    if args.json:
        print_json(summary)
    else:
        for key, value in summary.items():
            if isinstance(value, dict):
                print(f"{key}:")
                for k, v in value.items():
                    print(f"  {k}: {v}")
            else:
                print(f"{key}: {value}")
    return 0


def load_data(args, model=None):
    """The record as a Dataset in SI units (any format of :func:`casship.io.read_record`; for CSV also
    the preset, ``--columns``, ``--time``, ``--latlon``: :func:`casship.cli._common.read_records`); the
    model's angle columns checked for degrees and wrapped."""
    return read_records(args, [args.data], model)[0]


def filter_file(args, model=None):
    """Run the command's estimation; returns ``(summary, result, data, measured)``."""
    import numpy as np

    from ..discretize import discretize
    from ..errors import InputError
    from ..estimators import ESTIMATORS, prior_from_data
    from ..simulation import check_inputs, check_states, check_step

    params = None
    fit_noise = {}
    if getattr(args, "params", None):
        from ..identify import read_params
        from ..identify.params_file import load_fit_json
        from ._common import check_input_files

        check_input_files({"--params": args.params})
        model, params = read_params(args.params, args.model)     # the fitted variant, checked against the file
        fit_noise = load_fit_json(args.params).get("noise") or {}
    model = model if model is not None else load_model(args.model)
    data = load_data(args, model)
    if args.measured is not None:
        meas = tuple(parse_items(args.measured, "--measured"))
        if not meas:
            raise InputError("--measured: no output named (give a,b or leave the option out for the outputs in the data)")
        unknown = [n for n in meas if n not in model.output_names]
        if unknown:
            raise InputError(f"--measured: {unknown} not output(s) of model {model.name!r}; its outputs: "
                             f"{list(model.output_names)}")
    else:
        meas = tuple(n for n in model.output_names if n in data)
        if not meas:
            raise InputError(f"the data have none of the outputs {list(model.output_names)} of model "
                             f"{args.model!r}; columns: {list(data.names)} (use --columns or --measured)")
    missing = [n for n in (*model.input_names, *meas) if n not in data]
    if missing:
        raise InputError(f"the data have no column(s) {missing} needed by model {args.model!r}; "
                         f"columns: {list(data.names)} (use --columns)")
    if args.rate:
        try:
            data = data.resample(args.rate, hold=model.input_names)
        except ValueError as exc:
            raise InputError(f"--rate: {exc}") from None
    if len(data) < 2:
        raise InputError(f"data {args.data}: {len(data)} row(s); a filter run needs at least two")
    dt = args.dt or float(np.median(np.diff(data.t)))
    dm = discretize(model, dt, method=args.method)
    sources = {}

    # measurement covariance: --R / --R-std (any channels), the rest from the fit file or the record
    R = _variances(args.R, meas, "--R", every=False)
    given = "--R"
    if args.R_std is not None:
        std = _variances(args.R_std, meas, "--R-std", every=False)
        bad = {k: v for k, v in (std.items() if isinstance(std, dict) else [("all", std)]) if v <= 0}
        if bad:
            raise InputError(f"--R-std: a standard deviation must be positive, got {bad}")
        R = {k: v**2 for k, v in std.items()} if isinstance(std, dict) else std**2
        given = "--R-std"
    source = f"given ({given})"
    if isinstance(R, dict) and set(R) != set(meas):
        rest = [n for n in meas if n not in R]
        if isinstance(fit_noise.get("R"), dict) and set(rest) <= set(fit_noise["R"]):
            R.update({n: float(fit_noise["R"][n]) for n in rest})
            source = f"given ({given}) for {sorted(set(meas) - set(rest))}, from the fit file {args.params} for {rest}"
        else:
            more, how = record_noise(model, data, rest)
            R.update(more)
            source = (f"given ({given}) for {sorted(set(meas) - set(rest))}, estimated from the record: "
                      + ", ".join(f"{n} std {np.sqrt(v):.3g} ({how[n]})" for n, v in more.items()))
        R = {n: R[n] for n in meas}
    if R is None and isinstance(fit_noise.get("R"), dict) and set(meas) <= set(fit_noise["R"]):
        R = {n: float(fit_noise["R"][n]) for n in meas}
        source = f"from the fit file {args.params}"
    if R is None:
        R, how = record_noise(model, data, meas)
        source = "estimated from the record: " + ", ".join(f"{n} std {np.sqrt(v):.3g} ({how[n]})" for n, v in R.items())
    sources["R"] = source
    Q = _variances(args.Q, model.noise_names, "--Q", every=False)
    sources["Q"] = "given (--Q)"
    fit_q = fit_noise.get("Q") if isinstance(fit_noise.get("Q"), dict) and set(fit_noise["Q"]) <= set(model.noise_names) \
        else {}
    if isinstance(Q, dict) and set(Q) != set(model.noise_names):
        rest = [n for n in model.noise_names if n not in Q]
        Q = {n: float(Q[n]) if n in Q else float(fit_q.get(n, DEFAULT_Q)) for n in model.noise_names}
        sources["Q"] = (f"given (--Q) for {sorted(set(model.noise_names) - set(rest))}; "
                        + ", ".join(f"{n} {Q[n]:g} ({'the fit file' if n in fit_q else 'default'})" for n in rest))
    if Q is None and fit_q:
        Q = {n: float(fit_q.get(n, DEFAULT_Q)) for n in model.noise_names}
        sources["Q"] = f"from the fit file {args.params}" + (f" ({DEFAULT_Q:g} for the channels it did not estimate)"
                                                            if set(fit_q) != set(model.noise_names) else "")
    if Q is None:
        Q = DEFAULT_Q
        sources["Q"] = (f"default {DEFAULT_Q:g} per channel {list(model.noise_names)} (not tuned: compare the NIS "
                        "per measurement with 1, or estimate Q with casship identify --estimate-noise Q and give "
                        "the fit file here with --params)") \
            if model.nw else "none (no noise channels)"
    options = {k: _option_value(v) for k, v in parse_pairs(args.options, "--options", numbers=False).items()}
    est = ESTIMATORS[args.estimator](dm, Q, R, measured=meas, options=options)

    x0 = parse_pairs(args.x0, "--x0", names=model.state_names)
    prior = prior_from_data(model, data, measured=meas, R=est.R, x0=x0)
    P0 = _variances(args.P0, model.state_names, "--P0", every=False)     # the others keep their default
    if P0 is not None:
        negative = {k: v for k, v in (P0.items() if isinstance(P0, dict) else [("all", P0)]) if v < 0}
        if negative:
            raise InputError(f"--P0: a variance must be non-negative, got {negative}")
        var = np.diag(prior.cov).copy()
        if isinstance(P0, dict):
            var[[model.index(k) for k in P0]] = list(P0.values())
        else:
            var[:] = P0
        prior = type(prior)(prior.mean, var, names=prior.names, sources=prior.sources)
    if not args.allow_out_of_range:
        U = data.matrix(model.input_names, finite=True, what="input")
        check_inputs(model, U, data.t)
        check_states(model, prior.mean, what="starting state (--x0 or the record)")
        # the record's own step; a longer interval (a gap) is the estimator's to refuse or bridge
        # (option on_gap), checked at the state where it happens
        check_step(model, float(np.median(data.dt)), prior.mean, U[0] if model.nu else np.zeros(0),
                   model.params() if params is None else params,
                   args.method, where=" (the median step of the record)")
    _check_start(est, prior, data)
    result = (est.smooth if args.smooth else est.filter)(data, prior, params, seed=args.seed)
    _check_finite(result)
    n_meas = result.n_measured.sum()
    nis = float(np.nansum(result.nis) / n_meas) if n_meas else float("nan")
    if n_meas and not 0.2 <= nis <= 5.0:
        warnings.warn(f"the NIS per measurement is {nis:.3g} (about 1 when Q and R describe the record): the "
                      f"estimates and their standard deviations are not to be trusted as they are; R: {sources['R']}; "
                      f"Q: {sources['Q']}", UserWarning, stacklevel=2)
    health = result.health()
    summary = {"model": args.model, "estimator": result.estimator, "rows": len(data), "dt_s": dt, "measured": list(meas),
               "updates": int((result.n_measured > 0).sum()), "rejected": int(result.rejected.sum()),
               "loglik": result.loglik, "nis_per_measurement": nis, "health_ok": health.ok,
               "R": sources["R"], "Q": sources["Q"],
               "prior": {n: f"{m:.6g} +- {s:.3g} ({prior.sources[n]})" for n, m, s in
                         zip(model.state_names, prior.mean, prior.std)}}
    for name in ("U", "chi"):
        if name in model.state_names:
            summary[f"final_{name}"] = float(result[name][-1])
    if "log_speed" in data and "U" in model.state_names:
        ok = np.isfinite(data["log_speed"])
        summary["rmse_U_vs_log_speed"] = float(np.sqrt(np.mean((result["U"][ok] - data["log_speed"][ok]) ** 2)))
    return summary, result, data, meas


def _check_start(est, prior, data) -> None:
    """The model must be finite at the start: name the states to give with --x0."""
    from ..simulation import check_start

    m = est.model
    check_start(m, prior.mean, data.matrix(m.input_names)[0] if m.nu else [], m.params(), what="the starting state",
                unset=prior.defaulted(), option="--x0")


def _check_finite(result) -> None:
    """A run with a non-finite estimate or log-likelihood is an error, never a result."""
    import numpy as np

    from ..errors import SolverError

    bad = np.argwhere(~np.isfinite(result.x))
    if bad.size:
        k, i = bad[0]
        raise SolverError(f"the estimate of {result.state_names[i]!r} is not finite from row {k} (t = "
                          f"{result.t[k]:g} s): the filter diverged; check the starting state (--x0) and its variances (--P0: "
                          "1 for a state not measured), R, Q and the record")
    if not np.isfinite(result.loglik):
        k = int(np.flatnonzero(~np.isfinite(result.loglik_terms))[0])
        raise SolverError(f"the log-likelihood is not finite (first at row {k}, t = {result.t[k]:g} s): the filter "
                          "diverged; check the starting state (--x0) and its variances (--P0), R, Q and the record")
