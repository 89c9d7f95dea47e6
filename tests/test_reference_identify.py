"""Reference values of the identification's bookkeeping: the robust (HAC) covariance against a
hand-written Newey-West estimate with Bartlett weights and Andrews' (1991) bandwidth, the truth table of
the rule that decides when a port/starboard asymmetry is estimable from mirror pairs, and the output
and input biases when cross-validation replays a held-out record."""
from __future__ import annotations

import math

import numpy as np
import pytest

import casship as cs
from casship.identify import asymmetry
from casship.identify.uncertainty import _bandwidth, sandwich_covariance


# -- HAC (Newey-West) covariance ---------------------------------------------------------------------------------
def andrews_bandwidth(s):
    """Andrews (1991, eq. 6.4 with the AR(1) plug-in) for the Bartlett kernel, by the formula:
    S = 1.1447 (alpha(1) n)^(1/3), alpha(1) = sum 4 rho^2 sig^4 / ((1-rho)^6 (1+rho)^2) / sum sig^4/(1-rho)^4."""
    n, num, den = s.shape[0], 0.0, 0.0
    for a in range(s.shape[1]):
        x = s[:, a]
        rho = sum(x[t] * x[t + 1] for t in range(n - 1)) / sum(x[t] ** 2 for t in range(n - 1))
        rho = min(max(rho, -0.97), 0.97)
        sig2 = sum((x[t + 1] - rho * x[t]) ** 2 for t in range(n - 1)) / (n - 1)
        num += 4 * rho**2 * sig2**2 / ((1 - rho) ** 6 * (1 + rho) ** 2)
        den += sig2**2 / (1 - rho) ** 4
    return min(n // 4, math.ceil(1.1447 * (num / den * n) ** (1 / 3)))


def newey_west(s, L):
    """sum_t s_t s_t' + sum_{l=1..L} (1 - l/(L+1)) sum_t (s_t s_{t-l}' + s_{t-l} s_t'), written out."""
    n, k = s.shape
    B = np.zeros((k, k))
    for t in range(n):
        B += np.outer(s[t], s[t])
    for lag in range(1, L + 1):
        w = 1.0 - lag / (L + 1.0)
        for t in range(lag, n):
            B += w * (np.outer(s[t], s[t - lag]) + np.outer(s[t - lag], s[t]))
    return B


def ar1_scores(n, k, rho, seed):
    rng = np.random.default_rng(seed)
    s = np.zeros((n, k))
    e = rng.standard_normal((n, k))
    for t in range(1, n):
        s[t] = rho * s[t - 1] + e[t]
    return s - s.mean(axis=0)


def test_bandwidth_is_andrews_bartlett_plug_in():
    for n, rho, seed in ((400, 0.5, 1), (400, 0.9, 2), (1000, 0.2, 3), (40, 0.95, 4)):
        s = ar1_scores(n, 2, rho, seed)
        assert _bandwidth(s) == andrews_bandwidth(s), (n, rho)
    assert _bandwidth(ar1_scores(40, 1, 0.99, 5)) == 10               # capped at a quarter of the record


def test_bartlett_weights_on_a_small_exact_case():
    # n = 8 strongly autocorrelated scores: the bandwidth is the cap n // 4 = 2, weights 2/3 and 1/3
    s = np.array([[1.0], [2.0], [3.0], [4.0], [4.0], [3.0], [2.0], [1.0]]) - 2.5
    assert _bandwidth(s) == 2
    g0 = float(np.sum(s[:, 0] ** 2))
    g1 = float(np.sum(s[1:, 0] * s[:-1, 0]))
    g2 = float(np.sum(s[2:, 0] * s[:-2, 0]))
    B = g0 + 2 * (2 / 3) * g1 + 2 * (1 / 3) * g2
    cov, lags = sandwich_covariance(np.array([[2.0]]), np.zeros(1), [(s, [0])], 1, ["a"])
    assert lags == [2]
    assert cov[0, 0] == pytest.approx(B / 4.0, rel=1e-12)             # H^-1 B H^-1 with H = 2


def test_sandwich_is_h_inverse_b_h_inverse_with_newey_west():
    rng = np.random.default_rng(7)
    s1, s2 = ar1_scores(300, 3, 0.7, 8), ar1_scores(200, 2, 0.4, 9)
    A = rng.standard_normal((3, 3))
    H = A @ A.T + 3 * np.eye(3)
    cov, lags = sandwich_covariance(H, np.zeros(3), [(s1, [0, 1, 2]), (s2, [0, 2])], 3, ["a", "b", "c"])
    L1, L2 = andrews_bandwidth(s1), andrews_bandwidth(s2)
    assert lags == [L1, L2] and L1 > 1 and L2 > 1
    B = newey_west(s1, L1)
    B[np.ix_([0, 2], [0, 2])] += newey_west(s2, L2)          # records independent: no cross terms
    Hi = np.linalg.inv(H)
    np.testing.assert_allclose(cov, Hi @ B @ Hi, rtol=1e-9)
    # with a prior: (H B^-1 H + diag(prior precision))^-1
    prec = np.array([0.5, 0.0, 2.0])
    cov_p, _ = sandwich_covariance(H, prec, [(s1, [0, 1, 2]), (s2, [0, 2])], 3, ["a", "b", "c"])
    np.testing.assert_allclose(cov_p, np.linalg.inv(H @ np.linalg.inv(B) @ H + np.diag(prec)), rtol=1e-9)


# -- when a per-group asymmetry is estimable: the truth table of the mirror-pair rule ----------------------------
def sig(kind="zigzag", rudder=10.0, heading=10.0, side="+"):
    return {"kind": kind, "rudder_deg": rudder, "heading_deg": heading if kind == "zigzag" else None, "side": side}


@pytest.fixture
def signatures(monkeypatch):
    """Records stand for their own signature: the rule is tested apart from the classification of records."""
    monkeypatch.setattr(asymmetry, "maneuver_signature", lambda record, rudder="delta": record)


@pytest.mark.parametrize("a, b, estimable", [
    (sig(side="+"), sig(side="-"), True),                                    # the same zig-zag both ways
    (sig(side="+"), sig(side="+"), False),                                   # the same side twice
    (sig(side="-"), sig(side="-"), False),
    (sig(rudder=10.0), sig(rudder=12.0, side="-"), True),                   # rudder within 2 deg (edge)
    (sig(rudder=10.0), sig(rudder=12.5, side="-"), False),                  # rudder 2.5 deg apart
    (sig(heading=10.0), sig(heading=8.0, side="-"), True),                  # switch heading within 2 deg (edge)
    (sig(heading=10.0), sig(heading=7.5, side="-"), False),
    (sig("turning", 35.0), sig("turning", 35.0, side="-"), True),           # turning circles both ways
    (sig("turning", 35.0, heading=10.0), sig("turning", 35.0, heading=30.0, side="-"), True),   # heading ignored
    (sig("turning", 35.0), sig("turning", 38.0, side="-"), False),
    (sig("turning", 10.0), sig("zigzag", 10.0, side="-"), False),           # different manoeuvres
    (sig("other", 10.0), sig("other", 10.0, side="-"), False),              # "other" never pairs
])
def test_mirror_pair_truth_table(signatures, a, b, estimable):
    out = asymmetry.confounded_asymmetry([a, b], ["N_0"])
    assert ("N_0" not in out) == estimable
    assert (asymmetry.mirror_pairs([a, b]) == [(0, 1)]) == estimable


@pytest.mark.parametrize("within, estimable", [(None, True), (["A", "A"], True), (["A", "B"], False)])
def test_mirror_pair_only_within_the_same_facility(signatures, within, estimable):
    recs = [sig(side="+"), sig(side="-")]
    assert ("N_0" not in asymmetry.confounded_asymmetry(recs, ["N_0"], within=within)) == estimable
    assert (asymmetry.mirror_pairs(recs, within=within) == [(0, 1)]) == estimable


def test_per_group_copies_need_a_pair_inside_their_group(signatures):
    # groups: A holds a mirror pair (0, 1); B holds two starboard runs (2, 3) whose mirror (1) is in A;
    # C holds one port run; record 5 uses no copy
    recs = [sig(side="+"), sig(side="-"), sig(side="+"), sig(side="+"), sig(side="-"), sig(side="-")]
    copies = {"N_0": ["A", "A", "B", "B", "C", None]}
    q = ["N_0@A", "N_0@B", "N_0@C", "N_0"]
    out = asymmetry.confounded_asymmetry(recs, q, copies)
    assert set(out) == {"N_0@B", "N_0@C"}
    assert "group 'B'" in out["N_0@B"] and "first sides +" in out["N_0@B"]
    assert "first sides -" in out["N_0@C"]
    # a shared copy pairs across all records; a copy of an undeclared group has no records at all
    assert "N_0" not in out
    none = asymmetry.confounded_asymmetry(recs, ["N_0@Z"], copies)
    assert "first sides none" in none["N_0@Z"]
    # the record without a copy does not lend its side to group C
    assert "N_0@C" in asymmetry.confounded_asymmetry(recs, ["N_0@C"], {"N_0": ["A", "A", "B", "B", "C", "C"]}) \
        and "N_0@C" not in asymmetry.confounded_asymmetry(
            [*recs[:5], sig(side="+")], ["N_0@C"], {"N_0": ["A", "A", "B", "B", "C", "C"]})


def test_per_group_pair_within_a_facility(signatures):
    recs = [sig(side="+"), sig(side="-"), sig(side="+"), sig(side="-")]
    copies = {"N_0": ["G", "G", "H", "H"]}
    within = ["A", "B", "A", "A"]          # group G's pair crosses facilities; group H's does not
    out = asymmetry.confounded_asymmetry(recs, ["N_0@G", "N_0@H"], copies, within=within)
    assert set(out) == {"N_0@G"}


def test_turn_side_at_half_the_largest_deflection():
    t = np.arange(6.0)
    d = cs.Dataset(t, {"delta": np.radians([1.0, 1.0, -2.0, 12.0, 21.0, 0.0])})
    # deflections from the approach value 1 deg: 0, 0, -3, 11, 20, -1: the first beyond 10 is +11
    assert asymmetry.turn_side(d) == "+"
    d2 = cs.Dataset(t, {"delta": np.radians([0.0, -11.0, 20.0, 20.0, 20.0, 20.0])})
    assert asymmetry.turn_side(d2) == "-"             # -11 is beyond half of 20
    d3 = cs.Dataset(t, {"delta": np.radians([0.0, -10.0, 20.0, 20.0, 20.0, 20.0])})
    assert asymmetry.turn_side(d3) == "+"             # -10 is not beyond half of 20


# -- cross-validation's replay of a held-out record with the fold's biases -----------------------------------------
def _nomoto_record(b_out=0.0, b_in=0.0):
    m = cs.models.nomoto_first_order(K=0.1, T=20.0)
    t = np.arange(0.0, 60.0, 0.5)
    delta = 0.1 * np.sign(np.sin(2 * np.pi * t / 30.0))
    tr = cs.simulate(m, m.states(), t, {"delta": delta})
    # the rate gyro reads the model's yaw rate plus b_out; the rudder indicator reads the true rudder minus b_in
    data = cs.Dataset(t, {"psi": tr["psi"], "r": tr["r"] + b_out, "delta": delta - b_in})
    return m, data


def test_crossval_replay_removes_an_output_bias_from_the_record():
    """The replay starts from the record's first row: a rate-gyro bias b left in the record starts the
    replay turning at b, and the heading then drifts by b T (1 - exp(-t/T)) (first-order Nomoto)."""
    from casship.identify.crossval import _replay

    b, T = 0.002, 20.0
    m, data = _nomoto_record(b_out=b)
    params = m.param_dict(m.params({"K": 0.1, "T": T}))
    exact = _replay(m, data, params, {"r": b}, "rk4")
    assert exact.errors["psi_rmse_deg"] < 1e-9
    wrong = _replay(m, data, params, {"r": -b}, "rk4")     # bias added instead of removed: starts at 2 b
    t = data.t
    drift = 2 * b * T * (1 - np.exp(-(t - t[0]) / T))
    assert wrong.errors["psi_rmse_deg"] == pytest.approx(np.degrees(np.sqrt(np.mean(drift**2))), rel=1e-6)


def test_crossval_held_out_biases_are_the_copies_of_the_records_group():
    from types import SimpleNamespace

    from casship.identify import OutputErrorProblem
    from casship.identify.crossval import _held_out_values

    m = cs.models.nomoto_first_order()
    t = np.arange(0.0, 40.0, 1.0)
    runs = []
    for i, group in enumerate(("A", "A", "B", "C")):
        d = cs.Dataset(t, {"psi": 0.001 * t, "delta": 0.1 * np.sign(np.sin(t / (5.0 + i)) + 0.5)})
        d.meta.update(name=f"run {i}", facility=group)
        runs.append(d)
    prob = OutputErrorProblem(m, runs, free=["K", "T", "bias[delta]", "bias[psi]"], sigma={"psi": 0.005},
                              share={"bias[delta]": "facility"})
    # the fold that left out facility C estimated the copies of A and B only
    fit = SimpleNamespace(params={"K": 0.2, "T": 30.0},
                          estimates={"K": 0.2, "T": 30.0, "bias[delta]@A": 0.011, "bias[delta]@B": -0.009,
                                     "bias[psi]": 0.003})
    expect = [{"delta": 0.011, "psi": 0.003}, {"delta": 0.011, "psi": 0.003}, {"delta": -0.009, "psi": 0.003},
              {"psi": 0.003}]
    for r, biases in enumerate(expect):
        params, got = _held_out_values(fit, prob, r)
        assert got == biases, r
        assert params["K"] == 0.2 and params["T"] == 30.0


def test_crossval_replay_adds_an_input_bias_to_the_measured_input():
    from casship.identify.crossval import _replay

    m, data = _nomoto_record(b_in=0.01)
    exact = _replay(m, data, m.param_dict(m.params()), {"delta": 0.01}, "rk4")
    assert exact.errors["psi_rmse_deg"] < 1e-9
    none = _replay(m, data, m.param_dict(m.params()), {}, "rk4")
    assert none.errors["psi_rmse_deg"] > 0.1
