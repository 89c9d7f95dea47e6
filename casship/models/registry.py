"""Named model factories, so that the command line and studies can ask for a model by name."""
from __future__ import annotations

import json
from typing import Callable

from ..model import Model
from ..errors import InputError

__all__ = ["register", "get_model", "model_names"]

_FACTORIES: dict[str, tuple[Callable[..., Model], str]] = {}


def register(name: str, factory: Callable[..., Model], doc: str) -> None:
    """Register ``factory`` (called without arguments gives the preset) under ``name``.

    Parameters
    ----------
    name : str
        The registry key; it must be the name of the model the factory builds (:func:`get_model`
        checks this) and not be registered yet.
    factory : callable
        ``factory(**options) -> Model``; called without arguments it builds the preset.
    doc : str
        One-line description, listed by :func:`model_names` (and ``casship simulate --list``).

    Raises
    ------
    ValueError
        If ``name`` is already registered.

    Examples
    --------
    >>> from casship.models import nomoto_first_order
    >>> register("nomoto1", nomoto_first_order, "first-order Nomoto model")
    Traceback (most recent call last):
    ...
    ValueError: model name 'nomoto1' is already registered
    """
    if name in _FACTORIES:
        raise InputError(f"model name {name!r} is already registered")
    _FACTORIES[name] = (factory, doc)


def get_model(name: str, **options) -> Model:
    """Build the registered model ``name`` (keyword options go to its factory).

    The registry key is the model's name: ``get_model(name).name == name``. Options that JSON can
    hold are recorded in ``model.meta["options"]``, so that a fit or parameter file of the model
    records how to rebuild it (``get_model(name, **model.meta["options"])``).

    Parameters
    ----------
    name : str
        A registered model name (see :func:`model_names`).
    **options
        Keyword arguments of the model's factory (e.g. ``rudder_bias=True`` for ``nomoto1``).

    Returns
    -------
    Model
        The model, named ``name``.

    Raises
    ------
    ValueError
        If ``name`` is not registered (the message lists the known names).
    RuntimeError
        If the registered factory builds a model with another name.

    Examples
    --------
    >>> get_model("kvlcc2-l7").name
    'kvlcc2-l7'
    >>> get_model("nomoto1", rudder_bias=True).meta["options"]
    {'rudder_bias': True}
    """
    try:
        factory = _FACTORIES[name][0]
    except KeyError:
        raise InputError(f"unknown model {name!r}; known models: {sorted(_FACTORIES)}") from None
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
