"""``casship identify DATA... --model NAME --free P1,P2``: fit model parameters to one or many records.

Examples::

    casship identify run1.csv run2.csv --model nomoto1 --free K,T --R psi=1e-4 --out fit.json
    casship identify log.csv --model nomoto1 --free K,T --columns psi=heading:deg,delta=rudder:deg --time time:s
    casship identify ../shared/data/usv_fuzhou_gnss/zigzag_30_inter_xy.csv --preset usv-gnss \\
        --model sog-cog-latlon --free alpha1,alpha2 --estimate-noise Q --out usv.json
    casship identify A.dat B.dat C.dat --model kvlcc2 --objective oe --free N_r_dash,Y_v_dash,bias[n] \\
        --share bias[n]=record --prior-std N_r_dash=0.01,Y_v_dash=0.05 --measured u,v,r,psi --decimate 20 \\
        --identifiability --out fit.json --plot fit.png
    casship simulate --model kvlcc2 --params fit.json --inputs ../shared/data/kvlcc2_marin_free/MARIN_FREE_KVLCC2_zz_-20_m.dat
    casship identify --captive ../shared/data/kvlcc2_hmri_captive --rig hmri-t530 --model kvlcc2 --out captive.json

Without ``--free`` the records are identified by the ship workflow
(:func:`casship.identify.workflow.identify_ship`): propulsion first, a cost weighted by a stated
rule, priors about the preset, the free set chosen from run-level evidence, the inverse-dynamics
start; every choice is printed with its reason. ``--weights`` and ``--prior-std`` override its channel
weights and prior.

Records are CSV files with a header row (columns named like the model's inputs and outputs, SI
units, radians), MARIN ``.dat`` files (read by :func:`casship.io.read_marin`, rudder sign flipped
to the MMG convention), HSVA or NMEA logs; the record options (``--preset``, ``--columns``,
``--time``, ``--latlon``) are those of ``casship filter`` and ``simulate``, and a heading logged in
degrees is refused. ``--objective mle`` (default) maximises the likelihood through an EKF;
``--objective oe`` minimises the simulated output error. Every option maps onto the Python API
(:class:`casship.OutputErrorProblem`, :class:`casship.MLEProblem`).

Every fit is replayed on its records against the model it started from (the model's published
values, or ``--params``), and with several records left-one-out (refit without each record, replay
it): the verdict (``better``, ``no better``, ``worse``, ``stalled``, ``not judged``), the heading
RMSE per record and the model-discrepancy term of the bands are printed and written in the fit file.
Exit codes: 0 a fit that is not worse than its start; 3 a fit worse than its start or stalled (the
file is written and says so; ``--accept-worse`` exits 0); 2 a usage or input error. The USV example
(the remedy ``casship filter`` suggests) ends ``not judged`` (its model has no heading) with exit
code 0; the first two end ``better`` on records of a Nomoto ship. The kvlcc2 example shows the
options on three records of your own: its verdict says whether the fit beats the published constants
(on the shared MARIN 10/10 zig-zag a yaw-only free set with the surge channel in the cost does not:
verdict ``worse``, exit code 3), and the ``simulate`` line replays such a file with its bands.
The last line fits the HMRI captive tests alone on the rig's model (``--rig``: a known rig or a
JSON file, :mod:`casship.identify.rig`) and writes their hull and interaction coefficients carried
to the ship; with records beside ``--captive`` the captive-only model or the joint fit is chosen by
the nested rule of :mod:`casship.identify.captive_choice` (one record keeps the captive-only model,
judged on it out of sample).
"""
from __future__ import annotations

import warnings

from ._vocabulary import add_deprecated_alias
from ._common import (add_limits_option, add_record_options, check_input_files, check_outputs, check_record_ranges, count,
                      number, parse_items, parse_pairs, positive, print_json, read_records, refuse_unused, write_output)
from .cmd_filter import DEFAULT_Q, record_noise
from ..errors import InputError

#: Exit code for a fit worse than its start or stalled (:data:`casship.identify.verdict.EXIT_WORSE`; a literal
#: here so that ``--help`` loads no numerics).
EXIT_WORSE = 3


