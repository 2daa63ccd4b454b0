"""``manifoldgen demo NAME``: each demo runs the whole pipeline for one experiment on an embedded default.

A demo is a module here with ``run_demo(output: Path, seed: int, console) -> dict`` (the figures it
printed) and ``OUTPUTS``, the names it writes in ``output`` (folders end in ``/``); ``DEMOS`` maps the demo's name
to its module.
"""

from __future__ import annotations

import importlib
from pathlib import Path

from rich.console import Console

from manifoldgen.errors import ManifoldgenError

DEMOS = {"pose": "manifoldgen.demos.pose", "dualarm": "manifoldgen.demos.dualarm",
         "balance": "manifoldgen.demos.balance"}


def run(name: str, output: Path, seed: int, console: Console) -> dict:
    """Run the demo ``name`` into ``output``; returns its figures."""
    if name not in DEMOS:
        raise ManifoldgenError(f"no demo named '{name}'; choose one of {', '.join(DEMOS)}")
    demo = importlib.import_module(DEMOS[name])
    for entry in demo.OUTPUTS:  # before any work: a file where the demo writes a folder, or the other way round
        path, folder = output / entry.rstrip("/"), entry.endswith("/")
        if path.exists() and path.is_dir() != folder:
            raise ManifoldgenError(f"-o {output} holds {'a file' if folder else 'a folder'} {path.name} where the "
                                   f"{name} demo writes its {'folder' if folder else 'file'}; move or delete it, or "
                                   "give another -o")
    return demo.run_demo(output, seed, console)
