"""Conditional generative models p(q | y) behind one interface, and their registry.

``MODELS`` is their registry (names in the package, ``manifoldgen.models`` entry points of
other packages, ``module:Class``); :func:`load_model` reads any saved model directory
(validated, never unpickled); :func:`pretrained_model_dir` locates the shipped models. The model
classes are imported (with torch) when first named, so listing the names costs nothing.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from manifoldgen.errors import ManifoldgenError, file_reader
from manifoldgen.registry import Registry

if TYPE_CHECKING:
    from manifoldgen.models.base import ConditionalSampler

MODELS: Registry[ConditionalSampler] = Registry("model", "manifoldgen.models.base:ConditionalSampler", {
    "cvae": "manifoldgen.models.cvae:CVAE", "cgan": "manifoldgen.models.cgan:CGAN",
    "wgan": "manifoldgen.models.wgan:WGANGP", "flow": "manifoldgen.models.flow:ConditionalFlow",
    "cfm": "manifoldgen.models.cfm:ConditionalFlowMatching"})
_CLASSES = {"CVAE": "cvae", "CGAN": "cgan", "WGANGP": "wgan", "ConditionalFlow": "flow",
            "ConditionalFlowMatching": "cfm"}


def __getattr__(name: str):
    if name in _CLASSES:
        return MODELS.get(_CLASSES[name])
    if name == "ConditionalSampler":
        return MODELS.base
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def get_model_class(name: str) -> type[ConditionalSampler]:
    """The registered class for ``name`` (clear error with suggestions)."""
    return MODELS.get(name)


@file_reader
def load_model(path: str | Path) -> ConditionalSampler:
    """Load a model directory (model.json + model.safetensors) of any registered model, with its blend partner."""
    from manifoldgen.models.files import read_blend, read_model_dir

    doc, tensors = read_model_dir(path)
    if doc["model"] not in MODELS.names():
        raise ManifoldgenError(f"{path}: unknown model type '{doc['model']}' in model.json; "
                               f"known models: {', '.join(MODELS.names())}")
    model = MODELS.get(doc["model"]).from_files(path, doc, tensors)
    model.blend = read_blend(path, doc, load_model)
    return model


@file_reader
def open_model(path: str | Path):
    """A model directory as the planners use it, without loading torch
    (:class:`manifoldgen.models.files.SavedModel`: its facts, its network in the compiled core)."""
    from manifoldgen.models.files import SavedModel

    saved = SavedModel(path, load_model)
    if saved.name not in MODELS.names():
        raise ManifoldgenError(f"{path}: unknown model type '{saved.name}' in model.json; "
                               f"known models: {', '.join(MODELS.names())}")
    return saved


def pretrained_model_dir(name: str = "panda-pose-cvae") -> Path:
    """Directory of a model shipped with the package (``load_model(pretrained_model_dir())``): ``name`` is the plain
    name of one (a path is refused)."""
    root = Path(__file__).resolve().parent.parent / "data" / "pretrained"
    shipped = sorted(p.name for p in root.glob("*") if (p / "model.json").is_file()) if root.is_dir() else []
    if name not in shipped:
        raise ManifoldgenError(f"no pretrained model '{name}' (a shipped model's plain name, not a path); shipped: "
                               f"{', '.join(shipped) or 'none'}")
    return root / name


__all__ = ["CGAN", "CVAE", "MODELS", "WGANGP", "ConditionalFlow", "ConditionalFlowMatching", "ConditionalSampler",
           "get_model_class", "load_model", "open_model", "pretrained_model_dir"]
