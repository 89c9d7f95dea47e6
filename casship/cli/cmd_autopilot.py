"""``casship autopilot --model NAME``: design a course autopilot for a ship and run a course-change scenario.

The options are the settings of :func:`casship.autopilot.design_autopilot`, with the same defaults
(:data:`casship.autopilot.RULES`, derived from the ship): an option left out takes the rule shown in
``--help``; ``--show-defaults`` prints the values the rules give for a ship and where each came from.

Example::

    casship autopilot --model kvlcc2 --json
    casship autopilot --model kvlcc2 --scenario course-60 --method lqr --wind 10 45 --plot out/
    casship autopilot --model otter --mode course --gnss-std 0.02 --show-defaults
    casship autopilot --model kvlcc2 --params fit.json           # on the ship identified by casship identify
    casship autopilot --model kvlcc2 --speed 4 --schedule --scenario course-90 --json
    casship autopilot --model kvlcc2 --controller mpc --scenario course-60
"""
from __future__ import annotations

from pathlib import Path

from ._common import (add_model_option, add_overwrite_option, check_input_files, check_outputs, check_ship, print_json,
                      require, seed)

#: settings shown in degrees on the command line (name -> option suffix)
_DEGREES = {"r_max": "deg_s", "compass_std": "deg", "gyro_std": "deg_s"}
_CHOICES = {"method": ("pid", "lqr"), "mode": ("heading", "course"), "rate": ("estimator", "gyro"),
            "feedforward": ("nonlinear", "linear"),
            "integral": ("fossen", "exact", "none")}
_PAIRS = {"ekf_alpha", "ekf_q", "observer_q"}
_SKIP = {"lqr_weights", "turn_rate_top"}


#: One-line description (the command list of ``casship --help``).
HELP = "design a course autopilot for a named model and run a course change"


def _option(name: str) -> str:
    suffix = _DEGREES.get(name)
    return "--" + (f"{name}_{suffix}" if suffix else name).replace("_", "-")


def register(sub) -> None:
    from ..autopilot.defaults import RULES

    p = sub.add_parser("autopilot", help=HELP,
                       description="Design a course autopilot (python-control) for a registered ship and run the "
                                   "nonlinear closed loop (sensors, estimator, steering gear) through a course "
                                   "change. Every setting defaults to the rule shown, derived from the ship; the "
                                   "Python API (casship.autopilot.design_autopilot) uses the same rules.")
    add_model_option(p)
    p.add_argument("--scenario", default="course-20",
                   help="course-A (A deg, back to 0 at half the run; course-20 = Fossen & Fossen 2021) or step-A")
    p.add_argument("--t-end", type=float, default=None, help="duration [s] (default: two segments, see --segment)")
    for name, (unit, rule) in RULES.items():
        if name in _SKIP:
            continue
        kw = {"default": None, "dest": name}
        unit_txt = {"deg": "deg", "deg_s": "deg/s"}.get(_DEGREES.get(name), unit)
        rule = rule.replace("%", "%%")          # argparse formats help strings with %
        kw["help"] = f"[{unit_txt}] default: {rule}" if unit_txt else f"default: {rule}"
        if name in _CHOICES:
            kw["choices"] = _CHOICES[name]
        elif name in _PAIRS:
            kw.update(type=float, nargs=2, metavar=("A", "B"))
        else:
            kw["type"] = float
        p.add_argument(_option(name), **kw)
    p.add_argument("--controller", choices=("law", "mpc"), default="law",
                   help="'law': the designed PID/LQR law; 'mpc': the design's MPC (HPIPM, 60-step horizon) in the "
                        "compiled loop")
    p.add_argument("--schedule", type=float, nargs="*", default=None, metavar="SPEED",
                   help="gain scheduling over the speed: design at these speeds [m/s] (none given: 40, 55, 70, 85 and "
                        "100 %% of the approach speed) and interpolate the law in the measured speed")
    p.add_argument("--current", type=float, nargs=2, metavar=("SPEED", "DIR_DEG"), default=None,
                   help="uniform current speed [m/s] and the direction it flows towards [deg]")
    p.add_argument("--wind", type=float, nargs=2, metavar=("SPEED", "DIR_DEG"), default=None,
                   help="true wind speed [m/s] and the direction it comes from [deg] (Fujiwara loads)")
    p.add_argument("--params", default=None,
                   help='JSON file {"params": {name: value}} (e.g. a fit of casship identify) with the ship\'s parameters')
    p.add_argument("--seed", type=seed, default=0, help="sensor-noise seed")
    p.add_argument("--show-defaults", action="store_true", help="print the settings for this ship and exit")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--plot", default=None, metavar="DIR", help="save Bode/step and closed-loop plots to the new folder DIR")
    add_overwrite_option(p)
    p.set_defaults(func=run, parser=p)


