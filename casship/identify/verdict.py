"""The verdict of a fit: is the fitted model better than the model it started from, on its own runs?

A fit that lowers its cost can still predict worse: a likelihood through a filter rewards one-step
predictions, a cost dominated by one channel (surge) lets other parameters (yaw) absorb that
channel's mismatch. :func:`judge` therefore replays every record of a fit (the measured inputs from
the measured initial state, :func:`casship.maneuvers.replay`) twice: with the **starting model**
(the parameters the problem holds before the fit: the model's own values, or ``params=``, whatever
``guess`` the solver started from) and with the fit. With several records it also refits without
each record (left-one-out) and replays the record left out: the prediction of a run the fit has not
seen. The verdict compares the mean heading RMSE:

* ``"worse"`` -- the fit's mean heading RMSE on its records exceeds the start's by more than
  :data:`WORSE_MARGIN` (relative), or the fit's replay fails where the start's does not;
* ``"stalled"`` -- not worse, but the solver did not converge (its estimates are an iterate);
* ``"better"`` -- lower heading RMSE than the start on its records and (with several records)
  left-one-out;
* ``"no better"`` -- within the margin of the start, or better on its records but worse than the
  start left-one-out (refitted without a record, the procedure predicts it worse: the records do
  not show that the fit predicts a new run better);
* ``"not judged"`` -- the records or the model hold no heading ``psi`` (nothing to compare).

``casship identify`` exits with :data:`EXIT_WORSE` for ``"worse"`` and ``"stalled"`` unless
``--accept-worse`` is given; the fit file records the verdict either way.

The same replays give the fit's **model-discrepancy** term (:func:`heading_discrepancy`): the
heading variance the parameter band misses, growing linearly with the time since the start of a
replay, ``e^2 - s^2 = q t`` by least squares (``e`` the heading error, ``s`` the parameter band's
standard deviation), floored at 0. With several records it comes from the left-one-out replays
(each fold's band, averaged over the records); with one record (or ``loo=False``) from the fit's
own replays (in-sample: optimistic, the record was fitted), inflated by :data:`IN_SAMPLE_FACTOR`
as the stated default. A replay of the fit file adds ``q t`` to the parameter band's variance
(the predictive band, never narrower than the parameter band).
"""
from __future__ import annotations

import warnings
from typing import Callable, Sequence

import numpy as np

from .params_file import Q_MAX_DEG2_PER_S
from .result import IdentificationWarning
from .records import record_label

__all__ = ["judge", "judge_records", "judge_unseen", "heading_rmse", "heading_discrepancy", "WORSE_MARGIN", "EXIT_WORSE", "IN_SAMPLE_FACTOR", "Q_MAX_DEG2_PER_S",
           "VERDICTS"]

#: Relative margin of the mean heading RMSE beyond which a fit is worse than its start.
WORSE_MARGIN = 0.02
#: Exit code of ``casship identify`` for a fit that is worse than its start or stalled.
EXIT_WORSE = 3
#: Factor on the in-sample discrepancy (one record, or no left-one-out): a replay of a record the fit
#: was fitted on errs less than one of a new run; the default widens it by this factor (stated, not fitted).
IN_SAMPLE_FACTOR = 4.0
#: The verdicts, from the worst.
VERDICTS = ("worse", "stalled", "no better", "better", "not judged")


def heading_discrepancy(t, e, s) -> float:
    """Least-squares ``q`` of ``e^2 - s^2 = q t``, floored at 0: the heading variance a band misses.

    Parameters
    ----------
    t : array_like
        Time since the start of the replay [s].
    e : array_like
        Heading error of the replay [rad] (NaN: not measured).
    s : array_like
        Standard deviation of the parameter band [rad] (0 without one).

    Returns
    -------
    float
        ``q`` [rad^2/s].

    Examples
    --------
    >>> t = np.arange(0.0, 100.0)
    >>> round(heading_discrepancy(t, np.sqrt(0.01 * t), np.zeros(100)), 6)
    0.01
    """
    t, e, s = (np.asarray(a, dtype=float) for a in (t, e, s))
    ok = np.isfinite(e) & np.isfinite(s)
    den = float(np.sum(t[ok] ** 2))
    if den <= 0:
        return 0.0
    return max(float(np.sum((e[ok] ** 2 - s[ok] ** 2) * t[ok]) / den), 0.0)


