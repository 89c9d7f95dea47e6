"""The symbolic model core: declarations, names, immutability, composition, exact Jacobians."""
import zlib

import casadi as ca
import numpy as np
import pytest

import casship as cs
from casship.models import get_model, model_names


def nomoto_builder():
    b = cs.ModelBuilder("nomoto1", "test model")
    psi, r = b.state("psi", unit="rad", angle=True), b.state("r", unit="rad/s")
    delta = b.input("delta", unit="rad")
    K = b.param("K", 0.08, bounds=(0.0, 1.0), unit="1/s", source="test")
    T = b.param("T", 25.0)
    b.ode(psi=r, r=(K * delta - r) / T + b.noise("w_r"))
    b.output("psi", psi)
    return b


def surge_sway_yaw_builder():
    """A linear 3-DOF velocity model with an additive generalised-force port ``tau``."""
    b = cs.ModelBuilder("ship3")
    u, v, r = b.state("u"), b.state("v"), b.state("r")
    tau = b.port("tau", 3)
    m = b.param("m", 2.0)
    d = b.param("d", 0.5)
    b.ode(u=(-d * u + tau[0]) / m, v=(-d * v + tau[1]) / m, r=(-d * r + tau[2]) / m)
    b.output("u", u)
    return b


# -- declarations ----------------------------------------------------------------------------------

def test_declarations_give_named_functions_and_metadata():
    m = nomoto_builder().build()
    assert m.state_names == ("psi", "r")
    assert m.input_names == ("delta",)
    assert m.param_names == ("K", "T")
    assert m.noise_names == ("w_r",)
    assert m.output_names == ("psi",)
    assert (m.nx, m.nu, m.np, m.nw, m.ny) == (2, 1, 2, 1, 1)
    assert m.f.name_in() == ["x", "u", "p", "w"] and m.f.name_out() == ["xdot"]
    assert m.h.name_in() == ["x", "u", "p"] and m.h.name_out() == ["y"]
    assert m.f_jac.name_out() == ["A", "B", "Fp", "G"]
    assert m.h_jac.name_out() == ["C", "D", "Hp"]
    assert list(m.angle_states) == [True, False]
    assert list(m.angle_outputs) == [True]          # inferred: it measures an angle state
    K = m.param_vars[0]
    assert (K.value, K.lower, K.upper, K.unit, K.source) == (0.08, 0.0, 1.0, "1/s", "test")
    np.testing.assert_array_equal(m.param_lower, [0.0, -np.inf])
    xdot = np.array(m.f([0.1, 0.2], [0.3], [0.08, 25.0], [0.01])).ravel()
    np.testing.assert_allclose(xdot, [0.2, (0.08 * 0.3 - 0.2) / 25.0 + 0.01], rtol=1e-15)


def test_named_vectors():
    m = nomoto_builder().build()
    np.testing.assert_array_equal(m.states(r=0.5), [0.0, 0.5])
    np.testing.assert_array_equal(m.inputs(delta=0.1), [0.1])
    np.testing.assert_array_equal(m.params(), [0.08, 25.0])
    np.testing.assert_array_equal(m.params(T=10.0), [0.08, 10.0])
    np.testing.assert_array_equal(m.params({"K": 0.2}, T=3.0), [0.2, 3.0])
    np.testing.assert_array_equal(m.params(np.array([1.0, 2.0]), K=0.5), [0.5, 2.0])
    with pytest.raises(ValueError, match=r"parameter 'K' = 5 1/s of model 'nomoto1' is outside its valid range \[0, 1\]"):
        m.params(K=5.0)                 # the declared bounds are the parameter's valid range
    with pytest.raises(ValueError, match="parameter 'T' = nan of model 'nomoto1' is not finite"):
        m.params(T=np.nan)
    assert m.param_dict() == {"K": 0.08, "T": 25.0}
    assert m.param_dict([1.0, 2.0]) == {"K": 1.0, "T": 2.0}
    assert m.index("r") == 1 and m.index("T", "param") == 1 and m.index("psi", "output") == 0
    assert m.indices(["r", "psi"]) == [1, 0]


