"""How casship's costs grow with their work: EKF record length, MHE horizon, ML fit size.

* EKF (compiled, the 6-state ship model of ``bench_ship_filters``): CPU time per sample and memory of
  ``filter`` for records of 1e3 to 1e6 samples. Memory is traced with ``tracemalloc`` (NumPy reports
  its buffers to it): the peak during ``filter`` above what was allocated before, split into the
  result (every diagnostic of every sample, a ``FilterResult``), the record's inputs prepared for
  the fold, and the rest (the fold's pieces of 512 samples, a bounded amount, and transient copies
  made while the result is assembled); and the time and memory of the lean online runner
  (``x, P`` only), which keeps nothing per sample.
* MHE (the problem of ``bench_mhe``): CPU time per sample for horizons N = 10 .. 200 with IPOPT and
  the real-time iteration (interpreted: sparse QR of the KKT system; compiled: the Riccati recursion).
* ML fit (the problem of ``bench_identify``, the identification API as it stands): CPU time of a fit
  (compiled code reused, as in a repeat fit) against the record length (7 free parameters) and
  against the number of free parameters (3, 7, 15; 3000 samples).

No peers here: the rows give times per unit of work, and ``--plot FILE`` draws the growth curves
(the figure in ``docs/``). Run ``python -m benchmarks.bench_scaling [--quick] [--plot FILE]``.
"""
from __future__ import annotations

import sys
import time
import tracemalloc

import numpy as np

import casship as cs
from benchmarks import format_table, row

CLOCK = time.process_time


def _timed(func, repeat: int = 1):
    times, out = [], None
    for _ in range(repeat):
        t0 = CLOCK()
        out = func()
        times.append(CLOCK() - t0)
    return out, float(np.median(times))


def _traced(func):
    """``func()`` and the peak of traced memory above the start [bytes]."""
    tracemalloc.start()
    tracemalloc.reset_peak()
    base = tracemalloc.get_traced_memory()[0]
    out = func()
    peak = tracemalloc.get_traced_memory()[1] - base
    tracemalloc.stop()
    return out, peak


def _result_bytes(res) -> int:
    return sum(v.nbytes for v in vars(res).values() if isinstance(v, np.ndarray))


def ekf_rows(sizes) -> list[dict]:
    from benchmarks.bench_ship_filters import case

    rows = []
    model, dm, data, prior, Q, R, Qx, U, Y = case(max(sizes))
    ekf = cs.EKF(dm, Q, R, options={"jit": True})
    for n in sizes:
        d = data.slice(0, n)
        ekf.filter(d, prior)                               # folds built and compiled
        res, t = _timed(lambda: ekf.filter(d, prior), repeat=3 if n <= 100_000 else 1)
        _, peak = _traced(lambda: ekf.filter(d, prior))
        result = _result_bytes(res)
        inputs = sum(np.asarray(v).nbytes for v in ekf.prepare(d).values())
        del res
        Yn, Un = Y[:n], U[:n]

        def online():
            run = ekf.online(prior, u=Un[0])
            for k in range(n):
                run.update(Yn[k], 0.1 if k else 0.0, Un[k - 1] if k else Un[0], Un[k])
            return run.x

        if n <= 100_000:
            _, t_on = _timed(online)
            _, peak_on = _traced(online) if n <= 10_000 else (None, None)
        else:
            t_on, peak_on = None, None
        rows.append(row(f"EKF filter, compiled, ship model 6 states, {n} samples", t, "-", None,
                        f"{1e6 * t / n:.2f} us/sample; peak memory {peak / 1e6:.1f} MB: result {result / 1e6:.1f} MB "
                        f"({result / n:.0f} B/sample), prepared inputs {inputs / 1e6:.1f} MB, the rest "
                        f"{(peak - result - inputs) / 1e6:.2f} MB"
                        + (f"; online runner {1e6 * t_on / n:.2f} us/sample" if t_on else "")
                        + (f", {peak_on / 1e3:.0f} kB" if peak_on is not None else ""),
                        series="ekf", n=n, us_per_sample=1e6 * t / n, peak_mb=peak / 1e6, result_mb=result / 1e6,
                        inputs_mb=inputs / 1e6, working_mb=(peak - result - inputs) / 1e6,
                        online_us_per_sample=None if t_on is None else 1e6 * t_on / n,
                        online_peak_kb=None if peak_on is None else peak_on / 1e3))
    return rows


def mhe_rows(horizons, duration: float) -> list[dict]:
    from benchmarks.bench_mhe import problem, run_casship

    model, dm, data, prior, Q, R = problem(duration)
    rows = []
    for N in horizons:
        for solver, jit in (("rti", True), ("rti", False), ("ipopt", False)):
            mhe = cs.MHE(dm, Q, R, options={"horizon": N, "solver": solver, "jit": jit})
            t0 = time.perf_counter()
            mhe.window(N)
            if solver == "rti":
                mhe.window(N).gn()
            build = time.perf_counter() - t0
            _, t = run_casship(dm, data, prior, Q, R, N, solver, mhe=mhe)
            how = "compiled" if jit else "interpreted"
            rows.append(row(f"MHE {solver} ({how}) per sample, horizon N = {N}", t, "-", None,
                            f"{1e6 * t:.0f} us per sample, {1e6 * t / N:.2f} us per stage; window built in "
                            f"{build:.2f} s", series=f"mhe_{solver}_{how}", N=N, us_per_sample=1e6 * t))
    return rows


