"""Maximum-likelihood and output-error identification: exact gradients, recovery with calibrated
standard errors, identifiability warnings, solver failures and the FitResult value."""
import numpy as np
import pytest
from scipy import stats

import casship as cs
from casship.identify import FitResult, IdentificationWarning, MLEProblem, OutputErrorProblem

K_TRUE, T_TRUE = 0.1, 20.0
DT = 1.0


def _rudder(t):
    return 0.15 * np.sign(np.sin(2 * np.pi * t / 120.0))


def _record(seed, n=300, q=1e-7, r_std=0.01, model=None):
    """Nomoto record with process noise held over each step (the discrete EKF's convention)."""
    m = model or cs.models.nomoto_first_order(K=K_TRUE, T=T_TRUE)
    rng = np.random.default_rng(seed)
    t = np.arange(n) * DT
    w = np.sqrt(q) * rng.standard_normal((n, m.nw))
    tr = cs.simulate(m, m.states(), t, {"delta": _rudder(t)}, w=w)
    return cs.measure(tr, m, {"psi": r_std}, seed=rng)


def _ekf(q=1e-7, r_std=0.01, model=None):
    m = model or cs.models.nomoto_first_order(K=K_TRUE, T=T_TRUE)
    return cs.EKF(cs.discretize(m, DT), Q=q, R=r_std**2)


PRIOR = cs.Gaussian([0.0, 0.0], [1e-4, 1e-8])


def test_gradient_matches_central_differences():
    ekf = _ekf()
    prob = MLEProblem(ekf, [_record(1, 150), _record(2, 120)], free=["K", "T"], noise={"Q": True, "R": True},
                      x0=PRIOR, estimate_x0=["psi"])
    at = {"K": 0.08, "T": 15.0, "Q[w_r]": 2e-7, "R[psi]": 2e-4, "psi@0": 0.003, "psi@1": -0.002}
    g = prob.gradient(at)
    for i, name in enumerate(prob.free):
        h = 1e-5 * abs(at[name])
        up, dn = dict(at), dict(at)
        up[name] += h
        dn[name] -= h
        fd = (prob.negloglik(up) - prob.negloglik(dn)) / (2 * h)
        assert g[i] == pytest.approx(fd, rel=1e-5, abs=1e-6 * np.abs(g).max()), name


def test_negloglik_equals_filter_loglik():
    data = _record(3)
    ekf = _ekf()
    prob = MLEProblem(ekf, data, free=["K"], x0=PRIOR)
    res = ekf.filter(data, PRIOR, ekf.model.params(K=0.09))
    assert prob.negloglik({"K": 0.09}) == pytest.approx(-res.loglik, rel=1e-12)


def test_recovery_and_calibrated_standard_errors():
    """Over a Monte Carlo of seeds the 95 % intervals cover the truth about 95 % of the time and the
    standardised errors are chi-square distributed (neither too narrow nor too wide)."""
    truth = {"K": K_TRUE, "T": T_TRUE}
    z2, covered, total = 0.0, 0, 0
    ekf = _ekf()
    for seed in range(20):
        fit = MLEProblem(ekf, _record(100 + seed), free=["K", "T"], x0=PRIOR).solve(guess={"K": 0.05, "T": 10.0})
        for name, value in truth.items():
            lo, hi = fit.interval(name, 0.95)
            covered += lo <= value <= hi
            z2 += ((fit.estimates[name] - value) / fit.std_errors[name]) ** 2
            total += 1
    assert covered >= 34, f"{covered}/{total} intervals cover the truth"
    lo, hi = stats.chi2.ppf([0.001, 0.999], total)
    assert lo < z2 < hi


def test_noise_variances_recovered():
    data = [_record(7, 400, q=4e-7), _record(8, 400, q=4e-7)]
    fit = MLEProblem(_ekf(q=1e-6, r_std=0.02), data, free=["K", "T"], noise={"Q": True, "R": True},
                     x0=PRIOR).solve(guess={"K": 0.05, "T": 10.0})
    for name, value in {"K": K_TRUE, "T": T_TRUE, "Q[w_r]": 4e-7, "R[psi]": 1e-4}.items():
        assert abs(fit.estimates[name] - value) < 3.5 * fit.std_errors[name], name
    assert fit.noise["R"]["psi"] == pytest.approx(fit.estimates["R[psi]"])
    assert fit.params["K"] == fit.estimates["K"]
    assert set(fit.whiteness) == {"psi"}
    assert fit.whiteness["psi"]["white"]