#: One-line description (the command list of ``casship --help``).
HELP = "fit model parameters to records (maximum likelihood or output error)"


def register(sub) -> None:
    p = sub.add_parser("identify", help=HELP,
                       description="Estimate named parameters of a registered model from one or more records "
                                   "(one joint fit), with a prior, standard errors, correlations and warnings. "
                                   "Without --free: the ship workflow (casship.identify_ship): propulsion first, "
                                   "channels and records weighted by a stated rule, priors about the preset, the "
                                   "free set chosen from run-level evidence, the inverse-dynamics start; every "
                                   "choice printed with its reason (--weights, --prior-std, --measured override).\n\n"
                                   + __doc__.split("\n\n", 1)[1])
    p.add_argument("data", nargs="*", help="records: CSV with a header row, MARIN .dat, NMEA log (see "
                                            "casship.io.read_record); the record options below apply to each "
                                            "(none with --captive: the captive tests alone)")
    p.add_argument("--model", required=True, help="registered model name (see 'casship simulate --list')")
    add_record_options(p, "records")
    p.add_argument("--captive", default=None,
                   help="folder of captive (PMM) tests (casship.io.read_captive), fitted on the --rig's model of the "
                        "ship: alone without records (the classical route; the hull and interaction coefficients "
                        "carried to --model), joined with the records in the ship workflow otherwise")
    p.add_argument("--rig", default=None,
                   help="the captive tests' rig: a known name (hmri-t530) or a JSON file of the facility's "
                        "particulars (casship.identify.rig)")
    p.add_argument("--free", default=None,
                   help="comma-separated quantities to estimate: parameter names, bias[input], bias[output] "
                        "(default: the ship workflow chooses them from run-level evidence)")
    p.add_argument("--weights", default=None,
                   help="workflow: channel standard deviations of the cost name=value,... (default: the stated rule)")
    p.add_argument("--out", default="fit.json", help="JSON file for the fit (an existing file needs --overwrite)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing --out / --plot file")
    p.add_argument("--objective", dest="method", default="mle", choices=("mle", "oe"),
                   help="what the fit minimises: mle the negative log-likelihood through an EKF (default); oe the "
                        "output error of a simulation")
    add_deprecated_alias(p, "--method", "--objective", dest="method", choices=("mle", "oe"))
    p.add_argument("--measured", default=None, help="outputs to use a,b,... (default: outputs in every record)")
    p.add_argument("--share", default=None,
                   help="per-record or per-group quantities name=record|all|group,... (group: see --group)")
    p.add_argument("--group", default=None, help="one group label per record A,A,B,... (for --share name=group)")
    p.add_argument("--prior-std", dest="prior", default=None,
                   help="Gaussian prior standard deviations name=std,... centred on the published values (MAP)")
    add_deprecated_alias(p, "--prior", "--prior-std", dest="prior")
    p.add_argument("--prior-weight", dest="prior_weight", type=positive, default=1.0, help="weight of the prior")
    p.add_argument("--bounds", default=None, help="bounds name=lower:upper,...")
    p.add_argument("--R", default=None, help="measurement variances name=value,... (mle; default: estimated)")
    p.add_argument("--Q", default=None, help=f"process-noise variances: scalar or name=value,... (mle; default "
                                             f"{DEFAULT_Q:g})")
    p.add_argument("--estimate-noise", dest="estimate_noise", default=None,
                   help="noise variances to estimate: Q, R or Q,R (mle). Without this option R is estimated when "
                        "--R is absent; with --estimate-noise Q alone, R stays at --R or at the record's own "
                        "estimate (as casship filter takes it)")
    p.add_argument("--sigma", default=None,
                   help="output standard deviations name=value,... (oe weights; default: estimated from the records)")
    p.add_argument("--guess", default=None, help="starting values name=value,... (default: model values)")
    p.add_argument("--params", default=None, help='JSON {"params": {...}} with the fixed parameter values')
    p.add_argument("--estimate-x0", dest="estimate_x0", default=None,
                   help="states whose initial values are estimated per record a,b,...")
    p.add_argument("--decimate", type=count, default=1, help="keep every k-th sample (default 1)")
    p.add_argument("--shooting", default="single", choices=("single", "multiple"), help="oe: shooting")
    p.add_argument("--max-iter", dest="max_iter", type=count, default=100, help="iteration limit (default 100)")
    p.add_argument("--identifiability", action="store_true",
                   help="print the Fisher-information analysis of the free set at the guess before fitting")
    p.add_argument("--plot", default=None, help="PNG of measured outputs vs the fitted free-run simulation (with "
                                                "--captive: the captive force components, measured vs modelled)")
    p.add_argument("--json", action="store_true", help="print the fit as JSON instead of a table")
    p.add_argument("--no-loo", dest="no_loo", action="store_true",
                   help="judge the fit on its records only (no left-one-out refits: the model discrepancy is then "
                        "the in-sample default)")
    p.add_argument("--accept-worse", dest="accept_worse", action="store_true",
                   help=f"exit 0 although the verdict is worse than the start or stalled (default: exit code "
                        f"{EXIT_WORSE}; the fit file says the verdict either way)")
    add_limits_option(p)
    p.set_defaults(func=run, parser=p)


