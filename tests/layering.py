"""The import graph of a package, read from its source: what ``tests/test_layers.py`` checks
and the measurements of docs/architecture.md use.

Every ``import`` and ``from ... import`` statement counts, wherever it stands: at module
level, inside a function (an import deferred to keep start-up light is still a
dependency), under ``if TYPE_CHECKING:`` (a type is knowledge of the module that defines
it). Relative imports are resolved. A package's *units* are its top-level subpackages and
modules (``groundstation/flight/`` is the unit ``flight``, ``groundstation/types.py`` the
unit ``types``); the package's own ``__init__`` is its root.
"""

from __future__ import annotations

import ast
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

ROOT_UNIT = ""
"""The unit of the package's own ``__init__`` (the version and the layer order)."""


def module_names(package: Path) -> dict[str, Path]:
    """Every module of ``package`` (a directory) by its dotted name."""
    out: dict[str, Path] = {}
    for path in sorted(package.rglob("*.py")):
        parts = list(path.relative_to(package.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def _resolve(name: str, modules: Mapping[str, Path]) -> str | None:
    """The module ``name`` is, or the package it is in (an attribute import)."""
    while name and name not in modules:
        name = name.rpartition(".")[0]
    return name or None


def imports_of(module: str, path: Path, modules: Mapping[str, Path]) -> set[str]:
    """The modules of the package that ``module`` (at ``path``) imports, anywhere in it."""
    top = module.split(".")[0]
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    is_package = path.name == "__init__.py"
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] == top:
                    found.add(_resolve(alias.name, modules) or "")
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = module.split(".")[: None if is_package else -1]
                base = base[: len(base) - (node.level - 1)]
                name = ".".join([*base, *([node.module] if node.module else [])])
            else:
                name = node.module or ""
            if name.split(".")[0] != top:
                continue
            for alias in node.names:
                full = f"{name}.{alias.name}"
                found.add(full if full in modules else _resolve(name, modules) or "")
    found.discard("")
    found.discard(module)
    return found


def import_graph(package: Path) -> dict[str, set[str]]:
    """Module -> the package's modules it imports."""
    modules = module_names(package)
    return {name: imports_of(name, path, modules) for name, path in modules.items()}


def unit_of(module: str) -> str:
    """The unit (top-level subpackage or module) a module belongs to; ROOT_UNIT for the
    package's own ``__init__``."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ROOT_UNIT


def units(package: Path) -> set[str]:
    """The package's units, from its layout: each top-level subpackage and module."""
    out = {p.name for p in package.iterdir() if p.is_dir() and (p / "__init__.py").exists()}
    out |= {p.stem for p in package.glob("*.py") if p.name != "__init__.py"}
    return out


def cycles(graph: Mapping[str, Iterable[str]]) -> list[list[str]]:
    """The import cycles: every strongly connected set of more than one node (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for child in sorted(graph.get(node, ())):
            if child not in index:
                visit(child)
                low[node] = min(low[node], low[child])
            elif child in on_stack:
                low[node] = min(low[node], index[child])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return sorted(found)


@dataclass(frozen=True)
class Violation:
    """An import that does not go down the layers: ``importer`` (layer ``from_layer``)
    imports ``imported`` (layer ``to_layer``); ``beside`` when both stand in one layer."""

    importer: str
    imported: str
    from_layer: int
    to_layer: int

    @property
    def beside(self) -> bool:
        """The two units are peers in one layer (neither may know the other)."""
        return self.from_layer == self.to_layer

    def __str__(self) -> str:
        where = "beside it" if self.beside else "above it"
        return (f"{self.importer} (layer {self.from_layer}) imports {self.imported} "
                f"(layer {self.to_layer}, {where})")


def layer_index(layers: Iterable[Iterable[str]]) -> dict[str, int]:
    """Unit -> its layer's position in ``layers`` (bottom first)."""
    return {unit: i for i, layer in enumerate(layers) for unit in layer}


def violations(graph: Mapping[str, Iterable[str]],
               layers: Iterable[Iterable[str]]) -> list[Violation]:
    """Every import from one unit to another that does not go strictly down ``layers``.
    The package's root (its ``__init__``) stands below every layer; a module of a unit
    that ``layers`` does not place is reported against layer -1."""
    where = layer_index(layers)
    out = []
    for importer, imported in sorted((a, b) for a, bs in graph.items() for b in bs):
        src, dst = unit_of(importer), unit_of(imported)
        if src == dst or dst == ROOT_UNIT:
            continue
        i, j = where.get(src, -1), where.get(dst, -1)
        if src == ROOT_UNIT or j >= i:
            out.append(Violation(importer, imported, i, j))
    return out