@pytest.mark.parametrize("call, name", [
    (lambda m: m.states(rr=1.0), "rr"),
    (lambda m: m.inputs(rudder=1.0), "rudder"),
    (lambda m: m.params(KK=1.0), "KK"),
    (lambda m: m.params({"Tx": 1.0}), "Tx"),
    (lambda m: m.index("speed"), "speed"),
    (lambda m: m.index("K", "state"), "K"),
    (lambda m: m.index("psi", "colour"), "colour"),
    (lambda m: m.with_outputs(["heading"]), "heading"),
])
def test_unknown_names_raise_value_error_naming_the_item(call, name):
    m = nomoto_builder().build()
    with pytest.raises(ValueError, match=name):
        call(m)


def test_params_vector_of_wrong_size():
    m = nomoto_builder().build()
    with pytest.raises(ValueError, match="2 parameters"):
        m.params(np.ones(3))


@pytest.mark.parametrize("declare, match", [
    (lambda b: b.state("psi"), "'psi' is already declared as a state"),
    (lambda b: b.param("delta", 1.0), "'delta' is already declared as a input"),
    (lambda b: b.state("1x"), "'1x' is not a valid identifier"),
    (lambda b: b.input("a b"), "'a b' is not a valid identifier"),
    (lambda b: b.param("c", np.nan), "parameter 'c': nominal value must be finite"),
    (lambda b: b.param("c", 5.0, bounds=(0.0, 1.0)), "parameter 'c': nominal value 5.0 outside bounds"),
    (lambda b: b.ode(speed=1.0), "'speed' is not a declared state"),
    (lambda b: b.ode(K=1.0), "'K' is not a declared state"),
    (lambda b: b.ode(r=ca.SX.sym("q", 2)), "ode for 'r': expected a scalar expression"),
    (lambda b: b.add_to_ode(x=1.0), "state 'x' has no equation yet"),
    (lambda b: b.output("psi", b.sym("r")), "output 'psi' is already declared"),
    (lambda b: b.output("K", b.sym("r")), "output 'K' clashes with the param"),
    (lambda b: b.output("2y", b.sym("r")), "output name '2y' is not a valid identifier"),
    (lambda b: b.sym("nothing"), "unknown name 'nothing'"),
    (lambda b: b.feed("tau", 1.0), "unknown port 'tau'"),
    (lambda b: b.state("t"), "'t' is reserved for time stamps"),
    (lambda b: b.output("time", b.sym("r")), "'time' is reserved for time stamps"),
])
def test_bad_declarations_raise(declare, match):
    b = nomoto_builder()
    with pytest.raises(ValueError, match=match):
        declare(b)


def test_build_checks_equations_and_symbols():
    b = cs.ModelBuilder("incomplete")
    b.state("a")
    b.state("b")
    b.ode(a=1.0)
    with pytest.raises(ValueError, match=r"states without an equation: \['b'\]"):
        b.build()
    with pytest.raises(ValueError, match="has no states"):
        cs.ModelBuilder("empty").build()

    b = cs.ModelBuilder("foreign")
    b.state("a")
    b.ode(a=ca.SX.sym("stranger"))
    with pytest.raises(ValueError, match="undeclared symbols.*stranger"):
        b.build()

    b = cs.ModelBuilder("noisy_output")
    a = b.state("a")
    w = b.noise("w")
    b.ode(a=w)
    b.output("y", a + w)
    with pytest.raises(ValueError, match="must not depend on process noise"):
        b.build()


# -- immutability ----------------------------------------------------------------------------------

