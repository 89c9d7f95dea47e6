"""``casship demo``: an end-to-end run on built-in defaults, writing a report folder."""
from __future__ import annotations

from pathlib import Path

from ._common import add_overwrite_option


#: One-line description (the command list of ``casship --help``).
HELP = "end-to-end demonstration on built-in defaults (writes a report folder)"


def register(sub) -> None:
    p = sub.add_parser("demo", help=HELP,
                       description="KVLCC2 sea trials simulated and measured with noisy sensors; EKF, UKF and RTS "
                                   "estimates; a maximum-likelihood fit of hull derivatives; validation manoeuvres; "
                                   "a course autopilot on the fitted model. Writes report.md, summary.json and "
                                   "figures into the report folder (only when the run succeeds).")
    p.add_argument("--out", default="casship-demo", help="report folder (must be new or empty)")
    p.add_argument("--quick", action="store_true", help="shorter records and a two-parameter fit")
    add_overwrite_option(p)
    p.set_defaults(func=run)


def run(args) -> int:
    from ..demo import run_demo
    from ..outdir import check_output_folder

    check_output_folder(args.out, overwrite=args.overwrite)       # before minutes of work
    summary = run_demo(Path(args.out), quick=args.quick, overwrite=args.overwrite)
    print(f"report written to {Path(args.out) / 'report.md'} ({'quick' if args.quick else 'full'} run)")
    for key, value in summary["headline"].items():
        print(f"  {key}: {value}")
    return 0
