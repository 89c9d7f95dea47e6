"""One vocabulary across the command line: renamed options keep their old name as a deprecated alias.

The rule the names follow (checked by ``tests/test_cli_vocabulary.py``): angles are given in
degrees with a ``-deg`` (``-deg-s`` for a rate) name, or carry their unit in the name (``-N-m``
for a yaw moment); one option name means one thing in every command. An old name still works: it
says once on standard error which name replaces it, and gives the same value.
"""
from __future__ import annotations

import argparse
import sys

__all__ = ["add_deprecated_alias", "RENAMED"]

#: old option -> (new option, commands), the renames this vocabulary made (for the docs and tests)
RENAMED = {
    "--method": ("--design (autopilot), --integrator (simulate, filter), --objective (identify)",
                 ("autopilot", "simulate", "filter", "identify")),
    "--rate": ("--rate-source", ("autopilot",)),
    "--steer-max": ("--steer-max-deg (a rudder) or --steer-max-N-m (a yaw moment)", ("autopilot",)),
    "--steer-rate-max": ("--steer-rate-max-deg-s (a rudder) or --steer-rate-max-N-m-s (a yaw moment)",
                         ("autopilot",)),
    "--rudder-rate-deg": ("--rudder-rate-deg-s", ("design-trial",)),
    "--json": ("--json-file", ("bench",)),
    "--prior": ("--prior-std", ("identify",)),
    "--t-end": ("--duration", ("autopilot",)),
}


class _Deprecated(argparse.Action):
    """Stores the value under the new option's ``dest`` (converted if asked) and says the new name."""

    def __init__(self, option_strings, dest, *, new: str, convert=None, **kw):
        self.new, self.convert = new, convert
        super().__init__(option_strings, dest, **kw)

    def __call__(self, parser, namespace, values, option_string=None):
        print(f"{parser.prog}: warning: {option_string} is deprecated and will be removed; use {self.new}",
              file=sys.stderr)
        setattr(namespace, self.dest, self.convert(values) if self.convert else values)


def add_deprecated_alias(parser, old: str, new: str, *, dest: str, convert=None, **kw) -> None:
    """Accept ``old`` as a hidden, deprecated spelling of ``new``.

    Parameters
    ----------
    parser : argparse.ArgumentParser
    old : str
        The old option (e.g. ``"--method"``).
    new : str
        What replaces it, as said in the warning (e.g. ``"--integrator"``).
    dest : str
        The attribute the value goes to (the new option's).
    convert : callable, optional
        Applied to the parsed value (e.g. a unit conversion) before it is stored.
    **kw
        ``type``, ``choices``, ``nargs``, ``metavar`` as for the old option.
    """
    parser.add_argument(old, dest=dest, action=_Deprecated, new=new, convert=convert, default=argparse.SUPPRESS,
                        help=argparse.SUPPRESS, **kw)
