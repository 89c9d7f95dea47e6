"""Shared pieces of the sub-commands: parsing, the model option, required options, records and outputs.

One way each: :func:`parse_items` / :func:`parse_pairs` for every ``a,b`` and ``name=value,...``
option, :func:`load_record` for every record a command reads, :func:`check_input_files` for the other files
it reads (named by their option), :func:`check_outputs` and
:func:`write_output` for every file a command writes (distinct paths, the ``--overwrite`` rule,
atomic writes), :func:`print_json` for every ``--json`` answer.
"""
from __future__ import annotations

import argparse
import math
import sys

from ..errors import InputError

__all__ = ["Parser", "UsageError", "HelpFormatter", "add_model_option", "require", "load_model", "add_overwrite_option",
           "add_limits_option", "check_ship", "parse_items", "parse_pairs", "number", "positive", "finite", "count", "seed", "load_record",
           "add_record_options", "read_records", "check_angle_columns", "check_record_ranges", "RECORD_PRESETS",
           "check_input_files", "check_outputs", "write_output", "print_json", "refuse_unused"]


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

    def parse_known_args(self, args=None, namespace=None):
        """As argparse's, refusing an empty value (``--measured ""``) of an option whose default is None:
        that default means "left out" (every output, the model's values, no file), which an empty value
        would otherwise silently choose. An option with a non-empty default (a list of angles) keeps
        ``""`` as "none"."""
        namespace, rest = super().parse_known_args(args, namespace)
        for action in self._actions:
            value = getattr(namespace, action.dest, None)
            if action.default is None and (value == "" or (isinstance(value, list) and "" in value)):
                name = action.option_strings[0] if action.option_strings else action.metavar or action.dest
                self.error(f"{name}: an empty value names nothing"
                           + ("; give one, or leave the option out for its default" if action.option_strings else ""))
        return namespace, rest


class HelpFormatter(argparse.RawDescriptionHelpFormatter, argparse.ArgumentDefaultsHelpFormatter):
    """Descriptions kept as written (examples), defaults shown unless there is none to show."""

    def _get_help_string(self, action):
        # a flag (store_true/store_false) has no value to show: "--no-free (default: True)" misleads
        if action.default in (None, False, argparse.SUPPRESS) or action.default == [] or action.nargs == 0 \
                or "%(default)" in (action.help or ""):
            return action.help
        return super()._get_help_string(action)


# -- values ---------------------------------------------------------------------------------------------
def number(text: str, what: str) -> float:
    """``text`` as a finite float, or :class:`~casship.errors.InputError` naming ``what``."""
    try:
        value = float(text)
    except (TypeError, ValueError):
        raise InputError(f"{what}: {text!r} is not a number") from None
    if not math.isfinite(value):
        raise InputError(f"{what}: must be finite, got {text}")
    return value


def finite(text: str) -> float:
    """argparse type: a finite number."""
    try:
        return number(text, "value")
    except InputError as exc:
        raise argparse.ArgumentTypeError(str(exc).removeprefix("value: ")) from None


def positive(text: str) -> float:
    """argparse type: a positive finite number."""
    value = finite(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text}")
    return value


