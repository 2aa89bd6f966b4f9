"""The JSON boundary: the one type of a JSON object this package writes, and the conversion of its
values to what :mod:`json` accepts.

Results are typed dataclasses whose ``as_json`` returns a :data:`JsonObject`; code reads their fields,
only the JSON boundary (``--json``, summary files, fleet rows, tests of the printed keys) reads the
objects.
"""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING, Any, cast

import numpy as np

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

JsonObject = dict[str, Any]  # Any: a JSON value's type depends on its key (see below)
"""A JSON object as built by an ``as_json``, or a JSON or YAML mapping as read (a vehicle or terrain
file, a bag's metadata) before it is checked into a typed object. ``Any`` because a JSON value's type
depends on its key (a number, a string, a nested object, null) and a reader indexes it by key; the
typed view is the dataclass that made it or that the reader builds. The package's one ``Any`` for
JSON and YAML documents."""


class FieldsAsJson:
    """Mixin of a dataclass whose fields are already JSON values: ``as_json`` is its fields by name."""

    def as_json(self) -> JsonObject:
        return dataclasses.asdict(cast('DataclassInstance', self))


def jsonable(value: object) -> object:
    """``value`` with numpy types made plain, NaN as null and infinities as "inf"/"-inf"."""
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist())
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None if math.isnan(value) else ('inf' if value > 0 else '-inf')
    return value
