"""Exact gradients of the identification costs against central differences, for every kind of free
quantity at once (model parameters, per-record copies, input and output sensor biases, noise
variances, initial states) with a prior, for the filter likelihood and output error; and the optimum
each solver route returns is a stationary point of the cost computed by hand."""
import numpy as np
import pytest

import casship as cs
from casship.identify import MLEProblem, OutputErrorProblem, Prior

K_TRUE, T_TRUE, DT, R_STD = 0.1, 20.0, 1.0, 0.01
X0 = cs.Gaussian([0.0, 0.0], [1e-4, 1e-8])
PRIOR = Prior(std={"K": 0.01, "bias[delta]": 0.005}, mean={"K": 0.095, "bias[delta]": 0.004})


def records(count=2, n=160):
    """Nomoto records with a rudder offset and a heading-sensor offset of their own."""
    m = cs.models.nomoto_first_order(K=K_TRUE, T=T_TRUE)
    out = []
    for s in range(count):
        rng = np.random.default_rng(40 + s)
        t = np.arange(n + 20 * s) * DT
        delta = 0.15 * np.sign(np.sin(2 * np.pi * t / 90.0 + s))
        tr = cs.simulate(m, m.states(psi=0.01 * s), t, {"delta": delta + 0.003},
                         w=np.sqrt(1e-7) * rng.standard_normal((t.size, 1)))
        d = cs.measure(tr, m, {"psi": R_STD}, seed=rng)
        out.append(d.with_columns(psi=d["psi"] + 0.02 * (s + 1)))
    return m, out


def mle(estimator=cs.EKF):
    m, data = records()
    est = estimator(cs.discretize(m, DT), Q=1e-7, R=R_STD**2)
    return MLEProblem(est, data, free=["K", "T", "bias[delta]", "bias[psi]"], noise={"R": True}, x0=X0,
                      estimate_x0=["r"], share={"bias[psi]": "record", "T": "record"}, prior=PRIOR)


def output_error(shooting="single"):
    m, data = records()
    return OutputErrorProblem(m, data, free=["K", "T", "bias[delta]", "bias[psi]"], sigma={"psi": R_STD},
                              estimate_x0=["r"], share={"bias[psi]": "record", "T": "record"}, prior=PRIOR,
                              shooting=shooting, segment=40)


AT = {"K": 0.09, "T@0": 18.0, "T@1": 22.0, "bias[delta]": 0.002, "bias[psi]@0": 0.015, "bias[psi]@1": 0.05,
      "r@0": 0.0005, "r@1": -0.0004, "R[psi]": 1.2e-4}


def prior_cost(values):
    """The prior's cost written out: ``0.5 sum ((theta - mean) / std)^2`` over the quantities it names."""
    return 0.5 * (((values["K"] - 0.095) / 0.01) ** 2 + ((values["bias[delta]"] - 0.004) / 0.005) ** 2)


def hand_cost(prob, values):
    """Data cost (negative log-likelihood, or half the weighted squared residuals) plus the prior's."""
    if isinstance(prob, MLEProblem):
        data = prob.negloglik(values)
    else:
        data = 0.5 * sum(np.nansum(r**2) for r in prob.residuals(values))
    return data + prior_cost(values)


def central_gradient(cost, at, names, rel=1e-6):
    g = []
    for name in names:
        h = rel * max(abs(at[name]), 1e-3)
        up, dn = dict(at), dict(at)
        up[name] += h
        dn[name] -= h
        g.append((cost(up) - cost(dn)) / (2 * h))
    return np.array(g)


@pytest.mark.parametrize("make", [lambda: mle(cs.EKF), lambda: mle(cs.UKF), output_error],
                         ids=["mle-ekf", "mle-ukf", "oe"])
def test_gradient_of_every_kind_of_free_quantity_matches_central_differences(make):
    prob = make()
    at = {k: v for k, v in AT.items() if k in prob.free}
    assert sorted(at) == sorted(prob.free)
    assert prob.cost(at) == pytest.approx(hand_cost(prob, at), rel=1e-12)
    g = prob.gradient(at)
    fd = central_gradient(lambda v: hand_cost(prob, v), at, prob.free)
    scale = np.abs(fd).max()
    for name, gi, fi in zip(prob.free, g, fd):
        assert gi == pytest.approx(fi, rel=1e-5, abs=1e-7 * scale), name


@pytest.mark.parametrize("route", ["mle-fisher", "mle-ipopt", "oe-single", "oe-multiple"])
def test_each_solver_route_stops_at_a_stationary_point_of_the_hand_cost(route):
    """At the returned estimate the central-difference gradient of the hand-computed cost (data cost
    plus prior) is zero to within 1e-3 standard errors per quantity: the route's own gradient, prior
    and curvature led it to the optimum of the stated cost."""
    kind, how = route.split("-")
    if kind == "mle":
        prob = mle()
        fit = prob.solve(guess=AT, hessian="fisher" if how == "fisher" else "exact", show=False)
    else:
        prob = output_error(how)
        guess = {k: v for k, v in AT.items() if k in prob.free}
        fit = prob.solve(guess=guess, show=False, **({"tol": 1e-12} if how == "single" else {}))
    assert fit.status in ("converged", "Solve_Succeeded"), fit.message
    est = dict(fit.estimates)
    fd = central_gradient(lambda v: hand_cost(prob, v), est, prob.free, rel=1e-5)
    se = np.array([fit.std_errors[n] for n in prob.free])
    if kind == "oe":              # output error scales its errors by the residual variance
        se = se / fit.noise["weight_scale"]
    assert np.all(np.abs(fd * se) < 1e-3), dict(zip(prob.free, fd * se))
