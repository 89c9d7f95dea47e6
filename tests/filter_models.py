"""Small models and records shared by the filter tests."""
from __future__ import annotations

import numpy as np

import casship as cs


def oscillator(k: float = 0.5, c: float = 0.3):
    """Linear damped oscillator with an input, noise on the acceleration, position and a sum measured."""
    b = cs.ModelBuilder("oscillator")
    x1, x2 = b.state("x1"), b.state("x2")
    u = b.input("f")
    kk, cc = b.param("k", k), b.param("c", c)
    b.ode(x1=x2, x2=-kk * x1 - cc * x2 + u + b.noise("w"))
    b.output("y1", x1)
    b.output("y2", x1 + 0.5 * x2)
    return b.build()


def linear_record(model, dt=0.1, n=300, q=0.05, r=(0.04, 0.09), seed=1):
    """Simulate a linear model with held process noise and measure its outputs."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * dt
    u = np.sin(0.3 * t)
    w = np.sqrt(q) * rng.standard_normal((n, model.nw))
    traj = cs.simulate(model, model.states(x1=1.0), t, {"f": u}, w=w)
    std = dict(zip(model.output_names, np.sqrt(r)))
    return traj, cs.measure(traj, model, std, seed=rng)


def oscillator_case(n: int):
    """``(model, dmodel, trajectory, data, prior)`` of the oscillator over ``n`` samples at 0.1 s."""
    m = oscillator()
    traj, data = linear_record(m, n=n)
    return m, cs.discretize(m, 0.1), traj, data, cs.Gaussian([0.0, 0.0], [1.0, 1.0])
