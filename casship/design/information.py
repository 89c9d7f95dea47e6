"""The expected information of a trial and the classical design criteria.

A trial's Fisher information about the uncertain parameters is the Gauss-Newton matrix ``J' J`` of
the output-error likelihood the fit uses (:class:`casship.identify.OutputErrorProblem`: measured
channels, noise standard deviations as weights), at the current estimate, on the trial's noise-free
record, from the exact sensitivities of the simulated outputs (:mod:`~.infofold`, one compiled fold;
equal to the problem's own information to rounding, tested). With a model discrepancy (a heading
error growing as a random walk, the ``model_discrepancy`` of a fit file) the heading residuals are
whitened first, so the information is that of the trial under the error model the fit measured.
For a linear-Gaussian model it is the Fisher matrix exactly; for a nonlinear one it is the expected
information to first order.
"""
from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np

from ..errors import InputError
from .belief import ParameterBelief
from .sensitivity import Approach
from .trials import Trial

__all__ = ["trial_information", "criterion_value", "CRITERIA", "check_noise", "fit_noise"]

#: Classical criteria on the posterior covariance (smaller is better).
CRITERIA = ("D", "A")


def check_noise(model, noise: Mapping[str, float]) -> dict:
    """The measurement noise standard deviations by output name, checked.

    Parameters
    ----------
    model : Model
    noise : mapping output name -> standard deviation (SI units, radians)

    Returns
    -------
    dict

    Raises
    ------
    ValueError
        No channel, an unknown output name, or a deviation that is not positive and finite.
    """
    noise = {str(k): float(v) for k, v in dict(noise).items()}
    if not noise:
        raise InputError("no measured channel: give the noise standard deviation of at least one output")
    unknown = [k for k in noise if k not in model.output_names]
    if unknown:
        raise InputError(f"noise given for {unknown}, which are not outputs of {model.name!r}: {list(model.output_names)}")
    bad = [k for k, v in noise.items() if not (np.isfinite(v) and v > 0)]
    if bad:
        raise InputError(f"noise standard deviations must be positive and finite: {bad}")
    return noise


def fit_noise(fit) -> dict:
    """The noise of one sample per measured channel as a fit weighs it: an output-error fit's output
    standard deviations times its fitted residual scale, or the square roots of the diagonal of a
    likelihood fit's ``R``.

    A new trial's record enters the likelihood with weight 1 (per-record weights of the fit are a
    choice of its cost over its own records). These deviations include the model-structure error of
    the runs fitted, not only sensor noise.

    Parameters
    ----------
    fit : FitResult, str or Path
        An output-error or likelihood fit, or its file.

    Returns
    -------
    dict
        Output name -> standard deviation (SI units, radians).

    Raises
    ------
    ValueError
        A fit without output noise (neither ``sigma`` nor ``R``).
    """
    from ..identify import FitResult

    where = "the fit"
    if not isinstance(fit, FitResult):
        where, fit = str(fit), FitResult.from_json(fit)
    noise = fit.noise or {}
    if noise.get("sigma"):
        scale = float(noise.get("weight_scale", 1.0))
        return {str(k): float(v) * scale for k, v in noise["sigma"].items()}
    if noise.get("R"):
        return {str(k): float(np.sqrt(v)) for k, v in noise["R"].items()}
    raise InputError(f"{where} holds no output noise (an output-error fit's sigma or a likelihood fit's R); give the "
                     "noise explicitly (noise= in Python; --sigma name=std,... for casship design-trial)")


def trial_information(approach: Approach, trial: Trial, names: Sequence[str], noise: Mapping[str, float], *,
                      discrepancy: float = 0.0, fold=None, jit: bool | None = None) -> np.ndarray:
    """Fisher information of one trial about the parameters ``names`` at ``approach.p``.

    Parameters
    ----------
    approach : Approach
        Model, current estimate, approach.
    trial : Trial
    names : sequence of str
        The uncertain parameters.
    noise : mapping output -> standard deviation
        Measured channels and the standard deviation of one sample (as the fit weighs them).
    discrepancy : float
        The heading's model discrepancy ``q`` [rad^2/s]: heading residuals are white noise plus a
        random walk of variance ``q t`` (:mod:`~.infofold`); 0 for white residuals, where the
        information is ``J' J`` of the weighted residuals.
    fold : InformationFold, optional
        The compiled fold to use (one per model, uncertain set and channels; built when not given).
    jit : bool, optional
        Compile policy of the fold (None: in the background when a compiler works).

    Returns
    -------
    (k, k) array
        The trial's information.
    """
    from .infofold import InformationFold

    noise = check_noise(approach.model, noise)
    if abs(trial.dt - approach.dt) > 1e-12 * approach.dt:
        raise InputError(f"trial {trial.name!r} has step {trial.dt:g} s, the design {approach.dt:g} s")
    if not (np.isfinite(discrepancy) and discrepancy >= 0):
        raise InputError(f"discrepancy must be a finite non-negative heading variance growth [rad^2/s], got {discrepancy}")
    if fold is None or tuple(fold.names) != tuple(names) or tuple(fold.channels) != tuple(noise):
        fold = InformationFold(approach, names, list(noise), jit=jit)
    info = fold.information(approach.inputs(trial.rudder), noise, discrepancy)
    return 0.5 * (info + info.T)


def criterion_value(after: ParameterBelief, prior: ParameterBelief, criterion: str) -> float:
    """D- or A-criterion of the belief after a trial, relative to the belief before it.

    ``D``: ``log det cov_after - log det cov_prior`` (the log of the shrinkage of the uncertainty
    ellipsoid's volume; unit-free). ``A``: the mean of ``var_after / var_prior`` over the parameters
    (the trace of the covariance scaled by the prior variances, so that units do not weigh).

    Parameters
    ----------
    after, prior : ParameterBelief
        Over the same parameters.
    criterion : {"D", "A"}

    Returns
    -------
    float
        Smaller is better (0 and 1 for a trial that teaches nothing).
    """
    if criterion not in CRITERIA:
        raise InputError(f"unknown criterion {criterion!r}; use one of {CRITERIA}")
    if criterion == "D":
        return float(np.linalg.slogdet(after.cov)[1] - np.linalg.slogdet(prior.cov)[1])
    return float(np.mean(np.diag(after.cov) / np.diag(prior.cov)))
