"""The estimator contract (docs/architecture.md), checked for every registered estimator.

Every class in ``casship.estimators.ESTIMATORS`` gets every check below by being registered there:
the abstract contract, constructor and typed options, the step Function's named slots (or the
refusal of an estimator without one), lean and full steps, a linear model (all equal the Kalman
filter and python-control's ``dlqe``/``lqe``), NaN rows, wrapped angle residuals, batch = online,
time gaps (raised, or bridged alike in batch and online), NEES/NIS inside chi-square bounds on a
nonlinear ship model, unknown names and options, results as values (frozen, repr, summary,
save/load, plot), smoothing and prediction.

The traits a check needs come from the class: ``continuous`` (Q and R enter as spectral densities;
compared with ``lqe`` and not expected to equal a discrete filter sample by sample) and
``stochastic`` (draws random numbers: compared within Monte Carlo error); the step family
(``StepEstimator``) has ``step``, any other estimator (the MHE) has no ``step`` at all. Every sample,
batch or online, means the same to every estimator: masked = NaN = not measured, infinite refused
naming the item, gaps refused or bridged alike. ``FAST`` lists options that keep an expensive
estimator quick here; everything else runs on its defaults.
"""
from __future__ import annotations

import dataclasses

import control
import numpy as np
import pytest
from scipy import stats

import casship as cs
from casship.errors import InputError
from casship.estimators import ESTIMATORS, EstimatorOptions, FilterResult, StepEstimator
from filter_models import oscillator_case

FAST = {"mhe": {"solver": "rti", "horizon": 5}}
Q, R = 0.05, [0.04, 0.09]
NAMES = sorted(ESTIMATORS)


def make(name, dm, Q, R, **options):
    """The registered estimator ``name`` with the suite's options."""
    return ESTIMATORS[name](dm, Q, R, options={**FAST.get(name, {}), **options})


@pytest.fixture(scope="module")
def linear():
    return oscillator_case(300)


@pytest.fixture(scope="module")
def kf_reference(linear):
    m, dm, traj, data, prior = linear
    return cs.KF(dm, Q, R).filter(data, prior)


def test_every_registered_estimator_is_checked(linear):
    assert {"kf", "ekf", "ukf", "enkf", "kalman-bucy", "mhe"} <= set(ESTIMATORS)
    for cls in ESTIMATORS.values():
        assert issubclass(cls, cs.estimators.Estimator) and not cls.__abstractmethods__
    # the contract itself is abstract: the four verbs (and the options) are what an estimator must provide,
    # and nothing it promises is refused by one of them
    assert set(cs.estimators.Estimator.__abstractmethods__) == {"filter", "online", "smooth", "predict"}
    with pytest.raises(TypeError, match="abstract"):
        cs.estimators.Estimator(linear[1], Q, R)
    assert not hasattr(cs.estimators.Estimator, "step")
    for verb in ("prepare", "result", "gate_threshold"):        # the step family's, not the contract's
        assert not hasattr(cs.estimators.Estimator, verb) and hasattr(StepEstimator, verb), verb
    # the recursive filters share the step-based template, the MHE keeps the contract by itself, with no step
    assert not issubclass(ESTIMATORS["mhe"], StepEstimator)
    mhe = make("mhe", linear[1], Q, R)
    assert not hasattr(mhe, "step") and isinstance(mhe.options, cs.estimators.MHEOptions)


# -- constructor, options, step -----------------------------------------------------------------------

