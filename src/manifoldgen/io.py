"""Atomic file writes and the JSON ``meta`` carried by every .npz file."""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

import numpy as np

from manifoldgen.errors import ManifoldgenError


def _atomic(path: Path, write) -> None:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            write(f)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def atomic_write_text(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file and a rename."""
    _atomic(path, lambda f: f.write(text.encode()))


def atomic_write_bytes(path: Path, data: bytes) -> None:
    _atomic(path, lambda f: f.write(data))


def check_output_path(path: str | Path) -> Path:
    """Refuse an output path whose directory does not exist."""
    path = Path(path)
    if not path.parent.exists():
        raise ManifoldgenError(f"output directory {path.parent} does not exist; create it or choose another path")
    return path


def save_npz(file: str | Path, meta: dict, /, **arrays: np.ndarray) -> None:
    """Atomically write ``arrays`` (any names, ``path`` included) and ``meta`` (a JSON string) to an .npz."""
    _atomic(Path(file), lambda f: np.savez(f, meta=np.array(json.dumps(meta)), **arrays))


def load_npz(path: str | Path, required: tuple[str, ...]) -> tuple[dict, dict[str, np.ndarray]]:
    """Read an .npz written by :func:`save_npz`; clear errors for missing, truncated or foreign files."""
    path = Path(path)
    if not path.is_file():
        raise ManifoldgenError(f"file not found: {path}")
    try:
        with np.load(path, allow_pickle=False) as f:
            arrays = {k: f[k] for k in f.files}
    except Exception as exc:  # zipfile/np raise many types for damaged files
        raise ManifoldgenError(f"{path} is not a readable .npz file ({type(exc).__name__}: {exc}); "
                               "it may be truncated: regenerate it") from exc
    missing = [k for k in ("meta", *required) if k not in arrays]
    if missing:
        raise ManifoldgenError(f"{path} is not a manifoldgen file: missing {', '.join(missing)}")
    try:
        meta = json.loads(str(arrays.pop("meta")))
    except ValueError as exc:
        raise ManifoldgenError(f"{path} has a corrupted meta field: {exc}") from exc
    return meta, arrays
