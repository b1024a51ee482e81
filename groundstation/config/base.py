"""The base of every configuration section: strict, frozen, finite; covariance checks.

:class:`ConfigModel` refuses unknown keys and infinite or NaN numbers and takes numbers
and booleans strictly; :class:`FieldValueError` lets a check that reads several fields
blame the one the file must fix.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from pydantic import BaseModel, ConfigDict, GetCoreSchemaHandler
from pydantic_core import CoreSchema


def _strict_scalars(schema: Any) -> None:
    """Mark every int, float and bool in a pydantic core schema strict, in place."""
    if isinstance(schema, dict):
        if schema.get("type") in ("int", "float", "bool"):
            schema["strict"] = True
        for value in schema.values():
            _strict_scalars(value)
    elif isinstance(schema, list):
        for value in schema:
            _strict_scalars(value)


class FieldValueError(ValueError):
    """A refusal by a model validator (one that sees several fields) that one field must
    fix: ``field`` (its name in the model) and its ``value``. The error report then names
    that field, its value and its line in the file, not the whole section."""

    def __init__(self, field: str, value: object, message: str) -> None:
        super().__init__(message)
        self.field = field
        self.value = value


class ConfigModel(BaseModel):
    """Base: unknown keys are errors, instances are immutable, numbers are numbers.

    Every number must be finite (``allow_inf_nan=False``: ``.inf`` is no time, rate or
    length), and numbers and booleans are strict, each in every model: no
    ``true`` for a number (``vicon.port: true`` would be port 1), no ``1e30`` for an
    integer (``serial.baud``), no string for a number, no ``0``/``1`` for a boolean. An
    int is a float. The rest stays lax, as YAML needs it: a string is a path, a list a
    tuple. (pydantic's model-wide ``strict=True`` would refuse those, and validates
    defaults such as ``Path("flightlogs")`` against the JSON rules.)
    """

    model_config = ConfigDict(extra="forbid", frozen=True, validate_default=True,
                              allow_inf_nan=False)

    @classmethod
    def __get_pydantic_core_schema__(cls, source: type[BaseModel],
                                     handler: GetCoreSchemaHandler, /) -> CoreSchema:
        schema = handler(source)
        _strict_scalars(schema)
        return schema


def covariance_matrix(value: list[float] | list[list[float]], n: int, name: str) -> np.ndarray:
    """A covariance given as a diagonal (list) or a full matrix (list of lists) -> (n, n)."""
    arr = np.asarray(value, dtype=float)
    if arr.ndim == 1:
        if arr.shape != (n,):
            raise ValueError(f"{name} diagonal must have {n} entries, found {arr.shape[0]}")
        arr = np.diag(arr)
    if arr.shape != (n, n):
        raise ValueError(f"{name} must be {n}x{n}, found {arr.shape[0]}x{arr.shape[1]}")
    return arr


def check_covariance(value: list[float] | list[list[float]], n: int, name: str) -> None:
    """Raise ValueError unless ``value`` is a symmetric positive-definite n x n covariance."""
    arr = covariance_matrix(value, n, name)
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} has non-finite entries")
    if not np.allclose(arr, arr.T, rtol=1e-9, atol=1e-15):
        raise ValueError(f"{name} is not symmetric")
    try:
        np.linalg.cholesky(arr)
    except np.linalg.LinAlgError:
        raise ValueError(f"{name} is not positive definite") from None


Covariance = list[float] | list[list[float]]



Box = tuple[tuple[float, float], tuple[float, float], tuple[float, float]]
"""An axis-aligned box ``((x_min, x_max), (y_min, y_max), (z_min, z_max))``, NED [m]."""

