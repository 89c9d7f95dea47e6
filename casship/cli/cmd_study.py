"""``casship study NAME``: run a registered study (see :mod:`casship.studies`) into a report folder."""
from __future__ import annotations

from pathlib import Path

from ._common import count


#: One-line description (the command list of ``casship --help``).
HELP = "run a study (reproductions of published papers, real-data studies)"


def register(sub) -> None:
    p = sub.add_parser("study", help=HELP,
                       description="Run a study and write its report folder (report.md, figures, tables, "
                                   "summary.json). Measured data are found by --data DIR, else $CASSHIP_DATA, "
                                   "else ../shared/data beside a source checkout.")
    p.add_argument("name", nargs="?", help="study name (see --list)")
    p.add_argument("--list", action="store_true", help="list the studies")
    p.add_argument("--out", default=None, help="output folder (default: casship-out/NAME, or NAME-quick with --quick)")
    p.add_argument("--overwrite", action="store_true",
                   help="replace the contents of a non-empty output folder (no stale files are kept)")
    p.add_argument("--quick", action="store_true", help="small, fast variant (as run by the tests)")
    p.add_argument("--data", default=None, metavar="DIR", help="measured-data folder (default: $CASSHIP_DATA, "
                   "else ../shared/data beside a source checkout)")
    p.add_argument("--workers", type=count, default=None, help="local worker processes (default: CPU count)")
    p.add_argument("--scheduler", default=None, help="dask.distributed scheduler address")
    p.add_argument("--params", default=None, metavar="FIT_JSON",
                   help="a fit file for a study that designs on one (trial-design: skips its own fit)")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..studies import get_study, run_study, studies

    if args.list or not args.name:
        for name, study in studies().items():
            data = " (needs measured data)" if study.needs_data else ""
            print(f"{name:20s} {study.title}{data}")
        return 0
    study = get_study(args.name)
    default = f"{study.name}-quick" if args.quick else study.name
    out = Path(args.out) if args.out else Path("casship-out") / default
    run_study(study, out, quick=args.quick, workers=args.workers, scheduler=args.scheduler, data=args.data,
              overwrite=args.overwrite, params=args.params)
    print(f"study {study.name} ({'quick' if args.quick else 'full'} run): results in {out}")
    return 0