def test_output_error_single_and_multiple_shooting_agree_and_recover():
    m = cs.models.nomoto_first_order(K=K_TRUE, T=T_TRUE)
    data = _record(11, 300, q=0.0)
    fits = [OutputErrorProblem(m, data, free=["K", "T"], sigma={"psi": 0.01}, estimate_x0=["psi"],
                               shooting=s, segment=40).solve(guess={"K": 0.05, "T": 10.0}, **kw)
            for s, kw in (("single", {"tol": 1e-14}), ("multiple", {}))]
    for name in ("K", "T", "psi@0"):
        assert fits[0].estimates[name] == pytest.approx(fits[1].estimates[name], rel=1e-6, abs=1e-9)
    for name, value in {"K": K_TRUE, "T": T_TRUE}.items():
        assert abs(fits[0].estimates[name] - value) < 3 * fits[0].std_errors[name]
    # weights right: the weighted residual scale is about one
    assert fits[0].noise["weight_scale"] == pytest.approx(1.0, abs=0.15)


def _model_with_ghost():
    b = cs.ModelBuilder("ghost")
    psi, r = b.state("psi", angle=True), b.state("r")
    delta, d2 = b.input("delta"), b.input("d2")
    K, T, g = b.param("K", K_TRUE), b.param("T", T_TRUE), b.param("g", 1.0)
    c = b.param("c", 0.0)
    b.ode(psi=r, r=(K * g * delta + c * d2 - r) / T + b.noise("w_r"))
    b.output("psi", psi)
    return b.build()


def test_identifiability_warnings():
    m = _model_with_ghost()
    data = _record(5)  # Nomoto data: the same dynamics with g = 1, c = 0 and no d2 input
    ekf = cs.EKF(cs.discretize(m, DT), Q=1e-7, R=1e-4)
    fit = MLEProblem(ekf, data.with_columns(d2=np.zeros(len(data))), free=["K", "T", "g", "c"],
                     x0=PRIOR).solve(guess={"K": 0.05, "T": 10.0, "g": 1.0, "c": 0.0})
    text = "\n".join(fit.warnings)
    assert "do not determine c" in text
    assert any("K" in w and "g" in w for w in fit.warnings)
    assert not np.isfinite(fit.std_errors["c"])
    # without the ghost parameters the same data gives no warning
    clean = MLEProblem(ekf, data.with_columns(d2=np.zeros(len(data))), free=["K", "T"], x0=PRIOR).solve(
        guess={"K": 0.05, "T": 10.0})
    assert clean.warnings == []


def test_early_stop_returns_the_iterate_with_status():
    """A fit stopped by its iteration limit returns its best iterate, the status and a warning."""
    prob = MLEProblem(_ekf(), _record(9), free=["K", "T"], x0=PRIOR)
    start = prob.cost({"K": 0.05, "T": 10.0})
    with pytest.warns(IdentificationWarning, match="stopped early"):
        fit = prob.solve(guess={"K": 0.05, "T": 10.0}, max_iter=1)
    assert fit.status == "max_iterations" and fit.iterations == 1 and not fit.converged
    assert fit.cost < start and fit.estimates["K"] != 0.05
    assert any("stopped early" in w for w in fit.warnings)
    full = prob.solve(guess={"K": 0.05, "T": 10.0})
    assert full.status == "converged" and full.cost < fit.cost
    # IPOPT's iteration limit: the iterate and IPOPT's own status, not an exception
    with pytest.warns(IdentificationWarning, match="Maximum_Iterations_Exceeded"):
        ip = prob.solve(guess={"K": 0.05, "T": 10.0}, hessian="exact", options={"max_iter": 1})
    assert ip.status == "Maximum_Iterations_Exceeded" and np.isfinite(ip.estimates["K"])


def test_fitresult_json_round_trip_and_plot(tmp_path):
    fit = MLEProblem(_ekf(), _record(4), free=["K", "T"], noise={"R": True}, x0=PRIOR).solve(
        guess={"K": 0.05, "T": 10.0})
    path = fit.to_json(tmp_path / "fit.json")
    back = FitResult.from_json(path)
    assert back.model == "nomoto1" and back.free == fit.free
    for attr in ("params", "estimates", "std_errors", "noise", "whiteness"):
        assert getattr(back, attr) == getattr(fit, attr), attr
    np.testing.assert_allclose(back.correlation, fit.correlation)
    assert back.aic == fit.aic and back.bic == fit.bic and back.status == fit.status
    assert cs.models.get_model("nomoto1").params(back.params)[0] == pytest.approx(fit.estimates["K"])
    assert fit.plot(tmp_path / "fit.png").stat().st_size > 0
    with pytest.raises(ValueError, match="no predictions"):
        back.plot(tmp_path / "x.png")