def _replay(model, data, params: dict, biases: dict, method: str, uncertainty=None):
    """Replay ``data`` with ``params`` (and the record's input/output biases); None when it fails."""
    from ..simulation import IntegrationError
    from ..maneuvers import replay
    from .crossval import debiased

    d = debiased(model, data, biases)
    try:
        res = replay(model, d, model.params(params), method=method, check_limits=False, uncertainty=uncertainty,
                     samples=0)
    except (IntegrationError, ValueError, FloatingPointError, RuntimeError):
        return None
    e = res.errors.get("psi_rmse_deg")
    if e is None or not np.isfinite(e):
        return None
    return res


def heading_rmse(model, data, params, method: str = "rk4") -> float:
    """Heading RMSE [deg] of ``data`` replayed with ``params`` from its measured start (infinite when the
    replay fails), as the verdicts count it.

    Parameters
    ----------
    model : Model
    data : Dataset
    params : mapping or array
        The parameters (the others keep the model's).
    method : str
        Integration method.

    Returns
    -------
    float
    """
    return _rmse(_replay(model, data, params, {}, method))


def _record_values(fit, r: int) -> tuple[dict, dict]:
    """The parameters and biases record ``r`` of ``fit`` is replayed with (its own copies applied)."""
    own = fit.record_params[r] if fit.record_params and r < len(fit.record_params) else {}
    params = {**fit.params, **{k: v for k, v in own.items() if k in fit.params}}
    biases = {k[5:-1]: v for k, v in own.items() if k.startswith("bias[")}
    for name, value in fit.estimates.items():      # a bias shared by every record
        if name.startswith("bias[") and "@" not in name:
            biases.setdefault(name[5:-1], value)
    return params, biases


def _new_run_values(fit) -> tuple[dict, dict]:
    """The parameters and biases a run the fit has not seen is replayed with (shared values only)."""
    biases = {n[5:-1]: v for n, v in fit.estimates.items() if n.startswith("bias[") and "@" not in n}
    return dict(fit.params), biases


def _rmse(res) -> float:
    return float("inf") if res is None else float(res.errors["psi_rmse_deg"])


def _errors(res, data):
    """``(t, e, s)`` of a replay with bands: time since the start, heading error, parameter-band std."""
    from ..angles import wrap

    tr = res.trajectory
    e = wrap(np.asarray(tr["psi"]) - np.asarray(data["psi"]))
    s = res.bands.get("psi_std", np.zeros(len(tr))) if res.bands else np.zeros(len(tr))
    return tr.t - tr.t[0], e, s


def _uncertainty(fit):
    """The fit's parameter uncertainty for the bands, or None (none free, or a covariance not finite: the
    discrepancy is then estimated against no parameter band)."""
    try:
        return fit.uncertainty()
    except ValueError:
        return None


def _mean(values) -> float:
    v = np.asarray(list(values), dtype=float)
    return float(v.mean()) if v.size else float("nan")


def judge(problem, fit, *, loo: bool | None = None, refit: Callable | None = None, guess=None, method: str = "rk4",
          solve: dict | None = None) -> tuple[dict, dict]:
    """The verdict of ``fit`` against the model ``problem`` started from, and its model discrepancy.

    Parameters
    ----------
    problem : IdentificationProblem
        The problem ``fit`` solved (its records, model and starting parameters).
    fit : FitResult
    loo : bool, optional
        Refit without each record and replay it (default: when there are several records).
    refit : callable, optional
        ``refit(train) -> FitResult`` for the record indices ``train`` (default:
        ``problem.subset(train).solve(guess=guess, verdict=None, show=False, **solve)``); a workflow
        with stages of its own passes the whole workflow here.
    guess : mapping, optional
        Starting values of the left-one-out refits.
    method : str
        Integration method of the replays.
    solve : dict, optional
        Further arguments of the refits' ``solve``.

    Returns
    -------
    (dict, dict)
        The ``verdict`` block and the ``model_discrepancy`` block of the fit (JSON-ready; see the
        module text).
    """
    start = problem.model.param_dict(problem.space.params(problem.space.theta(None)))
    if refit is None:
        def refit(train):
            return problem.subset(train).solve(guess=guess, verdict=None, show=False, **dict(solve or {}))
    return judge_records(problem.model, problem.records, fit, start=start, labels=problem.labels, loo=loo,
                         refit=refit, method=method)