@pytest.mark.parametrize("name", NAMES)
def test_typed_options(name, linear):
    m, dm, *_ = linear
    cls = ESTIMATORS[name]
    assert issubclass(cls.Options, EstimatorOptions) and dataclasses.is_dataclass(cls.Options)
    est = make(name, dm, Q, R)
    assert isinstance(est.options, cls.Options)
    with pytest.raises(dataclasses.FrozenInstanceError):
        est.options.jit = True
    # a mapping and the dataclass are the same; an unknown key raises naming it and listing the known
    typed = make(name, dm, Q, R, outputs="all").options
    assert cls(dm, Q, R, options=typed).options == typed
    with pytest.raises(ValueError, match=r"unknown option\(s\) \['colour'\].*known: \[.*'jit'"):
        cls(dm, Q, R, options={"colour": "red"})
    with pytest.raises(ValueError, match="outputs"):
        cls(dm, Q, R, options={"outputs": ("x", "nees")})
    with pytest.raises(TypeError, match="DiscreteModel"):
        cls(m, Q, R)
    with pytest.raises(ValueError, match=r"unknown measured output\(s\) \['heading'\]"):
        cls(dm, Q, R, measured=["heading"])


@pytest.mark.parametrize("name", NAMES)
def test_step_has_named_slots_and_matrix_shapes(name, linear):
    m, dm, *_ = linear
    est = make(name, dm, Q, R)
    if not isinstance(est, StepEstimator):      # not of the step family: no step at all, nothing refused
        assert not hasattr(est, "step") and not hasattr(est, "step_function")
        return
    step, full = est.step, est.step_function("all")
    memory = est.memory
    draws = [n for n in step.name_in() if n.startswith("z_")]
    assert step.name_in() == [*memory, "u_prev", "u", "y", "mask", "dt", "p", "Q", "R", "gate", *draws]
    assert step.name_out() == [*memory, *(o for o in ("x", "P") if o not in memory)]     # lean by default
    assert full.name_out()[len(memory):] == [o for o in cs.estimators.options.DIAGNOSTICS if o not in memory]
    assert full.size_out("P") == (m.nx, m.nx) and full.size_out("K") == (m.nx, est.ny)
    assert full.size_in("Q") == (m.nw, m.nw) and full.size_in("R") == (est.ny, est.ny)
    for slot in memory:
        assert step.size_in(slot) == step.size_out(slot)


# -- linear model: everything equals the Kalman filter and python-control --------------------------------