def test_bad_input_is_named():
    ekf = _ekf()
    data = _record(1, 50)
    with pytest.raises(ValueError, match="'Kx'"):
        MLEProblem(ekf, data, free=["Kx"])
    with pytest.raises(ValueError, match="w_q"):
        MLEProblem(ekf, data, free=["K"], noise={"Q": ["w_q"]})
    with pytest.raises(ValueError, match="not free"):
        MLEProblem(ekf, data, free=["K"]).solve(guess={"T": 3.0})
    with pytest.raises(ValueError, match="outside its bounds"):
        MLEProblem(ekf, data, free=["K"], bounds={"K": (0.0, 1.0)}).solve(guess={"K": 2.0})
    with pytest.raises(ValueError, match="delta"):
        MLEProblem(ekf, data.select(["psi"]), free=["K"])
    with pytest.raises(TypeError):
        MLEProblem(ekf, [np.zeros(3)], free=["K"])


def test_too_little_data_and_long_gaps_are_refused():
    data = _record(1, 300)
    short = data.slice(0, 1)
    short.meta["name"] = "stub"
    with pytest.raises(ValueError, match="'stub' has 1 row"):
        MLEProblem(_ekf(), short, free=["K"], x0=PRIOR)
    with pytest.raises(ValueError, match="2 measured value.*2 free quantities"):
        MLEProblem(_ekf(), data.slice(0, 2), free=["K", "T"], x0=PRIOR)
    MLEProblem(_ekf(), data.slice(0, 2), free=["K", "T"], x0=PRIOR, prior={"K": 0.1})    # a prior closes it
    t = data.t.copy()
    t[150:] += 1e4                                                  # far beyond the rk4 stability limit
    gapped = cs.Dataset(t, {n: data[n] for n in data.names})
    with pytest.raises(ValueError, match="time gap of 1e\\+04 s .*rows 149 and 150"):
        MLEProblem(_ekf(), gapped, free=["K"], x0=PRIOR)
    with pytest.raises(ValueError, match="time gap .*rows 149 and 150"):
        OutputErrorProblem(cs.models.nomoto_first_order(K=K_TRUE, T=T_TRUE), gapped, free=["K"], sigma={"psi": 0.01})
    ekf = cs.EKF(cs.discretize(cs.models.nomoto_first_order(K=K_TRUE, T=T_TRUE), DT), Q=1e-7, R=1e-4,
                 options={"on_gap": "bridge"})
    with pytest.warns(UserWarning, match="bridged"):
        prob = MLEProblem(ekf, gapped, free=["K"], x0=PRIOR)
    assert len(prob.records[0]) > len(gapped)
    assert prob._n_obs() == len(gapped)                             # bridging rows carry no measurement


def test_likelihood_through_ukf_gradient_and_recovery():
    """The same problem through the UKF: exact gradient, and the fit agrees with the EKF's (linear
    measurement, mildly nonlinear dynamics: the two likelihoods are almost the same)."""
    data = _record(21)
    m = cs.models.nomoto_first_order(K=K_TRUE, T=T_TRUE)
    ukf = cs.UKF(cs.discretize(m, DT), Q=1e-7, R=1e-4)
    prob = MLEProblem(ukf, data, free=["K", "T"], x0=PRIOR)
    at = {"K": 0.09, "T": 18.0}
    g = prob.gradient(at)
    for i, name in enumerate(prob.free):
        h = 1e-5 * at[name]
        up, dn = dict(at), dict(at)
        up[name] += h
        dn[name] -= h
        assert g[i] == pytest.approx((prob.negloglik(up) - prob.negloglik(dn)) / (2 * h), rel=1e-5)
    fit = prob.solve(guess={"K": 0.05, "T": 10.0})
    ref = MLEProblem(_ekf(), data, free=["K", "T"], x0=PRIOR).solve(guess={"K": 0.05, "T": 10.0})
    for name in ("K", "T"):
        assert fit.estimates[name] == pytest.approx(ref.estimates[name], abs=0.1 * ref.std_errors[name])


@pytest.mark.slow
def test_coverage_large_monte_carlo():
    """100 seeds, 200 intervals: coverage of the 95 % intervals within the binomial 99.9 % band."""
    ekf = _ekf()
    covered, total = 0, 0
    for seed in range(100):
        fit = MLEProblem(ekf, _record(1000 + seed), free=["K", "T"], x0=PRIOR).solve(guess={"K": 0.05, "T": 10.0})
        for name, value in {"K": K_TRUE, "T": T_TRUE}.items():
            lo, hi = fit.interval(name, 0.95)
            covered += lo <= value <= hi
            total += 1
    lo, hi = stats.binom.ppf([0.0005, 0.9995], total, 0.95)
    assert lo <= covered <= hi, f"{covered}/{total}"


