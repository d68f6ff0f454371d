"""Zenoh sessions of the link (app/link/protocol.py): peer mode, the endpoint named.

The node (``deltadash robot``) listens on an endpoint (``link.listen``, e.g.
``tcp/0.0.0.0:7447``); a station connects to it (``link.robot``). Both run Zenoh in peer
mode with multicast scouting off, so a station talks to the node it names and nothing
joins by accident; a Zenoh router or ROS 2's rmw_zenoh on the same network can still
connect to either. With ``link.user`` and ``link.password`` set, each side authenticates
the other (Zenoh's user-password authentication: the node checks a dictionary of that one
user); with the ``link.tls_*`` files the endpoints are ``tls/...`` and the link is
encrypted (docs/server.md, "The robot node").
"""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Callable
from typing import Any

import zenoh

from app.config import LinkSettings


def zenoh_config(link: LinkSettings, listen: str | None = None, connect: str | None = None):
    """A peer-mode Zenoh config: listening on ``listen`` (a node) or connecting to
    ``connect`` (a station), multicast scouting off, with the link's authentication and
    TLS when the settings give them. Returns ``(config, cleanup)``: call ``cleanup()``
    once the session is closed (it removes the node's credentials file)."""
    config = zenoh.Config()
    config.insert_json5("mode", '"peer"')
    config.insert_json5("scouting/multicast/enabled", "false")
    # samples carry Zenoh's timestamps, as rmw_zenoh's sessions: a ROS publisher whose
    # late joiners get its last sample (/tf_static, app/ros2/publisher.py) needs them
    config.insert_json5("timestamping/enabled", "true")
    if listen is not None:
        config.insert_json5("listen/endpoints", json.dumps([listen]))
    if connect is not None:
        config.insert_json5("connect/endpoints", json.dumps([connect]))
        if listen is None:  # a station listens nowhere (Zenoh's peers default to tcp/[::]:0)
            config.insert_json5("listen/endpoints", "[]")
        # keep trying to reach a node that is not up yet, or went away
        config.insert_json5("connect/timeout_ms", "-1")
        config.insert_json5("connect/exit_on_failure", "false")
    cleanup: Callable[[], None] = lambda: None  # noqa: E731
    if link.user is not None and link.password is not None:
        usrpwd: dict[str, str] = {"user": link.user, "password": link.password}
        if listen is not None:  # the node checks who connects against this one user
            handle, path = tempfile.mkstemp(prefix="deltadash-link-", suffix=".txt")
            with os.fdopen(handle, "w") as out:
                out.write(f"{link.user}:{link.password}\n")
            usrpwd["dictionary_file"] = path
            cleanup = lambda: os.unlink(path)  # noqa: E731
        config.insert_json5("transport/auth/usrpwd", json.dumps(usrpwd))
    tls: dict[str, Any] = {}
    if link.tls_root_ca is not None:
        tls["root_ca_certificate"] = link.tls_root_ca
    if link.tls_certificate is not None and link.tls_private_key is not None:
        side = "listen" if listen is not None else "connect"
        tls[f"{side}_certificate"] = link.tls_certificate
        tls[f"{side}_private_key"] = link.tls_private_key
    if tls:
        config.insert_json5("transport/link/tls", json.dumps(tls))
    return config, cleanup
