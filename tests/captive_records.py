"""Synthetic captive-test records for the captive tests (a folder of tables, or a record from a model)."""
from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from casship.io.captive import CHANNELS, HARMONICS, CaptiveTests, DynamicTests, StaticTests
from casship.identify.captive_forces import CaptivePredictor

_STATIC = {"X": "X_prime", "Y": "Y_prime", "N": "N_prime", "RX": "RX_prime", "RY": "RY_prime", "T": "TX_prime"}
_SUF = ("mean", "in", "out", "in2", "out2", "in3", "out3")


def _dyn_cols():
    return [f"{c}_{s}_prime" for c in CHANNELS for s in _SUF]


def write_tables(folder: Path) -> Path:
    """A minimal folder in the HMRI layout (two rows per table, made-up numbers)."""
    folder.mkdir(parents=True, exist_ok=True)
    forces = list(_STATIC.values())

    def write(name, header, rows):
        with open(folder / name, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(header)
            w.writerows(rows)

    f = [0.001, 0.002, 0.0005, 0.0, 0.0001, 0.001]
    write("static_rudder.csv", ["run", "delta_deg", "speed_m_s", "rps", *forces],
          [[1, 10, 1.17, 9.9, *f], [2, -10, 1.17, 9.9, *f]])
    write("static_drift.csv", ["run", "beta_deg", "speed_m_s", "rps", *forces],
          [[3, 10, 1.17, 9.9, *f], [4, -10, 1.17, 9.9, *f]])
    write("drift_rudder.csv", ["run", "beta_deg", "delta_deg", "speed_m_s", "rps", *forces],
          [[3, 10, 0, 1.17, 9.9, *f], [5, 10, -10, 1.17, 9.9, *f]])
    d = list(np.linspace(1e-4, 4.2e-3, 42))
    write("pure_sway.csv", ["run", "speed_m_s", "rps", "freq_hz", "vdot_prime", *_dyn_cols()],
          [[6, 1.17, 9.9, 0.02, -0.1, *d]])
    write("pure_yaw.csv", ["run", "speed_m_s", "rps", "freq_hz", "r_prime", "rdot_prime", *_dyn_cols()],
          [[7, 1.17, 9.9, 0.03, 0.2, -0.2, *d]])
    write("yaw_drift.csv", ["run", "beta_deg", "speed_m_s", "rps", "freq_hz", "r_prime", "rdot_prime", *_dyn_cols()],
          [[7, 0, 1.17, 9.9, 0.03, 0.2, -0.2, *d], [8, 8, 1.17, 9.9, 0.03, 0.2, -0.2, *d[::-1]],
           [8, 12, 1.17, 9.9, 0.03, 0.2, -0.2, *d[::-1]]])
    return folder


def design(U: float = 1.18, rps: float = 10.0, L: float = 7.0) -> CaptiveTests:
    """A PMM series (forces zero): static drift and rudder sweeps, drift with rudder, pure sway,
    pure yaw and yaw with drift, at the approach speed ``U`` of a model of length ``L``."""
    beta_s = np.radians([-20, -12, -6, -3, 3, 6, 12, 20, 0, 0, 0, 0, 0, 0, 10, -10])
    delta_s = np.radians([0, 0, 0, 0, 0, 0, 0, 0, -20, -10, -5, 5, 10, 20, 15, -15])
    kinds = ("static_drift",) * 8 + ("static_rudder",) * 6 + ("drift_rudder",) * 2
    n = len(beta_s)
    zeros = {c: np.zeros(n) for c in CHANNELS}
    static = StaticTests(run=np.arange(n), kind=kinds, beta=beta_s, delta=delta_s, speed=np.full(n, U),
                         rps=np.full(n, rps), forces=zeros)
    # dynamic: pure sway (3), pure yaw (4), yaw with drift (2 drifts x 3)
    kind, beta, freq, vdot, r, rdot = [], [], [], [], [], []
    for f, a in ((0.02, -0.05), (0.03, -0.12), (0.04, -0.2)):
        kind.append("pure_sway"), beta.append(0.0), freq.append(f), vdot.append(a), r.append(np.nan), rdot.append(np.nan)
    for f, ra in ((0.02, 0.1), (0.03, 0.2), (0.045, 0.4), (0.055, 0.6)):
        w = 2 * np.pi * f
        kind.append("pure_yaw"), beta.append(0.0), freq.append(f), vdot.append(np.nan), r.append(ra)
        rdot.append(-ra * w * L / U)
    for b in (8.0, 16.0):
        for f, ra in ((0.025, 0.15), (0.04, 0.3), (0.055, 0.6)):
            w = 2 * np.pi * f
            kind.append("yaw_drift"), beta.append(np.radians(b)), freq.append(f), vdot.append(np.nan), r.append(ra)
            rdot.append(-ra * w * L / U)
    m = len(kind)
    dyn = DynamicTests(run=np.arange(100, 100 + m), kind=tuple(kind), beta=np.array(beta), speed=np.full(m, U),
                       rps=np.full(m, rps), freq_hz=np.array(freq), vdot_amp=np.array(vdot), r_amp=np.array(r),
                       rdot_amp=np.array(rdot), components={c: np.zeros((m, len(HARMONICS))) for c in CHANNELS})
    return CaptiveTests(static=static, dynamic=dyn, source="synthetic")


def synthetic(model, p, tests: CaptiveTests, channels=("X", "Y", "N"), noise: dict | None = None, seed: int = 0):
    """``tests`` with its forces replaced by ``model``'s at ``p`` plus Gaussian noise (per group
    ``static:C`` / ``dynamic:C`` standard deviations in ``noise``; the dynamic means NaN)."""
    rng = np.random.default_rng(seed)
    comps = HARMONICS[1:]
    pr = CaptivePredictor(model, tests, channels, comps)
    y = pr.predict(p)
    sf = {c: np.full(len(tests.static), np.nan) for c in CHANNELS}
    dc = {c: np.full((len(tests.dynamic), len(HARMONICS)), np.nan) for c in CHANNELS}
    for o, v in zip(pr.observations, y):
        s = (noise or {}).get(f"{o.test}:{o.channel}", 0.0)
        v = v + s * rng.standard_normal()
        if o.test == "static":
            sf[o.channel][o.index] = v
        else:
            dc[o.channel][o.index, HARMONICS.index(o.component)] = v
    st = tests.static
    dy = tests.dynamic
    static = StaticTests(run=st.run, kind=st.kind, beta=st.beta, delta=st.delta, speed=st.speed, rps=st.rps, forces=sf)
    dyn = DynamicTests(run=dy.run, kind=dy.kind, beta=dy.beta, speed=dy.speed, rps=dy.rps, freq_hz=dy.freq_hz,
                       vdot_amp=dy.vdot_amp, r_amp=dy.r_amp, rdot_amp=dy.rdot_amp, components=dc)
    return CaptiveTests(static=static, dynamic=dyn, source="synthetic")
