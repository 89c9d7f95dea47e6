"""Regenerate the captive-test figure of docs/identification.md (needs the measured data).

Run from the repository root::

    python docs/figures/make_captive_figure.py

Fits the HMRI captive tests on casship's ``hmri-t530`` rig by the rule of
``casship.identify.rig`` (what ``casship identify --captive ... --rig hmri-t530 --plot`` draws) and
writes ``docs/figures/captive-forces.png`` (small, 56 dpi).
"""
from __future__ import annotations

from pathlib import Path

from matplotlib.figure import Figure

from casship.identify import read_rig
from casship.io import data_dir, read_captive

HERE = Path(__file__).resolve().parent
DPI = 56


def main():
    tests = read_captive(data_dir(required=True) / "kvlcc2_hmri_captive")
    problem = read_rig("hmri-t530").problem(tests, "kvlcc2")
    fit = problem.solve(show=False)
    fig = Figure(figsize=(15, 17))
    axes = fig.subplots(6, 5, squeeze=False)
    problem.plot(fit, ax=axes)
    fig.suptitle("HMRI captive tests of the KVLCC2: measured against the published constants (x) and the captive fit (o)",
                 fontsize=13)
    fig.tight_layout(rect=(0, 0, 1, 0.975))        # room for the title
    fig.savefig(HERE / "captive-forces.png", dpi=DPI)
    print(f"wrote {HERE / 'captive-forces.png'} (cost {fit.cost:.6g}, {fit.n_obs} values)")


if __name__ == "__main__":
    main()
