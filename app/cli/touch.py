"""``deltadash touch``: a touch on a running server (docs/contact.md): a guarded move along a
direction that stops at a set force, then the outcome, the contact point and the forces.

Takes control of the server at ``--url`` (the lease), starts the touch (``POST
/api/contact/touch``), follows it (``GET /api/contact`` and ``GET /api/status``) until it has
ended and any retract is done, gives control back and prints the result. Lengths are mm and
speeds mm/s as for the other commands (``--si``: m and m/s); forces are N. Torque must be on
(a touch starts from where the arm is held). Ctrl-C e-stops the robot (``POST /api/estop``;
Reset clears it): the command line's way out; the page's Stop is ``POST /api/stop``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import sys
import time
from typing import Any

from app.cli.numbers import number, parse_number

POLL_S = 0.1  # how often the touch is looked at [s]
METRES_LIKELY_MM = 0.5  # a travel or speed under this [mm, mm/s] reads as SI typed without --si
AXES = {
    "x": (1.0, 0.0, 0.0),
    "y": (0.0, 1.0, 0.0),
    "z": (0.0, 0.0, 1.0),
}
EXIT_WORDS = (
    "Exit 0: contact (stopped at the set force); 1: it ended without contact (no contact "
    "within the travel, or stopped); 2: refused or bad input; 3: control could not be given "
    "back; 130: Ctrl-C (the robot is e-stopped)."
)


def add_parser(commands: argparse._SubParsersAction) -> argparse.ArgumentParser:
    parser = commands.add_parser(
        "touch",
        help="touch a surface on a running server: stop at a set force, print the point",
        description=__doc__,
        epilog=EXIT_WORDS,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "--url", default="http://127.0.0.1:8000", help="the server (default %(default)s)"
    )
    parser.add_argument(
        "--token", default=os.environ.get("DELTADASH_TOKEN"), help="the server's token"
    )
    parser.add_argument(
        "--take-over", action="store_true", help="take control from another client that holds it"
    )
    parser.add_argument(
        "--direction",
        type=direction,
        default=(0.0, 0.0, -1.0),
        metavar="D",
        help="the direction to move in, base frame: three numbers x,y,z (0,0,-1; normalised "
        "by the server) or an axis, e.g. --direction=-z (default: down, -z)",
    )
    parser.add_argument(
        "--force", type=number, metavar="N", help="set force [N] (default contact.touch_force_n)"
    )
    parser.add_argument(
        "--speed",
        type=number,
        metavar="V",
        help="approach speed [mm/s; m/s with --si] (default contact.touch_speed_m_s)",
    )
    parser.add_argument(
        "--travel",
        type=number,
        metavar="L",
        help="travel before 'no contact' [mm; m with --si] (default contact.touch_max_travel_m)",
    )
    parser.add_argument(
        "--retract",
        type=number,
        default=0.0,
        metavar="L",
        help="move back this far after the touch [mm; m with --si] (default 0: stay pressed)",
    )
    parser.add_argument("--si", action="store_true", help="lengths in m and speeds in m/s")
    parser.add_argument("--json", action="store_true", help="print the touch's result as JSON (SI)")
    parser.set_defaults(handler=run)
    return parser


def direction(text: str) -> tuple[float, float, float]:
    """argparse ``type=`` of ``--direction``: an axis (``-z``, ``+x``, ``y``) or three numbers
    separated by commas (``0,0,-1``) or, for decimal commas, by spaces or semicolons
    (``0 0,5 -1``). Not normalised (the server does). ArgumentTypeError naming the value."""
    word = str(text).strip().lower().replace("\u2212", "-")
    axis = re.fullmatch(r"([+-]?)([xyz])", word)
    if axis:
        sign = -1.0 if axis.group(1) == "-" else 1.0
        return tuple(sign * c for c in AXES[axis.group(2)])  # type: ignore[return-value]
    parts = re.split(r"[\s;]+", word) if re.search(r"[\s;]", word) else word.split(",")
    if len(parts) != 3:
        raise argparse.ArgumentTypeError(
            f"{text!r}: give three numbers x,y,z (e.g. 0,0,-1) or an axis (e.g. -z)"
        )
    try:
        values = tuple(parse_number(p) for p in parts)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"{text!r}: {exc}") from None
    if math.hypot(*values) == 0.0:
        raise argparse.ArgumentTypeError(f"{text!r}: the direction must not be zero")
    return values  # type: ignore[return-value]


def request_body(args: argparse.Namespace) -> dict[str, Any]:
    """The body of POST /api/contact/touch (SI) from the options (mm and mm/s unless --si).
    ValueError naming the option for a travel or speed that looks like SI typed as mm."""
    scale = 1.0 if args.si else 1e-3
    body: dict[str, Any] = {"direction": list(args.direction)}
    if args.force is not None:
        body["force_n"] = args.force
    for option, field in (("speed", "speed_m_s"), ("travel", "max_travel_m")):
        value = getattr(args, option)
        if value is None:
            continue
        if not args.si and 0 < abs(value) < METRES_LIKELY_MM:
            unit = "mm/s" if option == "speed" else "mm"
            raise ValueError(
                f"--{option} {value:g} {unit} looks like SI: "
                f"give {value * 1e3:g} {unit}, or add --si"
            )
        body[field] = value * scale
    body["retract_m"] = args.retract * scale
    return body


def _wait(seconds: float) -> None:
    """Between two looks at the touch (a test runs the robot's simulated time instead)."""
    time.sleep(seconds)


def _follow(url: str, body: dict[str, Any], headers: dict[str, str]) -> dict[str, Any]:
    """Start the touch and follow it to its end (its outcome known, the arm no longer in
    mode "touch": any retract done); its result (GET /api/contact "touch")."""
    from app.cli import run as cli_run

    started = cli_run._http(f"{url}/api/contact/touch", "POST", body, headers)
    source_id = started["result"]["source_id"]
    while True:
        touch = cli_run._http(f"{url}/api/contact", headers=headers)["touch"]
        mine = touch is not None and touch["source_id"] == source_id
        if mine and touch["outcome"] != "touching":
            mode = cli_run._http(f"{url}/api/status", headers=headers)["mode"]
            if mode != "touch":
                return touch
        _wait(POLL_S)


def _known(values: list[float | None] | None) -> list[float] | None:
    """``values`` when every one is known (the API's null: not known), else None."""
    if not values or any(v is None for v in values):
        return None
    return [float(v) for v in values if v is not None]


def _vector(values: list[float | None] | None, scale: float, digits: int) -> str:
    known = _known(values)
    if known is None:
        return "(none)"
    return "(" + ", ".join(f"{v * scale:.{digits}f}" for v in known) + ")"


def format_touch(touch: dict[str, Any], body: dict[str, Any], si: bool) -> str:
    """The touch's result in words: outcome (and why it stopped), contact point [mm or m],
    the force it stood at and the peak along the direction [N], the furthest travel."""
    scale, unit, digits = (1.0, "m", 6) if si else (1e3, "mm", 3)
    force = touch.get("force_n")
    known = _known(force)
    magnitude = "" if known is None else f", |F| {math.hypot(*known):.2f} N"
    peak = touch.get("peak_force_n")
    travel = touch.get("travel_m")
    set_force = body.get("force_n")
    reason = touch.get("reason")
    lines = [
        f"touch: {touch['outcome']}" + (f" ({reason})" if reason else ""),
        f"contact point: {_vector(touch.get('contact_point_m'), scale, digits)} {unit}",
        f"force at the stop (before any retract): {_vector(force, 1.0, 2)} N{magnitude}",
        "peak force along the direction: "
        + ("(none)" if peak is None else f"{peak:.2f} N")
        + ("" if set_force is None else f" (set {set_force:g} N)"),
        "travel (furthest commanded): "
        + ("(none)" if travel is None else f"{travel * scale:.{digits}f} {unit}"),
    ]
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    import urllib.error

    from app.cli import run as cli_run
    from app.cli.gcode import _refusal

    try:
        body = request_body(args)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    url = args.url.rstrip("/")
    problems: list[str] = []
    try:
        headers = cli_run._take_control(url, args.token, args.take_over)
        try:
            if not cli_run._http(f"{url}/api/status", headers=headers)["torque"]:
                print(
                    "error: torque is off: turn it on first (the page's Torque on, or "
                    'POST /api/torque {"enabled": true}); a touch starts where the arm is held',
                    file=sys.stderr,
                )
                return 2
            touch = _follow(url, body, headers)
        except KeyboardInterrupt:
            cli_run._try(problems, "e-stop", url, "/api/estop", "POST", headers)
            print("interrupted: the robot is e-stopped (Reset clears it)", file=sys.stderr)
            return 130
        finally:
            cli_run._try(problems, "give control back", url, "/api/lease", "DELETE", headers)
    except cli_run.LeaseRefused as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except urllib.error.HTTPError as exc:
        detail = _refusal(exc).get("detail", exc.reason)
        print(f"error: {exc.code} {detail}", file=sys.stderr)
        return 2
    except (urllib.error.URLError, OSError) as exc:
        print(f"error: {url}: {exc}", file=sys.stderr)
        return 2
    finally:
        for problem in problems:
            print(f"error: {problem}", file=sys.stderr)
    if args.json:
        print(json.dumps(touch, indent=1))
    else:
        print(format_touch(touch, body, args.si))
    if problems:
        return 3
    return 0 if touch["outcome"] == "contact" else 1
