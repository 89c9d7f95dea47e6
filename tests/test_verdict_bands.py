"""Bands that mean what they say: the 95 % band is 1.96 standard deviations, the predictive band is the
parameter band's own covariance plus the discrepancy, and a coverage far below nominal is flagged."""
import json

import numpy as np
import pytest

import casship as cs
from casship.cli import main
from casship.identify import replay_file
from casship.simulation import band_z


def _fit_file(tmp_path, q_deg2=None):
    """A nomoto1 fit file with a fixed, hand-written covariance (and optionally a discrepancy)."""
    m = cs.models.nomoto_first_order(K=0.1, T=20.0)
    doc = {"model": "nomoto1", "params": {"K": 0.1, "T": 20.0},
           "param_covariance": {"names": ["K", "T"], "values": [0.1, 20.0],
                                "matrix": [[1e-5, 0.0], [0.0, 1.0]], "source": "hand-written"}}
    if q_deg2 is not None:
        doc["model_discrepancy"] = {"psi_variance_growth_deg2_per_s": q_deg2}
    path = tmp_path / "fit.json"
    path.write_text(json.dumps(doc))
    t = np.arange(0.0, 200.0, 1.0)
    delta = np.radians(10.0) * np.sign(np.sin(2 * np.pi * t / 90.0) + 1e-9)
    clean = cs.simulate(m, m.states(), t, {"delta": delta})
    return path, t, delta, np.asarray(clean["psi"])


def test_band_z_is_1_96_at_95_percent():
    assert band_z(0.95) == pytest.approx(1.959963984540054, abs=1e-12)
    assert band_z(0.90) == pytest.approx(1.6448536269514722, abs=1e-12)


@pytest.mark.parametrize("key, q_deg2", [("coverage", None), ("coverage_predictive", 0.02)])
def test_coverage_counts_the_measured_heading_inside_1_96_standard_deviations(tmp_path, key, q_deg2):
    # measured heading = replay + k s at every sample, k = 1.95 on even and 1.97 on odd samples: with
    # z = 1.96 exactly the even samples are inside, so the coverage is one half (1.645 would give 0, 2.0 one)
    path, t, delta, psi = _fit_file(tmp_path, q_deg2)
    first = replay_file(path, cs.Dataset(t, {"psi": psi, "delta": delta}), samples=0)
    s = first.bands["psi_std" if key == "coverage" else "psi_std_predictive"]
    k = np.where(np.arange(t.size) % 2 == 0, 1.95, 1.97)
    measured = psi + k * s                      # s = 0 at the start: the replay starts where the record does
    res = replay_file(path, cs.Dataset(t, {"psi": measured, "delta": delta}), samples=0)
    np.testing.assert_allclose(res.trajectory["psi"], psi, atol=1e-12)
    inside = (np.arange(t.size) % 2 == 0) | (s == 0)
    assert res.bands[key] == pytest.approx(np.mean(inside), abs=1e-12)
    assert 0.45 < res.bands[key] < 0.55


def test_the_predictive_band_is_never_narrower_than_the_parameter_band(tmp_path):
    path, t, delta, psi = _fit_file(tmp_path, 0.05)
    res = replay_file(path, cs.Dataset(t, {"psi": psi, "delta": delta}), samples=0)
    s, p = res.bands["psi_std"], res.bands["psi_std_predictive"]
    assert np.all(p >= s)
    np.testing.assert_allclose(p, np.sqrt(s ** 2 + np.radians(np.radians(0.05)) * (t - t[0])), rtol=1e-12)


