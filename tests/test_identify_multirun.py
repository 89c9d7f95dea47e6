"""Multi-record identification: joint derivatives, per-record and per-group quantities, biases,
priors (MAP) with calibrated intervals, missing initial values and non-finite costs."""
import numpy as np
import pytest
from scipy import stats

import casship as cs
from casship.identify import IdentificationError, MLEProblem, OutputErrorProblem, Prior

K_TRUE, T_TRUE, DT = 0.1, 20.0, 1.0
PRIOR_X0 = cs.Gaussian([0.0, 0.0], [1e-4, 1e-8])


def _run(seed, n=200, K=K_TRUE, T=T_TRUE, bias=0.0, q=1e-7, r_std=0.01, period=120.0, amp=0.15):
    """Nomoto record whose rudder is offset by ``bias`` from the recorded one."""
    m = cs.models.nomoto_first_order(K=K, T=T)
    rng = np.random.default_rng(seed)
    t = np.arange(n) * DT
    delta = amp * np.sign(np.sin(2 * np.pi * t / period + seed))
    w = np.sqrt(q) * rng.standard_normal((n, m.nw))
    tr = cs.simulate(m, m.states(), t, {"delta": delta + bias}, w=w)
    data = cs.measure(tr, m, {"psi": r_std}, seed=rng)
    return data.with_columns(delta=delta)


def _fd(cost, at, name, rel=1e-6):
    h = rel * max(abs(at[name]), 1e-3)
    up, dn = dict(at), dict(at)
    up[name] += h
    dn[name] -= h
    return (cost(up) - cost(dn)) / (2 * h)


@pytest.mark.parametrize("kind", ["mle", "oe"])
def test_joint_gradient_is_the_sum_of_per_record_gradients(kind):
    """Shared K, T and a per-record rudder bias: the joint gradient is the sum of the records' own
    gradients (shared entries) or a record's own entry (its bias), and matches central differences."""
    runs = [_run(s, 150 + 20 * s, bias=0.01 * (s - 1)) for s in range(3)]
    m = cs.models.nomoto_first_order(K=K_TRUE, T=T_TRUE)
    ekf = cs.EKF(cs.discretize(m, DT), Q=1e-7, R=1e-4)

    def make(data, share=None):
        if kind == "mle":
            return MLEProblem(ekf, data, free=["K", "T", "bias[delta]"], x0=PRIOR_X0, share=share)
        return OutputErrorProblem(m, data, free=["K", "T", "bias[delta]"], sigma={"psi": 0.01}, share=share)

    joint = make(runs, {"bias[delta]": "record"})
    assert joint.free == ["K", "T", "bias[delta]@0", "bias[delta]@1", "bias[delta]@2"]
    at = {"K": 0.09, "T": 17.0, "bias[delta]@0": -0.004, "bias[delta]@1": 0.002, "bias[delta]@2": 0.007}
    g = dict(zip(joint.free, joint.gradient(at)))
    singles = [make(d).gradient({"K": at["K"], "T": at["T"], "bias[delta]": at[f"bias[delta]@{i}"]})
               for i, d in enumerate(runs)]
    for j, name in enumerate(("K", "T")):
        assert g[name] == pytest.approx(sum(s[j] for s in singles), rel=1e-10)
    for i in range(3):
        assert g[f"bias[delta]@{i}"] == pytest.approx(singles[i][2], rel=1e-10)
    sens = joint.engine.derivatives(joint.space.theta(at))[1]
    scale = np.abs(sens).max()
    for j, name in enumerate(joint.free):
        assert sens[j] == pytest.approx(_fd(joint.cost, at, name), rel=1e-5, abs=1e-7 * scale), name
        assert g[name] == pytest.approx(sens[j], rel=1e-9, abs=1e-12 * scale), name