def test_model_is_immutable():
    b = nomoto_builder()
    m = b.build()
    with pytest.raises(AttributeError, match="immutable"):
        m.f = None
    with pytest.raises(AttributeError, match="immutable"):
        m.name = "other"
    with pytest.raises(ValueError):
        m.angle_states[0] = False
    with pytest.raises(ValueError):
        m.param_lower[0] = 1.0
    with pytest.raises(TypeError):
        m.meta["x"] = 1
    p = m.params()
    p[0] = 99.0
    assert m.params()[0] == 0.08
    # later changes to the builder do not reach the built model
    b.ode(r=b.sym("r") * 0.0)
    b.state("extra")
    assert m.state_names == ("psi", "r")
    assert float(m.f([0, 1.0], [0], m.params(), [0])[1]) == pytest.approx(-1.0 / 25.0)


# -- composition -----------------------------------------------------------------------------------

def wind_term(b):
    Xw = b.param("X_wind", 0.4)
    Nw = b.input("N_wind")
    b.feed("tau", ca.vertcat(Xw, 0.0, Nw))


def test_unfed_port_is_zero_and_extend_adds_a_term():
    base = surge_sway_yaw_builder().build()
    windy = base.extend(wind_term, name="ship3+wind")
    assert windy.name == "ship3+wind"
    assert base.param_names == ("m", "d") and base.input_names == ()
    assert windy.param_names == ("m", "d", "X_wind") and windy.input_names == ("N_wind",)
    x = np.array([1.0, -0.5, 0.2])
    f0 = np.array(base.f(x, [], base.params(), [])).ravel()
    np.testing.assert_allclose(f0, -0.5 * x / 2.0, rtol=1e-15)
    f1 = np.array(windy.f(x, [0.3], windy.params(), [])).ravel()
    np.testing.assert_allclose(f1 - f0, [0.4 / 2.0, 0.0, 0.3 / 2.0], rtol=1e-14)


def test_two_terms_on_one_port_add_up():
    base = surge_sway_yaw_builder().build()

    def current(b):
        b.feed("tau", ca.vertcat(0.0, b.param("Y_cur", 0.6), 0.0))

    both = base.extend(wind_term).extend(current)
    x = np.zeros(3)
    f = np.array(both.f(x, [0.0], both.params(), [])).ravel()
    np.testing.assert_allclose(f, [0.2, 0.3, 0.0], rtol=1e-15)


def test_feed_checks_shape():
    b = surge_sway_yaw_builder()
    with pytest.raises(ValueError, match=r"port 'tau' has shape \(3, 1\)"):
        b.feed("tau", ca.vertcat(1.0, 2.0))


def test_builder_of_a_model_extends_equations():
    m = nomoto_builder().build()
    b = m.builder("nomoto1_bias")
    b.add_to_ode(r=b.param("bias", 0.01))
    m2 = b.build()
    d = np.array(m2.f([0, 0], [0], m2.params(), [0])).ravel() - np.array(m.f([0, 0], [0], m.params(), [0])).ravel()
    np.testing.assert_allclose(d, [0.0, 0.01], rtol=1e-15)
    assert m.param_names == ("K", "T")


def test_with_outputs():
    m = nomoto_builder().build()
    m2 = m.with_outputs(["psi", "r"])
    assert m2.output_names == ("psi", "r") and list(m2.angle_outputs) == [True, False]
    m3 = m.with_outputs({"psi_gyro": "psi", "turn": lambda b: 2.0 * b.sym("r")})
    assert m3.output_names == ("psi_gyro", "turn")
    y = np.array(m3.h([0.3, 0.1], [0], m3.params())).ravel()
    np.testing.assert_allclose(y, [0.3, 0.2])
    assert m.output_names == ("psi",)
    with pytest.raises(ValueError, match="'K' is not a state"):
        m.with_outputs({"y": "K"})
    with pytest.raises(TypeError, match="output 'y' must be given by a state name or a callable"):
        m.with_outputs({"y": 3.0})


# -- exact Jacobians of every registered model vs central differences --------------------------------

