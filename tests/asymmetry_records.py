"""Shared records of the asymmetry tests: noisy 10/10 and 20/20 zig-zags of a KVLCC2 with a known
asymmetry, first to starboard and first to port."""
from __future__ import annotations

import numpy as np

import casship as cs
from casship.maneuvers import run_maneuver
from casship.models import kvlcc2

SIGMA = {"psi": np.radians(0.05), "r": np.radians(0.002)}


def zigzag_record(ship, p, rudder_deg, heading_deg, seed):
    """A zig-zag of ``ship`` with parameters ``p``, heading and yaw rate with noise :data:`SIGMA`."""
    tr = run_maneuver(ship, "zigzag", rudder_deg=rudder_deg, heading_deg=heading_deg, p=p, dt=2.0,
                      duration=700.0).trajectory
    rng = np.random.default_rng(seed)
    d = cs.Dataset(tr.t, {"psi": tr["psi"] + SIGMA["psi"] * rng.standard_normal(len(tr)),
                          "r": tr["r"] + SIGMA["r"] * rng.standard_normal(len(tr)),
                          **{c: tr[c] for c in ("u", "v", "x", "y", "delta", "n")}})
    d.meta.update(name=f"zz {rudder_deg:g}/{heading_deg:+g}", facility="A")
    return d


def both_directions(truth: dict):
    """``(ship, starboard-first runs, port-first runs)`` of a KVLCC2 whose parameters are ``truth``."""
    ship = kvlcc2(asymmetry=True, smooth=True)
    p = ship.params(truth)
    starboard = [zigzag_record(ship, p, a, a, i) for i, a in enumerate((10.0, 20.0))]
    port = [zigzag_record(ship, p, a, -a, 10 + i) for i, a in enumerate((10.0, 20.0))]
    return ship, starboard, port