def judge_records(model, records, fit, *, start=None, labels=None, loo: bool | None = None,
                  refit: Callable | None = None, method: str = "rk4") -> tuple[dict, dict]:
    """The verdict of ``fit`` on ``records`` against the model ``start`` (see :func:`judge`).

    Parameters
    ----------
    model : Model
    records : sequence of Dataset
        The records ``fit`` was fitted on.
    fit : FitResult
    start : mapping or array, optional
        The starting model's parameters (default: the model's own values).
    labels : sequence of str, optional
        Record labels (default: their ``meta["name"]`` or their index).
    loo : bool, optional
        Left-one-out (default: when there are several records; needs ``refit``).
    refit : callable, optional
        ``refit(train) -> FitResult`` on the records ``train`` (indices).
    method : str
        Integration method of the replays.

    Returns
    -------
    (dict, dict)
    """
    records = list(records)
    labels = list(labels) if labels is not None else [record_label(d, i) for i, d in enumerate(records)]
    status = fit.status
    stalled = not fit.converged
    start_p = model.param_dict(model.params() if start is None else model.params(start))
    base = {"status": status, "margin": WORSE_MARGIN,
            "start": "the parameters the problem held before the fit (the model's own values or params=)"}
    if not _has_heading(model, records):
        verdict = "stalled" if stalled else "not judged"
        reason = "the records hold no heading psi to replay" + ("; the solver did not converge" if stalled else "")
        return ({**base, "verdict": verdict, "reason": reason, "records": []},
                {"psi_variance_growth_deg2_per_s": 0.0, "method": "none (no heading in the records)"})
    unc = _uncertainty(fit)
    rows, in_sample = [], []
    for r, data in enumerate(records):
        s_res = _replay(model, data, start_p, {}, method)
        f_params, f_biases = _record_values(fit, r)
        f_res = _replay(model, data, f_params, f_biases, method, uncertainty=unc)
        rows.append({"record": labels[r], "psi_rmse_deg_start": _rmse(s_res), "psi_rmse_deg_fit": _rmse(f_res)})
        if f_res is not None:
            in_sample.append(_errors(f_res, data))
    start_mean, fit_mean = _mean(r["psi_rmse_deg_start"] for r in rows), _mean(r["psi_rmse_deg_fit"] for r in rows)
    out = {**base, "records": rows, "psi_rmse_deg_start_mean": start_mean, "psi_rmse_deg_fit_mean": fit_mean}
    loo = (len(records) > 1 if loo is None else bool(loo) and len(records) > 1) and refit is not None
    held = []
    if loo:
        loo_rows = []
        for r, data in enumerate(records):
            train = [i for i in range(len(records)) if i != r]
            with warnings.catch_warnings():     # a fold's warnings are its own (fold.warnings), not the fit's
                warnings.simplefilter("ignore", IdentificationWarning)
                fold = refit(train)
            params, biases = _new_run_values(fold)
            res = _replay(model, data, params, biases, method, uncertainty=_uncertainty(fold))
            loo_rows.append({"record": labels[r], "psi_rmse_deg_start": rows[r]["psi_rmse_deg_start"],
                             "psi_rmse_deg_held_out": _rmse(res), "fold_status": fold.status})
            if res is not None:
                held.append(_errors(res, data))
        out["loo"] = {"records": loo_rows,
                      "psi_rmse_deg_start_mean": _mean(r["psi_rmse_deg_start"] for r in loo_rows),
                      "psi_rmse_deg_held_out_mean": _mean(r["psi_rmse_deg_held_out"] for r in loo_rows)}
    out["verdict"], out["reason"] = _decide(out, stalled)
    return out, _discrepancy(held, in_sample, loo, len(records))


def judge_unseen(model, records, params, *, uncertainty=None, start=None, labels=None,
                 method: str = "rk4") -> tuple[dict, dict]:
    """The verdict of parameter values fitted on *other* evidence (captive tests) on ``records``.

    The records took no part in the fit, so every replay is out of sample: the verdict compares the
    mean heading RMSE with the start's as :func:`judge_records` does, and the model discrepancy comes
    from these replays as from left-one-out replays (no in-sample factor).

    Parameters
    ----------
    model : Model
    records : sequence of Dataset
    params : mapping name -> float
        The values judged (the others keep the model's).
    uncertainty : ParameterBelief, optional
        Their covariance (the replays' parameter band).
    start, labels, method
        As for :func:`judge_records`.

    Returns
    -------
    (dict, dict)
        The verdict block and the ``model_discrepancy`` block.
    """
    records = list(records)
    labels = list(labels) if labels is not None else [record_label(d, i) for i, d in enumerate(records)]
    start_p = model.param_dict(model.params() if start is None else model.params(start))
    values = {**model.param_dict(), **dict(params)}
    base = {"status": "converged", "margin": WORSE_MARGIN, "out_of_sample": True,
            "start": "the parameters before the fit (the model's own values)"}
    if not _has_heading(model, records):
        return ({**base, "verdict": "not judged", "reason": "the records hold no heading psi to replay", "records": []},
                {"psi_variance_growth_deg2_per_s": 0.0, "method": "none (no heading in the records)"})
    rows, held = [], []
    for label, data in zip(labels, records):
        s_res = _replay(model, data, start_p, {}, method)
        f_res = _replay(model, data, values, {}, method, uncertainty=uncertainty)
        rows.append({"record": label, "psi_rmse_deg_start": _rmse(s_res), "psi_rmse_deg_fit": _rmse(f_res)})
        if f_res is not None:
            held.append(_errors(f_res, data))
    out = {**base, "records": rows, "psi_rmse_deg_start_mean": _mean(r["psi_rmse_deg_start"] for r in rows),
           "psi_rmse_deg_fit_mean": _mean(r["psi_rmse_deg_fit"] for r in rows)}
    verdict, reason = _decide(out, stalled=False)
    out["verdict"], out["reason"] = verdict, reason + " (the records took no part in the fit: every replay is out of sample)"
    if not held:
        return out, {"psi_variance_growth_deg2_per_s": 0.0, "method": "none (no replay succeeded)"}
    return out, _q_block(held, f"out of sample over {len(held)} record{'s' if len(held) > 1 else ''} the fit did not see: "
                               "least squares of e^2 - s^2 = q t per replay (the fit's parameter band), averaged")


