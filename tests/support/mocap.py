"""A motion-capture system on the twin, as a lab's would stream it to deltadash.

``TwinMocap`` reads the twin's own view of its platform (``measure_platform``: the true
centre plus marker, in the twin's measurement frame, with its noise) at ``rate_hz`` and
sends each reading to the server's UDP pose input as the documented JSON, body
"platform", with its own clock (one that runs on from one stream to the next), a still
orientation and ``shift_m`` added: the stream's world frame is then not the one the
twin's ``ee.external_m`` uses, so a fit that came out in the shifted frame used the
stream. It is what a VICON/OptiTrack bridge does, over the real socket and listener.
"""

from __future__ import annotations

import json
import socket
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np


def free_udp_port() -> int:
    """A UDP port free on 127.0.0.1 now."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


class TwinMocap:
    """Streams ``bus.measure_platform()`` + ``shift_m`` [m] to 127.0.0.1:``port`` over UDP."""

    def __init__(self, bus, port: int, rate_hz: float = 100.0, shift_m=(0.0, 0.0, 0.0)) -> None:
        self.bus, self.port, self.period_s = bus, port, 1.0 / rate_hz
        self.shift_m = np.asarray(shift_m, dtype=np.float64)
        self.sent = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="twin-mocap", daemon=True)

    def _run(self) -> None:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as out:
            while not self._stop.wait(self.period_s):
                position = self.bus.measure_platform() + self.shift_m
                sample = {
                    "t": time.monotonic(),  # a capture system's clock: it runs on between takes
                    "position": [float(v) for v in position],
                    "quaternion": [1.0, 0.0, 0.0, 0.0],
                    "body": "platform",
                }
                out.sendto(json.dumps(sample).encode(), ("127.0.0.1", self.port))
                self.sent += 1

    @contextmanager
    def streaming(self) -> Iterator[TwinMocap]:
        """Streams while the ``with`` lasts."""
        self._thread.start()
        try:
            yield self
        finally:
            self._stop.set()
            self._thread.join(timeout=2.0)
