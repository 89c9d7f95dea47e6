"""Every result that can be drawn: ``plot(ax=None, path=None)`` returns a figure with no path, the
caller's axes with ``ax``, and writes a PNG with a path; nothing in casship switches the backend."""
import re
from pathlib import Path

import numpy as np
import pytest
from matplotlib.axes import Axes
from matplotlib.figure import Figure

import casship as cs
from casship import autopilot as ap
from casship.errors import InputError

PNG = b"\x89PNG\r\n\x1a\n"


def _check(plot, tmp_path, name, n_axes=None):
    """The three calls of the contract on one result's ``plot`` (a callable taking ax/path)."""
    fig = plot()
    assert isinstance(fig, Figure), type(fig)
    assert fig.axes, "an empty figure"
    assert fig._repr_png_()[:8] == PNG              # what a notebook shows, without pyplot
    labelled = [a for a in fig.axes if a.get_xlabel() or a.get_ylabel()]
    assert labelled, "no axis labels"
    out = plot(path=tmp_path / f"{name}.png")
    assert Path(out) == tmp_path / f"{name}.png"
    assert out.read_bytes()[:8] == PNG and out.stat().st_size > 5_000
    if n_axes is not None:
        target = Figure()
        axes = target.subplots(1, n_axes, squeeze=False).ravel()
        back = plot(ax=axes if n_axes > 1 else axes[0])
        assert back is axes or back is axes[0]
        assert any(a.lines or a.patches or a.collections for a in axes)
    return fig


@pytest.fixture(scope="module")
def ship_run():
    ship = cs.models.get_model("kvlcc2")
    return ship, cs.maneuvers.run_maneuver(ship, "zigzag", rudder_deg=10, duration=300, dt=1.0).trajectory


def test_trajectory_of_a_ship_draws_track_and_heading(ship_run, tmp_path):
    _, tr = ship_run
    fig = _check(lambda **kw: tr.plot(**kw), tmp_path, "traj", n_axes=2)
    track, heading = fig.axes[:2]
    x, y = track.lines[0].get_data()
    np.testing.assert_array_equal(y, tr["x"])             # North up, East across
    np.testing.assert_array_equal(x, tr["y"])
    np.testing.assert_allclose(heading.lines[0].get_ydata(), np.degrees(np.unwrap(tr["psi"])))
    assert "deg" in heading.get_ylabel()


def test_maneuver_result_and_augmented_result(ship_run, tmp_path):
    from casship.estimators import augmented_ekf

    ship = cs.models.get_model("kvlcc2")
    man = cs.maneuvers.run_maneuver(ship, "turning", rudder_deg=35, duration=200, dt=1.0)
    fig = _check(lambda **kw: man.plot(**kw), tmp_path, "man", n_axes=2)
    assert "turning 35 deg" in fig.get_suptitle()
    m = cs.models.get_model("nomoto1")
    t = np.arange(0.0, 60.0, 0.5)
    data = cs.measure(cs.simulate(m, m.states(), t, {"delta": 0.1 * np.sign(np.sin(t / 10))}), m, {"psi": 0.01}, seed=1)
    prior = cs.Gaussian([0.0, 0.0], [1e-4, 1e-6])
    aug = augmented_ekf(m, ["K"], data, dt=0.5, Q=1e-8, R={"psi": 1e-4}, q_params=1e-8, prior=prior)
    fig = _check(lambda **kw: aug.plot(**kw), tmp_path, "aug", n_axes=1)
    assert fig.axes[0].get_ylabel().startswith("K")


def test_trajectory_of_any_model_draws_its_states_in_degrees():
    b = cs.ModelBuilder("rate")
    th, w = b.state("theta", unit="rad"), b.state("w", unit="rad/s")
    u = b.input("u")
    b.ode(theta=w, w=-w + u)
    m = b.build()
    tr = cs.simulate(m, [0.0, 0.0], np.arange(0.0, 2.0, 0.1), {"u": np.ones(20)})
    fig = tr.plot()
    assert [a.get_ylabel() for a in fig.axes] == ["theta [deg]", "w [deg/s]"]
    np.testing.assert_allclose(fig.axes[1].lines[0].get_ydata(), np.degrees(tr["w"]))


def test_a_plot_refuses_the_wrong_number_of_axes(ship_run):
    _, tr = ship_run
    with pytest.raises(InputError, match="ax: .* draws 2 panel"):
        tr.plot(ax=Figure().subplots(1, 3))


def test_filter_result(tmp_path):
    m = cs.models.get_model("nomoto1")
    t = np.arange(0.0, 60.0, 0.5)
    tr = cs.simulate(m, m.states(), t, {"delta": 0.1 * np.sign(np.sin(t / 10))})
    data = cs.measure(tr, m, {"psi": 0.01}, seed=1)
    dm = cs.discretize(m, 0.5)
    est = cs.EKF(dm, 1e-6, {"psi": 1e-4})
    res = est.filter(data, cs.prior_from_data(m, data, measured=["psi"], R={"psi": 1e-4}))
    _check(lambda **kw: res.plot(**kw), tmp_path, "filter")
    one = Figure().subplots()
    assert res.plot(ax=one, states=["psi"]) is one
    assert res.plot(tmp_path / "old.png").exists()          # the earlier plot(path) still writes


