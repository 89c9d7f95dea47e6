"""One replay with prediction bands, as ``casship simulate --params FIT --inputs RUN`` makes it.

A MARIN free-running zig-zag of the KVLCC2 model (3 844 samples) replayed with the study's model
(MMG with the asymmetry terms and the smooth forms) and the uncertainty of ten parameters, the ones
the study's fit file carries a covariance for (standard deviations of 1-30 % of the published values
here, for a fit file is not part of the repository): the replay itself, the exact sensitivities of
heading and track (the bands) and 40 parameter draws (the index intervals), that is
:func:`casship.maneuvers.replay` with ``uncertainty`` and ``samples=40``.

* casship: the replay with its folds compiled (``jit=True``; the library is in the cache after the
  first call): one fold per chunk of the record for the replay and for the sensitivities, the 40
  draws as one call of the fold mapped over them.
* peer: the same replay interpreted (``jit=False``, CasADi's virtual machine); the draws still
  mapped. Before the folds were shared and compiled, a replay ran interpreted and simulated each
  draw on its own (about 0.9 CPU s on this record, against 0.65 interpreted and mapped).

The two results are compared number for number (states, bands, intervals). CPU time, interleaved.

Run ``python -m benchmarks.bench_replay [--quick]`` (``--quick``: 10 draws). Needs the measured data
(``CASSHIP_DATA`` or ``../shared/data``); without them the row is skipped.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from benchmarks import compare, compared_row, format_table, skipped_row

RUN = "MARIN_FREE_KVLCC2_zz_10_m.dat"
# the parameters the study's fit file carries a covariance for, and a relative standard deviation each
UNCERTAIN = {"w_P0": 0.01, "C_2_plus": 0.03, "C_2_minus": 0.05, "epsilon": 0.05, "R_0_dash": 0.06,
             "gamma_R_plus": 0.27, "N_v_dash": 0.08, "Y_v_dash": 0.1, "N_vvr_dash": 0.28, "delta_0": 0.01}


def main(quick: bool = False) -> list[dict]:
    from casship.identify import ParameterUncertainty
    from casship.io import data_dir, read_record
    from casship.models import kvlcc2
    from casship.maneuvers import replay

    samples = 10 if quick else 40
    what = f"replay of a MARIN zig-zag with bands and {samples} draws, compiled"
    try:
        folder = data_dir()
    except FileNotFoundError:
        folder = None
    path = Path(folder or "") / "kvlcc2_marin_free" / RUN
    if folder is None or not path.is_file():
        return [skipped_row(what, "interpreted", "the measured data are absent (CASSHIP_DATA)")]
    record = read_record(path)
    model = kvlcc2(asymmetry=True, smooth=True)
    p = model.params()
    values = np.array([p[model.index(n, "param")] for n in UNCERTAIN])
    std = np.array([max(abs(v), 1e-3) * s for v, s in zip(values, UNCERTAIN.values())])
    unc = ParameterUncertainty(list(UNCERTAIN), values, np.diag(std**2), source="benchmark: assumed")

    def run(jit):
        return lambda: replay(model, record, p, uncertainty=unc, samples=samples, seed=0, jit=jit)

    a, b = run(True)(), run(False)()
    gap = max(float(np.abs(a.trajectory.x - b.trajectory.x).max()),
              *(float(np.abs(a.bands[k] - b.bands[k]).max()) for k in ("psi_std", "cross_track_std")))
    same = a.metric_intervals == b.metric_intervals and a.sampling == b.sampling
    check = (f"states and bands max abs diff {gap:.1e}; intervals and sampling "
             f"{'identical' if same else 'DIFFER'} ({len(record)} samples, {a.sampling['failed']} failed draws)")
    timing = compare(run(True), run(False), repeat=3 if quick else 5)
    return [compared_row(what, timing, "the same replay interpreted (jit=False)", check, samples=len(record))]


if __name__ == "__main__":
    print(format_table(main(quick="--quick" in sys.argv)))
