"""The small kit every study shares: measured data, cases, tables, figures, JSON and the report.

* **Data** -- :func:`resolve_data_dir` and :func:`data_folder` apply casship's one rule
  (:func:`casship.io.data_dir`) and announce on the console what a study skips without data.
* **Cases** -- :func:`run_cases` (from :mod:`casship.parallel`): Monte Carlo cases with their own
  seeds, serial, in a process pool or on Dask, with identical results.
* **Tables** -- :func:`md_table` turns rows (mappings) into Markdown.
* **Figures** -- :func:`figure` opens a Matplotlib figure (Agg) and saves it as PNG when the block ends.
* **JSON** -- :func:`json_ready`, :func:`write_json`.
* **Report** -- :class:`Report` writes ``report.md``: the first line says whether it is a quick or a
  full run, and every report carries the table of :class:`Departure` s from the paper it reproduces
  (each choice the paper leaves open or the study makes differently, the reading taken and its
  measured effect on the headline numbers); :func:`effect` formats such an effect.
"""
from __future__ import annotations

import math
import os
import sys
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Iterator, Mapping, Sequence

from casship.io import data_dir as _data_dir
from casship.io.jsonfile import json_ready as _json_ready, write_json as _write_json
from casship.parallel import run_cases

__all__ = ["resolve_data_dir", "data_folder", "announce", "run_cases", "md_table", "figure", "json_ready",
           "write_json", "Departure", "Report", "effect", "fmt"]


# -- measured data ----------------------------------------------------------------------------------------
def announce(study: str, message: str, stream=None) -> None:
    """Print ``study NAME: message`` on the console (stderr): skipped parts, data used."""
    print(f"study {study}: {message}", file=stream or sys.stderr, flush=True)


def resolve_data_dir(data_dir: str | os.PathLike | None, *, quiet: bool = False) -> Path | None:
    """The measured-data folder: ``data_dir`` if given, else casship's rule (None when absent).

    With ``quiet`` a folder named by ``CASSHIP_DATA`` that does not exist gives None instead of an
    error (for module-level defaults); a ``data_dir`` given explicitly must always exist.
    """
    if data_dir is not None:
        return _data_dir(data_dir)
    try:
        return _data_dir()
    except FileNotFoundError:
        if quiet:
            return None
        raise


def data_folder(data_dir: str | os.PathLike | None, sub: str, *, study: str, part: str) -> Path | None:
    """The data subfolder ``sub`` for one part of a study, or None with a console note saying that
    ``part`` is skipped and why."""
    root = resolve_data_dir(data_dir)
    if root is None:
        announce(study, f"skipped {part}: no measured-data folder (give --data DIR or set CASSHIP_DATA)")
        return None
    folder = root / sub
    if not folder.is_dir():
        announce(study, f"skipped {part}: {folder} is absent")
        return None
    return folder


# -- tables ------------------------------------------------------------------------------------------------
def fmt(value, spec: str = ".4g") -> str:
    """A number for a table (``spec`` for floats; NaN as 'n/a'); anything else as ``str``."""
    if isinstance(value, bool) or value is None:
        return str(value)
    if isinstance(value, (int,)) and not isinstance(value, bool):
        return str(value)
    try:
        v = float(value)
    except (TypeError, ValueError):
        return str(value)
    return "n/a" if math.isnan(v) else format(v, spec)


def md_table(rows: Mapping[str, Mapping] | Sequence[Mapping], columns: Sequence[str] | None = None, *,
             first: str = "case", spec: str = ".4g", headers: Mapping[str, str] | None = None) -> str:
    """A Markdown table: one row per entry of ``rows`` (name -> mapping, or a list of mappings).

    ``columns`` picks and orders the keys (default: the keys of the first row); ``headers`` renames
    them; numbers are formatted with ``spec``.
    """
    if isinstance(rows, Mapping):
        named = [(str(k), v) for k, v in rows.items()]
    else:
        named = [(None, v) for v in rows]
    if not named:
        raise ValueError("md_table: no rows")
    cols = list(columns or named[0][1].keys())
    headers = headers or {}
    head = ([first] if named[0][0] is not None else []) + [headers.get(c, c) for c in cols]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for name, row in named:
        cells = ([name] if name is not None else []) + [fmt(row.get(c, ""), spec) for c in cols]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


# -- figures and JSON --------------------------------------------------------------------------------------
@contextmanager
def figure(path: str | os.PathLike, nrows: int = 1, ncols: int = 1, *, margins: Mapping[str, float] | None = None,
           **kwargs) -> Iterator:
    """``with figure(out / "x.png", 2, 1, figsize=(8, 5)) as (fig, axes):`` -- saved (110 dpi); made
    without pyplot, so no backend is chosen and nothing stays open.

    The layout is matplotlib's tight layout, unless ``margins`` gives it in inches (keys ``left``,
    ``right``, ``bottom``, ``top``: figure edge to axes; ``wspace``, ``hspace``: between axes): for
    figures drawn many times over, as the tight layout draws every text once more to measure it.
    """
    from matplotlib.figure import Figure

    fig = Figure(figsize=kwargs.pop("figsize", None))
    axes = fig.subplots(nrows, ncols, **kwargs)
    yield fig, axes
    if margins is None:
        fig.tight_layout()
    else:
        _fixed_margins(fig, nrows, ncols, margins)
    fig.savefig(path, dpi=110)