def _records(args, model) -> list:
    """The records, read and decimated, their inputs and first states checked against the model's validity
    ranges (unless ``--allow-out-of-range``)."""
    records = []
    for d in read_records(args, args.data, model):
        _check_columns(d, model.input_names, f"input(s) of {model.name!r}")
        try:                    # NaN in an input is an error (rows as in the file, before decimation)
            d.matrix([n for n in model.input_names if n in d], finite=True, what="input")
        except InputError as exc:
            raise InputError(f"record {d.meta.get('name')}: {exc}") from None
        if args.decimate > 1 and args.decimate >= len(d):       # one row left (Dataset.decimate)
            raise InputError(f"--decimate {args.decimate}: record {d.meta.get('name')} has {len(d)} rows; a fit "
                             f"needs at least two after decimation (--decimate {max(len(d) - 1, 1)} at most)")
        records.append(d.decimate(args.decimate))
    if not args.allow_out_of_range:
        check_record_ranges(model, records)
    return records


def _check_columns(data, names, what: str) -> None:
    """Refuse a record that lacks a column of ``names``, naming the record."""
    missing = [n for n in names if n not in data]
    if missing:
        raise InputError(f"record {data.meta.get('name')}: no column(s) {missing}, the {what}; columns: "
                         f"{list(data.names)} (use --columns)")


def _bounds(text: str | None) -> dict:
    out = {}
    for name, rng in parse_pairs(text, "--bounds", numbers=False).items():
        lo, sep, hi = rng.partition(":")
        if not sep:
            raise InputError(f"--bounds: expected name=lower:upper, got {name}={rng}")
        lower = number(lo, f"--bounds {name} lower") if lo.strip() else -float("inf")
        upper = number(hi, f"--bounds {name} upper") if hi.strip() else float("inf")
        out[name] = (lower, upper)
    return out


