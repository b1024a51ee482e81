"""What Lichtblick (and Foxglove, which shares the code) accepts as a channel's JSON Schema:
a Python port of the rules of ``parseJsonSchema`` in Lichtblick's
``packages/mcap-support/src/parseJsonSchema.ts``, written from that source, not from this
project's schemas. Test-only, imported like ``lab_helpers``.

The viewer turns a JSON Schema into message definitions for its panels. It refuses, with
the error the user sees ("Failed to parse channel schema ..."):

* a schema (or nested object) whose ``type`` is not ``"object"``,
* an object without ``properties`` (JavaScript's ``Object.entries(undefined)`` throws),
* a field whose ``type`` is anything but one of ``boolean``, ``string`` (without a
  ``contentEncoding`` other than ``base64``), ``number``, ``integer``, ``object``,
  ``array``: so ``"null"`` and any list of types (``["number", "null"]``) are refused,
* an array whose ``items`` is not one schema of ``boolean``, ``string``, ``number``,
  ``integer`` or ``object`` (an array of arrays is refused).
"""

from __future__ import annotations

from typing import Any

SCALARS = {"boolean": "bool", "number": "float64", "integer": "float64", "string": "string"}


def parse_json_schema(schema: Any, type_name: str = "root") -> dict[str, list[tuple[str, str]]]:
    """The datatypes the viewer builds from ``schema``: type name -> its (field, type)
    list; ValueError with the viewer's reason where it would refuse the schema."""
    datatypes: dict[str, list[tuple[str, str]]] = {}
    _object(schema, type_name, datatypes)
    return datatypes


def _object(schema: Any, type_name: str, datatypes: dict[str, list[tuple[str, str]]]) -> None:
    if not isinstance(schema, dict) or schema.get("type") != "object":
        raise ValueError(f'Expected "type": "object" for schema {type_name}')
    properties = schema.get("properties")
    if not isinstance(properties, dict):
        raise ValueError(f"{type_name}: an object without properties (Object.entries of "
                         "undefined)")
    fields: list[tuple[str, str]] = []
    for name, field in properties.items():
        kind = field.get("type") if isinstance(field, dict) else None
        if kind == "string" and field.get("contentEncoding") not in (None, "base64"):
            raise ValueError(f"Unsupported contentEncoding for {name}")
        if isinstance(kind, str) and kind in SCALARS:
            fields.append((name, SCALARS[kind]))
        elif kind == "object":
            _object(field, f"{type_name}.{name}", datatypes)
            fields.append((name, f"{type_name}.{name}"))
        elif kind == "array":
            items = field.get("items")
            item_kind = items.get("type") if isinstance(items, dict) else None
            if item_kind == "string" and items.get("contentEncoding") is not None:
                raise ValueError(f"Unsupported contentEncoding for array item {name}")
            if isinstance(item_kind, str) and item_kind in SCALARS:
                fields.append((name, SCALARS[item_kind] + "[]"))
            elif item_kind == "object":
                _object(items, f"{type_name}.{name}", datatypes)
                fields.append((name, f"{type_name}.{name}[]"))
            else:
                raise ValueError(f"Unsupported array item type: {item_kind!r}")
        else:
            raise ValueError(f"Unsupported object field type for {name}: {kind!r}")
    datatypes[type_name] = fields
