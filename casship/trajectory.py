"""Simulated records: :class:`Trajectory`, a :class:`~casship.data.Dataset` that knows which columns
are a model's states, inputs and outputs."""
from __future__ import annotations

from typing import Mapping

import numpy as np

from .data import Dataset

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
            raise ValueError(f"trajectory of {model_name!r} has no column(s) {missing}")
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
            raise ValueError(f"record has no column(s) {missing} for the states/inputs of model {name!r}")
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
            raise ValueError("Trajectory.from_pandas: the frame carries no state names; pass model=")
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
            raise ValueError("Trajectory.from_csv needs model= (a CSV file does not store the state names)")
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
