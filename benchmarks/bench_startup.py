"""Start-up of the command line: ``casship --help`` and an argument error against ``import numpy``.

A command that only prints its help or refuses an argument loads none of the numerical stack
(CasADi, SciPy, pandas, matplotlib; NumPy neither): the command modules are registered lazily and
``import casship`` imports nothing heavy. Timed as the CPU time (user + system) of fresh
interpreter processes, which other jobs on a shared machine inflate less than wall-clock time;
the peer is a fresh interpreter that imports NumPy, the smallest start-up of a numerical tool.

Run ``python -m benchmarks.bench_startup [--quick]``.
"""
from __future__ import annotations

import resource
import subprocess
import sys

from benchmarks import format_table, row

CHECK = ("import sys\nfrom casship.cli import main\ntry:\n    main({argv!r})\nexcept SystemExit:\n    pass\n"
         "heavy = [m for m in ('casadi', 'scipy', 'pandas', 'matplotlib', 'numpy') if m in sys.modules]\n"
         "sys.stderr.write('HEAVY=' + ','.join(heavy))")


def _cpu(cmd: list[str], repeat: int) -> float:
    """Median CPU time [s] of ``repeat`` runs of ``cmd`` in a fresh process."""
    times = []
    for _ in range(repeat + 1):                      # the first run warms the file cache, untimed
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        subprocess.run(cmd, capture_output=True, check=False)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        times.append((after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime))
    return sorted(times[1:])[repeat // 2]


def _heavy(argv: list[str]) -> str:
    err = subprocess.run([sys.executable, "-c", CHECK.format(argv=argv)], capture_output=True, text=True).stderr
    return err.rsplit("HEAVY=", 1)[-1].strip() if "HEAVY=" in err else "?"


def main(quick: bool = False) -> list[dict]:
    repeat = 3 if quick else 9
    numpy_s = _cpu([sys.executable, "-c", "import numpy"], repeat)
    rows = []
    for label, argv in (("casship --help", ["--help"]), ("casship simulate --bogus (argument error)",
                                                          ["simulate", "--bogus"])):
        own = _cpu([sys.executable, "-m", "casship", *argv], repeat)
        heavy = _heavy(argv)
        rows.append(row(label, own, "python -c 'import numpy'", numpy_s,
                        f"modules of the numerical stack loaded: {heavy or 'none'}"))
    return rows


if __name__ == "__main__":
    print(format_table(main(quick="--quick" in sys.argv)))
