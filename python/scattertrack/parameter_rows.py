"""Parameter tables written in Python, in the schema of the Rust core's.

A Python-side estimator (Marvel) declares each parameter once, as a
dataclass field made by :func:`parameter`: its default, range, unit and
one-line description. :func:`rows_of` turns the dataclass into the rows
``_core.ParameterTable`` takes, so its values are checked by the same code
as the core's tables (docs/parameters.md shows both).
"""

from __future__ import annotations

import dataclasses


def parameter(default, range: str = "any", unit: str = "", description: str = "", *, choices=None, optional=None, kind=None):
    """A dataclass field that is a table row.

    ``range`` as the core writes ranges (``"> 0"``, ``">= 1"``, ``"[0, 1]"``,
    ``"(0, inf]"`` to allow infinity; ``"any"``: every finite number);
    ``unit`` e.g. ``"m"``, ``"s"``; ``description`` one line. The kind comes
    from the default (bool, int → integer, float) or ``choices`` (the allowed
    strings); ``optional`` (default: when the default is None) lets None
    switch the feature off.
    """
    if kind is None:
        kind = _kind_of(default, choices)
    if optional is None:
        optional = default is None
    metadata = {
        "kind": kind,
        "optional": optional,
        "choices": list(choices) if choices is not None else None,
        "range": range,
        "unit": unit,
        "description": description,
    }
    return dataclasses.field(default=default, metadata={"parameter": metadata})


def _kind_of(default, choices) -> str:
    if choices is not None:
        return "choice"
    if isinstance(default, bool):  # before int: True is an int
        return "bool"
    if isinstance(default, int):
        return "integer"
    if isinstance(default, float):
        return "float"
    raise TypeError(f"cannot tell a parameter's kind from its default {default!r}: give kind=")


def rows_of(cls) -> list[dict]:
    """The rows of a dataclass whose every field is a :func:`parameter`."""
    rows = []
    for f in dataclasses.fields(cls):
        row = f.metadata.get("parameter")
        if row is None:
            raise TypeError(f"{cls.__name__}.{f.name} is not declared with parameter()")
        rows.append({"name": f.name, "default": f.default, **row})
    return rows
