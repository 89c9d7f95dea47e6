"""``casship simulate --model NAME``: run a standard manoeuvre (or replay measured inputs) and print metrics.

Examples::

    casship simulate --model kvlcc2 --maneuver turning --rudder-deg 35 --speed 7.97 --json
    casship simulate --model kvlcc2-l7 --maneuver zigzag --rudder-deg 20 --first port --csv zz.csv --plot zz.png
    casship simulate --model kvlcc2 --params fit.json --inputs ../shared/data/kvlcc2_marin_free/MARIN_FREE_KVLCC2_zz_10_m.dat --json
    casship simulate --model nomoto1 --inputs trial.csv --columns psi=heading:deg,delta=rudder:deg --time time:s

A replay (``--inputs``) reads its record as ``filter`` and ``identify`` do (``--preset``, ``--columns``,
``--time``, ``--latlon``; a heading in degrees is refused). With ``--params`` a fit file, the replay
carries the file's bands: the parameter band (its covariance) and, when the file carries a model
discrepancy, the predictive band (the same covariance plus a heading variance growing as ``q t``);
each band's coverage of the measured heading is printed, and one far below its nominal level is
flagged. A fit file whose verdict is ``worse`` or ``stalled`` is replayed, with a warning.
"""
from __future__ import annotations

from ._vocabulary import add_deprecated_alias
from ._common import (add_limits_option, add_model_option, add_overwrite_option, add_record_options, check_input_files,
                      check_outputs, check_ship, level, load_model, print_json, read_records, refuse_unused, require,
                      seed, whole, write_output)

_METRIC_ORDER = ("advance_m", "transfer_m", "tactical_diameter_m", "steady_diameter_m", "steady_speed_mps",
                 "time_to_90_s", "time_to_180_s", "overshoot_1_deg", "overshoot_1_pct", "overshoot_2_deg",
                 "overshoot_2_pct", "overshoot_3_deg", "overshoot_3_pct",
                 "initial_turning_time_s", "period_s", "initial_turning_distance_m", "yaw_rate_at_release_deg_s",
                 "residual_yaw_rate_deg_s")


#: One-line description (the command list of ``casship --help``).
HELP = "simulate a manoeuvre of a named model and print its metrics"


def register(sub) -> None:
    p = sub.add_parser("simulate", help=HELP,
                       description="Simulate a standard manoeuvre of a registered model from a straight run "
                                   "(or replay the measured inputs of a record) and print the metrics. Inputs, "
                                   "speed and time step are checked against the model's validity ranges.\n\n"
                                   + __doc__.split("\n\n", 1)[1])
    add_model_option(p)
    p.add_argument("--list", action="store_true", help="list the registered models")
    p.add_argument("--maneuver", default="turning", choices=("turning", "zigzag", "pullout", "spiral", "random"),
                   help="manoeuvre")
    p.add_argument("--rudder-deg", type=float, default=35.0,
                   help="rudder angle [deg]; positive turns to starboard; negative zig-zag = port first")
    p.add_argument("--heading-deg", type=float, default=None,
                   help="zig-zag switch heading [deg] (default |rudder|); negative = port first")
    p.add_argument("--first", default=None, choices=("port", "starboard"),
                   help="zig-zag: the side of the first rudder (default: port if --rudder-deg or --heading-deg is "
                        "negative, else starboard)")
    p.add_argument("--speed", type=float, default=None, help="approach speed [m/s] (default: the preset's U0)")
    p.add_argument("--rps", type=float, default=None,
                   help="propeller rate [1/s]; by default solved for equilibrium at --speed")
    p.add_argument("--duration", type=float, default=None, help="simulated time [s] (default: scaled with L/U)")
    p.add_argument("--dt", type=float, default=None, help="time step [s] (default: L/U/400, rounded)")
    p.add_argument("--hold", type=float, default=None, help="hold time for pull-out/spiral/random [s]")
    p.add_argument("--seed", type=seed, default=None, help="seed of the random rudder sequence (default 0)")
    p.add_argument("--integrator", dest="method", default="rk4", choices=("rk4", "euler", "cvodes"),
                   help="how the model's equations are integrated in time")
    add_deprecated_alias(p, "--method", "--integrator", dest="method", choices=("rk4", "euler", "cvodes"))
    p.add_argument("--params", default=None,
                   help='JSON file {"params": {name: value}} overriding parameters (a fit file rebuilds the '
                        'model variant it was fitted on)')
    p.add_argument("--inputs", default=None,
                   help="replay the measured inputs of a record (CSV, MARIN .dat, NMEA; see casship.io.read_record) "
                        "from its measured initial state")
    add_record_options(p, "--inputs record")
    p.add_argument("--samples", type=whole, default=40,
                   help="parameter draws for the index intervals when the --params file carries a covariance "
                        "(0: none)")
    p.add_argument("--level", type=level, default=0.95, help="coverage of the prediction bands and intervals")
    p.add_argument("--no-bands", action="store_true", help="ignore the covariance of the --params file")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--csv", default=None, help="save the trajectory as CSV")
    p.add_argument("--plot", default=None, help="save a figure (.png, .pdf or .svg)")
    add_overwrite_option(p)
    add_limits_option(p)
    p.set_defaults(func=run, parser=p)