def test_a_coverage_far_below_nominal_is_flagged_in_the_text_output(tmp_path, capsys):
    path, t, delta, psi = _fit_file(tmp_path)
    drift = np.radians(0.05) * (t - t[0])        # a heading drift the narrow parameter band cannot hold
    csv = cs.Dataset(t, {"psi": psi + drift, "delta": delta}).to_csv(tmp_path / "run.csv")
    assert main(["simulate", "--model", "nomoto1", "--params", str(path), "--inputs", str(csv), "--samples", "0"]) == 0
    text = capsys.readouterr().out
    assert "warning: the 95 % parameter band covers" in text and "far below its nominal 95 %" in text
    assert main(["simulate", "--model", "nomoto1", "--params", str(path), "--inputs", str(csv), "--samples", "0",
                 "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["bands"]["psi_coverage"] < 0.5 and out["band_warnings"]
    # a file without a model discrepancy: the predictive band is the parameter band, reported and flagged as such
    assert out["bands"]["psi_predictive_coverage"] == out["bands"]["psi_coverage"]
    assert out["bands"]["psi_discrepancy_deg2_per_s"] == 0.0
    assert any("carries no model discrepancy" in w for w in out["band_warnings"])
    # a band that holds the measured heading is not flagged
    good = cs.Dataset(t, {"psi": psi, "delta": delta}).to_csv(tmp_path / "good.csv")
    assert main(["simulate", "--model", "nomoto1", "--params", str(path), "--inputs", str(good), "--samples", "0"]) == 0
    assert "far below" not in capsys.readouterr().out


def test_a_fits_own_discrepancy_reaches_the_replay_as_the_predictive_band(tmp_path, capsys):
    truth = cs.models.nomoto_first_order(K=0.1, T=20.0)
    t = np.arange(0.0, 300.0, 1.0)
    runs = []
    for i, (a, period) in enumerate(((0.15, 120.0), (-0.1, 90.0))):
        delta = a * np.sign(np.sin(2 * np.pi * t / period) + 1e-9)
        runs.append(cs.measure(cs.simulate(truth, truth.states(), t, {"delta": delta}), truth, {"psi": 0.01}, seed=i))
    prob = cs.OutputErrorProblem(cs.models.get_model("nomoto1"), runs, ["K", "T"], measured=["psi"],
                                 sigma={"psi": 0.01})
    fit = prob.solve(guess={"K": 0.05, "T": 10.0}, verdict="loo", show=False)
    path = fit.to_json(tmp_path / "fit.json")
    q = json.loads(path.read_text())["model_discrepancy"]["psi_variance_growth_deg2_per_s"]
    assert q == fit.model_discrepancy["psi_variance_growth_deg2_per_s"] > 0
    res = replay_file(path, runs[0], samples=0)
    np.testing.assert_allclose(res.bands["psi_std_predictive"],
                               np.sqrt(res.bands["psi_std"] ** 2 + np.radians(np.radians(q)) * (t - t[0])), rtol=1e-12)
    assert "psi_predictive_coverage" in res.band_summary()


def test_a_band_wider_than_a_quarter_turn_is_flagged_as_saying_nothing(tmp_path):
    from casship.maneuvers import UNINFORMATIVE_DEG

    path, t, delta, psi = _fit_file(tmp_path, 0.05)
    res = replay_file(path, cs.Dataset(t, {"psi": psi, "delta": delta}), samples=0)
    assert not any("says nothing" in n for n in res.coverage_notes())      # about 10 deg wide: informative
    q = (np.radians(UNINFORMATIVE_DEG) / 1.96) ** 2 / 140.0                  # crosses 90 deg near t = 140 s
    doc = json.loads(path.read_text())
    doc["model_discrepancy"] = {"psi_variance_growth_deg2_per_s": float(np.degrees(np.degrees(q)))}
    path.write_text(json.dumps(doc))
    wide = replay_file(path, cs.Dataset(t, {"psi": psi, "delta": delta}), samples=0)
    s = wide.bands["psi_std_predictive"]
    first = t[np.argmax(np.degrees(wide.bands["z"] * s) > UNINFORMATIVE_DEG)]
    notes = [n for n in wide.coverage_notes() if "says nothing" in n]
    assert len(notes) == 1 and f"from {first:.0f} s of 199 s" in notes[0], notes
    assert 130.0 < first < 145.0


def test_a_plot_keeps_the_lines_in_view_when_the_band_says_nothing(tmp_path):
    """The heading panel is scaled to the replay, the record and the informative part of the band (a band
    of hundreds of degrees used to flatten both lines), and marks where the band stops saying anything."""
    path, t, delta, psi = _fit_file(tmp_path, 0.05)
    doc = json.loads(path.read_text())
    doc["model_discrepancy"] = {"psi_variance_growth_deg2_per_s": 800.0}      # +-780 deg after 199 s
    path.write_text(json.dumps(doc))
    res = replay_file(path, cs.Dataset(t, {"psi": psi, "delta": delta}), samples=0)
    assert np.degrees(res.bands["z"] * res.bands["psi_std_predictive"][-1]) > 700.0
    fig = res.plot()
    heading = fig.axes[1]
    lo, hi = heading.get_ylim()
    top = max(np.degrees(np.abs(psi)).max(), 90.0)
    assert -1.2 * top < lo and hi < 1.2 * top, (lo, hi)
    assert any("says nothing" in line.get_label() for line in heading.get_lines())
