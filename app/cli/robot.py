"""``deltadash robot``: the robot node alone, e.g. on the drone's computer.

It owns the servo bus and runs the control loop; a station (``deltadash serve --robot
ENDPOINT``) commands it over Eclipse Zenoh (docs/server.md, "The robot node"). It prints
one line once it listens, and stops on Ctrl-C or SIGTERM, relaxing the servos as its
config says (``safety.torque_off_on_exit``).
"""

from __future__ import annotations

import argparse
import contextlib
import gc
import os
import signal
import sys
import threading
import time

GIL_SWITCH_S = 2.5e-4  # as app/server/app.py


def add_parser(commands: argparse._SubParsersAction) -> argparse.ArgumentParser:
    parser = commands.add_parser(
        "robot",
        help="run the robot node: the control loop and the servo bus, linked over Zenoh",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--config", help="TOML config file (see app/config.py)")
    parser.add_argument("--backend", choices=["sim", "emulated", "dynamixel"])
    parser.add_argument("--port", help="serial port of the servo bus, e.g. /dev/ttyUSB0")
    parser.add_argument("--baud", type=int, help="bus baud rate [bit/s], e.g. 4000000")
    parser.add_argument(
        "--listen",
        help="the Zenoh endpoint to listen on (default link.listen: tcp/127.0.0.1:7447; "
        "tcp/0.0.0.0:7447 for every interface, which needs link.user and link.password)",
    )
    parser.add_argument(
        "--parent",
        type=int,
        help=argparse.SUPPRESS,  # deltadash serve's pid: an embedded node ends after it
    )
    parser.add_argument(
        "--orphan-hold-s",
        type=float,
        default=5.0,
        help=argparse.SUPPRESS,  # how long an embedded node holds once its station is gone
    )
    parser.set_defaults(handler=run)
    return parser


def _overrides(args: argparse.Namespace) -> dict:
    hardware = {
        k: v
        for k, v in (("backend", args.backend), ("port", args.port), ("baud", args.baud))
        if v is not None
    }
    link = {"listen": args.listen} if args.listen else {}
    return {k: v for k, v in (("hardware", hardware), ("link", link)) if v}


def listen_host(listen: str) -> str:
    """The host of a Zenoh endpoint (tcp/0.0.0.0:7447 -> 0.0.0.0)."""
    return listen.split("/", 1)[-1].rsplit(":", 1)[0].strip("[]")


def is_loopback(host: str) -> bool:
    return host in ("localhost", "::1") or host.startswith("127.")


def check_exposure(listen: str, user: str | None, password: str | None) -> None:
    """Listening beyond loopback without a login would hand the robot to the network."""
    from app.config import ConfigError

    loopback = is_loopback(listen_host(listen))
    if not loopback and (user is None or password is None):
        raise ConfigError(
            f"link.listen = {listen!r} is reachable from other machines: set link.user and "
            "link.password (DELTADASH_LINK__USER, DELTADASH_LINK__PASSWORD; 8+ characters): "
            "the stations log in with them; TLS adds encryption, not a login (docs/server.md)"
        )


def _signal_when_parent_dies(signum: int) -> None:
    """Linux's PR_SET_PDEATHSIG: ``signum`` to this process when its parent exits (killed
    included); nothing elsewhere (the parent's pid is then polled)."""
    import ctypes

    with contextlib.suppress(OSError, AttributeError):
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, signum, 0, 0, 0)  # PR_SET_PDEATHSIG = 1


def run(args: argparse.Namespace) -> int:
    from app.config import ConfigError, load_settings
    from app.control.controller import Controller
    from app.robot.node import RobotNode
    from app.robot.realtime import ask_realtime, share_realtime
    from app.robot.zenoh_server import NodeServer
    from app.server.backends import open_backend

    try:
        settings = load_settings(args.config, **_overrides(args))
        link = settings.link
        check_exposure(link.listen, link.user, link.password)
    except ConfigError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    # the loop's thread gets the GIL back within a fraction of a tick when it wakes (the
    # default switch interval, 5 ms, let the link's threads delay it that long), and a full
    # collection never walks the start-up heap (MuJoCo, Zenoh): as the station does
    sys.setswitchinterval(GIL_SWITCH_S)
    gc.collect()
    gc.freeze()
    stop = threading.Event()
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, lambda *_: stop.set())
    parent_gone = threading.Event()
    if args.parent is not None:  # an embedded node hears at once that its station died
        signal.signal(signal.SIGUSR1, lambda *_: parent_gone.set())
        _signal_when_parent_dies(signal.SIGUSR1)
        if os.getppid() != args.parent:  # gone before the request took effect
            parent_gone.set()
    with open_backend(settings) as backend:
        controller = Controller(
            settings,
            backend.bus,
            backend.kind,
            backend.description,
            thread_setup=lambda: ask_realtime(settings.loop),
        )
        node = RobotNode(settings, controller, station_timeout_s=link.station_timeout_s)
        node.start()
        # beyond loopback the pages reach the node's e-stop where they reach its link
        host = listen_host(link.listen)
        node.start_estop_listener(None if is_loopback(host) else host)
        simulator = getattr(backend.bus, "simulator_pid", None)  # the twin's own process
        if simulator is not None:
            for _ in range(100):  # the loop's thread asks for SCHED_FIFO as it starts
                if controller.thread_setup_result is not None:
                    break
                time.sleep(0.01)
            share_realtime(controller.thread_setup_result, simulator)
        server = NodeServer(node, link, link.listen)
        print(
            f"deltadash robot: listening on {link.listen} (keys {link.key_prefix}/...), "
            f"backend {backend.kind}",
            flush=True,
        )
        try:
            while not stop.is_set():
                gone = parent_gone.wait(0.1) or (
                    args.parent is not None and os.getppid() != args.parent
                )
                if gone:
                    node.holder.expire()  # its link is lost now: the next tick stops and holds
                    print(
                        f"deltadash robot: station {args.parent} is gone; holding "
                        f"{args.orphan_hold_s:g} s, then stopping",
                        flush=True,
                    )
                    stop.wait(args.orphan_hold_s)
                    break
        finally:
            server.close()
            unsafe = node.stop()
    if unsafe:
        print(f"error: {unsafe}", file=sys.stderr)
        return 3
    return 0