def run(args) -> int:
    from ..models import model_names

    if args.list:
        for name, doc in model_names().items():
            print(f"{name:18s} {doc}")
        return 0
    require(args.parser, args, {"--model": args.model})
    if args.inputs:
        unused = {"--maneuver": args.maneuver != "turning", "--rudder-deg": args.rudder_deg != 35.0,
                  "--heading-deg": args.heading_deg is not None, "--first": args.first is not None,
                  "--speed": args.speed is not None, "--rps": args.rps is not None,
                  "--duration": args.duration is not None, "--dt": args.dt is not None, "--hold": args.hold is not None,
                  "--seed": args.seed is not None}
        refuse_unused(args.parser, unused, "--inputs replays the record's own inputs, start and time stamps")
    else:
        refuse_unused(args.parser, {"--preset": args.preset is not None, "--columns": args.columns is not None,
                                    "--time": args.time is not None, "--latlon": args.latlon is not None},
                      "the record options read the --inputs record")
        refuse_unused(args.parser, {"--first": args.first is not None and args.maneuver != "zigzag",
                                    "--heading-deg": args.heading_deg is not None and args.maneuver != "zigzag",
                                    "--hold": args.hold is not None and args.maneuver not in ("pullout", "spiral", "random"),
                                    "--seed": args.seed is not None and args.maneuver != "random" and not args.params},
                      f"not used by a {args.maneuver} manoeuvre (--first, --heading-deg: zig-zag; --hold: pull-out, "
                      "spiral, random; --seed: random, or the parameter draws of --params)")
    check_input_files({"--params": args.params, "--inputs": args.inputs})
    stamps = check_outputs({"--csv": args.csv, "--plot": args.plot}, overwrite=args.overwrite)
    unc, verdict_note = None, ""
    if args.params:
        from ..identify import read_fit_file

        # the fitted variant, checked against the file, and the file's parameter covariance
        fit = read_fit_file(args.params, args.model)
        model, p, unc = fit.model, fit.params, (None if args.no_bands else fit.uncertainty)
        verdict_note = _verdict_note(args.params)
    else:
        model = load_model(args.model)
        p = model.params()
    if not args.inputs:
        check_ship(model, args.model, "a manoeuvre")
    L = model.vessel.L_pp if model.vessel is not None else None
    out = {"model": args.model, "L_pp_m": L}
    if verdict_note:
        out["params_warning"] = verdict_note[len("warning: "):]
    measured, notes, late = None, [], []
    check = not args.allow_out_of_range
    if args.inputs:
        from ..identify import replay_file
        from ..maneuvers import replay

        measured = read_records(args, [args.inputs], model, wrap_angles=False)[0]
        options = dict(method=args.method, check_limits=check, level=args.level, samples=args.samples)
        res = (replay_file(args.params, measured, model, uncertainty=not args.no_bands, **options) if args.params
               else replay(model, measured, p, **options))
        traj = res.trajectory
        out.update({"maneuver": f"replay ({res.kind})", "inputs": str(args.inputs), "replay": res.errors,
                    "start": res.start, "not_compared": res.not_compared,
                    "metrics": res.metrics, "measured_metrics": res.measured_metrics,
                    "metric_notes": res.metric_notes})
        notes = res.start_notes()
        late = [f"warning: {n}" for n in res.coverage_notes()]
        if late:
            out["band_warnings"] = [n[len("warning: "):] for n in late]
        if res.bands:
            out.update({"bands": res.band_summary(), "metric_intervals": res.metric_intervals,
                        "sampling": res.sampling})
    else:
        from ..maneuvers import run_maneuver

        seed = 0 if args.seed is None else args.seed

        def simulate_with(pk):
            return run_maneuver(model, args.maneuver, rudder_deg=args.rudder_deg, heading_deg=args.heading_deg,
                                speed=args.speed, n=args.rps, duration=args.duration, dt=args.dt, p=pk,
                                hold=args.hold, seed=seed, method=args.method, check_limits=check, first=args.first)

        res = simulate_with(p)
        traj = res.trajectory
        s = res.settings
        out.update({"maneuver": args.maneuver, "speed_mps": s["speed_mps"], "rps": s["n"],
                    "rudder_deg": args.rudder_deg, "metrics": _with_percent(res.metrics, s), "settings": s})
        if "first_side" in s:
            out["first_side"] = s["first_side"]
        if unc is not None and args.samples:
            out.update(_maneuver_intervals(simulate_with, model, p, unc, args.samples, seed, args.level))
    if args.csv:
        write_output(args.csv, traj.to_csv, option="--csv", overwrite=args.overwrite, stamps=stamps)
        out["csv"] = str(args.csv)
    if args.plot:
        if getattr(res, "bands", None):              # the replay with its prediction bands
            draw = res.plot
        else:
            def draw(tmp):
                _plot(traj, measured, tmp, title=f"{args.model}: {out['maneuver']}")
        write_output(args.plot, draw, option="--plot", overwrite=args.overwrite, stamps=stamps)
        out["plot"] = str(args.plot)
    if args.json:
        print_json(out)
    else:
        _print_text(out, notes, late + ([verdict_note] if verdict_note else []))
    return 0