def _course_changes(res, steer_unit: str) -> list:
    """Per change: overshoot in % with degrees beside it, settling time, rate-limited fraction and
    steering travel (degrees for a rudder, N m for a yaw moment)."""
    import numpy as np

    sc, unit = (float(np.degrees(1.0)), "deg") if steer_unit == "deg" else (1.0, "N_m")
    return [{"change_deg": m["change_deg"], "overshoot_pct": m.get("overshoot_pct"),
             "overshoot_deg": m.get("overshoot_deg"), "settling_time_s": m.get("settling_time_s"),
             "rate_limited_fraction": m.get("rate_limited_fraction"), f"steer_travel_{unit}": sc * m["steer_travel"],
             "turn_rate_max_deg_s": float(np.degrees(m["turn_rate_max"]))} for m in res.metrics]


def settings_from_args(args) -> dict:
    """The settings given on the command line, in SI units (the others follow the rules)."""
    import numpy as np

    from ..autopilot.defaults import RULES

    out = {}
    for name in RULES:
        if name in _SKIP:
            continue
        value = getattr(args, name, None)
        if value is None:
            continue
        if name in _DEGREES:
            value = float(np.radians(value))
        elif name in _PAIRS:
            value = tuple(float(v) for v in value)
        out[name] = value
    return out


def _environment(args, model):
    """The current and wind options, checked: finite, non-negative, a current within the ship's speed range."""
    import numpy as np

    from ..errors import InputError
    from ..models.wind import add_current, add_wind

    env = {}
    if args.current is not None:
        speed, direction = args.current
        limit = model.limits.get("u")
        top = limit.upper if limit is not None and np.isfinite(limit.upper) else 2 * model.vessel.U0
        if not (np.isfinite(speed) and np.isfinite(direction) and 0 <= speed <= top):
            raise InputError(f"--current: speed {speed:g} m/s towards {direction:g} deg must be finite, >= 0 and at "
                             f"most {top:g} m/s (the speed range of model {model.name!r})")
        model = add_current(model)
        env.update(current_speed=speed, current_dir=float(np.radians(direction)))
    if args.wind is not None:
        speed, direction = args.wind
        if not (np.isfinite(speed) and np.isfinite(direction) and speed >= 0):
            raise InputError(f"--wind: speed {speed:g} m/s from {direction:g} deg must be finite and >= 0")
        model = add_wind(model)
        env.update(wind_speed=speed, wind_dir=float(np.radians(direction)))
    return model, env


def _db(value: float) -> str:
    """A gain margin in dB; beyond 100 dB either way it bounds nothing in practice."""
    if value != value:
        return "none"
    if abs(value) > 100:
        return f"{'>' if value > 0 else '<'} {100 if value > 0 else -100} dB (none in practice)"
    return f"{value:.1f} dB"


