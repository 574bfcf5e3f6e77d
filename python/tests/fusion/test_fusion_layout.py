"""The fusion package's shape: files of one concept, under 700 lines, and imports that point one way."""

from __future__ import annotations

import ast
from pathlib import Path

import scattertrack.fusion

PACKAGE = Path(scattertrack.fusion.__file__).parent


def _imports(path: Path) -> set[str]:
    """The ``scattertrack`` modules a file imports (``from scattertrack.fusion import x`` as ``scattertrack.fusion.x``)."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names if alias.name.startswith("scattertrack"))
        elif isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("scattertrack"):
            for alias in node.names:
                child = f"{node.module}.{alias.name}"
                found.add(child if (PACKAGE.parent / (child.split(".", 1)[1].replace(".", "/") + ".py")).is_file() else node.module)
    return found


def test_every_file_is_under_700_lines():
    lengths = {path.name: len(path.read_text().splitlines()) for path in PACKAGE.glob("*.py")}
    assert max(lengths.values()) < 700, lengths


def test_the_modules_import_each_other_without_a_cycle_and_nothing_above_them():
    modules = {f"scattertrack.fusion.{p.stem}": p for p in PACKAGE.glob("*.py") if p.stem != "__init__"}
    edges = {name: {m for m in _imports(path) if m in modules} for name, path in modules.items()}
    for path in PACKAGE.glob("*.py"):
        for imported in _imports(path):
            assert not imported.startswith(("scattertrack.track", "scattertrack.cli")), (path.name, imported)
    # Depth-first search for a back edge.
    state: dict[str, int] = {}

    def visit(name: str, trail: list[str]) -> None:
        state[name] = 1
        for other in edges[name]:
            assert state.get(other) != 1, " -> ".join([*trail, name, other])
            if other not in state:
                visit(other, [*trail, name])
        state[name] = 2

    for name in modules:
        if name not in state:
            visit(name, [])
