"""Named model factories, so that the command line and studies can ask for a model by name."""
from __future__ import annotations

import json
from typing import Callable

from ..model import Model

__all__ = ["register", "get_model", "model_names"]

_FACTORIES: dict[str, tuple[Callable[..., Model], str]] = {}


def register(name: str, factory: Callable[..., Model], doc: str) -> None:
    """Register ``factory`` (called without arguments gives the preset) under ``name``."""
    if name in _FACTORIES:
        raise ValueError(f"model name {name!r} is already registered")
    _FACTORIES[name] = (factory, doc)


def get_model(name: str, **options) -> Model:
    """Build the registered model ``name`` (keyword options go to its factory).

    The registry key is the model's name: ``get_model(name).name == name``. Options that JSON can
    hold are recorded in ``model.meta["options"]``, so that a fit or parameter file of the model
    records how to rebuild it (``get_model(name, **model.meta["options"])``).

    Examples
    --------
    >>> get_model("kvlcc2-l7").name
    'kvlcc2-l7'
    """
    try:
        factory = _FACTORIES[name][0]
    except KeyError:
        raise ValueError(f"unknown model {name!r}; known models: {sorted(_FACTORIES)}") from None
    model = factory(**options)
    if model.name != name:
        raise RuntimeError(f"registered model {name!r} builds a model named {model.name!r}; "
                           "register it under its own name")
    if options and "options" not in model.meta:
        try:
            json.dumps(options)
        except (TypeError, ValueError):
            return model
        b = model.builder()
        b.meta["options"] = dict(options)
        model = b.build()
    return model


def model_names() -> dict[str, str]:
    """Mapping name -> one-line description of every registered model."""
    return {k: v[1] for k, v in sorted(_FACTORIES.items())}
