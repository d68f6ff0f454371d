"""Response models made from the domain's records: one definition per shape.

A record of the product (a frozen dataclass: the loop's timing figures, a program
check's report) is what the code passes around; its wire shape is not written out again
as a second class beside it. :func:`model_of` makes the pydantic model of a record: the
same field names, types and order, with descriptions and the types that differ
on the wire (a nested record's model, a tuple sent as a list) given where it is made.
"""

from __future__ import annotations

import dataclasses
import typing
from collections.abc import Mapping
from typing import Any

from pydantic import BaseModel, Field, create_model


def model_of(
    record: type,
    name: str,
    *,
    base: type[BaseModel] = BaseModel,
    doc: str | None = None,
    describe: Mapping[str, str] | None = None,
    types: Mapping[str, Any] | None = None,
) -> type[BaseModel]:
    """The pydantic model ``name`` of the dataclass ``record``: each of its fields, in
    order, with its type (or ``types[field]``) and ``describe[field]`` as its description,
    each required (an answer carries every field; the record's defaults are the code's);
    ``doc`` (default: the record's docstring) as the schema's description; ``base`` (e.g.
    a model with ``extra="forbid"``). Raises TypeError if ``record`` is not a dataclass
    and KeyError for a described or retyped name that is not one of its fields."""
    if not dataclasses.is_dataclass(record):
        raise TypeError(f"{record!r} is not a dataclass")
    describe, types = dict(describe or {}), dict(types or {})
    fields = dataclasses.fields(record)
    names = {f.name for f in fields}
    for unknown in (describe.keys() | types.keys()) - names:
        raise KeyError(f"{record.__name__} has no field {unknown!r}")
    hints = typing.get_type_hints(record)
    definitions: dict[str, Any] = {}
    for f in fields:
        described = {"description": describe[f.name]} if f.name in describe else {}
        definitions[f.name] = (types.get(f.name, hints[f.name]), Field(**described))
    return create_model(name, __base__=base, __doc__=doc or record.__doc__, **definitions)
