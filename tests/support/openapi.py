"""Hypothesis strategies for request bodies, read from the server's own /openapi.json.

``bodies(doc, schema)`` draws JSON values that mostly follow the schema (types, bounds,
lengths, enums, required keys) with junk mixed in at every level (a string for a number,
NaN, a missing key, an extra key, the wrong length), so a route sees both what it should
run and what it must refuse.
"""

from __future__ import annotations

from typing import Any

from hypothesis import strategies as st

MAX_ITEMS = 6  # longer arrays add time, not cases
JUNK = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(2**70), 2**70),
    st.floats(),  # NaN and the infinities too (sent as NaN / Infinity)
    st.sampled_from([1e308, -1e308, 5e-324, 0.0, -0.0, "0", "0.1", "-0.24", "", "NaN"]),
    st.text(max_size=8),
    st.lists(st.integers(-3, 3), max_size=4),
    st.just({}),
)


def resolve(doc: dict, schema: dict) -> dict:
    while "$ref" in schema:
        schema = doc["components"]["schemas"][schema["$ref"].rsplit("/", 1)[-1]]
    return schema


def bodies(doc: dict, schema: dict) -> st.SearchStrategy[Any]:
    """Values for ``schema``: three in four follow it at this level, one in four is junk."""
    valid = _follow(doc, resolve(doc, schema))
    return st.one_of(valid, valid, valid, JUNK)


def _follow(doc: dict, schema: dict) -> st.SearchStrategy[Any]:
    if "anyOf" in schema:
        return st.one_of([bodies(doc, s) for s in schema["anyOf"]])
    if "enum" in schema:
        return st.sampled_from(schema["enum"])
    if "const" in schema:
        return st.just(schema["const"])
    kind = schema.get("type")
    if kind == "object":
        return _object(doc, schema)
    if kind == "array":
        items = bodies(doc, schema.get("items", {}))
        low = schema.get("minItems", 0)
        high = max(low, min(schema.get("maxItems", MAX_ITEMS), MAX_ITEMS))
        return st.lists(items, min_size=max(0, low - 1), max_size=high + 1)
    if kind in ("number", "integer"):
        return _number(schema, kind == "integer")
    if kind == "boolean":
        return st.booleans()
    if kind == "string":
        return st.text(min_size=schema.get("minLength", 0), max_size=schema.get("maxLength", 16))
    if kind == "null":
        return st.none()
    return JUNK


def _number(schema: dict, integer: bool) -> st.SearchStrategy[Any]:
    low = schema.get("minimum", schema.get("exclusiveMinimum"))
    high = schema.get("maximum", schema.get("exclusiveMaximum"))
    if integer:
        inside = st.integers(None if low is None else int(low), None if high is None else int(high))
    else:
        inside = st.floats(low, high, allow_nan=False, allow_infinity=False)
    edges = [v for v in (low, high) if v is not None]
    return st.one_of(inside, st.sampled_from([*edges, *(v * 1.0001 + 1e-9 for v in edges), 0]))


def _object(doc: dict, schema: dict) -> st.SearchStrategy[dict]:
    properties = schema.get("properties", {})
    required = set(schema.get("required", []))
    fields = {name: bodies(doc, sub) for name, sub in properties.items()}
    drawn = st.fixed_dictionaries(
        {k: v for k, v in fields.items() if k in required},
        optional={k: v for k, v in fields.items() if k not in required},
    )
    extra = st.dictionaries(st.sampled_from(["extra", "x", "position"]), JUNK, max_size=1)
    dropped = st.sampled_from(sorted(required)) if required else st.none()

    def combine(body: dict, more: dict, drop: str | None, mutate: bool) -> dict:
        if mutate:
            body = {**{k: v for k, v in body.items() if k != drop}, **more}
        return body

    return st.builds(combine, drawn, extra, dropped, st.integers(0, 3).map(lambda n: n == 0))
