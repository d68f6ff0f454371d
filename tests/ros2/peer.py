"""An independent ROS 2-over-Zenoh peer: ``zenoh-ros2-sdk`` (written for rmw_zenoh by
others), in a process of its own, speaking to a deltadash robot node.

    python tests/ros2/peer.py <host> <port> <domain_id>

It reads one JSON command per line on stdin and answers one JSON line on stdout:

- ``{"op": "topics"}``: the graph's topics and types (its liveliness query, as
  ``ros2 topic list -t``).
- ``{"op": "subscribe", "topic": T, "type": pkg/msg/Name}``: from then on every message
  is decoded by the SDK and printed as ``{"topic": T, "message": {...}, "received_s": ..}``
  (``"type_hash"``: the key's hash instead of the SDK's, e.g. Humble's).
- ``{"op": "publish", "topic": T, "type": ..., "message": {...}}``: one message, built
  from nested fields by the SDK's own types (type hash computed by the SDK from the
  definitions in tests/ros2/msg/, written from ROS 2's interface files).

The message definitions are loaded from tests/ros2/msg/ (the SDK would otherwise clone
ROS's repositories from the network).
"""

from __future__ import annotations

import json
import os
import sys
import threading
import time
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
# no multicast or gossip: this peer talks to the node it is given and nothing else
os.environ.setdefault(
    "ZENOH_CONFIG_OVERRIDE", "scouting/multicast/enabled=false;scouting/gossip/enabled=false"
)

from zenoh_ros2_sdk import ROS2Publisher, ROS2Subscriber  # noqa: E402
from zenoh_ros2_sdk.discovery import get_topic_names_and_types  # noqa: E402
from zenoh_ros2_sdk.message_registry import get_registry  # noqa: E402
from zenoh_ros2_sdk.session import ZenohSession  # noqa: E402

_out = threading.Lock()


def say(data: dict[str, Any]) -> None:
    with _out:
        sys.stdout.write(json.dumps(data, default=str) + "\n")
        sys.stdout.flush()


def plain(message: Any) -> Any:
    """A decoded message as JSON data."""
    if hasattr(message, "__dataclass_fields__"):
        return {
            name: plain(getattr(message, name))
            for name in message.__dataclass_fields__
            if not name.isupper() and name != "__msgtype__"
        }
    if hasattr(message, "tolist"):
        return message.tolist()
    if isinstance(message, list | tuple):
        return [plain(m) for m in message]
    return message


def build(store: Any, typename: str, fields: dict[str, Any]) -> Any:
    """A message of ``typename`` from nested ``fields`` (the SDK's type store)."""
    import numpy as np

    cls = store.types[typename]
    values: dict[str, Any] = {}
    for name, field in cls.__dataclass_fields__.items():
        if name.isupper() or name == "__msgtype__" or name not in fields:
            continue
        value = fields[name]
        kind = str(field.type)
        nested = kind.replace("__", "/")
        if isinstance(value, dict) and nested in store.types:
            values[name] = build(store, nested, value)
        elif isinstance(value, list) and "ndarray" in kind:
            dtype = next(
                (d for d in ("float32", "uint8", "int8", "float64") if d in kind), "float64"
            )
            values[name] = np.asarray(value, dtype=dtype)
        else:
            values[name] = value
    return cls(**values)


def stream(publisher: Any, store: Any, typename: str, command: dict, stop: threading.Event):
    """Publish ``command["message"]`` at ``rate_hz``, its header stamped with the time of
    sending (and PX4's ``timestamp`` [us]), until ``stop``."""
    period = 1.0 / command.get("rate_hz", 50.0)
    while not stop.wait(period):
        now = time.time()
        fields = json.loads(json.dumps(command["message"]))
        if "header" in fields:
            sec = int(now)
            fields["header"]["stamp"] = {"sec": sec, "nanosec": int((now - sec) * 1e9)}
        if "timestamp" in fields:
            fields["timestamp"] = fields["timestamp_sample"] = int(now * 1e6)
        message = build(store, typename, fields)
        publisher.publish(
            **{
                k: getattr(message, k)
                for k in message.__dataclass_fields__
                if k.islower() and not k.startswith("_")
            }
        )


def main() -> None:
    host, port, domain = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
    get_registry(str(HERE / "msg"))
    session = ZenohSession.get_instance(host, port)
    publishers: dict[str, Any] = {}
    subscribers: list[Any] = []
    streams: list[threading.Event] = []
    say({"ready": True, "zid": session.session_id})
    for line in sys.stdin:
        try:
            command = json.loads(line)
            op = command["op"]
            if op == "topics":
                topics = get_topic_names_and_types(domain, host, port, timeout=1.0)
                say({"op": op, "topics": topics})
            elif op == "subscribe":
                topic = command["topic"]

                def on_message(message: Any, topic: str = topic) -> None:
                    say({"topic": topic, "message": plain(message), "received_s": time.time()})

                subscribers.append(
                    ROS2Subscriber(
                        topic,
                        command["type"],
                        on_message,
                        domain_id=domain,
                        router_ip=host,
                        router_port=port,
                        node_name="peer_listener",
                        type_hash=command.get("type_hash"),  # Humble: TypeHashNotSupported
                    )
                )
                say({"op": op, "topic": topic, "key": subscribers[-1].keyexpr})
            elif op == "publish":
                topic, typename = command["topic"], command["type"]
                if topic not in publishers:
                    publishers[topic] = ROS2Publisher(
                        topic,
                        typename,
                        domain_id=domain,
                        router_ip=host,
                        router_port=port,
                        node_name="peer_talker",
                    )
                publisher = publishers[topic]
                message = build(session.store, typename, command["message"])
                # the SDK's own CDR and attachment (ROS2Publisher.publish builds from kwargs)
                publisher.publish(
                    **{
                        k: getattr(message, k)
                        for k in message.__dataclass_fields__
                        if k.islower() and not k.startswith("_")
                    }
                )
                say({"op": op, "topic": topic, "key": publisher.keyexpr})
            elif op == "stream":  # the message again and again, stamped now, until stopped
                topic, typename = command["topic"], command["type"]
                publisher = publishers.get(topic) or ROS2Publisher(
                    topic,
                    typename,
                    domain_id=domain,
                    router_ip=host,
                    router_port=port,
                    node_name="peer_talker",
                )
                publishers[topic] = publisher
                stop = threading.Event()
                streams.append(stop)
                threading.Thread(
                    target=stream,
                    args=(publisher, session.store, typename, command, stop),
                    daemon=True,
                ).start()
                say({"op": op, "topic": topic, "key": publisher.keyexpr})
            elif op == "stop_streams":
                for stop in streams:
                    stop.set()
                say({"op": op})
            else:
                say({"error": f"no op {op!r}"})
        except Exception as exc:  # tell the test, keep going
            say({"error": f"{type(exc).__name__}: {exc}"})


if __name__ == "__main__":
    main()
