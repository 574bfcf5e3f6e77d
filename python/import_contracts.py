"""Import Linter contract types of this project (configured in pyproject.toml, ``[tool.importlinter]``).

Not part of the ``scattertrack`` package: ``lint-imports`` (run from
``python/`` by ``make test-layers``) loads it from its working directory.

``module_acyclic``
    No import cycle between any two modules of the package, at any depth.
    The built-in ``acyclic_siblings`` contract compares siblings (children
    of one package, each with its descendants squashed), so it cannot see a
    cycle through a package's own ``__init__`` (``locate.rssi`` importing
    ``locate``, which imports ``locate.rssi``); this contract works on the
    module graph itself. Imports inside functions and under
    ``TYPE_CHECKING`` are edges too: grimp records both, and such an import
    still runs, so it still ties the two modules together.
"""

from __future__ import annotations

from grimp import ImportGraph
from importlinter import Contract, ContractCheck, fields, output
from importlinter.application import contract_utils
from importlinter.application.contract_utils import AlertLevel


def strongly_connected(graph: ImportGraph, modules: set[str]) -> list[list[str]]:
    """The import cycles: every strongly connected set of two or more modules (Tarjan, iterative), sorted."""
    successors = {m: sorted(graph.find_modules_directly_imported_by(m) & modules) for m in modules}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    cycles: list[list[str]] = []
    for root in sorted(modules):
        if root in index:
            continue
        work = [(root, 0)]
        while work:
            node, position = work.pop()
            if position == 0:
                index[node] = low[node] = len(index)
                stack.append(node)
                on_stack.add(node)
            children = successors[node]
            if position < len(children):
                work.append((node, position + 1))
                child = children[position]
                if child not in index:
                    work.append((child, 0))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1:
                    cycles.append(sorted(component))
            if work:
                parent = work[-1][0]
                low[parent] = min(low[parent], low[node])
    return sorted(cycles)


class ModuleAcyclicContract(Contract):
    """No two modules under ``containers`` import each other, directly or through others."""

    type_name = "module_acyclic"

    containers = fields.ListField(subfield=fields.StringField())
    ignore_imports = fields.SetField(subfield=fields.ImportExpressionField(), required=False)

    def check(self, graph: ImportGraph, verbose: bool) -> ContractCheck:
        removal = contract_utils.remove_ignored_imports_and_report(
            graph=graph, ignore_imports=self.ignore_imports, unmatched_alerting=AlertLevel.ERROR  # type: ignore[attr-defined]
        )
        modules: set[str] = set()
        for container in self.containers:  # type: ignore[attr-defined]
            modules |= {container} | graph.find_descendants(container)
        cycles = strongly_connected(graph, modules)
        edges = [
            [(importer, imported, [d["line_number"] for d in graph.get_import_details(importer=importer, imported=imported)])
             for importer in cycle for imported in sorted(graph.find_modules_directly_imported_by(importer) & set(cycle))]
            for cycle in cycles
        ]
        return ContractCheck(
            kept=not cycles,
            warnings=list(removal.warnings),
            ignored_import_count=removal.ignored_import_count,
            metadata={"cycles": cycles, "edges": edges},
        )

    def render_broken_contract(self, check: ContractCheck) -> None:
        for cycle, edges in zip(check.metadata["cycles"], check.metadata["edges"]):
            output.print_error(f"Import cycle through {len(cycle)} modules: {', '.join(cycle)}")
            for importer, imported, lines in edges:
                output.print_error(f"    {importer} -> {imported} (l.{', '.join(map(str, lines))})", bold=False)
            output.new_line()
