"""The package's modules form layers (docs/architecture.md): a module imports only from its own layer or those
below, and no imports go round in a circle. Every ``import`` and ``from ... import`` in a module counts, at
the top, inside functions and under ``if TYPE_CHECKING:`` alike; the graph is read from the source with
``ast``, nothing is imported."""

from __future__ import annotations

import ast
import functools
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "src" / "manifoldgen"

# Bottom to top. A name covers the module and everything under it (a package); the longest name that covers a
# module decides its layer; "" is the package's own __init__ (the `mg` namespace).
LAYERS = [
    ("base", ["errors", "io", "json_values", "registry", "runtime", "settings", "progress", "cluster"]),
    ("geometry and kinematics", ["robot", "collision", "spheres", "shapes"]),
    ("constraints", ["constraints", "provenance"]),
    ("space", ["space"]),
    ("compiled core", ["constraint_callbacks", "core_extension", "core_terms", "native", "targets"]),
    ("learning", ["coverage", "metrics", "dataset", "sampling", "training"]),
    ("planning", ["planning"]),
    ("problem", ["tasks", "scene"]),
    ("models", ["models"]),
    ("pipeline", ["data", "specs", "query", "selection", "model_sweep", "stability", "trajectory", "physics", "ompl_settings",
                  "ompl_bridge", "ompl_native", "api"]),
    ("front ends", ["bench", "viz", "viewer", "demos", "cli_common", "cli_view", "cli", ""]),
]


@functools.cache
def modules() -> dict[str, tuple[Path, bool]]:
    """Module name -> (file, whether it is a package's ``__init__``)."""
    found = {}
    for file in PACKAGE.rglob("*.py"):
        parts = ["manifoldgen", *file.relative_to(PACKAGE).with_suffix("").parts]
        package = parts[-1] == "__init__"
        found[".".join(parts[:-1] if package else parts)] = (file, package)
    return found


@functools.cache
def imports() -> dict[tuple[str, str], list[str]]:
    """(importer, imported module) -> ``'file:line'`` of each import statement that makes the edge."""
    known = modules()

    def resolve(name: str) -> str | None:
        while name and name not in known:
            name = name.rpartition(".")[0]
        return name or None

    edges: dict[tuple[str, str], list[str]] = {}
    for module, (file, package) in known.items():
        here = module if package else module.rpartition(".")[0]
        for node in ast.walk(ast.parse(file.read_text(), str(file))):
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    anchor = here.split(".")[:len(here.split(".")) - node.level + 1]
                    base = ".".join(anchor + ([node.module] if node.module else []))
                targets = [f"{base}.{alias.name}" if f"{base}.{alias.name}" in known else base for alias in node.names]
            else:
                continue
            for imported in sorted({resolve(t) for t in targets if t.split(".")[0] == "manifoldgen"} - {None, module}):
                edges.setdefault((module, imported), []).append(f"{file.relative_to(PACKAGE.parent)}:{node.lineno}")
    return edges


def layer_of(module: str) -> int:
    """The index in :data:`LAYERS` of the longest name covering ``module`` (-1: none does)."""
    best, found = -1, -1
    for index, (_, names) in enumerate(LAYERS):
        for name in names:
            full = f"manifoldgen.{name}" if name else "manifoldgen"
            if (module == full or (name and module.startswith(full + "."))) and len(full) > best:
                best, found = len(full), index
    return found


def circles(nodes: list[str], edges: set[tuple[str, str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    after: dict[str, list[str]] = {node: [] for node in nodes}
    for a, b in edges:
        after[a].append(b)
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    found: list[list[str]] = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        for nxt in after[node]:
            if nxt not in index:
                visit(nxt)
                low[node] = min(low[node], low[nxt])
            elif nxt in stack:
                low[node] = min(low[node], index[nxt])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for node in nodes:
        if node not in index:
            visit(node)
    return found


def test_the_layer_table_names_each_module_once():
    names = [name for _, group in LAYERS for name in group]
    assert len(names) == len(set(names)), sorted(n for n in names if names.count(n) > 1)
    known = modules()
    missing = [name for name in names if name and f"manifoldgen.{name}" not in known]
    assert not missing, f"LAYERS names modules that do not exist: {missing}"
    unplaced = sorted(module for module in known if layer_of(module) < 0)
    assert not unplaced, f"modules in no layer (add them to LAYERS and docs/architecture.md): {unplaced}"


def test_no_module_imports_from_a_higher_layer():
    edges = imports()
    upward = []
    for (a, b), where in sorted(edges.items()):
        if layer_of(b) > layer_of(a):
            upward.append(f"{a} ({LAYERS[layer_of(a)][0]}) -> {b} ({LAYERS[layer_of(b)][0]}) at {', '.join(where)}")
    assert not upward, "imports from a higher layer (see docs/architecture.md):\n" + "\n".join(upward)


def test_no_imports_go_round_in_a_circle():
    edges = imports()
    found = circles(sorted(modules()), set(edges))
    lines = [f"{' <-> '.join(group)}: " + "; ".join(f"{a} -> {b} at {', '.join(edges[a, b])}"
                                                  for a, b in sorted(edges) if a in group and b in group)
             for group in found]
    assert not found, "import circles:\n" + "\n".join(lines)