def run(args) -> int:
    import numpy as np

    from .. import autopilot as ap
    from ..models import get_model

    require(args.parser, args, {"--model": args.model})
    check_input_files({"--params": args.params})
    check_outputs({"--plot": args.plot}, overwrite=args.overwrite, folders=("--plot",))
    if args.params:
        from ..identify import read_params

        ship, p = read_params(args.params, args.model)     # the fitted variant, checked against the file
        given = ship.param_dict(p)
    else:
        ship, given = get_model(args.model), {}
    check_ship(ship, args.model, "an autopilot design", rudder=False)
    model, env = _environment(args, ship)
    p = model.params({k: v for k, v in given.items() if k in model.param_names}) if given else None
    schedule = None if args.schedule is None else (args.schedule or "default")
    design = ap.design_autopilot(model, p=p, schedule=schedule, **settings_from_args(args))   # designed in calm water
    s = design.settings
    if args.show_defaults:
        rows = {k: {"value": v, "source": s.sources.get(k, "")} for k, v in s.as_dict().items()}
        if args.json:
            print_json({"model": args.model, "settings": rows})
        else:
            for k, row in rows.items():
                print(f"{k:>15} = {row['value']!s:<40} ({row['source']})")
        return 0
    controller = ap.mpc_for_design(design) if args.controller == "mpc" else None
    res = design.simulate(args.scenario, args.t_end, seed=args.seed, environment=env, controller=controller)
    steer_unit = "N m" if design.plant.steer == "tau_N" else "deg"
    metrics = [{"overshoot_deg": np.nan, **m} for m in res.metrics]   # overshoot in % with degrees beside it
    out = {"model": args.model, "scenario": args.scenario, "t_end_s": float(res.data.t[-1]), "environment": env,
           **design.summary(), "metrics": metrics, "performance": res.performance,
           "course_changes": _course_changes(res, steer_unit)}
    perf = res.performance
    travel_key = "steer_travel_deg_per_hour" if steer_unit == "deg" else "steer_travel_N_m_per_hour"
    out[travel_key] = perf["steer_travel_per_hour"] * (float(np.degrees(1.0)) if steer_unit == "deg" else 1.0)
    if design.schedule:
        out["schedule_speeds_m_s"] = list(design.autopilot.speeds)
    out["controller"] = args.controller
    if controller is not None:
        out["mpc"] = {"period_s": controller.period, "horizon": int(controller.horizon), "solver": "hpipm"}
    if args.plot:
        from ..outdir import output_folder

        with output_folder(args.plot, overwrite=args.overwrite, what="--plot") as folder:
            loop_png, run_png = folder / f"{args.model}_loop.png", folder / f"{args.model}_{args.scenario}.png"
            ap.plot_design(design.loop, loop_png, f"{args.model}: loop on the linearised ship", design.closed_loop)
            ap.plot_closed_loop(res, run_png, f"{args.model} {args.scenario} ({s.mode}, {s.method})",
                                **({"steer_label": "yaw moment [N m]", "steer_scale": 1.0} if steer_unit == "N m"
                                   else {}))
        out["plots"] = [str(Path(args.plot) / p.name) for p in (loop_png, run_png)]
    if args.json:
        print_json(out)
        return 0
    mg, nom, g = design.margins, design.nomoto, design.gains
    print(f"{args.model} at {s.speed:.3g} m/s: Nomoto K = {nom.K:.4g} 1/s, T = {nom.T:.4g} s"
          + (f" (T1 {nom.T1:.4g}, T2 {nom.T2:.4g}, T3 {nom.T3:.4g})" if nom.second_order else ""))
    print(f"{g.method}: wn = {s.wn:.4g} rad/s, Kp = {g.Kp:.4g}, Kd = {g.Kd:.4g} s, Ki = {g.Ki:.4g} 1/s; "
          f"{s.mode} mode, loop period {s.dt:g} s")
    print(f"margins (python-control): gain {_db(mg['gain_margin_db'])} ({mg['gain_margin_side']}), phase "
          f"{mg['phase_margin_deg']:.1f} deg at {mg['gain_crossover_rad_s']:.3g} rad/s; upper/lower gain margin "
          f"{_db(mg['upper_gain_margin_db'])}/{_db(mg['lower_gain_margin_db'])}; closed loop stable: "
          f"{mg['closed_loop_stable']}")
    sc = 1.0 if steer_unit == "N m" else float(np.degrees(1.0))
    print(f"{'segment':>8} {'target':>7} {'rise s':>8} {'over %':>7} {'over deg':>9} {'settle s':>9} {'ss err':>7} "
          f"{'max steer':>10} {'rate lim':>9}  (target, errors in deg; steering in {steer_unit})")
    for k, m in enumerate(metrics):
        print(f"{k:>8d} {m['target_deg']:>7.1f} {m.get('rise_time_s', np.nan):>8.1f} "
              f"{m.get('overshoot_pct', np.nan):>7.2f} {m['overshoot_deg']:>9.3f} {m.get('settling_time_s', np.nan):>9.1f} "
              f"{m['steady_state_error_deg']:>7.2f} {sc * m['steer_max_abs']:>10.2f} "
              f"{m.get('rate_limited_fraction', np.nan):>9.3f}")
    travel = res.performance["steer_travel_per_hour"] * sc
    print(f"steering travel {travel:.4g} {steer_unit}/h beside the rate limit active "
          f"{res.performance['rate_limited_fraction']:.3f} of the time")
    for c in res.performance["checks"]:
        if c["check"] == "steering travel per hour":        # printed above in the steering's units
            continue
        flag = "" if c["ok"] is None else ("ok" if c["ok"] else "NOT MET")
        print(f"  {c['check']}: {c['value']:.4g} {c['unit']} {flag}")
    return 0
