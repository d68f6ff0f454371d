"""A plain Foxglove WebSocket client: the documented ``foxglove.sdk.v1`` protocol over the
``websockets`` package, nothing of foxglove-sdk.

It reads ``serverInfo`` and ``advertise`` (JSON text frames), subscribes
(``{"op": "subscribe", "subscriptions": [{"id", "channelId"}]}``) and reads each binary
``messageData`` frame (opcode 0x01, subscription id u32 LE, log time u64 LE [ns], the
payload), decoding each payload on its own by its channel's advertised encoding: JSON
with ``json``, protobuf with the FileDescriptorSet the channel advertised
(tests/foxglove/protobuf.py). A thread reads everything the server sends, so the server
never waits on the test (nor drops its messages).
"""

from __future__ import annotations

import base64
import json
import struct
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from websockets.exceptions import ConnectionClosed
from websockets.sync.client import ClientConnection, connect

from tests.foxglove import protobuf
from tests.support.wait import wait_for

SUBPROTOCOL = "foxglove.sdk.v1"
MESSAGE_DATA = 0x01


@dataclass(frozen=True)
class Received:
    topic: str
    log_time_ns: int
    message: Any  # the decoded payload


class FoxgloveClient:
    """One connection; ``with`` closes it."""

    def __init__(self, url: str, headers: dict[str, str] | None = None) -> None:
        self.ws: ClientConnection = connect(
            url,
            subprotocols=[SUBPROTOCOL],  # type: ignore[list-item]
            additional_headers=headers,
            proxy=None,
            max_size=None,
            open_timeout=30,
        )
        self.server_info: dict[str, Any] | None = None
        self.channels: dict[int, dict[str, Any]] = {}  # advertised, by channel id
        self.received: list[Received] = []
        self.errors: list[str] = []
        self._subscriptions: dict[int, int] = {}  # subscription id -> channel id
        self._decoders: dict[int, Callable[[bytes], Any]] = {}
        self._lock = threading.Lock()
        self._reader = threading.Thread(target=self._read, name="foxglove-client", daemon=True)
        self._reader.start()

    def __enter__(self) -> FoxgloveClient:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.ws.close()
        self._reader.join(timeout=10)

    # ---- reading ----
    def _read(self) -> None:
        try:
            for frame in self.ws:
                try:
                    if isinstance(frame, str):
                        self._on_text(json.loads(frame))
                    else:
                        self._on_binary(frame)
                except Exception as exc:  # a frame the test cannot read fails the test
                    self.errors.append(f"{type(exc).__name__}: {exc}")
        except ConnectionClosed:
            pass

    def _on_text(self, message: dict[str, Any]) -> None:
        op = message.get("op")
        with self._lock:
            if op == "serverInfo":
                self.server_info = message
            elif op == "advertise":
                for channel in message["channels"]:
                    self.channels[channel["id"]] = channel
            elif op == "unadvertise":
                for channel_id in message["channelIds"]:
                    self.channels.pop(channel_id, None)

    def _on_binary(self, frame: bytes) -> None:
        if frame[0] != MESSAGE_DATA:
            return  # time, service responses, ...: not what this client asked for
        subscription, log_time = struct.unpack_from("<IQ", frame, 1)
        payload = frame[1 + 4 + 8 :]
        with self._lock:
            channel = self.channels[self._subscriptions[subscription]]
            decoder = self._decoders[subscription]
        self.received.append(Received(channel["topic"], log_time, decoder(payload)))

    # ---- asking ----
    def topics(self) -> dict[str, dict[str, Any]]:
        with self._lock:
            return {c["topic"]: c for c in self.channels.values()}

    def wait_advertised(self, topics: set[str]) -> dict[str, dict[str, Any]]:
        wait_for(
            lambda: self.server_info is not None and topics <= set(self.topics()),
            f"serverInfo and the channels {sorted(topics)} advertised",
            seen=lambda: (self.server_info, sorted(self.topics()), self.errors),
        )
        return self.topics()

    def subscribe(self, topics: set[str]) -> None:
        advertised = self.wait_advertised(topics)
        subscriptions = []
        with self._lock:
            for topic in sorted(topics):
                channel = advertised[topic]
                sub_id = len(self._subscriptions) + 1
                self._subscriptions[sub_id] = channel["id"]
                self._decoders[sub_id] = decoder(channel)
                subscriptions.append({"id": sub_id, "channelId": channel["id"]})
        self.ws.send(json.dumps({"op": "subscribe", "subscriptions": subscriptions}))

    def messages(self, topic: str) -> list[Received]:
        return [r for r in list(self.received) if r.topic == topic]

    def wait_message(self, topic: str, test: Callable[[Any], bool], what: str) -> Received:
        """The first message on ``topic`` that passes ``test``, waiting for it."""

        def found() -> Received | None:
            assert not self.errors, self.errors
            return next((r for r in self.messages(topic) if test(r.message)), None)

        return wait_for(found, what, seen=lambda: [r.message for r in self.messages(topic)[-5:]])


def decoder(channel: dict[str, Any]) -> Callable[[bytes], Any]:
    """How to read a payload of ``channel``, from what it advertised."""
    encoding = channel["encoding"]
    if encoding == "json":
        return lambda payload: json.loads(payload)
    if encoding == "protobuf" and channel.get("schemaEncoding") == "protobuf":
        types = protobuf.descriptor_types(base64.b64decode(channel["schema"]))
        name = channel["schemaName"]
        assert name in types, (name, sorted(types))
        return lambda payload: protobuf.decode(types, name, payload)
    raise AssertionError(f"no decoder for {channel['topic']}: {encoding}")
