"""A Zenoh router (as rmw_zenohd runs one for a ROS 2 graph): ``python router.py <endpoint>``
listens there until killed; prints "router up" once it listens."""

from __future__ import annotations

import json
import sys
import threading

import zenoh

if __name__ == "__main__":
    config = zenoh.Config()
    config.insert_json5("mode", '"router"')
    config.insert_json5("listen/endpoints", json.dumps([sys.argv[1]]))
    config.insert_json5("scouting/multicast/enabled", "false")
    session = zenoh.open(config)
    print("router up", flush=True)
    threading.Event().wait()
