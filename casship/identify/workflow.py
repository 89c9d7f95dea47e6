"""The ship identification workflow as one call: :func:`identify_ship`.

What the KVLCC2 studies and the tutorial do by hand, with every choice returned and printed with
its reason (:attr:`ShipFit.choices`). On free-running records of a manoeuvring model:

1. **Propulsion first.** Values fitted to measured thrust before the manoeuvring fit are applied
   (``propulsion=``); the measured propeller rate drives every replay. The straight-run resistance
   ``R_0'`` starts at the value that holds each record's approach speed at its measured rate (the
   surge equation is linear in it), and is a candidate of the free set like any other parameter.
2. **Smooth and regress a start.** EKF + RTS smoothing of the pose into ``u, v, r`` and their rates,
   then the coefficients the model is linear in by regularised least squares
   (:func:`~casship.identify.inverse_dynamics`): *starting guesses only*, used when they lower the cost.
3. **A cost that weighs by a stated rule.** Each channel's ``sigma`` is its RMS error at the preset
   times the square root of its integrated autocorrelation time (``N`` correlated samples count as
   their ``N / tau`` effective ones), so no channel's size decides the fit (surge cannot swallow
   yaw); each record counts the same however long it is (``record_weights = N_mean / N_r``).
4. **Priors around the preset** with its stated uncertainty (:data:`PRESET_UNCERTAINTY`: linear hull
   derivatives 20 %, cubic 50 %, resistance 30 %, rudder and interaction factors 20-30 %, added
   masses 20 %, a neutral angle 1 deg).
5. **Asymmetry only from mirrored evidence.** Port/starboard terms (the propeller-induced side force
   and yaw moment) and direction-switched coefficients (``gamma_R_plus/minus``) are estimated on
   the records that form mirror pairs within one facility and nothing else. The rudder neutral
   angle ``delta_0`` is a facility's, not the ship's: one value per facility with a pair, pooled
   hierarchically (:func:`pool_facilities`: a population value and a between-facility spread); a
   record from a facility without a value is run at the population value. The direction-switched
   coefficients are the rudder's ``gamma_R_plus/minus`` and the wake's ``C_2_plus/minus``.

   **Facility quantities, the rule.** A quantity of a facility's model, rudder or propeller set
   (the neutral angle, a wake measured behind one facility's model: ``facility_values=``, the
   rudder's own :data:`RUDDER` candidates) is that facility's: never applied as exact to a record
   of another facility. The rudder's are free per facility (``epsilon@HSVA``) under the run-level
   rule like any candidate. Each is pooled over the facilities that have a value (population prior:
   the preset value with its stated uncertainty; between-facility spread: the same stated
   uncertainty, :data:`NEUTRAL_SPREAD` for the neutral angle), and a record of a facility without
   its own value runs at the population value in a replay (in the fit: a measured value's
   population value, a rudder quantity's preset), with ``sqrt(var(population) + spread^2)`` in its
   band.
6. **The free set from run-level evidence** (:meth:`~casship.identify.Identifiability.propose`,
   ``evidence="runs"``): greedy D-optimal forward selection admitting a quantity only while every
   chosen one has a posterior/prior standard deviation at most 0.5, where the standard deviation is
   the larger of the model-based one and the spread of the leave-one-run-out estimates (a
   linearised jackknife over the records, or over blocks of them when there are fewer than four).
   Chosen at the preset, refined, chosen again at that estimate (where the replays follow the
   runs) and refined again.

``free=``, ``weights=`` and ``prior=`` override steps 6, 3 and 4.
"""
from __future__ import annotations

import math
import time
import warnings
from typing import Mapping, Sequence

import numpy as np

from ..errors import InputError
from .asymmetry import mirror_pairs
from .identifiability import MAX_CORR, MAX_RATIO, RunEvidence
from .inverse_dynamics import inverse_dynamics, smooth_trial
from .output_error import OutputErrorProblem
from .prior import Prior
from .records import facility_of, record_label
from .result import IdentificationWarning
from .runlevel import MEASURED, approach_resistance, resample, run_evidence
from .shipfit import ShipFit, pool_facilities
from .uncertainty import effective_samples

__all__ = ["identify_ship", "ShipFit", "PRESET_UNCERTAINTY", "preset_prior_std", "run_evidence", "pool_facilities",
           "resample", "approach_resistance", "CANDIDATES", "ASYMMETRY", "DIRECTION_SWITCHED", "RUDDER", "MEASURED"]