def test_replay_result(ship_run, tmp_path):
    from casship.maneuvers import replay

    ship, tr = ship_run
    res = replay(ship, tr, ship.params())
    _check(lambda **kw: res.plot(**kw), tmp_path, "replay", n_axes=4)


def test_fit_result_and_identifiability(tmp_path):
    from casship.identify import OutputErrorProblem

    m = cs.models.get_model("nomoto1")
    t = np.arange(0.0, 120.0, 0.5)
    tr = cs.simulate(m, m.states(), t, {"delta": 0.1 * np.sign(np.sin(2 * np.pi * t / 60))})
    data = cs.measure(tr, m, {"psi": 0.005}, seed=2)
    prob = OutputErrorProblem(m, [data], free=["K", "T"], sigma={"psi": 0.005})
    fit = prob.solve()
    _check(lambda **kw: fit.plot(**kw), tmp_path, "fit", n_axes=1)
    idf = prob.identifiability()
    _check(lambda **kw: idf.plot(**kw), tmp_path, "idf", n_axes=3)


@pytest.fixture(scope="module")
def otter_design():
    return ap.design_autopilot(cs.models.get_model("otter"))


def test_closed_loop_result_names_its_controller(otter_design, tmp_path):
    res = otter_design.simulate("course-20", warn=False)
    assert res.controller.startswith("pid") and res.controller in repr(res)
    fig = _check(lambda **kw: res.plot(**kw), tmp_path, "loop", n_axes=4)
    assert "pid" in fig.get_suptitle()
    assert "yaw moment" in fig.axes[2].get_ylabel()         # the Otter steers by a yaw moment
    # the function form returns the figure too (it wrote and closed before)
    assert isinstance(ap.plot_closed_loop(res), Figure)
    assert isinstance(ap.plot_design(otter_design.loop, closed=otter_design.closed_loop), Figure)
    assert ap.plot_design(otter_design.loop, tmp_path / "d.png").read_bytes()[:8] == PNG


def test_track_control_plot_draws_waypoints_and_the_intended_track(otter_design):
    wp = ap.Waypoints([0.0, 150.0, 150.0], [0.0, 0.0, 150.0])
    g = ap.LOSGuidance.for_design(wp, otter_design)
    res = ap.simulate_autopilot(otter_design, 0.0, 60.0, guidance=g, warn=False)
    fig = res.plot()
    track_ax = fig.axes[3]
    labels = [line.get_label() for line in track_ax.lines]
    assert "waypoints" in labels and "intended track" in labels
    wp_line = track_ax.lines[labels.index("waypoints")]
    np.testing.assert_array_equal(wp_line.get_xdata(), wp.east)
    np.testing.assert_array_equal(wp_line.get_ydata(), wp.north)


def test_nothing_in_casship_switches_the_backend():
    root = Path(cs.__file__).parent
    pattern = re.compile(r"\b(matplotlib|mpl)\s*\.\s*use\s*\(|switch_backend\s*\(|plt\.close\(")
    hits = [str(p.relative_to(root)) for p in root.rglob("*.py") if pattern.search(p.read_text())]
    assert not hits, hits


def test_design_result(tmp_path):
    from casship.design import Approach, ParameterBelief, design_trials, standard_trials
    from casship.models import kvlcc2

    m = kvlcc2()
    belief = ParameterBelief.from_std({"N_r_dash": 0.01, "N_v_dash": 0.03}, m.param_dict())
    approach = Approach(m, m.params(), dt=4.0)
    turns = standard_trials(approach, turning=(35.0,), zigzag=(), pullout=(), spiral=False,
                            durations={"turning": 15.0})
    res = design_trials(m, belief, {"psi": np.radians(0.2)}, "tactical_diameter", dt=4.0, candidates=turns)
    fig = _check(lambda **kw: res.plot(**kw), tmp_path, "design", n_axes=1)
    bars = fig.axes[0].patches
    assert len(bars) == 2                                    # one bar per trial
    both = res.plot(approach=approach)                       # with the best trial's rudder, track, speed
    assert len(both.axes) == 4
    assert res.plot(tmp_path / "old.png", approach).is_file()        # the earlier plot(path, approach)


def test_cross_validation_figures(tmp_path):
    from casship.identify import OutputErrorProblem, cross_validate

    truth = cs.models.nomoto_first_order(K=0.1, T=20.0)
    runs = []
    for i in range(2):
        t = np.arange(0, 200.0, 1.0)
        tr = cs.simulate(truth, truth.states(), t, {"delta": 0.1 * np.sign(np.sin(2 * np.pi * t / (90 + 20 * i)))})
        d = cs.measure(tr, truth, {"psi": 0.005}, seed=i)
        d.meta.update(name=f"run {i}")
        runs.append(d)
    cv = cross_validate(OutputErrorProblem(cs.models.nomoto_first_order(), runs, free=["K", "T"],
                                           sigma={"psi": 0.005}))
    figs = cv.plot()
    assert len(figs) == 2 and all(isinstance(f, Figure) for f in figs)
    paths = cv.plot(tmp_path / "cv")
    assert [p.read_bytes()[:8] for p in paths] == [PNG, PNG]
    axes = Figure().subplots(1, 3)
    assert cv.plot(records=["run 1"], ax=axes) == [axes]
