"""Property-based tests (hypothesis): angles, names, data import, manoeuvre metrics."""
import keyword

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, example, given, settings
from hypothesis import strategies as st

import casship as cs
from casship import maneuvers
from casship.angles import unwrap, wrap, wrap_sym

# derandomized: the same examples on every run (reproducible in CI), no example database on disk
FAST = settings(max_examples=60, deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.too_slow])
SLOWER = settings(max_examples=15, deadline=None, derandomize=True, database=None,
                  suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])

finite_angles = st.floats(min_value=-1e4, max_value=1e4, allow_nan=False, allow_infinity=False)


# -- angles ----------------------------------------------------------------------------------------

@FAST
@given(finite_angles)
@example(float(np.nextafter(np.pi, 4.0)))      # np.mod rounds up to 2 pi here
@example(-np.pi)
@example(3 * np.pi)
def test_wrap_lands_in_the_half_open_interval_on_the_same_point_of_the_circle(a):
    w = wrap(a)
    assert -np.pi < w <= np.pi
    turns = (a - w) / (2 * np.pi)
    assert abs(turns - round(turns)) < 1e-9 * max(1.0, abs(a))
    assert wrap(w) == w                                   # idempotent


@FAST
@given(finite_angles, st.integers(min_value=-50, max_value=50))
def test_wrap_ignores_whole_turns(a, k):
    d = wrap(a + 2 * np.pi * k) - wrap(a)
    assert abs(wrap(d)) < 1e-9 * max(1.0, abs(a) + abs(k) * 2 * np.pi)


@FAST
@given(st.floats(min_value=-50.0, max_value=50.0))
def test_symbolic_wrap_agrees_with_numeric_wrap_on_the_circle(a):
    import casadi as ca

    x = ca.SX.sym("x")
    fn = ca.Function("w", [x], [wrap_sym(x)])
    assert abs(wrap(float(fn(a)) - wrap(a))) < 1e-12


@FAST
@given(st.lists(st.floats(min_value=-0.5, max_value=0.5), min_size=2, max_size=200),
       st.floats(min_value=-3.0, max_value=3.0))
def test_unwrap_recovers_a_continuous_heading(steps, start):
    heading = start + np.cumsum(steps)                # increments below pi: recoverable
    back = unwrap(wrap(heading))
    offset = back[0] - heading[0]
    assert abs(offset / (2 * np.pi) - round(offset / (2 * np.pi))) < 1e-9
    np.testing.assert_allclose(back - offset, heading, atol=1e-9)


@FAST
@given(st.lists(st.one_of(st.floats(min_value=-3.0, max_value=3.0), st.just(np.nan)), min_size=1, max_size=50))
def test_unwrap_keeps_missing_samples(values):
    a = np.array(values)
    out = unwrap(a)
    np.testing.assert_array_equal(np.isnan(out), np.isnan(a))


# -- names ---------------------------------------------------------------------------------------

identifiers = st.from_regex(r"[A-Za-z_][A-Za-z0-9_]{0,12}", fullmatch=True).filter(
    lambda s: not keyword.iskeyword(s) and s not in ("t", "time"))    # t, time: reserved for time stamps


@SLOWER
@given(st.lists(identifiers, min_size=1, max_size=6, unique=True), st.data())
def test_any_valid_names_work_and_unknown_names_are_named(names, data):
    b = cs.ModelBuilder("named")
    syms = [b.state(n) for n in names]
    b.ode(**{n: -s for n, s in zip(names, syms)})
    m = b.build()
    assert m.state_names == tuple(names)
    values = data.draw(st.lists(st.floats(-1e6, 1e6), min_size=len(names), max_size=len(names)))
    np.testing.assert_array_equal(m.states(**dict(zip(names, values))), values)
    for i, n in enumerate(names):
        assert m.index(n) == i
    stranger = data.draw(identifiers.filter(lambda s: s not in names))
    with pytest.raises(ValueError, match=stranger):
        m.states(**{stranger: 1.0})
    with pytest.raises(ValueError, match=stranger):
        m.index(stranger)


@FAST
@given(st.text(min_size=1, max_size=8).filter(lambda s: not s.isidentifier()))
def test_invalid_identifiers_are_rejected(name):
    with pytest.raises(ValueError, match="not a valid identifier"):
        cs.ModelBuilder("m").state(name)


@FAST
@given(identifiers)
def test_duplicate_names_are_rejected_across_kinds(name):
    b = cs.ModelBuilder("m")
    b.input(name)
    with pytest.raises(ValueError, match=f"{name!r} is already declared as a input"):
        b.param(name, 1.0)


# -- data import ---------------------------------------------------------------------------------

column_names = identifiers
values = st.one_of(st.floats(allow_nan=True, allow_infinity=False, width=64), st.just(np.nan))


