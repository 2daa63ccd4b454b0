"""One registry mechanism for constraints, models and planners.

A :class:`Registry` maps names to classes registered in the package, to classes that
other packages announce through a Python entry point group (``manifoldgen.constraints``,
``manifoldgen.models``, ``manifoldgen.planners``), and resolves ``module:Class`` names
(as task files write a user's own class) by importing the module.
"""

from __future__ import annotations

import importlib
from importlib.metadata import entry_points
from typing import Generic, TypeVar

from manifoldgen.errors import ManifoldgenError, unknown_name

T = TypeVar("T")


class Registry(Generic[T]):
    """Names -> subclasses of ``base`` for one ``kind`` (its entry point group: ``manifoldgen.<kind>s``)."""

    def __init__(self, kind: str, base: type):
        self.kind, self.base = kind, base
        self._classes: dict[str, type[T]] = {}
        self._entry_points_loaded = False

    def register(self, name: str):
        """Class decorator: register under ``name``."""
        def wrap(cls: type[T]) -> type[T]:
            self._classes[name] = cls
            return cls
        return wrap

    def _load_entry_points(self) -> None:
        if self._entry_points_loaded:
            return
        self._entry_points_loaded = True
        for ep in entry_points(group=f"manifoldgen.{self.kind}s"):
            if ep.name not in self._classes:
                self._classes[ep.name] = _require_subclass(ep.load(), self.base, self.kind,
                                                           f"entry point {ep.name} = {ep.value}")

    def names(self) -> list[str]:
        """Every registered name, the package's first."""
        self._load_entry_points()
        return list(self._classes)

    def get(self, name: str) -> type[T]:
        """The class registered as ``name``, or the class ``module:Class`` names."""
        if ":" in name:
            return import_class(name, self.base, self.kind)
        self._load_entry_points()
        if name not in self._classes:
            raise unknown_name(self.kind, name, list(self._classes))
        return self._classes[name]

    def name_of(self, cls: type) -> str:
        """The name ``cls`` is registered under, else its ``module:Class`` path."""
        for name, registered in self._classes.items():
            if registered is cls:
                return name
        return f"{cls.__module__}:{cls.__qualname__}"


def import_class(path: str, base: type, kind: str) -> type:
    """Import ``module:Class`` and check that it subclasses ``base``."""
    module_name, _, attr = path.partition(":")
    if not module_name or not attr:
        raise ManifoldgenError(f"'{path}' is not a {kind} name nor 'module:Class'; write e.g. 'my_module:MyClass'")
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise ManifoldgenError(f"cannot import module '{module_name}' for {kind} '{path}' ({exc}); put it on "
                               "PYTHONPATH or next to the task file") from exc
    obj = module
    for part in attr.split("."):
        obj = getattr(obj, part, None)
        if obj is None:
            raise ManifoldgenError(f"module '{module_name}' has no '{attr}' (for {kind} '{path}'); check the name")
    return _require_subclass(obj, base, kind, f"'{path}'")


def _require_subclass(obj, base: type, kind: str, what: str) -> type:
    if not (isinstance(obj, type) and issubclass(obj, base)):
        raise ManifoldgenError(f"{what} is not a {base.__name__} subclass; a {kind} class must subclass "
                               f"manifoldgen's {base.__name__}")
    return obj