def ml_rows(lengths, counts, n_for_counts: int) -> list[dict]:
    from benchmarks.bench_identify import FREE, TRUTH, _casship_fit, make_data

    free_sets = {**FREE, 15: ("a1", "a2", "a3", "a4", "a5", "a6", "a7", "a9", "b1", "b2", "b3", "b4", "c1", "c2", "c3")}
    rows = []

    def fit(n, k, seed):
        model, data = make_data(n, seed)
        truth = model.params(TRUTH)
        guess = {f: 0.7 * truth[model.index(f, "param")] for f in free_sets[k]}
        return _casship_fit(model, data, free_sets[k], guess)

    for n, k, series in [*((n, 7, "ml_length") for n in lengths), *((n_for_counts, k, "ml_params") for k in counts)]:
        fit(n, k, 0)                                        # compile (or load from the cache)
        res, t = _timed(lambda: fit(n, k, 1))
        rows.append(row(f"ML fit, {k} free parameters, {n} samples (compiled code reused)", t, "-", None,
                        f"{res.iterations} iterations ({res.status}); {1e3 * t / max(res.iterations, 1):.0f} ms per "
                        f"iteration, {1e6 * t / n:.1f} us per sample", series=series, n=n, free=k, seconds=t,
                        iterations=res.iterations))
    return rows


def main(quick: bool = False) -> list[dict]:
    if quick:
        return (ekf_rows([1000, 10_000]) + mhe_rows([10, 20, 50], 20.0)
                + ml_rows([300, 1000], [3, 7], 600))
    return (ekf_rows([1000, 10_000, 100_000, 1_000_000]) + mhe_rows([10, 20, 50, 100, 200], 40.0)
            + ml_rows([300, 1000, 3000, 10_000], [3, 7, 15], 3000))


def plot(rows: list[dict], path) -> None:
    """The growth curves of ``rows`` (from :func:`main`) as a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplot_mosaic("ABC;DE.", figsize=(15, 8.5))
    ekf = [r for r in rows if r.get("series") == "ekf"]
    n = np.array([r["n"] for r in ekf])

    def finish(ax, title, xlabel, ylabel):
        ax.set_title(title)
        ax.set_xlabel(xlabel)
        ax.set_ylabel(ylabel)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)

    ax = axes["A"]
    ax.semilogx(n, [r["us_per_sample"] for r in ekf], "o-", label="filter (every diagnostic)")
    on = [(r["n"], r["online_us_per_sample"]) for r in ekf if r.get("online_us_per_sample")]
    if on:
        ax.semilogx(*zip(*on), "s--", label="online update (x, P)")
    ax.set_ylim(bottom=0)
    finish(ax, "EKF (compiled), 6-state ship: time", "record length [samples]", "CPU time per sample [us]")
    ax = axes["B"]
    for key, label, mark in (("result_mb", "result (FilterResult)", "^-"), ("inputs_mb", "prepared inputs", "o-"),
                             ("working_mb", "the rest: fold pieces, transient copies", "v-")):
        ax.loglog(n, [max(r[key], 1e-3) for r in ekf], mark, label=label)
    pk = [(r["n"], r["online_peak_kb"] / 1e3) for r in ekf if r.get("online_peak_kb") is not None]
    if pk:
        ax.loglog(*zip(*pk), "s--", label="online runner (whole run)")
    finish(ax, "EKF (compiled), 6-state ship: memory", "record length [samples]", "peak traced memory [MB]")
    ax = axes["C"]
    for series, label in (("mhe_rti_compiled", "RTI, compiled (Riccati)"),
                          ("mhe_rti_interpreted", "RTI, interpreted (KKT QR)"),
                          ("mhe_ipopt_interpreted", "IPOPT, warm-started")):
        pts = [(r["N"], r["us_per_sample"]) for r in rows if r.get("series") == series]
        if pts:
            ax.plot(*zip(*pts), "o-", label=label)
    ax.set_yscale("log")
    finish(ax, "MHE, 6-state ship: time per sample", "horizon N [steps]", "CPU time per sample [us]")
    ax = axes["D"]
    pts = [(r["n"], r["seconds"]) for r in rows if r.get("series") == "ml_length"]
    if pts:
        ax.plot(*zip(*pts), "o-", label="7 free parameters")
    ax.set_ylim(bottom=0)
    finish(ax, "ML fit (compiled code reused) vs record length", "record length [samples]", "CPU time of the fit [s]")
    ax = axes["E"]
    pts = [(r["free"], r["seconds"]) for r in rows if r.get("series") == "ml_params"]
    if pts:
        ax.plot(*zip(*pts), "s-", label=f"{[r['n'] for r in rows if r.get('series') == 'ml_params'][0]} samples")
    ax.set_ylim(bottom=0)
    finish(ax, "ML fit (compiled code reused) vs free parameters", "free parameters", "CPU time of the fit [s]")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    rows = main(quick="--quick" in sys.argv)
    print(format_table(rows))
    if "--plot" in sys.argv:
        out = sys.argv[sys.argv.index("--plot") + 1]
        plot(rows, out)
        print(f"growth curves written to {out}")
