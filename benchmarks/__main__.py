"""Run every ``benchmarks/bench_*.py`` comparison: ``python -m benchmarks [--quick] [--json out.json]``.

Prints one table of median times and ratios (peer / casship) and writes the rows as JSON together
with a description of the machine. A module that cannot be imported because a peer library is
missing gives a ``skipped`` row; any other failure gives an ``error`` row (exit status 1), and the
remaining benchmarks still run.
"""
from __future__ import annotations

import argparse
import importlib
import json
import os
import pkgutil
import platform
import sys
import time
import traceback
from pathlib import Path

from . import format_table, format_targets, skipped_row

__all__ = ["discover", "run_all", "machine_info", "main"]


def discover(only: list[str] | None = None) -> list[str]:
    """Names of the benchmark modules (``bench_<topic>``), sorted; ``only`` keeps the named topics.

    A topic is named whole (``simulate`` or ``bench_simulate``): there is no prefix matching, so that
    ``ek`` runs nothing unexpected; an unknown or repeated name is refused, listing the topics.
    """
    here = Path(__file__).resolve().parent
    names = sorted(i.name for i in pkgutil.iter_modules([str(here)]) if i.name.startswith("bench_"))
    if only:
        topics = [n.removeprefix("bench_") for n in names]
        wanted = [o.removeprefix("bench_") for o in only]
        unknown = [o for o, w in zip(only, wanted) if w not in topics]
        if unknown:
            raise ValueError(f"unknown benchmark(s) {unknown}; known: {topics} (whole names, no prefix matching)")
        twice = sorted({w for w in wanted if wanted.count(w) > 1})
        if twice:
            raise ValueError(f"benchmark(s) {twice} named more than once")
        names = [n for n in names if n.removeprefix("bench_") in wanted]
    return names


def run_all(quick: bool = False, only: list[str] | None = None, verbose: bool = True,
            figures: Path | None = None) -> list[dict]:
    """Import and run every benchmark module; returns all rows (with a ``module`` key each).

    A module with a ``plot(rows, path)`` function draws its figure into ``figures`` (when given) as
    ``benchmarks-<topic>.png``.
    """
    rows: list[dict] = []
    for name in discover(only):
        if verbose:
            print(f"[bench] {name} ...", file=sys.stderr, flush=True)
        t0 = time.perf_counter()
        try:
            module = importlib.import_module(f"{__package__}.{name}")
        except ImportError as exc:
            missing = getattr(exc, "name", None) or str(exc)
            rows.append({**skipped_row(name, str(missing), f"cannot import {missing}: install the 'bench' extra"),
                         "module": name})
            continue
        try:
            result = module.main(quick=quick)
        except ImportError as exc:
            missing = getattr(exc, "name", None) or str(exc)
            rows.append({**skipped_row(name, str(missing), f"cannot import {missing}: install the 'bench' extra"),
                         "module": name})
            continue
        except Exception as exc:  # one broken benchmark must not hide the others
            rows.append({"benchmark": name, "casship_s": None, "peer": "", "peer_s": None, "ratio": None,
                         "accuracy_check": "", "error": f"{type(exc).__name__}: {exc}", "module": name,
                         "traceback": traceback.format_exc()})
            continue
        for r in result or []:
            rows.append({**r, "module": name})
        if figures is not None and hasattr(module, "plot") and result:
            path = Path(figures) / f"benchmarks-{name[len('bench_'):]}.png"
            module.plot(result, path)
            if verbose:
                print(f"[bench] {name}: figure {path}", file=sys.stderr, flush=True)
        if verbose:
            print(f"[bench] {name} done in {time.perf_counter() - t0:.1f} s", file=sys.stderr, flush=True)
    return rows


def machine_info() -> dict:
    """Python, CasADi, NumPy, SciPy versions, CPU model and count of the running machine."""
    import casadi
    import numpy
    import scipy

    cpu = platform.processor() or ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    try:
        load = [round(v, 2) for v in os.getloadavg()]
    except OSError:
        load = None
    return {"python": platform.python_version(), "casadi": casadi.__version__, "numpy": numpy.__version__,
            "load_average": load,
            "scipy": scipy.__version__, "platform": platform.platform(), "cpu": cpu,
            "cpu_count": os.cpu_count(), "date_utc": time.strftime("%Y-%m-%d %H:%M", time.gmtime())}


START, END = "<!-- results: written by python -m benchmarks --markdown -->", "<!-- end of results -->"


def results_markdown(rows: list[dict], info: dict, quick: bool, command: str) -> str:
    """The results section: command, machine, table."""
    return (f"{START}\n\nMeasured {info['date_utc']} UTC with `{command}`"
            + (" (quick sizes)" if quick else "") + " on:\n\n"
            f"- CPU: {info['cpu']}, {info['cpu_count']} logical CPUs ({info['platform']})"
            + (f"; load average at the end {info['load_average'][0]:g} (1 min), {info['load_average'][2]:g} (15 min)"
               if info.get("load_average") else "") + "\n"
            f"- Python {info['python']}, CasADi {info['casadi']}, NumPy {info['numpy']}, SciPy {info['scipy']}\n\n"
            + format_table(rows) + "\n\nThe speed targets (ratio = median of the interleaved repeats, "
            "range in brackets):\n\n" + format_targets(rows) + f"\n\n{END}")


def write_markdown(path: Path, section: str) -> None:
    """Replace the results section of ``path`` (between the markers), or append it."""
    text = path.read_text() if path.exists() else "# Benchmarks\n\n"
    if START in text and END in text:
        head, rest = text.split(START, 1)
        text = head + section + rest.split(END, 1)[1]
    else:
        text = text.rstrip() + "\n\n" + section + "\n"
    path.write_text(text)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks", description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="short problem sizes (a smoke run)")
    parser.add_argument("--json", default=None, help="write rows and machine description to this file")
    parser.add_argument("--only", nargs="+", default=None,
                        help="run only these topics, named whole (e.g. simulate ship_filters)")
    parser.add_argument("--markdown", default=None,
                        help="write the table and machine into the results section of this Markdown page "
                             "(and the figures, benchmarks-<topic>.png, beside it)")
    args = parser.parse_args(argv)
    try:
        names = discover(args.only)
    except ValueError as exc:
        parser.error(str(exc))
    figures = Path(args.markdown).parent if args.markdown else None
    rows = run_all(quick=args.quick, only=[n for n in names] if args.only else None, figures=figures)
    info = machine_info()
    print(format_table(rows))
    print("\n" + format_targets(rows))
    print(f"\nmedians in seconds; ratio = peer / casship (> 1: casship faster). "
          f"{info['cpu']} ({info['cpu_count']} CPUs), Python {info['python']}, CasADi {info['casadi']}"
          + (" [quick]" if args.quick else ""))
    if args.json:
        out = Path(args.json)
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps({"machine": info, "quick": args.quick, "rows": rows}, indent=2, default=str))
        print(f"rows written to {out}")
    if args.markdown:
        command = "python -m benchmarks" + (" --quick" if args.quick else "") + \
            (f" --only {' '.join(args.only)}" if args.only else "")
        write_markdown(Path(args.markdown), results_markdown(rows, info, args.quick, command))
        print(f"results section written to {args.markdown}")
    return 1 if any(r.get("error") for r in rows) else 0


if __name__ == "__main__":
    sys.exit(main())