HULL_LINEAR = ("Y_v_dash", "Y_r_dash", "N_v_dash", "N_r_dash")
HULL_CUBIC = ("Y_vvv_dash", "Y_vvr_dash", "Y_vrr_dash", "Y_rrr_dash", "N_vvv_dash", "N_vvr_dash", "N_vrr_dash",
              "N_rrr_dash", "X_vv_dash", "X_vr_dash", "X_rr_dash", "X_vvvv_dash")
#: Port/starboard terms of the ship (estimated on mirror pairs only, applied to every record).
ASYMMETRY = ("Y_0_dash", "N_0_dash")
#: The rudder neutral angle: a facility's quantity (its model and rudder), pooled over facilities.
FACILITY = ("delta_0",)
#: The rudder's own quantities (a facility's model rudder: its inflow factor, the propeller race's
#: straightening, its lift gradient; :data:`casship.identify.captive.FACILITY_PARAMS`): candidates
#: estimated per facility (``name@facility``) and pooled over facilities.
RUDDER = ("epsilon", "kappa", "f_alpha")
#: Coefficients that switch with the sign of a drift angle (rudder flow straightening, wake change in
#: manoeuvring): from mirrored evidence only.
DIRECTION_SWITCHED = ("gamma_R_plus", "gamma_R_minus", "C_2_plus", "C_2_minus")
#: Candidates of the free set (those the model has).
CANDIDATES = (*HULL_LINEAR, *HULL_CUBIC, "R_0_dash", "l_R_dash", "epsilon", "kappa", "f_alpha", "a_H", "x_H_dash",
              "t_R", "m_x_dash", "m_y_dash", "J_z_dash")
#: Coefficients the inverse-dynamics start regresses (those the model has).
REGRESSED = (*HULL_LINEAR, *HULL_CUBIC, "f_alpha")
#: Outputs of the cost when the records hold them.
#: The preset's stated uncertainty: relative prior standard deviations (``rel``), absolute ones
#: (``abs``) and floors, by parameter.
PRESET_UNCERTAINTY = {
    "rel": {**{k: 0.2 for k in HULL_LINEAR}, **{k: 0.5 for k in HULL_CUBIC}, "R_0_dash": 0.3,
            "gamma_R_minus": 0.25, "gamma_R_plus": 0.25, "l_R_dash": 0.2, "epsilon": 0.2, "kappa": 0.2,
            "f_alpha": 0.2, "a_H": 0.3, "x_H_dash": 0.2, "t_R": 0.3, "m_x_dash": 0.2, "m_y_dash": 0.2,
            "J_z_dash": 0.2, "w_P0": 0.2, "t_P": 0.2, "C_1": 0.3, "C_2_plus": 0.2, "C_2_minus": 0.2},
    "abs": {"delta_0": math.radians(1.0), "Y_0_dash": 0.05, "N_0_dash": 0.025},
    "floor": {"X_vr_dash": 0.01},
}
#: Smoother settings by default: positions, heading and the speed and yaw-rate columns a record holds,
#: with the resolution of a full-scale trial log printed to three digits.
SMOOTHER_SIGMA = {"x": 3.0, "y": 3.0, "psi": math.radians(0.3), "u": 0.01, "r": math.radians(0.002)}
JERK = {"u": 1e-3, "v": 1e-3, "r": 1e-5}
NEUTRAL_SPREAD = math.radians(1.0)   # between-facility spread of a neutral angle (its stated uncertainty)


def preset_prior_std(model, names: Sequence[str], override: Mapping[str, float] | None = None) -> dict:
    """Prior standard deviation of each named parameter: ``override`` first, else
    :data:`PRESET_UNCERTAINTY` (relative to the preset value, or absolute).

    Parameters
    ----------
    model : Model
    names : sequence of str
        The parameters.
    override : mapping name -> std, optional
        Standard deviations that take precedence.

    Raises
    ------
    InputError
        For a name the rule does not cover and ``override`` does not give.
    """
    nominal = model.param_dict()
    override = dict(override or {})
    out = {}
    for n in names:
        base = n.split("@")[0]
        if base in override:
            out[n] = float(override[base])
        elif base in PRESET_UNCERTAINTY["abs"]:
            out[n] = PRESET_UNCERTAINTY["abs"][base]
        elif base in PRESET_UNCERTAINTY["rel"] and nominal[base] != 0:
            out[n] = max(PRESET_UNCERTAINTY["rel"][base] * abs(nominal[base]), PRESET_UNCERTAINTY["floor"].get(base, 0))
        else:
            raise InputError(f"no stated prior uncertainty for {base!r}: give it (prior={{{base!r}: std}})")
    return out


