"""How a ROS 2 graph over Zenoh names things: key expressions, liveliness tokens, QoS and
the attachment, as rmw_zenoh writes them (ros2/rmw_zenoh docs/design.md), and the keys of
zenoh-bridge-ros2dds.

- Data: ``<domain>/<topic without its leading />/<DDS type name>/<type hash>``, the type
  hash ``RIHS01_<sha256>`` (Jazzy and later) or ``TypeHashNotSupported`` (Humble).
  zenoh-bridge-ros2dds: the topic's name alone (no domain, type or hash).
- Graph: a liveliness token per node (``NN``) and per publisher (``MP``) or subscription
  (``MS``) under ``@ros2_lv/<domain>/<session id>/<node id>/<entity id>/<kind>/<enclave>/
  <namespace>/<node name>[/<topic>/<type>/<hash>/<qos>]``, names "mangled" (``/`` -> ``%``,
  an empty field ``%``), so ``ros2 topic list`` on an rmw_zenoh machine sees the topics.
- Each sample's attachment: its sequence number (int64), source timestamp [ns since the
  epoch] (int64) and the publisher's 16-byte GID, in Zenoh's own serialization
  (``zenoh.ext.z_serialize``, as rmw_zenoh's ``zenoh::ext::Serializer``).
"""

from __future__ import annotations

import json
import os
import re
from dataclasses import dataclass

import zenoh
import zenoh.ext

ADMIN_SPACE = "@ros2_lv"
NO_HASH = "TypeHashNotSupported"  # Humble's rmw_zenoh
GID_BYTES = 16
KIND = {"node": "NN", "publisher": "MP", "subscription": "MS"}
_NAME = re.compile(r"^[A-Za-z_~/][A-Za-z0-9_/~]*$")


def dds_type_name(typename: str) -> str:
    """``pkg/msg/Name`` -> ``pkg::msg::dds_::Name_`` (the DDS name rmw_zenoh keys carry).
    ValueError for a name that is not ``pkg/msg/Name``."""
    parts = typename.split("/")
    if len(parts) != 3 or not all(parts) or parts[1] != "msg":
        raise ValueError(f"type: expected pkg/msg/Name, got {typename!r}")
    package, _, name = parts
    return f"{package}::msg::dds_::{name}_"


def ros_type_name(dds_name: str) -> str:
    """The inverse of :func:`dds_type_name`; ValueError for another form."""
    match = re.fullmatch(r"([A-Za-z0-9_]+)::msg::dds_::([A-Za-z0-9_]+)_", dds_name)
    if match is None:
        raise ValueError(f"type: not a DDS message type name: {dds_name!r}")
    return f"{match[1]}/msg/{match[2]}"


def qualified(namespace: str, node_name: str, name: str) -> str:
    """A topic's fully qualified name (ROS 2 name resolution): ``/x`` stays, ``~/x`` is
    under the node, ``x`` under the namespace. ValueError for a name ROS refuses."""
    if not _NAME.match(name) or "//" in name or name.endswith("/"):
        raise ValueError(f"topic: {name!r} is not a valid ROS 2 name")
    namespace = "/" + namespace.strip("/")
    if name.startswith("/"):
        return name
    if name.startswith("~"):
        return f"{namespace.rstrip('/')}/{node_name}{name[1:]}"
    return f"{namespace.rstrip('/')}/{name}"


def mangle(name: str) -> str:
    """A name as a single key chunk: ``/`` -> ``%`` (an empty name: ``%``)."""
    return name.replace("/", "%") or "%"


def topic_key(form: str, domain_id: int, topic: str, typename: str, type_hash: str) -> str:
    """The data key of fully qualified ``topic``: rmw_zenoh's (``form`` rmw_zenoh) or
    zenoh-bridge-ros2dds's (``form`` bridge). ``type_hash`` may be ``*`` (any hash)."""
    if form == "bridge":
        return topic.lstrip("/")
    return f"{domain_id}/{topic.lstrip('/')}/{dds_type_name(typename)}/{type_hash}"


def encode_qos(reliable: bool = True, transient_local: bool = False, depth: int = 10) -> str:
    """A QoS profile as rmw_zenoh's token field: ``reliability:durability:history,depth:
    deadline:lifespan:liveliness``, a value equal to ROS's default profile (reliable,
    volatile, keep last) left empty."""
    reliability = "" if reliable else "2"
    durability = "1" if transient_local else ""
    return f"{reliability}:{durability}:,{int(depth)}:,:,:,,"


@dataclass(frozen=True)
class GraphNode:
    """One ROS 2 node of a Zenoh session: ``session_id`` the session's Zenoh id (hex)."""

    domain_id: int
    session_id: str
    node_id: int
    namespace: str
    name: str

    def _prefix(self, entity_id: int, kind: str) -> str:
        namespace = mangle(self.namespace.rstrip("/"))
        return (
            f"{ADMIN_SPACE}/{self.domain_id}/{self.session_id}/{self.node_id}/{entity_id}/"
            f"{KIND[kind]}/%/{namespace}/{self.name}"
        )

    def token(self) -> str:
        """The node's own liveliness key (``NN``)."""
        return self._prefix(self.node_id, "node")

    def endpoint_token(
        self, entity_id: int, kind: str, topic: str, typename: str, type_hash: str, qos: str
    ) -> str:
        """A publisher's (``kind`` publisher) or subscription's liveliness key."""
        return (
            f"{self._prefix(entity_id, kind)}/{mangle(topic)}/{dds_type_name(typename)}/"
            f"{type_hash}/{qos}"
        )


def new_gid() -> bytes:
    """A publisher's GID: 16 random bytes."""
    return os.urandom(GID_BYTES)


def attachment(sequence: int, stamp_ns: int, gid: bytes) -> bytes:
    """One sample's rmw_zenoh attachment (sequence number, source time [ns], GID)."""
    return zenoh.ext.z_serialize(
        (zenoh.ext.Int64(sequence), zenoh.ext.Int64(stamp_ns), bytes(gid))
    ).to_bytes()


def read_attachment(data: bytes) -> tuple[int, int, bytes]:
    """``(sequence, source time [ns], gid)`` of an attachment; ValueError when it is not
    one (truncated, another layout)."""
    try:
        sequence, stamp, gid = zenoh.ext.z_deserialize(
            tuple[zenoh.ext.Int64, zenoh.ext.Int64, bytes], zenoh.ZBytes(bytes(data))
        )
    except (zenoh.ext.ZDeserializeError, TypeError) as exc:
        raise ValueError(f"attachment: not rmw_zenoh's ({exc})") from None
    return int(sequence), int(stamp), bytes(gid)


def session_config(connect: tuple[str, ...]) -> zenoh.Config:
    """A Zenoh session for the ROS 2 graph alone, as rmw_zenoh's: peer mode, connecting to
    ``connect`` (the graph's router, rmw_zenohd) until it answers, multicast scouting off,
    gossip on (ROS peers learn of each other through the router and connect directly),
    timestamping on."""
    config = zenoh.Config()
    config.insert_json5("mode", '"peer"')
    config.insert_json5("connect/endpoints", json.dumps(list(connect)))
    config.insert_json5("connect/timeout_ms", "-1")
    config.insert_json5("connect/exit_on_failure", "false")
    config.insert_json5("listen/endpoints", '["tcp/localhost:0"]')
    config.insert_json5("scouting/multicast/enabled", "false")
    config.insert_json5("timestamping/enabled", "true")
    return config
