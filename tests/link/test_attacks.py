"""The link against a peer that is not its station, as real processes over loopback.

A robot node (`deltadash robot`), its station (a RobotClient here, or `deltadash serve`)
and a third Zenoh session playing the attacker: it reads what any peer can read (the
node's status names the holder) and sends what any peer can send. Nothing it does may
move the robot, keep a lost station's link alive, hold the loop, or make a station show
what the node did not say.
"""

from __future__ import annotations

import json
import os
import signal
import time
import urllib.error
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest

from app.config import LinkSettings
from app.link.zenoh_session import zenoh_config
from tests.support.robot_node import node_env, robot_node, station, watch
from tests.support.server import serve, wait_for

pytestmark = pytest.mark.slow  # real processes


@contextmanager
def peer(endpoint: str, **login: str) -> Iterator[Any]:
    """A Zenoh session of the attacker's (a login only where given)."""
    import zenoh

    config, cleanup = zenoh_config(LinkSettings(**login), connect=endpoint)
    session = zenoh.open(config)
    try:
        yield session
    finally:
        session.close()
        cleanup()


def ask(session: Any, selector: str, payload: bytes = b"{}", timeout_s: float = 5.0) -> Any:
    """The node's answer to a query (None: no answer)."""
    replies = list(session.get(selector, payload=payload, timeout=timeout_s))
    if not replies or replies[0].ok is None:
        return None
    return json.loads(replies[0].ok.payload.to_bytes())


def _holder(session: Any) -> str:
    status: list[dict] = []
    subscriber = session.declare_subscriber(
        "deltadash/robot/node", lambda s: status.append(json.loads(s.payload.to_bytes()))
    )
    wait_for(lambda: status and status[-1]["link"]["holder"], "the node's status naming its holder")
    subscriber.undeclare()
    return status[-1]["link"]["holder"]


def test_a_peer_that_knows_the_holders_id_cannot_command_or_keep_it_alive(
    tmp_path: Path,
) -> None:
    env = node_env(station_timeout_s=0.5)  # a loaded machine's heartbeat gaps stay below
    with (
        robot_node(tmp_path, **env) as node,
        watch(node.endpoint) as seen,
        station(node.endpoint) as a,
        peer(node.endpoint) as evil,
    ):
        holder = _holder(evil)
        assert holder == a.station_id
        for op, args in (("torque", {"enabled": True}), ("reset", {}), ("tap", {"on": True})):
            said = ask(
                evil, f"deltadash/robot/cmd/{op}?station={holder}", json.dumps(args).encode()
            )
            assert said is not None and not said["ok"] and said["error"]["kind"] == "link", said
        forged = f"deltadash/robot/cmd/torque?station={holder};seq=1;mac=" + "0" * 64
        said = ask(evil, forged, b'{"enabled":true}')
        assert said["error"]["kind"] == "link" and "not signed" in said["error"]["message"]
        assert not seen.latest.torque
        # the holder goes silent; beats under its id keep nothing alive: the link is lost
        # while they keep coming
        status: list[dict] = []
        evil.declare_subscriber(
            "deltadash/robot/node", lambda s: status.append(json.loads(s.payload.to_bytes()))
        )
        beats = evil.declare_publisher(f"deltadash/robot/heartbeat/{holder}")
        a.transport._closed.set()  # its heartbeat thread stops: the station falls silent

        def forging() -> bool:
            beats.put(b"%d:%s" % (int(time.monotonic() * 1e3), b"f" * 64))
            return bool(status) and status[-1]["link"]["losses"] == 1

        wait_for(forging, "the holder lost under forged heartbeats")


def test_a_forged_state_or_garbage_does_not_reach_the_stations_status(tmp_path: Path) -> None:
    with robot_node(tmp_path) as node, serve(tmp_path, DELTADASH_LINK__ROBOT=node.endpoint) as st:
        before = st.get("/api/status")
        with peer(node.endpoint) as evil:
            state = evil.declare_publisher("deltadash/robot/state")
            forged = {"tick": 10**12, "estopped": True, "notice": "forged", "info": {"boot": "x"}}
            for payload in (
                b"{}",
                b'{"tick": 1e400}',
                b'{"tick": "x"}',
                json.dumps(forged).encode(),
                b"\xff",
            ):
                state.put(payload)
            sent_at = st.get("/api/status")["loop"]["ticks"]
            seen: list[dict] = []

            def moved_on() -> bool:
                """Every status the station gives while the real node ticks 100 more times
                (the forged states had their chance to arrive) is the real node's."""
                seen.append(st.get("/api/status"))
                return seen[-1]["loop"]["ticks"] > sent_at + 100

            wait_for(moved_on, "the real node's next 100 ticks at the station")
        assert all(s["notice"] != "forged" and not s["estopped"] for s in seen)
        assert seen[-1]["loop"]["ticks"] > before["loop"]["ticks"]  # the real node's, moving


