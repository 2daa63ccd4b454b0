"""Conditional generative models p(q | y) behind one interface, and their registry.

``MODELS`` maps names to classes; :func:`load_model` reads any saved model directory
(validated, never unpickled); :func:`pretrained_model_dir` locates the shipped models.
"""

from __future__ import annotations

from pathlib import Path

from manifoldgen.errors import ManifoldgenError, unknown_name
from manifoldgen.models.base import ConditionalSampler, read_model_dir
from manifoldgen.models.cvae import CVAE
from manifoldgen.models.flow import ConditionalFlow
from manifoldgen.models.cgan import CGAN
from manifoldgen.models.wgan import WGANGP

MODELS: dict[str, type[ConditionalSampler]] = {cls.name: cls for cls in (CVAE, CGAN, WGANGP, ConditionalFlow)}


def get_model_class(name: str) -> type[ConditionalSampler]:
    """The registered class for ``name`` (clear error with suggestions)."""
    if name not in MODELS:
        raise unknown_name("model", name, list(MODELS))
    return MODELS[name]


def load_model(path: str | Path) -> ConditionalSampler:
    """Load a model directory (model.json + model.safetensors) of any registered model."""
    doc, tensors = read_model_dir(path)
    if doc["model"] not in MODELS:
        raise ManifoldgenError(f"{path}: unknown model type '{doc['model']}' in model.json; "
                               f"known models: {', '.join(MODELS)}")
    return MODELS[doc["model"]].from_files(path, doc, tensors)


def pretrained_model_dir(name: str = "panda-pose-cvae") -> Path:
    """Directory of a model shipped with the package (``load_model(pretrained_model_dir())``)."""
    root = Path(__file__).resolve().parent.parent / "data" / "pretrained"
    path = root / name
    if not (path / "model.json").is_file():
        shipped = sorted(p.name for p in root.glob("*") if (p / "model.json").is_file()) if root.is_dir() else []
        raise ManifoldgenError(f"no pretrained model '{name}'; shipped: {', '.join(shipped) or 'none'}")
    return path


__all__ = ["CGAN", "CVAE", "MODELS", "WGANGP", "ConditionalFlow", "ConditionalSampler", "get_model_class",
           "load_model", "pretrained_model_dir"]