def central_jacobian(fun, args, k, h=1e-6):
    """d fun(*args)[0] / d args[k] by central differences (step relative to the entry's size)."""
    base = [np.asarray(a, dtype=float).copy() for a in args]
    n = base[k].size
    cols = []
    for i in range(n):
        step = h * max(1.0, abs(base[k][i]))
        plus = [a.copy() for a in base]
        minus = [a.copy() for a in base]
        plus[k][i] += step
        minus[k][i] -= step
        cols.append((np.array(fun(*plus)).ravel() - np.array(fun(*minus)).ravel()) / (2 * step))
    return np.column_stack(cols) if cols else np.zeros((0, 0))


def random_point(m, rng):
    """A generic, non-degenerate point: positive states/inputs of order one, perturbed parameters."""
    x = rng.uniform(0.2, 1.0, m.nx)
    u = rng.uniform(0.2, 1.0, m.nu)
    p = m.params() * rng.uniform(0.95, 1.05, m.np)
    w = rng.uniform(-0.1, 0.1, m.nw)
    return x, u, p, w


def assert_jacobian(exact, approx, what):
    exact = np.array(exact, dtype=float).reshape(approx.shape)
    scale = max(1.0, float(np.abs(exact).max(initial=0.0)))
    np.testing.assert_allclose(exact, approx, rtol=1e-5, atol=1e-6 * scale, err_msg=what)


@pytest.mark.parametrize("name", sorted(model_names()))
def test_jacobians_of_registered_models_match_central_differences(name):
    m = get_model(name)
    rng = np.random.default_rng(zlib.crc32(name.encode()))
    for _ in range(2):
        x, u, p, w = random_point(m, rng)
        exact = m.f_jac(x, u, p, w)
        for k, label in enumerate(("A", "B", "Fp", "G")):
            if exact[k].numel():
                assert_jacobian(exact[k], central_jacobian(m.f, (x, u, p, w), k), f"{name}: {label}")
        exact = m.h_jac(x, u, p)
        for k, label in enumerate(("C", "D", "Hp")):
            if exact[k].numel():
                assert_jacobian(exact[k], central_jacobian(m.h, (x, u, p), k), f"{name}: {label}")


@pytest.mark.parametrize("name", sorted(model_names()))
def test_registered_models_are_documented_and_named(name):
    m = get_model(name)
    assert m.doc, f"model {name!r} has no description with its source"
    assert len(set(m.state_names + m.input_names + m.param_names + m.noise_names)) == \
        m.nx + m.nu + m.np + m.nw
    assert isinstance(repr(m), str) and m.name in repr(m)


@pytest.mark.parametrize("name", ["nomoto1", "shi-taylor", "sog-cog-latlon"])
def test_models_and_discretisations_pickle(name):
    """Models travel to worker processes (casship.parallel) by pickling their declarations."""
    import pickle

    m = get_model(name)
    m2 = pickle.loads(pickle.dumps(m))
    assert (m2.name, m2.state_names, m2.param_names, m2.output_names) == \
        (m.name, m.state_names, m.param_names, m.output_names)
    x, u, p, w = random_point(m, np.random.default_rng(0))
    np.testing.assert_array_equal(np.array(m2.f(x, u, p, w)), np.array(m.f(x, u, p, w)))
    np.testing.assert_array_equal(np.array(m2.h_jac(x, u, p)[0]), np.array(m.h_jac(x, u, p)[0]))
    with pytest.raises(AttributeError, match="immutable"):
        m2.name = "x"
    dm = cs.discretize(m, 0.2, method="rk4", substeps=3)
    dm2 = pickle.loads(pickle.dumps(dm))
    assert (dm2.dt, dm2.method, dm2.substeps) == (0.2, "rk4", 3)
    np.testing.assert_array_equal(dm2.step(x, u, p, w), dm.step(x, u, p, w))


def test_param_as_state():
    b = nomoto_builder().build().builder("nomoto_aug")
    b.param_as_state("K")
    b.ode(K=b.noise("w_K"))
    m = b.build()
    assert m.state_names == ("psi", "r", "K") and m.param_names == ("T",) and m.noise_names == ("w_r", "w_K")
    assert m.state_vars[2].unit == "1/s"
    xdot = np.array(m.f([0.0, 0.1, 0.08], [0.3], [25.0], [0.0, 0.01])).ravel()
    np.testing.assert_allclose(xdot, [0.1, (0.08 * 0.3 - 0.1) / 25.0, 0.01], rtol=1e-15)
    with pytest.raises(ValueError, match="'psi' is not a declared parameter"):
        b.param_as_state("psi")