def _problem(args, model, records, free, measured):
    import numpy as np

    from ..discretize import discretize
    from ..estimators import EKF
    from ..identify import MLEProblem, OutputErrorProblem, Prior
    from ..identify.params_file import read_params

    share = parse_pairs(args.share, "--share", numbers=False)
    labels = parse_items(args.group, "--group", unique=False)
    groups = {"group": labels} if labels else None
    if any(h == "group" for h in share.values()) and not labels:
        raise InputError("--share name=group needs --group with one label per record")
    prior = Prior(parse_pairs(args.prior, "--prior-std"), weight=args.prior_weight) if args.prior else None
    params = read_params(args.params, model)[1] if args.params else None
    common = dict(share=share or None, groups=groups, prior=prior, params=params, bounds=_bounds(args.bounds) or None,
                  estimate_x0=parse_items(args.estimate_x0, "--estimate-x0"))
    if args.method == "oe":
        sigma = parse_pairs(args.sigma, "--sigma")
        _check_sigma_estimates(model, records, [n for n in measured if n not in sigma])
        free_x0 = set(parse_items(args.estimate_x0, "--estimate-x0"))
        zero = [s for s in model.state_names if s not in free_x0 and any(s not in d for d in records)]
        if zero:        # a simulation started at 0 (a speed of 0 stays put): say so, with the remedy
            warnings.warn(f"output error starts state(s) {zero} at 0 in the record(s) without a column for them "
                          f"({', '.join(sorted({str(d.meta.get('name')) for d in records if set(zero) - set(d.names)}))}"
                          f"); --estimate-x0 {','.join(zero)} estimates their start", UserWarning, stacklevel=2)
        return OutputErrorProblem(model, records, free, measured=measured, sigma=sigma or "estimate",
                                  shooting=args.shooting, **common)
    R = parse_pairs(args.R, "--R")
    unknown = set(R) - set(measured)
    if unknown:
        raise InputError(f"--R names {sorted(unknown)} not among measured outputs {measured}")
    rest = [n for n in measured if n not in R]
    start = {}
    for n in rest:              # the record's noise, the median over the records, as the starting value
        start[n] = float(np.median([record_noise(model, d, [n], "--R NAME=VARIANCE")[0][n] for d in records]))
    estimate = set(parse_items(args.estimate_noise, "--estimate-noise"))
    if estimate - {"Q", "R"}:
        raise InputError(f"--estimate-noise: unknown {sorted(estimate - {'Q', 'R'})}; use Q, R or Q,R")
    noise = {}
    if "R" in estimate:
        noise["R"] = True
    elif rest and not estimate:     # --estimate-noise Q alone keeps R at the record's values, as filter does
        noise["R"] = rest
    if "Q" in estimate:
        noise["Q"] = True
    Q = (parse_pairs(args.Q, "--Q") if "=" in args.Q else number(args.Q, "--Q")) if args.Q else DEFAULT_Q
    dt = float(np.median(np.concatenate([np.diff(d.t) for d in records])))
    ekf = EKF(discretize(model, dt), Q, {**start, **R}, measured=measured)
    return MLEProblem(ekf, records, free, noise=noise, **common)


def _check_sigma_estimates(model, records, names) -> None:
    """The output-error weights estimated from the records (:func:`casship.identify.records.noise_std`): a channel
    whose estimate fails is named with the option that gives it instead."""
    from ..identify.records import noise_std

    if any(len(d) < 2 for d in records):       # the problem names such a record itself
        return
    for n in names:
        try:
            noise_std(records, [n], [n] if model.angle_outputs[model.index(n, "output")] else [])
        except InputError as exc:
            raise InputError(f"{exc} with --sigma {n}=STD, or leave {n!r} out of --measured") from None


