"""The ``casship`` command line: one sub-command per module ``casship/cli/cmd_*.py``.

Each such module defines ``HELP`` (its one-line description) and ``register(subparsers)``, which
adds its parser and sets ``func``; only the command being run is registered in full, so that
``--help`` and argument errors answer without loading CasADi. Every sub-command shows its defaults
in ``--help``.

Errors are classified by their type alone: casship's own errors (:class:`casship.errors.CasshipError`:
``InputError``, ``SolverError``, ``SetupError``, ...) and ``OSError`` (a missing or unwritable file)
end with exit code 2 and one line ``casship CMD: error: ...`` naming the item. Anything else, a plain
``ValueError`` included, is a bug in casship: it is reported as one (``casship CMD: internal error:
...``, exit code 1). ``--debug`` shows the Python traceback of either. Warnings print as one line
``casship CMD: warning: ...``.

Ctrl-C: exit code 130 at once, the compilers this process runs stopped (their process groups) and
their build folders removed; an error raised while the interrupt unwinds is still an interrupt. A
command whose result is written exits without waiting for background compiles.
"""
from __future__ import annotations

import argparse
import importlib
import pkgutil
import signal
import sys
import threading
import warnings

from ._common import HelpFormatter, Parser, UsageError

__all__ = ["main", "build_parser", "is_user_error"]

def _commands() -> dict[str, str]:
    """Command name -> module name, from the ``cmd_*`` modules (nothing imported; ``cmd_design_trial``
    is the command ``design-trial``)."""
    return {info.name[4:].replace("_", "-"): info.name for info in sorted(pkgutil.iter_modules(__path__), key=lambda i: i.name)
            if info.name.startswith("cmd_")}


class _Version(argparse.Action):
    """``--version``: the installed version, read only when asked (see ``casship.__version__``)."""

    def __init__(self, option_strings, dest=argparse.SUPPRESS, default=argparse.SUPPRESS, help=None):
        super().__init__(option_strings, dest=dest, default=default, nargs=0, help=help)

    def __call__(self, parser, namespace, values, option_string=None):
        from .. import __version__

        print(f"casship {__version__}")
        parser.exit()


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The ``casship`` argument parser.

    Parameters
    ----------
    command : str, optional
        The one sub-command to register in full (its options and help); the others are listed with
        their one-line help only. Default: every sub-command in full.

    Returns
    -------
    argparse.ArgumentParser
    """
    parser = Parser(
        prog="casship", formatter_class=HelpFormatter,
        description="Ship manoeuvring models, state estimation and identification on CasADi.",
        epilog="casship COMMAND --help shows the options of a command.")
    parser.add_argument("--version", action=_Version, help="show the version of casship and exit")
    parser.add_argument("--debug", action="store_true", help="show the Python traceback of an error")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, module_name in _commands().items():
        module = importlib.import_module(f"{__name__}.{module_name}")
        if command is None or name == command:
            module.register(sub)
        else:
            sub.add_parser(name, help=module.HELP, add_help=False)
    for name, command_parser in sub.choices.items():
        command_parser.formatter_class = HelpFormatter
        if command_parser.description is None:
            # the one-line help of the command list doubles as the description of its own --help
            command_parser.description = next((a.help for a in sub._choices_actions if a.dest == name), None)
        if not any("--debug" in a.option_strings for a in command_parser._actions):
            command_parser.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                                        help="show the Python traceback of an error")
        if not any("--quiet" in a.option_strings for a in command_parser._actions):
            command_parser.add_argument("--quiet", action="store_true", default=argparse.SUPPRESS,
                                        help="no progress on standard error (bars on a terminal; otherwise a line "
                                             "at most every 10 s with stage, fraction and time left)")
    return parser


def _one_line(exc: BaseException) -> str:
    lines = [line.strip() for line in str(exc).strip().splitlines() if line.strip()]
    return "; ".join(lines) or type(exc).__name__


def is_user_error(exc: BaseException) -> bool:
    """Whether ``exc`` is a user's error (one line, exit 2) rather than a bug in casship, by its type alone.

    casship's own error types (:class:`casship.errors.CasshipError` and its subclasses: what casship
    raises on purpose about its input, its solvers and its environment) and ``OSError`` (files) are
    user errors. Anything else (a plain ``ValueError``, ``TypeError``, ``KeyError``, whoever raised
    it) is a bug: casship raises its own types for what the user can fix.

    Parameters
    ----------
    exc : BaseException

    Returns
    -------
    bool
    """
    from ..errors import CasshipError

    return isinstance(exc, (CasshipError, OSError))


def _usage(exc: UsageError) -> int:
    exc.parser.print_usage(sys.stderr)
    print(f"{exc.parser.prog}: error: {exc}", file=sys.stderr)
    return 2


def _selected(argv: list[str]) -> str | None:
    """The sub-command named in ``argv`` (the first word that is not an option), if any."""
    return next((a for a in argv if not a.startswith("-")), None)


def main(argv: list[str] | None = None) -> int:
    """Run the command line.

    Parameters
    ----------
    argv : list of str, optional
        Arguments (``sys.argv[1:]`` by default).

    Returns
    -------
    int
        Exit code: 0 success, 2 user error (one line on standard error), 1 a bug in casship,
        130 interrupted, 141 the reader of the output went away (a closed pipe).
    """
    argv_given = argv is not None
    argv = list(sys.argv[1:] if argv is None else argv)
    command = _selected(argv)
    parser = build_parser(command if command in _commands() else "")
    try:
        args = parser.parse_args(argv)
    except UsageError as exc:
        return _usage(exc)
    if not getattr(args, "func", None):
        parser.print_help()
        return 0
    command = args.command
    if getattr(args, "quiet", False):
        from ..progress import set_quiet

        set_quiet()

    def show(message, category, filename, lineno, file=None, line=None):
        print(f"casship {command}: warning: {_one_line(message) if isinstance(message, Warning) else message}",
              file=sys.stderr)

    interrupted = []
    previous = _on_interrupt(interrupted)
    code = None
    try:
        code = _run(args, command, show, interrupted, not argv_given)
        return code
    finally:
        if previous is not None:
            # run as the program (no argv given): the result is out, the exit must not be interrupted
            # ("Exception ignored ... KeyboardInterrupt" and exit status 0); otherwise put it back
            signal.signal(signal.SIGINT, signal.SIG_IGN if argv_given is False else previous)
        if code == 130 and argv_given is False:
            _exit_now(code)


def _exit_now(code: int) -> None:
    """End the program at once after a Ctrl-C: the work is unwound and the compilers are stopped; the
    interpreter's own teardown of a large numeric session can take seconds on a busy machine."""
    import logging
    import os

    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    logging.shutdown()
    os._exit(code)


