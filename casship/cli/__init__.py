"""The ``casship`` command line: one sub-command per module ``casship/cli/cmd_*.py``.

Each such module defines ``register(subparsers)``, which adds its parser and sets ``func``. Every
sub-command shows its defaults in ``--help``. A user error (bad value, unknown name, missing file,
out-of-range input) ends with exit code 2 and one line ``casship CMD: error: ...`` naming the
item; ``--debug`` shows the Python traceback instead. Warnings print as one line
``casship CMD: warning: ...``.
"""
from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys
import warnings

from ._common import HelpFormatter, Parser, UsageError

__all__ = ["main", "build_parser"]

#: Exceptions that are a user's error (bad input, missing file, failed solve): one line, exit 2.
USER_ERRORS = (ValueError, TypeError, KeyError, OSError, RuntimeError, ArithmeticError)


def build_parser() -> argparse.ArgumentParser:
    """The ``casship`` argument parser with every sub-command registered.

    Returns
    -------
    argparse.ArgumentParser
    """
    parser = Parser(
        prog="casship", formatter_class=HelpFormatter,
        description="Ship manoeuvring models, state estimation and identification on CasADi.",
        epilog="casship COMMAND --help shows the options of a command.")
    from .. import __version__

    parser.add_argument("--version", action="version", version=f"casship {__version__}")
    parser.add_argument("--debug", action="store_true", help="show the Python traceback of an error")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for info in sorted(pkgutil.iter_modules(__path__), key=lambda i: i.name):
        if info.name.startswith("cmd_"):
            importlib.import_module(f"{__name__}.{info.name}").register(sub)
    for name, command in sub.choices.items():
        command.formatter_class = HelpFormatter
        if command.description is None:
            # the one-line help of the command list doubles as the description of its own --help
            command.description = next((a.help for a in sub._choices_actions if a.dest == name), None)
        if not any("--debug" in a.option_strings for a in command._actions):
            command.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                                 help="show the Python traceback of an error")
    return parser


def _one_line(exc: BaseException) -> str:
    if isinstance(exc, KeyError):
        text = f"unknown name {next(iter(exc.args))!r}" if exc.args else "KeyError"
    else:
        text = str(exc)
    lines = [line.strip() for line in text.strip().splitlines() if line.strip()]
    return "; ".join(lines) or type(exc).__name__


def _usage(exc: UsageError) -> int:
    exc.parser.print_usage(sys.stderr)
    print(f"{exc.parser.prog}: error: {exc}", file=sys.stderr)
    return 2


def main(argv: list[str] | None = None) -> int:
    """Run the command line.

    Parameters
    ----------
    argv : list of str, optional
        Arguments (``sys.argv[1:]`` by default).

    Returns
    -------
    int
        Exit code: 0 success, 2 user error (one line on standard error), 130 interrupted.
    """
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except UsageError as exc:
        return _usage(exc)
    if not getattr(args, "func", None):
        parser.print_help()
        return 0
    command = args.command

    def show(message, category, filename, lineno, file=None, line=None):
        print(f"casship {command}: warning: {_one_line(message) if isinstance(message, Warning) else message}",
              file=sys.stderr)

    with warnings.catch_warnings():
        warnings.showwarning = show
        try:
            return int(args.func(args) or 0)
        except UsageError as exc:
            return _usage(exc)
        except KeyboardInterrupt:
            print(f"casship {command}: interrupted", file=sys.stderr)
            return 130
        except USER_ERRORS as exc:
            if getattr(args, "debug", False):
                raise
            print(f"casship {command}: error: {_one_line(exc)}", file=sys.stderr)
            return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