def test_a_huge_command_from_a_peer_is_refused_unread_and_holds_nothing(tmp_path: Path) -> None:
    with robot_node(tmp_path) as node, watch(node.endpoint) as seen, peer(node.endpoint) as evil:
        wait_for(lambda: seen.latest is not None, "states")
        said = ask(evil, "deltadash/robot/cmd/torque?station=evil", b"[" * (40 << 20), 20.0)
        assert said["error"]["kind"] == "invalid" and "bytes, more than" in said["error"]["message"]
        said = ask(evil, "deltadash/robot/cmd/torque?station=evil", b" " * (8 << 20), 20.0)
        assert said["error"]["kind"] == "link"  # not the holder: its body never parsed
        wait_for(lambda: len(seen.seen) > 10, "states after")
        gap = seen.latest.loop_window.longest_gap_ms
        assert gap < 1000.0, f"the loop was held {gap:.0f} ms"  # not a timing claim: a stall


def test_the_embedded_node_takes_no_session_but_its_stations(tmp_path: Path) -> None:
    with serve(tmp_path) as server:
        children = [
            p
            for p in Path("/proc").iterdir()
            if p.name.isdigit() and b"--parent\x00%d" % server.process.pid in _cmdline(p)
        ]
        assert len(children) == 1
        args = _cmdline(children[0]).split(b"\x00")
        endpoint = args[args.index(b"--listen") + 1].decode()
        with peer(endpoint) as evil:  # no login: the node's transport refuses the session
            assert ask(evil, "deltadash/robot/cmd/info", timeout_s=3.0) is None
            assert ask(evil, "deltadash/robot/cmd/estop", timeout_s=3.0) is None
        with peer(endpoint, user="station", password="not-the-password") as evil:
            assert ask(evil, "deltadash/robot/cmd/info", timeout_s=3.0) is None
        assert not server.get("/api/status")["estopped"]


def _cmdline(proc: Path) -> bytes:
    try:
        return (proc / "cmdline").read_bytes()
    except OSError:
        return b""


def test_a_restarted_node_is_followed_not_its_predecessors_last_state(tmp_path: Path) -> None:
    with robot_node(tmp_path) as node, serve(tmp_path, DELTADASH_LINK__ROBOT=node.endpoint) as st:
        wait_for(lambda: st.get("/api/status")["loop"]["ticks"] > 400, "the first node's ticks")
        node.kill(signal.SIGKILL)
        node.process.wait()
        with robot_node(tmp_path, endpoint=node.endpoint):

            def follows_the_new_one() -> bool:
                try:
                    status = st.get("/api/status")
                except urllib.error.HTTPError:
                    return False
                return status["loop"]["ticks"] < 400  # the new loop's count, not the old

            wait_for(follows_the_new_one, "the station following the new node", seen=st.brief)
            first = st.get("/api/status")["loop"]["ticks"]
            wait_for(lambda: st.get("/api/status")["loop"]["ticks"] > first, "it moving on")


def _listening_inodes() -> set[str]:
    """The inodes of TCP sockets in LISTEN state on this machine (/proc/net/tcp, tcp6)."""
    found = set()
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        with open(table) as rows:
            for row in list(rows)[1:]:
                fields = row.split()
                if fields[3] == "0A":  # LISTEN
                    found.add(fields[9])
    return found


def _own_socket_inodes() -> set[str]:
    inodes = set()
    for fd in Path("/proc/self/fd").iterdir():
        try:
            target = os.readlink(fd)
        except OSError:
            continue
        if target.startswith("socket:["):
            inodes.add(target[8:-1])
    return inodes


def test_a_station_session_listens_on_no_port() -> None:
    """A station only connects: Zenoh's peers would otherwise listen on every interface."""
    import zenoh

    from app.config import LinkSettings
    from app.link.zenoh_session import zenoh_config

    config, cleanup = zenoh_config(LinkSettings(), connect="tcp/127.0.0.1:9")
    before = _own_socket_inodes() & _listening_inodes()
    session = zenoh.open(config)
    try:
        assert (_own_socket_inodes() & _listening_inodes()) - before == set()
    finally:
        session.close()
        cleanup()
    # the check sees a listener where there is one: a node's session
    config, cleanup = zenoh_config(LinkSettings(), listen="tcp/127.0.0.1:0")
    session = zenoh.open(config)
    try:
        assert (_own_socket_inodes() & _listening_inodes()) - before != set()
    finally:
        session.close()
        cleanup()
