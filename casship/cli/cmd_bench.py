"""``casship bench``: run every comparison in ``benchmarks/`` (same runner as ``python -m benchmarks``)."""
from __future__ import annotations

import sys
from pathlib import Path

from ._vocabulary import add_deprecated_alias


#: One-line description (the command list of ``casship --help``).
HELP = "run the speed comparisons in benchmarks/ and print a table of ratios"


def register(sub) -> None:
    p = sub.add_parser("bench", help=HELP)
    p.add_argument("--quick", action="store_true", help="short problem sizes (a smoke run)")
    p.add_argument("--json-file", dest="json", default=None, metavar="FILE",
                   help="write rows and machine description to this JSON file")
    add_deprecated_alias(p, "--json", "--json-file", dest="json")
    p.add_argument("--only", nargs="+", default=None,
                   help="run only these topics, named whole: no prefix matching (e.g. simulate ship_filters)")
    p.add_argument("--markdown", default=None, help="write the results section of this Markdown page (an existing "
                                                    "page: only its results section is replaced)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing --json-file file")
    p.set_defaults(func=run)


def _import_runner():
    try:
        from benchmarks import __main__ as runner
    except ImportError:
        # benchmarks/ sits next to the casship package in a source checkout; it is not installed.
        root = Path(__file__).resolve().parents[2]
        if not (root / "benchmarks" / "__main__.py").is_file():
            from ..errors import SetupError

            raise SetupError("the benchmarks/ folder of the casship source checkout was not found; "
                               "run 'casship bench' from a clone of the repository") from None
        sys.path.insert(0, str(root))
        from benchmarks import __main__ as runner
    return runner


def run(args) -> int:
    from ._common import check_outputs

    check_outputs({"--json-file": args.json, "--markdown": args.markdown}, overwrite=True)    # distinct paths
    check_outputs({"--json-file": args.json}, overwrite=args.overwrite)
    if args.markdown and not Path(args.markdown).is_file():
        raise FileNotFoundError(f"--markdown {args.markdown}: no such page (the results section of an existing "
                                "page is replaced)")
    runner = _import_runner()
    if args.only:
        from ..errors import InputError

        try:
            runner.discover(args.only)
        except ValueError as exc:
            raise InputError(f"--only: {exc}") from None
    argv = (["--quick"] if args.quick else []) + (["--json", args.json] if args.json else [])
    if args.only:
        argv += ["--only", *args.only]
    if args.markdown:
        argv += ["--markdown", args.markdown]
    return runner.main(argv)
