"""The EKF step exported as standalone C (``casship.estimators.export_estimator``), run in a C loop, vs Python filters.

Problem: the SOG/COG EKF case of ``bench_filters`` (Fossen & Fossen 2021 model, 50 Hz, GNSS at 5 Hz,
NaN rows predict only). casship's EKF step Function is exported with ``export_estimator``, compiled
with ``gcc -O2 -ffp-contract=off`` together with a small driver that loops over the record the way
an onboard program would (two copies of the memory ``x, P`` that swap roles after every call; the
step exported lean, with ``x`` and ``P`` only), and timed in C with the process
CPU clock (median of repeats). Peers: filterpy's ``ExtendedKalmanFilter`` on the same discrete model
with a hand-written Jacobian (as in ``bench_filters``) and, for reference, casship's own batch filter
(the same step folded by CasADi's virtual machine). Accuracy: every filtered state of the C loop
against the Python batch filter. Run ``python -m benchmarks.bench_codegen [--quick]``.
"""
from __future__ import annotations

import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

import casship as cs
from benchmarks import format_table, median_time, row, skipped_row
from casship.estimators import export_estimator
from casship.runtime import compile_c

DRIVER = r"""#define _POSIX_C_SOURCE 199309L
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include "bench_ekf.h"
#include "bench_ekf_data.h"

#define NX bench_ekf_NX
#define NY bench_ekf_NY
#define SX bench_ekf_SIZE_x
#define SP bench_ekf_SIZE_P

static int cmp(const void *a, const void *b) {
    double d = *(const double *)a - *(const double *)b;
    return (d > 0) - (d < 0);
}

int main(int argc, char **argv) {
    /* input file: n, repeats, prior x (SX) and P (SP), then per sample y (NY), mask (NY), dt */
    FILE *in = fopen(argv[1], "rb"), *out = fopen(argv[2], "wb");
    double head[2], prior[SX + SP], times[64];
    long n, k, r, repeats;
    int now;
    if (!in || !out || fread(head, sizeof(double), 2, in) != 2) return 2;
    n = (long)head[0]; repeats = (long)head[1];
    if (repeats > 64 || fread(prior, sizeof(double), SX + SP, in) != SX + SP) return 2;
    double *rec = malloc(sizeof(double) * n * (2 * NY + 1)), *xs = malloc(sizeof(double) * n * NX);
    if ((long)fread(rec, sizeof(double), n * (2 * NY + 1), in) != n * (2 * NY + 1)) return 2;
    static double x[2][SX], P[2][SP], dt, gate = 1e300, none[1];
    static casadi_int iw[bench_ekf_SZ_IW + 1];
    static double w[bench_ekf_SZ_W + 1];
    const double *arg[bench_ekf_SZ_ARG] = {0, 0, none, none, 0, 0, &dt, bench_ekf_p, bench_ekf_Q, bench_ekf_R, &gate};
    double *res[bench_ekf_SZ_RES] = {0, 0};
    int mem = bench_ekf_checkout();
    for (r = 0; r < repeats; r++) {
        struct timespec t0, t1;
        memcpy(x[0], prior, sizeof(double) * SX);
        memcpy(P[0], prior + SX, sizeof(double) * SP);
        now = 0;
        clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t0);
        for (k = 0; k < n; k++) {
            const double *row = rec + k * (2 * NY + 1);
            arg[4] = row; arg[5] = row + NY; dt = row[2 * NY];
            arg[0] = x[now]; arg[1] = P[now]; res[0] = x[1 - now]; res[1] = P[1 - now];
            if (bench_ekf(arg, res, iw, w, mem)) return 1;
            now = 1 - now;
            memcpy(xs + k * NX, x[now], sizeof(double) * NX);
        }
        clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t1);
        times[r] = (t1.tv_sec - t0.tv_sec) + 1e-9 * (t1.tv_nsec - t0.tv_nsec);
    }
    bench_ekf_release(mem);
    qsort(times, repeats, sizeof(double), cmp);
    fwrite(&times[repeats / 2], sizeof(double), 1, out);
    fwrite(xs, sizeof(double), n * NX, out);
    fclose(in); fclose(out);
    return 0;
}
"""


def main(quick: bool = False) -> list[dict]:
    from benchmarks.bench_filters import Q_SOG, R_SOG, _filterpy_ekf, _sog_case

    name = "EKF step exported as C (gcc -O2), SOG/COG 5 states, 50 Hz, GNSS 5 Hz"
    if shutil.which("gcc") is None:
        return [skipped_row(name, "gcc", "no C compiler (gcc) on this machine")]
    m, dm, traj, data, prior = _sog_case(60.0 if quick else 600.0)
    ekf = cs.EKF(dm, Q_SOG, R_SOG)
    batch = ekf.filter(data, prior)
    n = len(data)
    arrays = ekf.prepare(data)
    record = np.vstack([arrays["y"], arrays["mask"], arrays["dt"]]).T            # (n, 2 ny + 1)
    repeats = 3 if quick else 7
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        files = export_estimator(ekf, folder, "bench_ekf")
        (folder / "driver.c").write_text(DRIVER)
        exe = compile_c([folder / "driver.c", files.source], folder / "driver",
                        flags=("-O2", "-ffp-contract=off", "-std=c99", f"-I{folder}"))
        memory = ekf.memory_from(prior)
        np.concatenate([[n, repeats], memory["x"], memory["P"].ravel(order="F"), record.ravel()]).astype(np.float64).tofile(
            folder / "in.bin")
        subprocess.run([str(exe), str(folder / "in.bin"), str(folder / "out.bin")], check=True)
        written = np.fromfile(folder / "out.bin", dtype=np.float64)      # the loop's time, then the states
    c_time, xs = float(written[0]), written[1:].reshape(n, m.nx)
    gap = float(np.max(np.abs(xs - batch.x)))
    check = f"max abs diff C loop vs Python filter = {gap:.1e} over {n} steps"
    rows = [row(name, c_time, "casship batch filter (CasADi VM fold)",
                median_time(lambda: ekf.filter(data, prior), repeat=repeats), check, steps=n)]
    try:
        import filterpy  # noqa: F401
    except ImportError:
        rows.append(skipped_row(name, "filterpy", "filterpy not installed (pip install filterpy)", c_time))
        return rows
    Y = data.matrix(["x_n", "y_n"])
    peer = _filterpy_ekf(Y, prior)
    check_peer = f"{check}; vs filterpy {float(np.max(np.abs(xs - peer))):.1e}"
    rows.append(row(name, c_time, "filterpy ExtendedKalmanFilter (hand Jacobian)",
                    median_time(lambda: _filterpy_ekf(Y, prior), repeat=max(1, repeats // 2)), check_peer, steps=n))
    for r in rows:
        r["casship_us_per_step"] = 1e6 * c_time / n
    return rows


if __name__ == "__main__":
    print(format_table(main(quick="--quick" in sys.argv)))
