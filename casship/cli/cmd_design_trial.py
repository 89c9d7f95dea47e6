"""``casship design-trial --model NAME --params fit.json --target tactical_diameter``: which trial to run next.

Examples::

    casship design-trial --model kvlcc2 --params fit.json --target tactical_diameter
    casship design-trial --model kvlcc2 --params fit.json --prior-std N_r_dash=0.01,Y_vvr_dash=0.2 \\
        --target port_starboard_difference --duration 900 --corridor 1500 --speed-min 4 --csv next.csv --plot next.png
    casship design-trial --model kvlcc2 --prior-std N_r_dash=0.01,N_v_dash=0.03 --sigma psi=0.0035,r=0.0002 --no-free

What is known now comes from ``--params`` (a fit file: the covariance it carries -- calibrated by a
run-level jackknife when the fit was -- or, with ``--covariance robust|model``, another of its
covariances; its noise standard deviations) and/or ``--prior-std`` (standard deviations of more
parameters, around the file's or the published values); the command says which covariance it used.
The ranked list gives, for each candidate trial, the target's expected standard deviation before
and after it; ``--csv FILE`` writes the optimised free rudder sequence as a CSV a tank can run (time,
rudder in degrees, propeller rate). Every option maps onto :func:`casship.design.design_trials`.
"""
from __future__ import annotations

import math

from ._vocabulary import add_deprecated_alias
from ._common import (add_overwrite_option, check_input_files, check_outputs, check_ship, count, finite, parse_pairs,
                      positive, print_json, refuse_unused, write_output)
from ..errors import InputError


#: The targets of :data:`casship.design.TARGETS` (listed here so that the command line starts without CasADi).
TARGET_NAMES = ("tactical_diameter", "tactical_diameter_port", "advance", "advance_port", "transfer", "first_overshoot",
                "first_overshoot_port", "port_starboard_difference")


#: The covariances of :data:`casship.design.COVARIANCES` (listed here for the same reason).
COVARIANCES = ("jackknife", "robust", "model")


HELP = "rank the trials that would most reduce a prediction's uncertainty, and optimise a free rudder sequence"


def register(sub) -> None:
    p = sub.add_parser("design-trial", help=HELP)
    p.add_argument("--model", required=True, metavar="NAME", help="registered model name")
    p.add_argument("--params", default=None, help="fit file (JSON from casship identify or a study): parameters, "
                                                  "covariance, noise")
    p.add_argument("--covariance", default=None, choices=COVARIANCES,
                   help="which covariance of the fit file is the belief (default: the one the file carries, "
                        "calibrated by a jackknife when present)")
    p.add_argument("--prior-std", dest="prior_std", default=None,
                   help="standard deviations name=std,... of uncertain parameters the fit holds fixed (or all, "
                        "without --params)")
    p.add_argument("--target", default="tactical_diameter", choices=TARGET_NAMES, help="the prediction to resolve")
    p.add_argument("--criterion", default=None, choices=("D", "A"),
                   help="rank by a classical criterion on the parameters instead (the target is still reported)")
    p.add_argument("--sigma", default=None, help="noise standard deviation of one sample per measured output "
                                                 "name=value,... in SI units and radians (default: the fit file's)")
    p.add_argument("--speed", type=positive, default=None, help="approach speed [m/s] (default: the vessel's)")
    p.add_argument("--dt", type=positive, default=None, help="design step and sampling of a trial [s] (default L/U/40)")
    p.add_argument("--turning", default="35", metavar="DEG,...",
                   help="turning-circle rudder angles [deg], comma-separated")
    p.add_argument("--zigzag", default="10,20", metavar="DEG,...", help="zig-zag angles [deg], comma-separated")
    p.add_argument("--pullout", default="35", metavar="DEG,...",
                   help="pull-out rudder angles [deg], comma-separated ('' for none)")
    p.add_argument("--no-spiral", dest="spiral", action="store_false", help="leave the spiral out")
    p.add_argument("--no-free", dest="free", action="store_false", help="rank the standard trials only")
    p.add_argument("--duration", type=positive, default=None, help="free trial: duration [s] (default 25 L/U)")
    p.add_argument("--rudder-max-deg", dest="rudder_max_deg", type=positive, default=None,
                   help="free trial: largest rudder angle [deg] (default: the rudder stop)")
    p.add_argument("--rudder-rate-deg-s", dest="rudder_rate_deg", type=positive, default=None,
                   help="free trial: largest rudder rate [deg/s] (default: the vessel's)")
    add_deprecated_alias(p, "--rudder-rate-deg", "--rudder-rate-deg-s", dest="rudder_rate_deg", type=positive)
    p.add_argument("--corridor", type=positive, default=None, help="free trial: half width of the track corridor [m]")
    p.add_argument("--speed-min", dest="speed_min", type=finite, default=None, help="free trial: speed floor [m/s]")
    p.add_argument("--knot", type=positive, default=None, help="free trial: time between rudder knots [s] (default L/U/4)")
    p.add_argument("--max-iter", dest="max_iter", type=count, default=60, help="free trial: iteration limit")
    p.add_argument("--discrepancy-deg2-s", dest="discrepancy", type=finite, default=None,
                   help="heading model discrepancy q [deg^2/s] (heading error variance growing as q t; default: the "
                        "fit file's model_discrepancy, else 0 = a model right in its structure); it sets the floor no "
                        "trial removes and tempers what long trials teach")
    p.add_argument("--csv", default=None, help="write the free rudder sequence as CSV (t_s, rudder_deg, n)")
    p.add_argument("--plot", default=None, help="figure (.png, .pdf or .svg): ranking, the best trial's rudder, track and speed")
    p.add_argument("--json", action="store_true", help="print the result as JSON instead of a table")
    add_overwrite_option(p)
    p.set_defaults(func=run, parser=p)