def _whole(text: str, low: int, what: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if value < low:
        raise argparse.ArgumentTypeError(f"{what} a whole number >= {low}, got {text}")
    return value


def count(text: str) -> int:
    """argparse type: a whole number >= 1 (workers, iterations, a decimation factor)."""
    return _whole(text, 1, "must be")


def whole(text: str) -> int:
    """argparse type: a whole number >= 0 (a count that may be zero)."""
    return _whole(text, 0, "must be")


def level(text: str) -> float:
    """argparse type: a coverage probability strictly between 0 and 1."""
    value = finite(text)
    if not 0 < value < 1:
        raise argparse.ArgumentTypeError(f"a coverage level lies strictly between 0 and 1, got {text}")
    return value


def seed(text: str) -> int:
    """argparse type: a random seed, a whole number >= 0."""
    return _whole(text, 0, "a seed is")


def parse_items(text: str | None, what: str = "list", *, unique: bool = True) -> list[str]:
    """Comma-separated items (commas inside brackets, as in ``bias[a,b]``, do not split).

    Parameters
    ----------
    text : str or None
        The option's value (None or empty: no items).
    what : str
        The option, for messages.
    unique : bool
        Refuse an item given twice (a name); False for labels that repeat (one per record).

    Returns
    -------
    list of str

    Raises
    ------
    InputError
        An empty item (``a,,b``), unbalanced brackets, or (``unique``) an item given twice.
    """
    if not text:
        return []
    out, depth, cur = [], 0, ""
    for ch in text:
        depth += (ch == "[") - (ch == "]")
        if depth < 0:
            raise InputError(f"{what}: unbalanced ']' in {text!r}")
        if ch == "," and depth == 0:
            out.append(cur.strip())
            cur = ""
        else:
            cur += ch
    if depth:
        raise InputError(f"{what}: unbalanced '[' in {text!r}")
    out.append(cur.strip())
    if "" in out:
        raise InputError(f"{what}: empty item in {text!r}")
    twice = sorted({s for s in out if out.count(s) > 1})
    if twice and unique:
        raise InputError(f"{what}: {twice} given more than once")
    return out


def parse_pairs(text: str | None, what: str, *, numbers: bool = True, names=None) -> dict:
    """``name=value,...`` as a dict (values as finite numbers, or as text with ``numbers=False``).

    Parameters
    ----------
    text : str or None
        The option's value (None or empty: an empty dict).
    what : str
        The option, for messages (e.g. ``"--R"``).
    numbers : bool
        Convert the values to finite floats.
    names : sequence of str, optional
        The accepted names (an unknown one raises, listing them).

    Returns
    -------
    dict

    Raises
    ------
    InputError
        An item that is not ``name=value``, a name given twice, a value that is not a finite number,
        or an unknown name.
    """
    out = {}
    for item in parse_items(text, what):
        key, sep, value = item.partition("=")
        key, value = key.strip(), value.strip()
        if not sep or not key or not value:
            raise InputError(f"{what}: expected name=value items, got {item!r}")
        if key in out:
            raise InputError(f"{what}: {key!r} given more than once")
        out[key] = number(value, f"{what} {key}") if numbers else value
    if names is not None:
        unknown = [k for k in out if k not in names]
        if unknown:
            raise InputError(f"{what}: unknown name(s) {unknown}; known: {list(names)}")
    return out


# -- options ----------------------------------------------------------------------------------------------
def add_model_option(parser: argparse.ArgumentParser) -> None:
    """``--model NAME``, the one way every sub-command takes the model."""
    parser.add_argument("--model", default=None, metavar="NAME",
                        help="registered model name (casship simulate --list shows them)")


def require(parser: argparse.ArgumentParser, args, needed: dict[str, object]) -> None:
    """Raise argparse's usage error (exit code 2) listing *all* missing required options at once.

    ``needed`` maps the option as the user types it (``"--model"``, ``"DATA"``) to its value.
    """
    missing = [name for name, value in needed.items() if value is None or value == [] or value == ""]
    if missing:
        parser.error(f"the following arguments are required: {', '.join(missing)}")


def refuse_unused(parser: argparse.ArgumentParser, given: dict[str, bool], reason: str) -> None:
    """Refuse options that would have no effect (usage error naming them and why)."""
    unused = [name for name, is_given in given.items() if is_given]
    if unused:
        parser.error(f"{', '.join(unused)} would have no effect: {reason}")


def load_model(name: str):
    """The registered model ``name`` (an unknown name raises ``ValueError`` listing the known ones)."""
    from ..models import get_model

    return get_model(name)


def check_ship(model, name: str, what: str, *, rudder: bool = True) -> None:
    """Refuse a model the command cannot run (no vessel, or no rudder where manoeuvres need one),
    naming the registered models it can run.

    Parameters
    ----------
    model : Model
    name : str
        The ``--model`` as given.
    what : str
        What the command does, for the message (e.g. ``"a manoeuvre"``).
    rudder : bool
        Whether a rudder is needed (manoeuvres), or a vessel is enough (an autopilot also steers
        a craft with two propellers).

    Raises
    ------
    InputError
    """
    from ..models import get_model, model_names

    def fits(m) -> bool:
        return m.vessel is not None and (bool(m.vessel.rudders) or not rudder)

    if fits(model):
        return
    why = ("has no vessel (particulars, rudder, propellers): it is not a ship model" if model.vessel is None else
           f"steers with its propellers {list(model.vessel.propellers)}, not a rudder")
    ships = [n for n in model_names() if fits(get_model(n))]
    raise InputError(f"--model {name}: {why}; {what} needs a ship with {'a rudder' if rudder else 'a vessel'}, "
                     f"registered: {ships} (in Python, a model of your own gets one with ModelBuilder.vessel)")


def add_overwrite_option(parser: argparse.ArgumentParser) -> None:
    """``--overwrite``: allow replacing existing result files / folders (see :mod:`casship.outdir`)."""
    parser.add_argument("--overwrite", action="store_true",
                        help="replace existing output files or folders (a folder is cleared first)")


def add_limits_option(parser: argparse.ArgumentParser) -> None:
    """``--allow-out-of-range``: the explicit opt-in for inputs outside the model's declared ranges."""
    parser.add_argument("--allow-out-of-range", dest="allow_out_of_range", action="store_true",
                        help="run although inputs, states or the time step leave the model's validity "
                             "ranges (a deliberate out-of-range study)")


# -- records ----------------------------------------------------------------------------------------------
#: Column presets of log formats (``--preset``): time column, columns with units, geodetic columns.
RECORD_PRESETS = {
    "usv-gnss": {
        "doc": "USV GNSS logs (time [s], lat/lon [deg]): lat/lon in rad and local x_n, y_n [m]; "
               "the log's own speed [kn] and heading [deg] kept as log_speed, log_heading for comparison",
        "time": "time:s",
        "columns": {"lat": "lat:deg", "lon": "lon:deg", "log_speed": "speed:kn", "log_heading": "heading:deg"},
        "latlon": ("lat", "lon"),
    },
}


def add_record_options(parser: argparse.ArgumentParser, what: str = "record") -> None:
    """The record options every command that reads records takes: ``--preset``, ``--columns``, ``--time``,
    ``--latlon`` (one vocabulary for ``filter``, ``identify`` and ``simulate``; see :func:`read_records`)."""
    parser.add_argument("--preset", default=None, choices=sorted(RECORD_PRESETS),
                        help=f"column preset of a log format for the {what} (see 'casship filter --list')")
    parser.add_argument("--columns", default=None,
                        help="NEW=SOURCE[:UNIT],... CSV columns to read and convert to SI (e.g. psi=heading:deg); "
                             "default: all columns as they are")
    parser.add_argument("--time", default=None, help="CSV time column and unit (default t:s, or the preset's)")
    parser.add_argument("--latlon", default=None, help="LAT,LON: geodetic columns (rad after conversion) that "
                                                       "also give local x_n, y_n [m]")


def read_records(args, paths, model=None, *, wrap_angles: bool = True) -> list:
    """The records of a command, read the one way (:func:`add_record_options`).

    Without record options a file is read by :func:`casship.io.read_record` (CSV, MARIN, HSVA, NMEA);
    with them as a CSV converted to SI (:func:`casship.io.read_csv`). Either way the model's angle
    columns are checked for degrees on the raw column (:func:`check_angle_columns`), before any
    wrapping, and then (``wrap_angles``) wrapped to (-pi, pi].

    Parameters
    ----------
    args : argparse.Namespace
        With ``preset``, ``columns``, ``time``, ``latlon`` (absent attributes count as not given).
    paths : sequence of str or Path
    model : Model, optional
    wrap_angles : bool

    Returns
    -------
    list of Dataset
    """
    from pathlib import Path

    from ..io import read_csv, read_record, record_format

    preset_name = getattr(args, "preset", None)
    preset = RECORD_PRESETS[preset_name] if preset_name else {}
    columns = dict(preset.get("columns", {}))
    columns.update(parse_pairs(getattr(args, "columns", None), "--columns", numbers=False))
    latlon_text = getattr(args, "latlon", None)
    latlon = tuple(parse_items(latlon_text, "--latlon")) if latlon_text else preset.get("latlon")
    if latlon is not None and len(latlon) != 2:
        raise InputError(f"--latlon: expected LAT,LON, got {latlon_text!r}")
    time = getattr(args, "time", None) or preset.get("time")
    out = []
    for path in paths:
        path = Path(path)
        if not columns and time is None and latlon is None:
            out.append(load_record(path, model, wrap_angles=wrap_angles))
            continue
        if not path.is_file():
            raise FileNotFoundError(f"data file {path}: no such file")
        kind = record_format(path)
        if kind != "csv":       # read_csv would take the file's title line for a header and miss its time column
            given = [o for o, v in (("--preset", preset_name), ("--columns", getattr(args, "columns", None)),
                                    ("--time", getattr(args, "time", None)), ("--latlon", latlon_text)) if v]
            raise InputError(f"{', '.join(given)}: record options read CSV files; {path} is a {kind} record, read "
                             f"with its own columns in SI units ({', '.join(read_record(path).names)}): leave "
                             f"{'it' if len(given) == 1 else 'them'} out")
        data = read_csv(path, columns or None, time=time or "t:s", latlon=latlon)
        data = _checked_and_wrapped(data, model, path, wrap_angles)
        data.meta.setdefault("name", path.name)
        out.append(data)
    return out


def check_record_ranges(model, records) -> None:
    """Refuse a record whose inputs or first-row states leave the validity ranges of ``model``, naming the record.

    What ``filter`` and ``simulate`` check before they run (their ``--allow-out-of-range`` opts out), for the
    records of a fit: a model-scale record on the full-scale ship (propeller rate ten times its range), or the
    reverse, is refused before any fitting.

    Parameters
    ----------
    model : Model
    records : sequence of Dataset
        Each named by ``meta["name"]`` (else ``meta["source"]``).

    Raises
    ------
    casship.simulation.ValidityError
        Naming the record, the variable, its value and the range.
    """
    import numpy as np

    from ..simulation import ValidityError, check_inputs, check_states

    for k, d in enumerate(records):
        label = d.meta.get("name") or d.meta.get("source") or f"#{k + 1}"
        try:
            check_inputs(model, {n: d[n] for n in model.input_names if n in d}, d.t)
            first = {n: float(d[n][0]) for n in model.state_names if n in d and np.isfinite(d[n][0])}
            check_states(model, first, what="first-row state")
        except ValidityError as exc:
            raise ValidityError(f"record {label}: {exc}") from None


def _angle_names(model) -> list[str]:
    names = [n for n, a in zip(model.output_names, model.angle_outputs) if a]
    names += [n for n, a in zip(model.state_names, model.angle_states) if a and n not in names]
    return names


def check_angle_columns(data, model, source: str = "the record") -> None:
    """Refuse an angle column of ``model`` (heading, course) that holds degrees, on the raw column.

    A heading in radians lies within +-2 pi, or (a continuous heading of a record that turns more
    than once) starts within +-2 pi and turns on steadily. Beyond 2 pi, the column is taken as degrees
    when it starts beyond 2 pi, jumps by more than half a turn between samples other than by one
    turn (a heading in degrees wrapping at 360), or turns back by more than half a turn (a zig-zag
    in degrees); and, with a yaw-rate column ``r``, when its rate is ten times that of ``r``.

    Parameters
    ----------
    data : Dataset
    model : Model
    source : str
        The record, for the message.

    Raises
    ------
    InputError
        Naming the column, the record and the reason.
    """
    import numpy as np

    if model is None:
        return
    for name in _angle_names(model):
        if name not in data:
            continue
        v = np.asarray(data[name], dtype=float)
        v = v[np.isfinite(v)]
        if not v.size or np.abs(v).max() <= 2 * np.pi + 1e-9:
            continue
        why = None
        d = np.diff(v)
        jumps = np.abs(d) > np.pi
        if abs(v[0]) > 2 * np.pi + 1e-9:
            why = f"it starts at {v[0]:.4g}"
        elif np.any(jumps & (np.abs(np.abs(d) - 2 * np.pi) > 0.5 * np.pi)):
            k = int(np.flatnonzero(jumps & (np.abs(np.abs(d) - 2 * np.pi) > 0.5 * np.pi))[0])
            why = f"it jumps from {v[k]:.4g} to {v[k + 1]:.4g} between two samples"
        elif max(np.max(np.maximum.accumulate(v) - v), np.max(v - np.minimum.accumulate(v))) > np.pi and \
                min(np.max(np.maximum.accumulate(v) - v), np.max(v - np.minimum.accumulate(v))) > np.pi:
            why = "it turns back and forth by more than half a turn"
        elif "r" in data and name == "psi" and data.t.size > 1:
            r = np.asarray(data["r"], dtype=float)
            rate = np.nanmean(np.abs(np.diff(np.asarray(data[name], dtype=float)) / np.diff(data.t)))
            if np.isfinite(rate) and rate > 10 * max(np.nanmean(np.abs(r)), 1e-12):
                why = f"it turns {rate:.3g} per second on average, the yaw rate column r only {np.nanmean(np.abs(r)):.3g} rad/s"
        if why is None:         # a continuous heading of a record that turns more than once
            continue
        raise InputError(f"{source}: column {name!r} reaches {np.abs(v).max():.4g} and {why}: it looks like degrees; "
                         f"angles are radians (give --columns {name}=SOURCE:deg, or convert the column)")


def _checked_and_wrapped(data, model, path, wrap_angles: bool):
    """``data`` with the model's angle columns checked for degrees (raw) and then wrapped."""
    from ..angles import wrap

    if model is None:
        return data
    check_angle_columns(data, model, str(path))
    if wrap_angles:
        angles = {n: wrap(data[n]) for n in _angle_names(model) if n in data}
        if angles:
            data = data.with_columns(**angles)
    return data


def load_record(path, model=None, *, wrap_angles: bool = False):
    """A record by :func:`casship.io.read_record` (CSV, MARIN, HSVA, NMEA), the one reader of the commands.

    Parameters
    ----------
    path : str or Path
    model : Model, optional
        The model whose angle columns are checked for degrees on the raw column
        (:func:`check_angle_columns`) and, with ``wrap_angles``, then wrapped to (-pi, pi] (trial
        files hold a continuous heading; an estimator compares angles on the circle).
    wrap_angles : bool
        Wrap the model's angle outputs.

    Returns
    -------
    Dataset
        ``meta["name"]`` is the file name.
    """
    from pathlib import Path

    from ..io import read_record

    data = _checked_and_wrapped(read_record(path), model, path, wrap_angles)
    data.meta.setdefault("name", Path(path).name)
    return data


def check_input_files(inputs: dict[str, object]) -> None:
    """Check that every input file a command's options name exists, naming the option and the path.

    Parameters
    ----------
    inputs : dict
        Option (``"--params"``) -> path (None: not given).

    Raises
    ------
    FileNotFoundError, IsADirectoryError
        A path that does not exist, or is a folder.
    """
    from pathlib import Path

    for option, path in inputs.items():
        if path is None:
            continue
        if Path(path).is_dir():
            raise IsADirectoryError(f"{option} {path}: is a folder; give a file")
        if not Path(path).exists():
            raise FileNotFoundError(f"{option} {path}: no such file")


# -- outputs ---------------------------------------------------------------------------------------------
#: The figure formats of ``--plot`` (chosen by the file name's suffix).
PLOT_SUFFIXES = (".png", ".pdf", ".svg")


def check_outputs(outputs: dict[str, object], *, overwrite: bool, folders: tuple[str, ...] = ()) -> dict:
    """Check every output of a command before any work: distinct paths, the ``--overwrite`` rule.

    Parameters
    ----------
    outputs : dict
        Option (``"--out"``) -> path (None: not asked for).
    overwrite : bool
        The command's ``--overwrite``.
    folders : tuple of str
        The options whose path is a folder.

    Returns
    -------
    dict
        Option -> the stamp of what is at its path now (see :func:`casship.outdir.stamp`), for
        :func:`write_output`.

    Raises
    ------
    InputError
        Two options naming the same path, or a ``--plot`` file whose suffix is not a figure format
        (:data:`PLOT_SUFFIXES`).
    FileExistsError, PermissionError, ...
        As :func:`casship.outdir.check_output_file` and :func:`~casship.outdir.check_output_folder`.
    """
    from pathlib import Path

    from ..outdir import check_output_file, check_output_folder, stamp

    given = {k: Path(v) for k, v in outputs.items() if v}
    for option, path in given.items():
        if option == "--plot" and option not in folders and path.suffix.lower() not in PLOT_SUFFIXES:
            raise InputError(f"--plot {path}: a figure is written as {', '.join(PLOT_SUFFIXES)}; give a file name "
                             "ending so")
    seen = {}
    for option, path in given.items():
        key = path.absolute().resolve()
        if key in seen:
            raise InputError(f"{seen[key]} and {option} name the same path {path}: one would replace the other")
        seen[key] = option
    stamps = {}
    for option, path in given.items():
        check = check_output_folder if option in folders else check_output_file
        check(path, overwrite=overwrite, what=option)
        stamps[option] = stamp(path)
    return stamps


def write_output(path, write, *, option: str, overwrite: bool, stamps: dict) -> None:
    """Write one output file atomically: ``write(tmp)`` into a temporary sibling, then move it into place.

    The move never replaces a file that appeared (or changed) since :func:`check_outputs` looked,
    with or without ``--overwrite`` (see :func:`casship.outdir.output_file`).
    """
    from ..outdir import output_file

    with output_file(path, overwrite=overwrite, what=option, expect=stamps.get(option)) as tmp:
        write(tmp)


def print_json(value, stream=None) -> None:
    """Print one JSON object (:func:`casship.io.jsonfile.dumps`: numpy values as numbers, non-finite as text)."""
    from ..io.jsonfile import dumps

    print(dumps(value), file=stream or sys.stdout)