def _labels(records, facility) -> list[str]:
    if facility is None:
        return [facility_of(r) for r in records]
    if isinstance(facility, str):
        return [facility] * len(records)
    labels = [str(f) for f in facility]
    if len(labels) != len(records):
        raise InputError(f"facility: {len(labels)} labels for {len(records)} records")
    return labels


def _with_rudder_offset(record, offset: float):
    return record.with_columns(delta=np.asarray(record["delta"], dtype=float) - offset) if offset else record


def identify_ship(records, model="kvlcc2", *, free: Sequence[str] | None = None,
                  weights: Mapping[str, float] | None = None, prior: Mapping[str, float] | None = None,
                  candidates: Sequence[str] | None = None, measured: Sequence[str] | None = None,
                  facility=None, propulsion: Mapping[str, float] | None = None,
                  facility_values: Mapping[str, Mapping[str, tuple]] | None = None, smoothed=None, dt: float = 2.0,
                  max_ratio: float = MAX_RATIO, max_corr: float = MAX_CORR, max_free: int = 15, passes: int = 2,
                  record_weights: str = "equal", reweigh: bool = True, terms=None, show: bool = False, verbose: bool = False,
                  verdict: str | None = "loo") -> ShipFit:
    """Identify a ship from free-running records by the workflow of the module text, in one call.

    Parameters
    ----------
    records : Dataset or sequence of Dataset
        Free-running records (SI units, radians) with the model's inputs and some of its outputs.
    model : str or Model
        A registered model name or a model (its parameter values are the preset).
    free : sequence of str, optional
        The free set (skips the run-level choice).
    weights : mapping output -> sigma, optional
        Channel standard deviations of the cost (else the stated rule).
    prior : mapping name -> std, optional
        Prior standard deviations that override :data:`PRESET_UNCERTAINTY`.
    candidates : sequence of str, optional
        Candidates of the free set (default :data:`CANDIDATES` the model has, and the mirror-pair
        terms when the records hold pairs; for a model with none of them, the names of ``prior``).
    measured : sequence of str, optional
        Outputs of the cost (default :data:`MEASURED` that every record holds).
    facility : str or sequence of str, optional
        Facility of each record (default ``meta["facility"]``, else one facility).
    propulsion : mapping name -> value, optional
        Values set before the fit for every record (e.g. a propeller's open-water thrust curve).
    facility_values : mapping name -> (mapping facility -> (value, standard error)), optional
        Quantities measured per facility before the fit (e.g. a wake fitted to one facility's
        measured thrust): each facility's records run at its own value, records of other facilities
        at the population value of :func:`pool_facilities` (prior and between-facility spread: the
        quantity's stated uncertainty), with that spread in their replays' band.
    smoothed : sequence of Dataset, optional
        Smoothed records with ``u_dot, v_dot, r_dot`` (else smoothed here, when they hold ``x, y, psi``).
    dt : float
        Sampling period of the fit records [s].
    max_ratio, max_corr, max_free, passes
        The selection rule (posterior/prior std, correlation, count) and how often it is applied.
    record_weights : {"equal", "samples"}
        Each record the same weight (default), or each sample.
    reweigh : bool
        Re-estimate the channel sigmas (same rule) at the estimate before each later choice.
    terms : sequence of CostTerm, optional
        Further evidence joined to the records in one objective (e.g. captive tests,
        :meth:`~casship.identify.CaptiveProblem.cost_term`): its shared quantities become candidates,
        its information counts in every replicate of the run-level rule (never left out), the
        refinements are :class:`~casship.identify.JointProblem` fits (its facility's own quantities,
        ``name@facility``, free beside the chosen set; the shared ones not chosen held at one value
        for both).
    show, verbose : bool
        Solver progress; print each choice as it is made.
    verdict : {"loo", "replay"} or None
        Judge the result (:func:`casship.identify.verdict.judge_records`): its records replayed with
        the ship's parameters against the preset, and with ``"loo"`` (default) each record replayed by
        the workflow run without it; sets ``fit.verdict`` and ``fit.model_discrepancy`` (the heading
        discrepancy its replays draw in the predictive band). None: not judged.

    Returns
    -------
    ShipFit
        ``fit`` (FitResult), ``choices`` (step, choice, reason), ``summary()``, ``to_json(path)``.

    Examples
    --------
    >>> fit = cs.identify_ship([zz10], model="kvlcc2")     # doctest: +SKIP
    >>> print(fit.summary())                                 # doctest: +SKIP
    """
    from ..data import Dataset
    from ..models import get_model

    t0 = time.perf_counter()
    if isinstance(records, Dataset):
        records = [records]
    records = list(records)
    if not records:
        raise InputError("identify_ship: no records")
    model = get_model(model) if isinstance(model, str) else model
    names = set(model.param_names)
    choices = []

    def note(step, choice, reason):
        choices.append({"step": step, "choice": choice, "reason": reason})
        if verbose:
            print(f"[{step}] {choice}\n    because {reason}", flush=True)

    fac = _labels(records, facility)
    inputs = list(model.input_names)
    for i, r in enumerate(records):
        missing = [n for n in inputs if n not in r]
        if missing:
            raise InputError(f"record {i} lacks the input column(s) {missing} of {model.name!r}")
    if measured is None:
        measured = [n for n in MEASURED if n in model.output_names and all(n in r for r in records)]
        if not measured:
            measured = [n for n in model.output_names if all(n in r for r in records)]
        note("cost", f"outputs {', '.join(measured)}", "the outputs every record holds (heading, yaw rate, speeds, "
             "track where present)")
    measured = list(measured)
    if not measured:
        raise InputError(f"no output of {model.name!r} {list(model.output_names)} is a column of every record")

    # 1. propulsion
    preset = {k: float(v) for k, v in dict(propulsion or {}).items()}
    unknown = sorted(set(preset) - names)
    if unknown:
        raise InputError(f"propulsion: {unknown} are not parameters of {model.name!r}")
    if preset:
        note("propulsion", ", ".join(f"{k} = {v:.4g}" for k, v in preset.items()),
             "fitted to measured thrust before the manoeuvring fit (given)")
    else:
        note("propulsion", "the preset propeller", "no propeller values fitted to measured thrust were given")
    # facility quantities measured before the fit: pooled, each record at its facility's value
    measured_pools = {}
    for q, by_fac in dict(facility_values or {}).items():
        if q not in names:
            raise InputError(f"facility_values: {q!r} is not a parameter of {model.name!r}")
        if q in preset:
            raise InputError(f"facility_values: {q!r} is also given in propulsion= (one value for every record)")
        std = preset_prior_std(model, [q], prior)[q]
        est = {str(f): (float(v), float(se)) for f, (v, se) in dict(by_fac).items()}
        measured_pools[q] = pool_facilities(est, spread=std, prior_std=std, prior_mean=model.param_dict()[q])
    population = {q: float(pool["population"]) for q, pool in measured_pools.items()}

    def facility_value(q, lab):
        own = measured_pools[q]["facilities"].get(lab)
        return own["value"] if own else measured_pools[q]["population"]

    own_values = [{q: facility_value(q, lab) for q in measured_pools} for lab in fac]
    record_params = own_values if measured_pools else None
    if measured_pools:
        note("facility", "; ".join(
            f"{q}: " + ", ".join(f"{f} {v['value']:.4g}" for f, v in pool["facilities"].items())
            + f", population {pool['population']:.4g} +- {pool['new_facility_std']:.3g} (records of "
            + (", ".join(sorted(set(fac) - set(pool["facilities"]))) or "no other facility") + ")"
            for q, pool in measured_pools.items()),
            "a quantity measured in one facility (its model, rudder or propeller) is that facility's: pooled over "
            "the facilities that measured it with a between-facility spread equal to its stated uncertainty; "
            "records of another facility run at the population value, never at another facility's value")
    fixed = model.params({**preset, **population})
    start = {}
    if "R_0_dash" in names and "n" in inputs and all("u" in r for r in records):
        r0s = []
        for i, (r, own) in enumerate(zip(records, own_values)):
            try:
                r0s.append(approach_resistance(model, r, model.params({**preset, **own})))
            except InputError as exc:           # which record is no manoeuvre
                raise InputError(f"record {record_label(r, i)}: {exc}") from None
        r0 = float(np.mean(r0s))
        start["R_0_dash"] = r0
        note("propulsion", f"R_0' starts at {r0:.4g} (preset {model.param_dict()['R_0_dash']:.4g})",
             "the value that holds the records' approach speeds at their measured propeller rates (mean over "
             "records); a candidate with a 30 % prior, not a silent trim")

    # 2. smooth and regress a start
    regress = [n for n in REGRESSED if n in names]
    if regress and smoothed is None and all(all(c in r for c in ("x", "y", "psi")) for r in records):
        smoothed = []
        for r in records:
            chans = [c for c in ("x", "y", "psi", "u", "r") if c in r]
            smoothed.append(smooth_trial(resample(r, 1.0, outputs=chans, inputs=inputs), SMOOTHER_SIGMA, JERK,
                                         measured=chans))
    if regress and smoothed is not None:
        pstd = preset_prior_std(model, regress, prior)
        idfit = inverse_dynamics(model, list(smoothed), regress, params=model.params({**preset, **start}),
                                 prior=pstd, autocorrelation=True)
        start.update({k: float(v) for k, v in idfit.estimates.items()})
        note("start", f"inverse dynamics on {len(regress)} coefficients",
             "the model is linear in them: one regularised least-squares solve on the smoothed accelerations "
             "gives starting guesses (used only where they lower the cost; nothing is moved by them)")
    else:
        note("start", "the preset", "no pose (x, y, psi) to smooth, or no coefficient the model is linear in")

    recs = [resample(r, dt, outputs=measured, inputs=inputs) for r in records]
    note("cost", f"records resampled every {dt:g} s", "inputs averaged over each interval (the zero-order hold of "
         "the full-rate signals), outputs sampled: the fit's time step")
    rw = (np.full(len(recs), 1.0) if record_weights == "samples" else
          np.mean([len(r) for r in recs]) / np.array([len(r) for r in recs], dtype=float))
    note("cost", "record weights " + ("1 (every sample the same)" if record_weights == "samples" else
                                      "N_mean / N_r (every record the same)"),
         "a long record (a turning circle) must not swamp the short ones" if record_weights != "samples"
         else "asked for")

    # candidates and the prior
    if candidates is None and not any(c in names for c in CANDIDATES):
        if not prior:
            raise InputError(f"the ship workflow has no candidates among the parameters of {model.name!r}: give "
                             "the candidates (candidates=, or their prior: prior= / --prior name=std), or the free "
                             "set (free= / --free)")
        candidates = list(prior)
        note("candidates", ", ".join(candidates), f"the parameters given a prior ({model.name!r} has none of the "
             "workflow's manoeuvring candidates)")
    if candidates is None:
        cands = [c for c in CANDIDATES if c in names]
        asym = [c for c in (*ASYMMETRY, *DIRECTION_SWITCHED) if c in names and c not in preset
                and c not in measured_pools]
        facq = [c for c in FACILITY if c in names and c not in measured_pools]
    else:
        cands = [c for c in candidates if c not in (*ASYMMETRY, *DIRECTION_SWITCHED, *FACILITY)]
        asym = [c for c in candidates if c in (*ASYMMETRY, *DIRECTION_SWITCHED)]
        facq = [c for c in candidates if c in FACILITY]
        bad = sorted(set(candidates) - names)
        if bad:
            raise InputError(f"candidates: {bad} are not parameters of {model.name!r}")
    if free is not None:
        bad = sorted(set(free) - names)
        if bad:
            raise InputError(f"free: {bad} are not parameters of {model.name!r}")
    terms = list(terms or ())
    if terms:
        shared = [n for t in terms for n in t.names if "@" not in n and n in names and n not in preset
                  and n not in measured_pools]
        extra = [n for n in dict.fromkeys(shared) if n not in cands and n not in facq and n not in asym]
        cands = [*cands, *extra]
        note("joined evidence", ", ".join(f"{t.label} ({t.n_obs} values)" for t in terms),
             "one objective with the records: one set of hull coefficients, each facility its own quantities; "
             + (f"its shared quantities {', '.join(extra)} become candidates" if extra else "no new candidates"))
    all_std = preset_prior_std(model, list(dict.fromkeys([*cands, *asym, *facq, *(free or ())])), prior)
    if prior:
        note("prior", ", ".join(f"{k} std {v:.3g}" for k, v in prior.items()), "given (overrides the stated rule)")
    note("prior", "Gaussian about the preset: linear hull derivatives 20 %, cubic 50 %, R_0' 30 %, rudder and "
         "interaction factors 20-30 %, added masses 20 %, neutral angle 1 deg",
         "the preset's stated uncertainty (PRESET_UNCERTAINTY): the data move a value only as far as they "
         "outweigh it")

    at0 = {k: float(v) for k, v in zip(model.param_names, fixed)}
    # channel weights
    if weights:
        sigma = {c: float(weights[c]) for c in measured if c in weights}
        rest = [c for c in measured if c not in sigma]
        note("cost", "channel sigmas " + ", ".join(f"{k} {v:.3g}" for k, v in sigma.items()), "given")
    else:
        sigma, rest = {}, list(measured)
    def channel_sigma(rs, params, where, own=None):
        own = record_params if own is None else own
        taken = {n for o in (own or []) for n in (o or {})}      # the one free value must not hide a record's own
        dummy = next(n for n in model.param_names if n not in taken)
        unit = OutputErrorProblem(model, rs, [dummy], measured=measured, sigma={c: 1.0 for c in measured},
                                  params=params, record_params=own)
        res = unit.residuals()           # at params (the one free value at its fixed value)
        neff = effective_samples(res, measured)
        out = {c: float(np.sqrt(sum(np.nansum(e[:, j] ** 2) for e in res) / max(neff[c]["n_eff"], 1.0)))
               for j, c in enumerate(measured) if c in rest}
        note("cost", "channel sigmas " + ", ".join(f"{k} {out[k]:.3g}" for k in rest),
             f"each channel's RMS error at {where} times sqrt of its autocorrelation time: every channel counts by "
             "its effective samples, none by its size (surge cannot swallow yaw)")
        return out

    if rest:
        sigma.update(channel_sigma(recs, fixed, "the preset"))

    def problem(rs, names_free, params, share=None, weights_=None, which=None):
        pri = {n: all_std[n.split("@")[0]] for n in names_free}
        own = None if record_params is None else [record_params[i] for i in (which or range(len(rs)))]
        return OutputErrorProblem(model, rs, names_free, measured=measured, sigma=sigma, params=params,
                                  prior=Prior(pri), record_weights=weights_, record_params=own,
                                  scale={k: v for k, v in PRESET_UNCERTAINTY["abs"].items() if k in names_free},
                                  share=share)

    def refine(prob, chosen, at, guess_pool, join=False):
        from .cost_term import JointProblem

        if join and terms:
            prob = JointProblem(prob, terms, hold_fixed=True)
        # a facility's copy starts from its own previous value where there is one
        guess_id = {q: guess_pool.get(q, guess_pool.get(q.split("@")[0], at.get(q, at[q.split("@")[0]])))
                    for q in chosen}
        preset_guess = {q: at.get(q, at[q.split("@")[0]]) for q in chosen}
        use = bool(chosen) and prob.cost(guess_id) < prob.cost(preset_guess)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", IdentificationWarning)
            # the stages are not judged one by one: the workflow's result is (identify_ship(verdict=...))
            extra = {} if isinstance(prob, JointProblem) else {"verdict": None}
            return prob.solve(guess=guess_id if use else None, show=show, **extra), use

    def with_terms(idf, prob, point):
        """The identifiability with the joined evidence in its information and in every replicate."""
        if not terms:
            return idf
        import dataclasses

        fixed_p = dict(zip(model.param_names, np.asarray(prob.space.params(prob.space.theta(point))).ravel()))
        k = len(prob.free)
        Fc, gc = np.zeros((k, k)), np.zeros(k)
        for t in terms:
            vals = np.array([point.get(n, fixed_p.get(n, t.start[j])) for j, n in enumerate(t.names)])
            r, J = t.residual(vals)
            cols = [(j, prob.free.index(n)) for j, n in enumerate(t.names) if n in prob.free]
            jt, jp = [c[0] for c in cols], [c[1] for c in cols]
            Fc[np.ix_(jp, jp)] += J[:, jt].T @ J[:, jt]
            gc[jp] += J[:, jt].T @ r
        ev = idf.evidence
        ev = RunEvidence(ev.labels, ev.information, ev.gradient, ev.prior_gradient, ev.kind, Fc, gc)
        return dataclasses.replace(idf, information=idf.information + Fc, evidence=ev)

    # 5. asymmetry and facility quantities from mirror pairs
    pairs = mirror_pairs(recs, within=fac) if (asym or facq) and all("delta" in r for r in recs) else []
    paired = sorted({i for p in pairs for i in p})
    asym_values, asym_fit, pools, offsets, unpinned = {}, None, {}, {}, {}
    if free is None and (asym or facq):
        if not paired:
            unpinned = {q: all_std[q] for q in asym}
            for q in facq:
                pools[q] = pool_facilities({}, spread=NEUTRAL_SPREAD, prior_std=all_std[q])
            note("asymmetry", f"{', '.join([*asym, *facq])} at the preset, with their prior uncertainty in the bands",
                 "no mirror pair (the same manoeuvre turning first to both sides) within a facility: a "
                 "port/starboard term fitted on these records would absorb the turning dynamics, and a run "
                 "turning the other way (or of another facility) is predicted with what the prior knows")
        else:
            sub = [recs[i] for i in paired]
            labs = [fac[i] for i in paired]
            share = {q: labs for q in facq} or None
            names_a = [*cands, *asym, *facq]
            prob_a = problem(sub, names_a, fixed, share=share, which=paired, weights_=np.mean([len(r) for r in sub]) /
                             np.array([len(r) for r in sub], dtype=float))
            at_a = {q: at0[q.split("@")[0]] for q in prob_a.free}
            idf = prob_a.identifiability(at=at_a, pairs_within=labs)
            idf.evidence = run_evidence(prob_a, at_a)
            chosen, rows = idf.propose(max_ratio=max_ratio, max_corr=max_corr, max_count=max_free,
                                       evidence="runs", explain=True, candidates=prob_a.free, keep=[])
            declared = list(dict.fromkeys(q.split("@")[0] for q in chosen))
            prob_a2 = problem(sub, declared, fixed, share={q: [lab if f"{q}@{lab}" in chosen else None for lab in labs]
                                                           for q in facq if q in declared} or None,
                              weights_=prob_a.record_weights, which=paired)
            asym_fit, _ = refine(prob_a2, chosen, at0, start)
            asym_values = {q: float(asym_fit.estimates[q]) for q in chosen if q in asym}
            pair_names = ", ".join(str(r.meta.get("name", f"record {i}")) for i, r in zip(paired, sub))
            note("asymmetry", ("applied: " + ", ".join(f"{k} = {v:.4g}" for k, v in asym_values.items()))
                 if asym_values else "no ship asymmetry term chosen",
                 f"estimated on the mirror-pair records only ({pair_names}), free set by the run-level rule; "
                 "every other estimate of that stage is discarded")
            for q in facq:
                est = {lab: (float(asym_fit.estimates[f"{q}@{lab}"]), float(asym_fit.std_errors[f"{q}@{lab}"]))
                       for lab in sorted(set(labs)) if f"{q}@{lab}" in asym_fit.estimates}
                pools[q] = pool_facilities(est, spread=NEUTRAL_SPREAD, prior_std=all_std[q])
                note("facility", f"{q}: " + (", ".join(f"{k} {math.degrees(v[0]):.3g} deg" for k, v in est.items())
                                              or "no facility estimate") +
                     f"; population {math.degrees(pools[q]['population']):.3g} deg, a new facility +- "
                     f"{math.degrees(pools[q]['new_facility_std']):.3g} deg",
                     "a neutral angle belongs to a facility's model and rudder: one value per facility with a "
                     "mirror pair, pooled with a between-facility spread of 1 deg; records of other facilities "
                     "run at the population value")
            if "delta_0" in pools:
                for lab in set(fac):
                    own = pools["delta_0"]["facilities"].get(lab)
                    offsets[lab] = own["value"] if own else pools["delta_0"]["population"]
    fixed = model.params({**preset, **population, **asym_values})
    recs_b = [_with_rudder_offset(r, offsets.get(f, 0.0)) for r, f in zip(recs, fac)]

    # 6. the free set and the refinement
    if free is not None:
        chosen, rows, first = list(free), [], list(free)
        note("free set", ", ".join(chosen), "given (--free)")
        fit, use = refine(problem(recs_b, chosen, fixed, weights_=rw), chosen, at0, start, join=True)
    else:
        at, guess, first, fit, rows = dict(at0), dict(start), [], None, []
        # the rudder's own quantities: one copy per facility (never one value carried across facilities)
        own_cands = [c for c in cands if c in RUDDER]
        if own_cands:
            note("facility", ", ".join(own_cands) + " per facility (" + ", ".join(sorted(set(fac))) + ")",
                 "the rudder's own quantities belong to a facility's model rudder: a copy per facility, each chosen "
                 "by the run-level rule like any candidate, pooled over facilities after the fit")
        for k in range(max(1, passes)):
            if k > 0 and rest and reweigh:
                own_at = [{**(record_params[i] if record_params else {}),
                           **{q: at[f"{q}@{lab}"] for q in own_cands if f"{q}@{lab}" in at}} for i, lab in enumerate(fac)]
                sigma.update(channel_sigma(recs_b, model.params({**dict(zip(model.param_names, fixed)), **{
                    q: at[q] for q in cands}}), "the previous estimate", own_at))
            prob = problem(recs_b, cands, fixed, weights_=rw, share={q: list(fac) for q in own_cands} or None)
            point = {q: at.get(q, at[q.split("@")[0]]) for q in prob.free}
            idf = prob.identifiability(at=point)
            idf.evidence = run_evidence(prob, point)
            idf = with_terms(idf, prob, point)
            chosen, rows = idf.propose(max_ratio=max_ratio, max_corr=max_corr, max_count=max_free, evidence="runs",
                                       explain=True, candidates=prob.free, keep=[])
            where = "the preset" if k == 0 else "the previous estimate"
            note("free set", ", ".join(chosen) or "nothing",
                 f"chosen at {where} by run-level evidence ({idf.evidence.kind}, {len(idf.evidence.labels)} units): "
                 f"each admitted while every chosen one's posterior/prior std (the larger of the model-based and "
                 f"the leave-one-{'run' if idf.evidence.kind == 'records' else 'block'}-out spread) is <= "
                 f"{max_ratio:g} and no two correlate beyond {max_corr:g}")
            if k == 0:
                first = list(chosen)
            if not chosen:
                break
            declared = list(dict.fromkeys(q.split("@")[0] for q in chosen))
            copies = {q: [lab if f"{q}@{lab}" in chosen else None for lab in fac] for q in own_cands if q in declared}
            fit, use = refine(problem(recs_b, declared, fixed, weights_=rw, share=copies or None), chosen, at, guess,
                              join=True)
            note("refinement", f"MAP output error, status {fit.status}, started from the "
                 + ("inverse-dynamics values" if use else "point of the choice"),
                 "the start with the lower cost" if use else "the inverse-dynamics start did not lower the cost")
            est = {q: float(v) for q, v in fit.estimates.items() if "@" not in q or q.split("@")[0] in own_cands}
            at.update(est)
            guess.update(est)
        if fit is None:               # nothing the runs determine: a result, said as one
            from .result import IdentificationError

            raise IdentificationError(
                f"the records determine none of the candidates {cands} by the run-level rule (posterior/prior std "
                f"<= {max_ratio:g}): the preset stays; widen the prior of the quantities you expect to move "
                "(prior= / --prior) or give the free set (free= / --free)", "nothing determined")
        nominal = model.param_dict()
        for q in own_cands:
            est_q = {lab: (float(fit.estimates[f"{q}@{lab}"]), _std_error(fit, f"{q}@{lab}"))
                     for lab in sorted(set(fac)) if f"{q}@{lab}" in fit.estimates}
            if est_q:
                pools[q] = pool_facilities(est_q, spread=all_std[q], prior_std=all_std[q], prior_mean=nominal[q])
                note("facility", f"{q}: " + ", ".join(f"{lab} {v:.4g}" for lab, (v, _) in est_q.items())
                     + f"; population {pools[q]['population']:.4g} +- {pools[q]['new_facility_std']:.3g}",
                     "pooled with a between-facility spread equal to its stated uncertainty; a record of a facility "
                     "without its own value is replayed at the population value with that spread in its band")
    ship = ShipFit(fit, model, list(chosen), choices, sigma, [float(w) for w in rw], rows, first,
                   {**preset, **asym_values}, start, asym_fit, asym_values, {**measured_pools, **pools}, fac,
                   time.perf_counter() - t0,
                   unpinned)
    if verdict is not None:
        ship.judge(list(records), verdict, lambda train: identify_ship(
            [records[i] for i in train], model, free=free, weights=weights, prior=prior, candidates=candidates,
            measured=measured, facility=[fac[i] for i in train], propulsion=propulsion,
            facility_values=facility_values, dt=dt, max_ratio=max_ratio,
            max_corr=max_corr, max_free=max_free, passes=passes, record_weights=record_weights, reweigh=reweigh,
            terms=terms, verdict=None))
        note("verdict", f"{ship.fit.verdict['verdict']}: replays of the records against the preset"
             + (" and left-one-out" if verdict == "loo" and len(records) > 1 else ""), ship.fit.verdict["reason"])
    return ship


def _std_error(fit, name: str) -> float:
    """The robust standard error of a free quantity where finite (the fit file's covariance), else the
    model-based one."""
    se = fit.std_errors_robust.get(name, math.nan)
    return float(se) if np.isfinite(se) and se > 0 else float(fit.std_errors[name])
