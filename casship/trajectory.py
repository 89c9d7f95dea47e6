"""Simulated records: :class:`Trajectory`, a :class:`~casship.data.Dataset` that knows which columns
are a model's states, inputs and outputs."""
from __future__ import annotations

from typing import Mapping

import numpy as np

from .data import Dataset
from .errors import InputError

__all__ = ["Trajectory"]


class Trajectory(Dataset):
    """A simulated record: a :class:`Dataset` whose columns include a model's states, inputs, outputs.

    Parameters
    ----------
    t, columns, units, meta
        As for :class:`Dataset`.
    model_name : str
        The model simulated.
    state_names, input_names, output_names : sequence of str
        Which columns are the model's states, inputs and outputs.

    Attributes
    ----------
    model_name : str
    state_names, input_names, output_names : tuple of str
    """

    def __init__(self, t, columns, *, model_name: str, state_names, input_names, output_names,
                 units=None, meta=None):
        super().__init__(t, columns, units, meta)
        missing = [n for n in (*state_names, *input_names, *output_names) if n not in self._columns]
        if missing:
            raise InputError(f"trajectory of {model_name!r} has no column(s) {missing}")
        self.model_name = model_name
        self.state_names = tuple(state_names)
        self.input_names = tuple(input_names)
        self.output_names = tuple(output_names)

    def _names(self) -> dict:
        return {"model_name": self.model_name, "state_names": list(self.state_names),
                "input_names": list(self.input_names), "output_names": list(self.output_names)}

    def slice(self, start: int | None = None, stop: int | None = None) -> "Trajectory":
        """Rows ``start:stop`` as a Trajectory (names kept).

        Parameters
        ----------
        start, stop : int, optional
            Row indices.

        Returns
        -------
        Trajectory
        """
        return Trajectory.from_dataset(super().slice(start, stop), self._names())

    def _like(self, data: Dataset) -> "Trajectory":
        return Trajectory.from_dataset(data, self._names())

    # -- figure ------------------------------------------------------------------------------------
    def plot(self, ax=None, path=None, *, measured: Dataset | None = None, title: str | None = None):
        """The run as a person reads it.

        A ship (a ``psi`` column): its track (North over East, when ``x`` and ``y`` are columns)
        and its heading with the rudder angles, in degrees. Any other model: one panel per state
        (radians drawn in degrees).

        Parameters
        ----------
        ax : matplotlib Axes or sequence of Axes, optional
            Draw into these axes (one per panel) instead of a new figure.
        path : str or Path, optional
            Also write the figure there (PNG unless the suffix says otherwise).
        measured : Dataset, optional
            A record to draw beside the run (its ``x``, ``y``, ``psi``).
        title : str, optional
            Figure title (default: the model's name; not drawn into a caller's axes).

        Returns
        -------
        matplotlib.figure.Figure, the axes given, or Path
            See :mod:`casship.plotting`.

        Examples
        --------
        >>> import casship as cs
        >>> fig = cs.simulate(cs.get_model("nomoto1"), [0.0, 0.0], cs.maneuvers.step(0.1, 10.0, 0.1)).plot()  # doctest: +SKIP
        """
        from .plotting import finish, panels, split_args

        ax, path = split_args(ax, path)
        given = ax
        if "psi" in self:
            track = "x" in self and "y" in self
            fig, axes = panels(ax, 1, 2 if track else 1, figsize=(11 if track else 6.5, 4.5),
                               what=f"the trajectory plot of {self.model_name!r}")
            drawn = list(axes.ravel())
            if track:
                t_ax = drawn.pop(0)
                t_ax.plot(self["y"], self["x"], label="simulated")
                if measured is not None and "x" in measured and "y" in measured:
                    t_ax.plot(measured["y"], measured["x"], "--", label="measured")
                t_ax.set(xlabel="East y [m]", ylabel="North x [m]", title="track")
                t_ax.set_aspect("equal", adjustable="datalim")
                t_ax.legend(fontsize=8)
            h_ax = drawn[0]
            h_ax.plot(self.t, np.degrees(np.unwrap(self["psi"])), label="heading psi")
            if measured is not None and "psi" in measured:
                h_ax.plot(measured.t, np.degrees(np.unwrap(measured["psi"])), "--", label="heading (measured)")
            for name in dict.fromkeys((*self.input_names, *self.state_names)):
                if name.startswith("delta"):
                    h_ax.plot(self.t, np.degrees(self[name]), ":", label=f"{name}")
            h_ax.set(xlabel="t [s]", ylabel="heading, rudder [deg]")
            h_ax.legend(fontsize=8)
        else:
            names = list(self.state_names)
            fig, axes = panels(ax, len(names), 1, figsize=(7.5, 1.8 * len(names) + 0.8),
                               what=f"the trajectory plot of {self.model_name!r} ({len(names)} states)", sharex=True)
            for a, name in zip(axes[:, 0], names):
                unit = self.units.get(name, "") or ""
                base, _, rest = unit.partition("/")
                if base == "rad":
                    a.plot(self.t, np.degrees(self[name]))
                    unit = "deg" + (f"/{rest}" if rest else "")
                else:
                    a.plot(self.t, self[name])
                a.set_ylabel(f"{name} [{unit}]" if unit else name)
            axes[-1, 0].set_xlabel("t [s]")
        for a in np.ravel(axes):
            a.grid(True, alpha=0.3)
        if given is None:
            fig.suptitle(self.model_name if title is None else title)
        return finish(fig, given, path)

    # -- I/O with the names kept -----------------------------------------------------------------
    def to_pandas(self):
        """A DataFrame with ``t`` and all columns; the model and variable names go to ``frame.attrs``."""
        frame = super().to_pandas()
        frame.attrs.update(self._names())
        return frame

    @classmethod
    def from_dataset(cls, data: Dataset, model) -> "Trajectory":
        """View a record with a column for every state and input of ``model`` as a Trajectory.

        ``model`` is a :class:`~casship.Model` or a mapping with ``state_names``, ``input_names``,
        ``output_names`` (and optionally ``model_name``), e.g. the ``attrs`` of :meth:`to_pandas`.

        Parameters
        ----------
        data : Dataset
            The record.
        model : Model or mapping
            See above.

        Returns
        -------
        Trajectory
        """
        get = (lambda k: model.get(k, ())) if isinstance(model, Mapping) else (lambda k: getattr(model, k))
        names = {k: tuple(get(k)) for k in ("state_names", "input_names", "output_names")}
        name = model.get("model_name", "") if isinstance(model, Mapping) else model.name
        missing = [n for n in (*names["state_names"], *names["input_names"]) if n not in data]
        if missing:
            raise InputError(f"record has no column(s) {missing} for the states/inputs of model {name!r}")
        outputs = tuple(n for n in names["output_names"] if n in data)
        return cls(data.t, {n: data[n] for n in data.names}, model_name=name, state_names=names["state_names"],
                   input_names=names["input_names"], output_names=outputs, units=data.units, meta=data.meta)

    @classmethod
    def from_pandas(cls, frame, time: str = "t", units: Mapping[str, str] | None = None,
                    model=None) -> "Trajectory":
        """Inverse of :meth:`to_pandas`; names from ``model`` or else from ``frame.attrs``.

        Parameters
        ----------
        frame : pandas.DataFrame
            As written by :meth:`to_pandas`.
        time : str
            Time column.
        units : mapping, optional
            Column -> unit.
        model : Model, optional
            Names of states, inputs and outputs (default: ``frame.attrs``).

        Returns
        -------
        Trajectory
        """
        source = model if model is not None else frame.attrs
        if model is None and "state_names" not in frame.attrs:
            raise InputError("Trajectory.from_pandas: the frame carries no state names; pass model=")
        return cls.from_dataset(Dataset.from_pandas(frame, time, units), source)

    @classmethod
    def from_csv(cls, path, model=None, time: str | None = None, rename: Mapping[str, str] | None = None,
                 scale: Mapping[str, float] | None = None) -> "Trajectory":
        """Read a CSV written by :meth:`Dataset.to_csv`; ``model`` names the states, inputs and outputs.

        Parameters
        ----------
        path : str or Path
            The file.
        model : Model or mapping
            Names of states, inputs and outputs.
        time, rename, scale
            As for :meth:`Dataset.from_csv`.

        Returns
        -------
        Trajectory
        """
        if model is None:
            raise InputError("Trajectory.from_csv needs model= (a CSV file does not store the state names)")
        return cls.from_dataset(Dataset.from_csv(path, time=time, rename=rename, scale=scale), model)

    @property
    def x(self) -> np.ndarray:
        """States as an (N, nx) array."""
        return self.matrix(self.state_names)

    @property
    def u(self) -> np.ndarray:
        """Inputs as an (N, nu) array.

        Returns
        -------
        numpy.ndarray
        """
        return self.matrix(self.input_names)

    @property
    def y(self) -> np.ndarray:
        """Outputs as an (N, ny) array.

        Returns
        -------
        numpy.ndarray
        """
        return self.matrix(self.output_names)
