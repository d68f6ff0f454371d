"""The independent peer's message definitions (tests/ros2/msg/), and decoders built from
them by ``mcap-ros2-support`` (a CDR reader that is not rosbags)."""

from __future__ import annotations

import re
from functools import cache
from pathlib import Path
from typing import Any

from mcap_ros2._dynamic import generate_dynamic

MSG = Path(__file__).resolve().parent / "msg"
PRIMITIVES = {
    "bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16",
    "int32", "uint32", "int64", "uint64", "string", "wstring",
}  # fmt: skip


def text(typename: str) -> str:
    """The ``.msg`` of ``pkg/msg/Name``."""
    package, _, name = typename.split("/")
    return (MSG / package / "msg" / f"{name}.msg").read_text()


def dependencies(typename: str) -> list[str]:
    """Every message type ``typename`` uses, depth first, each once."""
    package = typename.split("/")[0]
    found: list[str] = []
    for line in text(typename).splitlines():
        if not line.strip() or "=" in line:  # a blank line, a constant
            continue
        kind = re.sub(r"\[.*\]$", "", line.split()[0])
        if kind in PRIMITIVES:
            continue
        full = (
            f"{kind.split('/')[0]}/msg/{kind.split('/')[1]}"
            if "/" in kind
            else (f"{package}/msg/{kind}")
        )
        for dep in [*dependencies(full), full]:
            if dep not in found:
                found.append(dep)
    return found


def schema(typename: str) -> str:
    """``typename``'s ros2msg schema: its definition, then each dependency's."""
    parts = [text(typename)]
    for dep in dependencies(typename):
        package, _, name = dep.split("/")
        parts.append("=" * 80 + f"\nMSG: {package}/{name}\n" + text(dep))
    return "\n".join(parts)


@cache
def decoder(typename: str) -> Any:
    """mcap-ros2-support's decoder of ``typename`` (CDR with its header -> an object)."""
    package, _, name = typename.split("/")
    return generate_dynamic(f"{package}/msg/{name}", schema(typename))[f"{package}/msg/{name}"]