def run(args) -> int:
    from ..models import get_model
    from ..progress import stage

    if args.method == "oe":
        refuse_unused(args.parser, {"--R": args.R is not None, "--Q": args.Q is not None,
                                    "--estimate-noise": args.estimate_noise is not None},
                      "--objective oe weighs the output errors with --sigma (no filter, no noise covariances)")
    else:
        refuse_unused(args.parser, {"--sigma": args.sigma is not None, "--shooting": args.shooting != "single"},
                      "--objective mle runs the likelihood through an EKF (no simulation weights or shooting)")
    refuse_unused(args.parser, {"--prior-weight": args.prior_weight != 1.0 and not args.prior,
                                "--group": bool(args.group) and "=group" not in (args.share or "")},
                  "--prior-weight weighs a --prior-std; --group labels the records for --share NAME=group")
    if args.captive is None:
        refuse_unused(args.parser, {"--rig": args.rig is not None}, "--rig names the model of a --captive folder")
        if not args.data:
            raise InputError("identify: give the records to fit, or --captive DIR --rig RIG for captive tests")
    else:
        if args.rig is None:
            raise InputError("--captive: name the rig the tests were made on: --rig hmri-t530 or --rig RIG.json "
                             "(the facility's particulars; see casship.identify.rig)")
        refuse_unused(args.parser, {"--free": args.free is not None},
                      "captive tests fit the free set of the rule in casship.identify.rig, and join records in the "
                      "ship workflow (without --free)")
        if not args.data:
            return _captive_alone(args)
    if args.free is None:
        return _workflow(args)
    refuse_unused(args.parser, {"--weights": args.weights is not None},
                  "--weights sets the channel weights of the workflow (without --free); with --free use --sigma")
    check_input_files({"--params": args.params})
    stamps = check_outputs({"--out": args.out, "--plot": args.plot}, overwrite=args.overwrite)  # before the fit
    model = get_model(args.model)
    stage("reading the records", 1, 5)
    records = _records(args, model)
    free = parse_items(args.free, "--free")
    if not free:
        raise InputError("--free: give at least one quantity")
    measured = (parse_items(args.measured, "--measured") if args.measured is not None
                else [n for n in model.output_names if all(n in d for d in records)])
    if not measured:
        raise InputError(f"no output of {model.name!r} {list(model.output_names)} is a column of every record")
    for d in records:
        _check_columns(d, [n for n in measured if n in model.output_names], "--measured output(s)")
    stage("building the problem", 2, 5)
    prob = _problem(args, model, records, free, measured)
    guess = parse_pairs(args.guess, "--guess")
    if args.identifiability:
        idf = prob.identifiability(guess or None)
        print(idf.summary())
        print(f"proposed free set (relative std error <= {idf.max_rel_std:g}, |rho| <= {idf.max_corr:g}): "
              f"{idf.propose()}")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        stage("fitting", 3, 5)
        fit = prob.solve(guess=guess, max_iter=args.max_iter, verdict=None)
        # replayed on its records against the starting model, and left-one-out when there are several
        stage("judging the fit: replays against the start" + ("" if args.no_loo or len(records) < 2 else
                                                              ", left-one-out refits"), 4, 5)
        prob.judge(fit, loo=not args.no_loo, guess=guess, solve={"max_iter": args.max_iter})
    for w in caught:            # the fit's own warnings are printed once, with the fit
        if not any(str(w.message).endswith(text) for text in fit.warnings) and "verdict" not in str(w.message):
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    stage("writing", 5, 5)
    write_output(args.out, fit.to_json, option="--out", overwrite=args.overwrite, stamps=stamps)
    if args.plot:
        write_output(args.plot, fit.plot, option="--plot", overwrite=args.overwrite, stamps=stamps)
    if args.json:
        print_json(fit.to_dict())
    else:
        print(fit.summary())
        print(f"fit written to {args.out}" + (f" (verdict: {fit.verdict['verdict']})" if fit.worse else ""))
    return _exit_code(fit.worse, fit.verdict, args.accept_worse)


def _exit_code(worse: bool, verdict: dict | None, accept: bool) -> int:
    """0, or :data:`~casship.identify.verdict.EXIT_WORSE` for a fit worse than its start or stalled."""
    import sys

    if not worse:
        return 0
    word = verdict["verdict"]
    if accept:
        print(f"casship identify: verdict {word} accepted (--accept-worse): {verdict['reason']}", file=sys.stderr)
        return 0
    print(f"casship identify: verdict {word}: {verdict['reason']}; the fit file records it (exit code "
          f"{EXIT_WORSE}; --accept-worse to exit 0)", file=sys.stderr)
    return EXIT_WORSE


def _own_fit_options(args) -> dict:
    """The options of a fit of one's own (``--free``), each with whether it was given: what the ship workflow and
    the captive tests alone refuse."""
    return {"--share": args.share is not None, "--group": args.group is not None, "--bounds": args.bounds is not None,
            "--R": args.R is not None, "--Q": args.Q is not None, "--estimate-noise": args.estimate_noise is not None,
            "--sigma": args.sigma is not None, "--guess": args.guess is not None, "--params": args.params is not None,
            "--estimate-x0": args.estimate_x0 is not None, "--shooting": args.shooting != "single",
            "--identifiability": args.identifiability, "--prior-weight": args.prior_weight != 1.0}


