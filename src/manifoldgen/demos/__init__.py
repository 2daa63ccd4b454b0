"""``manifoldgen demo NAME``: each demo runs the whole pipeline for one experiment on an embedded default.

A demo is a module here with ``run_demo(output: Path, seed: int, console) -> dict`` (the figures it
printed); ``DEMOS`` maps the demo's name to its module.
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
    return importlib.import_module(DEMOS[name]).run_demo(output, seed, console)