def _angles(text, what: str, model=None) -> list[float]:
    """The comma-separated rudder angles [deg] of ``what``, each within (0, 90] and the rudder stop of ``model``."""
    try:
        out = [float(s) for s in (text or "").split(",") if s.strip()]
    except ValueError:
        raise InputError(f"{what}: expected comma-separated angles in degrees, got {text!r}") from None
    bad = [a for a in out if not (0 < a <= 90)]
    if bad:
        raise InputError(f"{what}: angles must be in (0, 90] deg, got {bad}")
    stop = getattr(getattr(model, "vessel", None), "rudder_max", None)
    if stop:
        from ..simulation import MARGIN

        beyond = [a for a in out if a > math.degrees(stop) * (1 + MARGIN)]
        if beyond:
            raise InputError(f"{what}: {beyond} deg beyond the rudder stop {math.degrees(stop):g} deg of "
                             f"{model.name!r}; give angles up to the stop")
    return out


def _discrepancy(args) -> tuple[float, str]:
    """The heading's model discrepancy [rad^2/s] and where it comes from: ``--discrepancy-deg2-s``, else the fit
    file's ``model_discrepancy``, else none."""
    import numpy as np

    from ..identify import read_fit_file

    if args.discrepancy is not None:
        q = args.discrepancy
        if not (math.isfinite(q) and 0 <= q <= 1e4):
            raise InputError(f"--discrepancy-deg2-s: a heading variance growth in [0, 1e4] deg^2/s, got {q:g}")
        return float(np.radians(np.radians(q))), "--discrepancy-deg2-s"
    if args.params:
        unc = read_fit_file(args.params, args.model).uncertainty
        q = getattr(unc, "psi_variance_rate", None) if unc is not None else None
        if q:
            return float(q), f"{args.params} (model_discrepancy)"
        return 0.0, f"{args.params} carries no model_discrepancy"
    return 0.0, "none given"