def _workflow(args) -> int:
    """``casship identify`` without ``--free``: the ship workflow of the Python API, printed choice by choice."""
    import numpy as np

    from ..identify.workflow import identify_ship
    from ..models import get_model

    refuse_unused(args.parser, _own_fit_options(args),
                  "without --free the ship workflow runs (output error, its own start and weights); give --free "
                  "for a fit of your own")
    stamps = check_outputs({"--out": args.out, "--plot": args.plot}, overwrite=args.overwrite)
    model = get_model(args.model)
    records = _records(args, model)
    measured = parse_items(args.measured, "--measured") if args.measured is not None else None
    for d in records:
        _check_columns(d, [n for n in measured or () if n in model.output_names], "--measured output(s)")
        # the workflow smooths and weighs every output a record holds: one never measured stops it
        empty = [n for n in model.output_names if n in d and not np.isfinite(np.asarray(d[n], dtype=float)).any()]
        if empty:
            raise InputError(f"record {d.meta.get('name')}: column(s) {empty} hold no finite value (never measured); "
                             "remove them from the record")
    # the workflow passes over a name it does not use: an unknown one is refused here, by its option
    weights = parse_pairs(args.weights, "--weights", names=measured or model.output_names)
    prior = parse_pairs(args.prior, "--prior-std", names=model.param_names)
    for option, values in (("--weights", weights), ("--prior-std", prior)):
        bad = {k: v for k, v in values.items() if not v > 0}
        if bad:
            raise InputError(f"{option}: a standard deviation must be positive, got {bad}")
    options = dict(weights=weights or None, prior=prior or None, measured=measured)
    if args.captive is not None:            # the captive-only model or the joint fit, chosen on the records
        return _captive(args, model, stamps, records, options)
    ship = identify_ship(records, model, verbose=not args.json, **options)
    write_output(args.out, ship.to_json, option="--out", overwrite=args.overwrite, stamps=stamps)
    if args.plot:
        write_output(args.plot, ship.fit.plot, option="--plot", overwrite=args.overwrite, stamps=stamps)
    if args.json:
        print_json(ship.to_dict())
    else:
        print(ship.fit.summary())
        print(f"fit written to {args.out}" + (f" (verdict: {ship.fit.verdict['verdict']})" if ship.fit.worse else ""))
    return _exit_code(ship.fit.worse, ship.fit.verdict, args.accept_worse)


def _captive_fit(args):
    """The ``--captive`` folder fitted on the ``--rig``'s model of ``--model``: ``(problem, fit)``."""
    from ..identify.rig import read_rig
    from ..io import read_captive
    from ..progress import stage

    rig = read_rig(args.rig)
    stage(f"reading the captive tests of {rig.facility}", 1, 3)
    tests = read_captive(args.captive)
    problem = rig.problem(tests, args.model)
    stage(f"fitting {len(problem.free)} coefficients to {len(problem.predictor.measured)} measured force values", 2, 3)
    return problem, problem.solve(max_iter=args.max_iter)


def _captive_alone(args) -> int:
    """``casship identify --captive DIR --rig RIG --model NAME`` without records: the classical route."""
    from ..models import get_model

    refuse_unused(args.parser, {**_own_fit_options(args), "--weights": args.weights is not None,
                                "--measured": args.measured is not None, "--prior-std": args.prior is not None,
                                "--decimate": args.decimate != 1, "--no-loo": args.no_loo,
                                "--allow-out-of-range": args.allow_out_of_range,
                                "--accept-worse": args.accept_worse},
                  "without records the captive tests are fitted alone by the rule of casship.identify.rig")
    stamps = check_outputs({"--out": args.out, "--plot": args.plot}, overwrite=args.overwrite)
    return _captive(args, get_model(args.model), stamps, [], {})


def _captive(args, model, stamps, records, options) -> int:
    """The captive tests alone or beside ``records`` (:func:`casship.identify.captive_choice.identify_with_captive`),
    written, plotted and printed."""
    from ..identify.captive_choice import identify_with_captive
    from ..progress import stage

    problem, alone = _captive_fit(args)
    result = identify_with_captive(records, model, problem, alone, workflow=options, verbose=not args.json,
                                   progress=lambda text: stage(text, 3, 3))
    write_output(args.out, result.to_json, option="--out", overwrite=args.overwrite, stamps=stamps)
    if args.plot:
        write_output(args.plot, lambda path: problem.plot(alone, path=path), option="--plot", overwrite=args.overwrite,
                     stamps=stamps)
    if args.json:
        print_json({**result.to_dict(), "out": str(args.out)})
    else:
        print(result.summary())
        print(f"fit written to {args.out}")
    return _exit_code(result.worse, result.verdict_block, args.accept_worse)
