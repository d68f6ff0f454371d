"""``deltadash serve``: start the control server (and print where to find it)."""

from __future__ import annotations

import argparse
import ipaddress
import os
import pathlib
import sys
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # app.config imports pydantic: only when a command runs (fast --help)
    from app.config import Settings


def add_parser(commands: argparse._SubParsersAction) -> argparse.ArgumentParser:
    parser = commands.add_parser(
        "serve",
        help="start the control server (simulator by default)",
        description="Start the HTTP/WebSocket control server and its 200 Hz control loop.",
    )
    parser.add_argument("--config", help="TOML config file (see app/config.py)")
    parser.add_argument("--backend", choices=["sim", "emulated", "dynamixel"])
    parser.add_argument("--port", help="serial port of the servo bus, e.g. /dev/ttyUSB0")
    parser.add_argument("--baud", type=int, help="bus baud rate [bit/s], e.g. 4000000")
    parser.add_argument("--host", help="bind address (default 127.0.0.1)")
    parser.add_argument("--http-port", type=int, help="HTTP port (default 8000)")
    parser.add_argument(
        "--foxglove",
        action="store_true",
        default=None,
        help="serve the robot live to Foxglove ([foxglove]: ws://127.0.0.1:8765; docs/foxglove.md)",
    )
    parser.add_argument(
        "--robot",
        help="where the control loop runs: embedded (default: a robot node started here as "
        "a child process), the Zenoh endpoint of a robot node elsewhere (e.g. "
        "tcp/192.168.1.20:7447, see deltadash robot), or in-process",
    )
    parser.add_argument(
        "--take-over",
        action="store_true",
        default=None,
        help="take the robot node's link from another station that holds it (logged by "
        "the node; that station's commands are refused from then on)",
    )
    parser.add_argument(
        "--token",
        default=os.environ.get("DELTADASH_TOKEN"),
        help="control token ($DELTADASH_TOKEN)",
    )
    parser.set_defaults(handler=run)
    return parser


def _overrides(args: argparse.Namespace) -> dict[str, Any]:
    hardware = {
        k: v
        for k, v in (("backend", args.backend), ("port", args.port), ("baud", args.baud))
        if v is not None
    }
    server = {
        k: v
        for k, v in (("host", args.host), ("http_port", args.http_port), ("token", args.token))
        if v is not None
    }
    link = {
        k: v for k, v in (("robot", args.robot), ("take_over", args.take_over)) if v is not None
    }
    foxglove = {"enabled": True} if getattr(args, "foxglove", None) else {}
    sections = (("hardware", hardware), ("server", server), ("link", link), ("foxglove", foxglove))
    return {key: value for key, value in sections if value}


def _is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def check_exposure(settings: Settings) -> None:
    """Binding beyond loopback without a token would hand the robot to the network."""
    from app.config import ConfigError

    if not _is_loopback(settings.server.host) and settings.server.token is None:
        raise ConfigError(
            f"server.host = {settings.server.host!r} is reachable from other machines: "
            "set a token (--token or DELTADASH_TOKEN, 8+ characters)"
        )


def run(args: argparse.Namespace) -> int:
    from app.config import ConfigError, load_settings
    from app.server import create_app
    from app.server.serving import serve

    try:
        settings = load_settings(args.config, **_overrides(args))
        check_exposure(settings)
    except ConfigError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    server, robot = settings.server, settings.link.robot
    where = {
        "embedded": f"a robot node of its own on backend {settings.hardware.backend}",
        "in-process": f"the loop in this process on backend {settings.hardware.backend}",
    }.get(robot, f"the robot node at {robot}")
    print(
        f"deltadash: dashboard and API on http://{server.host}:{server.http_port}/ "
        f"(API docs at /docs), {where}",
        flush=True,
    )
    if server.scene:
        from app.scene.scene import scene_host

        print(
            f"deltadash: 3D scene on http://{scene_host(server.host)}:{server.viser_port}/",
            flush=True,
        )
    app = create_app(settings, config_path=pathlib.Path(args.config) if args.config else None)
    serve(  # uvicorn, its check workers killed as the stop begins (app/server/serving.py)
        app,
        host=server.host,
        port=server.http_port,
        log_level="info",
        # telemetry is ~1 kB of JSON per message at 50 Hz per client: compressing it cost the
        # server's main thread more than the JSON itself (py-spy), holding the loop's GIL
        ws_per_message_deflate=False,
    )
    return 0