def _fixed_margins(fig, nrows: int, ncols: int, margins: Mapping[str, float]) -> None:
    """Place the subplots with the margins and gaps ``margins`` [in] (see :func:`figure`)."""
    m = {"left": 0.8, "right": 0.15, "bottom": 0.6, "top": 0.35, "wspace": 0.8, "hspace": 0.8}
    unknown = sorted(set(margins) - set(m))
    if unknown:
        raise ValueError(f"figure: unknown margin(s) {unknown}; known: {sorted(m)}")
    m.update(margins)
    width, height = fig.get_size_inches()
    axis_w = (width - m["left"] - m["right"] - (ncols - 1) * m["wspace"]) / ncols
    axis_h = (height - m["bottom"] - m["top"] - (nrows - 1) * m["hspace"]) / nrows
    if axis_w <= 0 or axis_h <= 0:
        raise ValueError(f"figure: margins {m} leave no room for {nrows} x {ncols} axes in {width:g} x {height:g} in")
    fig.subplots_adjust(left=m["left"] / width, right=1 - m["right"] / width, bottom=m["bottom"] / height,
                        top=1 - m["top"] / height, wspace=m["wspace"] / axis_w, hspace=m["hspace"] / axis_h)


def json_ready(value):
    """``value`` with numpy scalars/arrays as plain numbers/lists (NaN kept), ready for ``json.dumps``
    (:func:`casship.io.jsonfile.json_ready`)."""
    return _json_ready(value, nonfinite="keep")


def write_json(path: str | os.PathLike, value) -> dict:
    """Write ``value`` as indented JSON (NaN kept); returns the JSON-ready value."""
    return _write_json(path, value, nonfinite="keep")


# -- the report --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Departure:
    """One choice the paper leaves open, or that the study makes differently.

    Parameters
    ----------
    topic : str
        What the choice is about (e.g. "data noise of experiments 1 and 3").
    paper : str
        What the paper says (or that it says nothing).
    reading : str
        The reading this study takes.
    effect : str
        Its measured effect on the headline numbers (both readings run where cheap), or why it is
        not measured.
    """

    topic: str
    paper: str
    reading: str
    effect: str


def effect(main: Mapping[str, float], alt: Mapping[str, float], *, alt_name: str = "the other reading",
           spec: str = ".3g", units: Mapping[str, str] | None = None, relative: bool = True) -> str:
    """``"key: 1.23 -> 1.45 (+18 %); ..."`` -- headline numbers of this study vs the other reading
    (``relative=False`` leaves out the relative change, e.g. for numbers that are already errors in %)."""
    units = units or {}
    parts = []
    for key, a in main.items():
        b = alt[key]
        unit = f" {units[key]}" if key in units else ""
        rel = ""
        try:
            if relative and float(a) != 0 and math.isfinite(float(a)) and math.isfinite(float(b)):
                rel = f" ({100.0 * (float(b) - float(a)) / abs(float(a)):+.0f} %)"
        except (TypeError, ValueError):
            pass
        parts.append(f"{key}: {fmt(a, spec)} -> {fmt(b, spec)}{unit}{rel}")
    return f"with {alt_name}: " + "; ".join(parts)


class Report:
    """A study's ``report.md``, assembled in order and written once.

    The first line is the title followed by ``(quick run)`` or ``(full run)``, so a quick report is
    never mistaken for a full one.

    Examples
    --------
    >>> rep = Report("Shi et al. (2009) reproduced", quick=True)
    >>> rep.section("Table 2")
    >>> rep.add(md_table({"advance": {"paper": 790.0, "casship": 801.2}}, first="item"))
    >>> rep.departures([Departure("P(0)", "1e5 I", "R for u, v, r", "advance: +1 %")])
    >>> rep.text().splitlines()[0]
    '# Shi et al. (2009) reproduced (quick run)'
    """

    def __init__(self, title: str, *, quick: bool):
        self.quick = bool(quick)
        mode = ("quick run: shortened records and fewer seeds, numbers are indicative only"
                if quick else "full run")
        self._parts: list[str] = [f"# {title} ({'quick run' if quick else 'full run'})", "",
                                  f"_{mode[0].upper() + mode[1:]}._", ""]
        self._has_departures = False

    def add(self, *blocks: str) -> "Report":
        """Append paragraphs or tables (each followed by a blank line)."""
        for block in blocks:
            self._parts += [str(block).rstrip("\n"), ""]
        return self

    def section(self, title: str, level: int = 2) -> "Report":
        """Start a section ``## title``."""
        return self.add("#" * level + " " + title)

    def image(self, name: str, caption: str) -> "Report":
        """Embed a PNG written into the same folder."""
        return self.add(f"![{caption}]({name})")

    def departures(self, items: Iterable[Departure], intro: str = "") -> "Report":
        """The "Departures from the paper" table."""
        items = list(items)
        if not items:
            raise ValueError("a study reproducing a paper lists at least one departure (or says there is none)")
        rows = ["| choice | the paper | this study's reading | measured effect on the headline numbers |",
                "|---|---|---|---|"]
        cell = lambda s: str(s).replace("|", "\\|").replace("\n", " ")  # noqa: E731
        rows += [f"| {cell(d.topic)} | {cell(d.paper)} | {cell(d.reading)} | {cell(d.effect)} |" for d in items]
        self.section("Departures from the paper")
        if intro:
            self.add(intro)
        self._has_departures = True
        return self.add("\n".join(rows))

    def text(self) -> str:
        """The Markdown text so far."""
        return "\n".join(self._parts).rstrip("\n") + "\n"

    def write(self, out: str | os.PathLike, name: str = "report.md") -> Path:
        """Write ``out/name``; a report without its departures table is refused."""
        if not self._has_departures:
            raise ValueError("report.md needs its 'Departures from the paper' table (Report.departures)")
        path = Path(out) / name
        path.write_text(self.text())
        return path
