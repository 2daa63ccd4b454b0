"""One registry mechanism for constraints, models and planners.

A :class:`Registry` maps names to classes registered in the package (by a decorator, or listed as
``module:Class`` paths that are imported only when the name is first used, so listing the names for a
command's ``--help`` imports neither torch nor the compiled core), to classes that other packages announce
through a Python entry point group (``manifoldgen.constraints``, ``manifoldgen.models``,
``manifoldgen.planners``), and resolves ``module:Class`` names (as task files write a user's own class)
by importing the module.
"""

from __future__ import annotations

import functools
import importlib
from typing import Generic, TypeVar

from manifoldgen.errors import ManifoldgenError, unknown_name

T = TypeVar("T")


@functools.cache
def _entry_points():
    """Every installed package's entry points, read once for all the registries (each read scans every package)."""
    from importlib.metadata import entry_points

    return entry_points()


class Registry(Generic[T]):
    """Names -> subclasses of ``base`` (a class, or its ``module:Class`` path) for one ``kind`` (its entry point
    group: ``manifoldgen.<kind>s``); ``built_in``: name -> ``module:Class`` of the package's own classes."""

    def __init__(self, kind: str, base: type | str, built_in: dict[str, str] | None = None):
        self.kind, self._base = kind, base
        self._paths = dict(built_in or {})
        self._classes: dict[str, type[T]] = {}
        self._entry_points: dict | None = None

    @property
    def base(self) -> type:
        if isinstance(self._base, str):
            module, _, attr = self._base.partition(":")
            self._base = getattr(importlib.import_module(module), attr)
        return self._base

    def register(self, name: str):
        """Class decorator: register under ``name``."""
        def wrap(cls: type[T]) -> type[T]:
            self._classes[name] = cls
            return cls
        return wrap

    def _announced(self) -> dict:
        """Other packages' entry points of this group, by name (not loaded)."""
        if self._entry_points is None:
            self._entry_points = {ep.name: ep for ep in _entry_points().select(group=f"manifoldgen.{self.kind}s")}
        return self._entry_points

    def names(self, *, announced: bool = True) -> list[str]:
        """Every registered name, the package's first (nothing is imported); ``announced=False``: without reading
        other packages' entry points (0.05-0.1 s: ``--help`` lists these), so only names already loaded."""
        own = list(self._paths) + [name for name in self._classes if name not in self._paths]
        return own + ([name for name in self._announced() if name not in own] if announced else [])

    def get(self, name: str) -> type[T]:
        """The class registered as ``name``, or the class ``module:Class`` names."""
        if ":" in name:
            return import_class(name, self.base, self.kind)
        if name in self._classes:
            return self._classes[name]
        if name in self._paths:
            self._classes[name] = import_class(self._paths[name], self.base, self.kind)
        elif name in self._announced():
            ep = self._announced()[name]
            self._classes[name] = _require_subclass(ep.load(), self.base, self.kind, f"entry point {name} = {ep.value}")
        else:
            raise unknown_name(self.kind, name, self.names())
        return self._classes[name]

    def name_of(self, cls: type) -> str:
        """The name ``cls`` is registered under, else its ``module:Class`` path."""
        path = f"{cls.__module__}:{cls.__qualname__}"
        for name, registered in self._classes.items():
            if registered is cls:
                return name
        return next((name for name, known in self._paths.items() if known == path), path)


def import_class(path: str, base: type, kind: str) -> type:
    """Import ``module:Class`` and check that it subclasses ``base``."""
    module_name, _, attr = path.partition(":")
    if not module_name or not attr:
        raise ManifoldgenError(f"'{path}' is not a {kind} name nor 'module:Class'; write e.g. 'my_module:MyClass'")
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        missing = isinstance(exc, ModuleNotFoundError) and exc.name is not None \
            and (module_name == exc.name or module_name.startswith(exc.name + "."))
        if not missing:  # the module was found and failed as it ran: the caller names its file and line
            raise
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
