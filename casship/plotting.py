"""The one contract of every ``plot`` in casship: ``plot(ax=None, path=None, ...)``.

* no ``ax``, no ``path``: a new :class:`matplotlib.figure.Figure` is drawn and returned. It is not
  held by ``pyplot`` (nothing to close, no backend chosen or switched) and shows itself as PNG
  (``_repr_png_``): a notebook shows the returned figure once, whether or not ``pyplot`` was
  imported; a script saves it (``fig.savefig``) or passes its own axes;
* ``ax``: the panels are drawn into the caller's axes (one ``Axes``, or as many as the figure has
  panels) and those axes are returned, so the figure can be composed with others and shown by
  ``plt.show()``;
* ``path``: the figure is also written there (the suffix picks the format, PNG without one) and the
  path is returned.

A path given in the place of ``ax`` (the earlier ``plot(path)``) is taken as the path.
"""
from __future__ import annotations

import os
from io import BytesIO
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from .errors import InputError

__all__ = ["split_args", "panels", "finish", "view_lines", "mark_uninformative"]


class _ShownFigure(Figure):
    """A figure that a notebook shows as PNG when it is the value of a cell (IPython's
    ``_repr_png_``), without ``pyplot``: shown once, never twice."""

    def _repr_png_(self) -> bytes:
        buf = BytesIO()
        self.savefig(buf, format="png", dpi=100, bbox_inches="tight")
        return buf.getvalue()


def split_args(ax, path):
    """``(ax, path)`` with a path given in the place of ``ax`` moved to ``path``.

    Parameters
    ----------
    ax : Axes, array of Axes, str, Path or None
        What the caller passed first.
    path : str or Path or None

    Returns
    -------
    tuple
        ``(ax, path)``.
    """
    if isinstance(ax, (str, os.PathLike)):
        if path is not None:
            raise InputError(f"plot: two paths given ({ax!r} and {path!r})")
        return None, ax
    return ax, path


def panels(ax, nrows: int, ncols: int, *, figsize, what: str, **subplot_kw):
    """The figure and a ``(nrows, ncols)`` array of axes to draw into.

    Parameters
    ----------
    ax : matplotlib Axes, array of Axes, or None
        The caller's axes (``nrows * ncols`` of them), or None for a new figure.
    nrows, ncols : int
        The panels of the figure.
    figsize : tuple
        Size of a new figure [in].
    what : str
        What is drawn, for the message when ``ax`` has the wrong number of axes.
    **subplot_kw
        Passed to ``Figure.subplots`` for a new figure (``sharex``, ``gridspec_kw``...).

    Returns
    -------
    fig : matplotlib.figure.Figure
    axes : numpy.ndarray of Axes, shape (nrows, ncols)
    """
    if ax is None:
        fig = _ShownFigure(figsize=figsize)
        axes = fig.subplots(nrows, ncols, squeeze=False, **subplot_kw)
        return fig, axes
    axes = np.asarray(ax, dtype=object).ravel()
    if axes.size != nrows * ncols or not all(hasattr(a, "plot") and hasattr(a, "figure") for a in axes):
        raise InputError(f"ax: {what} draws {nrows * ncols} panel(s) ({nrows} x {ncols}); give that many "
                         f"matplotlib axes, or leave ax out for a new figure (got {axes.size})")
    return axes[0].figure, axes.reshape(nrows, ncols)


def finish(fig, ax, path, *, dpi: int = 110, tight: bool = True):
    """Lay out, save when asked, and return what the contract says.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
    ax : Axes, array of Axes, or None
        What the caller passed (returned as given when not None and no path).
    path : str or Path or None
        Where to write the figure.
    dpi : int
    tight : bool
        Apply ``tight_layout`` to a new figure (a caller's figure is left as laid out).

    Returns
    -------
    Figure, the caller's axes, or Path
    """
    if tight and ax is None:
        fig.tight_layout()
    if path is None:
        return fig if ax is None else ax
    path = Path(path)
    fig.savefig(path, dpi=dpi, format=path.suffix[1:].lower() or "png")
    return path


def view_lines(ax, xs, ys, *, min_span: tuple[float, float] = (0.0, 0.0)) -> None:
    """Autoscale ``ax`` to the given lines only, so that a band wider than them is clipped rather than
    scaling the axes until the lines are flat (a prediction band of hundreds of degrees beside a
    heading that stays within ten). The axes keep autoscaling (an equal aspect then adjusts them).

    Parameters
    ----------
    ax : matplotlib Axes
    xs, ys : sequences of arrays
        The lines' coordinates (pairwise); points with a NaN are left out.
    min_span : (float, float)
        The smallest x and y span shown (data units).
    """
    x = np.concatenate([np.asarray(v, dtype=float).ravel() for v in xs]) if len(xs) else np.zeros(0)
    y = np.concatenate([np.asarray(v, dtype=float).ravel() for v in ys]) if len(ys) else np.zeros(0)
    ok = np.isfinite(x) & np.isfinite(y)
    if not ok.any():
        return
    pts = np.column_stack([x[ok], y[ok]])
    centre = 0.5 * (pts.min(axis=0) + pts.max(axis=0))
    half = 0.5 * np.asarray(min_span, dtype=float)
    ax.ignore_existing_data_limits = True
    ax.update_datalim(np.vstack([pts, centre - half, centre + half]))
    ax.autoscale_view()


def mark_uninformative(ax, t, halfwidth, limit: float) -> None:
    """A dotted vertical line where a band's half-width first exceeds ``limit`` (nothing when it
    never does), labelled for the legend.

    Parameters
    ----------
    ax : matplotlib Axes
    t, halfwidth : arrays
        Time and the band's half-width (the unit of ``limit``).
    limit : float
    """
    wide = np.asarray(halfwidth) > limit
    if wide.any():
        ax.axvline(float(np.asarray(t)[int(np.argmax(wide))]), color="0.4", ls=":", lw=1.0,
                   label=f"band wider than +-{limit:g} from here (says nothing)")