def _belief_and_noise(args, model):
    """The belief and the noise from ``--params`` (with ``--covariance``) / ``--prior-std`` / ``--sigma``."""
    from ..design import ParameterBelief, fit_noise
    from ..identify import FitResult, read_params

    extra = parse_pairs(args.prior_std, "--prior-std")
    sigma = parse_pairs(args.sigma, "--sigma")
    if args.params:
        check_input_files({"--params": args.params})
        model, p = read_params(args.params, args.model)
        fit = FitResult.from_json(args.params)
        estimated = sorted(set(extra) & {q.split("@", 1)[0] for q in fit.free})
        if estimated:
            raise InputError(f"--prior-std: {estimated} estimated by the fit {args.params} (their covariance comes "
                             "from it); give --prior-std for parameters the fit held fixed")
        if any(q.split("@", 1)[0] in model.param_names for q in fit.free):
            belief = ParameterBelief.from_fit(args.params, covariance=args.covariance, extra_std=extra,
                                              params=model.param_dict(p))
        elif extra and not args.covariance:
            belief = ParameterBelief.from_std(extra, model.param_dict(p), source=f"prior around {args.params}")
        else:
            raise InputError(f"--params {args.params} estimates no model parameter; give --prior-std")
        sigma = sigma or fit_noise(fit)
    else:
        if args.covariance:
            raise InputError("--covariance chooses among a fit file's covariances: give --params")
        if not extra:
            raise InputError("give --params (a fit file) or --prior-std (what is uncertain now)")
        if not sigma:
            raise InputError("without --params give --sigma: the noise of each measured output")
        p = model.params()
        belief = ParameterBelief.from_std(extra, model.param_dict(), source="prior around the published values")
    return model, p, belief, sigma


def run(args) -> int:
    from ..design import Approach, TrialLimits, design_trials, standard_trials
    from ..models import get_model

    free = args.free
    if not free:
        refuse_unused(args.parser, {"--csv": args.csv is not None}, "--no-free optimises no free rudder sequence")
    # before minutes of work: distinct paths, the --overwrite rule
    stamps = check_outputs({"--csv": args.csv, "--plot": args.plot}, overwrite=args.overwrite)
    model = get_model(args.model)
    check_ship(model, args.model, "a trial design")
    model, p, belief, sigma = _belief_and_noise(args, model)
    angles = {what: _angles(getattr(args, what), f"--{what}", model) for what in ("turning", "zigzag", "pullout")}
    q, q_source = _discrepancy(args)
    if not args.json:
        print(f"belief: {belief.kind} ({belief.source}); {len(belief.names)} uncertain parameters")
        print(f"model discrepancy: {math.degrees(math.degrees(q)):.4g} deg^2/s ({q_source})")
    approach = Approach(model, p, speed=args.speed, dt=args.dt)
    limits = None
    if free:
        duration = args.duration if args.duration is not None else round(25 * approach.time_scale / approach.dt) * approach.dt
        limits = TrialLimits(duration, rudder_max=None if args.rudder_max_deg is None else math.radians(args.rudder_max_deg),
                             rudder_rate=None if args.rudder_rate_deg is None else math.radians(args.rudder_rate_deg),
                             corridor=args.corridor, speed_min=args.speed_min, knot=args.knot)
        limits.resolved(approach)
    candidates = standard_trials(approach, **angles, spiral=args.spiral)
    res = design_trials(model, belief, sigma, args.target, criterion=args.criterion, p=p, speed=args.speed,
                        dt=approach.dt, candidates=candidates, limits=limits, max_iter=args.max_iter, discrepancy=q)
    if args.csv:
        write_output(args.csv, lambda tmp: res.trials["free"].to_csv(tmp, approach), option="--csv",
                     overwrite=args.overwrite, stamps=stamps)
    if args.plot:
        write_output(args.plot, lambda tmp: res.plot(tmp, approach), option="--plot", overwrite=args.overwrite,
                     stamps=stamps)
    if args.json:
        print_json(res.to_dict())
    else:
        print(res.summary())
        print(res.table())
        if free:
            where = f"written to {args.csv}" if args.csv else "--csv FILE writes its rudder sequence"
            print(f"free trial: {res.free['outcome']} ({res.free['iterations']} iterations); {where}")
    return 0
