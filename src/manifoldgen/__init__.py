"""manifoldgen: constrained motion planning with learned samplers.

The Python API is this namespace (see ``docs/python-api.md``)::

    import manifoldgen as mg

    task = mg.load_task("pose", robot="panda")
    scene = mg.load_scene(task, "wall")
    result = mg.plan(task, scene, sampler=mg.load_model(mg.pretrained_model_dir()), time_limit=10)
    report = mg.check_path(task, scene, result)

Importing the package is cheap: every name below is resolved on first use (module ``__getattr__``), so
torch, pinocchio and matplotlib load only when a function that needs them runs.
"""

from __future__ import annotations

import importlib

# name -> module that defines it; resolved lazily by __getattr__
_LAZY = {
    "ManifoldgenError": "manifoldgen.errors",
    "Dataset": "manifoldgen.dataset",
    "Task": "manifoldgen.tasks",
    "Scene": "manifoldgen.scene",
    "PathReport": "manifoldgen.space",
    "QueryResult": "manifoldgen.api",
    "builtin_tasks": "manifoldgen.api",
    "load_task": "manifoldgen.api",
    "load_scene": "manifoldgen.api",
    "collect": "manifoldgen.api",
    "train": "manifoldgen.api",
    "load_model": "manifoldgen.api",
    "pretrained_model_dir": "manifoldgen.api",
    "sampler": "manifoldgen.api",
    "plan": "manifoldgen.api",
    "check_path": "manifoldgen.api",
}

__all__ = sorted(_LAZY)


def _version() -> str:
    """The installed distribution's version; in a source tree without one, pyproject.toml's."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("manifoldgen")
    except PackageNotFoundError:
        import tomllib
        from pathlib import Path

        try:
            with open(Path(__file__).resolve().parents[2] / "pyproject.toml", "rb") as f:
                return str(tomllib.load(f)["project"]["version"])
        except (OSError, KeyError, tomllib.TOMLDecodeError):
            return "0+unknown"


def __getattr__(name: str):
    if name == "__version__":
        value = _version()
    elif name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name]), name)
    else:  # AttributeError (not ImportError) keeps `from manifoldgen import submodule` working
        raise AttributeError(f"module 'manifoldgen' has no attribute '{name}'")
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_LAZY, "__version__"})