def test_nan_or_inf_constants_are_rejected_at_build_naming_the_state():
    import math

    b = cs.ModelBuilder("bad_math")
    psi, r = b.state("psi"), b.state("r")
    b.ode(psi=r, r=math.cos(psi) - r)            # math.cos on a CasADi symbol gives a float NaN
    with pytest.raises(ValueError, match=r"model 'bad_math': the equation of state 'r' contains the constant nan"):
        b.build()
    b = cs.ModelBuilder("bad_output")
    x = b.state("x")
    b.ode(x=-x)
    b.output("y", x + np.inf)
    with pytest.raises(ValueError, match=r"the output 'y' contains the constant inf"):
        b.build()


def test_param_as_state_with_its_rate_in_continuous_and_discrete_time():
    b = nomoto_builder().build().builder("nomoto_aug")
    b.param_as_state("K", rate=b.noise("w_K"))
    m = b.build()
    xdot = np.array(m.f([0.0, 0.1, 0.08], [0.3], [25.0], [0.0, 0.01])).ravel()
    np.testing.assert_allclose(xdot, [0.1, (0.08 * 0.3 - 0.1) / 25.0, 0.01], rtol=1e-15)
    # discrete time: the rate over a step, so x[k+1] = x[k] + dt * rate (as add_to_ode)
    d = cs.ModelBuilder("cv", dt=0.5)
    x, v = d.state("x"), d.state("v")
    c = d.param("c", 0.9)
    d.next(x=x + 0.5 * v, v=c * v)
    d.param_as_state("c", rate=d.noise("w_c"))
    step = cs.discretize(d.build()).step
    np.testing.assert_allclose(np.ravel(step([1.0, 2.0, 0.9], [], [], [0.4], 0.5)), [2.0, 1.8, 0.9 + 0.5 * 0.4],
                               rtol=1e-15)


def test_declarations_are_a_read_only_snapshot():
    b = nomoto_builder()
    snap = b.declarations()
    b.param("extra", 1.0)
    b.drop_outputs()
    assert [v.name for v in snap.params] == ["K", "T"] and [v.name for v in snap.outputs] == ["psi"]
    assert set(snap.symbols) == {"psi", "r", "delta", "K", "T", "w_r"} and set(snap.rates) == {"psi", "r"}
    with pytest.raises(TypeError):
        snap.rates["psi"] = 0
    with pytest.raises(AttributeError):
        snap.name = "other"
    assert b.declarations().outputs == () and len(b.declarations().params) == 3


def test_composition_leaves_the_model_as_it_was():
    m = nomoto_builder().build()
    m.with_outputs({"turn": lambda b: b.sym("r")})
    b = m.builder("copy")
    b.drop_outputs()
    assert m.output_names == ("psi",) and m.builder().declarations().outputs[0].name == "psi"


def test_derived_objects_are_built_once_and_go_with_the_model():
    """What simulate derives from a model (discretisations, mapped outputs) is kept by the model: built
    once per key, and freed with the model (nothing else holds the model alive)."""
    import gc
    import weakref

    m = nomoto_builder().build()
    made = []
    assert m.derived(("k", 1), lambda: made.append(1) or "one") == "one"
    assert m.derived(("k", 1), lambda: made.append(2) or "two") == "one" and made == [1]
    t = np.arange(0.0, 5.0, 0.5)
    first = cs.simulate(m, m.states(), t, {"delta": 0.1})
    np.testing.assert_array_equal(cs.simulate(m, m.states(), t, {"delta": 0.1}).x, first.x)
    ref = weakref.ref(m)
    del m, first
    gc.collect()
    assert ref() is None