def test_per_record_and_per_group_quantities_are_recovered():
    """Rudder offsets that differ by facility (group) and initial headings per record are recovered
    with the shared K, T; a record outside every group keeps the fixed value."""
    bias = {"A": 0.02, "B": -0.015}
    facility = ["A", "A", "B", "B"]
    runs = [_run(10 + i, 300, bias=bias[f], q=0.0) for i, f in enumerate(facility)]
    m = cs.models.nomoto_first_order(K=K_TRUE, T=T_TRUE)
    prob = OutputErrorProblem(m, runs, free=["K", "T", "bias[delta]"], sigma={"psi": 0.01},
                              share={"bias[delta]": "facility"}, groups={"facility": facility}, estimate_x0=["psi"])
    assert prob.free[:4] == ["K", "T", "bias[delta]@A", "bias[delta]@B"]
    fit = prob.solve(guess={"K": 0.06, "T": 12.0})
    assert fit.converged
    truth = {"K": K_TRUE, "T": T_TRUE, "bias[delta]@A": bias["A"], "bias[delta]@B": bias["B"]}
    for name, value in truth.items():
        assert abs(fit.estimates[name] - value) < 4 * fit.std_errors[name], name
    assert fit.record_params[0]["bias[delta]"] == pytest.approx(fit.estimates["bias[delta]@A"])
    assert fit.record_params[3]["bias[delta]"] == pytest.approx(fit.estimates["bias[delta]@B"])
    # labels from the records' meta; None = that record keeps the fixed value (no copy)
    tagged = [d.with_columns() for d in runs]
    for d, f in zip(tagged, facility):
        d.meta["facility"] = f
    by_meta = OutputErrorProblem(m, tagged, free=["K", "bias[delta]"], sigma={"psi": 0.01},
                                 share={"bias[delta]": "facility"})
    assert by_meta.free == ["K", "bias[delta]@A", "bias[delta]@B"]
    partial = OutputErrorProblem(m, runs, free=["K", "bias[delta]"], sigma={"psi": 0.01},
                                 share={"bias[delta]": ["A", "A", None, None]})
    assert partial.free == ["K", "bias[delta]@A"]
    assert list(partial.space.record_map(3).cols) == [0]
    with pytest.raises(ValueError, match="meta"):
        OutputErrorProblem(m, runs, free=["K"], sigma={"psi": 0.01}, share={"K": "facility"})


def test_zero_weight_prior_reproduces_the_unregularised_fit():
    runs = [_run(20), _run(21)]
    ekf = cs.EKF(cs.discretize(cs.models.nomoto_first_order(K=K_TRUE, T=T_TRUE), DT), Q=1e-7, R=1e-4)
    free, guess = ["K", "T"], {"K": 0.05, "T": 10.0}
    plain = MLEProblem(ekf, runs, free=free, x0=PRIOR_X0).solve(guess=guess, tol=1e-14)
    off = MLEProblem(ekf, runs, free=free, x0=PRIOR_X0, prior=Prior({"K": 0.01, "T": 1.0}, weight=0.0)).solve(
        guess=guess, tol=1e-14)
    for name in free:
        assert off.estimates[name] == pytest.approx(plain.estimates[name], rel=1e-9)
        assert off.std_errors[name] == pytest.approx(plain.std_errors[name], rel=1e-9)
    assert off.prior == {} and plain.prior == {}
    on = MLEProblem(ekf, runs, free=free, x0=PRIOR_X0, prior=Prior({"K": 0.01, "T": 1.0})).solve(guess=guess)
    assert on.prior["quantities"]["T"] == {"mean": 20.0, "std": 1.0}       # the published value by default
    assert "prior" in on.summary() and "N(20, 1^2)" in on.summary()
    assert on.std_errors["T"] < plain.std_errors["T"]
    assert abs(on.estimates["T"] - 20.0) < abs(plain.estimates["T"] - 20.0)
    with pytest.raises(ValueError, match="not free"):
        MLEProblem(ekf, runs, free=free, x0=PRIOR_X0, prior={"a1": 1.0})


def test_map_recovery_and_coverage_of_posterior_intervals():
    """Truths drawn from the prior, three short records each: the MAP estimates recover them and the
    95 % posterior intervals cover them about 95 % of the time (binomial 99.9 % band), with the
    standardised errors chi-square distributed (fixed seeds)."""
    mu, sd = {"K": 0.1, "T": 20.0}, {"K": 0.02, "T": 4.0}
    m = cs.models.nomoto_first_order(**mu)          # its published values are the prior means
    ekf = cs.EKF(cs.discretize(m, DT), Q=1e-7, R=1e-4)
    rng = np.random.default_rng(2024)
    covered = total = 0
    z2 = 0.0
    for rep in range(30):
        truth = {n: mu[n] + sd[n] * rng.standard_normal() for n in mu}
        runs = [_run(100 * rep + i, 120, K=truth["K"], T=truth["T"], amp=0.05, period=80.0) for i in range(3)]
        fit = MLEProblem(ekf, runs, free=["K", "T"], x0=PRIOR_X0, prior=Prior(sd)).solve(show=False)
        assert fit.converged
        for n, value in truth.items():
            lo, hi = fit.interval(n)
            covered += lo <= value <= hi
            z2 += ((fit.estimates[n] - value) / fit.std_errors[n]) ** 2
            total += 1
    lo, hi = stats.binom.ppf([0.0005, 0.9995], total, 0.95)
    assert lo <= covered <= hi, f"{covered}/{total}"
    assert stats.chi2.ppf(0.001, total) < z2 < stats.chi2.ppf(0.999, total)