@pytest.mark.parametrize("name", NAMES)
def test_linear_model_equals_kf_and_python_control(name, linear, kf_reference):
    m, dm, traj, data, prior = linear
    cls = ESTIMATORS[name]
    est = make(name, dm, Q, R)
    res = est.filter(data, prior, seed=5)
    H = np.array(m.h_jac(m.states(), m.inputs(), m.params())[0])
    if cls.continuous:                      # Kalman-Bucy: its stationary covariance is lqe's
        jac = m.f_jac(m.states(), m.inputs(), m.params(), [0.0])
        A, G = np.array(jac[0]), np.array(jac[3])
        L, P, _ = control.lqe(A, G, H, np.atleast_2d(Q) * dm.dt, np.diag(R) * dm.dt)
        np.testing.assert_allclose(res.P[-1], P, rtol=1e-7)
        np.testing.assert_allclose(est.steady_state()[0], L, rtol=1e-10)
        return
    A, _, G = dm.linearize(m.states(), m.inputs())
    L, P, _ = control.dlqe(A, G, H, np.atleast_2d(Q), np.diag(R))
    kf = kf_reference
    if cls.stochastic:                      # within the Monte Carlo error of 100 members
        assert np.abs(res.x - kf.x).mean() < 0.25 * kf.std.mean()
        np.testing.assert_allclose(res.P_pred[-50:].mean(axis=0), P, rtol=0.35, atol=0.1 * np.abs(P).max())
        return
    np.testing.assert_allclose(res.x, kf.x, rtol=1e-7, atol=1e-8)
    np.testing.assert_allclose(res.P, kf.P, rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(res.P_pred[-1], P, rtol=1e-8)
    np.testing.assert_allclose(res.K, kf.K, rtol=1e-7, atol=1e-10)
    np.testing.assert_allclose(res.loglik, kf.loglik, rtol=1e-7)


# -- missing data, angles -------------------------------------------------------------------------------

@pytest.mark.parametrize("name", NAMES)
def test_nan_rows_skip_the_update(name, linear):
    m, dm, traj, data, prior = linear
    gap = (np.arange(len(data)) >= 100) & (np.arange(len(data)) < 110)
    holes = data.with_columns(y1=np.where(gap, np.nan, data["y1"]), y2=np.where(gap, np.nan, data["y2"]))
    est = make(name, dm, Q, R)
    res = est.filter(holes, prior, seed=5)
    assert np.isnan(res.innovations[gap]).all() and np.isfinite(res.innovations[~gap]).all()
    assert (res.n_measured[gap] == 0).all() and not res.rejected.any()
    assert np.all(res.K[gap] == 0) and np.all(res.nis[gap] == 0)
    rows = np.flatnonzero(gap)
    if ESTIMATORS[name].continuous:         # the filter only integrates the dynamics: its own prediction
        for k in rows[:3]:
            head = res.replace(**{f: getattr(res, f)[:k] for f in ("t", "x", "P", "x_pred", "P_pred", "C", "K",
                                                                   "innovations", "S", "nis", "n_measured",
                                                                   "loglik_terms", "rejected", "inputs")})
            pred = est.predict(head, [data.t[k]], u=holes["f"][k - 1])
            np.testing.assert_allclose(pred.x[0], res.x[k], rtol=1e-12, atol=1e-14)
    else:
        np.testing.assert_allclose(res.x[gap], res.x_pred[gap], rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(res.P[gap], res.P_pred[gap], rtol=1e-9, atol=1e-14)
    # the covariance grows through the gap and the filter is back after it
    var = res.P[:, 0, 0]
    assert np.all(np.diff(var[rows]) > 0)
    assert var[rows[-1] + 5] < var[rows[-1]]


@pytest.mark.parametrize("name", NAMES)
def test_angle_residuals_wrapped(name):
    """Heading through +-180 deg, prior on the other side of the cut: no spike, no 2 pi innovation."""
    m = cs.models.nomoto_first_order()
    dm = cs.discretize(m, 0.2)
    t = np.arange(0.0, 60.0, 0.2)
    traj = cs.simulate(m, m.states(psi=np.deg2rad(179.0), r=0.004), t, {"delta": 0.0})
    data = cs.measure(traj, m, {"psi": np.deg2rad(0.5)}, seed=5)
    prior = cs.Gaussian(m.states(psi=np.deg2rad(-179.5), r=0.0), [np.deg2rad(2) ** 2, 1e-5])
    res = make(name, dm, 1e-8, np.deg2rad(0.5) ** 2).filter(data, prior, seed=3)
    assert np.abs(res.innovations[:, 0]).max() < np.deg2rad(10.0)
    assert np.abs(np.rad2deg(cs.wrap(res["psi"] - traj["psi"]))).max() < 2.0
    assert np.abs(np.rad2deg(cs.wrap(np.diff(res["psi"][5:])))).max() < 1.0    # no jump at the cut
    assert np.abs(res["r"] - traj["r"]).max() < 0.01


# -- batch = online; lean = full ---------------------------------------------------------------------------

@pytest.mark.parametrize("name", NAMES)
def test_batch_equals_online_and_lean_equals_full(name, linear):
    m, dm, traj, data, prior = linear
    data = data.slice(0, 120)
    lean, full = make(name, dm, Q, R), make(name, dm, Q, R, outputs="all")
    res = lean.filter(data, prior, seed=9)
    Y, U = data.matrix(["y1", "y2"]), data.matrix(["f"])
    runs = [lean.online(prior, seed=9, u=U[0]), full.online(prior, seed=9, u=U[0])]
    for k in range(len(data)):
        dt = data.t[k] - data.t[k - 1] if k else 0.0
        xs = [run.update(Y[k], dt, u_prev=U[max(k - 1, 0)], u=U[k]) for run in runs]
        np.testing.assert_allclose(xs[0], res.x[k], rtol=1e-10, atol=1e-12)
        np.testing.assert_array_equal(xs[0], xs[1])                 # the lean step computes x and P alike
        np.testing.assert_array_equal(runs[0].P, runs[1].P)
        np.testing.assert_allclose(runs[0].P, res.P[k], rtol=1e-10, atol=1e-14)
        assert runs[1].info["nis"] == pytest.approx(res.nis[k], rel=1e-9, abs=1e-12)
    with pytest.raises(ValueError, match="y must hold 2 values"):
        runs[0].update([1.0], 0.1)
    with pytest.raises(ValueError, match="dt must be >= 0"):
        runs[0].update(Y[0], -0.1)


# -- masked and infinite samples: the same meaning for every estimator, batch and online ----------------------

def _hidden(data):
    """Rows 20..29 of y1 and every third row of y2 masked, with a wild value hidden under the mask."""
    k = np.arange(len(data))
    masks = {"y1": (k >= 20) & (k < 30), "y2": k % 3 == 1}
    masked = {n: np.ma.array(np.where(masks[n], 1e3, data[n]), mask=masks[n]) for n in masks}
    nan = {n: np.where(masks[n], np.nan, data[n]) for n in masks}
    return masks, masked, nan


@pytest.mark.parametrize("name", NAMES)
def test_masked_samples_are_not_measured_in_batch_and_online(name, linear):
    """Masked = NaN = not measured, whatever the value under the mask (before: the MHE's online run used it)."""
    m, dm, traj, data, prior = linear
    data = data.slice(0, 60)
    masks, masked, nan = _hidden(data)
    est = make(name, dm, Q, R)
    by_nan = est.filter(data.with_columns(**nan), prior, seed=2)
    by_mask = est.filter(cs.Dataset(data.t, {"f": data["f"], **masked}), prior, seed=2)
    np.testing.assert_array_equal(by_mask.x, by_nan.x)
    np.testing.assert_array_equal(by_mask.n_measured, by_nan.n_measured)
    assert (by_nan.n_measured[20:30] == [1, 1, 0, 1, 1, 0, 1, 1, 0, 1]).all()
    U = data.matrix(["f"])
    runs = [est.online(prior, seed=2, u=U[0]) for _ in range(2)]
    for k in range(len(data)):
        dt = data.t[k] - data.t[k - 1] if k else 0.0
        hidden = np.ma.array([masked[n].data[k] for n in ("y1", "y2")], mask=[masks[n][k] for n in ("y1", "y2")])
        xa = runs[0].update(hidden, dt, u_prev=U[max(k - 1, 0)], u=U[k])
        xb = runs[1].update(np.array([nan["y1"][k], nan["y2"][k]]), dt, u_prev=U[max(k - 1, 0)], u=U[k])
        np.testing.assert_array_equal(xa, xb)
        np.testing.assert_allclose(xa, by_nan.x[k], rtol=1e-9, atol=1e-11)
    with pytest.raises(InputError, match=r"u is masked for \['f'\]; inputs must be given"):
        runs[0].update([0.1, 0.2], 0.1, u=np.ma.array([0.1], mask=[True]))


def test_a_masked_heading_leaves_every_estimator_where_nothing_measured_does():
    """The defect of the MHE: ``update(np.ma.array([5.0], mask=[True]), dt)`` moved psi on a Nomoto model."""
    m = cs.models.nomoto_first_order()
    dm = cs.discretize(m, 0.1)
    prior = cs.Gaussian(m.states(), [1e-2, 1e-4])
    for name in NAMES:
        est = make(name, dm, 1e-6, 1e-4)
        a, b = est.online(prior, seed=1), est.online(prior, seed=1)
        xa = a.update(np.ma.array([5.0], mask=[True]), 0.1)
        xb = b.update(np.array([np.nan]), 0.1)
        np.testing.assert_array_equal(xa, xb, err_msg=name)
        assert abs(xa[m.state_names.index("psi")]) < 0.05, name      # the hidden 5 rad pulls it to about -1.3


@pytest.mark.parametrize("name", NAMES)
def test_infinite_samples_are_refused_naming_the_item_in_batch_and_online(name, linear):
    m, dm, traj, data, prior = linear
    data = data.slice(0, 20)
    est = make(name, dm, Q, R)
    y2 = np.where(np.arange(20) == 7, -np.inf, data["y2"])
    with pytest.raises(InputError, match=r"measurement 'y2' is infinite at row 7 \(NaN means not measured\)"):
        est.filter(data.with_columns(y2=y2), prior, seed=1)
    f = np.where(np.arange(20) == 4, np.inf, data["f"])
    with pytest.raises(InputError, match=r"input 'f' is not finite at row 4"):
        est.filter(data.with_columns(f=f), prior, seed=1)
    run = est.online(prior, seed=1, u=[0.0])
    run.update([0.1, 0.2], 0.0)
    x, P = run.x, run.P
    for args, message in ((([0.1, np.inf], 0.1), r"measurement\(s\) \['y2'\] infinite \(NaN means not measured\)"),
                          (([0.1, 0.2], 0.1, [np.inf]), r"inputs \['f'\] must be finite, got u_prev = \[inf\]"),
                          (([0.1, 0.2], 0.1, [0.0], [np.nan]), r"inputs \['f'\] must be finite, got u = \[nan\]"),
                          (([0.1, 0.2], np.inf), r"dt must be >= 0 and finite, got inf")):
        with pytest.raises(InputError, match=message):
            run.update(*args)
        np.testing.assert_array_equal(run.x, x)                   # a refused sample changes nothing
        np.testing.assert_array_equal(run.P, P)
    assert run.samples == 1
    with pytest.raises(InputError, match=r"u must hold 1 value for \['f'\]"):
        est.online(prior, u=[0.0, 1.0])
    with pytest.raises(InputError, match=r"inputs \['f'\] must be finite, got u = \[nan\]"):
        est.online(prior, u=[np.nan])


def test_one_sample_check_for_every_engine(linear):
    """The same bad sample is refused with the same words by every estimator's online run (one check)."""
    m, dm, traj, data, prior = linear
    bad = [(([0.1], 0.1), "y"), (([0.1, np.inf], 0.1), "infinite"), (("ab", 0.1), "numbers"),
           (([[0.1, 0.2]], 0.1), "shape"), (([0.1, 0.2], -1.0), "dt"), (([0.1, 0.2], "0.1"), "dt"),
           (([0.1, 0.2], 0.1, [np.nan]), "input"), (([0.1, 0.2], 0.1, None, [1.0, 2.0]), "u"),
           (([0.1, 0.2], 0.1, np.ma.array([0.1], mask=[True])), "masked input")]
    messages = {}
    for name in NAMES:
        run = make(name, dm, Q, R).online(prior, seed=1, u=[0.0])
        run.update([0.1, 0.2], 0.0)
        for k, (args, _) in enumerate(bad):
            with pytest.raises(InputError) as info:
                run.update(*args)
            messages.setdefault(k, {})[name] = str(info.value)
    for k, by_name in messages.items():
        assert len(set(by_name.values())) == 1, (bad[k][1], by_name)


# -- time gaps ------------------------------------------------------------------------------------------------

def _gap_case(linear):
    """The oscillator record's first 6 s with a gap of 5.1 s between rows 29 and 30."""
    m, dm, traj, data, prior = linear
    d = data.slice(0, 60)
    t = d.t + np.where(np.arange(len(d)) >= 30, 5.0, 0.0)
    return dm, cs.Dataset(t, {k: d[k] for k in ("f", "y1", "y2")}), prior


@pytest.mark.parametrize("name", NAMES)
def test_time_gaps_raise_or_are_bridged_alike_in_batch_and_online(name, linear):
    dm, gapped, prior = _gap_case(linear)
    msg = rf"{ESTIMATORS[name].name}: time gap of 5.1 s between t = 2.9 and 8 s \(rows 29 and 30\) is longer than 1 s"
    with pytest.raises(ValueError, match=msg):
        make(name, dm, Q, R, max_gap=1.0).filter(gapped, prior, seed=1)
    # beyond the stability limit of the rk4 prediction (the default limit) as well
    far = cs.Dataset(np.concatenate([gapped.t[:30], gapped.t[30:] + 1e4]), {k: gapped[k] for k in ("f", "y1", "y2")})
    with pytest.raises(ValueError, match="is longer than .* s, the longest interval the rk4 prediction bridges"):
        make(name, dm, Q, R).filter(far, prior, seed=1)
    est = make(name, dm, Q, R, max_gap=1.0, on_gap="bridge", outputs="all")
    with pytest.warns(UserWarning, match=r"1 time gap\(s\) longer than the prediction bridges in one step .* bridged by 10 prediction-only row"):
        res = est.filter(gapped, prior, seed=4)
    rows = np.flatnonzero(np.isin(res.t, gapped.t))
    inserted = np.setdiff1d(np.arange(len(res.t)), rows)
    assert len(res.t) == len(gapped) + 10 and np.diff(res.t).max() <= 0.5 + 1e-12
    assert (res.n_measured[inserted] == 0).all() and np.isfinite(res.x).all()
    spread = np.einsum("kii->k", res.P)
    assert spread[inserted].max() > 2 * spread[rows[29]]          # the belief spreads across the gap
    # online: the same bridging, the same numbers at the record's rows
    U, Y = gapped.matrix(["f"]), gapped.matrix(["y1", "y2"])
    run = est.online(prior, seed=4, u=U[0])
    for k in range(len(gapped)):
        dt = gapped.t[k] - gapped.t[k - 1] if k else 0.0
        if k == 30:
            with pytest.warns(UserWarning, match="time gap of 5.1 s before update 31 bridged by 10 prediction-only"):
                x = run.update(Y[k], dt, u_prev=U[k - 1], u=U[k])
        else:
            x = run.update(Y[k], dt, u_prev=U[max(k - 1, 0)], u=U[k])
        np.testing.assert_allclose(x, res.x[rows[k]], rtol=1e-9, atol=1e-11)
        np.testing.assert_allclose(run.P, res.P[rows[k]], rtol=1e-9, atol=1e-13)
    refusing = make(name, dm, Q, R, max_gap=1.0).online(prior, seed=4, u=U[0])
    refusing.update(Y[0], 0.0, u_prev=U[0], u=U[0])
    x0, P0 = refusing.x, refusing.P
    with pytest.raises(ValueError, match="time gap of 5.1 s before update 2 is longer than 1 s"):
        refusing.update(Y[1], 5.1, u_prev=U[0], u=U[1])
    np.testing.assert_array_equal(refusing.x, x0)               # a refused update changes nothing
    np.testing.assert_array_equal(refusing.P, P0)


# -- statistical consistency on a nonlinear ship model ---------------------------------------------------

def ship_case(seed, linear=False, n=375, dt=0.2):
    """A ship with matched process noise, the truth drawn from the prior: the Taylor response model of
    Shi et al. (2009) measuring surge speed, yaw rate and heading (positions dead-reckoned), or for
    estimators that need a linear model the first-order Nomoto model measuring heading."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * dt
    if linear:
        m = cs.models.nomoto_first_order()
        Qd, P0, std = np.array([1e-7]), np.diag([1e-3, 1e-5]), {"psi": 0.01}
        inputs = {"delta": 0.1 * np.sign(np.sin(2 * np.pi * t / 60))}
    else:
        m = cs.models.shi_taylor().with_outputs(["u", "r", "psi"])
        Qd, P0 = np.array([1e-4, 1e-4, 1e-6]), np.diag([0.04, 0.01, 1e-5, 1.0, 1.0, 1e-3])
        std = {"u": 0.05, "r": 1e-3, "psi": 0.01}
        inputs = {"delta": 0.2 * np.sign(np.sin(2 * np.pi * t / 40)), "n": 1.5}
    prior = cs.Gaussian(m.states(u=8.0) if "u" in m.state_names else m.states(), P0)
    tr = cs.simulate(m, prior.sample(1, rng)[0], t, inputs, w=rng.standard_normal((n, m.nw)) * np.sqrt(Qd))
    data = cs.measure(tr, m, std, seed=rng)
    return cs.discretize(m, dt, "rk4"), tr, data, prior, Qd, {k: v**2 for k, v in std.items()}


# options under which a stochastic estimator's sampling error is small against the chi-square band
# (with 100 members the EnKF's spurious correlations shrink the spread of the unmeasured positions)
CONSISTENT = {"enkf": {"members": 1000, "jit": True}}


@pytest.mark.parametrize("name", NAMES)
def test_nees_and_nis_inside_chi_square_bounds(name):
    """Monte Carlo (M runs, truth drawn from the prior, matched noise): the average NEES and NIS
    inside their 95 % chi-square bounds (Bar-Shalom et al. 2001, Sec. 5.4), overall and at most steps."""
    M = 16
    linear = getattr(ESTIMATORS[name], "linear", False)
    nees, nis = [], []
    est = None
    for run in range(M):
        dm, tr, data, prior, Qd, Rd = ship_case(200 + run, linear)
        est = est or make(name, dm, Qd, Rd, **CONSISTENT.get(name, {}))
        res = est.filter(data, prior, seed=run)
        nees.append(res.nees(tr.x))
        nis.append(res.nis)
    for values, dof in ((np.mean(nees, axis=0), dm.model.nx), (np.mean(nis, axis=0), len(Rd))):
        lo, hi = stats.chi2.ppf([0.025, 0.975], M * dof) / M
        assert lo < values.mean() < hi, (values.mean(), lo, hi)
        assert np.mean((values > lo) & (values < hi)) > 0.85


# -- results are values --------------------------------------------------------------------------------

@pytest.mark.parametrize("name", NAMES)
def test_results_are_values(name, linear, tmp_path):
    m, dm, traj, data, prior = linear
    est = make(name, dm, Q, R)
    res = est.filter(data.slice(0, 80), prior, seed=1)
    assert isinstance(res, FilterResult)
    with pytest.raises(dataclasses.FrozenInstanceError):
        res.x = res.x + 1
    with pytest.raises(ValueError, match="read-only"):
        res.x[0, 0] = 1.0
    text = repr(res)
    assert "\n" not in text and len(text) < 200 and res.estimator in text
    assert res.estimator in res.summary() and "x1" in res.summary()
    back = FilterResult.load(res.save(tmp_path / "run.npz"))
    for f in dataclasses.fields(FilterResult):
        a, b = getattr(res, f.name), getattr(back, f.name)
        if isinstance(a, np.ndarray):
            np.testing.assert_array_equal(a, b)
        else:
            assert a == b, f.name
    assert res.plot(tmp_path / "run.png").stat().st_size > 1000
    with pytest.raises(ValueError, match="unknown state 'x3'"):
        res["x3"]
    assert res.health().ok
    # prediction past the last sample: the belief spreads, nothing is measured
    pred = est.predict(res, 2.0, seed=2)
    assert pred.estimator == f"{est.name} prediction" and pred.t[0] > res.t[-1] and (pred.n_measured == 0).all()
    assert np.trace(pred.P[-1]) > np.trace(res.P[-1])
    # one smoothing entry point: a smoothed result, or a reason why not
    if ESTIMATORS[name].continuous:
        with pytest.raises(ValueError, match="no smoother"):
            est.smooth(data.slice(0, 80), prior)
    else:
        sm = est.smooth(data.slice(0, 80), prior, seed=1)
        assert sm.t.size == res.t.size and sm.health().not_pd.size == 0
        assert np.all(np.einsum("kii->ki", sm.P)[:-1].mean(axis=0) <= np.einsum("kii->ki", res.P)[:-1].mean(axis=0))
