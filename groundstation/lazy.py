"""Re-exports that load on first use (PEP 562).

A package's ``__init__`` names what its modules define for the reader and the type checker
under ``if TYPE_CHECKING:``, and imports each module only when one of its names is first
asked for. So ``import groundstation.model`` (the configuration does, for the vehicle's
defaults) does not load scipy, reading a flight log does not load the flight, and ``gs
status`` or ``gs --help`` does not load the controllers, the estimator or the virtual lab: a
`gs` start-up loads what its command uses. Used by ``model``, ``estimation``, ``control``,
``flight``, ``app`` and ``sim_device``.

In a package's ``__init__``::

    from typing import TYPE_CHECKING

    from groundstation.lazy import reexports

    if TYPE_CHECKING:  # the names, imported from their modules on first use
        from groundstation.model.linear import LinearModel, hover_model

    __all__ = ["LinearModel", "hover_model"]

    if not TYPE_CHECKING:
        __getattr__ = reexports(__name__)

The ``from ... import`` statements of that block are the one list of the names (read from
the package's source, once): a name is always where its statement says.
"""

from __future__ import annotations

import ast
import importlib
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

__all__ = ["reexports"]


def _homes(source: str) -> dict[str, tuple[str, str]]:
    """name -> (module, name there) for each ``from X import Y [as Z]`` of the module-level
    ``if TYPE_CHECKING:`` blocks in ``source``."""
    homes: dict[str, tuple[str, str]] = {}
    for node in ast.parse(source).body:
        if not (isinstance(node, ast.If) and isinstance(node.test, ast.Name)
                and node.test.id == "TYPE_CHECKING"):
            continue
        for statement in node.body:
            if isinstance(statement, ast.ImportFrom) and statement.module \
                    and statement.level == 0:
                for alias in statement.names:
                    homes[alias.asname or alias.name] = (statement.module, alias.name)
    return homes


def reexports(package: str) -> Callable[[str], Any]:
    """The module ``__getattr__`` of ``package`` (an imported package's ``__name__``): each
    name its ``__init__`` imports under ``if TYPE_CHECKING:`` comes from its module on first
    use, and is then kept in the package (later uses do not come back here)."""
    namespace = sys.modules[package].__dict__
    homes = _homes(Path(namespace["__file__"]).read_text(encoding="utf-8"))

    def load(name: str) -> Any:
        home = homes.get(name)
        if home is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(home[0]), home[1])
        namespace[name] = value
        return value

    return load