def test_nan_in_an_initial_row_is_an_error_naming_record_and_column():
    runs = [_run(30, 50), _run(31, 50)]
    bad = runs[1].with_columns(psi=np.concatenate([[np.nan], runs[1]["psi"][1:]]))
    bad.meta["name"] = "zz-port"
    m = cs.models.nomoto_first_order()
    with pytest.raises(ValueError, match=r"'zz-port'.*'psi'"):
        OutputErrorProblem(m, [runs[0], bad], free=["K"], sigma={"psi": 0.01})
    ekf = cs.EKF(cs.discretize(m, DT), Q=1e-7, R=1e-4)
    with pytest.raises(ValueError, match=r"'zz-port'.*'psi'"):
        MLEProblem(ekf, [runs[0], bad], free=["K"])
    # estimating that state, or giving it, is fine
    assert OutputErrorProblem(m, [runs[0], bad], free=["K"], sigma={"psi": 0.01}, estimate_x0=["psi"]).free[-1] == "psi@1"
    OutputErrorProblem(m, [runs[0], bad], free=["K"], sigma={"psi": 0.01}, x0={"psi": 0.0})


def test_a_free_set_with_a_non_finite_cost_stops_with_a_reason():
    m = cs.models.nomoto_first_order()
    runs = [_run(40, 100), _run(41, 100)]
    prob = OutputErrorProblem(m, runs, free=["K", "T"], sigma={"psi": 0.01})
    with pytest.raises(IdentificationError, match=r"not finite at the start.*record") as err:
        prob.solve(guess={"K": 0.1, "T": 1e-6})
    assert err.value.status == "nan" and "t = " in str(err.value)


def test_noise_estimate_from_the_records():
    """The high-pass noise estimate recovers the measurement noise of a smooth record."""
    runs = [_run(50 + i, 600, q=0.0, r_std=0.02, period=400.0, amp=0.05) for i in range(3)]
    est = cs.identify.noise_std(runs, ["psi"], angles=["psi"])
    assert est["psi"] == pytest.approx(0.02, rel=0.1)
    m = cs.models.nomoto_first_order()
    prob = OutputErrorProblem(m, runs, free=["K", "T"], estimate_x0=["psi"])     # sigma estimated by default
    assert prob.sigma[0] == pytest.approx(0.02, rel=0.1)
    fit = prob.solve(guess={"K": 0.05, "T": 10.0})
    assert fit.noise["weight_scale"] == pytest.approx(1.0, abs=0.1)
    assert set(fit.channel_share["optimum"]) == {"psi"}
    with pytest.raises(ValueError, match="noise estimate is zero"):
        cs.identify.noise_std([runs[0].with_columns(psi=np.zeros(600))], ["psi"])


def test_bounds_are_honoured_and_reported():
    runs = [_run(60, 200, q=0.0), _run(61, 200, q=0.0)]
    m = cs.models.nomoto_first_order(K=K_TRUE, T=T_TRUE)
    fit = OutputErrorProblem(m, runs, free=["K", "T"], sigma={"psi": 0.01}, bounds={"K": (0.02, 0.08)}).solve(
        guess={"K": 0.05, "T": 10.0})
    assert fit.estimates["K"] == pytest.approx(0.08) and fit.converged
    assert any("K ended at a bound" in w for w in fit.warnings)
    with pytest.raises(ValueError, match="outside its bounds"):
        OutputErrorProblem(m, runs, free=["K"], sigma={"psi": 0.01}, bounds={"K": (0.02, 0.08)}).solve(guess={"K": 0.1})
