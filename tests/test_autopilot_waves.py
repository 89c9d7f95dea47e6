"""Fossen's wave filter: the wave band leaves the rudder command, the low-frequency heading stays."""
import numpy as np
import pytest

import casship as cs
from casship import autopilot as ap


def _command_amplitude(est, prior, gains, t, psi_m, r_m, w):
    """Amplitude at ``w`` of the PD part of the command on the filter's estimates (a linear map of
    the measurements: Kalman filter on a linear model, then a linear law)."""
    data = cs.Dataset(t, {"psi_m": psi_m, "r_m": r_m, "delta": np.zeros(t.size)})
    res = est.filter(data, prior)
    cmd = -(gains.Kp * res["psi"] + gains.Kd * res["r"])
    tail = t >= t[-1] / 2                                  # after the filter's transient
    c, s = np.cos(w * t[tail]), np.sin(w * t[tail])
    a = 2 * np.mean(cmd[tail] * c)
    b = 2 * np.mean(cmd[tail] * s)
    return float(np.hypot(a, b))


@pytest.mark.parametrize("ship, w0", [("kvlcc2", 0.6), ("otter", 2.5)])
def test_wave_filter_removes_the_wave_band_from_the_command(ship, w0):
    d = ap.design_autopilot(cs.models.otter(munk_moment=False) if ship == "otter" else cs.models.get_model(ship))
    s = d.settings
    wave = ap.WaveYaw(w0, np.radians(4.0), 0.1)
    dt = s.dt
    t = np.arange(0.0, 400.0 * 2 * np.pi / w0, dt) if ship == "otter" else np.arange(0.0, 3000.0, dt)
    amp = np.radians(1.0)
    ratios = {}
    for w, name in ((w0, "wave"), (s.wn / 2, "low")):   # the wave peak, and half the loop bandwidth
        psi_m, r_m = amp * np.sin(w * t), amp * w * np.cos(w * t)
        out = {}
        for filt in (False, True):
            obs = ap.heading_observer(d.nomoto.K, d.nomoto.T, wave if filt else None, steer="delta")
            q_r, q_b = s.observer_q
            est = ap.heading_kf(obs, dt, compass_std=s.compass_std, gyro_std=s.gyro_std, q_r=q_r, q_b=q_b)
            prior = cs.Gaussian(obs.states(), np.eye(obs.nx) * 1e-4)
            out[filt] = _command_amplitude(est, prior, d.gains, t, psi_m, r_m, w)
        ratios[name] = out[True] / out[False]
    assert ratios["wave"] < 0.1          # the wave band is taken out of the command
    assert 0.8 < ratios["low"] < 1.25     # a slow heading change is steered on as before


def test_wave_model_spectrum_peaks_at_the_encounter_frequency():
    wave = ap.WaveYaw(0.8, 0.05, 0.1)
    sys = wave.system()
    w = np.logspace(-2, 1, 400)
    mag = np.abs(sys(1j * w)[0, 0])
    assert w[np.argmax(mag)] == pytest.approx(0.8 * np.sqrt(1 - 2 * 0.1**2), rel=0.01)
    w_peak = 0.8 * np.sqrt(1 - 2 * 0.1**2)
    assert abs(sys(1j * w_peak)[0, 0]) == pytest.approx(wave.sigma / np.sqrt(1 - 0.1**2), rel=1e-9)
    # the discrete wave process has the stationary variance of the continuous one (sigma^2 lambda w0)
    Ad, Bd = wave.discrete(0.05)
    rng = np.random.default_rng(0)
    x, samples = np.zeros(2), []
    for v in rng.standard_normal(200_000):
        x = Ad @ x + Bd[:, 0] * v
        samples.append(x[0])
    assert np.std(samples[2000:]) == pytest.approx(wave.std, rel=0.05)
