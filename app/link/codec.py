"""The link's encoding of the loop's records: frozen dataclasses to JSON and back.

What crosses the link between the robot node and the station (app/link/): the published
:class:`~app.control.state.Snapshot` and the records inside it (faults, timing, the bus's
counters, gains), and the commands' arguments and answers. Standard JSON (RFC 8259), so
any Zenoh tool can read the link: a non-finite float is written ``null`` (NaN), ``"inf"``
or ``"-inf"``, and read back as such where the field is a float or an array. An array of
more than PACKED_OVER values (a run's samples) goes as ``{"packed": base64, "dtype":
"<f8" | "<i8", "shape": [...]}``: parsing a list of a million floats would hold the
node's interpreter (and its loop) for a second, the bytes take milliseconds. A whole
number, a text or a flag of the wrong type is refused naming the field.

:func:`encode` works on any dataclass; :func:`decode` rebuilds one from its type hints
(``np.ndarray`` fields as float arrays, tuples, nested dataclasses, mappings of arrays,
unions with None), so a field added to a record crosses the link without a change here.
"""

from __future__ import annotations

import base64
import dataclasses
import json
import math
import types
import typing
from collections.abc import Callable, Mapping
from functools import cache
from typing import Any, TypeVar, get_args, get_origin

import numpy as np

T = TypeVar("T")
PACKED_OVER = 64  # an array of more values goes as base64 bytes (a run's samples), not a list
_INF = {"inf": math.inf, "-inf": -math.inf}


class CodecError(ValueError):
    """A message that does not decode to the record it should be; says the field."""