@st.composite
def records(draw):
    n = draw(st.integers(min_value=1, max_value=30))
    steps = draw(st.lists(st.floats(min_value=1e-3, max_value=1e3), min_size=n, max_size=n))
    t0 = draw(st.floats(min_value=-1e6, max_value=1e6))
    t = t0 + np.cumsum(steps)
    assume(np.all(np.diff(t) > 0))
    names = draw(st.lists(column_names, min_size=1, max_size=4, unique=True))
    cols = {c: draw(st.lists(values, min_size=n, max_size=n)) for c in names}
    return cs.Dataset(t, cols)


def same(a, b):
    np.testing.assert_array_equal(a.t, b.t)
    assert a.names == b.names
    for c in a.names:
        np.testing.assert_array_equal(a[c], b[c])


@SLOWER
@given(records())
def test_csv_round_trip_is_bit_exact(tmp_path_factory, data):
    path = tmp_path_factory.mktemp("csv") / "rec.csv"
    same(data, cs.Dataset.from_csv(data.to_csv(path)))


@FAST
@given(records())
def test_pandas_round_trip_is_bit_exact(data):
    same(data, cs.Dataset.from_pandas(data.to_pandas()))


# -- manoeuvre metrics: a turning circle drawn exactly ------------------------------------------------

def circle_track(radius, psi0, x0, y0, direction, speed=5.0, dt=0.5):
    """Straight run, then a circle of ``radius`` to starboard (+1) or port (-1) from t = 20 s."""
    t = np.arange(0.0, 20.0 + 2.2 * np.pi * radius / speed, dt)
    tau = np.maximum(t - 20.0, 0.0)
    straight = np.minimum(t, 20.0) * speed
    turn = direction * speed * tau / radius               # heading change
    along = straight + radius * np.sin(np.abs(turn))
    lateral = direction * radius * (1.0 - np.cos(turn))
    x = x0 + along * np.cos(psi0) - lateral * np.sin(psi0)
    y = y0 + along * np.sin(psi0) + lateral * np.cos(psi0)
    return cs.Dataset(t, {"x": x, "y": y, "psi": wrap(psi0 + turn)})


@SLOWER
@given(st.floats(min_value=100.0, max_value=1500.0), st.floats(min_value=-np.pi, max_value=np.pi),
       st.floats(min_value=-1e4, max_value=1e4), st.floats(min_value=-1e4, max_value=1e4),
       st.sampled_from([1, -1]))
def test_turning_metrics_are_those_of_the_circle_whatever_the_pose(radius, psi0, x0, y0, direction):
    m = maneuvers.turning_metrics(circle_track(radius, psi0, x0, y0, direction), t_exec=20.0)
    assert m["turn_direction"] == direction
    # sampling and linear interpolation of the crossing: errors of order (speed dt)^2 / radius
    tol = 2e-3 * radius
    assert m["advance_m"] == pytest.approx(radius, abs=tol)
    assert m["transfer_m"] == pytest.approx(radius, abs=tol)
    assert m["tactical_diameter_m"] == pytest.approx(2 * radius, abs=tol)
    assert m["steady_diameter_m"] == pytest.approx(2 * radius, rel=1e-6)
    assert m["time_to_90_s"] == pytest.approx(0.5 * np.pi * radius / 5.0, abs=0.5)


@SLOWER
@given(st.floats(min_value=12.0, max_value=40.0), st.sampled_from([10.0, 5.0]),
       st.floats(min_value=-np.pi, max_value=np.pi), st.sampled_from([1, -1]),
       st.floats(min_value=60.0, max_value=400.0))
def test_zigzag_metrics_of_a_sinusoidal_heading(amplitude_deg, heading_deg, psi0, side, period):
    """Heading change A sin(2 pi t / T) after the execute: overshoots A - heading, period T, first side,
    whatever the initial heading (also across +-180 deg)."""
    t = np.arange(0.0, 10.0 + 3.2 * period, 0.1)
    change = side * np.radians(amplitude_deg) * np.sin(2 * np.pi * np.maximum(t - 10.0, 0.0) / period)
    data = cs.Dataset(t, {"psi": wrap(psi0 + change)})
    m = maneuvers.zigzag_metrics(data, heading_deg, t_exec=10.0)
    assert m["first_side"] == side
    for k in (1, 2):
        assert m[f"overshoot_{k}_deg"] == pytest.approx(amplitude_deg - heading_deg, abs=1e-3 * amplitude_deg)
    assert m["period_s"] == pytest.approx(period, abs=0.01)
    t_first = np.arcsin(heading_deg / amplitude_deg) * period / (2 * np.pi)
    assert m["initial_turning_time_s"] == pytest.approx(t_first, abs=0.01)