def test_identification_guide_examples_run(tmp_path, monkeypatch):
    import re
    from pathlib import Path

    monkeypatch.chdir(tmp_path)
    page = Path(__file__).resolve().parents[1] / "docs" / "identification.md"
    namespace: dict = {}
    for block in re.findall(r"```python\n(.*?)```", page.read_text(), re.S):
        if block.startswith("# needs the measured data") and not _have_data():
            continue          # the blocks that read ../shared/data run where it is
        exec(compile(block, str(page), "exec"), namespace)
    assert (tmp_path / "fit.json").exists() and (tmp_path / "fit.png").exists()


def test_output_error_derivatives_match_central_differences():
    """Output error over two records with per-record initial states: the forward-sensitivity gradient,
    the reverse-mode gradient and central differences of the cost agree; Gauss-Newton iterations
    reach the IPOPT multiple-shooting optimum."""
    m = cs.models.nomoto_first_order(K=K_TRUE, T=T_TRUE)
    data = [_record(31, 200, q=0.0), _record(32, 150, q=0.0)]
    prob = OutputErrorProblem(m, data, free=["K", "T"], sigma={"psi": 0.01}, estimate_x0=["psi"])
    assert prob.free == ["K", "T", "psi@0", "psi@1"]
    at = {"K": 0.08, "T": 15.0, "psi@0": 0.002, "psi@1": -0.003}
    theta = prob.space.theta(at)
    g_sens = prob.engine.derivatives(theta)[1]
    g_rev = prob.gradient(at)
    for i, name in enumerate(prob.free):
        h = 1e-6 * max(abs(at[name]), 1e-3)
        up, dn = dict(at), dict(at)
        up[name] += h
        dn[name] -= h
        fd = (prob.cost(up) - prob.cost(dn)) / (2 * h)
        assert g_sens[i] == pytest.approx(fd, rel=1e-6, abs=1e-8 * np.abs(g_sens).max()), name
        assert g_rev[i] == pytest.approx(g_sens[i], rel=1e-10, abs=1e-12 * np.abs(g_sens).max()), name
    gn = prob.solve(guess={"K": 0.05, "T": 10.0}, tol=1e-14)
    ms = OutputErrorProblem(m, data, free=["K", "T"], sigma={"psi": 0.01}, estimate_x0=["psi"],
                            shooting="multiple", segment=40).solve(guess={"K": 0.05, "T": 10.0})
    for name in gn.free:
        assert gn.estimates[name] == pytest.approx(ms.estimates[name], abs=1e-6 * gn.std_errors[name]), name


def test_compiled_likelihood_gives_the_same_fit_and_is_reused():
    from casship.runtime import cache_info

    ekf = _ekf()
    data = [_record(41, 120), _record(42, 120)]
    ref = MLEProblem(ekf, data, free=["K", "T"], x0=PRIOR, jit=False).solve(guess={"K": 0.05, "T": 10.0})
    fit = MLEProblem(ekf, data, free=["K", "T"], x0=PRIOR, jit=True).solve(guess={"K": 0.05, "T": 10.0})
    for name in ("K", "T"):
        assert fit.estimates[name] == pytest.approx(ref.estimates[name], rel=1e-10)
        assert fit.std_errors[name] == pytest.approx(ref.std_errors[name], rel=1e-8)
    n_compiled = cache_info().entries
    # other records (other lengths) and another free set of the same size reuse the compiled code
    other = MLEProblem(ekf, [_record(43, 300), _record(44, 77)], free=["K", "T"], x0=PRIOR, jit=True)
    again = other.solve(guess={"K": 0.05, "T": 10.0})
    assert cache_info().entries == n_compiled
    plain = MLEProblem(ekf, other.records, free=["K", "T"], x0=PRIOR, jit=False).solve(guess={"K": 0.05, "T": 10.0})
    assert again.estimates["K"] == pytest.approx(plain.estimates["K"], rel=1e-10)


def _have_data() -> bool:
    """Whether the measured data are here (the docs' blocks marked "# needs the measured data" need them)."""
    from casship.io import data_dir

    try:
        return data_dir() is not None
    except FileNotFoundError:
        return False


def test_a_trial_step_beyond_float_range_is_rejected_without_a_warning():
    # a log-variance step past exp's range is inf: the trust region rejects it; nothing reaches the user
    import warnings
    from casship.identify._space import ParamSpace

    m = cs.models.nomoto_first_order()
    space = ParamSpace(m, 1, [], measured=["psi"], noise=[("R", 0, "R[psi]", 1e-4)], Q=np.zeros((1, 1)),
                       R=np.eye(1) * 1e-4)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert np.isinf(space.natural([800.0])).all()