def plain(value: Any) -> Any:
    """``value`` as JSON-ready data: dataclasses as dicts, arrays and tuples as lists,
    NaN as None and infinities as ``"inf"`` / ``"-inf"``, NumPy scalars as Python ones."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, np.ndarray):
        if value.size > PACKED_OVER and value.dtype.kind in "fiub":
            kind = "<i8" if value.dtype.kind in "iub" else "<f8"
            data = np.ascontiguousarray(value, dtype=kind).tobytes()
            return {"packed": base64.b64encode(data).decode(), "dtype": kind, "shape": value.shape}
        return [plain(v) for v in value.tolist()]
    if isinstance(value, bool | None | str | int) and not isinstance(value, np.generic):
        return value
    if isinstance(value, float | np.floating):
        number = float(value)
        if math.isfinite(number):
            return number
        return None if math.isnan(number) else ("inf" if number > 0 else "-inf")
    if isinstance(value, np.integer | np.bool_):
        return value.item()
    if isinstance(value, Mapping):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [plain(v) for v in value]
    raise TypeError(f"{type(value).__name__} does not cross the link")


def encode(value: Any) -> bytes:
    """``value`` (a dataclass, or plain data holding them) as UTF-8 JSON bytes."""
    return json.dumps(plain(value), separators=(",", ":")).encode()


def number(value: Any) -> float:
    """A float from its JSON form: null is NaN, "inf" / "-inf" the infinities."""
    if value is None:
        return math.nan
    if isinstance(value, str):
        if value in _INF:
            return _INF[value]
        raise CodecError(f"expected a number, got {value!r}")
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise CodecError(f"expected a number, got {value!r}")
    return float(value)


def _array(value: Any) -> np.ndarray:
    if isinstance(value, dict) and "packed" in value:
        return _unpack(value)
    if not isinstance(value, list):
        raise CodecError(f"expected a list of numbers, got {type(value).__name__}")
    return np.array([_array(v) if isinstance(v, list) else number(v) for v in value], float)


def _unpack(value: dict) -> np.ndarray:
    """An array packed by :func:`plain` (base64 of little-endian float64 or int64)."""
    kind, shape = value.get("dtype"), value.get("shape")
    if kind not in ("<f8", "<i8") or not isinstance(shape, list):
        raise CodecError("a packed array needs dtype <f8 or <i8 and a shape")
    if not all(isinstance(n, int) and not isinstance(n, bool) and n >= 0 for n in shape):
        raise CodecError(f"a packed array's shape must be sizes, got {shape!r}")
    try:
        data = base64.b64decode(value["packed"], validate=True)
        array = np.frombuffer(data, dtype=kind)
        return array.reshape(shape).astype(np.float64 if kind == "<f8" else np.int64)
    except (ValueError, TypeError) as exc:
        raise CodecError(f"a packed array does not decode: {exc}") from None


def _int(value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise CodecError(f"expected a whole number, got {value!r:.40}")
    return value


def _str(value: Any) -> str:
    if not isinstance(value, str):
        raise CodecError(f"expected a text, got {value!r:.40}")
    return value


def _bool(value: Any) -> bool:
    if not isinstance(value, bool):
        raise CodecError(f"expected true or false, got {value!r:.40}")
    return value


@cache
def _reader(hint: Any) -> Callable[[Any], Any]:
    """A function that rebuilds a value of type ``hint`` from its JSON form."""
    origin, args = get_origin(hint), get_args(hint)
    if hint is np.ndarray:
        return _array
    if hint is float:
        return number
    if hint is int:
        return _int
    if hint is str:
        return _str
    if hint is bool:
        return _bool
    if hint is Any or hint is type(None):
        return lambda v: v
    if dataclasses.is_dataclass(hint):
        return lambda v: _decode_record(hint, v)
    if origin in (typing.Union, types.UnionType):
        if type(None) in args:
            others = [a for a in args if a is not type(None)]
            inner = _reader(others[0]) if len(others) == 1 else (lambda v: v)
            return lambda v: None if v is None else inner(v)
        return lambda v: v
    if origin is tuple:
        if len(args) == 2 and args[1] is Ellipsis:
            item = _reader(args[0])
            return lambda v: tuple(item(x) for x in v)
        items = [_reader(a) for a in args]
        return lambda v: tuple(r(x) for r, x in zip(items, v, strict=True))
    if origin in (list,):
        item = _reader(args[0]) if args else (lambda v: v)
        return lambda v: [item(x) for x in v]
    if origin in (dict, Mapping):
        value_reader = _reader(args[1]) if len(args) == 2 else (lambda v: v)
        return lambda v: {k: value_reader(x) for k, x in v.items()}
    if hint in (dict, list):
        return lambda v: v
    raise TypeError(f"no link reader for {hint!r}")


@cache
def _plan(cls: type) -> tuple[tuple[str, Callable[[Any], Any], bool], ...]:
    hints = typing.get_type_hints(cls)
    return tuple(
        (
            f.name,
            _reader(hints[f.name]),
            f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING,
        )
        for f in dataclasses.fields(cls)
        if f.init
    )


def _decode_record(cls: type[T], data: Any) -> T:
    if not isinstance(data, dict):
        raise CodecError(f"{cls.__name__}: expected an object, got {type(data).__name__}")
    values: dict[str, Any] = {}
    for name, read, required in _plan(cls):
        if name not in data:
            if required:
                raise CodecError(f"{cls.__name__}.{name}: missing")
            continue
        try:
            values[name] = read(data[name])
        except CodecError as exc:
            raise CodecError(f"{cls.__name__}.{name}: {exc}") from None
        except (TypeError, ValueError, AttributeError) as exc:
            raise CodecError(f"{cls.__name__}.{name}: {exc}") from None
    return cls(**values)


def decode(cls: type[T], payload: bytes | str | dict) -> T:
    """The record of type ``cls`` (a dataclass) from :func:`encode`'s bytes (or their
    parsed JSON). Fields the message lacks take their defaults; a required one missing, or
    a value of the wrong shape, raises :class:`CodecError` naming ``Class.field``."""
    if isinstance(payload, bytes | str):
        try:
            payload = json.loads(payload)
        except ValueError as exc:
            raise CodecError(f"{cls.__name__}: not JSON ({exc})") from None
    return _decode_record(cls, payload)
