"""``casship study NAME``: run a study from ``problems/`` and write its report folder."""
from __future__ import annotations

import json
from pathlib import Path


def register(sub) -> None:
    p = sub.add_parser("study", help="run a study (seed-paper reproductions, real-data studies)")
    p.add_argument("name", nargs="?", help="study name (see --list)")
    p.add_argument("--list", action="store_true", help="list the studies")
    p.add_argument("--out", default=None, help="output folder (default: casship-out/NAME)")
    p.add_argument("--quick", action="store_true", help="small, fast variant (as run by the tests)")
    p.add_argument("--workers", type=int, default=None, help="local worker processes (default: CPU count)")
    p.add_argument("--scheduler", default=None, help="dask.distributed scheduler address")
    p.set_defaults(func=run)


def run(args) -> int:
    import problems

    if args.list or not args.name:
        for name, study in problems.studies().items():
            print(f"{name:20s} {study.title}")
        return 0
    study = problems.get_study(args.name)
    out = Path(args.out or Path("casship-out") / study.name)
    out.mkdir(parents=True, exist_ok=True)
    summary = study.run(out, quick=args.quick, workers=args.workers, scheduler=args.scheduler)
    (out / "summary.json").write_text(json.dumps(summary, indent=2, default=float))
    print(f"study {study.name}: results in {out}")
    return 0