def _decide(out: dict, stalled: bool) -> tuple[str, str]:
    """The verdict word and its reason from the replay numbers (see the module text)."""
    limit = 1.0 + WORSE_MARGIN
    s, f = out["psi_rmse_deg_start_mean"], out["psi_rmse_deg_fit_mean"]
    if not np.isfinite(f) and np.isfinite(s):
        return "worse", "the fit's replay fails on its records where the starting model's does not"
    if np.isfinite(s) and f > limit * s:
        return "worse", (f"mean heading RMSE on its records {f:.3g} deg against {s:.3g} deg for the starting model "
                         f"(more than {100 * WORSE_MARGIN:.0f} % worse)")
    if stalled:
        return "stalled", f"the solver did not converge (status {out['status']}): the estimates are an iterate"
    text = f"mean heading RMSE on its records {f:.3g} deg against {s:.3g} deg for the starting model"
    if "loo" in out:
        ls, lf = out["loo"]["psi_rmse_deg_start_mean"], out["loo"]["psi_rmse_deg_held_out_mean"]
        loo_text = f"left-one-out {lf:.3g} deg against {ls:.3g} deg"
        if (not np.isfinite(lf) and np.isfinite(ls)) or (np.isfinite(ls) and lf > limit * ls):
            # the fit itself is better on its records, but refitted without a record the procedure predicts
            # that record worse than the start: the records do not show that it predicts a new run better
            return "no better", (f"{text}, but {loo_text} (more than {100 * WORSE_MARGIN:.0f} % worse): the records "
                                 "do not show that it predicts a new run better")
        if f < s and lf < ls:
            return "better", f"{text}; {loo_text}"
        return "no better", f"{text}; {loo_text}"
    if f < s:
        return "better", text
    return "no better", f"{text} (within {100 * WORSE_MARGIN:.0f} %)"


def _discrepancy(held: Sequence, in_sample: Sequence, loo: bool, n: int) -> dict:
    """The ``model_discrepancy`` block: ``q`` from the left-one-out replays, else in-sample times the factor."""
    if loo and held:
        return _q_block(held, f"left-one-out over {n} records: least squares of e^2 - s^2 = q t per held-out replay "
                              "(its fold's parameter band), averaged")
    if in_sample:
        return _q_block(in_sample, f"in-sample default: {IN_SAMPLE_FACTOR:g} x the least-squares q of e^2 - s^2 = q t "
                                   "on the fit's own replays (a record the fit has seen errs less than a new run)",
                        factor=IN_SAMPLE_FACTOR)
    return {"psi_variance_growth_deg2_per_s": 0.0, "method": "none (no replay of the fit succeeded)"}


def _q_block(series: Sequence, method: str, factor: float = 1.0) -> dict:
    """The ``model_discrepancy`` block of replays ``(t, e, s)``: the mean least-squares ``q`` [deg^2/s] times
    ``factor``, how it was made, and each replay's own ``q``."""
    qs = [heading_discrepancy(*ser) for ser in series]
    return {"psi_variance_growth_deg2_per_s": float(factor * np.degrees(np.degrees(np.mean(qs)))), "method": method,
            "per_record_deg2_per_s": [float(np.degrees(np.degrees(q))) for q in qs]}


def _has_heading(model, records) -> bool:
    """True when the model has a heading ``psi`` (state or output) and every record holds it."""
    return ("psi" in model.state_names or "psi" in model.output_names) and all("psi" in d for d in records)