def _verdict_note(path) -> str:
    """A line for a fit file whose verdict says it is worse than its start (or stalled), else ''."""
    import json
    from pathlib import Path

    try:
        v = json.loads(Path(path).read_text()).get("verdict") or {}
    except (OSError, ValueError, AttributeError):
        return ""
    word = v.get("verdict") if isinstance(v, dict) else None
    if word in ("worse", "stalled"):
        return f"warning: {path} holds a fit whose verdict is {word} ({v.get('reason', '')})"
    return ""


def _with_percent(metrics: dict, settings: dict) -> dict:
    """Zig-zag overshoot angles [deg] with the overshoot in % of the switch heading beside them."""
    heading = abs(settings.get("heading_deg") or 0.0)
    out = {}
    for k, v in metrics.items():
        out[k] = v
        if k.startswith("overshoot_") and k.endswith("_deg") and heading:
            out[k[:-4] + "_pct"] = 100.0 * v / heading
    return out


def _maneuver_intervals(simulate_with, model, p, unc, samples: int, seed: int, level: float) -> dict:
    """Index intervals of a manoeuvre from parameter draws of the fit file's covariance."""
    from ..simulation import sampled_metrics

    def run(pk):
        return {k: v for k, v in simulate_with(pk).metrics.items() if isinstance(v, (int, float))}, None

    s = sampled_metrics(run, unc.sample(model, p, samples, seed), level)
    return {"metric_intervals": s["intervals"], "sampling": {"samples": s["samples"], "failed": s["failed"],
                                                             "failures": s["failures"],
                                                             "level": level, "source": unc.source}}


def _print_text(out, notes=(), late=()) -> None:
    length = f" (L_pp = {out['L_pp_m']} m)" if out["L_pp_m"] is not None else ""
    print(f"model {out['model']}{length}, manoeuvre {out['maneuver']}")
    if "first_side" in out:
        print(f"first rudder to {out['first_side']}")
    if out.get("speed_mps") is not None:
        rps = out.get("rps")
        print(f"approach speed {out['speed_mps']:.3f} m/s" + (f", propeller {rps:.4f} 1/s" if rps is not None else ""))
    if "replay" in out:
        for k, v in out["replay"].items():
            print(f"  {k:28s} {v:12.4f}")
    for note in notes:
        print(f"  {note}")
    metrics = out.get("metrics", {})
    measured = out.get("measured_metrics", {})
    keys = [k for k in _METRIC_ORDER if k in metrics or k in measured]
    intervals = out.get("metric_intervals", {})
    if keys:
        print(f"  {'metric':28s} {'simulated':>12s}" + (f" {'measured':>12s}" if measured else "")
              + ("  interval" if intervals else ""))
        for k in keys:
            sim = f"{metrics[k]:12.2f}" if k in metrics else f"{'-':>12s}"
            meas = (f" {measured[k]:12.2f}" if k in measured else f" {'-':>12s}") if measured else ""
            iv = f"  [{intervals[k][0]:.2f}, {intervals[k][1]:.2f}]" if k in intervals else ""
            print(f"  {k:28s} {sim}{meas}{iv}")
        for k, why in out.get("metric_notes", {}).items():         # a "-" above says why here
            print(f"  {k:28s} not compared: {why}")
    sampling = out.get("sampling", {})
    for why, n in sampling.get("failures", {}).items():          # intervals from the draws that ran
        print(f"  {n} of {sampling['samples']} parameter draws failed (left out of the intervals): {why}")
    for k, v in out.get("bands", {}).items():
        print(f"  band {k:23s} {v}" if isinstance(v, str) else f"  band {k:23s} {v:12.4g}")
    if "spiral" in metrics:
        for row in metrics["spiral"]:
            print(f"  rudder {row['rudder_deg']:7.2f} deg  yaw rate {row['yaw_rate_deg_s']:8.4f} deg/s")
    for note in late:
        print(f"  {note}")
    for key in ("csv", "plot"):
        if key in out:
            print(f"{key} written to {out[key]}")


def _plot(traj, measured, path, title="") -> None:
    """Track and heading with the rudder (:meth:`casship.Trajectory.plot`), the record beside them."""
    traj.plot(path=path, measured=measured, title=title)
