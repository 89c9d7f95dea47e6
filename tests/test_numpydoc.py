"""Every public function and class of casship has a numpydoc docstring documenting its parameters.

Public means: listed in the module's ``__all__`` (or, without one, a name not starting with ``_``
defined in that module), in every module of the package except the command line (``casship.cli``,
whose functions are not an API). For each such function, class and public method:

* a docstring exists;
* every parameter of the signature (``self``/``cls`` and names starting with ``_`` aside; ``*args``
  and ``**kwargs`` as ``*args``/``**kwargs``) is documented in a numpydoc ``Parameters`` (or ``Other
  Parameters``) section; a class documents its constructor's parameters in the class docstring.

``ALLOWED`` lists today's offenders. It only shrinks: an entry that no longer offends fails the test
(remove it), and a new offender fails it too. The idea follows python-control's docstring test.
"""
from __future__ import annotations

import importlib
import inspect
import pkgutil
import warnings


import casship
from numpydoc import docscrape as numpydoc_docscrape

SKIP_PACKAGES = ("casship.cli", "casship.__main__")

# Current offenders ("module.qualname"). Fix one, then delete its line here.
ALLOWED = frozenset()


def _modules():
    for info in pkgutil.walk_packages(casship.__path__, "casship."):
        name = info.name
        if name.startswith(SKIP_PACKAGES) or any(part.startswith("_") for part in name.split(".")[1:]):
            continue
        with warnings.catch_warnings():         # the former module paths warn that they moved
            warnings.filterwarnings("ignore", r"casship\.\w+ is deprecated", DeprecationWarning)
            module = importlib.import_module(name)
        yield module


def _public(module):
    names = getattr(module, "__all__", None)
    if names is None:
        names = [n for n in vars(module) if not n.startswith("_")]
    for name in names:
        obj = getattr(module, name, None)
        if (inspect.isfunction(obj) or inspect.isclass(obj)) and getattr(obj, "__module__", "") == module.__name__:
            yield name, obj


def _documented(doc) -> set[str]:
    names = set()
    for section in ("Parameters", "Other Parameters"):
        for par in doc[section]:
            for part in par.name.split(","):
                names.add(part.strip().lstrip("*") if part.strip().startswith("*") else part.strip())
    return names


def _wanted(func, skip_first: bool) -> list[str]:
    try:
        sig = inspect.signature(func)
    except (TypeError, ValueError):
        return []
    params = list(sig.parameters.values())
    if skip_first and params:
        params = params[1:]
    return [p.name for p in params if not p.name.startswith("_")]


def _problems(obj, doc_cls, skip_first: bool, doc_text=None) -> list[str]:
    text = inspect.getdoc(obj) if doc_text is None else doc_text
    if not text or not text.strip():
        return ["no docstring"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            doc = numpydoc_docscrape.NumpyDocString(text)
        except Exception as exc:   # numpydoc raises on malformed sections
            return [f"docstring does not parse as numpydoc ({exc})"]
    wanted = _wanted(obj if doc_cls is None else doc_cls, skip_first)
    missing = [n for n in wanted if n not in _documented(doc)]
    if missing:
        return [f"parameter(s) {missing} not in a Parameters section"]
    return []


def _class_problems(cls) -> dict[str, list[str]]:
    out = {}
    init = cls.__dict__.get("__init__")
    if init is not None or "__dataclass_fields__" in cls.__dict__:
        # constructor parameters belong in the class docstring (or, failing that, __init__'s)
        text = inspect.getdoc(cls) or ""
        if init is not None and inspect.getdoc(init) and "Parameters" not in text:
            text = inspect.getdoc(init)
        problems = _problems(cls, cls, skip_first=False, doc_text=text)
    else:
        problems = [] if (inspect.getdoc(cls) or "").strip() else ["no docstring"]
    if problems:
        out[cls.__qualname__] = problems
    for name, member in vars(cls).items():
        if name.startswith("_"):
            continue
        if isinstance(member, (staticmethod, classmethod)):
            func, skip = member.__func__, isinstance(member, classmethod)
        elif inspect.isfunction(member):
            func, skip = member, True
        elif isinstance(member, property):
            if not (member.__doc__ or "").strip():
                out[f"{cls.__qualname__}.{name}"] = ["no docstring"]
            continue
        else:
            continue
        problems = _problems(func, None, skip_first=skip)
        if problems:
            out[f"{cls.__qualname__}.{name}"] = problems
    return out


def offenders() -> dict[str, list[str]]:
    """Mapping ``module.qualname`` -> problems, over every public function, class and method."""
    found = {}
    for module in _modules():
        for name, obj in _public(module):
            if inspect.isclass(obj):
                for qual, problems in _class_problems(obj).items():
                    found[f"{module.__name__}.{qual}"] = problems
            else:
                problems = _problems(obj, None, skip_first=False)
                if problems:
                    found[f"{module.__name__}.{name}"] = problems
    return found


def test_public_api_has_numpydoc_parameters():
    found = offenders()
    new = {k: v for k, v in found.items() if k not in ALLOWED}
    fixed = sorted(ALLOWED - set(found))
    lines = [f"{k}: {'; '.join(v)}" for k, v in sorted(new.items())]
    assert not new, "public API without a numpydoc Parameters section:\n" + "\n".join(lines)
    assert not fixed, "fixed, now remove from ALLOWED in tests/test_numpydoc.py:\n" + "\n".join(fixed)


def test_checker_catches_a_missing_parameter():
    def documented(a, b):
        """Add.

        Parameters
        ----------
        a, b : float
            Terms.
        """

    def half(a, b):
        """Add.

        Parameters
        ----------
        a : float
            First term.
        """

    assert _problems(documented, None, skip_first=False) == []
    assert _problems(half, None, skip_first=False) == ["parameter(s) ['b'] not in a Parameters section"]
    assert _problems(lambda x: x, None, skip_first=False) == ["no docstring"]
