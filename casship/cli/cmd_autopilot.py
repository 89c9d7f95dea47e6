"""``casship autopilot MODEL``: design a course autopilot at a speed and run a course-change scenario.

Example::

    casship autopilot kvlcc2 --speed 7.97 --scenario course-20 --json
    casship autopilot kvlcc2 --speed 7.97 --scenario course-60 --method lqr --plot out/
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np


def register(sub) -> None:
    p = sub.add_parser("autopilot", help="design a course autopilot for a named model and run a course change")
    p.add_argument("model", help="registered model name (see `casship simulate --list` or casship.models)")
    p.add_argument("--speed", type=float, default=None, help="straight-run speed [m/s] (default: the model's U0)")
    p.add_argument("--scenario", default="course-20",
                   help="course-A (A deg, back to 0 at mid-run; course-20 = Fossen & Fossen 2021) or step-A")
    p.add_argument("--t-end", type=float, default=None, help="duration [s] (default: 40 s, or 1200 s per 100 m "
                   "of ship length)")
    p.add_argument("--method", choices=("pid", "lqr"), default="pid", help="design method (default: pid)")
    p.add_argument("--mode", choices=("course", "heading"), default="course",
                   help="course: GNSS + SOG/COG EKF; heading: compass + rate gyro")
    p.add_argument("--rate", choices=("estimator", "gyro"), default="gyro",
                   help="rate fed back in course mode (EKF course rate or gyro yaw rate)")
    p.add_argument("--wn", type=float, default=None, help="closed-loop natural frequency [rad/s] (default U/L)")
    p.add_argument("--zeta", type=float, default=1.0, help="relative damping (default 1)")
    p.add_argument("--filter", type=float, default=None, dest="filter_T",
                   help="rudder command low-pass time constant [s] (default 0.125 L/U)")
    p.add_argument("--gnss-std", type=float, default=0.5, help="GNSS position noise [m] (default 0.5)")
    p.add_argument("--current", type=float, nargs=2, metavar=("SPEED", "DIR_DEG"), default=None,
                   help="uniform current speed [m/s] and the direction it flows towards [deg]")
    p.add_argument("--wind", type=float, nargs=2, metavar=("SPEED", "DIR_DEG"), default=None,
                   help="true wind speed [m/s] and the direction it comes from [deg] (Fujiwara loads)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--plot", default=None, metavar="DIR", help="save Bode/step and closed-loop plots to DIR")
    p.set_defaults(func=run)


def _clean(v):
    if isinstance(v, dict):
        return {k: _clean(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_clean(x) for x in v]
    if isinstance(v, complex):
        return [v.real, v.imag]
    if isinstance(v, (float, np.floating)):
        return None if not np.isfinite(v) else float(v)
    if isinstance(v, np.generic):
        return v.item()
    return v


def run(args) -> int:
    from dataclasses import replace

    from .. import autopilot as ap
    from ..models import get_model
    from ..linear import trim
    from ..models.wind import add_current, add_wind

    model = get_model(args.model)
    env = {}
    if args.current is not None:
        model = add_current(model)
        env.update(current_speed=args.current[0], current_dir=np.radians(args.current[1]))
    if args.wind is not None:
        model = add_wind(model)
        env.update(wind_speed=args.wind[0], wind_dir=np.radians(args.wind[1]))
    vessel = model.vessel
    speed = args.speed if args.speed is not None else (vessel.U0 if vessel is not None else None)
    if speed is None:
        raise ValueError(f"model {args.model!r} has no nominal speed; give --speed")
    L = vessel.L_pp if vessel is not None else None
    kw = {}
    if vessel is not None and not vessel.rudders and len(vessel.propellers) == 2:
        # twin-propeller craft (Otter): steer by a yaw moment, hold the speed by the surge force
        base = model
        model = ap.steering_model(base, ["tau_X", "tau_N"], ap.twin_propeller_allocation(base),
                                  name=f"{base.name}_tau")
        tau_X = trim(model, {"u": speed}, {"tau_X": 10.0}, free=["tau_X"], zero=["u"]).values["tau_X"]
        kw = dict(steer="tau_N", propeller="tau_X", steer_max=ap.twin_propeller_yaw_limit(base, tau_X),
                  steer_rate_max=np.inf, actuator_T=0.1)
    filter_T = args.filter_T if args.filter_T is not None else (0.125 * L / speed if L else 0.0)
    design = ap.design_autopilot(model, speed, method=args.method, wn=args.wn, zeta=args.zeta, filter_T=filter_T,
                                 delay=1.0 / 5.0, **kw)
    t_end = args.t_end
    if t_end is None and L:
        t_end = max(40.0, 12.0 * L)
    command, t_end, steps = ap.course_scenario(args.scenario, t_end)
    # SOG/COG EKF tuning: slow Singer constants and small process noise for ships (L > 20 m), the
    # MSS defaults with a larger process noise for small craft.
    ship = L is not None and L > 20
    ekf = dict(ekf_alpha=(1e-5, 1e-5), ekf_q=(1e-4, 1e-6)) if ship else dict(ekf_alpha=(0.01, 0.1), ekf_q=(0.1, 0.01))
    plant = replace(design.plant, inputs={**design.plant.inputs, **env})     # designed in calm water
    res = ap.simulate_autopilot(plant, design.autopilot, command, t_end, x0=design.x0, step_times=steps,
                                mode=args.mode, rate=args.rate, gnss_std=args.gnss_std, **ekf, seed=args.seed)
    out = {"model": args.model, "scenario": args.scenario, "mode": args.mode, "t_end_s": t_end, "environment": env,
           **design.summary(), "metrics": res.metrics}
    if args.plot:
        folder = Path(args.plot)
        folder.mkdir(parents=True, exist_ok=True)
        ap.plot_design(design.loop, folder / f"{args.model}_loop.png", f"{args.model}: loop on the design model",
                       design.autopilot.reference)
        ap.plot_closed_loop(res, folder / f"{args.model}_{args.scenario}.png",
                            f"{args.model} {args.scenario} ({args.mode}, {args.method})",
                            **({"steer_label": "yaw moment [N m]", "steer_scale": 1.0} if kw else {}))
        out["plots"] = [str(folder / f"{args.model}_loop.png"), str(folder / f"{args.model}_{args.scenario}.png")]
    if args.json:
        print(json.dumps(_clean(out)))
        return 0
    mg = design.margins
    nom = design.nomoto
    print(f"{args.model} at {speed:.3g} m/s: Nomoto K = {nom.K:.4g} 1/s, T = {nom.T:.4g} s"
          + (f" (T1 {nom.T1:.4g}, T2 {nom.T2:.4g}, T3 {nom.T3:.4g})" if nom.second_order else ""))
    g = design.gains
    print(f"{design.gains.method}: Kp = {g.Kp:.4g}, Kd = {g.Kd:.4g} s, Ki = {g.Ki:.4g} 1/s")
    print(f"margins: gain {mg['gain_margin_db']:.1f} dB, phase {mg['phase_margin_deg']:.1f} deg at "
          f"{mg['gain_crossover_rad_s']:.3g} rad/s, closed loop stable: {mg['closed_loop_stable']}")
    sc, unit = (1.0, "N m") if kw else (float(np.degrees(1.0)), "deg")
    print(f"{'segment':>8} {'target':>7} {'rise s':>8} {'over deg':>9} {'settle s':>9} {'ss err':>7} "
          f"{'IAE deg s':>10} {'max steer':>10} {'rms rate':>9}  (steering in {unit}, rate per s)")
    for k, m in enumerate(res.metrics):
        print(f"{k:>8d} {m['target_deg']:>7.1f} {m.get('rise_time_s', np.nan):>8.1f} "
              f"{m.get('overshoot_deg', np.nan):>9.2f} {m.get('settling_time_s', np.nan):>9.1f} "
              f"{m['steady_state_error_deg']:>7.2f} {m['iae_deg_s']:>10.0f} {sc * m['steer_max_abs']:>10.1f} "
              f"{sc * m['steer_rate_rms']:>9.2f}")
    return 0
