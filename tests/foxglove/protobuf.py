"""A small protobuf decoder driven by the schema a Foxglove server advertises.

A channel with ``schemaEncoding: protobuf`` advertises its schema as a serialized
``google.protobuf.FileDescriptorSet`` (base64). Nothing here comes from foxglove-sdk or
the protobuf package: the descriptor set is read with descriptor.proto's own field numbers
and each message decoded from the protobuf wire format, so a test checks the bytes the
server sent against the schema it advertised, independently of the code that wrote them.
Fields left out of the wire (proto3 writes no zero or empty value) read as their defaults.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from typing import Any

# FieldDescriptorProto.Type
DOUBLE, FLOAT, INT64, UINT64, INT32, FIXED64, FIXED32, BOOL, STRING = range(1, 10)
GROUP, MESSAGE, BYTES, UINT32, ENUM, SFIXED32, SFIXED64, SINT32, SINT64 = range(10, 19)
REPEATED = 3  # FieldDescriptorProto.Label
VARINT_TYPES = {INT64, UINT64, INT32, BOOL, UINT32, ENUM, SINT32, SINT64}
FIXED64_TYPES = {DOUBLE, FIXED64, SFIXED64}
FIXED32_TYPES = {FLOAT, FIXED32, SFIXED32}


def _varint(data: bytes, at: int) -> tuple[int, int]:
    value = shift = 0
    while True:
        byte = data[at]
        at += 1
        value |= (byte & 0x7F) << shift
        if not byte & 0x80:
            return value, at
        shift += 7


def wire_fields(data: bytes) -> list[tuple[int, int, Any]]:
    """(field number, wire type, raw value) of every field in ``data`` in order: an int
    for varints, bytes for the fixed and length-delimited types."""
    out: list[tuple[int, int, Any]] = []
    at = 0
    while at < len(data):
        key, at = _varint(data, at)
        number, wire = key >> 3, key & 7
        value: Any
        if wire == 0:
            value, at = _varint(data, at)
        elif wire == 1:
            value, at = data[at : at + 8], at + 8
        elif wire == 2:
            size, at = _varint(data, at)
            value, at = data[at : at + size], at + size
        elif wire == 5:
            value, at = data[at : at + 4], at + 4
        else:
            raise ValueError(f"wire type {wire} (groups) not supported")
        out.append((number, wire, value))
    if at != len(data):
        raise ValueError("truncated message")
    return out


@dataclass
class Field:
    name: str
    number: int
    type: int
    repeated: bool
    type_name: str  # ".pkg.Message" for messages and enums


@dataclass
class MessageType:
    name: str  # full name without the leading dot: foxglove.Log
    fields: dict[int, Field] = field(default_factory=dict)


def _strings(raw: list[tuple[int, int, Any]], number: int) -> list[str]:
    return [v.decode() for n, _, v in raw if n == number]


def _messages(prefix: str, raw: bytes, types: dict[str, MessageType]) -> None:
    """A DescriptorProto (name 1, field 2, nested_type 3) and its nested types."""
    fields = wire_fields(raw)
    full = f"{prefix}.{_strings(fields, 1)[0]}".lstrip(".")
    message = MessageType(full)
    for number, _, value in fields:
        if number == 2:  # FieldDescriptorProto: name 1, number 3, label 4, type 5, type_name 6
            parts = wire_fields(value)
            ints = {n: v for n, w, v in parts if w == 0}
            type_name = _strings(parts, 6)
            message.fields[ints[3]] = Field(
                _strings(parts, 1)[0],
                ints[3],
                ints[5],
                ints.get(4) == REPEATED,
                type_name[0] if type_name else "",
            )
        elif number == 3:
            _messages(full, value, types)
    types[full] = message


def descriptor_types(file_descriptor_set: bytes) -> dict[str, MessageType]:
    """Every message type of a FileDescriptorSet (file 1: FileDescriptorProto with
    package 2 and message_type 4), by full name."""
    types: dict[str, MessageType] = {}
    for number, _, raw_file in wire_fields(file_descriptor_set):
        if number != 1:
            continue
        parts = wire_fields(raw_file)
        package = (_strings(parts, 2) or [""])[0]
        for n, _, raw in parts:
            if n == 4:
                _messages(package, raw, types)
    return types


def _scalar(kind: int, wire: int, value: Any) -> Any:
    if kind == DOUBLE:
        return struct.unpack("<d", value)[0]
    if kind == FLOAT:
        return struct.unpack("<f", value)[0]
    if kind in (FIXED64, SFIXED64):
        return struct.unpack("<Q" if kind == FIXED64 else "<q", value)[0]
    if kind in (FIXED32, SFIXED32):
        return struct.unpack("<I" if kind == FIXED32 else "<i", value)[0]
    if kind == BOOL:
        return bool(value)
    if kind in (SINT32, SINT64):
        return (value >> 1) ^ -(value & 1)
    if kind in (INT32, INT64):  # two's complement in 64 bits
        return value - (1 << 64) if value >= 1 << 63 else value
    if kind == STRING:
        return value.decode()
    return value  # UINT32, UINT64, ENUM, BYTES


def _packed(kind: int, data: bytes) -> list[Any]:
    if kind in FIXED64_TYPES:
        return [_scalar(kind, 1, data[i : i + 8]) for i in range(0, len(data), 8)]
    if kind in FIXED32_TYPES:
        return [_scalar(kind, 5, data[i : i + 4]) for i in range(0, len(data), 4)]
    out, at = [], 0
    while at < len(data):
        value, at = _varint(data, at)
        out.append(_scalar(kind, 0, value))
    return out


def _default(f: Field) -> Any:
    if f.repeated:
        return []
    if f.type == MESSAGE:
        return None
    if f.type == STRING:
        return ""
    if f.type == BYTES:
        return b""
    if f.type == BOOL:
        return False
    return 0.0 if f.type in (DOUBLE, FLOAT) else 0


def decode(types: dict[str, MessageType], name: str, data: bytes) -> dict[str, Any]:
    """``data``, a serialized ``name`` message, as a dict by field name (nested messages
    as dicts, enums as their numbers); a field absent from the wire has its default, and
    ``__present__`` lists the fields the wire carried (proto3 ``optional`` presence)."""
    message = types[name]
    out: dict[str, Any] = {f.name: _default(f) for f in message.fields.values()}
    present: list[str] = []
    for number, wire, value in wire_fields(data):
        f = message.fields.get(number)
        if f is None:
            continue  # unknown to the schema: ignored, as protobuf does
        present.append(f.name)
        if f.type == MESSAGE:
            item: Any = decode(types, f.type_name.lstrip("."), value)
        elif f.repeated and wire == 2 and f.type not in (STRING, BYTES):
            out[f.name].extend(_packed(f.type, value))
            continue
        else:
            item = _scalar(f.type, wire, value)
        if f.repeated:
            out[f.name].append(item)
        else:
            out[f.name] = item
    out["__present__"] = present
    return out
