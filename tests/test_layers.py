"""Layers you can draw: every import goes down, and nothing imports in a circle.

The package's layout gives the units (each top-level subpackage and module of
``groundstation/``); ``groundstation.LAYERS`` stands them in layers, bottom first; the
layer of every module is its unit's. A module may import its own unit and any unit of a
lower layer: never one above (a layer that knew what stands on it could not be drawn)
and never a peer beside it in the same layer (peers know nothing of each other; what
joins them stands above both). No module imports in a circle. The import graph is read
from the source (:mod:`layering`): imports inside functions and under ``TYPE_CHECKING``
count as well. docs/architecture.md draws the same layers.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from layering import ROOT_UNIT, cycles, import_graph, units, violations

import groundstation

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "groundstation"


@pytest.fixture(scope="module")
def graph() -> dict[str, set[str]]:
    return import_graph(PACKAGE)


def test_every_unit_of_the_layout_stands_in_exactly_one_layer() -> None:
    placed = [unit for layer in groundstation.LAYERS for unit in layer]
    assert len(placed) == len(set(placed)), "a unit placed twice"
    assert set(placed) == units(PACKAGE), (
        f"not in a layer: {sorted(units(PACKAGE) - set(placed))}; "
        f"in a layer but not in the layout: {sorted(set(placed) - units(PACKAGE))}")


def test_no_module_imports_a_layer_above_its_own_or_a_peer_beside_it(
        graph: dict[str, set[str]]) -> None:
    found = [str(v) for v in violations(graph, groundstation.LAYERS)]
    assert found == []


def test_no_module_imports_in_a_circle(graph: dict[str, set[str]]) -> None:
    assert cycles(graph) == []


def test_the_root_imports_nothing_of_the_package(graph: dict[str, set[str]]) -> None:
    """``groundstation/__init__.py`` holds the version and the layers; everything may
    import it, so it may import nothing."""
    assert graph["groundstation"] == set()
    assert all(ROOT_UNIT not in layer for layer in groundstation.LAYERS)


def test_the_architecture_document_draws_the_same_layers() -> None:
    """docs/architecture.md's layer table names every layer's units, in the same order."""
    text = (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")
    rows = [line for line in text.splitlines() if line.startswith("| ") and "`" in line]
    drawn = [sorted(cell.strip("` ") for cell in row.split("|")[2].split(",") if cell.strip())
             for row in rows if row.split("|")[1].strip().isdigit()]
    assert drawn == [sorted(layer) for layer in reversed(groundstation.LAYERS)]


# --------------------------------------------------------------------------- the checker
def _package(tmp_path: Path, files: dict[str, str]) -> Path:
    package = tmp_path / "pkg"
    for name, text in {"__init__.py": "", **files}.items():
        path = package / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
    return package


def test_the_scan_sees_every_form_of_import(tmp_path: Path) -> None:
    """Top-level, inside a function, under TYPE_CHECKING, relative, and an attribute
    import of a module."""
    package = _package(tmp_path, {
        "low/__init__.py": "", "low/a.py": "", "low/b.py": "", "low/c.py": "",
        "low/d.py": "", "high.py": (
            "from typing import TYPE_CHECKING\n"
            "import pkg.low.a\n"
            "if TYPE_CHECKING:\n    from pkg.low import b\n"
            "def f():\n    from .low.c import x\n"
            "from pkg.low import d as e\n")})
    graph = import_graph(package)
    assert graph["pkg.high"] == {"pkg.low.a", "pkg.low.b", "pkg.low.c", "pkg.low.d"}


def test_the_checker_finds_an_upward_import_a_peer_and_a_cycle(tmp_path: Path) -> None:
    package = _package(tmp_path, {
        "base.py": "def f():\n    import pkg.top\n",  # deferred, still upward
        "left.py": "import pkg.base\nfrom pkg import right\n",  # a peer
        "right.py": "import pkg.base\n",
        "top/__init__.py": "", "top/a.py": "from pkg.top import b\n",
        "top/b.py": "from . import a\n"})  # a cycle inside one unit
    graph = import_graph(package)
    layers = (("base",), ("left", "right"), ("top",))
    found = {(v.importer, v.imported, v.beside) for v in violations(graph, layers)}
    assert found == {("pkg.base", "pkg.top", False), ("pkg.left", "pkg.right", True)}
    assert cycles(graph) == [["pkg.top.a", "pkg.top.b"]]
    assert units(package) == {"base", "left", "right", "top"}
