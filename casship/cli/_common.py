"""Shared pieces of the sub-commands: the model option, required options, output checks, record reading."""
from __future__ import annotations

import argparse

__all__ = ["Parser", "UsageError", "HelpFormatter", "add_model_option", "require", "load_model", "add_overwrite_option",
           "add_limits_option"]


class UsageError(Exception):
    """A command-line usage error (missing or malformed option): usage line and message, exit code 2."""

    def __init__(self, parser: argparse.ArgumentParser, message: str):
        super().__init__(message)
        self.parser = parser


class Parser(argparse.ArgumentParser):
    """An argument parser whose errors are raised (:class:`UsageError`) instead of exiting, so that
    :func:`casship.cli.main` returns the exit code 2 itself."""

    def error(self, message):
        raise UsageError(self, message)


class HelpFormatter(argparse.RawDescriptionHelpFormatter, argparse.ArgumentDefaultsHelpFormatter):
    """Descriptions kept as written (examples), defaults shown unless there is none to show."""

    def _get_help_string(self, action):
        if action.default in (None, False, argparse.SUPPRESS) or action.default == [] \
                or "%(default)" in (action.help or ""):
            return action.help
        return super()._get_help_string(action)


def add_model_option(parser: argparse.ArgumentParser, legacy_positional: bool = False) -> None:
    """``--model NAME``, the one way every sub-command takes the model.

    ``legacy_positional`` adds a hidden positional slot so that the old spelling
    ``casship CMD NAME`` gets a helpful error instead of "unrecognized arguments".
    """
    parser.add_argument("--model", default=None, metavar="NAME",
                        help="registered model name (casship simulate --list shows them)")
    if legacy_positional:
        parser.add_argument("legacy_model", nargs="?", default=None, help=argparse.SUPPRESS)


def require(parser: argparse.ArgumentParser, args, needed: dict[str, object]) -> None:
    """Raise argparse's usage error (exit code 2) listing *all* missing required options at once.

    ``needed`` maps the option as the user types it (``"--model"``, ``"DATA"``) to its value.
    """
    legacy = getattr(args, "legacy_model", None)
    if legacy is not None:
        parser.error(f"the model is given with --model: casship {parser.prog.split()[-1]} --model {legacy} ...")
    missing = [name for name, value in needed.items() if value is None or value == [] or value == ""]
    if missing:
        parser.error(f"the following arguments are required: {', '.join(missing)}")


def load_model(name: str):
    """The registered model ``name`` (an unknown name raises ``ValueError`` listing the known ones)."""
    from ..models import get_model

    return get_model(name)


def add_overwrite_option(parser: argparse.ArgumentParser) -> None:
    """``--overwrite``: allow replacing existing result files / folders (see :mod:`casship.outdir`)."""
    parser.add_argument("--overwrite", action="store_true",
                        help="replace existing output files or folders (a folder is cleared first)")


def add_limits_option(parser: argparse.ArgumentParser) -> None:
    """``--allow-out-of-range``: the explicit opt-in for inputs outside the model's declared ranges."""
    parser.add_argument("--allow-out-of-range", dest="allow_out_of_range", action="store_true",
                        help="run although inputs, states or the time step leave the model's validity "
                             "ranges (a deliberate out-of-range study)")
