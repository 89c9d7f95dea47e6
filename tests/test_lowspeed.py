"""Yoshimura low-speed twin-rudder model: cross-flow integrals, Jacobians, symmetry, sanity."""
import numpy as np

from casship import simulate
from casship.maneuvers import propeller_rate_for_speed, random_rudder_inputs
from casship.models import get_model
from casship.models.lowspeed import crossflow_integrals, esso_osaka_twin
from model_checks import assert_jacobians


_GAUSS = np.polynomial.legendre.leggauss(100)


def _reference(a, b, nodes=100, panels=20):
    """Fine composite Gauss-Legendre quadrature: 20 panels of 100 nodes each side of the zero of a + b xi."""
    cuts = [-0.5, 0.5]
    if b != 0 and abs(a / b) < 0.5:
        cuts = [-0.5, -a / b, 0.5]
    xg, wg = _GAUSS if nodes == _GAUSS[0].size else np.polynomial.legendre.leggauss(nodes)
    edges = np.concatenate([np.linspace(lo, hi, panels + 1) for lo, hi in zip(cuts[:-1], cuts[1:])])
    lo, hi = edges.reshape(-1, panels + 1)[:, :-1].ravel(), edges.reshape(-1, panels + 1)[:, 1:].ravel()
    half = 0.5 * (hi - lo)[:, None]
    s = half * xg[None, :] + 0.5 * (hi + lo)[:, None]
    g = np.abs(a + b * s) * (a + b * s)
    return float(np.sum(half * wg * g)), float(np.sum(half * wg * g * s))


def test_closed_form_matches_fine_quadrature():
    """Stated tolerance: |closed form - quadrature| <= 1e-12 (a^2 + b^2) over both branches."""
    rng = np.random.default_rng(7)
    cases = [(0.0, 0.0), (0.3, 0.0), (0.0, 0.4), (0.1, 0.2), (0.1, -0.2), (-0.05, 2.0), (1e-9, 1.0)]
    cases += [tuple(rng.normal(size=2) * rng.choice([1e-3, 1.0, 10.0])) for _ in range(200)]
    for a, b in cases:
        I0, I1 = crossflow_integrals(a, b)
        R0, R1 = _reference(a, b)
        tol = 1e-12 * max(a * a + b * b, 1e-30)
        assert abs(I0 - R0) <= tol and abs(I1 - R1) <= tol, (a, b, I0 - R0, I1 - R1)


def test_closed_form_beats_the_trapezoid_rule_it_replaces():
    a, b = 0.05, 0.4            # the flow changes sign on the hull
    I0, I1 = crossflow_integrals(a, b)
    s = np.linspace(-0.5, 0.5, 101)     # 100 strips, as in the public implementations
    g = np.abs(a + b * s) * (a + b * s)
    assert abs(np.trapezoid(g, s) - I0) > 1e-7
    assert abs(np.trapezoid(g * s, s) - I1) > 1e-8


def test_registered_and_inputs():
    ship = get_model("mmg-twin-lowspeed")
    assert ship.input_names == ("n", "delta_s", "delta_p")
    assert ship.state_names == ("u", "v", "r", "x", "y", "psi")
    assert "ASSUMED" in {v.name: v.source for v in ship.param_vars}["A_R"]


def test_jacobians_including_rest_and_astern():
    ship = esso_osaka_twin()
    rng = np.random.default_rng(11)
    points = [(0.0, 0.0, 0.0), (-0.1, 0.02, 0.01), (0.4, 0.0, 0.0)]
    points += [(rng.uniform(-0.2, 0.6), rng.uniform(-0.1, 0.1), rng.uniform(-0.2, 0.2)) for _ in range(5)]
    for u, v, r in points:
        x = ship.states(u=u, v=v, r=r, x=1.0, y=-2.0, psi=rng.uniform(-3, 3))
        inp = ship.inputs(n=rng.uniform(2, 15), delta_s=rng.uniform(-0.6, 1.8), delta_p=rng.uniform(-1.8, 0.6))
        # near rest the smoothing scale is 1e-4 m/s, so difference with a smaller step there
        assert_jacobians(ship, x, inp, h=1e-9 if abs(u) + abs(v) < 1e-2 else 1e-6)


def test_mirror_symmetry_of_twin_rudders():
    """(delta_s, delta_p) -> (-delta_p, -delta_s) mirrors the motion (symmetric hull, no propeller side force)."""
    ship = esso_osaka_twin({"x_G_dash": 0.03119})
    t = np.arange(0, 60, 0.1)
    a = simulate(ship, ship.states(u=0.4), t, {"n": 11.0, "delta_s": 0.5, "delta_p": 0.2})
    b = simulate(ship, ship.states(u=0.4), t, {"n": 11.0, "delta_s": -0.2, "delta_p": -0.5})
    np.testing.assert_allclose(a["u"], b["u"], rtol=1e-10, atol=1e-12)
    for name in ("v", "r", "y", "psi"):
        np.testing.assert_allclose(a[name], -b[name], rtol=1e-9, atol=1e-12)
    assert a["psi"][-1] > 0.1


def test_straight_run_and_no_propeller():
    ship = esso_osaka_twin()
    n0 = propeller_rate_for_speed(ship, 0.4)
    t = np.arange(0, 100, 0.1)
    tr = simulate(ship, ship.states(u=0.4, psi=-0.7), t, {"n": n0, "delta_s": 0.0, "delta_p": 0.0})
    np.testing.assert_allclose(tr["u"], 0.4, atol=1e-9)
    np.testing.assert_allclose(tr["psi"], -0.7, atol=1e-12)
    tr = simulate(ship, ship.states(u=0.4), t, {"n": 0.0, "delta_s": 0.0, "delta_p": 0.0})
    assert np.all(np.diff(tr["u"]) < 0) and tr["u"][-1] < 0.3


def test_hovering_rudders_brake():
    """VecTwin-style 105/-105 deg rudders brake the ship (Koike et al. 2023 ranges)."""
    ship = esso_osaka_twin()
    f = np.asarray(ship.f(ship.states(u=0.3), ship.inputs(n=11.0, delta_s=np.radians(105), delta_p=-np.radians(105)),
                          ship.params(), np.zeros(3))).ravel()
    assert f[0] < 0 and abs(f[2]) < 1e-12


def test_random_rudder_sequence_koike2023_ranges():
    ship = esso_osaka_twin()
    t = np.arange(0, 300, 0.1)
    u = random_rudder_inputs(ship, t, 11.0, hold=10.0, seed=2)
    assert np.degrees(u["delta_s"]).min() >= -35 and np.degrees(u["delta_s"]).max() <= 105
    assert np.degrees(u["delta_p"]).min() >= -105 and np.degrees(u["delta_p"]).max() <= 35
    assert np.degrees(u["delta_s"]).max() > 60     # the sequence really uses the wide range
    tr = simulate(ship, ship.states(u=0.4), t, u)
    assert np.all(np.isfinite(tr.x))
