"""``casship demo``: an end-to-end run on built-in defaults, writing a report folder."""
from __future__ import annotations

from pathlib import Path


def register(sub) -> None:
    p = sub.add_parser("demo", help="end-to-end demonstration on built-in defaults (writes a report folder)")
    p.add_argument("--out", default="casship-demo", help="report folder (default: %(default)s)")
    p.add_argument("--quick", action="store_true", help="shorter records (under a minute)")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..demo import run_demo

    summary = run_demo(Path(args.out), quick=args.quick)
    print(f"report written to {Path(args.out) / 'report.md'}")
    for key, value in summary["headline"].items():
        print(f"  {key}: {value}")
    return 0