def _run(args, command: str, show, interrupted: list, program: bool) -> int:
    """The command, its errors turned into exit codes (see :func:`main`)."""
    from ..progress import command as command_progress

    with warnings.catch_warnings():
        warnings.showwarning = show
        try:
            with command_progress(command):
                return int(args.func(args) or 0)
        except UsageError as exc:
            return _usage(exc)
        except KeyboardInterrupt:
            return _interrupted(command, program)
        except BrokenPipeError:
            # the reader of the output went away (casship ... | head): nothing to report, as a tool
            # that SIGPIPE stops; standard output is pointed at devnull so that its flush at exit is quiet
            import os

            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            return 141
        except Exception as exc:
            if interrupted:         # an error raised while a Ctrl-C unwound the work: still an interrupt
                return _interrupted(command, program)
            if getattr(args, "debug", False):
                raise
            if is_user_error(exc):
                print(f"casship {command}: error: {_opt_in(_one_line(exc), args, command)}", file=sys.stderr)
                return 2
            print(f"casship {command}: internal error (a bug in casship): {type(exc).__name__}: "
                  f"{_one_line(exc)}; run it again with --debug for the traceback and report it", file=sys.stderr)
            return 1


def _opt_in(message: str, args, command: str) -> str:
    """``message`` without the validity errors' opt-in hint (``--allow-out-of-range``) where the command has no
    such option: it would name an option the command refuses."""
    validity = sys.modules.get("casship.simulation.validity")
    if validity is None or hasattr(args, "allow_out_of_range") or validity.OPT_IN not in message:
        return message
    return message.replace(f"; {validity.OPT_IN}", "").replace(validity.OPT_IN, "") + \
        f" (casship {command} stays within the model's validity ranges: give a value inside them)"


def _on_interrupt(seen: list):
    """Note every Ctrl-C in ``seen`` while a command runs (then raise ``KeyboardInterrupt`` as Python
    does); returns the handler it replaced, or None where no handler can be set (not the main thread)."""
    if threading.current_thread() is not threading.main_thread():
        return None

    def handler(signum, frame):
        seen.append(signum)
        raise KeyboardInterrupt

    try:
        return signal.signal(signal.SIGINT, handler)
    except (ValueError, OSError):
        return None


def _interrupted(command: str, program: bool) -> int:
    """Ctrl-C: stop the compilers this process runs (their process groups and build folders) at once."""
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)        # a second Ctrl-C does not break the clean-up
    runtime = sys.modules.get("casship.runtime")
    if runtime is not None and program:         # the process ends: no compile of it is wanted any more
        runtime.stop_compilers()
    try:
        print(f"casship {command}: interrupted", file=sys.stderr)
    except (KeyboardInterrupt, OSError):
        pass
    return 130

if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
