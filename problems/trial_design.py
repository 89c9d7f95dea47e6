"""Trial design for the KVLCC2: which manoeuvre to run next, and a closed check by simulation.

Part 1 (measured data): the KVLCC2 identified on the shared free-running runs by the registered
``kvlcc2-marin`` study, run here into a subfolder (or any fit file a user has, ``params``); this
study reads only its ``fit.json``, as a user would (:func:`casship.identify.read_params`). The
belief is the covariance the file carries -- the run-level jackknife of the parameters the fit
moved, when the study calibrated it -- and this study's stated prior (:data:`HELD_PRIOR`) for the
manoeuvring coefficients the file does not cover; the noise is the fit's (its output weights times
the fitted scale). The standard manoeuvres in both directions and a free rudder sequence (limits
below) are ranked for the tactical diameter and for the port/starboard difference of the tactical
diameter.

Part 2 (no data needed), the closed check: a known "true" ship, the KVLCC2 with its hull
derivatives moved by one seeded draw from the prior and a port/starboard asymmetry like the one
the MARIN fit finds (rudder neutral angle 0.5 deg, propeller-induced side force and yaw moment).
The designer knows only the prior around the published values. Each trial of the ranking is run
on the true ship (the zig-zags switching on its own heading, the free sequence as designed) with
sensor noise, refitted (MAP output error with the same prior), and the target predicted with the
fitted model; over noise seeds the RMSE of that prediction is set against the designed trial's
predicted standard deviation.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

import casship as cs
from casship.design import (Approach, ParameterBelief, TrialLimits, design_trials, fit_noise, get_target,
                            standard_trials, trial_information)
from casship.identify import Prior, read_params
from casship.models import kvlcc2
from casship.studies import Study, run_study

from .kit import Departure, Report, announce, data_folder, figure, md_table, run_cases, write_json

__all__ = ["PRIOR_REL", "PRIOR_ABS", "HELD_PRIOR", "ASYMMETRY", "NOISE", "TRUTH_SEED", "prior_std", "true_params",
           "kvlcc2_marin_fit", "fit_belief", "design_on_fit", "run", "STUDY"]

#: Prior of part 2: relative to the published value ...
PRIOR_REL = {"Y_v_dash": 0.2, "Y_r_dash": 0.2, "N_v_dash": 0.2, "N_r_dash": 0.2, "Y_vvr_dash": 0.5,
             "Y_vrr_dash": 0.5, "N_vvr_dash": 0.5, "N_vrr_dash": 0.5}
#: ... and absolute for the asymmetry terms (rudder neutral angle 1 deg).
PRIOR_ABS = {"delta_0": np.radians(1.0), "Y_0_dash": 0.05, "N_0_dash": 0.025}
#: Part 1: what this study believes of the manoeuvring coefficients a fit file does not cover (a stated
#: prior, as ``casship design-trial --prior-std`` states one), relative to the published value, with
#: :data:`PRIOR_ABS` for the asymmetry terms: hull derivatives 20 % (linear) and 50 % (cubic), resistance,
#: hull-rudder interaction and thrust deduction at the rudder 30 %, the rest of the rudder model and the
#: added masses 20 to 25 %.
HELD_PRIOR = {**PRIOR_REL, "Y_vvv_dash": 0.5, "Y_rrr_dash": 0.5, "N_vvv_dash": 0.5, "N_rrr_dash": 0.5,
              "R_0_dash": 0.3, "gamma_R_minus": 0.25, "gamma_R_plus": 0.25, "l_R_dash": 0.2, "epsilon": 0.2,
              "kappa": 0.2, "f_alpha": 0.2, "a_H": 0.3, "x_H_dash": 0.2, "t_R": 0.3, "m_x_dash": 0.2,
              "m_y_dash": 0.2, "J_z_dash": 0.2}
#: The true ship's asymmetry (close to the MARIN fit's: -0.44 deg, -0.031, 0.021 with the other sign of delta_0).
ASYMMETRY = {"delta_0": np.radians(0.5), "Y_0_dash": -0.03, "N_0_dash": 0.02}
#: Sensor noise of one sample: heading 0.2 deg, yaw rate 0.02 deg/s, surge speed 0.02 m/s.
NOISE = {"psi": np.radians(0.2), "r": np.radians(0.02), "u": 0.02}
TRUTH_SEED = 7
TARGET = "port_starboard_difference"
QUICK = {"dt": 4.0, "seeds": 3, "max_iter": 30}
FULL = {"dt": 2.0, "seeds": 12, "max_iter": 150, "max_iter_fitted": 40}   # part 1: some 35 parameters


def study_model() -> cs.Model:
    """The full-scale KVLCC2 with the asymmetry terms and smooth sign switches."""
    return kvlcc2(asymmetry=True, smooth=True)


def prior_std(model: cs.Model, relative: dict = PRIOR_REL) -> dict:
    """Prior standard deviation of each uncertain parameter of ``model`` (part 2's by default; part 1
    passes :data:`HELD_PRIOR`): ``relative`` times the published value, :data:`PRIOR_ABS` absolute."""
    nominal = model.param_dict()
    return {k: v for k, v in {**{k: r * abs(nominal[k]) for k, r in relative.items()}, **PRIOR_ABS}.items()
            if k in nominal}


def true_params(model: cs.Model) -> dict:
    """The true ship of part 2: one seeded draw from the prior for the hull, the stated asymmetry."""
    nominal, std = model.param_dict(), prior_std(model)
    z = np.random.default_rng(TRUTH_SEED).standard_normal(len(PRIOR_REL))
    truth = dict(nominal)
    truth.update({k: nominal[k] + std[k] * zk for k, zk in zip(PRIOR_REL, z)})
    truth.update(ASYMMETRY)
    return truth


def _limits(approach: Approach) -> TrialLimits:
    """The free trial: as long as a standard turning circle (25 L/U), 30 % of the approach speed at least."""
    return TrialLimits(round(25 * approach.time_scale / approach.dt) * approach.dt, speed_min=0.3 * approach.speed)


# -- part 1: the fit on the shared runs -------------------------------------------------------------------
def kvlcc2_marin_fit(out: Path, data_dir, quick: bool, workers=None, scheduler=None) -> Path | None:
    """Run the registered ``kvlcc2-marin`` study into ``out`` (as ``casship study kvlcc2-marin`` would) and
    return its ``fit.json``; None, said on the console, without the measured runs."""
    marin = data_folder(data_dir, "kvlcc2_marin_free", study="trial-design", part="the design on the fitted KVLCC2")
    if marin is None:
        return None
    announce("trial-design", f"part 1: the kvlcc2-marin study{' (quick)' if quick else ''} into {out}")
    run_study("kvlcc2-marin", out, quick=quick, workers=workers, scheduler=scheduler, data=marin.parent)
    return Path(out) / "fit.json"


def fit_belief(fit_file: Path, covariance: str | None = None):
    """The model, parameters, belief and noise a fit file gives the design.

    The belief is the covariance the file carries (calibrated by the run-level jackknife when the
    fit was; ``covariance`` chooses another) and :data:`HELD_PRIOR` for the parameters it does not
    cover; the noise is the fit's own (:func:`casship.design.fit_noise`).
    """
    model, p, _ = read_params(fit_file, "kvlcc2", uncertainty=True)     # the file's covariance checked too
    values = model.param_dict(p)
    belief = ParameterBelief.from_fit(fit_file, covariance=covariance, params=values)
    held = {n: s for n, s in prior_std(model, HELD_PRIOR).items() if n not in belief.names}
    return model, p, belief.extended(held, values), fit_noise(fit_file)


def design_on_fit(fit_file: Path, out: Path, rep: Report, *, dt: float, max_iter: int, free: bool,
                  covariance: str | None = None) -> dict:
    """Part 1 on a fit file: the standard manoeuvres (and, with ``free``, a free trial) ranked for the
    tactical diameter and for the port/starboard difference."""
    fit_file, out = Path(fit_file), Path(out)
    model, p, belief, noise = fit_belief(fit_file, covariance)
    approach = Approach(model, p, dt=dt)
    out_rows = {}
    shown = fit_file.relative_to(out) if fit_file.is_relative_to(out) else fit_file
    rep.add(f"Fit file: `{shown}`. Belief: {belief.source}; {len(belief.names)} uncertain parameters. "
            f"Noise of one {dt:g} s sample, as the fit weighs it: "
            + ", ".join(f"{k} {v:.3g}" for k, v in noise.items()) + " (SI, rad).")
    for target in ("tactical_diameter", TARGET):
        res = design_trials(model, belief, noise, target, p=p, dt=dt, max_iter=max_iter,
                            limits=_limits(approach) if free else None)
        (out / f"ranking_fit_{target}.md").write_text(res.table() + "\n")
        res.plot(out / f"fig_fit_{target}.png", approach)
        rep.section(f"Target: {res.target.name}", 3)
        rep.add(res.summary().replace("\n", "  \n"), res.table())
        rep.image(f"fig_fit_{target}.png", f"ranking for {target} on the fitted ship, the best trial")
        out_rows[target] = {"value": res.target.value, "best": res.best.name, "ranking": res.rows,
                            "free": res.free}
    return {"fit_file": str(shown), "noise": noise, "belief": belief.source, "covariance": belief.kind,
            "uncertain": list(belief.names), "designs": out_rows}


# -- part 2: the closed check --------------------------------------------------------------------------------
def _refit_case(case: dict) -> dict:
    """One trial on the true ship with one noise seed: refit, predict the target (module level: picklable)."""
    import warnings

    from casship.identify import IdentificationWarning

    model = study_model()
    trial, dt, n = case["trial"], case["dt"], case["n"]
    truth = Approach(model, model.params(case["truth"]), dt=dt, n=n)
    if trial.kind != "free":               # a standard manoeuvre switches on the true ship's own heading
        trial = next(t for t in standard_trials(truth, turning=case["turning"], zigzag=case["zigzag"], pullout=(),
                                                spiral=False) if t.name == trial.name)
    meas = cs.measure(trial.record(truth), model, NOISE, seed=case["seed"])
    std = prior_std(model)
    prob = cs.OutputErrorProblem(model, [meas], list(std), measured=list(NOISE), sigma=NOISE, params=model.params(),
                                 prior=Prior(std), x0=[truth.x0])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", IdentificationWarning)
        fit = prob.solve(show=False)
    fitted = Approach(model, model.params(fit.params), dt=dt)
    value = get_target(TARGET).evaluate(fitted, list(std)).value
    return {"trial": case["trial"].name, "seed": case["seed"], "value": value, "status": fit.status}


def _predicted_at_truth(model, truth, design, res, checked, turning, zigzag, belief) -> dict:
    """The target's standard deviation after each checked trial, linearised at the true ship instead of
    the prior mean (the trials as sailed there): what the design would predict if it knew the truth."""
    names = list(belief.names)
    ship = Approach(model, model.params(truth), dt=design.dt, n=design.n)
    sailed = {t.name: t for t in standard_trials(ship, turning=turning, zigzag=zigzag, pullout=(), spiral=False)}
    grad = get_target(TARGET).evaluate(Approach(model, model.params(truth), dt=design.dt), names).gradient
    out = {}
    for name in checked:
        trial = res.trials[name] if name == "free" else sailed[name]
        info = trial_information(ship, trial, names, NOISE)
        out[name] = float(np.sqrt(belief.after(info).variance_of(grad)))
    return out


def _closed_check(out: Path, quick: bool, cfg: dict, workers, scheduler, rep: Report) -> dict:
    model = study_model()
    dt = cfg["dt"]
    std = prior_std(model)
    belief = ParameterBelief.from_std(std, model.param_dict(), source="prior around the published values")
    truth = true_params(model)
    design = Approach(model, model.params(), dt=dt)
    turning, zigzag = (35.0,), (10.0, 20.0)
    candidates = standard_trials(design, turning=turning, zigzag=zigzag, pullout=(35.0,), spiral=not quick)
    res = design_trials(model, belief, NOISE, TARGET, dt=dt, candidates=candidates, limits=_limits(design),
                        max_iter=cfg["max_iter"])
    within = [r for r in res.rows if not r["violations"]]
    standard = [r for r in within if r["trial"] != "free"]
    checked = [r["trial"] for r in within] if not quick else ["free", standard[0]["trial"]]
    g_true = get_target(TARGET).evaluate(Approach(model, model.params(truth), dt=dt), list(std)).value
    cases = [{"trial": res.trials[name], "dt": dt, "n": design.n, "truth": truth, "seed": 100 + s,
              "turning": turning, "zigzag": zigzag} for name in checked for s in range(cfg["seeds"])]
    announce("trial-design", f"closed check: {len(cases)} refits ({len(checked)} trials x {cfg['seeds']} seeds)")
    results = run_cases(_refit_case, cases, workers=workers, scheduler=scheduler)
    at_truth = _predicted_at_truth(model, truth, design, res, checked, turning, zigzag, belief)
    rows = {}
    for name in checked:
        errs = np.array([r["value"] - g_true for r in results if r["trial"] == name])
        pred = res.row(name)["sd_after"]
        rmse = float(np.sqrt(np.mean(errs**2)))
        rows[name] = {"duration_s": res.row(name)["duration_s"], "predicted_sd_m": pred, "realised_rmse_m": rmse,
                      "mean_error_m": float(errs.mean()), "realised_over_predicted": rmse / pred,
                      "predicted_at_truth_m": at_truth[name],
                      "converged": sum(r["status"] == "converged" for r in results if r["trial"] == name)}
    prior_error = res.target.value - g_true
    best_std = min((n for n in rows if n != "free"), key=lambda n: rows[n]["realised_rmse_m"])
    factor = max(max(r["realised_over_predicted"], 1 / r["realised_over_predicted"]) for r in rows.values())
    verdict = {"recommended": res.best.name, "best_standard_realised": best_std,
               "recommended_beats_best_standard": rows[res.best.name]["realised_rmse_m"] < rows[best_std]["realised_rmse_m"],
               "predicted_vs_realised_factor": factor}
    (out / "ranking_closed_check.md").write_text(res.table() + "\n")
    table = md_table(rows, ["duration_s", "predicted_sd_m", "realised_rmse_m", "mean_error_m",
                            "realised_over_predicted", "predicted_at_truth_m", "converged"], first="trial",
                     headers={"duration_s": "duration [s]", "predicted_sd_m": "predicted sd after [m]",
                              "realised_rmse_m": "realised RMSE [m]", "mean_error_m": "mean error [m]",
                              "realised_over_predicted": "realised / predicted",
                              "predicted_at_truth_m": "sd predicted at the true ship [m]",
                              "converged": "fits converged"})
    (out / "closed_check.md").write_text(table + "\n")
    with figure(out / "fig_closed_check.png", 1, 2, figsize=(12, 4.5)) as (fig, (a, b)):
        names = list(rows)
        x = np.arange(len(names))
        a.bar(x - 0.2, [rows[n]["predicted_sd_m"] for n in names], 0.4, label="predicted sd after")
        a.bar(x + 0.2, [rows[n]["realised_rmse_m"] for n in names], 0.4, label="realised RMSE")
        a.axhline(abs(prior_error), color="k", ls="--", label="error of the prior prediction")
        a.set_yscale("log")
        a.set_xticks(x, names, rotation=30, ha="right")
        a.set_ylabel(f"error of {res.target.name} [m]")
        a.legend()
        free = res.trials["free"]
        b.step(free.t[:-1], np.degrees(free.rudder), where="post")
        b.set_xlabel("t [s]")
        b.set_ylabel("rudder [deg]")
        b.set_title("the recommended free trial")
    free.to_csv(out / "free_trial.csv", design)
    rep.section("Part 2: closed check on a known ship")
    rep.add(f"True ship: hull derivatives moved by one draw from the prior (seed {TRUTH_SEED}), asymmetry "
            + ", ".join(f"{k} = {v:.4g}" for k, v in ASYMMETRY.items())
            + f". Target {res.target.name}: true {g_true:.4g} m, predicted by the prior {res.target.value:.4g} m "
            f"(error {prior_error:+.4g} m, prior sd {res.rows[0]['sd_before']:.4g} m). Sensor noise: "
            + ", ".join(f"{k} {v:.3g}" for k, v in NOISE.items()) + f" (SI, rad) per {dt:g} s sample; "
            f"{cfg['seeds']} noise seeds per trial.")
    rep.add("Design ranking (at the prior mean):", res.table())
    rep.add("Realised against predicted:", table, "![closed check](fig_closed_check.png)")
    rep.add("The last column linearises at the true ship instead of the prior mean: where it is close to the "
            "realised RMSE and the design's prediction is not, the difference is the linearisation point (a trial "
            "designed at the prior mean teaches less on a ship that is not there), not the noise model.")
    rep.add(f"The recommended trial ({res.best.name}) {'reduces' if verdict['recommended_beats_best_standard'] else 'does NOT reduce'} "
            f"the target's error more than the best standard manoeuvre ({best_std}); realised RMSE and predicted "
            f"standard deviation agree within a factor {factor:.3g} over the trials checked.")
    return {"target": res.target.name, "true_value": g_true, "prior_value": res.target.value, "rows": rows,
            "verdict": verdict, "ranking": res.rows, "free": res.free}


def run(out: Path, quick: bool = False, workers=None, scheduler=None, data_dir: Path | None = None,
        params: Path | None = None) -> dict:
    """Part 1 on the fitted ship, part 2's closed check.

    Part 1 runs the registered ``kvlcc2-marin`` study into ``out/kvlcc2-marin`` and designs on its
    ``fit.json``, or on the fit file ``params`` when given (no data needed then). ``quick``: the
    quick fit and no free trial in part 1, a coarser step, two trials and 3 seeds in part 2.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    cfg = QUICK if quick else FULL
    t0 = time.perf_counter()
    rep = Report("Trial design: the next manoeuvre for the KVLCC2", quick=quick)
    rep.add("The expected information of each trial comes from the exact sensitivities of its simulated outputs "
            "through the output-error likelihood; added to the current belief, it gives the target's standard "
            "deviation after the trial by the delta method (see docs/trial-design.md).")
    rep.section("Part 1: the next trial for the fitted KVLCC2")
    fit_file = Path(params) if params is not None else kvlcc2_marin_fit(out / "kvlcc2-marin", data_dir, quick,
                                                                          workers, scheduler)
    t_fit = time.perf_counter() - t0
    if fit_file is None:
        rep.add("Skipped: no measured data (give --data DIR or set CASSHIP_DATA).")
        part1 = None
    else:
        if params is None:
            rep.add(f"The fit is the `kvlcc2-marin` study's on the shared runs, run here into `kvlcc2-marin/` "
                    f"({t_fit:.0f} s; its report is there).")
        part1 = design_on_fit(fit_file, out, rep, dt=cfg["dt"], max_iter=cfg.get("max_iter_fitted", 0),
                              free=not quick)
    t1 = time.perf_counter()
    part2 = _closed_check(out, quick, cfg, workers, scheduler, rep)
    seconds = time.perf_counter() - t0
    rep.add(f"Run time: {seconds:.0f} s (part 1 {t1 - t0:.0f} s, part 2 {seconds - t1 + t0:.0f} s).")
    rep.departures([
        Departure("paper", "this study reproduces no paper", "the choices it makes are listed here",
                  "not applicable"),
        Departure("true ship", "-", "one seeded draw from the prior for 8 hull derivatives, a stated asymmetry",
                  "another draw changes the true target and the prior's error; the ranking does not depend on it"),
        Departure("belief of part 1", "-", "the covariance the fit file carries (the kvlcc2-marin study's run-level "
                  "jackknife when it has one) and this study's prior for the parameters it does not cover "
                  "(independent of them)", "not measured"),
        Departure("trial record", "-", f"rudder sampled at mid-step and held over each {cfg['dt']:g} s step, the "
                  "same discretisation in truth and fit", "not measured"),
    ])
    rep.write(out)
    summary = {"study": "trial-design", "quick": quick, "seconds": seconds, "seconds_fit": t_fit, "fitted_ship": part1,
               "closed_check": part2}
    return write_json(out / "summary.json", summary)


STUDY = Study("trial-design", "Which next trial best resolves the KVLCC2's turning circle and its asymmetry; a "
              "closed check by simulation on a known ship (Monte Carlo over noise seeds)", run)
